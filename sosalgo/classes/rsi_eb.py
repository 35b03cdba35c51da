"""Functions with a restricted secant inequality and an error bound at their minimizer
(PEPit's RsiEbFunction): for every point x, with x* a stationary point (a minimizer),

    <g, x - x*> >= mu |x - x*|^2        (RSI),        |g| <= L |x - x*|        (EB).

These are the conditions PEPit imposes, between each point and x* only (scope
"optimum"); they are necessary, not known to be sufficient for interpolation
(``interpolating`` False): a PEP over them is an upper bound of the worst case over the
class, not necessarily tight (the output says so). The class need not be convex; its PEP
keeps x* (``minimizer``), and its values play no role (no condition involves f). Its
conditions are about f itself: the only function of its spec (``alone``).

No Lyapunov family of ``analyze`` takes them (``homogeneous`` False): ``analyze`` refuses
the class; ``sosalgo pep`` answers (specs/subgradient-rsi-eb.yaml).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, check_mu_below_L


def secant_form(mu: Any) -> np.ndarray:
    """Q of ``<g_a - g_b, x_a - x_b> - mu |x_a - x_b|^2`` on (x_a, x_b, g_a, g_b)."""
    h = Fraction(1, 2)
    Q = np.full((4, 4), 0 * mu, dtype=object)
    for (i, j), v in {(0, 2): h, (1, 3): h, (0, 3): -h, (1, 2): -h}.items():
        Q[i, j] = Q[j, i] = Q[i, j] + v
    for (i, j), v in {(0, 0): -1, (1, 1): -1, (0, 1): 1, (1, 0): 1}.items():
        Q[i, j] = Q[i, j] + v * mu
    return Q


def error_bound_form(L: Any) -> np.ndarray:
    """Q of ``L^2 |x_a - x_b|^2 - |g_a - g_b|^2`` on (x_a, x_b, g_a, g_b)."""
    L2 = L * L
    Q = np.full((4, 4), 0 * L, dtype=object)
    for (i, j), v in {(0, 0): 1, (1, 1): 1, (0, 1): -1, (1, 0): -1}.items():
        Q[i, j] = Q[i, j] + v * L2
    for (i, j), v in {(2, 2): -1, (3, 3): -1, (2, 3): 1, (3, 2): 1}.items():
        Q[i, j] = Q[i, j] + v
    return Q


class RsiEb(FunctionClass):
    name = "rsi_eb"
    description = ("restricted secant <g, x - x*> >= mu|x - x*|^2 and error bound |g| <= "
                   "L|x - x*| (necessary conditions: an upper bound, not tight)")
    parameters = ("mu", "L")
    defaults = {"mu": "m", "L": "L"}
    oracles = frozenset({"gradient"})
    finite_everywhere = True
    convex = False
    minimizer = True
    tilt_invariant = False
    homogeneous = False
    alone = True
    interpolating = False
    tilted_text = ("<g_a, x_a - x*> >= mu |x_a - x*|^2 and |g_a|^2 <= L^2 |x_a - x*|^2 "
                   "(every point, with x*)",
                   r"\langle g_a, x_a - x_\star\rangle \ge \mu\|x_a - x_\star\|^2,\quad"
                   r" \|g_a\|^2 \le L^2\|x_a - x_\star\|^2")

    def check(self, params: Mapping[str, float]) -> None:
        check_mu_below_L(params)

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        mu, L = float(params["mu"]), float(params["L"])
        return [Inequality(0.0, secant_form(mu).astype(float), 0.0, "optimum"),
                Inequality(0.0, error_bound_form(L).astype(float), 0.0, "optimum")]

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        return self.inequalities(params)  # the only function: s* = 0 (``alone``)

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(0), secant_form(params["mu"])),
                (Fraction(0), error_bound_form(params["L"]))]

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any]:
        return [Fraction(0), Fraction(0)]


CLASS = RsiEb()
