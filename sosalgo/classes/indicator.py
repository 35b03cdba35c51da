"""Indicators of closed convex sets: f = 0 on the set, subgradients are normal vectors,
so <g_b, x_a - x_b> <= 0 for points a, b of the set; the proximal step is the projection.
A subgradient call answers a normal vector at its point, which says that the point lies in
the set: a method may make it only where its point is in the set by construction (a
projection already made, such as the start P_C(x_0) of a method that projects x_0 first:
docs/operators.md, "A first step unlike the others").

The tilted indicator h = f - <s*, . - x*> (s* a normal vector at x*) is convex, h >= 0,
h(x*) = 0, and its values on the set are -<s*, x - x*>: the certificate keeps them as free
nonnegative values with the convex inequalities (:meth:`Indicator.tilted`), a relaxation:
the rates it certifies hold for every closed convex function queried by the same
proximal steps, indicators included.

Test functions: the indicators of a box, of a ball, of the whole space.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form, exact_convex_form
from sosalgo.classes.members import ProxFunction, ball, box, zero


class Indicator(FunctionClass):
    name = "indicator"
    description = "indicator of a closed convex set (prox = projection)"
    oracles = frozenset({"proximal", "subgradient"})
    zero_values = True
    tilt_invariant = False
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b>, values h >= 0 kept free (tilted "
                   "indicator: a relaxation)",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle,\ h \ge 0\ "
                   r"\text{(tilted indicator, relaxed)}")

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, convex_form())]

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(0.0, convex_form())]  # the values are 0: alpha plays no role

    def pinned(self, params: Mapping[str, float]) -> list[Inequality]:
        """With the optimal normal vector 0 (x* in the set; indicators alone) the values
        are the indicator's own, 0 on the set: its interpolation conditions
        <g_b, x_a - x_b> <= 0 exactly, no relaxation (Taylor, Hendrickx, Glineur 2017)."""
        return self.inequalities(params)

    def exact_pinned(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(0), Q) for _, Q in self.exact_tilted(params)]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return 0.0, 0.0  # the indicator of the whole space

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(1), exact_convex_form())]

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return Fraction(0), Fraction(0)  # the indicator of the whole space

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        return [box(xs, rng), ball(xs, rng), replace(zero(xs), name="whole-space",
                                                     tiltable=False, grad=None)]


CLASS = Indicator()
