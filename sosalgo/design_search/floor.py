"""The class floor of a design: a rate no method of the spec's kind can beat (a theorem).

On F(m, L) no first-order method has a worst-case rate below 1 - 1/sqrt(kappa) (the lower
complexity bound attained by the triple momentum method; Drori, Taylor 2022). On a
composite problem min f + sum_j g_j the same floor holds when it is a theorem:

* exactly one function f is outside the classes that contain the zero function (a class
  contains it when its quadratics (q/2)|x|^2 include q = 0: ``convex``, ``indicator`` of
  the whole space, ``smooth_strongly_convex`` with m = 0), and f's class has a floor for
  methods querying its gradients alone
  (:meth:`~sosalgo.classes.base.FunctionClass.gradient_floor`: ``smooth_strongly_convex``
  with m > 0, 1 - 1/sqrt(L_f/m_f));
* every call to f is a gradient call (its diagonal entry of D is identically 0).

Then the problems with every g_j = 0 are in the class; on them a proximal step on g_j is
the identity and its subgradient is 0, so the method is a first-order method querying
gradients of f alone, and the floor of F(m_f, L_f) bounds its worst case, hence that of the
whole class. Anything else (a proximal step on f, as in the proximal point method or
Douglas-Rachford, which converge arbitrarily fast as t grows; two strongly convex
functions; a class without a gradient floor) gets no floor: None.
"""

from __future__ import annotations

import math

from sosalgo.errors import ModelError
from sosalgo.spec import Spec

__all__ = ["class_floor"]


def _contains_zero(fn) -> bool:
    """Whether the function's class contains f = 0 (curvature 0 among its quadratics)."""
    cur = fn.cls.curvatures(fn.params)
    return cur is not None and cur[0] <= 0.0 <= cur[1]


def _gradient_only(spec: Spec, fname: str) -> bool:
    """Whether every call to ``fname`` is a gradient call (D_ii identically 0)."""
    from sosalgo.kernel.expr import constant_value

    D = spec.matrices.get("D")
    for i, name in enumerate(spec.oracles):
        if name != fname or D is None:
            continue
        e = D[i][i]
        if not (e.is_constant and constant_value(e) == 0):
            return False
    return True


def class_floor(spec: Spec, kappa: float) -> float | None:
    """1 - 1/sqrt(L_f/m_f) where it is a theorem for the spec's problem class (see the
    module), else None. The seed's setting: 1 - 1/sqrt(kappa)."""
    if spec.has_seed_form:
        return 1.0 - 1.0 / math.sqrt(kappa)
    from sosalgo.model import bind

    try:
        om = bind(spec, kappa)
    except ModelError:
        return None
    hard = [fn for fn in om.functions if not _contains_zero(fn)]
    if len(hard) != 1:
        return None
    f = hard[0]
    floor = f.cls.gradient_floor(f.params)
    if floor is None or not _gradient_only(spec, f.name):
        return None
    return floor
