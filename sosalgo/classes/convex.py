"""Closed, proper, convex functions (possibly nonsmooth): f_a >= f_b + <g_b, x_a - x_b>
(Taylor, Hendrickx, Glineur 2017, Thm. 1 with L = inf)."""

from __future__ import annotations

from collections.abc import Mapping

from sosalgo.classes.base import FunctionClass, Inequality, convex_form


class Convex(FunctionClass):
    name = "convex"
    description = "closed, proper, convex, possibly nonsmooth"
    oracles = frozenset({"subgradient", "proximal"})

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, convex_form())]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return 0.0, 0.0


CLASS = Convex()
