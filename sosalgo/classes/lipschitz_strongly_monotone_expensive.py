"""L-Lipschitz, mu-strongly monotone operators with PEPit's "expensive" conditions
(LipschitzStronglyMonotoneOperatorExpensive; Rubbens, Hendrickx, Taylor 2025, Prop.
3.15; the ``optimistic_gradient_refined`` example).

Besides the two pairwise conditions of ``lipschitz_strongly_monotone``, for every ordered
triple (i, j, k) of the operator's points (x* included) that are not all the same point,
two 7 x 7 LMIs with nine free multipliers each (:func:`~sosalgo.classes.lmi_forms.
three_point_lmi`), with

    A_ab = |u_a - u_b|^2 - L^2 |x_a - x_b|^2,
    B_ab = 2L (mu |x_a - x_b|^2 - <u_a - u_b, x_a - x_b>),

the one with (A, B) and the other with (B, A) in their places. They are necessary, not
known sufficient for interpolation: a PEP over them is an **upper bound** of the worst
case over the class, not known tight (tighter than the pairwise conditions alone).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sosalgo.classes.base import TupleLMI
from sosalgo.classes.lipschitz_strongly_monotone import LipschitzStronglyMonotone
from sosalgo.classes.lmi_forms import three_point_lmis


def lipschitz_lmis(mu: Any, L: Any, exact: bool) -> list[TupleLMI]:
    """The two LMIs of a triple (floats or exact numbers): A the Lipschitz, B the strong
    monotonicity form of each pair."""
    return three_point_lmis(lambda dx, du: (du.sq() - dx.sq() * (L * L),
                                            (dx.sq() * mu - du.dot(dx)) * (2 * L)),
                            2 * mu, exact)


class LipschitzStronglyMonotoneExpensive(LipschitzStronglyMonotone):
    name = "lipschitz_strongly_monotone_expensive"
    pairwise_defined = False  # the LMIs too: a pairwise member is not known to be one
    homogeneous = False  # no Lyapunov family takes the LMIs: ``pep`` answers
    interpolating = False  # necessary conditions: the PEP is an upper bound
    description = ("L-Lipschitz mu-strongly monotone operator, PEPit's expensive "
                   "conditions (7 x 7 LMIs per triple; necessary: an upper bound, not "
                   "known tight)")
    tilted_text = ("<u_a - u_b, x_a - x_b> >= mu |x_a - x_b|^2 and |u_a - u_b| <= L |x_a - "
                   "x_b|, and two 7 x 7 LMIs per triple (necessary, not known to "
                   "interpolate)",
                   r"\langle u_a - u_b, x_a - x_b\rangle \ge \mu \|x_a - x_b\|^2,\ "
                   r"\|u_a - u_b\| \le L \|x_a - x_b\|,\ \text{two LMIs per triple "
                   r"(necessary)}")

    def lmis(self, params: Mapping[str, float]) -> list[TupleLMI]:
        return lipschitz_lmis(float(params["mu"]), float(params["L"]), exact=False)

    def exact_lmis(self, params: Mapping[str, Any]) -> list[TupleLMI]:
        return lipschitz_lmis(params["mu"], params["L"], exact=True)


CLASS = LipschitzStronglyMonotoneExpensive()
