"""Trajectories that repeat up to a factor: xi_K = s xi_0 after K steps (s = rho^K).

s = 1 is a cycle (Goujaud, Taylor, Dieuleveut 2023: a feasibility SDP on the Gram matrix
of the cycle); s < 1 a self-similar trajectory, which with its copies scaled by s^j never
decays faster than rho^k. Every function of the method is placed at x* = 0 with
subgradient 0 and value 0 there (each f_j minimized at 0, so the sum is too), so the
deviations follow the method's own recursion.

Layout (in d = 1 templates, ``⊗ I_d`` implied): z = (xi_0, u_0, ..., u_{K-1}); the closure
xi_K - s xi_0 = 0 is solved for n pivot coordinates of z, leaving t (r = pK coordinates)
free: z = N t. The Gram matrix H of t makes every interpolation inequality linear
(alpha (f_a - f_b) + <R' Q R, H>, R the rows of x_a, x_b, g_a, g_b on t); a witness in
dimension d is t = V (r x d), V V' ≈ H. The same layout on exact balls (the method's exact
matrices, :func:`sosalgo.certificates.exact_composite.exact_oracle_method`) turns a rounded V into
the exact trajectory, which :func:`check` verifies.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
import scipy.linalg

from sosalgo.verify.exact import Ball
from sosalgo.witnesses.balls import solve_right

__all__ = ["Layout", "Point", "build_layout", "check", "function_points", "pair_scales",
           "quad_min_lower"]

RANK_TOL = 1e-9  # relative pivot size below which the closure is called rank deficient


@dataclass
class Layout:
    """Rows on t of every state, input, call point and output over one period."""

    K: int
    s: Any  # rho^K (float or Fraction)
    piv: list[int]
    xi: list[np.ndarray]  # K arrays n x r
    u: list[np.ndarray]  # K arrays p x r
    y: list[np.ndarray]  # K arrays p x r
    out: list[np.ndarray]  # K rows r

    @property
    def r(self) -> int:
        return self.u[0].shape[1]


@dataclass
class Point:
    """A point of one function: rows (or vectors) of x and g, and its value's index."""

    x: Any
    g: Any
    f: int | None  # index into the values (None: the optimum, value 0)


def _zeros(shape: tuple[int, ...], balls: bool) -> np.ndarray:
    return np.full(shape, Ball(0), dtype=object) if balls else np.zeros(shape)


def _eye(k: int, balls: bool) -> np.ndarray:
    out = _zeros((k, k), balls)
    for i in range(k):
        out[i, i] = Ball(1) if balls else 1.0
    return out


def pivots(closure: np.ndarray) -> list[int] | None:
    """n columns of the (float) closure that make it invertible (QR with pivoting)."""
    n = closure.shape[0]
    _, R, piv = scipy.linalg.qr(closure, pivoting=True)
    d = np.abs(np.diag(R))
    if len(d) < n or not d.size or d[n - 1] <= RANK_TOL * max(d[0], 1.0):
        return None
    return sorted(int(c) for c in piv[:n])


def build_layout(m: dict[str, np.ndarray], K: int, s: Any,
                 piv: Sequence[int] | None = None) -> Layout | None:
    """The layout of a period of K steps for matrices ``m`` (A, B, C, D, erow, drow: the
    output is erow xi + drow u), float or balls; None when the closure is singular."""
    A, B = m["A"], m["B"]
    balls = A.dtype == object
    n, p = A.shape[0], B.shape[1]
    nz = n + p * K
    U = []
    for k in range(K):
        Uk = _zeros((p, nz), balls)
        Uk[:, n + p * k: n + p * (k + 1)] = _eye(p, balls)
        U.append(Uk)
    Xi = [_zeros((n, nz), balls)]
    Xi[0][:, :n] = _eye(n, balls)
    for k in range(K):
        Xi.append(A @ Xi[k] + B @ U[k])
    closure = Xi[K] - Xi[0] * s
    if piv is None:
        fl = np.array([[float(b.c) for b in row] for row in closure]) if balls else closure
        piv = pivots(fl)
        if piv is None:
            return None
    free = [c for c in range(nz) if c not in piv]
    rhs = -closure[:, free]
    X = solve_right(closure[:, piv], rhs) if balls else np.linalg.solve(closure[:, piv], rhs)
    N = _zeros((nz, len(free)), balls)
    N[list(piv)] = X
    N[free] = _eye(len(free), balls)
    rows = [(Xi[k] @ N, U[k] @ N, (m["C"] @ Xi[k] + m["D"] @ U[k]) @ N,
             (m["erow"] @ Xi[k] + m["drow"] @ U[k]) @ N) for k in range(K)]
    return Layout(K, s, list(piv), *[[r[i] for r in rows] for i in range(4)])


def function_points(oracles: Sequence[int], J: int, xs: Sequence[Any],
                    gs: Sequence[Any], zero: Any) -> list[list[Point]]:
    """The points of every function: its calls at every step (x, g from ``xs[k][i]``,
    ``gs[k][i]``; value index k p + i), then the optimum (``zero``, value 0)."""
    p = len(oracles)
    pts: list[list[Point]] = [[] for _ in range(J)]
    for k in range(len(xs)):
        for i, j in enumerate(oracles):
            pts[j].append(Point(xs[k][i], gs[k][i], k * p + i))
    for j in range(J):
        pts[j].append(Point(zero, zero, None))
    return pts


def pair_scales(pts: Sequence[Point], samples: Sequence[float]
                ) -> Iterator[tuple[Point, Point, float, float]]:
    """Ordered pairs (a, b, scale of a, scale of b) the search imposes: distinct points at
    scale 1, and for a self-similar trajectory every two points of the period (the same
    one too) with one of them scaled by each sample of s^j (the optimum is fixed by
    scaling)."""
    for ia, a in enumerate(pts):
        for ib, b in enumerate(pts):
            if ia != ib:
                yield a, b, 1.0, 1.0
            if a.f is None or b.f is None:
                continue
            for sig in samples:
                yield a, b, 1.0, sig
                if ia != ib:
                    yield a, b, sig, 1.0


def _dot(u: np.ndarray, v: np.ndarray) -> Ball:
    return sum((x * y for x, y in zip(u, v, strict=True)), Ball(0))


def _value(alpha: Ball, Q: np.ndarray, a: Point, b: Point, sa: Any, sb: Any,
           values: Sequence[Fraction]) -> Ball:
    """alpha (f(sa a) - f(sb b)) + X'QX on X = (sa x_a, sb x_b, sa g_a, sb g_b) (balls)."""
    X = [a.x * sa, b.x * sb, a.g * sa, b.g * sb]
    fa = Fraction(0) if a.f is None else values[a.f]
    fb = Fraction(0) if b.f is None else values[b.f]
    out = alpha * (fa * sa * sa - fb * sb * sb)
    for i in range(4):
        for j in range(4):
            if not (Q[i, j].c == 0 and Q[i, j].r == 0):
                out = out + Q[i, j] * _dot(X[i], X[j])
    return out


def quad_min_lower(c: Sequence[Ball], s: Fraction) -> Fraction:
    """A lower bound of c0 + c1 σ + c2 σ² over σ in [0, s] (s <= 1), exact on centers
    minus the radii's bound r0 + r1 s + r2 s²."""
    c0, c1, c2 = (b.c for b in c)
    cands = [Fraction(0), s]
    if c2 > 0 and 0 < -c1 / (2 * c2) < s:
        cands.append(-c1 / (2 * c2))
    low = min(c0 + c1 * x + c2 * x * x for x in cands)
    return low - (c[0].r + c[1].r * s + c[2].r * s * s)


def _interval_ok(alpha: Ball, Q: np.ndarray, a: Point, b: Point, s: Fraction,
                 values: Sequence[Fraction], first: bool) -> bool:
    """The inequality of (σ a, b) (``first``) or (a, σ b) for every σ in [0, s]: a
    quadratic in σ, its coefficients from its values at σ = 0, 1, -1."""
    def v(x: int) -> Ball:
        return _value(alpha, Q, a, b, x, 1, values) if first else \
            _value(alpha, Q, a, b, 1, x, values)
    v0, v1, vm = v(0), v(1), v(-1)
    half = Fraction(1, 2)
    return quad_min_lower([v0, (v1 - vm) * half, (v1 + vm) * half - v0], s) >= 0


def check(method: Any, traj: dict[str, Any], ineqs: Sequence[Sequence[tuple[Ball, Any]]]
          ) -> tuple[bool, str]:
    """Exact check of a trajectory (balls; exact when every radius is 0): the recursion
    xi_{k+1} = A xi_k + B u_k, y_k = C xi_k + D u_k with xi_K = s xi_0; every inequality of
    every function's class between its points (and, for s < 1, against all their copies
    scaled by s^j, through σ in [0, s]); zero values where the class says so; and an
    output point other than x* = 0. Returns (passed, the first failure or "ok")."""
    xi, u, y, vals, s = traj["xi"], traj["u"], traj["y"], traj["values"], traj["s"]
    K = len(u)
    for k in range(K):
        nxt = xi[0] * s if k == K - 1 else xi[k + 1]
        res = np.concatenate([(nxt - (method.A @ xi[k] + method.B @ u[k])).ravel(),
                              (y[k] - (method.C @ xi[k] + method.D @ u[k])).ravel()])
        if any(not b.lo <= 0 <= b.hi for b in res):
            return False, f"recursion fails at step {k}"
    zero = np.full(u[0].shape[1], Ball(0), dtype=object)
    pts = function_points(method.oracles, len(method.functions), y, u, zero)
    for j, (name, cls, _) in enumerate(method.functions):
        if cls.zero_values and any(vals[q.f] != 0 for q in pts[j] if q.f is not None):
            return False, f"{name}: values must be 0"
        for alpha, Q in ineqs[j]:
            for ia, a in enumerate(pts[j]):
                for ib, b in enumerate(pts[j]):
                    if ia != ib and _value(alpha, Q, a, b, 1, 1, vals).lo < 0:
                        return False, f"{name}: interpolation fails between points {ia}, {ib}"
                    if s == 1 or a.f is None or b.f is None:
                        continue
                    if not all(_interval_ok(alpha, Q, a, b, s, vals, first)
                               for first in (False, True)):
                        return False, f"{name}: scaled copies fail between {ia}, {ib}"
    outs = [(method.E @ xi[k])[0] if method.output is None else y[k][method.output]
            for k in range(K)]
    if not any(not (b.lo <= 0 <= b.hi) for o in outs for b in o):
        return False, "every output point is x*"
    return True, "ok"
