"""Inexact gradient calls in the PEP: relative error.

A call with relative error eps (spec: ``oracles: [{function: f, relative_error: eps}]``)
answers some d with |d - g| <= eps |g|, g = grad f(y) the true gradient at the call's
point y. The method moves with d; the class inequalities hold on (y, g, f(y)). So the
PEP keeps d where the exact call has it (u~_k/s = K xi~_k + b_k, the trajectory
unchanged) and gives g a basis vector of its own (``g_<call>/s``, tilted: g~ = g - s_j*),
with one homogeneous quadratic constraint per call (PEPit's ``inexact_gradient_step``,
``notion='relative'``):

    eps^2 |g~ + s_j*|^2 - |d~ - g~|^2 >= 0        (d~ - g~ = d - g).

It is a row (label ``inexact:<call>``) after the class inequalities, X = (d~ - g~, g~ +
s_j*, 0, 0) / s and Qc = diag(-1, eps^2, 0, 0): its multiplier mu >= 0 enters S = tau I0
- M - sum lambda_k Q_k - sum mu_c X_c' Qc_c X_c like a pair's (no function values), in the
float SDP, in the exact proof (:func:`sosalgo.pep.exact.prove_at`, eps as written,
enclosed) and in the witness check (:func:`call_checks`: every exact call's answer is the
gradient of its point, every inexact one within eps of it, in ball arithmetic).
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np

__all__ = ["call_checks", "inexact_calls"]


def _label(i: int, k: int, p: int) -> str:
    return f"y{k}" if p == 1 else f"y{i + 1}_{k}"


def inexact_calls(mt: Any, pts: list[list[Any]], U: list[np.ndarray],
                  sstar: list[np.ndarray], cols: list[str], eye: np.ndarray
                  ) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Give each inexact call's point its own gradient column (appended to ``cols``) and
    return its constraint rows (label, X (4 x d), Qc (4 x 4)), on floats or exact numbers
    as ``mt`` is."""
    out: list[tuple[str, np.ndarray, np.ndarray]] = []
    if not mt.errors:
        return out
    p = mt.p
    zero = eye[0] * 0
    for j, fp in enumerate(pts):
        for pt in fp:
            if pt.t is None:
                continue
            i = next((i for i in range(p) if mt.oracles[i] == j
                      and _label(i, pt.t, p) == pt.label), None)
            if i is None or i not in mt.errors:
                continue
            c = len(cols)
            cols.append(f"g_{pt.label}/s")
            pt.g = eye[c]
            eps = mt.errors[i]
            X = np.vstack([U[pt.t][i] - pt.g, pt.g + sstar[j], zero, zero])
            Qc = np.zeros((4, 4), dtype=object if mt.exact else float)
            Qc[0, 0] = -1
            Qc[1, 1] = eps * eps
            out.append((f"inexact:{pt.label}", X, Qc))
    return out


def call_checks(doc: dict[str, Any], av: Any) -> tuple[int, int]:
    """(calls checked, calls not proven) of a witness: the answer d of every call
    (``calls``) against the gradient g its function has at the call's point: d = g
    exactly for an exact call, eps^2 |g|^2 - |d - g|^2 >= 0 in ball arithmetic for an
    inexact one (eps of the exact method)."""
    from sosalgo.pep.exact import ball

    mt = av.mt
    p = mt.p
    checked = bad = 0
    for k in range(int(doc["call_steps"])):
        for i, j in enumerate(mt.oracles):
            name = mt.functions[j][0]
            label = _label(i, k, p)
            pt = next((q for q in doc["functions"][name]["points"] if q["label"] == label),
                      None)
            checked += 1
            if pt is None:
                bad += 1
                continue
            d, g = doc["calls"][k][i], pt["g"]
            if i not in mt.errors:
                bad += any(Fraction(a) != Fraction(b) for a, b in zip(d, g, strict=True))
                continue
            e = ball(mt.errors[i])
            gb = [ball(v) for v in g]
            gap = [ball(a) - b for a, b in zip(d, gb, strict=True)]
            diff = sum((v * v for v in gap), ball(0))  # (arb 0) ** 2 is nan
            bad += not (e * e * sum((b * b for b in gb), ball(0)) - diff >= 0)
    if getattr(mt, "line_search", False):
        c, b = _line_search_checks(doc, mt)
        checked, bad = checked + c, bad + b
    return checked, bad


def _line_search_checks(doc: dict[str, Any], mt: Any) -> tuple[int, int]:
    """(steps checked, not proven): <g_{k+1}, d_k> = 0 exactly for every step (the
    point x_{k+1} = x_k + t_k d_k minimizes the convex f on the line: an exact line
    search), g_{k+1} the gradient of the point of call k + 1, d_k the answer of call k."""
    name = mt.functions[0][0]
    grads = {q["label"]: q["g"] for q in doc["functions"][name]["points"]}
    bad = 0
    N = int(doc["steps"])
    for k in range(N):
        g = grads.get(_label(0, k + 1, mt.p))
        d = doc["calls"][k][0]
        bad += g is None or sum((Fraction(a) * Fraction(b) for a, b in zip(g, d, strict=True)),
                                Fraction(0)) != 0
    return N, bad
