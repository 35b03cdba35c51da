"""L-Lipschitz, mu-strongly monotone operators (mu = 0: Lipschitz and monotone):
<u_a - u_b, x_a - x_b> >= mu |x_a - x_b|^2 and |u_a - u_b| <= L |x_a - x_b|.

Not known to interpolate: the two pairwise conditions are necessary, and no finite set of
conditions is known to be sufficient (Ryu, Taylor, Bergeling, Giselsson 2020, Section
3.2; PEPit's LipschitzStronglyMonotoneOperatorCheap). A PEP over them maximizes over a
larger set than the class: its value is an upper bound of the worst case (still a proof),
tightness is not claimed. Calls: the evaluation M(y), the resolvent (M is maximally
monotone and continuous).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import check_mu_below_L
from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, skew_unit


class LipschitzStronglyMonotone(OperatorClass):
    name = "lipschitz_strongly_monotone"
    pairwise_defined = True  # its members: the operators meeting its pairwise conditions
    interpolating = False  # necessary conditions: the PEP is an upper bound
    description = ("L-Lipschitz mu-strongly monotone operator (necessary conditions: "
                   "upper bounds, not known tight)")
    parameters = ("mu", "L")
    defaults = {"mu": "m", "L": "L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True
    tilted_text = ("<u_a - u_b, x_a - x_b> >= mu |x_a - x_b|^2 and |u_a - u_b| <= L |x_a - "
                   "x_b| (necessary, not known to interpolate)",
                   r"\langle u_a - u_b, x_a - x_b\rangle \ge \mu \|x_a - x_b\|^2,\ "
                   r"\|u_a - u_b\| \le L \|x_a - x_b\|\ \text{(necessary)}")

    def check(self, params: Mapping[str, float]) -> None:
        check_mu_below_L(params, zero=True)

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        mu, L = params["mu"], params["L"]
        return [(Fraction(1), -mu, Fraction(0)), (Fraction(0), L * L, Fraction(-1))]



    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (params["mu"], params["L"])  # q I with mu <= q <= L

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (upper("mu"), lower("L"))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d, mu, L = len(xs), params["mu"], params["L"]
        w = float(np.sqrt(max(L * L - mu * mu, 0.0)))
        return [linear_member(mu * np.eye(d) + w * skew_unit(d, rng), xs, rng, "mu+skew",
                              "mu I plus skew, |M| = L"),
                linear_member(L * np.eye(d), xs, rng, "L*I", "L I")]


CLASS = LipschitzStronglyMonotone()
