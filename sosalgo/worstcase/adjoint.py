"""Calls of a linear operator's transpose in the PEP (:mod:`sosalgo.spec.adjoint`).

A spec with transpose calls solves, e.g., min_x f(x) + g(Mx), with the optimality
condition s_f* + M^T s_g* = 0 (the spec's ``optimality:``; s_j* the (sub)gradient of f_j at
its point at the solution). The PEP is written at x* = 0 with every optimal subgradient 0,
which loses no instance:

- translation: x -> x - x*, each function's argument by its point at the solution (x* or
  M x*), takes any instance to one with x* = 0, hence M x* = 0;
- tilt: f_j -> f_j - <s_j*, .> for every function that is not the operator keeps
  f + g(M .) (the optimality condition) and each class (every such class must be
  ``tilt_invariant``), and leaves the operator alone.

The method commutes with both: its trajectory moves by the fixed point of x* and of the
s_j* (the reference tables of :meth:`sosalgo.oracles.OracleMethod.reference_tables`, solved
exactly), so the deviations from the solution, which every term measures, are unchanged,
and so are the tilted values h_j = f_j - f_j* - <s_j*, . - y_j*> the PEP's values are (an
``f`` term is the value of the one function with values, composed with M, whose tilt term
<s_g*, M(x - x*)> = <M^T s_g*, x - x*> vanishes when the optimality has no other term).
Only the start is not moved: a start xi_0 = u x_0 (not ``sdist``) is refused when the
fixed point moves with the s_j* or with M x* (:func:`check_start`).

At x* = 0 with optimal subgradients 0 every call's data is raw. The calls of M and those of
M^T are two point lists: the operator (``M``) and its transpose part (``M.T``, the same
class and parameters). Data (x_a, y_a = M x_a) and (u_b, v_b = M^T u_b) are those of one
linear M with |M| <= L if and only if (Bousselmi, Hendrickx, Glineur, "Interpolation
conditions for linear operators and applications to performance estimation problems",
Thm. 3.1)

    <x_a, v_b> = <y_a, u_b> (every a, b),   [L^2 <x_a, x_b> - <y_a, y_b>] ⪰ 0,
    [L^2 <u_a, u_b> - <v_a, v_b>] ⪰ 0:

the class's Gram-level block over each list, and the equalities as extra rows
``adjoint:a,b+`` (>= 0) and ``adjoint:a,b-`` (<= 0).
"""

from __future__ import annotations

from dataclasses import fields
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.errors import InputError
from sosalgo.oracles import BoundFunction, Method

__all__ = ["adjoint_rows", "check_start", "split_transposes"]

PART = ".T"  # the transpose part's name: the operator's name + PART


def split_transposes(mt: Any, om: Any) -> None:
    """Give ``mt`` (the PEP's frame around an OracleMethod with transpose calls) the
    transpose part of its operator as a function of its own (the same class, parameters,
    inequalities and blocks) with the transpose calls on it, no free optimal subgradient (``moves``:
    whether the solution's state moves with them or M x*, for :func:`check_start`), and
    ``mt.adjoint``. InputError when a function is in a
    class that is not closed under adding linear functions."""
    adj = om.adjoint
    for j in adj.free:
        name, cls, _ = mt.functions[j]
        if not cls.tilt_invariant or cls.alone or not cls.convex:
            raise InputError(f"functions.{name}: {cls.name} with transpose calls: the PEP "
                             "needs a convex class closed under adding linear functions")
    op = adj.dual[0]
    name, cls, params = mt.functions[op]
    # the solution's state moves with the s_j* or with M x* (the last column)
    moves = any(_nonzero(v) for v in np.ravel(mt.Xs))
    mt.Xs = mt.Xs[:, :len(adj.free)]
    if cls.transpose_sign:  # M' = M or -M: calls of M (negated answers for -M)
        mt.adjoint = {"dual": adj.dual, "part": None, "plain": list(adj.plain),
                      "negated": frozenset(adj.transposes if cls.transpose_sign < 0 else ()),
                      "moves": moves}
        mt.method = _with_calls(mt.method, oracles=tuple(
            op if i in adj.transposes else j for i, j in enumerate(mt.oracles)))
        return
    part = len(mt.functions)
    mt.ineqs = [*mt.ineqs, list(mt.ineqs[op])]
    if mt.blocks:
        mt.blocks = [*mt.blocks, list(mt.blocks[op])]
    if mt.constants is not None:
        mt.constants = [*mt.constants, list(mt.constants[op])]
        mt.scopes = [*(mt.scopes or []), list((mt.scopes or [])[op])]
    mt.method = _with_calls(
        mt.method, functions=(*mt.functions, BoundFunction(name + PART, cls, params)),
        oracles=tuple(part if i in adj.transposes else j for i, j in enumerate(mt.oracles)))
    mt.adjoint = {"dual": adj.dual, "part": part, "plain": list(adj.plain),
                  "negated": frozenset(), "moves": moves}


def _with_calls(method: Method, **calls: Any) -> Method:
    """``method`` with its ``functions`` or ``oracles`` replaced (the transpose calls on
    the operator's transpose part): the one Method of the same numbers, not re-checked
    (the float method it comes from was)."""
    return Method(**{f.name: getattr(method, f.name) for f in fields(Method)} | calls)


def check_start(mt: Any, free: bool, option: str) -> None:
    """InputError unless the start is free (``sdist``) or the solution's state does not
    move with the optimal subgradients nor with M x* (their columns of the fixed point
    are 0: the start u x_0 is then invariant under the tilt and the translation)."""
    if free or not mt.adjoint["moves"]:
        return
    raise InputError(f"{option}: with transpose calls the state at the solution moves with "
                     "the optimal subgradients or M x*: start anywhere (sdist)")


def _nonzero(v: Any) -> bool:
    if hasattr(v, "c"):
        return bool(v.c != 0 or v.r != 0)
    return bool(abs(v) > 1e-13) if isinstance(v, float | np.floating) else bool(v != 0)


def adjoint_rows(mt: Any, pts: list[list[Any]]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The rows of the equalities <x_a, v_b> = <y_a, u_b> between every call of M and
    every call of M^T (two rows each, >= 0 and <= 0)."""
    op, part = mt.adjoint["dual"][0], mt.adjoint["part"]
    if part is None:  # M' = M or -M: the class's own conditions over M's points
        return []
    half = Fraction(1, 2) if mt.exact else 0.5
    Q = np.full((4, 4), half * 0, dtype=object if mt.exact else float)
    Q[0, 3] = Q[3, 0] = half
    Q[1, 2] = Q[2, 1] = -half
    rows = []
    for pa in pts[op]:
        for pb in pts[part]:
            if "x*" in (pa.label, pb.label):  # (0, 0): no condition
                continue
            X = np.vstack([pa.x, pa.g * mt.s, pb.x, pb.g * mt.s])
            lab = f"adjoint:{pa.label},{pb.label}"
            rows += [(lab + "+", X, Q), (lab + "-", X, -Q)]
    return rows
