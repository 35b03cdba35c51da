"""Linear minimization calls in the PEP (Frank-Wolfe's oracle).

A call ``{function: h, lmo: j}`` on the indicator h of a closed convex set C, at the
point y = C_i xi (D_i = 0), answers

    u = s - y,    s in argmin_{s in C} <g, s>,    g the answer of gradient call j,

the same step's. s minimizes <g, .> over C exactly when -g is in the normal cone of C at
s, i.e. -g is a subgradient of h at s (PEPit's ``linear_optimization_step``). So the
call adds to h the point s with subgradient -g; s is free (its own basis vector: the
call's answer, as every answer is), and the class inequalities of h between s and its
other points are the whole constraint. At the fixed point y = x* the answer s - y = 0 is
one valid answer (x* minimizes <grad f(x*), .> over C), so the call's optimal answer is
0 (:meth:`sosalgo.oracles.OracleMethod.optimal_map`) and the deviations are the points.

In the tilted coordinates (:mod:`sosalgo.worstcase.structure`): the answer row is u/s, the
point s = y + s u/s, the tilted subgradient of h there -(g~/s + s_f*/s) - s_h*/s.

The start x_0 is a point of the set (the method starts feasible, as PEPit's
``frank_wolfe`` assumes): h gets a point at x_0 with the subgradient 0 (0 is in the
normal cone at every point of the set, so every instance satisfies h's inequalities with
it: the PEP still bounds every instance, and a free subgradient there would only add
columns whose multipliers must cancel exactly in the proof). When every step
keeps the iterate in the set — one state, x+ = x + lambda_k (s_k - x) with the call at x
and lambda_k in [0, 1] (proven on the exact numbers), the other calls not moving the
state — h gets a point at the output x_N too, so that ``f`` (every function's value:
f(x_N) + h(x_N)) may be asked there; otherwise a term at x_N that needs h is refused (h
may be infinite there).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["lmo_points"]


def lmo_points(mt: Any, pts: list[list[Any]], Yr: list[list[np.ndarray]],
               U: list[list[np.ndarray]], sstar: list[np.ndarray], state: dict[str, Any],
               where: dict[str, np.ndarray], steps: int) -> None:
    """Move each linear minimization call's point to s = y + s u/s with the subgradient
    -g of its direction; give h points at x_0 (and at x_N when the iterates stay in the
    set), before x*."""
    for fp in pts:
        for pt in fp:
            if pt.t is None:
                continue
            i = _call_of(mt, pt.label)
            if i not in mt.lmo:
                continue
            j, d = mt.oracles[i], mt.lmo[i]
            pt.x = Yr[pt.t][i] + U[pt.t][i] * mt.s
            pt.g = -(U[pt.t][d] + sstar[mt.oracles[d]]) - sstar[j]
    sets = sorted({mt.oracles[i] for i in mt.lmo})
    for j in sets:
        _add_point(mt, pts, j, where["x0"], "x0", sstar, state)
        if iterates_in_set(mt, steps, j):
            _add_point(mt, pts, j, where["x"], f"x{steps}", sstar, state)


def _call_of(mt: Any, label: str) -> int:
    """The call index of a call point's label (``y<k>``, or ``y<i>_<k>``)."""
    if mt.p == 1:
        return 0
    return int(label[1:].split("_")[0]) - 1


def _add_point(mt: Any, pts: list[list[Any]], j: int, row: np.ndarray, label: str,
               sstar: list[np.ndarray], state: dict[str, Any]) -> None:
    """Function j's point at ``row`` with the subgradient 0 (in every normal cone of the
    set; tilted: -s_j*) and a value of its own, before x*."""
    point = type(pts[j][-1])  # the structure's PEPPoint (x*'s): no import cycle
    pt = point(label, row, -sstar[j], state["nF"])
    state["nF"] += 1
    pts[j].insert(len(pts[j]) - 1, pt)  # x* stays last


def _interval(v: Any) -> tuple[Any, Any]:
    if hasattr(v, "c"):
        return v.c - v.r, v.c + v.r
    return v, v


def _is(v: Any, target: int) -> bool:
    lo, hi = _interval(v)
    return bool(lo == target and hi == target)


def iterates_in_set(mt: Any, steps: int, j: int) -> bool:
    """Whether every x_k (k <= steps) is in the set of function j, given x_0 is: one
    state, output x = xi, and at every step x+ = x + lambda (s - x) by function j's one
    linear minimization call i at x (C_i = 1, D_i = 0) with lambda in [0, 1], every other
    call's column of B zero."""
    if mt.n != 1 or mt.output is not None or mt.E is None or not _is(mt.E[0, 0], 1):
        return False
    calls = [i for i in mt.lmo if mt.oracles[i] == j]
    if len(calls) != 1:
        return False
    i = calls[0]
    for k in range(steps):
        A, B, C, D = mt.step(k)
        lo, hi = _interval(B[0, i])
        if not (_is(A[0, 0], 1) and _is(C[i, 0], 1) and lo >= 0 and hi <= 1
                and all(_is(D[i, c], 0) for c in range(mt.p))
                and all(_is(B[0, c], 0) for c in range(mt.p) if c != i)):
            return False
    return True
