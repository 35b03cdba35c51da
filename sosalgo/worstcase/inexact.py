"""Inexact gradient and proximal calls in the PEP: relative error.

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
float SDP, in the exact proof (:func:`sosalgo.worstcase.exact.prove_at`, eps as written,
enclosed) and in the witness check (:mod:`sosalgo.worstcase.call_checks`: every exact call's
answer is the gradient of its point, every inexact one within eps of it, in ball
arithmetic).

On a proximal call (D_ii = -t != 0) the same entry is a relatively inexact proximal
step (PEPit's ``inexact_proximal_step`` with ``opt='PD_gapII'`` and the error bounded by
sigma^2 |y - v|^2 / 2, as in its relatively inexact proximal point algorithm): the call
at v = C_i xi + sum_{l<i} D_il u_l answers d and the method moves with it, y = v - t d;
g is a subgradient of f at y. With the error e = y - (v - t g) = t (g - d) the condition
|e| <= sigma |y - v| is

    sigma^2 |d~ + s_j*|^2 - |d~ - g~|^2 >= 0,

the same row with X = (d~ - g~, d~ + s_j*, 0, 0) / s: relative to the answer (the step
the prox made), not to the true subgradient.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["inexact_calls", "is_prox_call", "reference"]


def _label(i: int, k: int, p: int) -> str:
    return f"y{k}" if p == 1 else f"y{i + 1}_{k}"


def is_prox_call(mt: Any, i: int, k: int) -> bool:
    """Whether call i of step k is a proximal step (D_ii != 0), on floats or exact
    numbers."""
    v = mt.step(k)[3][i][i]
    return bool(v.c != 0 or v.r != 0) if hasattr(v, "c") else bool(v != 0)


def reference(mt: Any, i: int, pt: Any, U: list[np.ndarray],
              sstar: list[np.ndarray]) -> np.ndarray:
    """The row of the vector call i's error is relative to: ``relative_to``'s combination
    of the step's answers, else the answer d itself (a proximal call) or the true
    gradient g (a gradient call)."""
    if i in mt.error_refs:
        out = 0 * U[pt.t][i]
        for c, (row, j) in zip(mt.error_refs[i], zip(U[pt.t], mt.oracles, strict=True),
                               strict=True):
            if c:
                out = out + (row + sstar[j]) * c
        return out
    j = mt.oracles[i]
    return (U[pt.t][i] if is_prox_call(mt, i, pt.t) else pt.g) + sstar[j]


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
            twin = next((t for t, src in mt.twins.items() if src == i), None)
            if twin is None:
                c = len(cols)
                cols.append(f"g_{pt.label}/s")
                pt.g = eye[c]
            else:  # a call answers this point's true subgradient: its answer is it
                pt.g = U[pt.t][twin]
            eps = mt.errors[i]
            X = np.vstack([U[pt.t][i] - pt.g, reference(mt, i, pt, U, sstar), zero, zero])
            Qc = np.zeros((4, 4), dtype=object if mt.exact else float)
            Qc[0, 0] = -1
            Qc[1, 1] = eps * eps
            out.append((f"inexact:{pt.label}", X, Qc))
    return out

