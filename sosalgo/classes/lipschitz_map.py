"""Fixed-point residuals of L-Lipschitz maps: a call at y answers u = y - T(y) for a T
with |T x_a - T x_b| <= L |x_a - x_b| (contractive for L < 1, nonexpansive for L = 1); a
zero of u is a fixed point x* = T x*, as for :mod:`sosalgo.classes.nonexpansive` (the
case L = 1).

The condition on T is, in the residual (expand |(x_a - u_a) - (x_b - u_b)|^2 <=
L^2 |x_a - x_b|^2),

    <u_a - u_b, x_a - x_b> >= (1 - L^2)/2 |x_a - x_b|^2 + 1/2 |u_a - u_b|^2,

and every u meeting it is I - T for an L-Lipschitz T. Interpolation: Kirszbraun-Valentine
for T (Ryu, Taylor, Bergeling, Giselsson 2020, Prop. 2; PEPit's LipschitzOperator with a
fixed point): exact. The measure ``grad`` is |x - T x|^2 (PEPit's optimal contractive
Halpern iteration). Calls: the residual at any point.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, positive, rotation


class LipschitzMap(OperatorClass):
    name = "lipschitz_map"
    pairwise_defined = True  # its members: the operators meeting its pairwise conditions
    description = "residual u = y - T y of an L-Lipschitz map T (calls: the residual)"
    parameters = ("L",)
    defaults = {"L": "1"}
    oracles = frozenset({"gradient"})
    finite_everywhere = True
    tilted_text = ("|T x_a - T x_b|^2 <= L^2 |x_a - x_b|^2 with u = x - T x: "
                   "<u_a - u_b, x_a - x_b> >= (1 - L^2)/2 |x_a - x_b|^2 + 1/2 |u_a - u_b|^2",
                   r"\|T x_a - T x_b\| \le L \|x_a - x_b\|,\ u = x - Tx:\ "
                   r"\langle u_a - u_b, x_a - x_b\rangle \ge \tfrac{1 - L^2}{2}"
                   r" \|x_a - x_b\|^2 + \tfrac12 \|u_a - u_b\|^2")

    def check(self, params: Mapping[str, float]) -> None:
        positive(params, "L")

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        L = params["L"]
        return [(Fraction(1), (L * L - 1) * Fraction(1, 2), Fraction(-1, 2))]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (1.0 - params["L"], 1.0 + params["L"])  # T = (1 - q) I with |1 - q| <= L

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (1 - lower("L"), 1 + lower("L"))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d, L = len(xs), params["L"]
        return [linear_member(np.eye(d) - L * rotation(d, rng), xs, rng, "I-L*Q",
                              "T = L Q, Q orthogonal", resolvent=False),
                linear_member((1 + L) * np.eye(d), xs, rng, "(1+L)I", "T = -L I",
                              resolvent=False)]


CLASS = LipschitzMap()
