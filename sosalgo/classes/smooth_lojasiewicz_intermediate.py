"""L-smooth functions with a quadratic Lojasiewicz (PL) inequality, PEPit's
"intermediate" conditions (SmoothQuadraticLojasiewiczFunctionCheap with its ``alpha``,
Rubbens, Hendrickx, Taylor 2025, Prop. 3.2; the
``gradient_descent_quadratic_lojasiewicz_intermediate`` example).

The conditions of ``smooth_lojasiewicz`` (L-smoothness between every ordered pair, x*
included; |g_a|^2/(2L) <= f_a - f* <= |g_a|^2/(2 mu) at every point), and for every
ordered pair (i, j) of distinct points (x* included), with c = alpha / ((1 - alpha)
(2 mu - (L + mu) alpha)) and 0 <= alpha <= 2 mu / (2L + mu):

    f_i - f_j >= <g_i + g_j, x_i - x_j>/2 + |g_i - g_j|^2/(4L) - L/4 |x_i - x_j|^2
                 + c ((1 - alpha)^2 (L + mu)(f_i - f* - |g_i|^2/(2L))
                      - (L - mu)(f_j - f* + |g_j|^2/(2L))).

That condition involves three points (i, j and x*) with distinct value coefficients:
it is a 1 x 1 LMI on (i, j, x*) (:class:`~sosalgo.classes.base.TupleLMI`), written here
times 4L (1 - alpha)(2 mu - (L + mu) alpha) > 0. The conditions are necessary, not
sufficient for interpolation (``interpolating`` False): the PEP is an **upper bound**
of the worst case over the class, not tight.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sosalgo.classes.base import TupleLMI
from sosalgo.classes.lmi_forms import Tuple
from sosalgo.classes.smooth_lojasiewicz import SmoothLojasiewicz


def combined_lmi(mu: Any, L: Any, alpha: Any, exact: bool) -> TupleLMI:
    """The alpha condition on (i, j, x*) as a 1 x 1 LMI (floats or exact numbers)."""
    t = Tuple(2, optimum=True)
    i, j, s = 0, 1, 2
    one = 1 - alpha
    gap = 2 * mu - (L + mu) * alpha
    K = 4 * L * one * gap
    dx, dg = t.x(i) - t.x(j), t.g(i) - t.g(j)
    entry = ((t.f(i) - t.f(j)) * K - (t.g(i) + t.g(j)).dot(dx) * (2 * L * one * gap)
             - dg.sq() * (one * gap) + dx.sq() * (L * L * one * gap)
             - (t.f(i) - t.f(s)) * (4 * L * alpha * one * one * (L + mu))
             + t.g(i).sq() * (2 * alpha * one * one * (L + mu))
             + (t.f(j) - t.f(s)) * (4 * L * alpha * (L - mu))
             + t.g(j).sq() * (2 * alpha * (L - mu)))
    return t.lmi([[entry]], exact)


class SmoothLojasiewiczIntermediate(SmoothLojasiewicz):
    name = "smooth_lojasiewicz_intermediate"
    description = ("L-smooth with f - f* <= |grad f|^2/(2 mu), PEPit's intermediate "
                   "conditions (alpha; necessary: an upper bound, not tight)")
    parameters = ("mu", "L", "alpha")
    defaults = {"mu": "m", "L": "L", "alpha": "2*m/(2*L + m)"}
    tilted_text = None

    def check(self, params: Mapping[str, float]) -> None:
        super().check(params)
        mu, L, alpha = params["mu"], params["L"], params["alpha"]
        top = 2 * mu / (2 * L + mu)
        if not (0 <= alpha <= top):
            raise ValueError(f"alpha: must be in [0, 2 mu/(2L + mu)] = [0, {top:g}], "
                             f"got {alpha:g}")

    def lmis(self, params: Mapping[str, float]) -> list[TupleLMI]:
        return [combined_lmi(float(params["mu"]), float(params["L"]),
                             float(params["alpha"]), exact=False)]

    def exact_lmis(self, params: Mapping[str, Any]) -> list[TupleLMI]:
        return [combined_lmi(params["mu"], params["L"], params["alpha"], exact=True)]

    def listing_text(self, params: Mapping[str, float], latex: bool) -> str:
        return ("L-smooth; |g_a|^2/(2L) <= h_a <= |g_a|^2/(2 mu); and the alpha "
                "condition on every pair with x* (Rubbens, Hendrickx, Taylor 2025, "
                "Prop. 3.2)")


CLASS = SmoothLojasiewiczIntermediate()
