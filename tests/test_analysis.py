"""Analysis against closed forms and an independent soundness bound (quadratics)."""

from __future__ import annotations

import numpy as np
import pytest

from sosalgo.analysis import analyze_algorithm, analyze_spec
from sosalgo.certificates import THEOREM1
from sosalgo.kernel.solvers import SOLVERS
from sosalgo.model import Algorithm, bind
from sosalgo.spec import load_spec

from .conftest import SPECS

KAPPAS = (2.0, 10.0, 100.0)


@pytest.mark.parametrize("kappa", KAPPAS)
def test_gradient_step_1_over_L(kappa):
    res = analyze_spec(load_spec(SPECS / "gradient.yaml"), kappa)
    assert res.certified
    assert res.rho == pytest.approx(1 - 1 / kappa, abs=1e-5)
    assert res.rho >= 1 - 1 / kappa - 1e-9  # Theorem 1 is tight: never below the truth


@pytest.mark.parametrize("kappa", KAPPAS)
def test_gradient_optimal_step(kappa):
    res = analyze_spec(load_spec(SPECS / "gradient-optimal.yaml"), kappa)
    assert res.rho == pytest.approx((kappa - 1) / (kappa + 1), abs=1e-5)
    assert res.rho >= (kappa - 1) / (kappa + 1) - 1e-9


@pytest.mark.parametrize("kappa", [10.0, 100.0])
def test_nesterov_beats_nesterovs_bound(kappa):
    res = analyze_spec(load_spec(SPECS / "nesterov.yaml"), kappa)
    assert res.certified
    assert res.rho <= np.sqrt(1 - 1 / np.sqrt(kappa))
    # and never below the rate on quadratics (lower bound for any certificate)
    assert res.rho >= _quadratic_rate(bind(load_spec(SPECS / "nesterov.yaml"), kappa)) - 1e-6


def test_heavy_ball_not_certified_at_25():
    res = analyze_spec(load_spec(SPECS / "heavy-ball.yaml"), 25.0)
    assert res.certified is False
    assert res.rho is None and res.P is None


def _theorem1_M_by_hand(A, B, C, E, m, L, P, lam, rho):
    """Eqs. (13)-(15) written out again, independently of sosalgo.certificates: the rows
    of each quadratic form are the pairs (point difference, gradient) it involves."""
    n = A.shape[0]
    Z = np.zeros
    S = np.block([[A, B]])  # xi+ = S (xi, u)
    I0 = np.block([[np.eye(n), Z((n, 1))]])
    u = np.block([[Z((1, n)), np.ones((1, 1))]])
    xplus, x, y = E @ S, E @ I0, C @ I0
    r2 = rho**2

    def q(a, b, Q):  # (a w, b w)' Q (a w, b w) as a matrix in w = (xi, u)
        Wm = np.vstack([a, b])
        return Wm.T @ Q @ Wm

    half = 0.5
    N1 = q(xplus - y, u, np.array([[L / 2, half], [half, 0]]))  # f(x+) - f(y) <= ...
    N2 = q(y - x, u, np.array([[-m / 2, half], [half, 0]]))  # f(y) - f(x) <= ...
    N3 = q(y, u, np.array([[-m / 2, half], [half, 0]]))  # f(y) - f* <= ...
    N4 = q(y, u, np.array([[-m * L / (m + L), half], [half, -1 / (m + L)]]))
    M0 = S.T @ P @ S - r2 * I0.T @ P @ I0
    return M0 + r2 * (N1 + N2) + (1 - r2) * (N1 + N3) + lam * N4


def test_returned_certificate_is_checked():
    spec = load_spec(SPECS / "nesterov.yaml")
    res = analyze_spec(spec, 10.0)
    alg = bind(spec, 10.0)
    M = _theorem1_M_by_hand(alg.A, alg.B, alg.C, alg.E, alg.m, alg.L, res.P, res.lam, res.rho)
    assert np.linalg.eigvalsh(M).max() <= 1e-9 * max(1.0, np.abs(res.P).max())
    assert np.linalg.eigvalsh(res.P).min() >= 0 and res.lam >= 0
    # the family's own matrix agrees with the hand-written one
    own = THEOREM1.matrix(alg, res.rho, {"P": res.P, "lambda": res.lam})
    assert np.abs(own - M).max() <= 1e-9 * max(1.0, np.abs(M).max())
    assert res.rho_infeasible < res.rho <= res.rho_infeasible + 1e-6


def _quadratic_rate(alg: Algorithm, points: int = 801) -> float:
    """max over q in [m, L] of the spectral radius of A + q B C (grid max <= true max)."""
    qs = np.linspace(alg.m, alg.L, points)
    return max(np.abs(np.linalg.eigvals(alg.A + q * alg.B @ alg.C)).max() for q in qs)


def _random_methods(count: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        kappa = float(np.exp(rng.uniform(np.log(1.5), np.log(200))))
        m, L = 1.0, kappa
        kind = i % 3
        if kind == 0:  # the three-parameter family of eq. (9)
            h, b, g = rng.uniform(0, 2 / L), rng.uniform(0, 1), rng.uniform(0, 1)
            A = np.array([[0, 1], [-b, 1 + b]])
            B = np.array([[0], [-h]])
            C = np.array([[-g, 1 + g]])
            E = np.array([[0.0, 1.0]])
        elif kind == 1:  # random 1-state: A = 1, C u = E u = 1 for u = 1/c
            c = rng.choice([-1, 1]) * rng.uniform(0.5, 2)
            A = np.array([[1.0]])
            B = np.array([[-rng.uniform(0, 2.5 / L) / c]])
            C = E = np.array([[c]])
        else:  # random 2-state with A u = u, C u = E u = 1
            u = rng.normal(size=2)
            V = np.column_stack([u, rng.normal(size=2)])
            A = V @ np.diag([1.0, rng.uniform(-0.9, 0.9)]) @ np.linalg.inv(V)
            c, e = rng.normal(size=2), rng.normal(size=2)
            C = (c + (1 - c @ u) * u / (u @ u))[None, :]
            E = (e + (1 - e @ u) * u / (u @ u))[None, :]
            B = rng.normal(size=(2, 1)) / L
        out.append(Algorithm(A, B, C, E, m, L))
    return out


def test_soundness_against_quadratics():
    """Quadratics q x^2/2, q in [m, L], are in F(m, L): no certified rate may beat them."""
    methods = _random_methods(210)
    certified = 0
    for alg in methods:
        res = analyze_algorithm(alg, tol=1e-6)
        if res.certified:
            certified += 1
            assert res.rho >= _quadratic_rate(alg) - 1e-6, (alg, res.rho)
            assert res.max_eig_M <= 0 and res.min_eig_P >= 0
    assert certified >= 60  # the test must exercise many certificates


class _LyingSolver:
    """Claims 'solved' with a point that does not satisfy the inequality."""

    def __call__(self, problem, rho, margin):
        return "solved", np.zeros(problem.nvar) + 1.0, "Solved"


class _CrashingSolver:
    def __call__(self, problem, rho, margin):
        raise RuntimeError("boom")


def test_lying_and_crashing_solvers_never_certify(monkeypatch):
    monkeypatch.setitem(SOLVERS, "liar", _LyingSolver())
    monkeypatch.setitem(SOLVERS, "crash", _CrashingSolver())
    alg = bind(load_spec(SPECS / "nesterov.yaml"), 10.0)
    res = analyze_algorithm(alg, solvers=("liar", "crash"))
    assert not res.certified and res.rho is None
    # with a real solver behind the liar, the liar's answers are discarded, not trusted
    res = analyze_algorithm(alg, solvers=("liar", "clarabel"))
    honest = analyze_algorithm(alg)
    assert res.certified and res.rho == pytest.approx(honest.rho, abs=2e-6)
    assert res.solver == "clarabel"


def test_lag_field_of_results():
    """JSON rows of the interpolation family carry the certificate's lag (chosen here);
    Theorem 1 rows have no lag; an uncertified chosen-lag result has none either."""
    from sosalgo.certificates.interpolation import Interpolation

    spec = load_spec(SPECS / "heavy-ball.yaml")
    tight = analyze_spec(spec, 10.0, family=Interpolation()).to_dict()
    assert tight["lag"] == tight["certificate"]["lag"] >= 2
    assert len(tight["certificate"]["p"]) == tight["lag"] + 1
    assert "lag" not in analyze_spec(spec, 10.0).to_dict()
    none = analyze_spec(spec, 25.0, family=Interpolation())
    assert not none.certified and none.lag is None
