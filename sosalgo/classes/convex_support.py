"""Support functions: f(x) = sup_{c in C} <c, x - o> for a nonempty closed convex set C,
i.e. closed, convex and positively homogeneous about an origin o (PEPit's
ConvexSupportFunction with M = inf).

Interpolation (Taylor, Hendrickx, Glineur 2017, "Exact worst-case performance of
first-order methods for composite convex optimization", Cor. 3.7): data (x_i, g_i, f_i)
are interpolated by a support function about o if and only if

    f_a = <g_a, x_a - o>      and      <g_b, x_a - o> <= f_a      for every a, b,

so a PEP over them is exact. With f_b = <g_b, x_b - o> the second is the convex
inequality f_a >= f_b + <g_b, x_a - x_b>; the first is the convex inequality between a and
the point o (value 0, subgradient 0 in tilted terms: below) together with the condition
of scope "anchor", f_a - f(o) - <g_a, x_a - o> >= 0.

The origin o is a point of the problem like x*: its position is free (the PEP gives it a
column of its own; a witness states it). A support function bounded below has f(o) = 0
as its minimum (0 is in C), and x* is any point where f = 0. Tilting keeps the class:
f - f* - <s*, . - x*> = sup_{c in C - s*} <c, . - o> (f* = <s*, x* - o>, s* in C), whose
value at o is 0 and 0 is one of its subgradients there (0 in C - s*); so o enters the
tilted PEP with value 0 and subgradient 0 (``anchored``). C may be unbounded: f may be
+inf off the points the method queries (not ``finite_everywhere``).

No Lyapunov family of ``analyze`` takes a condition about o (``homogeneous`` False):
``analyze`` refuses the class; ``sosalgo pep`` answers, and ``verify`` checks its
witnesses (o's value 0 included).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality, convex_form, exact_convex_form


def anchor_form(one: Any = 1.0) -> np.ndarray:
    """Q of ``-<g_a, x_a - x_b>`` on (x_a, x_b, g_a, g_b), b the origin o (``one``: 1.0,
    or Fraction(1) for the exact twin)."""
    h = one / 2
    Q = np.full((4, 4), 0 * one, dtype=object)
    Q[0, 2] = Q[2, 0] = -h
    Q[1, 2] = Q[2, 1] = h
    return Q


class ConvexSupport(FunctionClass):
    name = "convex_support"
    description = "support function of a closed convex set (convex, positively homogeneous)"
    parameters = ()
    defaults = {}
    oracles = frozenset({"subgradient", "proximal"})
    homogeneous = False
    anchored = True
    tilted_text = ("h_a >= h_b + <g_b, x_a - x_b> (every pair, o among the points: h_o = 0,"
                   " g_o = 0);  h_a = <g_a, x_a - o> (every point)",
                   r"h_a \ge h_b + \langle g_b, x_a - x_b\rangle,\quad h_a = \langle g_a,"
                   r" x_a - o\rangle")

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(1.0, convex_form()),
                Inequality(1.0, anchor_form().astype(float), 0.0, "anchor")]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(1), exact_convex_form()), (Fraction(1), anchor_form(Fraction(1)))]

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any]:
        return [Fraction(0), Fraction(0)]


CLASS = ConvexSupport()
