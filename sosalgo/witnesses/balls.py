"""Linear algebra on rational balls (:class:`sosalgo.kernel.exact.Ball`) for the witnesses.

A ball of radius 0 is an exact rational, so every routine here is exact on rational data
and outward-rounded (rigorous enclosures) on irrational data: reciprocals and linear
solves with pivots chosen on the centers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction

import numpy as np

from sosalgo.kernel.exact import Ball, fraction_str

__all__ = ["ball_array", "ball_str", "exact", "recip", "solve_right", "tidy"]

TIDY_BITS = 160  # centers are rounded (outward, into the radius) to this many bits


def tidy(b: Ball) -> Ball:
    """``b`` with its center rounded to a multiple of 2^-TIDY_BITS times its size, the
    rounding error added to the radius (no-op on short exact rationals)."""
    c = b.c
    if c.denominator < 2**64:
        return b
    scale = 2 ** max(TIDY_BITS - max(abs(c).numerator.bit_length()
                                     - c.denominator.bit_length(), 0), 8)
    q = Fraction(math.floor(c * scale), scale)
    return Ball(q, b.r + abs(c - q))


def recip(b: Ball) -> Ball:
    """1/b (ValueError when the ball contains 0)."""
    if b.r == 0:
        if b.c == 0:
            raise ValueError("division by zero")
        return Ball(1 / b.c)
    if b.lo <= 0 <= b.hi:
        raise ValueError("division by a ball containing 0")
    a, z = 1 / b.lo, 1 / b.hi
    return tidy(Ball((a + z) / 2, abs(a - z) / 2))


def ball_array(M: np.ndarray | Sequence[Sequence[object]]) -> np.ndarray:
    """An object array of Balls from Balls, Fractions or ints."""
    arr = np.array(M, dtype=object)
    return np.vectorize(Ball.of, otypes=[object])(arr) if arr.size else arr


def exact(M: np.ndarray) -> bool:
    """Whether every ball of ``M`` has radius 0 (an exact rational array)."""
    return all(b.r == 0 for b in np.asarray(M, dtype=object).ravel())


def ball_str(b: Ball) -> str:
    """``p/q`` for an exact ball, else ``center +- radius`` (decimal radius)."""
    return fraction_str(b.c) if b.r == 0 else f"{fraction_str(b.c)} +- {float(b.r):.3g}"


def _eliminate(M: np.ndarray, rhs: np.ndarray, piv: Sequence[int]) -> np.ndarray:
    """Gauss–Jordan on ``M`` (k x k) with the pivot order ``piv`` (rows), solving
    M X = rhs; ValueError when a pivot ball contains 0."""
    k = M.shape[0]
    a = np.concatenate([M, rhs], axis=1).astype(object)
    order = list(piv)
    for col in range(k):
        i = order[col]
        inv = recip(a[i, col])
        a[i] = np.array([tidy(v * inv) for v in a[i]], dtype=object)
        for j in range(k):
            if j != i and not (a[j, col].c == 0 and a[j, col].r == 0):
                f = a[j, col]
                a[j] = np.array([tidy(x - f * y) for x, y in zip(a[j], a[i], strict=True)],
                                dtype=object)
    return a[order, k:]


def solve_right(M: np.ndarray, rhs: np.ndarray, M_float: np.ndarray | None = None
                ) -> np.ndarray:
    """X with M X = rhs (balls), pivots chosen on the float centers (partial pivoting)."""
    f = np.array([[float(b.c) for b in row] for row in M]) if M_float is None else M_float
    k = f.shape[0]
    piv: list[int] = []
    work = f.copy()
    for col in range(k):
        cand = [i for i in range(k) if i not in piv]
        i = max(cand, key=lambda r: abs(work[r, col]))
        if work[i, col] == 0:
            raise ValueError("singular matrix")
        piv.append(i)
        for j in range(k):
            if j != i:
                work[j] -= work[j, col] / work[i, col] * work[i]
    return _eliminate(M, rhs, piv)
