"""A test function class: L-smooth convex functions, written from the paper alone.

It exists to show that a class plugs in through one module and one registry line
(``register_class(CLASS)``) and then runs through analyze (rates, brackets), pep and
verify (exact checks, simulations on its test functions). Its inequality is derived here
from Taylor, Hendrickx, Glineur (2017), Thm. 4 with m = 0, independently of the shipped
``smooth_strongly_convex`` module: for f L-smooth and convex,

    f_a >= f_b + <g_b, x_a - x_b> + |g_a - g_b|^2 / (2L),

written (times L) as L (f_a - f_b) + X'QX >= 0 on X = (x_a, x_b, g_a, g_b).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes import FunctionClass, Inequality
from sosalgo.classes.members import ProxFunction, huber_smooth, quadratic


def _form(L: Any) -> list[list[Any]]:
    """Q of L (f_a - f_b) - L <g_b, x_a - x_b> - |g_a - g_b|^2 / 2 >= 0 (any numbers)."""
    h = Fraction(1, 2)
    z = Fraction(0)
    return [[z, z, z, -(L * h)],
            [z, z, z, L * h],
            [z, z, -h, h],
            [-(L * h), L * h, h, -h]]


class SmoothConvex(FunctionClass):
    name = "test_smooth_convex"
    description = "L-smooth convex (test class)"
    parameters = ("L",)
    defaults = {"L": "L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b> + |g_a - g_b|^2/(2L)",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle + \frac{\|g_a - g_b\|^2}{2L}")

    def check(self, params: Mapping[str, float]) -> None:
        if not (np.isfinite(params["L"]) and params["L"] > 0):
            raise ValueError(f"L: must be positive and finite, got {params['L']:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        L = float(params["L"])
        return [Inequality(L, np.array(_form(L), dtype=float))]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(params["L"], np.array(_form(params["L"]), dtype=object))]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return 0.0, params["L"]

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return Fraction(0), lower("L")

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        L = params["L"]
        return [quadratic(np.full(len(xs), L), xs, rng, "quad-L"),
                huber_smooth(0.0, L, xs, rng)]


CLASS = SmoothConvex()
