"""Skew-symmetric linear operators with |M| <= L (PEPit's SkewSymmetricLinearOperator;
monotone): calls u = M y and the resolvent (I + tM)^-1.

Interpolation (Bousselmi, Hendrickx, Glineur, "Interpolation conditions for linear
operators and applications to performance estimation problems", Cor. 3.2): data
(x_a, u_a) are those of such an M if and only if

    <u_a, x_b> = -<u_b, x_a>   (every pair, and <u_a, x_a> = 0 at every point)   and
    T[a, b] = L^2 <x_a, x_b> - <u_a, u_b>  ⪰ 0.

On the tilted data (x - x*, M x - M x*): the affine maps x -> M x + c, which contain the
linear ones. ``pep`` answers; no Lyapunov family takes the matrix condition.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import Inequality
from sosalgo.classes.linear_operator import norm_block
from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, positive, skew_unit


def skew_forms(zero: Any) -> list[np.ndarray]:
    """Q of <u_a, x_b> + <u_b, x_a> (>= 0; the reversed pair is the same form, so each
    pair gives it twice: with ``diagonal_forms`` its negative too) and of +-<u_a, x_a>,
    on (x_a, x_b, u_a, u_b)."""
    h = Fraction(1, 2) + zero
    Q = np.full((4, 4), zero, dtype=object)
    Q[1, 2] = Q[2, 1] = h
    Q[0, 3] = Q[3, 0] = h
    out = [Q, -Q]
    for sign in (1, -1):
        D = np.full((4, 4), zero, dtype=object)
        D[0, 2] = D[2, 0] = h * sign
        out.append(D)
    return out


class SkewSymmetricLinearOperator(OperatorClass):
    name = "skew_symmetric_linear_operator"
    description = "skew-symmetric linear operator, |M| <= L (calls: M(y), resolvent)"
    parameters = ("L",)
    defaults = {"L": "L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True
    transposable = True  # M' = -M: calls of M' are calls of M, negated
    transpose_sign = -1
    homogeneous = False  # a Gram-level (matrix) condition: no Lyapunov family takes it
    tilted_text = ("<u_a, x_b> = -<u_b, x_a>, <u_a, x_a> = 0, "
                   "[L^2 <x_a, x_b> - <u_a, u_b>]_(a,b) PSD",
                   r"\langle u_a, x_b\rangle = -\langle u_b, x_a\rangle,\ \langle u_a, x_a"
                   r"\rangle = 0,\ \big[L^2 \langle x_a, x_b\rangle - \langle u_a, u_b"
                   r"\rangle\big]_{a,b} \succeq 0")

    def check(self, params: Mapping[str, float]) -> None:
        positive(params, "L")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        forms = skew_forms(0.0)
        return ([Inequality(0.0, Q.astype(float)) for Q in forms[:2]]
                + [Inequality(0.0, Q.astype(float), scope="optimum") for Q in forms[2:]])

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(0), Q) for Q in skew_forms(Fraction(0))]

    def blocks(self, params: Mapping[str, float]) -> list[np.ndarray]:
        return [norm_block(float(params["L"])).astype(float)]

    def exact_blocks(self, params: Mapping[str, Any]) -> list[np.ndarray]:
        return [norm_block(params["L"])]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (0.0, 0.0)  # the zero operator (q I is skew only for q = 0)

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (Fraction(0), Fraction(0))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d, L = len(xs), params["L"]
        return [linear_member(L * skew_unit(d, rng), xs, rng, "L*K",
                              "skew, singular values L")]


CLASS = SkewSymmetricLinearOperator()
