"""Tests of sosalgo.verify: exact proofs of Theorem 1 certificates and simulation checks.

Expected values are derived here (closed forms, hand-derived certificates, the paper's
formulas), not taken from sosalgo's own output.
"""

from __future__ import annotations

import functools
import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from sosalgo.analysis import analyze_spec
from sosalgo.certificates.theorem1 import THEOREM1, theorem1_terms
from sosalgo.kernel.exact import _pivoted_ldl, enclose, prove_psd, psd_by_minors, rational_at_least
from sosalgo.model import Algorithm, bind
from sosalgo.proofs import (
    function_suite,
    lrp_counterexample,
    simulate_check,
    theorem1_exact,
    verify_exact,
    write_certificate,
)
from sosalgo.spec import load_spec

SPECS = sorted((Path(__file__).resolve().parents[1] / "specs").glob("*.yaml"))
KAPPAS = (2, 10, 100)


@functools.cache
def _spec(name: str):
    return load_spec(next(p for p in SPECS if p.stem == name))


@functools.cache
def _analysis(name: str, kappa: float):
    return analyze_spec(_spec(name), kappa, tol=1e-6)


F = Fraction


# --------------------------------------------------------------------------- PSD prover


def test_psd_definite():
    proof = prove_psd([[2, 1], [1, 2]])
    assert proof.psd and proof.kind == "definite" and proof.method == "ldl"
    assert proof.pivots == (F(2), F(3, 2))


def test_psd_singular_semidefinite():
    proof = prove_psd([[1, 1], [1, 1]])
    assert proof.psd and proof.kind == "semidefinite" and proof.method == "minors"
    assert prove_psd([[1, 0], [0, 0]]).psd
    assert prove_psd([[0, 0], [0, 0]]).psd
    assert prove_psd([[0, 0, 0], [0, 4, 2], [0, 2, 1]]).psd


def test_psd_indefinite_by_a_hair():
    proof = prove_psd([[1, 0], [0, F(-1, 10**30)]])
    assert not proof.psd and proof.kind == "indefinite"
    # zero diagonal with a nonzero off-diagonal entry
    assert not prove_psd([[0, F(1, 10**30)], [F(1, 10**30), 0]]).psd
    assert not prove_psd([[1, 1], [1, 1 - F(1, 10**40)]]).psd
    assert prove_psd([[1, 1], [1, 1 + F(1, 10**40)]]).psd


def test_psd_large_singular_uses_pivoted_ldl():
    rng = np.random.default_rng(3)
    G = rng.integers(-3, 4, size=(6, 10))  # rank <= 6 in R^10: PSD and singular
    S = [[F(int(v)) for v in row] for row in G.T @ G]
    proof = prove_psd(S)
    assert proof.psd and proof.kind == "semidefinite" and proof.method == "pivoted-ldl"
    # push it out of the cone along a null direction of G: indefinite by 1e-30
    null = sp.Matrix(G.tolist()).nullspace()[0]
    v = [F(int(sp.fraction(x)[0]), int(sp.fraction(x)[1])) for x in null]
    eps = F(1, 10**30)
    S2 = [[S[i][j] - eps * v[i] * v[j] for j in range(10)] for i in range(10)]
    assert not prove_psd(S2).psd


def test_psd_rejects_nonsymmetric():
    with pytest.raises(ValueError):
        prove_psd([[1, 2], [0, 1]])


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 4).flatmap(
    lambda n: st.lists(st.integers(-3, 3), min_size=n * n, max_size=n * n).map(
        lambda xs: (n, xs))))
def test_psd_prover_agrees_with_minors(data):
    n, xs = data
    G = [[F(xs[i * n + j]) for j in range(n)] for i in range(n)]
    # a symmetric matrix and a PSD one (G' G, often singular)
    S = [[G[i][j] + G[j][i] for j in range(n)] for i in range(n)]
    GtG = [[sum(G[k][i] * G[k][j] for k in range(n)) for j in range(n)] for i in range(n)]
    for X in (S, GtG):
        expected = psd_by_minors(X)
        assert prove_psd(X).psd == expected
        assert _pivoted_ldl(X)[0] == expected
        eig = np.linalg.eigvalsh(np.array(X, dtype=float))
        if eig[0] < -1e-9:
            assert not expected
        if eig[0] > 1e-9:
            assert expected
    assert prove_psd(GtG).psd


# --------------------------------------------------------------------------- exact pieces


def test_enclosures_are_rigorous_and_tight():
    b = enclose(sp.sqrt(10))
    assert b.lo * b.lo <= 10 <= b.hi * b.hi and b.r < F(1, 10**49)
    b = enclose((sp.sqrt(10) - 1) / (sp.sqrt(10) + 1))  # = (11 - 2 sqrt 10) / 9
    lo2, hi2 = (11 - 9 * b.hi) / 2, (11 - 9 * b.lo) / 2  # enclosure of sqrt(10)
    assert lo2 * lo2 <= 10 <= hi2 * hi2
    assert enclose(sp.Rational(3, 7)).r == 0
    assert enclose(sp.Min(sp.sqrt(2), sp.Rational(3, 2))).lo > F(141, 100)
    b = enclose(sp.log(2) + sp.exp(1) + sp.pi)  # 6.55302166260878...
    assert F("6.5530216626") < b.lo and b.hi < F("6.5530216627") and b.r < F(1, 10**49)


def test_rational_at_least():
    assert rational_at_least(0.5) == F(1, 2)
    x = 0.1  # binary value has a denominator 2^55 > 10^12
    r = rational_at_least(x)
    assert r >= F(x) and r.denominator <= 10**12 and r - F(x) < F(1, 10**12)


@pytest.mark.parametrize("seed", range(5))
def test_theorem1_exact_matches_sosalgo(seed):
    """The verifier's own eq. (14)-(15) agrees with sosalgo's theorem1_terms."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4))

    def rat(*shape):
        return [[F(int(v), 7) for v in row] for row in rng.integers(-9, 10, size=shape)]

    A, B, C, E = rat(n, n), rat(n, 1), rat(1, n), rat(1, n)
    Pm = rat(n, n)
    P = [[Pm[i][j] + Pm[j][i] for j in range(n)] for i in range(n)]
    m, L, rho, lam = F(1, 3), F(7, 2), F(5, 6), F(9, 4)
    M = theorem1_exact(A, B, C, E, m, L, P, rho, lam)
    fl = lambda X: np.array(X, dtype=float)  # noqa: E731
    alg = Algorithm(fl(A), fl(B), fl(C), fl(E), float(m), float(L), require_fixed_point=False)
    expected = THEOREM1.matrix(alg, float(rho), {"P": fl(P), "lambda": float(lam)})
    assert np.allclose(fl(M), expected, rtol=1e-12, atol=1e-12)
    t = theorem1_terms(*(sp.Matrix(X) for X in (A, B, C, E)), sp.Rational(1, 3),
                       sp.Rational(7, 2), sp.Matrix(P), symbolic=True)
    r2 = sp.Rational(25, 36)
    Ms = (t["M0P"] - r2 * t["PP"] + r2 * (t["N1"] + t["N2"]) + (1 - r2) * (t["N1"] + t["N3"])
          + sp.Rational(9, 4) * t["N4"])
    assert all(F(str(Ms[i, j])) == M[i][j] for i in range(n + 1) for j in range(n + 1))


# --------------------------------------------------------------------------- shipped specs


@pytest.mark.parametrize("kappa", KAPPAS)
@pytest.mark.parametrize("name", [p.stem for p in SPECS if not load_spec(p).composite])
def test_shipped_certificates_verify_exactly(name, kappa):
    res = _analysis(name, kappa)
    if not res.certified:
        # Theorem 1 (only sufficient) certifies none here (heavy-ball: docs/paper-notes.md,
        # item 11): nothing to verify
        assert (name, kappa) in {
            ("heavy-ball", 10), ("heavy-ball", 100), ("triple-momentum", 10),
            ("triple-momentum", 100), ("nesterov-quadratic", 100),
        }
        pytest.skip(f"{name} at kappa={kappa} is not certified by Theorem 1")
    spec = _spec(name)
    v = verify_exact(spec, kappa, res.rho, res.P, res.lam)
    assert v.verified == "exact", v.reason
    rho_q = F(v.rho_proven)
    assert rho_q >= F(res.rho) and float(rho_q) <= res.rho * (1 + 1e-7)
    assert F(v.lambda_rational) >= 0 and F(v.delta) >= 0
    assert prove_psd([[F(x) for x in row] for row in v.P_rational]).psd
    # a deliberately wrong certificate: same P, lambda, rho lowered by 1e-3
    w = verify_exact(spec, kappa, res.rho - 1e-3, res.P, res.lam)
    assert w.verified == "failed" and w.reason and "M ⪯ 0" in w.reason
    assert w.rho_proven is None


def _recheck_with_sympy(cert: dict) -> bool:
    """The reviewer's recipe of docs/verify.md: sympy only, exact algebraic entries."""
    R = sp.Rational
    m, L, rho, lam = R(cert["m"]), R(cert["L"]), R(cert["rho_proven"]), R(cert["lambda"])
    A, B, C, E = (sp.Matrix(cert["matrices"][k]).applyfunc(lambda s: sp.radsimp(sp.sympify(s)))
                  for k in "ABCE")
    P = sp.Matrix(cert["P"]).applyfunc(R)
    n, h = A.shape[0], R(1, 2)
    S = A.row_join(B)
    M0 = S.T * P * S - rho**2 * sp.diag(P, 0)
    last = sp.zeros(1, n).row_join(sp.ones(1, 1))
    X1 = (E * A - C).row_join(E * B).col_join(last)
    X2 = (C - E).row_join(sp.zeros(1, 1)).col_join(last)
    X3 = C.row_join(sp.zeros(1, 1)).col_join(last)
    N1 = X1.T * sp.Matrix([[L / 2, h], [h, 0]]) * X1
    N2 = X2.T * sp.Matrix([[-m / 2, h], [h, 0]]) * X2
    N3 = X3.T * sp.Matrix([[-m / 2, h], [h, 0]]) * X3
    N4 = X3.T * sp.Matrix([[-m * L / (m + L), h], [h, -1 / (m + L)]]) * X3
    M = (M0 + rho**2 * (N1 + N2) + (1 - rho**2) * (N1 + N3) + lam * N4).applyfunc(sp.expand)

    def definite(X: sp.Matrix) -> bool:  # leading principal minors > 0, signs at 60 digits
        return all(sp.N(sp.expand(X[:k, :k].det(method="berkowitz")), 60) > 0
                   for k in range(1, X.shape[0] + 1))

    return definite(-M) and definite(P) and lam >= 0 and 0 < rho <= 1


def test_written_certificate_rechecks_without_sosalgo(tmp_path):
    res = _analysis("nesterov", 10)
    v = verify_exact(_spec("nesterov"), 10, res.rho, res.P, res.lam)
    path = write_certificate(v, tmp_path / "cert.json")
    cert = json.loads(path.read_text())
    assert cert["verified"] == "exact" and cert["fixed_point_u"] == ["1", "1"]
    assert cert["params"]["beta"] == str((sp.sqrt(10) - 1) / (sp.sqrt(10) + 1))
    assert _recheck_with_sympy(cert)
    # the same recipe rejects the certificate with rho lowered by 1e-3
    cert["rho_proven"] = str(F(cert["rho_proven"]) - F(1, 1000))
    assert not _recheck_with_sympy(cert)


def test_theta_override_is_exact():
    spec = _spec("three-parameter")
    theta = {"h": 0.1, "beta": 0.5, "gamma": 0.5}
    res = analyze_spec(spec, 10, theta=theta, tol=1e-6)
    assert res.certified
    v = verify_exact(spec, 10, res.rho, res.P, res.lam, theta=theta)
    assert v.verified == "exact", v.reason
    assert v.theta["h"] == "3602879701896397/36028797018963968"  # the binary value of 0.1
    assert all(lo == hi for mat in v.enclosures.values() for row in mat for lo, hi in row)


# --------------------------------------------------------------------------- gradient by hand


def _gradient_certificate(kappa: Fraction, rho: Fraction) -> tuple[Fraction, Fraction]:
    """Closed-form Theorem 1 certificate of the gradient method, h = 1/L, m = 1, L = kappa.

    With n = 1 (A = 1, B = -h, C = E = 1, so N2 = 0), c = 1 - rho^2, eq. (15) reads
      M11 = c p - c/2 - lambda k/(k+1),  M12 = -p/k + c/2 + lambda/2,
      M22 = p/k^2 - 1/(2k) - lambda/(k+1).
    det M is a concave quadratic in lambda; at its maximizer
      lambda = (k+1)(2p(1-c) + 1 - ck) / (k-1)^2
    it is det M = F1 F2 / (4 k^2 (k-1)^2), F1 = c(2k-1) - k - 2p(1-c) < 0 (as c < 1/2 here)
    and F2 = p(2ck^2 - 4k + 2) + ck^2 - k = -2 eta k^2 p + (k-1) - eta k^2, where
    eta = rho^2 - (1 - 1/k)^2 > 0. p = (k-1)/(2 eta k^2) gives F2 = -eta k^2 < 0, so
    det M > 0, and M22 < 0 for k >= 2 (sympy-checked): M ≺ 0, P = p > 0, lambda > 0.
    At rho = 1 - 1/k itself no certificate exists: w = (1, 1) gives w'Mw = (k-1)/(2k^2).
    """
    k = kappa
    eta = rho * rho - (1 - 1 / k) ** 2
    assert eta > 0
    p = (k - 1) / (2 * eta * k * k)
    c = 1 - rho * rho
    lam = (k + 1) * (2 * p * (1 - c) + 1 - c * k) / (k - 1) ** 2
    return p, lam


@pytest.mark.parametrize("kappa,eps", [(2, F(1, 100)), (10, F(1, 1000)), (100, F(1, 10**6))])
def test_gradient_hand_certificate(kappa, eps):
    k = F(kappa)
    rho = 1 - 1 / k + eps
    p, lam = _gradient_certificate(k, rho)
    spec = _spec("gradient")
    v = verify_exact(spec, kappa, rho, [[p]], lam, rho_steps=(0,))
    assert v.verified == "exact", v.reason
    assert F(v.rho_proven) == rho and v.P_rational == [[str(p)]]
    assert v.lambda_rational == str(lam) and F(v.delta) > 0
    M = theorem1_exact([[1]], [[-1 / k]], [[1]], [[1]], 1, k, [[p]], rho, lam)
    assert M[1][1] < 0 and M[0][0] * M[1][1] - M[0][1] ** 2 > 0


@pytest.mark.parametrize("kappa", [2, 10, 100])
def test_gradient_rate_one_minus_inverse_kappa_is_not_attained(kappa):
    """w = (1, 1) (the quadratic of curvature m) gives w'Mw = (k-1)/(2k^2) for every P, lambda."""
    k = F(kappa)
    rho = 1 - 1 / k
    for p, lam in [(F(1), F(1)), (F(10**6), F(3, 7)), (F(0), F(0)), (F(5), F(10**5))]:
        M = theorem1_exact([[1]], [[-1 / k]], [[1]], [[1]], 1, k, [[p]], rho, lam)
        assert M[0][0] + 2 * M[0][1] + M[1][1] == (k - 1) / (2 * k * k)
    p, lam = _gradient_certificate(k, rho + F(1, 10**4))
    v = verify_exact(_spec("gradient"), kappa, rho, [[p]], lam, rho_steps=(0,))
    assert v.verified == "failed" and "disproved" in v.reason


# --------------------------------------------------------------------------- simulation


def test_function_suite_membership():
    """Every test function satisfies eq. (4)-(5) on random pairs; gap(0) = 0, grad(0) = 0."""
    rng = np.random.default_rng(7)
    m, L = 0.5, 12.0
    for d in (1, 3):
        for f in function_suite(m, L, d, rng):
            z = rng.standard_normal((300, d)) * 10 ** rng.uniform(-3, 1.5, (300, 1))
            y = rng.standard_normal((300, d)) * 10 ** rng.uniform(-3, 1.5, (300, 1))
            dz, dg = z - y, f.grad_z(z) - f.grad_z(y)
            nz2 = np.einsum("bi,bi->b", dz, dz)
            inner = np.einsum("bi,bi->b", dz, dg)
            assert np.all(inner >= m * nz2 * (1 - 1e-9)), f.name
            assert np.all(np.einsum("bi,bi->b", dg, dg) <= L**2 * nz2 * (1 + 1e-9)), f.name
            lin = f.gap(y) + np.einsum("bi,bi->b", f.grad_z(y), dz)
            scale = 1e-9 * (1 + np.abs(f.gap(z)))
            assert np.all(f.gap(z) >= lin + m / 2 * nz2 - scale), f.name
            assert np.all(f.gap(z) <= lin + L / 2 * nz2 + scale), f.name
            zero = np.zeros((1, d))
            assert f.gap(zero)[0] == 0 and np.all(f.grad_z(zero) == 0), f.name
            x = f.x_star + z[:3]
            assert np.allclose(f.value(x), f.f_star + f.gap(z[:3]), rtol=1e-12, atol=1e-12)
            h = 1e-6
            fd = [(f.value(x[0] + h * e) - f.value(x[0] - h * e)) / (2 * h) for e in np.eye(d)]
            assert np.allclose(fd, f.grad(x[0]), rtol=1e-5, atol=1e-5), f.name


def test_lrp_function_matches_paper():
    f = lrp_counterexample(1, np.random.default_rng(0), 1.0, 25.0)
    x = np.array([[0.5], [1.5], [3.0], [-2.0]])
    assert np.allclose(f.grad(x)[:, 0], [12.5, 1.5 + 24, 75 - 24, -50])
    assert f.x_star.tolist() == [0.0] and f.f_star == 0.0


def test_simulation_nesterov_certificate_has_no_violation():
    res = _analysis("nesterov", 10)
    alg = bind(_spec("nesterov"), 10)
    sim = simulate_check(alg, res.rho, res.P, res.lam)
    assert sim.ok and sim.n_violations == 0, sim.violations[:3]
    assert sim.worst_ratio <= 1 + 1e-9 and sim.consistency < 1e-12
    n_fns = (4 + 4) + 2 * (3 + 4)  # d = 1: 4 quadratics; d > 1: 3; plus 4 other functions
    assert len(sim.functions) == n_fns
    assert sim.trajectories == 20 * n_fns + 3 * 3  # + the 3 suggested LRP starts per dim


def test_simulation_finds_wrong_gradient_rate():
    """rho = 0.5 for gradient at kappa = 10: on f = x^2/2, V_{k+1}/V_k = (1 - 1/10)^2."""
    res = _analysis("gradient", 10)
    sim = simulate_check(bind(_spec("gradient"), 10), 0.5, res.P, res.lam)
    assert not sim.ok and sim.n_violations > 0
    on_m = [v for v in sim.violations if v.function == "quadratic q=1" and v.kind == "decrease"]
    assert on_m and np.isclose(on_m[0].ratio, 0.81 / 0.25)


def test_heavy_ball_lrp_counterexample():
    """Heavy-ball tuned for quadratics, kappa = 25 (Lessard, Recht, Packard 2016, Sec. 4.6)."""
    spec = _spec("heavy-ball")
    alg = bind(spec, 25)
    assert np.isclose(alg.params["h"], 1 / 9) and np.isclose(alg.params["beta"], 4 / 9)
    assert not analyze_spec(spec, 25, tol=1e-6).certified
    f = lrp_counterexample(1, np.random.default_rng(0), alg.m, alg.L)
    # the method does not converge from x_{-1} = x_0 = 3.3: it settles on a cycle
    xi = np.full(2, 3.3)
    gaps = []
    for _ in range(300):
        g = f.grad(np.array([alg.C[0] @ xi]))[0]
        xi = alg.A @ xi + alg.B[:, 0] * g
        gaps.append(f.value(np.array([alg.E[0] @ xi])) - f.f_star)
    assert min(gaps[200:]) > 1.0
    # so any claimed rho < 1 fails, whatever P: V cannot decay along a cycle
    for P in (np.eye(2), np.zeros((2, 2)), 100 * np.eye(2)):
        sim = simulate_check(alg, 0.99, P, 0.0, functions=[f], starts=4, iters=400)
        assert not sim.ok and sim.violations_by_function.get("lrp (d=1)", 0) > 0
    v = verify_exact(spec, 25, 0.99, np.eye(2), 1.0)
    assert v.verified == "failed"
