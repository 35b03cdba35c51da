"""L-smooth convex functions whose gradients are also bounded, |grad f| <= M (PEPit's
SmoothConvexLipschitzFunction).

Conditions (those PEPit imposes): the interpolation inequality of L-smooth convex
functions between every ordered pair (Taylor, Hendrickx, Glineur 2017, Thm. 4 with
m = 0) and |g_a|^2 <= M^2 at every point (an inhomogeneous condition, scope "optimum" with
Q on g_a only, as for ``convex_lipschitz``). They are necessary; they are not known to be
sufficient for interpolation (``interpolating`` False): a PEP over them is an upper bound
of the worst case, not necessarily tight. The bound on |g| is about f itself: the only
function of its spec (``alone``).

No Lyapunov family of ``analyze`` takes the constant (``homogeneous`` False): ``analyze``
refuses the class; ``sosalgo pep`` answers.
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality
from sosalgo.classes.convex_lipschitz import gradient_norm_form
from sosalgo.classes.smooth_strongly_convex import interpolation_matrix


class SmoothConvexLipschitz(FunctionClass):
    name = "smooth_convex_lipschitz"
    description = ("L-smooth convex with |grad f| <= M (necessary conditions: an upper "
                   "bound, not known to be tight)")
    parameters = ("L", "M")
    defaults = {"L": "L", "M": "L"}
    oracles = frozenset({"gradient"})
    finite_everywhere = True
    tilt_invariant = False
    homogeneous = False
    alone = True
    interpolating = False
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b> + |g_a - g_b|^2/(2L) (every pair);  "
                   "|g_a|^2 <= M^2 (every point)",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle + \frac{\|g_a - g_b\|^2}"
                   r"{2L},\quad \|g_a\|^2 \le M^2")

    def check(self, params: Mapping[str, float]) -> None:
        for key in ("L", "M"):
            v = params[key]
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{key}: must be positive and finite, got {v:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        L, M = float(params["L"]), float(params["M"])
        smooth = 0.5 * np.array(interpolation_matrix(0.0, L), dtype=float)
        return [Inequality(L, smooth),
                Inequality(0.0, gradient_norm_form(), M * M, "optimum")]

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        return self.inequalities(params)  # the only function: s* = 0 (``alone``)

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        L = params["L"]
        h = Fraction(1, 2)
        rows = interpolation_matrix(0 * L, L)
        Q = np.full((4, 4), Fraction(0), dtype=object)
        Q[2, 2] = Fraction(-1)
        return [(L, np.array([[v * h for v in row] for row in rows], dtype=object)),
                (Fraction(0), Q)]

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any]:
        M = params["M"]
        return [Fraction(0), M * M]


CLASS = SmoothConvexLipschitz()
