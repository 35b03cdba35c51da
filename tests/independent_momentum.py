"""An independent judge for sublinear constants, noise sensitivity, PEP bounds and rate
brackets: numpy, scipy and fractions only, no sosalgo code.

The methods judged are gradient methods with momentum on one function f,

    y_k = x_k + eta (x_k - x_{k-1}),   x_{k+1} = x_k - h grad f(y_k) + beta (x_k - x_{k-1}),

with state xi_k = (x_{k-1}, x_k), output x_k, started at rest (x_{-1} = x_0) or from a
linear start (x0 + c g0, x0 + c' g0) (a spec's ``initial_state:``), and with
exact rational parameters (h L, beta, eta, m, L). Everything here gives LOWER bounds on
worst cases (a bad instance is a proof that the worst case is at least its value), or
re-checks a claimed witness from its numbers:

- :func:`sublinear_floor`: max over k <= kmax of k (f(x_k) - f*) / |x_0 - x*|^2 on 1-D
  quadratics and Huber functions of F(0, L);
- :func:`gamma_quadratic`: the noise sensitivity on quadratics (q/2)|x|^2, q in [m, L]
  (discrete Lyapunov equation per q), and :func:`noise_monte_carlo` on a Huber-type f;
- :func:`pep_floor`: measure(x_N) / |x_0 - x*|^2 on quadratics and Huber-type functions;
  :func:`gd_tau_convex`, :func:`gd_tau_strong`, :func:`gd_tau_steps`: gradient
  descent's exact worst cases (the last with a different first step);
- :func:`max_radius`: the largest spectral radius of the closed loop over q in [m, L];
  :func:`max_visible_radius`: the same over the modes the output sees (Kalman
  observability, for any (A, B, C, E) with D = 0);
- :func:`check_cycle`, :func:`check_pep_witness`: a claimed cycle / worst-case trajectory
  re-checked with the recursion and the F(m, L) interpolation inequality in fractions.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from scipy.linalg import solve_discrete_lyapunov
from scipy.optimize import minimize_scalar

Vec = tuple[Fraction, ...]


@dataclass(frozen=True)
class Momentum:
    """The method with step h = hL / L; every number an exact rational."""

    hL: Fraction
    beta: Fraction
    eta: Fraction
    m: Fraction
    L: Fraction

    @property
    def h(self) -> Fraction:
        return self.hL / self.L

    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, E) as floats, state (x_{k-1}, x_k)."""
        b, e, h = float(self.beta), float(self.eta), float(self.h)
        return (np.array([[0.0, 1.0], [-b, 1.0 + b]]), np.array([[0.0], [-h]]),
                np.array([[-e, 1.0 + e]]), np.array([[0.0, 1.0]]))

    def loop(self, q: float) -> np.ndarray:
        """Closed loop on f = (q/2) x^2: xi+ = (A + q B C) xi."""
        A, B, C, _ = self.matrices()
        return A + q * B @ C


# ------------------------------------------------------------------ test functions


def huber(x: np.ndarray, m: float, L: float, delta: np.ndarray | float,
          flip: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(f, f') of a Huber-type function of F(m, L), minimum 0 at 0, kink at |x| = delta.

    flip False: f = m x^2/2 + (L - m) H(x), curvature L inside, m outside;
    flip True:  f = L x^2/2 - (L - m) H(x), curvature m inside, L outside;
    H(x) = x^2/2 (|x| <= delta), delta |x| - delta^2/2 (else), H' = clip(x, -delta, delta).
    """
    ax = np.abs(x)
    H = np.where(ax <= delta, x * x / 2, delta * ax - delta * delta / 2)
    dH = np.clip(x, -delta, delta)
    if flip:
        return L * x * x / 2 - (L - m) * H, L * x - (L - m) * dH
    return m * x * x / 2 + (L - m) * H, m * x + (L - m) * dH


Start = tuple[Fraction, Fraction]  # (c_prev, c_cur): x_{-1} = x0 + c_prev g0, x_0 = x0 + c_cur g0


def run(meth: Momentum, grad: Callable[[np.ndarray], np.ndarray], x0: np.ndarray,
        steps: int, start: Start | None = None) -> np.ndarray:
    """x_0 .. x_steps (rows) of the method for a batch of 1-D problems: from rest
    (x_{-1} = x_0 = x0), or from the linear start (x0 + c_prev g0, x0 + c_cur g0),
    g0 = grad(x0) (a spec's ``initial_state: [x0 + c_prev*g0, x0 + c_cur*g0]``)."""
    h, b, e = float(meth.h), float(meth.beta), float(meth.eta)
    xs = np.empty((steps + 1, *np.shape(x0)))
    prev = x = np.array(x0, dtype=float)
    if start is not None:
        g0 = grad(x)
        prev, x = x + float(start[0]) * g0, x + float(start[1]) * g0
    xs[0] = x
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(steps):
            x, prev = x - h * grad(x + e * (x - prev)) + b * (x - prev), x
            xs[k + 1] = x
    return xs


# ------------------------------------------------------------------ 1. sublinear


def sublinear_floor(meth: Momentum, kmax: int = 2000, points: int = 201
                    ) -> tuple[float, str]:
    """max_{1 <= k <= kmax} k (f(x_k) - f*) / |x_0 - x*|^2 over f = (q/2) x^2, q in [0, L],
    and f = L H_delta (Huber, delta on a log grid); x_0 = 1, x* = 0 (unique). Returns the
    value (inf when some trajectory blows up) and the instance."""
    L = float(meth.L)
    q = np.linspace(0.0, L, points)
    d = np.geomspace(1e-5, 1.0, points)
    xq = run(meth, lambda y: q * y, np.ones(points), kmax)
    xh = run(meth, lambda y: L * np.clip(y, -d, d), np.ones(points), kmax)
    k = np.arange(kmax + 1)[:, None]
    with np.errstate(over="ignore", invalid="ignore"):
        vq = k * q * xq * xq / 2
        vh = k * L * np.where(np.abs(xh) <= d, xh * xh / 2, d * np.abs(xh) - d * d / 2)
    vq, vh = np.nan_to_num(vq, nan=np.inf), np.nan_to_num(vh, nan=np.inf)
    iq, ih = np.unravel_index(np.argmax(vq), vq.shape), np.unravel_index(np.argmax(vh), vh.shape)
    if vq[iq] >= vh[ih]:
        return float(vq[iq]), f"quadratic q = {q[iq[1]]:.6g}, k = {iq[0]}"
    return float(vh[ih]), f"Huber delta = {d[ih[1]]:.6g}, k = {ih[0]}"


# ------------------------------------------------------------------ 2. noise


def gamma2_at(meth: Momentum, q: float) -> float:
    """gamma_q^2 = E X E' with X = A_q X A_q' + B B' (inf when A_q is not stable)."""
    Aq = meth.loop(q)
    if max(abs(np.linalg.eigvals(Aq))) >= 1.0:
        return math.inf
    _, B, _, E = meth.matrices()
    X = solve_discrete_lyapunov(Aq, B @ B.T)
    return float((E @ X @ E.T)[0, 0])


def gamma_quadratic(meth: Momentum, points: int = 2001) -> tuple[float, float]:
    """(max over q in [m, L] of gamma_q, the worst q): a grid, then a bounded search
    around the best grid point."""
    m, L = float(meth.m), float(meth.L)
    qs = np.linspace(m, L, points)
    vals = np.array([gamma2_at(meth, q) for q in qs])
    i = int(np.argmax(vals))
    if not math.isfinite(vals[i]):
        return math.inf, float(qs[i])
    lo, hi = qs[max(i - 1, 0)], qs[min(i + 1, points - 1)]
    best, qb = vals[i], qs[i]
    if hi > lo:
        r = minimize_scalar(lambda q: -gamma2_at(meth, q), bounds=(lo, hi), method="bounded",
                            options={"xatol": 1e-12 * max(1.0, L)})
        if math.isfinite(r.fun) and -r.fun > best:
            best, qb = -r.fun, float(r.x)
    return math.sqrt(best), float(qb)


def noise_monte_carlo(meth: Momentum, delta: float, flip: bool, sigma: float,
                      chains: int = 64, dim: int = 16, steps: int = 3000, burn: int = 1000,
                      seed: int = 0) -> tuple[float, float]:
    """(mean, standard error) of the long-run average of |x_k - x*|^2 / (d sigma^2) for the
    method with u_k = grad f(y_k) + w_k, w_k ~ N(0, sigma^2 I), f = sum of d Huber-type
    functions, started at x* = 0; the tail k >= burn is averaged per chain."""
    rng = np.random.default_rng(seed)
    m, L = float(meth.m), float(meth.L)
    h, b, e = float(meth.h), float(meth.beta), float(meth.eta)
    prev = x = np.zeros((chains, dim))
    acc = np.zeros(chains)
    for k in range(steps):
        g = huber(x + e * (x - prev), m, L, delta, flip)[1]
        x, prev = x - h * (g + sigma * rng.standard_normal(x.shape)) + b * (x - prev), x
        if k + 1 >= burn:
            acc += (x * x).sum(axis=1)
    per = acc / ((steps - burn + 1) * dim * sigma * sigma)
    return float(per.mean()), float(per.std(ddof=1) / math.sqrt(chains))


def noise_monte_carlo_late(meth: Momentum, delta: float, flip: bool, sigma: float,
                           chains: int = 400, dim: int = 4, steps: int = 1500,
                           checkpoints: tuple[int, ...] = (500, 750, 1000, 1250, 1499),
                           seed: int = 0) -> tuple[float, float]:
    """(largest chain mean of |x_k - x*|^2 / (d sigma^2) over the ``checkpoints`` k, its
    standard error): E|x_k - x*|^2 at single late times (not a time average), for the
    limsup; same method, noise and Huber-type functions as :func:`noise_monte_carlo`."""
    rng = np.random.default_rng(seed)
    m, L = float(meth.m), float(meth.L)
    h, b, e = float(meth.h), float(meth.beta), float(meth.eta)
    prev = x = np.zeros((chains, dim))
    best, best_se = -math.inf, 0.0
    for k in range(steps):
        g = huber(x + e * (x - prev), m, L, delta, flip)[1]
        x, prev = x - h * (g + sigma * rng.standard_normal(x.shape)) + b * (x - prev), x
        if k in checkpoints:
            v = (x * x).sum(axis=1) / (dim * sigma ** 2)
            if v.mean() > best:
                best, best_se = float(v.mean()), float(v.std(ddof=1) / math.sqrt(chains))
    return best, best_se


# ------------------------------------------------------------------ 3. PEP


def gd_tau_convex(L: float, N: int) -> float:
    """Gradient descent, h = 1/L, L-smooth convex: sup (f(x_N) - f*)/|x_0 - x*|^2 =
    L/(4N + 2) (Drori and Teboulle 2014, tight)."""
    return L / (4 * N + 2)


def gd_tau_strong(h: float, m: float, L: float, N: int) -> float:
    """Gradient descent on F(m, L): sup |x_N - x*|^2 / |x_0 - x*|^2 = max(|1 - hm|,
    |1 - hL|)^(2N) (attained on a quadratic; the contraction of x - h grad f is exactly
    that factor)."""
    return max(abs(1 - h * m), abs(1 - h * L)) ** (2 * N)


def gd_tau_steps(hs: Sequence[Fraction], m: Fraction, L: Fraction
                 ) -> tuple[Fraction, Fraction]:
    """Gradient descent with steps h_1 .. h_K on F(m, L), dist/dist: (the larger of the
    quadratics q = m, L, prod_k (1 - h_k q)^2, a bad instance; prod_k max(|1 - h_k m|,
    |1 - h_k L|)^2, the product of the steps' Lipschitz constants, an upper bound), exact;
    equal when every step is on the same side of 2/(m + L)."""
    lo = max(math.prod(((1 - h * q) ** 2 for h in hs), start=Fraction(1)) for q in (m, L))
    hi = math.prod((max(abs(1 - h * m), abs(1 - h * L)) ** 2 for h in hs), start=Fraction(1))
    return lo, hi


def pep_floor(meth: Momentum, N: int, measure: str, points: int = 401,
              start: Start | None = None) -> tuple[float, str]:
    """max measure(x_N) / |x0 - x*|^2 over quadratics (q/2) x^2, q in [m, L], and both
    Huber-type functions of F(m, L) (kink on a grid), x0 = 1, x* = 0, from rest or from
    ``start`` (:func:`run`); measure "f" (f(x_N) - f*) or "dist" (|x_N - x*|^2)."""
    m, L = float(meth.m), float(meth.L)
    q = np.linspace(m, L, points)
    xq = run(meth, lambda y: q * y, np.ones(points), N, start)[-1]
    best = [(q * xq * xq / 2 if measure == "f" else xq * xq, "quadratic q", q)]
    d = np.geomspace(1e-4, 1.0, points)
    for flip in ((False, True) if m > 0 else (False,)):
        xh = run(meth, lambda y, fl=flip: huber(y, m, L, d, fl)[1], np.ones(points), N,
                 start)[-1]
        val = huber(xh, m, L, d, flip)[0] if measure == "f" else xh * xh
        best.append((val, f"Huber (flip {flip}) delta", d))
    v, what, grid = max(best, key=lambda t: float(np.nanmax(t[0])))
    i = int(np.nanargmax(v))
    return float(v[i]), f"{what} = {grid[i]:.6g}"


# ------------------------------------------------------------------ 4. brackets


def radii(meth: Momentum, qs: np.ndarray) -> np.ndarray:
    """Spectral radius of the closed loop A + q B C for each q (stacked 2 x 2 eigvals)."""
    A, B, C, _ = meth.matrices()
    loops = A[None] + np.asarray(qs, dtype=float)[:, None, None] * (B @ C)[None]
    return np.abs(np.linalg.eigvals(loops)).max(axis=1)


def radius(meth: Momentum, q: float) -> float:
    return float(radii(meth, np.array([q]))[0])


def max_radius(meth: Momentum, points: int = 20001) -> tuple[float, float]:
    """(max over q in [m, L] of the closed loop's spectral radius, the q): a fine grid,
    then bounded searches around the five best grid points."""
    m, L = float(meth.m), float(meth.L)
    qs = np.linspace(m, L, points)
    rs = radii(meth, qs)
    best, qb = float(rs.max()), float(qs[int(rs.argmax())])
    for i in np.argsort(rs)[-5:]:
        lo, hi = qs[max(i - 1, 0)], qs[min(i + 1, points - 1)]
        r = minimize_scalar(lambda q: -radius(meth, q), bounds=(lo, hi), method="bounded",
                            options={"xatol": 1e-13 * max(1.0, L)})
        if -r.fun > best:
            best, qb = float(-r.fun), float(r.x)
    return best, qb


def observable(meth: Momentum, q: Fraction) -> bool:
    """The output x_k = E xi_k sees every mode of the loop at q: det [E; E A_q] != 0,
    exactly (E = (0, 1), so this is the (2, 1) entry of A_q = -beta + q h eta)."""
    return -meth.beta + q * meth.h * meth.eta != 0


# ------------------------------------------------------------------ exact re-checks


def frac(v: str | int | float) -> Fraction:
    """A JSON number: "p/q", an integer or a float (its exact binary value)."""
    return Fraction(v) if isinstance(v, str | int) else Fraction(float(v))


def vec(v: Sequence[str | int | float]) -> Vec:
    return tuple(frac(t) for t in v)


def dot(a: Vec, b: Vec) -> Fraction:
    return sum((s * t for s, t in zip(a, b, strict=True)), Fraction(0))


def sub(a: Vec, b: Vec) -> Vec:
    return tuple(s - t for s, t in zip(a, b, strict=True))


def interpolation_gap(i: tuple[Vec, Vec, Fraction], j: tuple[Vec, Vec, Fraction],
                      m: Fraction, L: Fraction) -> Fraction:
    """f_i - f_j - <g_j, x_i - x_j> - (|g_i - g_j|^2/L + m |x_i - x_j|^2
    - 2 (m/L) <g_i - g_j, x_i - x_j>) / (2 (1 - m/L)): >= 0 for every pair of points of a
    function of F(m, L) (Taylor, Hendrickx, Glineur 2017, Theorem 4), and conversely."""
    (xi, gi, fi), (xj, gj, fj) = i, j
    dx, dg = sub(xi, xj), sub(gi, gj)
    curv = (dot(dg, dg) / L + m * dot(dx, dx) - 2 * (m / L) * dot(dg, dx)) / (2 * (1 - m / L))
    return fi - fj - dot(gj, dx) - curv


def interpolable(pts: Sequence[tuple[Vec, Vec, Fraction]], m: Fraction,
                 L: Fraction) -> str | None:
    """None when every ordered pair satisfies the inequality, else the first failure."""
    for a, pa in enumerate(pts):
        for b, pb in enumerate(pts):
            if a != b and interpolation_gap(pa, pb, m, L) < 0:
                return f"interpolation inequality ({a}, {b}) fails"
    return None


def check_cycle(meth: Momentum, cycle: Mapping) -> str | None:
    """Re-check a cycle (JSON of ``analyze``): the recursion on its states, y_k, closure
    xi_K = xi_0, every inequality between its points and x* = 0 (g = 0, f = 0), and some
    x_k != 0. None when it holds, else the reason."""
    K = int(cycle["length"])
    states = [(vec(s[0]), vec(s[1])) for s in cycle["states"]]
    ys, gs = [vec(p) for p in cycle["points"]], [vec(g) for g in cycle["gradients"]]
    fs = [frac(v) for v in cycle["values"]]
    if not (len(states) == len(ys) == len(gs) == len(fs) == K) or str(cycle["factor"]) != "1":
        return "malformed cycle"
    h, b, e = meth.h, meth.beta, meth.eta
    for k, (xp, x) in enumerate(states):
        y = tuple(xx + e * (xx - pp) for pp, xx in zip(xp, x, strict=True))
        nxt = tuple(xx - h * g + b * (xx - pp) for pp, xx, g in zip(xp, x, gs[k], strict=True))
        if y != ys[k]:
            return f"y_{k} is not x_k + eta (x_k - x_(k-1))"
        if states[(k + 1) % K] != (x, nxt):
            return f"step {k} does not follow the recursion (or the cycle does not close)"
    zero = tuple(Fraction(0) for _ in ys[0])
    pts = [*zip(ys, gs, fs, strict=True), (zero, zero, Fraction(0))]
    bad = interpolable(pts, meth.m, meth.L)
    if bad:
        return bad
    if all(x == zero for _, x in states):
        return "every iterate is x*"
    return None


def check_pep_witness(meth: Momentum, w: Mapping, measure: str, start: Start | None = None
                      ) -> tuple[Fraction | None, str]:
    """Recompute a PEP witness of the method (one function, x* = 0, f* = 0): iterates from
    its x0 (from rest, or from ``start`` with g0 the subgradient given at the point x0)
    and gradients in fractions, every inequality between its points (the calls y_k, x0,
    the evaluation point x_N, x*), and measure(x_N)/|x0|^2. Returns (the exact ratio, "")
    when it holds, else (None, the reason). The document's own "x" fields are not read."""
    (fn,) = w["functions"].values()
    x0 = vec(w["x0"])
    grads = [vec(c[0]) for c in w["calls"]]
    given = {p["label"]: vec(p["g"]) for p in fn["points"]}
    N = len(grads)
    prev, x, ys = x0, x0, []
    if start is not None:
        g0 = given.get("x0", grads[0])  # no point x0: y_0 must be x0 (checked below)
        prev = tuple(a + start[0] * g for a, g in zip(x0, g0, strict=True))
        x = tuple(a + start[1] * g for a, g in zip(x0, g0, strict=True))
    for g in grads:
        ys.append(tuple(xx + meth.eta * (xx - pp) for pp, xx in zip(prev, x, strict=True)))
        x, prev = tuple(xx - meth.h * gg + meth.beta * (xx - pp)
                        for pp, xx, gg in zip(prev, x, g, strict=True)), x
    if start is not None and "x0" not in given and ys[0] != x0:
        return None, "no point x0 with its gradient g0, and y0 != x0"
    where = {f"y{k}": ys[k] for k in range(N)} | {f"x{N}": x} | (
        {"x0": x0} if start is not None else {})
    pts, fx = [], None
    for p in fn["points"]:
        if p["label"] not in where:
            return None, f"unknown point {p['label']}"
        pts.append((where[p["label"]], vec(p["g"]), frac(p["h"])))
        if p["label"] == f"x{N}":
            fx = pts[-1][2]
    if any(given.get(f"y{k}") != grads[k] for k in range(N)):
        return None, "the points are not the calls (labels y0 .. y(N-1), their gradients)"
    zero = tuple(Fraction(0) for _ in x0)
    bad = interpolable([*pts, (zero, vec(fn["optimal_subgradient"]), Fraction(0))],
                       meth.m, meth.L)
    if bad:
        return None, bad
    top = fx if measure == "f" else dot(x, x)
    if top is None:
        return None, "no value at x_N"
    return top / dot(x0, x0), ""


# ------------------------------------------------------------------ observability


def visible_radius(A: np.ndarray, B: np.ndarray, C: np.ndarray, E: np.ndarray, q: float,
                   tol: float = 1e-9) -> tuple[float, float, int]:
    """(spectral radius of the modes of M = A + q B C that the output E sees, radius of
    all modes, rank of the observability matrix O = [E; E M; ...; E M^(n-1)]). The seen
    modes are the eigenvalues of M on the quotient by ker O (A-invariant): with Q an
    orthonormal basis of the row space of O (M'-invariant), eig(Q' M Q) (Kalman). Rank by
    singular values > tol * largest: a near-deficient O counts as full (all modes), which
    only raises this value."""
    M = A + q * B @ C
    n = M.shape[0]
    rows, r = [], E
    for _ in range(n):
        rows.append(r)
        r = r @ M
    obs = np.vstack(rows)
    _, s, vt = np.linalg.svd(obs)
    k = int((s > tol * max(s[0], 1e-300)).sum())
    full = float(np.abs(np.linalg.eigvals(M)).max())
    if k == n:
        return full, full, k
    if k == 0:
        return 0.0, full, 0
    Q = vt[:k].T
    return float(np.abs(np.linalg.eigvals(Q.T @ M @ Q)).max()), full, k


def max_visible_radius(A: np.ndarray, B: np.ndarray, C: np.ndarray, E: np.ndarray,
                       m: float, L: float, points: int = 4001) -> tuple[float, float]:
    """(max over q in [m, L] of :func:`visible_radius`, the q): a grid, then bounded
    searches around the five best grid points."""
    qs = np.linspace(m, L, points)
    rs = np.array([visible_radius(A, B, C, E, q)[0] for q in qs])
    best, qb = float(rs.max()), float(qs[int(rs.argmax())])
    for i in np.argsort(rs)[-5:]:
        lo, hi = qs[max(i - 1, 0)], qs[min(i + 1, points - 1)]
        r = minimize_scalar(lambda q: -visible_radius(A, B, C, E, q)[0], bounds=(lo, hi),
                            method="bounded", options={"xatol": 1e-13 * max(1.0, L)})
        if -r.fun > best:
            best, qb = float(-r.fun), float(r.x)
    return best, qb
