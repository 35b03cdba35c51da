"""Theorem 1's matrices against the paper's Section IV (typed from the paper, not derived
by our code) and against an independent numeric construction."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from sosalgo.certificates import THEOREM1
from sosalgo.model import bind
from sosalgo.spec import load_spec
from sosalgo.symbolic import symbolic_lmi, symbolic_matrix

from .conftest import SPECS

m, L, h, beta, rho, lam, p = sp.symbols("m L h beta rho lambda p", real=True)


def _same(a: sp.Matrix, b: sp.Matrix) -> bool:
    return all(sp.simplify(x) == 0 for x in (a - b))


def _rename(M: sp.Matrix) -> sp.Matrix:
    """Map our symbols (with assumptions) to plain real symbols by name."""
    sub = {s: sp.Symbol(s.name, real=True) for s in M.free_symbols}
    return M.xreplace(sub)


def test_gradient_matches_section_iv_with_notes_fix():
    """Section IV, gradient method; M3 = Q_f = 2(m+L) N4, so lambda_paper = lambda/(2(m+L));
    M22 with the factor p the paper drops (docs/paper-notes.md, item 2)."""
    M, _ = symbolic_matrix(load_spec(SPECS / "gradient.yaml"), free=["h"])
    M = _rename(M)
    lp = lam / (2 * (m + L))
    m11 = (p - m / 2) * (1 - rho**2) - 2 * m * L * lp
    m12 = -h * p - rho**2 / 2 + sp.Rational(1, 2) + lp * (m + L)
    m22 = p * h**2 + (L * h**2 - 2 * h) / 2 - 2 * lp
    paper = sp.Matrix([[m11, m12], [m12, m22]])
    assert _same(M, paper)


def test_nesterov_matches_eq_19():
    """Section IV, Nesterov (gamma = beta): M1, M2 and M3 = X' Q_f X as printed (eq. 19)."""
    M, syms = symbolic_matrix(load_spec(SPECS / "nesterov.yaml"), free=["h", "beta"])
    M = _rename(M)
    P = _rename(syms["P"])
    A = sp.Matrix([[0, 1], [-beta, 1 + beta]])
    B = sp.Matrix([[0], [-h]])
    M0 = sp.Matrix(sp.BlockMatrix([[A.T * P * A - rho**2 * P, A.T * P * B],
                                   [B.T * P * A, B.T * P * B]]).as_explicit())
    half = sp.Rational(1, 2)
    g = L * h**2 / 2 - h
    M1 = sp.Matrix([[-half * m * beta**2, half * m * beta**2, -half * beta],
                    [half * m * beta**2, -half * m * beta**2, half * beta],
                    [-half * beta, half * beta, g]])
    M2 = sp.Matrix([[-half * m * beta**2, half * m * beta * (beta + 1), -half * beta],
                    [half * m * beta * (beta + 1), -half * m * (beta + 1) ** 2, half * (beta + 1)],
                    [-half * beta, half * (beta + 1), g]])
    Qf = sp.Matrix([[-2 * m * L, m + L], [m + L, -2]])
    X = sp.Matrix([[-beta, 1 + beta, 0], [0, 0, 1]])
    M3 = X.T * Qf * X
    lp = lam / (2 * (m + L))
    assert _same(M, M0 + rho**2 * M1 + (1 - rho**2) * M2 + lp * M3)


def _independent_M(alg, r, P, la):
    """Theorem 1 assembled directly from its statement with d = 1 (eq. 14-15)."""
    A, B, C, E, mm, LL = alg.A, alg.B, alg.C, alg.E, alg.m, alg.L
    n = A.shape[0]
    M0 = np.block([[A.T @ P @ A - r**2 * P, A.T @ P @ B], [B.T @ P @ A, B.T @ P @ B]])
    z = np.zeros((1, n))
    X1 = np.block([[E @ A - C, E @ B], [z, np.ones((1, 1))]])
    X2 = np.block([[C - E, np.zeros((1, 1))], [z, np.ones((1, 1))]])
    X3 = np.block([[C, np.zeros((1, 1))], [z, np.ones((1, 1))]])
    N1 = X1.T @ np.array([[LL / 2, 0.5], [0.5, 0]]) @ X1
    N2 = X2.T @ np.array([[-mm / 2, 0.5], [0.5, 0]]) @ X2
    N3 = X3.T @ np.array([[-mm / 2, 0.5], [0.5, 0]]) @ X3
    N4 = X3.T @ np.array([[-mm * LL / (mm + LL), 0.5], [0.5, -1 / (mm + LL)]]) @ X3
    return M0 + r**2 * (N1 + N2) + (1 - r**2) * (N1 + N3) + la * N4


@pytest.mark.parametrize("name", ["gradient", "nesterov", "triple-momentum", "three-parameter"])
def test_assembled_blocks_match_independent_M(name):
    rng = np.random.default_rng(0)
    spec = load_spec(SPECS / f"{name}.yaml")
    alg = bind(spec, 7.0)
    prob = THEOREM1.problem(alg)
    n = alg.n
    for _ in range(5):
        G = rng.normal(size=(n, n))
        P = G @ G.T
        la = float(rng.uniform(0, 3))
        r = float(rng.uniform(0.1, 1))
        x = THEOREM1.pack(alg, {"P": P, "lambda": la})
        assert np.allclose(prob.unpack(x)["P"], P)
        Mind = _independent_M(alg, r, P, la)
        assert np.allclose(THEOREM1.matrix(alg, r, {"P": P, "lambda": la}), Mind)
        # The solver's (normalized) block is congruent: M = L D^-1 Mn D^-1, D = diag(I, L).
        Mn = prob.blocks[0].value(x, r)
        D = np.diag([1.0] * n + [alg.L])
        assert np.allclose(alg.L * np.linalg.inv(D) @ Mn @ np.linalg.inv(D), Mind)


def test_symbolic_equals_numeric_at_a_point():
    spec = load_spec(SPECS / "nesterov.yaml")
    M, syms = symbolic_matrix(spec)
    alg = bind(spec, 10.0)
    P = np.array([[2.0, -1.0], [-1.0, 3.0]])
    vals = {s: v for s, v in zip(
        [syms["P"][0, 0], syms["P"][0, 1], syms["P"][1, 1], syms["rho"], syms["lambda"]],
        [2.0, -1.0, 3.0, 0.9, 0.4], strict=True)}
    for s in M.free_symbols:
        if s.name in alg.params:
            vals[s] = alg.params[s.name]
        elif s.name == "m":
            vals[s] = alg.m
        elif s.name == "L":
            vals[s] = alg.L
    num = np.array(M.evalf(subs=vals), dtype=float)
    assert np.allclose(num, THEOREM1.matrix(alg, 0.9, {"P": P, "lambda": 0.4}))


def test_lmi_listing_and_latex():
    spec = load_spec(SPECS / "gradient.yaml")
    text = symbolic_lmi(spec)
    assert "M22 = L*h**2/2 + h**2*p - h - lambda/(L + m)" in text
    latex = symbolic_lmi(spec, latex=True)
    assert r"\begin{aligned}" in latex and "M_{22}" in latex
