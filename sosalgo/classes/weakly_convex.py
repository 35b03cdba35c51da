"""Weakly convex functions: f + (rho/2)|x|^2 convex (rho > 0), f finite on R^d; and the
smooth ones, L-smooth with curvature in [-rho, L].

Interpolation (both are theorems, not only necessary conditions). The shift
f -> f + (rho/2)|.|^2 maps the data (x_i, g_i, f_i) to (x_i, g_i + rho x_i, f_i + (rho/2)
|x_i|^2), one to one, and maps the class onto the convex functions (``weakly_convex``) or
onto the (L + rho)-smooth convex functions (``smooth_weakly_convex``). Data are therefore
interpolated by a function of the class if and only if the shifted data are interpolated
by a function of the shifted class, whose conditions are known exactly (Taylor, Hendrickx,
Glineur 2017, Thm. 4 and Thm. 3.10):

- ``weakly_convex`` (parameter ``rho``): f_a >= f_b + <g_b, x_a - x_b> - (rho/2)|x_a -
  x_b|^2 for every ordered pair, the convex inequality of the shifted data;
- ``smooth_weakly_convex`` (``rho``, ``L``, 0 < rho <= L): the inequality of F(m, L) at m =
  -rho (:mod:`sosalgo.classes.smooth`, the shifted smooth convex one rewritten;
  hypoconvex functions, Rotaru, Glineur, Patrinos 2022). rho > L is refused: every
  L-smooth function has curvature >= -L, so that class is the one with rho = L.

A PEP over either is exact. Both are closed under adding linear functions. Neither
assumes a minimizer: like ``smooth`` the PEP keeps no x*, so its measure and initial
condition are free of f* and x* (gradient norms, differences f(x_0) - f(x_N), step
lengths). No Lyapunov family of ``analyze`` applies to a nonconvex class: ``analyze``
refuses them, ``sosalgo pep`` answers (``pep``, ``verify`` of its claims, witnesses).

A proximal step on ``weakly_convex`` is read as the inclusion (v - y)/t in the
subdifferential at y: for t rho < 1 this is prox_{t f}(v), unique (the subproblem is
strongly convex); for t rho >= 1 it is any critical point of the subproblem, and the
bound holds for every such choice.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form, exact_convex_form
from sosalgo.classes.members import ProxFunction
from sosalgo.classes.smooth import Smooth


def _check_rho(rho: float) -> None:
    if not (np.isfinite(rho) and rho > 0):
        raise ValueError(f"rho: must be positive and finite (rho = 0: use a convex class), "
                         f"got {rho:g}")


class WeaklyConvex(FunctionClass):
    name = "weakly_convex"
    description = "rho-weakly convex (f + rho/2 |x|^2 convex), possibly nonsmooth"
    parameters = ("rho",)
    defaults = {"rho": "L"}
    oracles = frozenset({"subgradient", "proximal"})
    finite_everywhere = True
    convex = False
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b> - (rho/2)|x_a - x_b|^2",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle - \frac{\rho}{2}"
                   r"\|x_a - x_b\|^2")

    def check(self, params: Mapping[str, float]) -> None:
        _check_rho(params["rho"])

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, convex_form(-float(params["rho"])))]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(1), exact_convex_form(-params["rho"]))]


class SmoothWeaklyConvex(Smooth):
    name = "smooth_weakly_convex"
    description = "L-smooth and rho-weakly convex: curvature in [-rho, L]"
    parameters = ("rho", "L")
    defaults = {"rho": "L", "L": "L"}
    tilted_text = (
        "h_a >= h_b + <g_b, x_a - x_b> + |g_a - g_b|^2/(2(L + rho))"
        " - rho L |x_a - x_b|^2/(2(L + rho)) + rho <g_a - g_b, x_a - x_b>/(L + rho)",
        r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle + \frac{\|g_a - g_b\|^2}{2(L + \rho)}"
        r" - \frac{\rho L\,\|x_a - x_b\|^2}{2(L + \rho)} + \frac{\rho\,\langle g_a - g_b,"
        r" x_a - x_b\rangle}{L + \rho}")

    @staticmethod
    def _as_smooth(params: Mapping[str, Any]) -> dict[str, Any]:
        return {"m": -params["rho"], "L": params["L"]}

    def check(self, params: Mapping[str, float]) -> None:
        rho, L = params["rho"], params["L"]
        if not (np.isfinite(L) and L > 0):
            raise ValueError(f"L: must be positive and finite, got {L:g}")
        _check_rho(rho)
        if rho > L:
            raise ValueError(f"rho: must be at most L = {L:g} (an L-smooth function has "
                             f"curvature >= -L: rho = L is every L-smooth f), got {rho:g}")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return super().inequalities(self._as_smooth(params))

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return super().exact_tilted(self._as_smooth(params))

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float]:
        return -params["rho"], params["L"]

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction]) -> tuple[Fraction, Fraction]:
        return -lower("rho"), lower("L")  # an inner interval of [-rho, L]

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        return super().test_functions(self._as_smooth(params), xs, rng)


CLASS = WeaklyConvex()
SMOOTH = SmoothWeaklyConvex()
