"""L-smooth functions with a quadratic Lojasiewicz (Polyak-Lojasiewicz) inequality:
f(x) - f* <= |grad f(x)|^2 / (2 mu) at every x (f* the minimum; PEPit's
SmoothQuadraticLojasiewiczFunctionCheap without its ``alpha``, the conditions of its
``gradient_descent_quadratic_lojasiewicz_naive`` example).

Conditions (PEPit's "naive" set): L-smoothness between every ordered pair (the
interpolation inequality of the ``smooth`` class at m = -L, x* included), and between each
point and x* (a stationary point of value f*)

    2 mu (f* - f_a) + |g_a|^2 >= 0,        2L (f_a - f*) - |g_a|^2 >= 0.

They are necessary, not sufficient for interpolation (``interpolating`` False): a PEP over
them is an **upper bound** of the worst case over the class, not tight (PEPit's
"intermediate" set adds pairwise conditions mixing f* with two points, its "expensive"
set a 2 x 2 LMI per pair; neither is a pairwise difference inequality, so this class
implements the naive set only). The class is not convex; its PEP keeps x*
(``minimizer``: every stationary point is a global minimizer). The PL inequality is about
f itself: the only function of its spec (``alone``).

No Lyapunov family of ``analyze`` takes it (``homogeneous`` False): ``analyze`` refuses
the class; ``sosalgo pep`` answers (specs/gradient-pl.yaml).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, check_mu_below_L
from sosalgo.classes.smooth_strongly_convex import interpolation_matrix


def gradient_square_form(sign: int) -> np.ndarray:
    """Q of ``sign |g_a|^2`` on (x_a, x_b, g_a, g_b)."""
    Q = np.full((4, 4), Fraction(0), dtype=object)
    Q[2, 2] = Fraction(sign)
    return Q


class SmoothLojasiewicz(FunctionClass):
    name = "smooth_lojasiewicz"
    description = ("L-smooth with f - f* <= |grad f|^2/(2 mu) (Polyak-Lojasiewicz; "
                   "necessary conditions: an upper bound, not tight)")
    parameters = ("mu", "L")
    defaults = {"mu": "m", "L": "L"}
    oracles = frozenset({"gradient"})
    finite_everywhere = True
    convex = False
    minimizer = True
    tilt_invariant = False
    homogeneous = False
    alone = True
    interpolating = False
    tilted_text = ("L-smooth (every pair, x* included); |g_a|^2/(2L) <= h_a <= "
                   "|g_a|^2/(2 mu) (every point)",
                   r"L\text{-smooth};\quad \frac{\|g_a\|^2}{2L} \le h_a \le "
                   r"\frac{\|g_a\|^2}{2\mu}")

    def check(self, params: Mapping[str, float]) -> None:
        check_mu_below_L(params)

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        mu, L = float(params["mu"]), float(params["L"])
        smooth = 0.5 * np.array(interpolation_matrix(-L, L), dtype=float)
        return [Inequality(2.0 * L, smooth),
                Inequality(-2.0 * mu, gradient_square_form(1).astype(float), 0.0, "optimum"),
                Inequality(2.0 * L, gradient_square_form(-1).astype(float), 0.0, "optimum")]

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        return self.inequalities(params)  # the only function: s* = 0 (``alone``)

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        mu, L = params["mu"], params["L"]
        h = Fraction(1, 2)
        rows = interpolation_matrix(-L, L)
        smooth = np.array([[v * h for v in row] for row in rows], dtype=object)
        return [(2 * L, smooth), (-2 * mu, gradient_square_form(1)),
                (2 * L, gradient_square_form(-1))]

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any]:
        return [Fraction(0)] * 3


CLASS = SmoothLojasiewicz()
