"""Fixed-point residuals of nonexpansive maps: a call at y answers u = y - T(y) for a
T with |T x_a - T x_b| <= |x_a - x_b|; a zero of u is a fixed point x* = T x* (so the
problem 0 = u(x*) is the fixed-point problem, and a step x+ = (1 - theta) x + theta T x is
x+ = x - theta u: Krasnosel'skii-Mann).

The condition on T is, in the residual, <u_a - u_b, x_a - x_b> >= 1/2 |u_a - u_b|^2
(expand |(x_a - u_a) - (x_b - u_b)|^2 <= |x_a - x_b|^2): u is 1/2-cocoercive, and every
1/2-cocoercive u is I - T for a nonexpansive T. Interpolation: Kirszbraun-Valentine for
T (Ryu, Taylor, Bergeling, Giselsson 2020, Prop. 2): exact. The measure ``grad`` is
|x - T x|^2 (PEPit's Krasnosel'skii-Mann example measures 1/4 |x_N - T x_N|^2:
``1/4*grad``). Calls: the residual at any point.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, rotation


class Nonexpansive(OperatorClass):
    name = "nonexpansive"
    pairwise_defined = True  # its members: the operators meeting its pairwise conditions
    description = "residual u = y - T y of a nonexpansive map T (calls: the residual)"
    oracles = frozenset({"gradient"})
    finite_everywhere = True
    tilted_text = ("|T x_a - T x_b|^2 <= |x_a - x_b|^2 with u = x - T x: "
                   "<u_a - u_b, x_a - x_b> >= 1/2 |u_a - u_b|^2",
                   r"\|T x_a - T x_b\| \le \|x_a - x_b\|,\ u = x - Tx:\ "
                   r"\langle u_a - u_b, x_a - x_b\rangle \ge \tfrac12 \|u_a - u_b\|^2")

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        return [(Fraction(1), Fraction(0), Fraction(-1, 2))]



    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (0.0, 2.0)  # T = (1 - q) I with |1 - q| <= 1

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (Fraction(0), Fraction(2))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d = len(xs)
        return [linear_member(np.eye(d) - rotation(d, rng), xs, rng, "I-Q",
                              "T = Q orthogonal (an isometry)", resolvent=False),
                linear_member(2 * np.eye(d), xs, rng, "2I", "T = -I (a reflection)",
                              resolvent=False)]


CLASS = Nonexpansive()
