"""PEP cost: the Clarabel solves of one PEP stay few, and the SDP's rows stay sparse as N
grows (no timing asserts: the times are in ``bench/pep.py``)."""

from __future__ import annotations

import collections
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import sosalgo

SPECS = Path(__file__).resolve().parent.parent / "specs"


@pytest.fixture
def solves(monkeypatch):
    """Counts the Clarabel solves (by raw status) of the block."""
    import clarabel

    count: collections.Counter[str] = collections.Counter()
    inner = clarabel.DefaultSolver

    class Spy:
        def __init__(self, *args):
            self.solver = inner(*args)

        def solve(self):
            sol = self.solver.solve()
            count[str(sol.status)] += 1
            return sol

    monkeypatch.setattr(clarabel, "DefaultSolver", Spy)
    return count


def test_gradient_thirty_steps_few_solves(solves):
    """h = 1/L, kappa = 10, |x_N - x*|^2 / |x_0 - x*|^2 = (1 - 1/kappa)^(2N) (tight on a
    quadratic), proven exactly with a handful of solves (the SDP, a rescale, the
    certificate: an almost-solved answer is not retried where it only sets the scale)."""
    N = 30
    res = sosalgo.pep(SPECS / "gradient.yaml", 10.0, N, "dist", witness=False)
    cert = res.certificate
    assert cert["check_kind"].startswith("exact")
    proven = Fraction(cert["tau_proven"])
    assert proven >= Fraction(9, 10) ** (2 * N)
    assert float(proven) == pytest.approx(0.9 ** (2 * N), rel=1e-5)
    assert sum(solves.values()) <= 4, dict(solves)


def test_nesterov_moderate_horizon_few_solves(solves):
    """Nesterov at N = 15: proven, within the solver's accuracy of the SDP value, and the
    solves bounded (the scale and violated-pair rounds accept an almost-solved answer)."""
    res = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, 15, witness=False)
    cert = res.certificate
    assert cert["check_kind"].startswith("exact")
    proven = Fraction(cert["tau_proven"])
    assert Fraction(res.tau) <= proven <= Fraction(res.tau) * (1 + Fraction(1, 10**5))
    assert sum(solves.values()) <= 8, dict(solves)


@pytest.mark.deep  # about a minute at load 10: three solves of the whole PEP at N = 60
def test_nesterov_sixty_steps_one_round_past_the_seed(monkeypatch):
    """Nesterov at N = 60: past the seed (360 pairs), one constraint-generation round
    (its pairs solved again at most in their own unit and for the certificate; the
    second round only added pairs violated by less than 1e-6), proven below Nesterov's
    bound (1 - 1/sqrt(kappa))^N (L + m)/2."""
    import clarabel

    sizes: list[int] = []
    inner = clarabel.DefaultSolver

    def spy(P, q, A, *args):
        sizes.append(A.shape[1] - 1)  # tau and one multiplier per active pair
        return inner(P, q, A, *args)

    monkeypatch.setattr(clarabel, "DefaultSolver", spy)
    N = 60
    res = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, N, witness=False)
    assert res.certificate["check_kind"].startswith("exact")
    upper = Fraction(res.certificate["tau_proven"])
    assert float(upper) <= (1 - 10 ** -0.5) ** N * (10 + 1) / 2
    seed = min(sizes)
    assert len({k for k in sizes if k > seed}) == 1, sizes


@pytest.mark.parametrize("spec,N", [("nesterov.yaml", 40), ("gradient.yaml", 60)])
def test_pair_rows_are_sparse_and_match_the_dense_forms(spec, N):
    """svec Q_k of every pair, built on the columns the pair uses, equals the dense
    X_k' Qc_k X_k (einsum) on a sample, and its entries grow like the pairs, not like
    pairs times d^2 (the memory of a long horizon)."""
    from sosalgo.kernel.conic import svec
    from sosalgo.worstcase.core import pep_problem
    from sosalgo.worstcase.sdp import pep_data

    loaded = sosalgo.load_spec(SPECS / spec)
    mt, st, *_ = pep_problem(loaded, 10.0, N, None, None)
    data = pep_data(mt, st)
    K = len(st.pairs)
    rows = data.svec_rows(np.arange(K))
    assert rows.shape == (K, st.d * (st.d + 1) // 2)
    assert rows.nnz <= 40 * K < K * st.d ** 2 / 20
    sample = np.random.default_rng(0).choice(K, size=50, replace=False)
    dense = svec(data.q(sample))
    assert np.allclose(rows[sample].toarray(), dense, rtol=1e-12, atol=1e-12)


@pytest.mark.deep  # about 10 s and 1 GB: 40 000 pairs
def test_gradient_two_hundred_steps_proven():
    """N = 200 (the longest horizon allowed): tau = 0.81^200 ~ 5e-19, the multipliers
    spanning more than 14 orders of magnitude; proven exactly, within 2e-5 above."""
    N = 200
    res = sosalgo.pep(SPECS / "gradient.yaml", 10.0, N, "dist", witness=False)
    cert = res.certificate
    assert cert["check_kind"].startswith("exact")
    proven = Fraction(cert["tau_proven"])
    closed = Fraction(81, 100) ** N
    assert closed <= proven <= closed * (1 + Fraction(2, 10**5))


def _nesterov_balls(N: int, digits: int):
    """Nesterov's recursion at kappa = 10 in the deadbeat basis, xi_{k+1} = A xi_k +
    s B (K xi_k + b_k), b_k = (-1)^k, in rational balls (beta enclosed to ``digits``
    decimals, long centres rounded outward as the exact PEP does); with mpmath's value
    of the same recursion at 400 digits."""
    import mpmath
    import sympy as sp

    from sosalgo.kernel.exact import Ball, enclose
    from sosalgo.worstcase.structure import coarsen, deadbeat_gain, enclosure_bits

    beta_s = (sp.sqrt(10) - 1) / (sp.sqrt(10) + 1)
    beta = enclose(beta_s, digits)
    A = [[Ball(0), Ball(1)], [-beta, beta + 1]]
    sB = [Fraction(0), Fraction(-1)]  # s h with h = 1/L, s = L
    Kf = deadbeat_gain(np.array([[0, 1], [-float(beta_s), 1 + float(beta_s)]]),
                       np.array([[0.0], [-0.1]]), 10.0)
    K = [Fraction(float(v)) for v in Kf[0]]
    bits = enclosure_bits(digits)
    xi = [Ball(1), Ball(0)]
    with mpmath.workdps(400):
        bm = (mpmath.sqrt(10) - 1) / (mpmath.sqrt(10) + 1)
        ref = [mpmath.mpf(1), mpmath.mpf(0)]
        km = [mpmath.mpf(q.numerator) / q.denominator for q in K]  # exact: binary
        for k in range(N):
            b = (-1) ** k
            u = K[0] * xi[0] + K[1] * xi[1] + b
            xi = [coarsen(A[i][0] * xi[0] + A[i][1] * xi[1] + sB[i] * u, bits)
                  for i in range(2)]
            ur = km[0] * ref[0] + km[1] * ref[1] + b
            ref = [ref[1], -bm * ref[0] + (1 + bm) * ref[1] - ur]
        ref_q = [Fraction(mpmath.nstr(v, 300, strip_zeros=False)) for v in ref]
    return [Ball.of(v) for v in xi], ref_q, Kf


def test_enclosure_precision_grows_with_the_horizon():
    """The precision rule: Nesterov's beta is irrational and ball arithmetic widens its
    enclosure's radius by the Perron root of |A| + s|B||K| (3.35) per step. With the
    short horizons' 50 decimals the state after 70 steps is wider than the 1e-23 an
    exact proof at N = 70 needs (tau ~ 2e-17); with :func:`enclosure_digits` it ends
    below 10^-ENCLOSURE_TARGET at N = 70 and N = 150, and every ball still holds the
    value computed independently with mpmath at 400 digits."""
    from sosalgo.worstcase.structure import ENCLOSURE_TARGET, enclosure_digits, radius_growth

    wide, ref, Kf = _nesterov_balls(70, 50)
    assert max(b.r for b in wide) > Fraction(1, 10**23)
    assert all(abs(b.c - v) <= b.r for b, v in zip(wide, ref, strict=True))
    beta = (10 ** 0.5 - 1) / (10 ** 0.5 + 1)
    g = radius_growth(np.array([[0, 1], [-beta, 1 + beta]]), np.array([[0.0], [-0.1]]),
                      Kf, 10.0)
    assert 3.2 < g < 3.5
    assert enclosure_digits(g, 1) == 50  # short horizons keep their precision
    assert enclosure_digits(1e300, 10**12) <= 1000  # a hostile growth or horizon: bounded
    for N in (70, 150):
        digits = enclosure_digits(g, N)
        balls, ref, _ = _nesterov_balls(N, digits)
        assert max(b.r for b in balls) < Fraction(1, 10 ** ENCLOSURE_TARGET), (N, digits)
        assert all(abs(b.c - v) <= b.r for b, v in zip(balls, ref, strict=True))
