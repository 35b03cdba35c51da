"""L-smooth functions with a quadratic Lojasiewicz (PL) inequality, PEPit's
"expensive" conditions (SmoothQuadraticLojasiewiczFunctionExpensive, Rubbens,
Hendrickx, Taylor 2025, Prop. 3.4; the
``gradient_descent_quadratic_lojasiewicz_expensive`` example).

|g_a|^2/(2L) <= f_a - f* <= |g_a|^2/(2 mu) at every point, and for every ordered pair
(i, j) of distinct points (x* included) two 2 x 2 LMIs sharing two free multipliers
M12, M22: with

    A = f_j - f_i + <g_i + g_j, x_i - x_j>/2 + |g_i - g_j|^2/(4L) - L/4 |x_i - x_j|^2,
    B = (L + mu)(f_i - f* - |g_i|^2/(2L)),  C = (L - mu)(f_j - f* + |g_j|^2/(2L)),
    D = B - C - (L + 3 mu) A,  M11 = -(2L + mu) A,

    [[M11 - 4 mu/(2L + mu) M12 - D, M12 - mu/(2L + mu) M22 - (L + mu)/2 A + B],
     [.,                            M22 - B]] ⪰ 0,     [[M11, M12], [M12, M22]] ⪰ 0.

Written here as one block-diagonal 4 x 4 LMI on (i, j, x*) (:class:`TupleLMI`), every
entry times 4L and the first block times 2L + mu (no division by a parameter). The
conditions are necessary, not sufficient for interpolation (``interpolating`` False):
the PEP is an **upper bound** of the worst case over the class, not tight. The
smoothness is in the LMIs (no pairwise smoothness inequality, as PEPit's).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from sosalgo.classes.base import Inequality, TupleLMI
from sosalgo.classes.lmi_forms import Tuple
from sosalgo.classes.smooth_lojasiewicz import SmoothLojasiewicz, gradient_square_form


def expensive_lmi(mu: Any, L: Any, exact: bool) -> TupleLMI:
    """The two 2 x 2 LMIs of a pair (i, j) with x*, block diagonal (floats or exact)."""
    t = Tuple(2, optimum=True)
    i, j, s = 0, 1, 2
    dx, dg = t.x(i) - t.x(j), t.g(i) - t.g(j)
    A = ((t.f(j) - t.f(i)) * (4 * L) + (t.g(i) + t.g(j)).dot(dx) * (2 * L) + dg.sq()
         - dx.sq() * (L * L))
    B = (t.f(i) - t.f(s)) * (4 * L * (L + mu)) - t.g(i).sq() * (2 * (L + mu))
    C = (t.f(j) - t.f(s)) * (4 * L * (L - mu)) + t.g(j).sq() * (2 * (L - mu))
    D = B - C - A * (L + 3 * mu)
    m11 = A * (-(2 * L + mu))
    m12, m22 = t.free(), t.free()
    w = 2 * L + mu
    n11 = (m11 - D) * w - m12 * (4 * mu)
    n12 = (m12 - A * ((L + mu) * Fraction(1, 2)) + B) * w - m22 * mu
    n22 = (m22 - B) * w
    return t.lmi([[n11, n12, 0, 0], [n12, n22, 0, 0], [0, 0, m11, m12], [0, 0, m12, m22]],
                 exact)


class SmoothLojasiewiczExpensive(SmoothLojasiewicz):
    name = "smooth_lojasiewicz_expensive"
    description = ("L-smooth with f - f* <= |grad f|^2/(2 mu), PEPit's expensive "
                   "conditions (2 x 2 LMIs per pair; necessary: an upper bound, not tight)")
    tilted_text = None

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        mu, L = float(params["mu"]), float(params["L"])
        return [Inequality(-2.0 * mu, gradient_square_form(1).astype(float), 0.0, "optimum"),
                Inequality(2.0 * L, gradient_square_form(-1).astype(float), 0.0, "optimum")]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(-2 * params["mu"], gradient_square_form(1)),
                (2 * params["L"], gradient_square_form(-1))]

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any]:
        return [Fraction(0)] * 2

    def lmis(self, params: Mapping[str, float]) -> list[TupleLMI]:
        return [expensive_lmi(float(params["mu"]), float(params["L"]), exact=False)]

    def exact_lmis(self, params: Mapping[str, Any]) -> list[TupleLMI]:
        return [expensive_lmi(params["mu"], params["L"], exact=True)]

    def listing_text(self, params: Mapping[str, float], latex: bool) -> str:
        return ("|g_a|^2/(2L) <= h_a <= |g_a|^2/(2 mu) (every point); two 2 x 2 LMIs "
                "with free multipliers on every pair with x* (Rubbens, Hendrickx, Taylor "
                "2025, Prop. 3.4)")


CLASS = SmoothLojasiewiczExpensive()
