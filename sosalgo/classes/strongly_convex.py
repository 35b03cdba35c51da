"""Closed, proper, m-strongly convex functions (possibly nonsmooth), m > 0:
f_a >= f_b + <g_b, x_a - x_b> + m/2 |x_a - x_b|^2."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form


class StronglyConvex(FunctionClass):
    name = "strongly_convex"
    description = "closed, proper, m-strongly convex, possibly nonsmooth"
    parameters = ("m",)
    defaults = {"m": "m"}
    oracles = frozenset({"subgradient", "proximal"})

    def check(self, params: Mapping[str, float]) -> None:
        m = params["m"]
        if not (np.isfinite(m) and m > 0):
            raise ValueError(f"m: must be positive and finite, got {m:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, convex_form(params["m"]))]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return params["m"], params["m"]


CLASS = StronglyConvex()
