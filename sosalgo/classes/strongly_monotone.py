"""mu-strongly monotone, maximally monotone operators:
<u_a - u_b, x_a - x_b> >= mu |x_a - x_b|^2.

Interpolation: M is mu-strongly monotone iff M - mu I is monotone, so the monotone
interpolation theorem applies (Ryu, Taylor, Bergeling, Giselsson 2020, Prop. 2): exact.
Calls: an element of M(y), the resolvent J_{tM} (a contraction by 1/(1 + t mu)).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, positive, skew_unit


class StronglyMonotone(OperatorClass):
    name = "strongly_monotone"
    pairwise_defined = True  # its members: the operators meeting its pairwise conditions
    description = "mu-strongly monotone maximally monotone operator (calls: M(y), resolvent)"
    parameters = ("mu",)
    defaults = {"mu": "m"}
    oracles = frozenset({"subgradient", "proximal"})
    tilted_text = ("<u_a - u_b, x_a - x_b> >= mu |x_a - x_b|^2",
                   r"\langle u_a - u_b, x_a - x_b\rangle \ge \mu \|x_a - x_b\|^2")

    def check(self, params: Mapping[str, float]) -> None:
        positive(params, "mu")

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        return [(Fraction(1), -params["mu"], Fraction(0))]



    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (params["mu"], params["mu"])  # q I with q >= mu

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (upper("mu"), upper("mu"))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d, mu = len(xs), params["mu"]
        P = rng.standard_normal((d, d))
        return [linear_member(mu * np.eye(d) + 3 * mu * skew_unit(d, rng), xs, rng,
                              "mu+skew", "mu I plus skew: <Mx, x> = mu |x|^2"),
                linear_member(mu * np.eye(d) + 0.3 * P @ P.T, xs, rng, "mu+psd",
                              "mu I plus positive semidefinite")]


CLASS = StronglyMonotone()
