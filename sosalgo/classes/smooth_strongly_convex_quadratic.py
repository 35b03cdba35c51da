"""Quadratics f(x) = 1/2 (x - c)' Q (x - c) + <b, x> + const with Q symmetric, spectrum
in [mu, L] (PEPit's SmoothStronglyConvexQuadraticFunction; for mu > 0 every one has a
stationary point, and the linear term is a shift of c).

Interpolation (Bousselmi, Hendrickx, Glineur, "Interpolation conditions for linear
operators and applications to performance estimation problems", Thm. 3.3 and its
quadratic corollary): tilted data (x_a, g_a, h_a) with x* = 0, g* = 0, h* = 0 (h = f -
f* - <s*, . - x*> is 1/2 (x - x*)' Q (x - x*)) are those of such a quadratic if and only if

    <g_a, x_b> = <g_b, x_a>                      (every pair: g = Q x, Q symmetric)
    h_a - h_b = 1/2 <g_a + g_b, x_a - x_b>       (every pair: the values of 1/2 x' Q x)
    T[a, b] = (L + mu) <g_a, x_b> - <g_a, g_b> - mu L <x_a, x_b>  ⪰ 0   (spectrum in [mu, L])

The equalities are pairs of inequalities (both orders of a pair); T is a Gram-level
condition over all the points of the function (:meth:`blocks`), so the PEP is exact. The
class is closed under adding linear functions (tilt invariant). No Lyapunov family takes
the matrix condition (``homogeneous`` False): ``analyze`` refuses the class, ``pep``
answers (specs/gradient-quadratics.yaml, specs/proximal-gradient-quadratics.yaml).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, check_mu_below_L
from sosalgo.classes.members import ProxFunction, quadratic


def value_form(zero: Any) -> np.ndarray:
    """Q of ``-1/2 <g_a + g_b, x_a - x_b>`` on (x_a, x_b, g_a, g_b) (with alpha = 1:
    h_a - h_b >= 1/2 <g_a + g_b, x_a - x_b>; the reversed pair gives <=)."""
    q = Fraction(1, 4) + zero
    Q = np.full((4, 4), zero, dtype=object)
    for (i, j), v in {(0, 2): -q, (1, 2): q, (0, 3): -q, (1, 3): q}.items():
        Q[i, j] = Q[j, i] = v
    return Q


def symmetry_form(zero: Any) -> np.ndarray:
    """Q of ``<g_a, x_b> - <g_b, x_a>`` on (x_a, x_b, g_a, g_b) (alpha = 0; with the
    reversed pair: equality)."""
    h = Fraction(1, 2) + zero
    Q = np.full((4, 4), zero, dtype=object)
    Q[1, 2] = Q[2, 1] = h
    Q[0, 3] = Q[3, 0] = -h
    return Q


def spectrum_block(mu: Any, L: Any) -> np.ndarray:
    """K of T[a, b] = [x_a; g_a]' K [x_b; g_b] = (L + mu) <g_a, x_b> - <g_a, g_b>
    - mu L <x_a, x_b> (symmetrized): T ⪰ 0 iff the spectrum of Q is in [mu, L]."""
    half = (L + mu) * Fraction(1, 2)
    return np.array([[-(mu * L), half], [half, Fraction(-1) + 0 * L]], dtype=object)


class SmoothStronglyConvexQuadratic(FunctionClass):
    name = "smooth_strongly_convex_quadratic"
    description = "quadratic 1/2 x'Qx + <b, x>, spectrum of Q in [mu, L]"
    parameters = ("mu", "L")
    defaults = {"mu": "m", "L": "L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True
    homogeneous = False  # a Gram-level (matrix) condition: no Lyapunov family takes it
    tilted_text = (
        "<g_a, x_b> = <g_b, x_a>, h_a - h_b = <g_a + g_b, x_a - x_b>/2, "
        "[(L + mu) <g_a, x_b> - <g_a, g_b> - mu L <x_a, x_b>]_(a,b) PSD",
        r"\langle g_a, x_b\rangle = \langle g_b, x_a\rangle,\ h_a - h_b = \tfrac12"
        r"\langle g_a + g_b, x_a - x_b\rangle,\ \big[(L + \mu)\langle g_a, x_b\rangle"
        r" - \langle g_a, g_b\rangle - \mu L \langle x_a, x_b\rangle\big]_{a,b} \succeq 0")

    def check(self, params: Mapping[str, float]) -> None:
        check_mu_below_L(params, zero=True)

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, value_form(0.0).astype(float)),
                Inequality(0.0, symmetry_form(0.0).astype(float))]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        zero = Fraction(0)
        return [(Fraction(1), value_form(zero)), (zero, symmetry_form(zero))]

    def blocks(self, params: Mapping[str, float]) -> list[np.ndarray]:
        return [spectrum_block(float(params["mu"]), float(params["L"])).astype(float)]

    def exact_blocks(self, params: Mapping[str, Any]) -> list[np.ndarray]:
        return [spectrum_block(params["mu"], params["L"])]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return params["mu"], params["L"]

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return upper("mu"), lower("L")  # an inner interval

    def strong_convexity(self, params: Mapping[str, float]) -> float:
        return params["mu"]

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        mu, L = params["mu"], params["L"]
        q = rng.uniform(mu, L, len(xs))
        q[0], q[-1] = mu, L
        return [quadratic(q, xs, rng, "spread"), quadratic(np.full(len(xs), mu), xs, rng,
                                                           "quad-mu"),
                quadratic(np.full(len(xs), L), xs, rng, "quad-L")]


CLASS = SmoothStronglyConvexQuadratic()
