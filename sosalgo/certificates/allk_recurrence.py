"""The recurrence theta_0 = 1, theta_{k+1} = (1 + sqrt(1 + 4 theta_k^2))/2 of FISTA and
OGM, for the all-k potentials (:mod:`sosalgo.certificates.allk`, docs/all-k.md).

The recurrence is used as an identity, theta_{k+1}^2 - theta_{k+1} = theta_k^2: the pairs
(theta_k, theta_{k+1}) lie on the hyperbola (tau - 1/2)^2 - theta^2 = 1/4, whose rational
parametrization by w = theta_k + theta_{k+1} - 1/2 > 0 is

    theta_k = (4 w^2 - 1)/(8 w),     theta_{k+1} = (2 w + 1)^2/(8 w).

So every condition of step k (a polynomial in theta_k and theta_{k+1}) times a power of w
is a polynomial in the one variable w, and it must hold for every w the sequence reaches.
The proof (:func:`check_lemma`, exact) shows:

- the identity theta_{k+1}^2 - theta_{k+1} - theta_k^2 = 0 in w, and theta_{k+1} - theta_k
  - 1/2 = 1/(4 w) > 0: by induction from theta_0 = 1, theta_k >= 1 + k/2 (the growth
  lemma), so theta_{N-1} >= (N + 1)/2;
- theta_k(w) increases with w and theta_k(W0) <= 1 (W0 = 2): every step has w_k >= W0,
  so the conditions are proven for w = W0 + s, s >= 0 (s is the certificate's variable);
- theta_k(w) > 0 there (the multipliers, polynomials in theta_k with nonnegative
  coefficients, are >= 0).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

from sosalgo.spec.types import SpecError

if TYPE_CHECKING:
    from sosalgo.spec.types import Spec

__all__ = ["W0", "Recurrence", "check_lemma", "recognize"]

W0 = Fraction(2)


@dataclass
class Recurrence:
    """The sequence ``name`` in the variable ``var`` (s >= 0, w = W0 + s): its value
    ``at`` step k and ``next`` (theta_{k+1}) as rational functions of s, and ``w`` (the
    factor the conditions are multiplied by, positive)."""

    name: str
    var: Any
    w: Any
    at: Any
    next: Any


def make(name: str, var: Any) -> Recurrence:
    """The recurrence of the module's docstring in the variable ``var``."""
    import sympy as sp

    w = sp.Rational(W0.numerator, W0.denominator) + var
    return Recurrence(name, var, w, (4 * w**2 - 1) / (8 * w), (2 * w + 1) ** 2 / (8 * w))


def check_lemma(rec: Recurrence) -> str | None:
    """Why the facts of the module's docstring fail (None: all proven exactly)."""
    import sympy as sp

    s, w = rec.var, rec.w
    if sp.cancel(rec.next**2 - rec.next - rec.at**2) != 0:
        return "theta_{k+1}^2 - theta_{k+1} = theta_k^2 fails"
    if sp.cancel(rec.next - rec.at - sp.Rational(1, 2) - 1 / (4 * w)) != 0:
        return "theta_{k+1} - theta_k - 1/2 = 1/(4w) fails"
    if sp.cancel(sp.diff(rec.at, s) - (4 * w**2 + 1) / (8 * w**2)) != 0:
        return "theta_k(w) is not increasing"
    if rec.at.subs(s, 0) > 1:
        return "theta_k(W0) > theta_0"
    num, den = sp.fraction(sp.cancel(rec.at))
    for poly in (sp.Poly(num, s), sp.Poly(den, s)):
        if poly.eval(0) <= 0 or poly.count_roots(0, None):
            return "theta_k(w) is not positive on w >= W0"
    return None


def _standard_next(decl: Any, spec: Spec) -> bool:
    import sympy as sp

    from sosalgo.kernel.expr.parse import sympy_symbol, to_sympy

    t = sympy_symbol(decl.name)
    target = (1 + sp.sqrt(1 + 4 * t**2)) / 2
    try:
        nxt = to_sympy(decl.next)
        first = to_sympy(decl.first)
    except Exception:  # noqa: BLE001 - an expression sympy cannot take is not the form
        return False
    return sp.simplify(nxt - target) == 0 and sp.simplify(first - 1) == 0


def recognize(spec: Spec, used: list[str], var: Any) -> Recurrence | None:
    """The :class:`Recurrence` of the one sequence the method uses (None when it uses
    none); SpecError naming the field when that sequence is not theta_0 = 1,
    theta_{k+1} = (1 + sqrt(1 + 4 theta_k^2))/2 at every step, or when it uses more."""
    if not used:
        return None
    if len(used) > 1:
        raise SpecError(spec.source, f"sequences.{used[1]}", "the all-k bound takes one "
                        f"sequence (the method uses {', '.join(used)})")
    decl = spec.sequences[used[0]]
    where = f"sequences.{decl.name}"
    if decl.last is not None:
        raise SpecError(spec.source, f"{where}.last", "a last-step rule makes the last "
                        "step another method: the all-k bound needs the same step at every k")
    if not _standard_next(decl, spec):
        raise SpecError(spec.source, where, f"{decl.name} is given by a recurrence that is "
                        f"not {decl.name}[0] = 1, {decl.name}[k+1] = (1 + sqrt(1 + "
                        f"4*{decl.name}**2))/2 (the one recurrence the all-k bound takes; "
                        "otherwise parameters must be rational functions of k)")
    return make(decl.name, var)
