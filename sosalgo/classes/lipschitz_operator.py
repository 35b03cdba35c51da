"""L-Lipschitz operators (not necessarily monotone): |u_a - u_b| <= L |x_a - x_b|.

Interpolation: the Kirszbraun-Valentine theorem (Kirszbraun 1934; Valentine 1943; Ryu,
Taylor, Bergeling, Giselsson 2020, Prop. 2): pairwise data extend to an L-Lipschitz map
of the whole space, so a PEP over this class is exact. Calls: the evaluation M(y) only
(a resolvent needs monotonicity).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, positive, rotation


class LipschitzOperator(OperatorClass):
    name = "lipschitz_operator"
    pairwise_defined = True  # its members: the operators meeting its pairwise conditions
    description = "L-Lipschitz operator, not necessarily monotone (calls: M(y))"
    parameters = ("L",)
    defaults = {"L": "L"}
    oracles = frozenset({"gradient"})
    finite_everywhere = True
    tilted_text = ("|u_a - u_b|^2 <= L^2 |x_a - x_b|^2",
                   r"\|u_a - u_b\|^2 \le L^2 \|x_a - x_b\|^2")

    def check(self, params: Mapping[str, float]) -> None:
        positive(params, "L")

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        L = params["L"]
        return [(Fraction(0), L * L, Fraction(-1))]



    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (-params["L"], params["L"])  # q I with |q| <= L

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (-lower("L"), lower("L"))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d, L = len(xs), params["L"]
        return [linear_member(L * rotation(d, rng), xs, rng, "L*Q", "L times orthogonal",
                              resolvent=False),
                linear_member(-L * np.eye(d), xs, rng, "-L*I", "antimonotone, L-Lipschitz",
                              resolvent=False)]


CLASS = LipschitzOperator()
