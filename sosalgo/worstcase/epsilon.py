"""Epsilon-subgradient calls in the PEP (spec: ``oracles: [{function: f, epsilon: eps}]``).

The call at y answers some g in the eps-subdifferential of the convex f at y:

    f(z) >= f(y) + <g, z - y> - eps    for every z,

equivalently f(y) + f^*(g) - <g, y> <= eps. As PEPit's ``epsilon_subgradient_step`` the
PEP writes f^*(g) = <g, w> - f(w) with a free point w whose subgradient is g: the call's
answer g keeps its place in the trajectory (the method moves with it), w gets a basis
vector of its own (``w<call>-x*``), the point y a subgradient of its own (``g_<call>/s``,
for f(y) and the class inequalities there), and one row (label ``epsilon:<call>``)

    eps - f(y) + f(w) + <g, y - w> >= 0

joins the class inequalities (tilted values and subgradients: the linear tilt cancels).
Its constant eps makes the PEP inhomogeneous: the worst case is the one under initial <= 1
and the dual certificate's bound is t + sum_k lambda_k c_k, t >= 0 the initial condition's
multiplier (:attr:`sosalgo.worstcase.structure.PEPStructure.constants`, proven by
:func:`sosalgo.worstcase.exact.prove_at`). Every eps-subgradient oracle's answers satisfy
the row, so the value bounds the method. A term ``grad(P)`` at the call's point reads the
answer g (the eps-subgradient the method used), as PEPit's example bounds |g_t| <= M.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sosalgo.errors import InputError

__all__ = ["epsilon_calls", "float_epsilons"]


def float_epsilons(spec: Any, om: Any, kappa: float | None, mt: Any) -> dict[int, float]:
    """The eps of each epsilon-subgradient call at the bound parameters (InputError naming
    ``oracles[i].epsilon`` when it is not a finite number >= 0 or the call is a proximal
    one)."""
    import math

    from sosalgo.kernel.expr.tree import evaluate
    from sosalgo.worstcase.inexact import is_prox_call

    out = {}
    env = {"m": om.m, "L": om.L, "kappa": math.nan if kappa is None else kappa,
           **(getattr(om, "params", None) or {})}
    for i, expr in (getattr(spec, "epsilon", None) or {}).items():
        where = f"{spec.source}: oracles[{i}].epsilon"
        try:
            eps = float(evaluate(expr, env))
        except (ValueError, ZeroDivisionError, OverflowError) as exc:
            raise InputError(f"{where}: {exc}") from None
        if not math.isfinite(eps) or eps < 0:
            raise InputError(f"{where}: {eps:g}: an accuracy is a finite number >= 0")
        if is_prox_call(mt, i, 0):
            raise InputError(f"{where}: an epsilon-subgradient call is a gradient call "
                             "(D_ii = 0), not a proximal step")
        out[i] = eps
    return out


def _label(i: int, k: int, p: int) -> str:
    return f"y{k}" if p == 1 else f"y{i + 1}_{k}"


def epsilon_calls(mt: Any, pts: list[list[Any]], cols: list[str], eye: np.ndarray,
                  nF: int, point: Any) -> tuple[list[tuple[str, np.ndarray, np.ndarray]],
                                                dict[int, dict[int, Any]], dict[int, Any],
                                                int]:
    """Split every epsilon call's point into (y, its own subgradient) and (w, the answer)
    and return (rows (label, X, Qc), values by row index, constants by row index, nF).
    ``point(label, x, g, f)``: a new point (:class:`sosalgo.worstcase.structure.PEPPoint`)."""
    rows: list[tuple[str, np.ndarray, np.ndarray]] = []
    values: dict[int, dict[int, Any]] = {}
    consts: dict[int, Any] = {}
    if not mt.epsilons:
        return rows, values, consts, nF
    zero = eye[0] * 0
    half = mt.s / 2
    for j, fp in enumerate(pts):
        for pt in list(fp):
            i = next((i for i in mt.epsilons if mt.oracles[i] == j and pt.t is not None
                      and _label(i, pt.t, mt.p) == pt.label), None)
            if i is None:
                continue
            c = len(cols)
            cols.append(f"g_{pt.label}/s")
            cols.append(f"w{pt.label}-x*")
            pt.answer, pt.g = pt.g, eye[c]
            w = point(f"w{pt.label}", eye[c + 1], pt.answer, nF)
            fp.append(w)
            nF += 1
            Qc = np.zeros((4, 4), dtype=object if mt.exact else float)
            Qc[0, 1] = Qc[1, 0] = half
            values[len(rows)] = {pt.f: -mt.s, w.f: mt.s}
            consts[len(rows)] = mt.epsilons[i]
            rows.append((f"epsilon:{pt.label}", np.vstack([pt.answer, pt.x - w.x, zero, zero]),
                         Qc))
    return rows, values, consts, nF
