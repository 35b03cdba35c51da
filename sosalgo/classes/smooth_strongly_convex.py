"""L-smooth, m-strongly convex functions F(m, L), 0 <= m < L.

Interpolation (Taylor, Hendrickx, Glineur 2017, Thm. 4), scaled by L - m:
(L - m)(f_a - f_b) + 1/2 X' MM X >= 0 with MM as in Taylor, Van Scoy, Lessard (2018), (11).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality


class SmoothStronglyConvex(FunctionClass):
    name = "smooth_strongly_convex"
    description = "L-smooth, m-strongly convex (m = 0: smooth convex)"
    parameters = ("m", "L")
    defaults = {"m": "m", "L": "L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True

    def check(self, params: Mapping[str, float]) -> None:
        m, L = params["m"], params["L"]
        if not (np.isfinite(m) and m >= 0):
            raise ValueError(f"m: must be >= 0 and finite, got {m:g}")
        if not (np.isfinite(L) and L > m):
            raise ValueError(f"L: must be finite and > m = {m:g}, got {L:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        m, L = params["m"], params["L"]
        MM = np.array([[-m * L, m * L, m, -L], [m * L, -m * L, -m, L], [m, -m, -1, 1],
                       [-L, L, 1, -1]], dtype=float)
        return [Inequality(L - m, 0.5 * MM)]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return params["m"], params["L"]


CLASS = SmoothStronglyConvex()
