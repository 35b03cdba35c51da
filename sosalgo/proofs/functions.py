"""Test functions in F(m, L) with a known minimizer x* and optimal value f*.

Every function is stored relative to its minimizer: ``gap(z) = f(x* + z) - f*`` and
``grad_z(z) = grad f(x* + z)``, both evaluated without cancellation, so a simulation can
follow f(x_k) - f* and the Lyapunov function of eq. (12) down to 1e-250 instead of stopping
at the rounding level of f*. ``value`` and ``grad`` give f and grad f in absolute
coordinates. Batches: z has shape (batch, d); gap returns (batch,), grad_z (batch, d).

Membership in F(m, L) (eq. 4-5): for C^1 functions with a piecewise-constant Hessian H(x),
m I ⪯ H ⪯ L I wherever it exists is enough (grad f is then m-strongly monotone and
L-Lipschitz along every segment); separable sums and orthogonal changes of variables keep
both bounds. Each ``note`` says why the function belongs to the class.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Objective",
    "function_suite",
    "huber_like",
    "logsumexp",
    "lrp_counterexample",
    "quadratic",
    "random_rotation",
]

Array = np.ndarray


@dataclass(frozen=True, eq=False)
class Objective:
    """f(x) = f* + gap(x - x*) on R^d, in F(m, L), with minimizer x* (gap(0) = 0)."""

    name: str
    d: int
    m: float
    L: float
    x_star: Array
    f_star: float
    gap: Callable[[Array], Array]
    grad_z: Callable[[Array], Array]
    note: str
    starts: tuple[float, ...] = field(default=())  # scalars t: suggested starts x0 = x* + t 1

    def value(self, x: Array) -> Array:
        """f(x) for x of shape (batch, d) or (d,)."""
        z = np.atleast_2d(np.asarray(x, float) - self.x_star)
        out = self.f_star + self.gap(z)
        return out if np.ndim(x) > 1 else out[0]

    def grad(self, x: Array) -> Array:
        """grad f(x) for x of shape (batch, d) or (d,)."""
        z = np.atleast_2d(np.asarray(x, float) - self.x_star)
        out = self.grad_z(z)
        return out if np.ndim(x) > 1 else out[0]


def random_rotation(d: int, rng: np.random.Generator) -> Array:
    """A Haar-random orthogonal d x d matrix (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(rng.standard_normal((d, d)))
    return q * np.sign(np.diag(r))


def _placement(d: int, rng: np.random.Generator) -> tuple[Array, float]:
    return rng.standard_normal(d), float(rng.standard_normal())


def quadratic(
    curvatures: Array, rng: np.random.Generator, m: float, L: float, rotate: bool = True,
    name: str | None = None,
) -> Objective:
    """f(x) = f* + 1/2 (x - x*)' Q diag(q) Q' (x - x*) with every q_i in [m, L]."""
    q = np.asarray(curvatures, float)
    if np.any(q < m) or np.any(q > L):
        raise ValueError("curvatures must lie in [m, L]")
    d = q.size
    Q = random_rotation(d, rng) if rotate and d > 1 else np.eye(d)
    H = (Q * q) @ Q.T
    H = 0.5 * (H + H.T)
    x_star, f_star = _placement(d, rng)

    def gap(z: Array) -> Array:
        return 0.5 * np.einsum("bi,bi->b", z @ H, z)

    def grad_z(z: Array) -> Array:
        return z @ H

    label = name or "quadratic q=" + ",".join(f"{v:.4g}" for v in q[:3]) + ("..." if d > 3 else "")
    note = (f"Hessian Q diag(q) Q' with eigenvalues q in [{q.min():.6g}, {q.max():.6g}] "
            f"within [m, L] = [{m:g}, {L:g}]")
    return Objective(label, d, m, L, x_star, f_star, gap, grad_z, note)


def huber_like(
    d: int, rng: np.random.Generator, m: float, L: float, inner: str = "L", width: float = 1.0,
    rotate: bool = True,
) -> Objective:
    """f(x) = f* + sum_i phi((Q'(x - x*))_i), phi'' = a on |t| < width, b outside.

    ``inner="L"``: (a, b) = (L, m) (Huber-like, flat tails); ``inner="m"``: (a, b) = (m, L).
    phi is C^1: phi'(t) = a t for |t| <= w, sign(t)(a w + b(|t| - w)) beyond.
    """
    a, b = (L, m) if inner == "L" else (m, L)
    w = float(width)
    Q = random_rotation(d, rng) if rotate and d > 1 else np.eye(d)
    x_star, f_star = _placement(d, rng)

    def phi(t: Array) -> Array:
        s = np.abs(t)
        out = 0.5 * a * t * t
        o = s > w
        out[o] = 0.5 * a * w * w + a * w * (s[o] - w) + 0.5 * b * (s[o] - w) ** 2
        return out

    def dphi(t: Array) -> Array:
        s = np.abs(t)
        out = a * t
        o = s > w
        out[o] = np.sign(t[o]) * (a * w + b * (s[o] - w))
        return out

    def gap(z: Array) -> Array:
        return phi(z @ Q).sum(axis=1)

    def grad_z(z: Array) -> Array:
        return dphi(z @ Q) @ Q.T

    note = (f"separable phi with phi' continuous, piecewise linear, slopes {a:g} and {b:g} in "
            f"[m, L]; orthogonal change of variables")
    return Objective(f"huber-{inner}-inside", d, m, L, x_star, f_star, gap, grad_z, note)


def lrp_counterexample(
    d: int, rng: np.random.Generator, m: float, L: float, rotate: bool = True
) -> Objective:
    """Lessard, Recht, Packard (2016, Sec. 4.6) counterexample for heavy-ball, scaled to (m, L).

    1-D: g(t) = L t (t < 1), m t + (L - m) (1 <= t < 2), L t - (L - m) (t >= 2), i.e.
    25t, t + 24, 25t - 24 for (m, L) = (1, 25); f(t) = integral of g from 0, minimizer 0,
    f* = 0. In d > 1 the separable sum over coordinates after a rotation (none if d == 1).
    """
    Lm = L - m
    Q = random_rotation(d, rng) if rotate and d > 1 else np.eye(d)
    x_star = np.zeros(d) if d == 1 else rng.standard_normal(d)
    f2 = 1.5 * L + 0.5 * m  # f(2)

    def phi(t: Array) -> Array:
        out = 0.5 * L * t * t
        mid = (t >= 1) & (t < 2)
        hi = t >= 2
        out[mid] = 0.5 * L + 0.5 * m * (t[mid] ** 2 - 1) + Lm * (t[mid] - 1)
        out[hi] = f2 + 0.5 * L * (t[hi] ** 2 - 4) - Lm * (t[hi] - 2)
        return out

    def dphi(t: Array) -> Array:
        out = L * t
        mid = (t >= 1) & (t < 2)
        hi = t >= 2
        out[mid] = m * t[mid] + Lm
        out[hi] = L * t[hi] - Lm
        return out

    def gap(z: Array) -> Array:
        return phi(z @ Q).sum(axis=1)

    def grad_z(z: Array) -> Array:
        return dphi(z @ Q) @ Q.T

    note = ("g continuous (L at t = 1, L + m at t = 2), piecewise linear with slopes L, m, L "
            "in [m, L]; g(0) = 0 is its only zero")
    return Objective("lrp", d, m, L, x_star, 0.0, gap, grad_z, note, starts=(3.3, 3.1, 3.45))


def _lse_excess(w: Array, p: Array) -> Array:
    """D(w) = log(sum_i p_i exp(w_i)) - p'w >= 0 without cancellation (rows of w).

    |w| < 1e-3: cumulant series k2/2 + k3/6 + k4/24 (relative error ~ |w|^3);
    |w| < 1: log1p(sum p_i expm1(w_i)) - p'w; else the shifted log-sum-exp.
    """
    mu = w @ p
    size = np.max(np.abs(w), axis=1)
    out = np.empty(w.shape[0])
    tiny, mid, big = size < 1e-3, (size >= 1e-3) & (size < 1.0), size >= 1.0
    if np.any(tiny):
        c = w[tiny] - mu[tiny, None]
        c2, c3, c4 = (c**2) @ p, (c**3) @ p, (c**4) @ p
        out[tiny] = c2 / 2 + c3 / 6 + (c4 - 3 * c2**2) / 24
    if np.any(mid):
        out[mid] = np.log1p(np.expm1(w[mid]) @ p) - mu[mid]
    if np.any(big):  # log sum_i exp(log p_i + w_i), shifted by its largest term
        u = _log_p(p) + w[big]
        shift = np.max(u, axis=1)
        out[big] = shift + np.log(np.exp(u - shift[:, None]).sum(axis=1)) - mu[big]
    return np.maximum(out, 0.0)


def _log_p(p: Array) -> Array:
    """log p with log 0 = -inf (an underflowed softmax weight), without a warning."""
    with np.errstate(divide="ignore"):
        return np.log(p)


def _softmax_minus_p(w: Array, p: Array) -> Array:
    """softmax(a + w) - p for p = softmax(a), stably: p (expm1(w) - S) / (1 + S)."""
    big = np.max(np.abs(w), axis=1) >= 1.0
    out = np.empty_like(w)
    if np.any(~big):
        e = np.expm1(w[~big])
        S = e @ p
        out[~big] = p * (e - S[:, None]) / (1 + S[:, None])
    if np.any(big):
        # shift by the largest log p_i + w_i (finite: p has an entry >= 1/k), so the
        # largest term is exp(0) = 1 and the sum is >= 1: never 0/0 at large errors
        u = _log_p(p) + w[big]
        ex = np.exp(u - np.max(u, axis=1, keepdims=True))
        out[big] = ex / ex.sum(axis=1, keepdims=True) - p
    return out


def logsumexp(
    d: int, rng: np.random.Generator, m: float, L: float, rows: int | None = None,
    newton_tol: float = 1e-14,
) -> Objective:
    """f(x) = m/2 |x|^2 + c lse(W x + b) - r'x, with c = 2 (L - m) / ||W||_2^2 (0.999 safety).

    The Hessian is m I + c W' (diag(p) - p p') W with p = softmax(Wx + b); for any v,
    v'(diag(p) - pp')v = Var_p(v) <= |v|^2 / 2 (Popoviciu: Var <= (max - min)^2 / 4), so
    m I ⪯ Hessian ⪯ (m + c ||W||^2 / 2) I ⪯ L I. x* is found by Newton's method; the tiny
    residual gradient r = grad(x*) is then subtracted (r'x is linear, the Hessian is
    unchanged), so x* is the exact minimizer of the function that is simulated.
    """
    k = rows or d + 3
    W = rng.standard_normal((k, d))
    b = rng.standard_normal(k)
    c = 0.999 * 2 * (L - m) / np.linalg.norm(W, 2) ** 2

    def lse(u: Array) -> Array:
        s = np.max(u, axis=-1, keepdims=True)
        return s[..., 0] + np.log(np.exp(u - s).sum(axis=-1))

    def soft(u: Array) -> Array:
        e = np.exp(u - u.max())
        return e / e.sum()

    x = np.zeros(d)
    for _ in range(100):
        p = soft(W @ x + b)
        g = m * x + c * W.T @ p
        if np.linalg.norm(g) <= newton_tol * (1 + np.linalg.norm(x)):
            break
        H = m * np.eye(d) + c * W.T @ (np.diag(p) - np.outer(p, p)) @ W
        x = x - np.linalg.solve(H, g)
    x_star = x
    a = W @ x_star + b
    p = soft(a)
    r = m * x_star + c * W.T @ p  # residual gradient, ~1e-16, removed by the tilt
    f_star = float(0.5 * m * x_star @ x_star + c * lse(a) - r @ x_star)

    def gap(z: Array) -> Array:
        return 0.5 * m * np.einsum("bi,bi->b", z, z) + c * _lse_excess(z @ W.T, p)

    def grad_z(z: Array) -> Array:
        return m * z + c * _softmax_minus_p(z @ W.T, p) @ W

    nw = float(np.linalg.norm(W, 2))
    note = (f"m/2|x|^2 + c lse(Wx+b) - r'x, c = {c:.6g}, ||W||_2 = {nw:.6g}: "
            f"Hessian in [m, m + c||W||^2/2] = [{m:g}, {m + c * nw**2 / 2:.6g}]")
    return Objective("logsumexp", d, m, L, x_star, f_star, gap, grad_z, note)


def function_suite(m: float, L: float, d: int, rng: np.random.Generator) -> list[Objective]:
    """The default functions of F(m, L) on R^d used by :func:`simulate_check`."""
    fns: list[Objective] = []
    if d == 1:
        for q in (m, L, float(np.sqrt(m * L)), 0.5 * (m + L)):
            fns.append(quadratic(np.array([q]), rng, m, L, name=f"quadratic q={q:.6g}"))
    else:
        fns.append(quadratic(np.full(d, m), rng, m, L, name="quadratic q=m"))
        fns.append(quadratic(np.full(d, L), rng, m, L, name="quadratic q=L"))
        spread = np.linspace(m, L, d)
        fns.append(quadratic(spread, rng, m, L, name="quadratic spectrum [m, L]"))
    fns.append(huber_like(d, rng, m, L, inner="L"))
    fns.append(huber_like(d, rng, m, L, inner="m"))
    fns.append(lrp_counterexample(d, rng, m, L))
    fns.append(logsumexp(d, rng, m, L))
    return fns
