"""Writing a class's tuple LMIs (:class:`~sosalgo.classes.base.TupleLMI`) the way PEPit
writes its conditions: vectors of a tuple's points, their inner products, the points'
values and free multipliers, combined with numbers (floats, or rationals and balls for
the exact twin; no division by a parameter: a condition is scaled to avoid one; a
number that may be a ball goes on the right: ``form * k``).

    t = Tuple(3)                      # a triple of points (x_i, g_i, f_i)
    a = (t.g(0) - t.g(1)).sq() - (t.x(0) - t.x(1)).sq() * (L * L)
    m14 = t.free()                    # a free multiplier
    lmi = t.lmi([[a, m14], [m14, -a]])
"""

from __future__ import annotations

from collections.abc import Callable
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import TupleLMI

__all__ = ["Form", "Tuple", "Vec", "three_point_lmi"]

HALF = Fraction(1, 2)


def _zeros(*shape: int) -> np.ndarray:
    return np.full(shape, Fraction(0), dtype=object)


class Vec:
    """A combination of the tuple's vectors z = (x_1, ..., x_p, g_1, ..., g_p)."""

    def __init__(self, t: Tuple, c: np.ndarray):
        self.t, self.c = t, c

    def __add__(self, o: Vec) -> Vec:
        return Vec(self.t, self.c + o.c)

    def __sub__(self, o: Vec) -> Vec:
        return Vec(self.t, self.c - o.c)

    def __neg__(self) -> Vec:
        return Vec(self.t, -self.c)

    def __mul__(self, k: Any) -> Vec:
        return Vec(self.t, np.array([v * k for v in self.c], dtype=object))

    __rmul__ = __mul__

    def dot(self, o: Vec) -> Form:
        """<self, o> as a form (symmetric Gram coefficients)."""
        f = self.t.zero()
        outer = np.outer(self.c, o.c)
        f.gram = np.array([[HALF * (outer[i, j] + outer[j, i]) for j in range(len(self.c))]
                           for i in range(len(self.c))], dtype=object)
        return f

    def sq(self) -> Form:
        return self.dot(self)


class Form:
    """z' gram z + values . f + free . M: an entry of a tuple LMI."""

    def __init__(self, t: Tuple):
        self.t = t
        self.gram = _zeros(2 * t.p, 2 * t.p)
        self.values = _zeros(t.p)
        self.free = _zeros(t.nfree)

    def _map(self, o: Form, op: Any) -> Form:
        f = Form(self.t)
        f.gram, f.values = op(self.gram, o.gram), op(self.values, o.values)
        n = max(len(self.free), len(o.free))
        f.free = op(_pad(self.free, n), _pad(o.free, n))
        return f

    def __add__(self, o: Form) -> Form:
        return self._map(o, lambda a, b: a + b)

    def __sub__(self, o: Form) -> Form:
        return self._map(o, lambda a, b: a - b)

    def __neg__(self) -> Form:
        return self.t.zero() - self

    def __mul__(self, k: Any) -> Form:
        """The form times a number (write ``form * k`` when k may be a ball)."""
        f = Form(self.t)
        f.gram = np.array([[v * k for v in row] for row in self.gram], dtype=object)
        f.values = np.array([v * k for v in self.values], dtype=object)
        f.free = np.array([v * k for v in self.free], dtype=object)
        return f

    __rmul__ = __mul__


def _rational(x: Any) -> Any:
    return Fraction(x.c) if getattr(x, "r", None) == 0 else x


def _pad(v: np.ndarray, n: int) -> np.ndarray:
    return np.concatenate([v, _zeros(n - len(v))]) if len(v) < n else v


class Tuple:
    """The points of one tuple: ``arity`` points, x* appended when ``optimum`` (its
    index ``arity``); vectors x(i), g(i), values f(i), free multipliers."""

    def __init__(self, arity: int, optimum: bool = False):
        self.arity, self.optimum = arity, optimum
        self.p = arity + int(optimum)
        self.nfree = 0

    def zero(self) -> Form:
        return Form(self)

    def _unit(self, i: int) -> Vec:
        c = _zeros(2 * self.p)
        c[i] = Fraction(1)
        return Vec(self, c)

    def x(self, i: int) -> Vec:
        return self._unit(i)

    def g(self, i: int) -> Vec:
        return self._unit(self.p + i)

    def f(self, i: int) -> Form:
        out = self.zero()
        out.values[i] = Fraction(1)
        return out

    def free(self) -> Form:
        """A new free multiplier (a real variable of this tuple's LMIs)."""
        self.nfree += 1
        out = self.zero()
        out.free = _zeros(self.nfree)
        out.free[-1] = Fraction(1)
        return out

    def lmi(self, rows: list[list[Any]], exact: bool) -> TupleLMI:
        """The TupleLMI of a symmetric matrix of forms (0 for a zero entry); object
        arrays when ``exact``, floats otherwise."""
        m = len(rows)
        n = 2 * self.p
        gram, values = _zeros(m, m, n, n), _zeros(m, m, self.p)
        free = _zeros(self.nfree, m, m)
        for u in range(m):
            for v in range(m):
                e = rows[u][v]
                if isinstance(e, Form):
                    gram[u, v], values[u, v] = e.gram, e.values
                    free[:, u, v] = _pad(e.free, self.nfree)
        if exact:  # an exact ball (radius 0) as its rational: faster sums
            gram, values, free = (np.vectorize(_rational, otypes=[object])(a)
                                  for a in (gram, values, free))
        else:
            gram, values, free = (a.astype(float) for a in (gram, values, free))
        return TupleLMI(self.arity, gram, values, free, self.optimum)


def three_point_lmi(t: Tuple, A: dict[str, Form], B: dict[str, Form], c: Any,
                    exact: bool) -> TupleLMI:
    """The 7 x 7 LMI of a triple (i, j, k) of Rubbens, Hendrickx, Taylor 2025 (Prop.
    3.15, App. F; PEPit's strongly monotone "expensive" operators): A, B the pairwise
    forms at "ij", "ik", "jk", nine free multipliers, and the centre entry
    ``A_ij + c B_ij - A_jk - A_ik - 2 (M17 + M26 + M34)``."""
    m14, m15, m16, m17, m26, m27, m34, m37, m46 = (t.free() for _ in range(9))
    m55 = A["ij"] + B["ij"] * c - A["jk"] - A["ik"] - (m17 + m26 + m34) * 2
    z = 0
    rows = [[-B["ij"], z, z, m14, m15, m16, m17],
            [z, -A["jk"], -m15, z, -m14, m26, m27],
            [z, -m15, -B["ij"], m34, -m16, z, m37],
            [m14, z, m34, -B["jk"], -m27, m46, z],
            [m15, -m14, -m16, -m27, m55, -m37, -m46],
            [m16, m26, z, m46, -m37, -A["ik"], z],
            [m17, m27, m37, z, -m46, z, -B["ik"]]]
    return t.lmi(rows, exact)


# PEPit's orientation (a, b) of each pair of a triple (i, j, k)
TRIPLE_PAIRS = {"ij": (0, 1), "ik": (0, 2), "jk": (2, 1)}


def three_point_lmis(pair_forms: Callable[[Vec, Vec], tuple[Form, Form]], c: Any,
                     exact: bool) -> list[TupleLMI]:
    """The two LMIs of a triple, (A, B) and (B, A) in their places
    (:func:`three_point_lmi`): ``pair_forms(dx, du)`` gives (A_ab, B_ab) from the pair's
    x_a - x_b and u_a - u_b."""
    out = []
    for swap in (False, True):
        t = Tuple(3)
        A: dict[str, Form] = {}
        B: dict[str, Form] = {}
        for key, (a, b) in TRIPLE_PAIRS.items():
            A[key], B[key] = pair_forms(t.x(a) - t.x(b), t.g(a) - t.g(b))
        out.append(three_point_lmi(t, B, A, c, exact) if swap
                   else three_point_lmi(t, A, B, c, exact))
    return out
