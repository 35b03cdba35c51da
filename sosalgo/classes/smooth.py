"""L-smooth functions, possibly nonconvex: F(m, L) with -L <= m < 0 (m = -L: every
L-smooth function; -L < m < 0: hypoconvex, f - (m/2)|x|^2 convex).

Interpolation: the inequality of F(m, L) holds for m < 0 too, scaled by L - m,

    (L - m)(f_a - f_b) + 1/2 X' MM X >= 0,

i.e. f_a >= f_b + <g_b, x_a - x_b> + |g_a - g_b|^2 / (2(L - m)) + m L |x_a - x_b|^2 /
(2(L - m)) - m <g_a - g_b, x_a - x_b> / (L - m); at m = -L it reads f_a - f_b >= -L/4
|x_a - x_b|^2 + 1/2 <g_a + g_b, x_a - x_b> + |g_a - g_b|^2 / (4L) (Taylor, Hendrickx,
Glineur 2017, "Exact worst-case performance of first-order methods for composite convex
optimization", Thm. 3.10; for the hypoconvex range, Rotaru, Glineur, Patrinos 2022,
"Tight convergence rates of the gradient method on smooth hypoconvex functions"). These
are necessary and sufficient: a PEP over this class is exact.

The PEP keeps a point x* with gradient 0 where h = f - f* = 0 and h >= 0 at the points
(:mod:`sosalgo.worstcase.structure`): for a nonconvex class x* is then a stationary point below
the points, not provably a global minimizer, so a measure that involves f* or x* (f - f*,
dist) is bounded over a larger set than the functions with a global minimizer (still an
upper bound). A measure and initial condition free of f* and x* (gradient norms,
f(x_0) - f(x_N)) are unaffected: a stationary point far away and low enough can always be
added to interpolable data.

No Lyapunov family certifies rates on a nonconvex class (``convex`` False): ``analyze``
refuses it; ``sosalgo pep`` answers. Test functions: quadratics with curvatures in
[m, L] (a concave direction among them), a separable m/2 z^2 + (L - m) H_delta(z).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality
from sosalgo.classes.members import ProxFunction, curvature_members
from sosalgo.classes.smooth_strongly_convex import interpolation_matrix


class Smooth(FunctionClass):
    name = "smooth"
    description = "L-smooth, possibly nonconvex, curvature >= m (m = -L: every L-smooth f)"
    parameters = ("m", "L")
    defaults = {"m": "-L", "L": "L"}
    oracles = frozenset({"gradient"})
    finite_everywhere = True
    convex = False
    tilted_text = (
        "h_a >= h_b + <g_b, x_a - x_b> + |g_a - g_b|^2/(2(L - m))"
        " + m L |x_a - x_b|^2/(2(L - m)) - m <g_a - g_b, x_a - x_b>/(L - m)   (m < 0)",
        r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle + \frac{\|g_a - g_b\|^2}{2(L - m)}"
        r" + \frac{m L\,\|x_a - x_b\|^2}{2(L - m)} - \frac{m\,\langle g_a - g_b,"
        r" x_a - x_b\rangle}{L - m}\quad (m < 0)")

    def check(self, params: Mapping[str, float]) -> None:
        m, L = params["m"], params["L"]
        if not (np.isfinite(L) and L > 0):
            raise ValueError(f"L: must be positive and finite, got {L:g}")
        if not (np.isfinite(m) and -L <= m < 0):
            raise ValueError(f"m: must be in [-L, 0) = [{-L:g}, 0) (m >= 0: use a convex "
                             f"class), got {m:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        m, L = params["m"], params["L"]
        return [Inequality(L - m, 0.5 * np.array(interpolation_matrix(m, L), dtype=float))]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        m, L = params["m"], params["L"]
        h = Fraction(1, 2)
        rows = interpolation_matrix(m, L)
        return [(L - m, np.array([[v * h for v in row] for row in rows], dtype=object))]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return params["m"], params["L"]

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return upper("m"), lower("L")  # an inner interval: every q in it is in [m, L]

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        return curvature_members(params["m"], params["L"], xs, rng, "indefinite-quadratic")


CLASS = Smooth()
