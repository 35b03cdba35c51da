"""The exact noise sensitivity on quadratics (docs/noise.md).

On f = (q/2)|x - x*|^2 the noisy method is linear: xi_{k+1} - xi* = A_q (xi_k - xi*) + B w_k
with A_q = A + q B C. When A_q is Schur stable the covariance of xi_k - xi* tends (per
coordinate, sigma = 1) to the solution X_q of the discrete Lyapunov equation
X = A_q X A_q' + B B', so gamma_q^2 = E X_q E'; gamma_q = inf when A_q is not stable.
The sensitivity on the quadratics of F(m, L) is the largest gamma_q over q in [m, L]
(a function of q that is smooth where finite): a grid, then a bounded scalar search
around the best grid point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["QuadraticNoise", "noise_quadratic", "quadratic_gamma2"]


@dataclass(frozen=True)
class QuadraticNoise:
    """The largest sensitivity over the quadratics of F(m, L) and where it is attained."""

    gamma: float  # inf when some quadratic makes the method unstable
    q: float  # the worst curvature

    def to_dict(self) -> dict[str, Any]:
        return {"gamma": self.gamma, "q": self.q}


def quadratic_gamma2(A: np.ndarray, B: np.ndarray, C: np.ndarray, E: np.ndarray,
                     qs: np.ndarray) -> np.ndarray:
    """gamma_q^2 = E X_q E' for each curvature in ``qs`` (inf where A + qBC is not stable),
    from vec(X) = (I - A_q ⊗ A_q)^{-1} vec(B B')."""
    qs = np.atleast_1d(np.asarray(qs, dtype=float))
    n = A.shape[0]
    Aq = A[None] + qs[:, None, None] * (B @ C)[None]
    radius = np.max(np.abs(np.linalg.eigvals(Aq)), axis=1)
    K = np.einsum("qij,qkl->qikjl", Aq, Aq).reshape(len(qs), n * n, n * n)
    rhs = np.broadcast_to((B @ B.T).reshape(n * n), (len(qs), n * n))
    out = np.full(len(qs), math.inf)
    ok = radius < 1.0
    if np.any(ok):
        X = np.linalg.solve(np.eye(n * n)[None] - K[ok], rhs[ok][..., None])[..., 0]
        X = X.reshape(-1, n, n)
        out[ok] = np.einsum("i,qij,j->q", E[0], X, E[0])
    return out


def noise_quadratic(alg: Any, points: int = 201) -> QuadraticNoise:
    """max over q in [m, L] of gamma_q (grid of ``points``, then a bounded search)."""
    from scipy.optimize import minimize_scalar

    A, B, C, E = (np.asarray(M, dtype=float) for M in (alg.A, alg.B, alg.C, alg.E))
    m, L = float(alg.m), float(alg.L)
    grid = np.linspace(m, L, points)
    vals = quadratic_gamma2(A, B, C, E, grid)
    k = int(np.argmax(vals))
    if not math.isfinite(vals[k]):
        return QuadraticNoise(math.inf, float(grid[k]))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, points - 1)]
    best_q, best = float(grid[k]), float(vals[k])
    res = minimize_scalar(lambda q: -float(quadratic_gamma2(A, B, C, E, [q])[0]),
                          bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-12 * max(L, 1.0)})
    if res.success and math.isfinite(res.fun) and -res.fun > best:
        best_q, best = float(res.x), float(-res.fun)
    return QuadraticNoise(math.sqrt(best), best_q)
