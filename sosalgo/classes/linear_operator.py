"""Linear operators M with |M| <= L (spectral norm; PEPit's LinearOperator, without its
transpose calls): calls u = M y.

Interpolation (Bousselmi, Hendrickx, Glineur, "Interpolation conditions for linear
operators and applications to performance estimation problems", Thm. 3.1 with no points
of M'): data (x_a, u_a) are those of a linear M with |M| <= L if and only if the matrix

    T[a, b] = L^2 <x_a, x_b> - <u_a, u_b>  ⪰ 0

over all the points (it makes the u's a linear image of the x's, of norm at most L). A
Gram-level condition only (:meth:`blocks`; no pairwise inequality), on the tilted data
(x - x*, M x - M x*): the class is that of the affine maps x -> M x + c with |M| <= L,
which contains the linear ones (the same when M is the only operator and x* its zero).
With calls of the transpose M' too (``{function: M, transpose: true}``), the data of
both are interpolated together (Thm. 3.1: <x_a, M' u_b> = <M x_a, u_b> and the same block
over M' 's points; :mod:`sosalgo.worstcase.adjoint`). ``pep`` answers; no Lyapunov
family takes the matrix condition.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import Inequality
from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, positive, rotation


def norm_block(L: Any) -> np.ndarray:
    """K of T[a, b] = L^2 <x_a, x_b> - <u_a, u_b>."""
    return np.array([[L * L, 0 * L], [0 * L, Fraction(-1) + 0 * L]], dtype=object)


class LinearOperator(OperatorClass):
    name = "linear_operator"
    description = "linear operator with |M| <= L (calls: M(y))"
    parameters = ("L",)
    defaults = {"L": "L"}
    oracles = frozenset({"gradient"})
    finite_everywhere = True
    transposable = True  # calls of M^T (:mod:`sosalgo.worstcase.adjoint`)
    homogeneous = False  # a Gram-level (matrix) condition: no Lyapunov family takes it
    tilted_text = ("[L^2 <x_a, x_b> - <u_a, u_b>]_(a,b) PSD",
                   r"\big[L^2 \langle x_a, x_b\rangle - \langle u_a, u_b\rangle\big]_{a,b}"
                   r" \succeq 0")

    def check(self, params: Mapping[str, float]) -> None:
        positive(params, "L")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return []

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return []

    def blocks(self, params: Mapping[str, float]) -> list[np.ndarray]:
        return [norm_block(float(params["L"])).astype(float)]

    def exact_blocks(self, params: Mapping[str, Any]) -> list[np.ndarray]:
        return [norm_block(params["L"])]

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
                linear_member(-L * np.eye(d), xs, rng, "-L*I", "|M| = L", resolvent=False)]


CLASS = LinearOperator()
