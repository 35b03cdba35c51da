"""Smoothness relative to a kernel h (the mirror map of a Bregman step): pair conditions.

``relatively_smooth`` (Bauschke, Bolte and Teboulle 2017; Lu, Freund and Nesterov 2018):
f is L-smooth and mu-strongly convex relative to h when

    f - mu h   and   L h - f   are convex          (0 <= mu < L; mu = 0: f convex),

``smooth_adaptable`` (Bolte, Sabach, Teboulle and Vaisbourd 2018, L-smad; f nonconvex):

    L h - f   and   L h + f   are convex.

Both are conditions on the pair (f, h), not on f alone: they are only meaningful in a
spec with ``mirror:`` (its kernel is h, :mod:`sosalgo.worstcase.mirror`), and a spec without one
is refused. Each is written as *blocks* (cf, ch): the function cf f + ch h is convex. The
PEP writes the convex interpolation inequalities of every block between every pair of
points where f and h are both evaluated (value cf f_a + ch h_a, subgradient cf g_a + ch
gh_a), as PEPit does with ``h = (d + f)/L`` (Dragomir, Taylor, d'Aspremont and Bolte 2021,
Section 3).

What is claimed. Given values and subgradients of (f, h) at finitely many points, the
block inequalities hold if and only if there are closed convex functions interpolating
each block; then f and h (linear combinations of the blocks, L > mu) interpolate the data
with every block convex. So the conditions are interpolating for the class of pairs
(f, h) whose blocks are closed proper convex, h possibly nonsmooth: the class PEPit's
examples use, and the PEP's value is the worst case over it. A kernel that must also be
differentiable (or Legendre, with f differentiable on the interior of its domain) is a
smaller class: for it the value is an upper bound, whose tightness is not claimed here
(Dragomir et al. 2021 show the NoLips bound is attained in a limit).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form, exact_convex_form


class RelativeClass(FunctionClass):
    """A condition on f relative to the spec's kernel h: :meth:`blocks` (cf, ch), each
    cf f + ch h convex. Only ``pep`` of a ``mirror:`` spec answers it."""

    oracles = frozenset({"gradient"})
    finite_everywhere = True  # differentiable where the method goes (int dom h)
    homogeneous = False  # no Lyapunov family: the conditions involve a second function
    relative = True

    def blocks(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        """(cf, ch) of each convex block cf f + ch h (floats or exact rationals)."""
        raise NotImplementedError

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]] | None:
        return None


class RelativelySmooth(RelativeClass):
    name = "relatively_smooth"
    description = ("L-smooth and mu-strongly convex relative to the mirror kernel h: "
                   "f - mu h and L h - f convex")
    parameters = ("L", "mu")
    defaults = {"L": "L", "mu": "0"}
    tilted_text = ("f - mu h and L h - f convex (relative to the kernel h)",
                   r"f - \mu h,\ L h - f\ \text{convex (relative to the kernel } h)")

    def check(self, params: Mapping[str, float]) -> None:
        L, mu = params["L"], params["mu"]
        if not (np.isfinite(L) and L > 0):
            raise ValueError(f"L: must be positive and finite, got {L:g}")
        if not (np.isfinite(mu) and 0 <= mu < L):
            raise ValueError(f"mu: must be in [0, L) = [0, {L:g}), got {mu:g}")

    def blocks(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        one = Fraction(1) if isinstance(params["L"], Fraction) else 1.0
        return [(one, -params["mu"]), (-one, params["L"])]

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        # f alone: convex (mu >= 0); the rest is about the pair (refused without a kernel)
        return [Inequality(1.0, convex_form())]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(1), exact_convex_form())]


class SmoothAdaptable(RelativeClass):
    name = "smooth_adaptable"
    description = ("nonconvex, L-smooth adaptable relative to the mirror kernel h: "
                   "L h - f and L h + f convex")
    parameters = ("L",)
    defaults = {"L": "L"}
    convex = False
    tilted_text = ("L h - f and L h + f convex (relative to the kernel h)",
                   r"L h \mp f\ \text{convex (relative to the kernel } h)")

    def check(self, params: Mapping[str, float]) -> None:
        L = params["L"]
        if not (np.isfinite(L) and L > 0):
            raise ValueError(f"L: must be positive and finite, got {L:g}")

    def blocks(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        one = Fraction(1) if isinstance(params["L"], Fraction) else 1.0
        return [(-one, params["L"]), (one, params["L"])]

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        # f alone: no condition (L h + f and L h - f convex say nothing without h)
        return [Inequality(0.0, np.zeros((4, 4)))]


CLASS = RelativelySmooth()
ADAPTABLE = SmoothAdaptable()
