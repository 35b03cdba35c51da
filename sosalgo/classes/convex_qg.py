"""Convex functions with a quadratic upper bound at their minimizer: f convex and
f(x) - f* <= (L/2)|x - x*|^2 (PEPit's ConvexQGFunction; "quadratic growth" from above).

Interpolation (Goujaud, Taylor, Dieuleveut 2022, "Optimal first-order methods for convex
functions with a quadratic upper bound", Thm. 2.6): data with a minimizer x* are
interpolated by such a function if and only if

    f_a >= f_b + <g_b, x_a - x_b>                         for every ordered pair,
    f* >= f_a + <g_a, x* - x_a> + |g_a|^2 / (2L)           for every point a,

so a PEP over them is exact. The second holds between a point and x* only (scope
"optimum"); it is written times 2L: -2L (f_a - f*) + 2L <g_a, x_a - x*> - |g_a|^2 >= 0.
Like a bound on |g|, it is about the function itself, not f - <s*, .>: the PEP takes the
class as the only function of its spec (``alone``; s* = 0 then).

No Lyapunov family of ``analyze`` takes a condition about x* alone (``homogeneous``
False): ``analyze`` refuses the class; ``sosalgo pep`` answers (specs/gradient-qg.yaml).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form, exact_convex_form


def growth_form(L: Any) -> np.ndarray:
    """Q of ``2L <g_a, x_a - x_b> - |g_a|^2`` on (x_a, x_b, g_a, g_b) (object array: L a
    float, a rational or a ball)."""
    Q = np.full((4, 4), 0 * L, dtype=object)
    Q[0, 2] = Q[2, 0] = L
    Q[1, 2] = Q[2, 1] = -L
    Q[2, 2] = Q[2, 2] - 1
    return Q


class ConvexQG(FunctionClass):
    name = "convex_qg"
    description = "convex, f - f* <= (L/2)|x - x*|^2 (quadratic upper bound at x*)"
    parameters = ("L",)
    defaults = {"L": "L"}
    oracles = frozenset({"subgradient"})
    finite_everywhere = True
    tilt_invariant = False
    homogeneous = False
    alone = True
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b> (every pair);  h_a <= <g_a, x_a - x*> - "
                   "|g_a|^2/(2L) (every point, with x*)",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle,\quad h_a \le \langle g_a,"
                   r" x_a - x_\star\rangle - \frac{\|g_a\|^2}{2L}")

    def check(self, params: Mapping[str, float]) -> None:
        L = params["L"]
        if not (np.isfinite(L) and L > 0):
            raise ValueError(f"L: must be positive and finite, got {L:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        L = float(params["L"])
        return [Inequality(1.0, convex_form()),
                Inequality(-2.0 * L, growth_form(L).astype(float), 0.0, "optimum")]

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        return self.inequalities(params)  # the only function: s* = 0 (``alone``)

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        L = params["L"]
        return [(Fraction(1), exact_convex_form()), (-2 * L, growth_form(L))]

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any]:
        return [Fraction(0), Fraction(0)]


CLASS = ConvexQG()
