"""beta-cocoercive operators: <u_a - u_b, x_a - x_b> >= beta |u_a - u_b|^2 (single
valued, 1/beta-Lipschitz, maximally monotone; the gradients of convex 1/beta-smooth
functions are among them, the class is larger).

Interpolation: M is beta-cocoercive iff M^{-1} - beta I is monotone, so the monotone
interpolation theorem applies (Ryu, Taylor, Bergeling, Giselsson 2020, Prop. 2): exact.
Calls: the evaluation M(y) (anywhere: M is defined everywhere), the resolvent J_{tM}.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, positive, rotation


class Cocoercive(OperatorClass):
    name = "cocoercive"
    pairwise_defined = True  # its members: the operators meeting its pairwise conditions
    description = "beta-cocoercive operator (calls: M(y), resolvent)"
    parameters = ("beta",)
    defaults = {"beta": "1/L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True
    tilted_text = ("<u_a - u_b, x_a - x_b> >= beta |u_a - u_b|^2",
                   r"\langle u_a - u_b, x_a - x_b\rangle \ge \beta \|u_a - u_b\|^2")

    def check(self, params: Mapping[str, float]) -> None:
        positive(params, "beta")

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        return [(Fraction(1), Fraction(0), -params["beta"])]



    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (0.0, 1.0 / params["beta"])  # q I with 0 <= q <= 1/beta

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (Fraction(0), 1 / upper("beta"))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d, beta = len(xs), params["beta"]
        R = rotation(d, rng)
        # 0.9 (I + Q)/(2 beta): <Mv, v> = (beta/0.9) |Mv|^2 for Q orthogonal, near the
        # boundary but not on it (at gamma = beta a step would land exactly on x*)
        return [linear_member(0.9 * (np.eye(d) + rotation(d, rng)) / (2 * beta), xs, rng,
                              "0.9(I+Q)/(2 beta)", "<Mv, v> = beta/0.9 |Mv|^2, Q orthogonal"),
                linear_member((R * rng.uniform(0, 1 / beta, d)) @ R.T, xs, rng,
                              "symmetric", "symmetric, eigenvalues in [0, 1/beta]")]


CLASS = Cocoercive()
