"""Symmetric linear operators with spectrum in [mu, L], 0 <= mu <= L (PEPit's
SymmetricLinearOperator, monotone): calls u = M y and the resolvent (I + tM)^-1.

Interpolation (Bousselmi, Hendrickx, Glineur, "Interpolation conditions for linear
operators and applications to performance estimation problems", Thm. 3.3): data
(x_a, u_a) are those of such an M if and only if

    <u_a, x_b> = <u_b, x_a>   (every pair)   and
    T[a, b] = (L + mu) <u_a, x_b> - <u_a, u_b> - mu L <x_a, x_b>  ⪰ 0,

the gradients of the quadratics of :mod:`sosalgo.classes.smooth_strongly_convex_quadratic`
without their values. On the tilted data (x - x*, M x - M x*): the affine maps
x -> M x + c (the same as the linear ones for mu > 0: M is invertible). ``pep`` answers;
no Lyapunov family takes the matrix condition.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import Inequality, check_mu_below_L
from sosalgo.classes.members import ProxFunction
from sosalgo.classes.operator import OperatorClass, linear_member, rotation
from sosalgo.classes.smooth_strongly_convex_quadratic import spectrum_block, symmetry_form


class SymmetricLinearOperator(OperatorClass):
    name = "symmetric_linear_operator"
    description = "symmetric linear operator, spectrum in [mu, L] (calls: M(y), resolvent)"
    parameters = ("mu", "L")
    defaults = {"mu": "m", "L": "L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True
    transposable = True  # M' = M: calls of M' are calls of M
    transpose_sign = 1
    homogeneous = False  # a Gram-level (matrix) condition: no Lyapunov family takes it
    tilted_text = ("<u_a, x_b> = <u_b, x_a>, [(L + mu) <u_a, x_b> - <u_a, u_b> "
                   "- mu L <x_a, x_b>]_(a,b) PSD",
                   r"\langle u_a, x_b\rangle = \langle u_b, x_a\rangle,\ \big[(L + \mu)"
                   r"\langle u_a, x_b\rangle - \langle u_a, u_b\rangle - \mu L"
                   r"\langle x_a, x_b\rangle\big]_{a,b} \succeq 0")

    def check(self, params: Mapping[str, float]) -> None:
        check_mu_below_L(params, zero=True)

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(0.0, symmetry_form(0.0).astype(float))]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(0), symmetry_form(Fraction(0)))]

    def blocks(self, params: Mapping[str, float]) -> list[np.ndarray]:
        return [spectrum_block(float(params["mu"]), float(params["L"])).astype(float)]

    def exact_blocks(self, params: Mapping[str, Any]) -> list[np.ndarray]:
        return [spectrum_block(params["mu"], params["L"])]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return (params["mu"], params["L"])

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return (upper("mu"), lower("L"))

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        d, mu, L = len(xs), params["mu"], params["L"]
        R = rotation(d, rng)
        q = rng.uniform(mu, L, d)
        q[0], q[-1] = mu, L
        return [linear_member((R * q) @ R.T, xs, rng, "symmetric",
                              "symmetric, eigenvalues in [mu, L]")]


CLASS = SymmetricLinearOperator()
