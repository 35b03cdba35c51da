"""The exact PSD check's shortcut: a scaled S whose floating-point least eigenvalue is
clearly negative skips the exact rational decision (which could only refuse it); a
semidefinite S (exact zero eigenvalues) must still reach that decision. Judged by sympy's
exact eigenvalues of random rational matrices."""

from __future__ import annotations

import random
from fractions import Fraction

import numpy as np
import pytest
import sympy as sp
from flint import arb_mat

from sosalgo.kernel.exact import prove_psd
from sosalgo.worstcase.exact import _scaled_psd, ball


def _gram(rng: random.Random, d: int, r: int) -> list[list[Fraction]]:
    """B B' for a random rational d x r matrix B: semidefinite of rank <= r."""
    B = [[Fraction(rng.randint(-4, 4), rng.randint(1, 3)) for _ in range(r)]
         for _ in range(d)]
    return [[sum((B[i][k] * B[j][k] for k in range(r)), Fraction(0)) for j in range(d)]
            for i in range(d)]


def _least_eig(S: list[list[Fraction]]) -> float:
    vals = sp.Matrix(S).eigenvals()
    return min(float(sp.re(sp.N(v, 30))) for v in vals)


def _arb(S: list[list[Fraction]]) -> arb_mat:
    return arb_mat([[ball(v) for v in row] for row in S])


@pytest.mark.parametrize("seed", range(6))
def test_semidefinite_reaches_the_exact_decision(seed):
    rng = random.Random(seed)
    d = rng.randint(3, 6)
    S = _gram(rng, d, rng.randint(1, d - 1))  # singular: no Cholesky margin
    ok, _, _, indefinite = _scaled_psd(_arb(S), np.ones(d))
    assert not ok and not indefinite
    assert prove_psd(S).psd  # the exact decision proves it


@pytest.mark.parametrize("seed", range(6))
def test_clearly_indefinite_is_flagged(seed):
    rng = random.Random(seed)
    d = rng.randint(3, 6)
    S = _gram(rng, d, d)
    i = rng.randrange(d)
    S[i][i] -= Fraction(1000)  # a diagonal entry far below: a negative eigenvalue
    assert _least_eig(S) < -1e-6 * float(max(abs(v) for row in S for v in row))
    ok, _, _, indefinite = _scaled_psd(_arb(S), np.ones(d))
    assert not ok and indefinite
    assert not prove_psd(S).psd
