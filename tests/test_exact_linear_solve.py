"""Exact rational solves of affine systems (:func:`sosalgo.kernel.exact.solve_affine`),
judged by sympy's own Gauss-Jordan elimination and by substitution."""

from __future__ import annotations

import random
from fractions import Fraction

import pytest
import sympy as sp

from sosalgo.kernel.exact import solve_affine


def _system(rng: random.Random) -> tuple[list[list[Fraction]], list[Fraction], int]:
    m, n = rng.randint(1, 6), rng.randint(1, 7)
    A = [[Fraction(rng.randint(-3, 3), rng.randint(1, 4)) if rng.random() < 0.6
          else Fraction(0) for _ in range(n)] for _ in range(m)]
    if rng.random() < 0.4:  # a dependent row: consistent or not, by the right side
        A.append([a + b for a, b in zip(A[0], A[-1], strict=True)])
    b = [Fraction(rng.randint(-3, 3), rng.randint(1, 3)) for _ in A]
    return A, b, n


def _free_value(c: int) -> Fraction:
    return Fraction(c + 1, 3)


@pytest.mark.parametrize("seed", range(4))
def test_solve_affine_matches_sympy(seed):
    rng = random.Random(seed)
    for _ in range(60):
        A, b, n = _system(rng)
        mine = solve_affine(A, b, n, _free_value)
        try:
            sol, params, free = sp.Matrix(A).gauss_jordan_solve(sp.Matrix(b), freevar=True)
        except ValueError:
            assert mine is None
            continue
        values = sol.xreplace({p: sp.Rational(_free_value(i).numerator,
                                              _free_value(i).denominator)
                               for p, i in zip(params, free, strict=True)})
        assert mine == [Fraction(int(sp.Rational(v).p), int(sp.Rational(v).q))
                        for v in values]
        assert all(sum(a * x for a, x in zip(row, mine, strict=True)) == r
                   for row, r in zip(A, b, strict=True))


def test_solve_affine_inconsistent_and_empty():
    assert solve_affine([[Fraction(1), Fraction(1)], [Fraction(2), Fraction(2)]],
                        [Fraction(1), Fraction(3)], 2, _free_value) is None
    assert solve_affine([], [], 3, _free_value) == [_free_value(c) for c in range(3)]
