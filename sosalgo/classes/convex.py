"""Closed, proper, convex functions (possibly nonsmooth): f_a >= f_b + <g_b, x_a - x_b>
(Taylor, Hendrickx, Glineur 2017, Thm. 1 with L = inf).

Test functions: lambda |x - c|_1 (soft thresholding), a Huber function, the indicator of a
box and of a ball (projections), the zero function.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form, exact_convex_form
from sosalgo.classes.members import ProxFunction, ball, box, huber, l1, zero


class Convex(FunctionClass):
    name = "convex"
    description = "closed, proper, convex, possibly nonsmooth"
    oracles = frozenset({"subgradient", "proximal"})
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b>",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle")
    free_curvature = True

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, convex_form())]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(1), exact_convex_form())]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return 0.0, 0.0

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return Fraction(0), Fraction(0)  # the zero function

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        return [l1(xs, rng), huber(xs, rng), box(xs, rng, True), ball(xs, rng, True),
                zero(xs)]


CLASS = Convex()
