"""beta-cocoercive, mu-strongly monotone operators with PEPit's "expensive" conditions
(CocoerciveStronglyMonotoneOperatorExpensive; Rubbens, Hendrickx, Taylor 2025, App. F;
the ``optimistic_gradient_refined_cocoercive`` example).

The pairwise conditions <u_a - u_b, x_a - x_b> >= beta |u_a - u_b|^2 and >= mu |x_a -
x_b|^2, and for every ordered triple (i, j, k) of the operator's points (x* included)
that are not all the same point, two 7 x 7 LMIs with nine free multipliers each
(:func:`~sosalgo.classes.lmi_forms.three_point_lmi`), with

    A_ab = mu |x_a - x_b|^2 - <u_a - u_b, x_a - x_b>,
    B_ab = beta |u_a - u_b|^2 - <u_a - u_b, x_a - x_b>,

the one with (A, B) and the other with (B, A) in their places, centre coefficient
-2 (1 - 2 beta mu). Necessary, not known sufficient for interpolation when mu > 0: a PEP
over them is an **upper bound** of the worst case over the class, not known tight.
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import TupleLMI
from sosalgo.classes.lmi_forms import three_point_lmis
from sosalgo.classes.operator import OperatorClass, positive


def cocoercive_lmis(mu: Any, beta: Any, exact: bool) -> list[TupleLMI]:
    """The two LMIs of a triple (floats or exact numbers): A the strong monotonicity, B
    the cocoercivity form of each pair."""
    return three_point_lmis(lambda dx, du: (dx.sq() * mu - du.dot(dx),
                                            du.sq() * beta - du.dot(dx)),
                            (1 - 2 * beta * mu) * (-2), exact)


class CocoerciveStronglyMonotoneExpensive(OperatorClass):
    name = "cocoercive_strongly_monotone_expensive"
    description = ("beta-cocoercive mu-strongly monotone operator, PEPit's expensive "
                   "conditions (7 x 7 LMIs per triple; necessary: an upper bound, not "
                   "known tight)")
    parameters = ("mu", "beta")
    defaults = {"mu": "m", "beta": "1/L"}
    oracles = frozenset({"gradient", "proximal"})
    finite_everywhere = True
    homogeneous = False  # no Lyapunov family takes the LMIs: ``pep`` answers
    interpolating = False
    tilted_text = ("<u_a - u_b, x_a - x_b> >= beta |u_a - u_b|^2 and >= mu |x_a - x_b|^2, "
                   "and two 7 x 7 LMIs per triple (necessary)",
                   r"\langle u_a - u_b, x_a - x_b\rangle \ge \max(\beta \|u_a - u_b\|^2, "
                   r"\mu \|x_a - x_b\|^2),\ \text{two LMIs per triple (necessary)}")

    def check(self, params: Mapping[str, float]) -> None:
        positive(params, "beta")
        mu, beta = params["mu"], params["beta"]
        if not (np.isfinite(mu) and 0 <= mu <= 1 / beta):
            raise ValueError(f"mu: must be in [0, 1/beta] = [0, {1 / beta:g}], got {mu:g}")

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        return [(Fraction(1), Fraction(0), -params["beta"]),
                (Fraction(1), -params["mu"], Fraction(0))]

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float] | None:
        lo, hi = params["mu"], 1.0 / params["beta"]
        return (lo, hi) if lo <= hi else None

    def lmis(self, params: Mapping[str, float]) -> list[TupleLMI]:
        return cocoercive_lmis(float(params["mu"]), float(params["beta"]), exact=False)

    def exact_lmis(self, params: Mapping[str, Any]) -> list[TupleLMI]:
        return cocoercive_lmis(params["mu"], params["beta"], exact=True)


CLASS = CocoerciveStronglyMonotoneExpensive()
