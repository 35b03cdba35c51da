"""Indicators of closed convex sets: f = 0 on the set, subgradients are normal vectors,
so <g_b, x_a - x_b> <= 0 for points a, b of the set; the proximal step is the projection.
Only proximal steps are answered (a subgradient call would need its point in the set).

The tilted indicator h = f - <s*, . - x*> (s* a normal vector at x*) is convex, h >= 0,
h(x*) = 0, and its values on the set are -<s*, x - x*>: the certificate keeps them as free
nonnegative values with the convex inequalities (:meth:`Indicator.tilted`), a relaxation:
the rates it certifies hold for every closed convex function queried by the same
proximal steps, indicators included.
"""

from __future__ import annotations

from collections.abc import Mapping

from sosalgo.classes.base import FunctionClass, Inequality, convex_form


class Indicator(FunctionClass):
    name = "indicator"
    description = "indicator of a closed convex set (prox = projection)"
    oracles = frozenset({"proximal"})
    zero_values = True
    tilt_invariant = False

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, convex_form())]

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(0.0, convex_form())]  # the values are 0: alpha plays no role

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return 0.0, 0.0  # the indicator of the whole space


CLASS = Indicator()
