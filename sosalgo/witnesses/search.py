"""The floating-point search of a trajectory (:mod:`sosalgo.witnesses.trajectory`): a
Gram SDP solved with Clarabel, then rounded to an exact candidate that
:func:`sosalgo.witnesses.trajectory.check` accepts or not (nothing found here is a claim).

Phase 1 maximizes the smallest slack delta of every interpolation inequality with the
outputs normalized (sum_k |x_k|^2 = 1); phase 2 keeps delta >= delta*/2 and minimizes a
reweighted trace of H (Fazel's log-det heuristic) for a low-dimensional witness.
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction
from typing import Any

import numpy as np
import scipy.sparse as sps

from sosalgo.kernel.conic import svec, unsvec
from sosalgo.witnesses.trajectory import Layout, function_points, pair_scales

__all__ = ["gram_search", "rounded_factors"]

MIN_SLACK = 1e-7  # phase 1 optimum below this: no strictly feasible trajectory here
SAMPLES = 6  # scaled copies s^1..s^SAMPLES imposed in the search (all of them checked)


def _rows(lay: Layout, method: Any, samples: Sequence[float]) -> tuple[list, list]:
    """(Gram and value coefficients of every inequality, value indices fixed at 0)."""
    zero = np.zeros(lay.r)
    pts = function_points(method.oracles, len(method.functions), lay.y, lay.u, zero)
    rows, fixed = [], []
    for j, fn in enumerate(method.functions):
        if fn.cls.zero_values:
            fixed += [q.f for q in pts[j] if q.f is not None]
        for ineq in fn.cls.inequalities(fn.params):
            Q = np.asarray(ineq.Q, dtype=float)
            for a, b, sa, sb in pair_scales(pts[j], samples):
                R = np.array([sa * a.x, sb * b.x, sa * a.g, sb * b.g])
                fv: dict[int, float] = {}
                for q, w in ((a, ineq.alpha * sa * sa), (b, -ineq.alpha * sb * sb)):
                    if q.f is not None:
                        fv[q.f] = fv.get(q.f, 0.0) + w
                rows.append((R.T @ Q @ R, fv))
    return rows, fixed


def _solve(q: np.ndarray, A: np.ndarray, b: np.ndarray, cones: list) -> np.ndarray | None:
    from sosalgo.kernel.solvers import SolverStatus, clarabel_solve, quiet_settings, solver_status

    settings = quiet_settings()
    settings.max_iter = 200
    n = len(q)
    try:
        sol = clarabel_solve(sps.csc_matrix((n, n)), q, sps.csc_matrix(A), b, cones, settings)
    except Exception:  # noqa: BLE001 - a crash is no answer
        return None
    if solver_status(str(sol.status)) != SolverStatus.SOLVED:
        return None
    return np.array(sol.x)


def gram_search(lay: Layout, method: Any, nvals: int
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """(H, values) of a strictly feasible trajectory, or None (phase 1 slack too small or
    a solver status other than solved)."""
    r = lay.r
    nh = r * (r + 1) // 2
    nv = nh + nvals + 1  # svec(H), values, delta
    s = float(lay.s)
    samples = [s ** j for j in range(1, SAMPLES + 1)] if s < 1 else []
    rows, fixed = _rows(lay, method, samples)
    G = np.zeros((len(rows), nv))
    for i, (M, fv) in enumerate(rows):
        G[i, :nh] = -svec(M)
        for f, w in fv.items():
            G[i, nh + f] -= w
        G[i, -1] = 1.0
    norm = np.zeros((1, nv))
    norm[0, :nh] = svec(sum(np.outer(o, o) for o in lay.out))
    fix = np.zeros((len(fixed), nv))
    for i, f in enumerate(fixed):
        fix[i, nh + f] = 1.0
    cap = np.zeros((1, nv))
    cap[0, -1] = 1.0
    psd = np.hstack([-np.eye(nh), np.zeros((nh, nvals + 1))])
    A = np.vstack([norm, fix, G, cap, psd])
    b = np.concatenate([[1.0], np.zeros(len(fixed)), np.zeros(len(rows)), [1.0],
                        np.zeros(nh)])
    cones = [("zero", 1 + len(fixed)), ("nonneg", len(rows) + 1), ("psd", r)]
    q = np.zeros(nv)
    q[-1] = -1.0
    x = _solve(q, A, b, cones)
    if x is None or not x[-1] > MIN_SLACK:
        return None
    floor = np.zeros((1, nv))
    floor[0, -1] = -1.0
    A2 = np.vstack([norm, fix, G, cap, floor, psd])
    b2 = np.concatenate([b[: 2 + len(fixed) + len(rows)], [-0.5 * x[-1]], np.zeros(nh)])
    cones2 = [cones[0], ("nonneg", len(rows) + 2), cones[2]]
    W = np.eye(r)
    for _ in range(3):  # reweighted trace: pushes H towards low rank
        q2 = np.zeros(nv)
        q2[:nh] = svec(W)
        x2 = _solve(q2, A2, b2, cones2)
        if x2 is None:
            break
        x = x2
        H = unsvec(x[:nh], r)
        W = np.linalg.inv(H + 1e-3 * np.trace(H) / r * np.eye(r))
    return unsvec(x[:nh], r), x[nh: nh + nvals]


def rounded_factors(H: np.ndarray, values: np.ndarray, dims: Sequence[int],
                    scales: Sequence[int]):
    """Exact candidates (V integer r x d, values rational), smallest dimension first:
    V from the leading eigenvectors of H scaled so that max |V| = scale, the values
    scaled alike (the inequalities are homogeneous: x, g by c and f by c^2)."""
    w, Q = np.linalg.eigh(H)
    order = np.argsort(w)[::-1]
    w, Q = np.clip(w[order], 0, None), Q[:, order]
    for d in dims:
        if d > len(w) or not w[d - 1] > 0:
            break
        V = Q[:, :d] * np.sqrt(w[:d])
        big = float(np.abs(V).max())
        for scale in scales:
            c = scale / big
            Vq = np.array([[Fraction(round(v * c)) for v in row] for row in V], dtype=object)
            vq = [Fraction(round(v * c * c * 16), 16) for v in values]
            yield d, Vq, vq

