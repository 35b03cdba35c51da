"""The interface of a function class: parameters, oracles, interpolation data.

A class describes the functions one name of a spec's ``functions:`` may stand for. The
interpolation certificate family only reads the data declared here:

- ``parameters`` and their default expressions (in m, L, kappa of the spec);
- ``oracles``: which calls it answers (``gradient``, ``subgradient``, ``proximal``);
- :meth:`FunctionClass.inequalities`: its pairwise interpolation inequalities, each
  ``alpha (f_a - f_b) + X' Q X >= 0`` with ``X = (x_a, x_b, g_a, g_b)`` (the d = 1
  template; ``⊗ I_d`` implied), required for every ordered pair of points (a, b) of one
  function (Taylor, Hendrickx, Glineur 2017, Thm. 4 and Section 3);
- :meth:`FunctionClass.tilted`: the inequalities of the tilted functions
  h(z) = f(z) - f(x*) - <s*, z - x*> (s* a subgradient at x*), which the certificate uses;
  the class's own inequalities when ``tilt_invariant`` (the class is closed under adding
  linear functions);
- ``zero_values``: every function value is 0 (indicators: f = 0 on the set);
- ``finite_everywhere``: the function has a (sub)gradient at every point, so it may be
  evaluated where the method never queries it (the output point of ``measure: function``);
- :meth:`FunctionClass.curvatures`: the curvatures q of the quadratics (q/2)|x|^2 in the
  class (an interval, or None), for the rate-on-quadratics lower bound.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["FunctionClass", "Inequality", "ORACLE_KINDS", "convex_form"]

ORACLE_KINDS = ("gradient", "subgradient", "proximal")


@dataclass(frozen=True)
class Inequality:
    """``alpha (f_a - f_b) + X' Q X >= 0`` on ``X = (x_a, x_b, g_a, g_b)`` (Q 4 x 4)."""

    alpha: float
    Q: np.ndarray


class FunctionClass:
    """Base of the shipped classes; a new class overrides the members below."""

    name: str = ""
    description: str = ""
    parameters: tuple[str, ...] = ()
    defaults: Mapping[str, str] = {}
    oracles: frozenset[str] = frozenset()
    zero_values: bool = False
    finite_everywhere: bool = False
    tilt_invariant: bool = True

    def check(self, params: Mapping[str, float]) -> None:
        """Raise ValueError('<parameter>: what is wrong') for invalid values."""

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        """The pairwise interpolation inequalities at these parameter values."""
        raise NotImplementedError

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        """Inequalities valid for the tilted functions h = f - f(x*) - <s*, . - x*> (values
        and subgradients of h): the class's own when ``tilt_invariant``."""
        if not self.tilt_invariant:
            raise NotImplementedError(f"class {self.name}: not tilt invariant, give tilted()")
        return self.inequalities(params)

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float] | None:
        """[lo, hi] such that (q/2)|x|^2 is in the class for q in [lo, hi] (None: none)."""
        return None

    @property
    def explicit(self) -> bool:
        """Whether the class answers a (sub)gradient call (a zero diagonal entry of D)."""
        return bool({"gradient", "subgradient"} & self.oracles)

    @property
    def proximal(self) -> bool:
        """Whether the class answers a proximal step (a diagonal entry -t of D)."""
        return "proximal" in self.oracles


def convex_form(mu: float = 0.0) -> np.ndarray:
    """Q of ``f_a - f_b - <g_b, x_a - x_b> - mu/2 |x_a - x_b|^2 >= 0`` on (x_a, x_b, g_a, g_b)
    (convex for mu = 0, mu-strongly convex otherwise)."""
    Q = np.zeros((4, 4))
    Q[0, 3] = Q[3, 0] = -0.5  # -<g_b, x_a>
    Q[1, 3] = Q[3, 1] = 0.5  # +<g_b, x_b>
    Q[:2, :2] -= 0.5 * mu * np.array([[1.0, -1.0], [-1.0, 1.0]])
    return Q
