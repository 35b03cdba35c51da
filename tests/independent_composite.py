"""An independent judge for composite / proximal rates: no sosalgo code.

Given a method as plain matrices, ``xi+ = A xi + B u``, ``y = C xi + D u`` (D lower
triangular; ``D_ii = -t < 0`` makes call i the proximal step ``y_i = prox_{t f_j}(v_i)``),
``u_i`` a (sub)gradient of the function ``oracles[i]`` at ``y_i``, output ``x = E xi`` or
the point of one call, it gives LOWER bounds on the worst-case linear rate rho
(``measure(x_k) <= rho^(2k) V_0``) over the problem's function classes, by bad instances:

- :func:`quadratic_bound`: every function a quadratic of its class, ``f_j = x'Q_j x/2``
  (1-D curvatures on a grid, and random 2-D pairs with non-commuting eigenvectors). A
  gradient call is ``u = Q v``, a proximal step ``u = Q (I + tQ)^{-1} v`` (from
  ``prox_{t q|.|^2/2}(v) = v/(1 + tq)``), with ``q = inf`` (the indicator of ``{0}``, or
  of a line in 2-D) giving ``u = v/t`` for functions queried only by proximal steps. The
  bound is the largest ``|lambda|`` of the closed loop over the modes the measure sees
  (Hautus test), since ``measure(x_k)`` then decays like ``|lambda|^(2k)``.
- :func:`simulate_decay`: a trajectory on a nonquadratic separable instance (Huber plus
  quadratic, l1, box indicator; closed-form proxes and minimizer) and its observed decay
  factor of the measure per step in the tail: a lower bound on rho^2 only in the limit,
  a sanity check with slack.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

INF = math.inf
HAUTUS_TOL = 1e-9  # relative singular value below which a mode counts as unobservable


@dataclass(frozen=True)
class Fn:
    """One function of the problem: ``cls`` in smooth_strongly_convex {m, L}, convex,
    strongly_convex {m}, indicator."""

    cls: str
    m: float = 0.0
    L: float = INF


@dataclass(frozen=True)
class Method:
    """A composite method as matrices; ``output`` is E (1 x n) or the index of a call."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    output: np.ndarray | int
    oracles: tuple[int, ...]
    functions: tuple[Fn, ...]
    measure: str = "distance"
    steps: tuple[float, ...] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", tuple(float(-d) for d in np.diag(self.D)))


# ---------------------------------------------------------------- quadratics


def curvature_grid(fn: Fn, prox_only: bool, points: int = 15) -> np.ndarray:
    """Curvatures q with ``q|x|^2/2`` in the class (inf: the indicator of {0})."""
    if fn.cls == "smooth_strongly_convex":
        grid = np.concatenate([np.linspace(fn.m, fn.L, points),
                               np.geomspace(max(fn.m, 1e-9), fn.L, points)])
    elif fn.cls == "convex":
        grid = np.concatenate([[0.0], np.geomspace(1e-3, 1e6, points)])
    elif fn.cls == "strongly_convex":
        grid = fn.m * np.geomspace(1.0, 1e6, points)
    elif fn.cls == "indicator":
        grid = np.array([0.0])
    else:
        raise ValueError(f"unknown class {fn.cls}")
    if (prox_only and fn.cls != "smooth_strongly_convex") or fn.cls == "indicator":
        grid = np.append(grid, INF)  # a nonsmooth class queried only by proximal steps
    return np.unique(grid)


def call_gain(q: np.ndarray, t: float) -> np.ndarray:
    """u = gain * v for eigen-curvatures q: q (gradient call) or q/(1 + tq) (proximal)."""
    q = np.asarray(q, dtype=float)
    if t <= 0:
        if np.any(np.isinf(q)):
            raise ValueError("a gradient call on an infinite curvature")
        return q
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(np.isinf(q), 1.0 / t, q / (1.0 + t * q))


def closed_loop(method: Method, gains: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(A_cl, O) in dimension n*d for per-call gain matrices (d x d): u = K xi."""
    d = gains[0].shape[0]
    eye = np.eye(d)
    p = len(gains)
    K: list[np.ndarray] = []
    for i in range(p):
        v = np.kron(method.C[i:i + 1], eye)
        for k in range(i):
            v = v + method.D[i, k] * K[k]
        K.append(gains[i] @ v)
    Acl = np.kron(method.A, eye) + sum(np.kron(method.B[:, i:i + 1], eye) @ K[i]
                                       for i in range(p))
    if isinstance(method.output, int):
        i = method.output
        out = np.kron(method.C[i:i + 1], eye) + sum(method.D[i, k] * K[k] for k in range(i + 1))
    else:
        out = np.kron(np.atleast_2d(method.output), eye)
    return Acl, out


def observed_radius(Acl: np.ndarray, out: np.ndarray) -> float:
    """Largest |lambda| of Acl whose mode ``out`` sees (Hautus: [Acl - lambda I; out] full rank)."""
    lams = np.linalg.eigvals(Acl)
    scale = 1.0 + np.linalg.norm(Acl) + np.linalg.norm(out)
    n = Acl.shape[0]
    for lam in sorted(lams, key=abs, reverse=True):
        stack = np.vstack([Acl - lam * np.eye(n), out.astype(complex)])
        if np.linalg.svd(stack, compute_uv=False)[-1] > HAUTUS_TOL * scale:
            return float(abs(lam))
    return 0.0


def _instance_rate(method: Method, curv: list[np.ndarray], rot: list[np.ndarray]) -> float:
    """The observed radius when function j is R_j diag(curv_j) R_j'. For the function
    measure the measure map is sqrt(sum_j Q_j) O (0 for instances with q = inf)."""
    gains = [rot[j] @ np.diag(call_gain(curv[j], method.steps[i])) @ rot[j].T
             for i, j in enumerate(method.oracles)]
    Acl, out = closed_loop(method, gains)
    if method.measure == "function":
        if any(np.any(np.isinf(c)) for c in curv):
            return 0.0
        S = sum(r @ np.diag(c) @ r.T for c, r in zip(curv, rot, strict=True))
        w, V = np.linalg.eigh(S)
        root = V @ np.diag(np.sqrt(np.clip(w, 0, None))) @ V.T
        out = np.kron(np.eye(out.shape[0] // root.shape[0]), root) @ out
    return observed_radius(Acl, out)


def _prox_only(method: Method) -> list[bool]:
    return [all(method.steps[i] > 0 for i, j in enumerate(method.oracles) if j == f)
            for f in range(len(method.functions))]


def _rotation(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def quadratic_bound(method: Method, samples_2d: int = 200, seed: int = 0) -> float:
    """Lower bound on rho: the worst observed radius over quadratic instances of the classes
    (every combination of 1-D grid curvatures, then random non-commuting 2-D pairs)."""
    po = _prox_only(method)
    grids = [curvature_grid(fn, p) for fn, p in zip(method.functions, po, strict=True)]
    mesh = np.meshgrid(*grids, indexing="ij")
    one = [np.eye(1)] * len(grids)
    best = 0.0
    for combo in zip(*(g.ravel() for g in mesh), strict=True):
        best = max(best, _instance_rate(method, [np.array([q]) for q in combo], one))
    rng = np.random.default_rng(seed)
    for _ in range(samples_2d):
        curv = [rng.choice(g, size=2) for g in grids]
        rot = [_rotation(rng.uniform(0, math.pi)) for _ in grids]
        best = max(best, _instance_rate(method, curv, rot))
    return best


# ---------------------------------------------------------------- simulation


@dataclass(frozen=True)
class Separable:
    """A separable nonquadratic function on R^d, by kind:

    - ``huber``: ``m|z|^2/2 + (L - m) huber_delta(z)``, ``z = x - a`` (m-strongly convex,
      L-smooth);
    - ``l1``: ``lam |x|_1 + mu |x - a|^2/2`` (convex for mu = 0, else mu-strongly convex);
    - ``box``: the indicator of ``[lo, hi]^d``; ``zero``: 0.
    """

    kind: str
    a: np.ndarray
    m: float = 0.0
    L: float = 0.0
    delta: float = 1.0
    lam: float = 0.0
    mu: float = 0.0
    lo: float = -1.0
    hi: float = 1.0

    def value(self, x: np.ndarray) -> float:
        if self.kind == "huber":
            z = np.abs(x - self.a)
            hub = np.where(z <= self.delta, z**2 / 2, self.delta * (z - self.delta / 2))
            return float(np.sum(self.m * z**2 / 2 + (self.L - self.m) * hub))
        if self.kind == "l1":
            return float(self.lam * np.abs(x).sum() + self.mu * np.sum((x - self.a)**2) / 2)
        if self.kind == "box":
            return 0.0 if np.all((x >= self.lo - 1e-12) & (x <= self.hi + 1e-12)) else INF
        return 0.0

    def grad(self, x: np.ndarray) -> np.ndarray:
        if self.kind == "huber":
            z = x - self.a
            return self.m * z + (self.L - self.m) * np.clip(z, -self.delta, self.delta)
        if self.kind == "zero":
            return np.zeros_like(x)
        raise ValueError(f"no gradient for {self.kind}")

    def prox(self, v: np.ndarray, t: float) -> np.ndarray:
        """argmin_x f(x) + |x - v|^2/(2t), in closed form."""
        if self.kind == "huber":
            w = v - self.a
            inner = w / (1 + t * self.L)
            outer = (w - t * (self.L - self.m) * self.delta * np.sign(w)) / (1 + t * self.m)
            return self.a + np.where(np.abs(inner) <= self.delta, inner, outer)
        if self.kind == "l1":
            c = (v + t * self.mu * self.a) / (1 + t * self.mu)
            return np.sign(c) * np.maximum(np.abs(c) - t * self.lam / (1 + t * self.mu), 0)
        if self.kind == "box":
            return np.clip(v, self.lo, self.hi)
        return v.copy()


def minimizer(fns: list[Separable]) -> np.ndarray:
    """argmin of the sum, coordinate by coordinate, from the (monotone) subdifferentials."""
    d = fns[0].a.size
    x = np.zeros(d)
    boxes = [f for f in fns if f.kind == "box"]
    lo = max([f.lo for f in boxes], default=-INF)
    hi = min([f.hi for f in boxes], default=INF)
    lam = sum(f.lam for f in fns if f.kind == "l1")
    for i in range(d):
        def slope(s: float, i: int = i) -> float:
            e = np.zeros(d)
            e[i] = s
            return float(sum(f.grad(e)[i] if f.kind in ("huber", "zero")
                             else f.mu * (s - f.a[i]) if f.kind == "l1" else 0.0
                             for f in fns))
        x[i] = _root_1d(slope, lam, lo, hi)
    return x


def _root_1d(slope, lam: float, lo: float, hi: float) -> float:
    """The s in [lo, hi] with 0 in slope(s) + lam d|s| + N_[lo,hi](s); slope increasing."""
    def phi(s: float) -> float:
        return slope(s) + lam * np.sign(s)
    big = 1e6
    a, b = max(lo, -big), min(hi, big)
    if lam > 0 and a <= 0 <= b and abs(slope(0.0)) <= lam:
        return 0.0
    if phi(a) >= 0:
        return a
    if phi(b) <= 0:
        return b
    if lam > 0 and a < 0 < b:
        a, b = (a, 0.0) if slope(0.0) > lam else (0.0, b)
    return brentq(phi, a, b, xtol=1e-15, rtol=4 * np.finfo(float).eps)


def _step(method: Method, fns: list[Separable], xi: np.ndarray) -> tuple[np.ndarray, list]:
    """One iteration on R^d (xi: n x d): the oracle calls in order, then the state update."""
    us: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    for i, j in enumerate(method.oracles):
        v = method.C[i] @ xi + sum(method.D[i, k] * us[k] for k in range(i))
        t = method.steps[i]
        y = fns[j].prox(v, t) if t > 0 else v
        us.append((v - y) / t if t > 0 else fns[j].grad(y))
        ys.append(y)
    return method.A @ xi + method.B @ np.array(us), ys


def trajectory(method: Method, fns: list[Separable], xi0: np.ndarray, steps: int,
               floor: float = 1e-22) -> np.ndarray:
    """measure(x_k), k = 0..K-1, stopping below ``floor`` x the largest value seen."""
    xstar = minimizer(fns)
    fstar = sum(f.value(xstar) for f in fns)
    xi = xi0
    out: list[float] = []
    for _ in range(steps):
        nxt, ys = _step(method, fns, xi)
        x = ys[method.output] if isinstance(method.output, int) else (method.output @ xi)[0]
        if method.measure == "function":
            val = sum(f.value(x) for f in fns) - fstar
        else:
            val = float(np.sum((x - xstar) ** 2))
        out.append(val)
        if not math.isfinite(val) or val <= floor * max(out) or val > 1e30:
            break
        xi = nxt
    return np.array(out)


def tail_decay(values: np.ndarray, min_steps: int = 20) -> float | None:
    """The observed factor per step over the second half of the positive part of a
    trajectory (None when too short to say anything)."""
    k1 = len(values) - 1
    while k1 > 0 and not values[k1] > 0:
        k1 -= 1
    k0 = k1 // 2
    if k1 - k0 < min_steps or not values[k0] > 0:
        return None
    return float((values[k1] / values[k0]) ** (1.0 / (k1 - k0)))


def simulate_decay(method: Method, fns: list[Separable], steps: int = 4000,
                   seed: int = 0) -> float | None:
    """Tail decay factor of the measure from a random start (a lower bound on rho^2 only
    in the limit: compare with slack). The trajectory stops above rounding noise: 1e-22 of
    the largest squared distance, 1e-10 of the largest function gap (F(x) - F* loses the
    digits of F* itself)."""
    rng = np.random.default_rng(seed)
    xi0 = rng.normal(scale=3.0, size=(method.A.shape[0], fns[0].a.size))
    floor = 1e-10 if method.measure == "function" else 1e-22
    return tail_decay(trajectory(method, fns, xi0, steps, floor))
