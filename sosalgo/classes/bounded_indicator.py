"""Indicators of closed convex sets of diameter at most D (PEPit's ConvexIndicatorFunction
with D): the ``indicator`` class's conditions (its tilted form, a relaxation: the values
of the tilted indicator kept free and nonnegative) and, between every ordered pair of
points of the set (x* included), |x_a - x_b|^2 <= D^2: an inhomogeneous condition, so the
worst case is the one under ``initial <= 1`` (Taylor, Hendrickx, Glineur 2017, Thm. 3.6
for the indicator's interpolation with a diameter). It involves the points only, so it
holds for the tilted indicator as well.

Only proximal steps (projections). No Lyapunov family of ``analyze`` takes the constant
(``homogeneous`` False): ``analyze`` refuses the class; ``sosalgo pep`` answers (with a
linear minimization oracle it is Frank-Wolfe's set).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import Inequality
from sosalgo.classes.indicator import Indicator


def distance_form() -> np.ndarray:
    """Q of ``-|x_a - x_b|^2`` on (x_a, x_b, g_a, g_b)."""
    Q = np.zeros((4, 4), dtype=object)
    Q[:, :] = Fraction(0)
    Q[0, 0] = Q[1, 1] = Fraction(-1)
    Q[0, 1] = Q[1, 0] = Fraction(1)
    return Q


class BoundedIndicator(Indicator):
    name = "bounded_indicator"
    description = "indicator of a closed convex set of diameter <= D (prox = projection)"
    parameters = ("D",)
    defaults = {"D": "1"}
    homogeneous = False
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b>, values h >= 0 kept free (tilted "
                   "indicator: a relaxation);  |x_a - x_b|^2 <= D^2",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle,\ h \ge 0;\quad"
                   r" \|x_a - x_b\|^2 \le D^2")

    def check(self, params: Mapping[str, float]) -> None:
        D = params["D"]
        if not (np.isfinite(D) and D > 0):
            raise ValueError(f"D: must be positive and finite, got {D:g}")

    def _diameter(self, params: Mapping[str, float]) -> Inequality:
        D = float(params["D"])
        return Inequality(0.0, distance_form().astype(float), D * D, "pairs")

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        return [*super().tilted(params), self._diameter(params)]

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [*super().inequalities(params), self._diameter(params)]

    def curvatures(self, params: Mapping[str, float]) -> None:
        return None  # the whole space is not bounded

    def exact_curvatures(self, lower: Any, upper: Any) -> None:
        return None

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [*super().exact_tilted(params), (Fraction(0), distance_form())]

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any]:
        D = params["D"]
        return [Fraction(0), D * D]

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list:
        return []


CLASS = BoundedIndicator()
