"""Convex M-Lipschitz functions: closed, proper, convex f on R^d with every subgradient
bounded, |g| <= M (PEPit's ConvexLipschitzFunction).

Interpolation (Taylor, Hendrickx, Glineur 2017, "Exact worst-case performance of
first-order methods for composite convex optimization", Thm. 3.5): data (x_i, g_i, f_i)
are interpolated by a convex M-Lipschitz function if and only if

    f_a >= f_b + <g_b, x_a - x_b>   for every ordered pair,   |g_a|^2 <= M^2 for every point,

so a PEP over these conditions is exact. The bound on |g| is inhomogeneous (a constant
M^2: the worst case is not scale invariant, it is the one under ``initial <= 1``) and a
condition on each point alone (scope "optimum": the pair (a, x*), with Q on g_a only).
It bounds the function itself, not f - <s*, .>: the PEP takes the class as the only
function of its spec (then s* = 0, the tilted data are the function's own; ``alone``).

No Lyapunov family of ``analyze`` takes an inhomogeneous condition (``homogeneous``
False): ``analyze`` refuses the class; ``sosalgo pep`` answers (the subgradient method:
``specs/subgradient.yaml``, measure ``minf``).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form, exact_convex_form


def gradient_norm_form() -> np.ndarray:
    """Q of ``-|g_a|^2`` on (x_a, x_b, g_a, g_b)."""
    Q = np.zeros((4, 4))
    Q[2, 2] = -1.0
    return Q


class ConvexLipschitz(FunctionClass):
    name = "convex_lipschitz"
    description = "convex, M-Lipschitz (every subgradient |g| <= M), possibly nonsmooth"
    parameters = ("M",)
    defaults = {"M": "L"}
    oracles = frozenset({"subgradient"})
    finite_everywhere = True
    tilt_invariant = False
    homogeneous = False
    alone = True
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b> (every pair);  |g_a|^2 <= M^2 (every "
                   "point)",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle,\quad \|g_a\|^2 \le M^2")

    def check(self, params: Mapping[str, float]) -> None:
        M = params["M"]
        if not (np.isfinite(M) and M > 0):
            raise ValueError(f"M: must be positive and finite, got {M:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        M = float(params["M"])
        return [Inequality(1.0, convex_form()),
                Inequality(0.0, gradient_norm_form(), M * M, "optimum")]

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        return self.inequalities(params)  # the only function: s* = 0 (``alone``)

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        Q = np.full((4, 4), Fraction(0), dtype=object)
        Q[2, 2] = Fraction(-1)
        return [(Fraction(1), exact_convex_form()), (Fraction(0), Q)]

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any]:
        M = params["M"]
        return [Fraction(0), M * M]


CLASS = ConvexLipschitz()
