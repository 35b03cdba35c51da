"""Closed, proper, m-strongly convex functions (possibly nonsmooth), m > 0:
f_a >= f_b + <g_b, x_a - x_b> + m/2 |x_a - x_b|^2.

Test functions: m/2 |x - c|^2 + lambda |x - c'|_1, a quadratic with curvatures >= m,
m/2 |x - c|^2 + the indicator of a box.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form, exact_convex_form
from sosalgo.classes.members import (
    ProxFunction,
    quadratic,
    strongly_convex_box,
    strongly_convex_l1,
)


class StronglyConvex(FunctionClass):
    name = "strongly_convex"
    description = "closed, proper, m-strongly convex, possibly nonsmooth"
    parameters = ("m",)
    defaults = {"m": "m"}
    oracles = frozenset({"subgradient", "proximal"})
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b> + (m/2)|x_a - x_b|^2",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle"
                   r" + \tfrac{m}{2}\|x_a - x_b\|^2")

    def check(self, params: Mapping[str, float]) -> None:
        m = params["m"]
        if not (np.isfinite(m) and m > 0):
            raise ValueError(f"m: must be positive and finite, got {m:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, convex_form(params["m"]))]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(1), exact_convex_form(params["m"]))]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return params["m"], params["m"]

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return upper("m"), upper("m")  # (q/2)|x|^2 with q >= m

    def strong_convexity(self, params: Mapping[str, float]) -> float:
        return params["m"]

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        m, d = params["m"], len(xs)
        return [strongly_convex_l1(m, xs, rng), quadratic(m * rng.uniform(1, 10, d), xs, rng,
                                                         "quadratic>=m"),
                strongly_convex_box(m, xs, rng)]


CLASS = StronglyConvex()
