"""Maximally monotone operators: <u_a - u_b, x_a - x_b> >= 0.

Interpolation: a finite set of pairs (x_i, u_i) satisfying the condition pairwise is the
restriction of a maximally monotone operator (Zorn's lemma / Minty; Bauschke and
Combettes 2017, Thm. 20.21; Ryu, Taylor, Bergeling, Giselsson 2020, "Operator splitting
performance estimation: tight contraction factors and optimal parameter selection",
Prop. 2): a PEP over this class is exact. Calls: an element of M(y) at a point of the
method (set-valued: no evaluation where the method does not query it), the resolvent
J_{tM}.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, skew_unit


class Monotone(OperatorClass):
    name = "monotone"
    pairwise_defined = True  # its members: the operators meeting its pairwise conditions
    state_change_rates = True  # Douglas-Rachford on two of them: the state change
    description = "maximally monotone operator (calls: M(y), resolvent)"
    oracles = frozenset({"subgradient", "proximal"})
    tilted_text = ("<u_a - u_b, x_a - x_b> >= 0  (monotone operator)",
                   r"\langle u_a - u_b, x_a - x_b\rangle \ge 0")

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        return [(Fraction(1), Fraction(0), Fraction(0))]



    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (0.0, 0.0)  # the zero operator

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (Fraction(0), Fraction(0))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d = len(xs)
        P = rng.standard_normal((d, d))
        return [linear_member(2 * skew_unit(d, rng), xs, rng, "rotation-generator",
                              "skew linear: <Mx, x> = 0"),
                linear_member(0.3 * P @ P.T + skew_unit(d, rng), xs, rng, "psd+skew",
                              "positive semidefinite plus skew")]


CLASS = Monotone()
