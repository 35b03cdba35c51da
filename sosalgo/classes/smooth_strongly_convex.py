"""L-smooth, m-strongly convex functions F(m, L), 0 <= m < L.

Interpolation (Taylor, Hendrickx, Glineur 2017, Thm. 4), scaled by L - m:
(L - m)(f_a - f_b) + 1/2 X' MM X >= 0 with MM as in Taylor, Van Scoy, Lessard (2018), (11).

Test functions: rotated quadratics with curvatures in [m, L] (random, all m, all L), a
rotated separable Huber-type m/2 z^2 + (L - m) H_delta(z) (curvature L near the kink
region, m outside). Gradient-only methods cannot beat 1 - 1/sqrt(L/m) on the class (the
lower complexity bound attained by the triple momentum method; Drori, Taylor 2022).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality
from sosalgo.classes.members import ProxFunction, curvature_members


def interpolation_matrix(m: Any, L: Any) -> list[list[Any]]:
    """MM of the interpolation inequality (floats or exact numbers)."""
    return [[-(m * L), m * L, m, -L], [m * L, -(m * L), -m, L], [m, -m, -1, 1],
            [-L, L, 1, -1]]


class SmoothStronglyConvex(FunctionClass):
    name = "smooth_strongly_convex"
    description = "L-smooth, m-strongly convex (m = 0: smooth convex)"
    parameters = ("m", "L")
    defaults = {"m": "m", "L": "L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True
    noisy_gradients = True
    tilted_text = (
        "h_a >= h_b + <g_b, x_a - x_b> + |g_a - g_b|^2/(2L) "
        "+ m |x_a - x_b - (g_a - g_b)/L|^2/(2(1 - m/L))",
        r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle + \frac{\|g_a - g_b\|^2}{2L}"
        r" + \frac{m\,\|x_a - x_b - (g_a - g_b)/L\|^2}{2(1 - m/L)}")

    def check(self, params: Mapping[str, float]) -> None:
        m, L = params["m"], params["L"]
        if not (np.isfinite(m) and m >= 0):
            raise ValueError(f"m: must be >= 0 and finite, got {m:g}")
        if not (np.isfinite(L) and L > m):
            raise ValueError(f"L: must be finite and > m = {m:g}, got {L:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        m, L = params["m"], params["L"]
        MM = np.array(interpolation_matrix(m, L), dtype=float)
        return [Inequality(L - m, 0.5 * MM)]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        m, L = params["m"], params["L"]
        h = Fraction(1, 2)
        Q = np.array([[v * h for v in row] for row in interpolation_matrix(m, L)], dtype=object)
        return [(L - m, Q)]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return params["m"], params["L"]

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return upper("m"), lower("L")  # an inner interval: every q in it is in [m, L]

    def strong_convexity(self, params: Mapping[str, float]) -> float:
        return params["m"]

    def gradient_floor(self, params: Mapping[str, float]) -> float | None:
        m, L = params["m"], params["L"]
        if not (m > 0 and L > m):
            return None
        return 1.0 - 1.0 / math.sqrt(L / m)

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        return curvature_members(params["m"], params["L"], xs, rng, "quadratic", ("m", "L"))


CLASS = SmoothStronglyConvex()
