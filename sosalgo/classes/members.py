"""Functions with closed-form proximal steps: the building blocks of each class's
:meth:`~sosalgo.classes.base.FunctionClass.test_functions`.

A composite problem min_x sum_j f_j(x) is simulated with actual functions
(:mod:`sosalgo.proofs.prox_functions`): each :class:`ProxFunction` has its value, a
(sub)gradient selection (None: proximal steps only) and prox_{t f}(v) = argmin_y f(y) +
|y - v|^2 / (2 t) in closed form, all on batches (shape (batch, d)), and a subgradient
``s`` at the problem's minimizer x*. The functions are built around a given x* (kinks, set
boundaries and the nonsmooth parts placed at x* on some coordinates, so that the steps
stick there); :meth:`ProxFunction.tilt` adds a linear term (prox_{t(f + <a, .>)}(v) =
prox_{t f}(v - t a)). ``note`` says why each function belongs to its class.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["ProxFunction", "ball", "box", "huber", "huber_smooth", "l1", "quadratic",
           "strongly_convex_box", "strongly_convex_l1", "zero"]

Array = np.ndarray


@dataclass(frozen=True, eq=False)
class ProxFunction:
    """f on R^d: value, subgradient selection (None: prox only), prox, and a subgradient
    ``s`` at the problem's x*."""

    name: str
    value: Callable[[Array], Array]
    prox: Callable[[Array, float], Array]
    grad: Callable[[Array], Array] | None
    s: Array
    note: str
    tiltable: bool = True

    def tilt(self, a: Array) -> ProxFunction:
        """f + <a, .> (same class when ``tiltable``)."""
        val, prox, grad = self.value, self.prox, self.grad
        return replace(self, name=f"{self.name}+linear", s=self.s + a,
                       value=lambda x: val(x) + x @ a,
                       prox=lambda v, t: prox(v - t * a, t),
                       grad=None if grad is None else (lambda x: grad(x) + a))


def _rotation(d: int, rng: np.random.Generator) -> Array:
    q, r = np.linalg.qr(rng.standard_normal((d, d)))
    return q * np.sign(np.diag(r))


def _soft(z: Array, tau: Array | float) -> Array:
    return np.sign(z) * np.maximum(np.abs(z) - tau, 0.0)


def _half_mask(d: int, rng: np.random.Generator) -> Array:
    """About half the coordinates (at least one), where a kink or boundary sits at x*."""
    mask = rng.random(d) < 0.5
    mask[rng.integers(d)] = True
    return mask


def quadratic(q: Array, xs: Array, rng: np.random.Generator, label: str) -> ProxFunction:
    """1/2 (x - c)' H (x - c), H = R diag(q) R'; prox (I + tH)^-1 (v + tH c)."""
    d = len(xs)
    R = _rotation(d, rng)
    H = (R * q) @ R.T
    c = xs + rng.standard_normal(d)

    def prox(v: Array, t: float) -> Array:
        return np.linalg.solve(np.eye(d) + t * H, (v + t * (H @ c)).T).T

    return ProxFunction(label, lambda x: 0.5 * np.einsum("bi,ij,bj->b", x - c, H, x - c),
                        prox, lambda x: (x - c) @ H, H @ (xs - c),
                        f"quadratic, curvatures in [{q.min():.3g}, {q.max():.3g}]")


def huber_smooth(m: float, L: float, xs: Array, rng: np.random.Generator) -> ProxFunction:
    """sum phi(R'(x - c)), phi(z) = m z^2/2 + (L - m) H(z), H(z) = z^2/2 (|z| <= delta),
    delta |z| - delta^2/2 beyond: phi'' in {m, L}, so the function is in F(m, L)."""
    d = len(xs)
    R, delta = _rotation(d, rng), 0.5
    w = rng.uniform(-2, 2, d)  # R'(x* - c): some inside the quadratic region, some outside
    c = xs - R @ w

    def dphi(z: Array) -> Array:
        return m * z + (L - m) * np.clip(z, -delta, delta)

    def phi(z: Array) -> Array:
        a = np.abs(z)
        hub = np.where(a <= delta, 0.5 * z * z, delta * a - 0.5 * delta**2)
        return (0.5 * m * z * z + (L - m) * hub).sum(axis=-1)

    def prox(v: Array, t: float) -> Array:
        z = (v - c) @ R
        inner = z / (1 + t * L)
        outer = (z - t * (L - m) * delta * np.sign(z)) / (1 + t * m)
        y = np.where(np.abs(z) <= delta * (1 + t * L), inner, outer)
        return c + y @ R.T

    return ProxFunction("huber-type", lambda x: phi((x - c) @ R), prox,
                        lambda x: dphi((x - c) @ R) @ R.T, R @ dphi(w),
                        f"separable phi'' in {{m, L}} = {{{m:g}, {L:g}}}, rotated")


def _l1_centre(xs: Array, rng: np.random.Generator, lam: float) -> tuple[Array, Array]:
    """c = x* on some coordinates (kinks at x*) and a subgradient of lam |x - c|_1 at x*."""
    d = len(xs)
    kink = _half_mask(d, rng)
    c = np.where(kink, xs, xs + rng.standard_normal(d))
    return c, np.where(kink, rng.uniform(-lam, lam, d), lam * np.sign(xs - c))


def l1(xs: Array, rng: np.random.Generator, lam: float = 1.0) -> ProxFunction:
    """lam |x - c|_1 with c = x* on some coordinates; prox: soft thresholding."""
    c, s = _l1_centre(xs, rng, lam)
    return ProxFunction("l1", lambda x: lam * np.abs(x - c).sum(axis=-1),
                        lambda v, t: c + _soft(v - c, t * lam),
                        lambda x: lam * np.sign(x - c), s, "a norm: convex, nonsmooth")


def huber(xs: Array, rng: np.random.Generator, lam: float = 1.0,
          delta: float = 0.3) -> ProxFunction:
    """lam sum H_delta(x - c), H(z) = z^2/(2 delta) (|z| <= delta), |z| - delta/2 beyond."""
    d = len(xs)
    c = xs - rng.uniform(-2 * delta, 2 * delta, d)

    def prox(v: Array, t: float) -> Array:
        z = v - c
        y = np.where(np.abs(z) <= delta + t * lam, z * delta / (delta + t * lam),
                     z - t * lam * np.sign(z))
        return c + y

    def val(x: Array) -> Array:
        a = np.abs(x - c)
        return lam * np.where(a <= delta, a * a / (2 * delta), a - delta / 2).sum(axis=-1)

    return ProxFunction("huber", val, prox, lambda x: lam * np.clip((x - c) / delta, -1, 1),
                        lam * np.clip((xs - c) / delta, -1, 1), "convex (H'' in {0, 1/delta})")


def box(xs: Array, rng: np.random.Generator, tiltable: bool = False) -> ProxFunction:
    """Indicator of a box with x* on some of its faces; prox: clipping."""
    d = len(xs)
    on = _half_mask(d, rng)
    lower = rng.random(d) < 0.5
    lo = np.where(on & lower, xs, xs - rng.uniform(0.5, 2, d))
    hi = np.where(on & ~lower, xs, xs + rng.uniform(0.5, 2, d))
    s = np.where(on, np.where(lower, -1.0, 1.0) * rng.uniform(0, 2, d), 0.0)
    return ProxFunction("box", _set_value(lambda x: np.maximum(lo - x, x - hi).max(axis=-1)),
                        lambda v, t: np.clip(v, lo, hi), None, s,
                        "indicator of a box (normal cone at x*)", tiltable)


def ball(xs: Array, rng: np.random.Generator, tiltable: bool = False) -> ProxFunction:
    """Indicator of a ball with x* on its sphere; prox: radial projection."""
    d = len(xs)
    nv = rng.standard_normal(d)
    nv /= np.linalg.norm(nv)
    radius = float(rng.uniform(0.5, 2))
    cc = xs - radius * nv

    def proj(v: Array, t: float) -> Array:
        r = np.linalg.norm(v - cc, axis=-1, keepdims=True)
        return cc + (v - cc) * np.minimum(1.0, radius / np.maximum(r, 1e-300))

    return ProxFunction("ball", _set_value(
        lambda x: np.linalg.norm(x - cc, axis=-1) - radius), proj, None,
        float(rng.uniform(0, 2)) * nv, "indicator of a ball, x* on the sphere", tiltable)


def _set_value(excess: Callable[[Array], Array]) -> Callable[[Array], Array]:
    """0 on the set (up to rounding), +inf outside."""
    def value(x: Array) -> Array:
        scale = 1.0 + np.abs(x).max(axis=-1)
        return np.where(excess(x) <= 1e-9 * scale, 0.0, np.inf)
    return value


def zero(xs: Array) -> ProxFunction:
    """The zero function (convex; the indicator of the whole space)."""
    return ProxFunction("zero", lambda x: np.zeros(x.shape[0]), lambda v, t: v.copy(),
                        lambda x: np.zeros_like(x), np.zeros(len(xs)), "0")


def strongly_convex_l1(m: float, xs: Array, rng: np.random.Generator,
                       lam: float = 1.0) -> ProxFunction:
    """m/2 |x - c|^2 + lam |x - c'|_1 with c' = x* on some coordinates: the prox combines
    the quadratics and soft-thresholds, prox(v) = c' + soft(w - c', t lam/(1 + t m)) with
    w = (v + t m c)/(1 + t m)."""
    c1, s1 = _l1_centre(xs, rng, lam)
    c = xs + rng.standard_normal(len(xs))

    def prox(v: Array, t: float) -> Array:
        w = (v + t * m * c) / (1 + t * m)
        return c1 + _soft(w - c1, t * lam / (1 + t * m))

    return ProxFunction("strongly-convex+l1",
                        lambda x: (0.5 * m * (x - c) ** 2 + lam * np.abs(x - c1)).sum(axis=-1),
                        prox, lambda x: m * (x - c) + lam * np.sign(x - c1), m * (xs - c) + s1,
                        "m-strongly convex quadratic + a norm")


def strongly_convex_box(m: float, xs: Array, rng: np.random.Generator) -> ProxFunction:
    """m/2 |x - c|^2 + indicator of a box: prox clips (v + t m c)/(1 + t m)."""
    b = box(xs, rng)
    c = xs + rng.standard_normal(len(xs))
    return ProxFunction("strongly-convex+box",
                        lambda x: 0.5 * m * ((x - c) ** 2).sum(axis=-1) + b.value(x),
                        lambda v, t: b.prox((v + t * m * c) / (1 + t * m), t), None,
                        m * (xs - c) + b.s, "m-strongly convex quadratic + a box", True)


def curvature_members(m: float, L: float, xs: Array, rng: np.random.Generator,
                      spread: str, ends: tuple[str, ...] = ("m",)) -> list[ProxFunction]:
    """The members of F(m, L) every smooth class tests: a quadratic with curvatures spread
    over [m, L] (both ends included; labelled ``spread``), the quadratics of curvature m
    (and L: ``ends``), and a Huber-like function whose curvature jumps between m and L."""
    q = rng.uniform(m, L, len(xs))
    q[0], q[-1] = m, L
    out = [quadratic(q, xs, rng, spread)]
    out += [quadratic(np.full(len(xs), {"m": m, "L": L}[e]), xs, rng, f"quad-{e}")
            for e in ends]
    return out + [huber_smooth(m, L, xs, rng)]
