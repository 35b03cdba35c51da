"""Certified sensitivity to additive gradient noise (sosalgo.sensitivity), checked against
closed forms, an independent Lyapunov solver and Monte Carlo runs written here."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.linalg import solve_discrete_lyapunov

import sosalgo
from sosalgo.cli import cli
from sosalgo.model import bind
from sosalgo.proofs.functions import huber_like
from sosalgo.sensitivity.exact import verify_noise
from sosalgo.sensitivity.quadratic import noise_quadratic
from sosalgo.sensitivity.sdp import noise_certificate

SPECS = "specs"
SEED_SPECS = ["gradient", "gradient-optimal", "nesterov", "nesterov-quadratic", "heavy-ball",
              "triple-momentum", "three-parameter"]


def _alg(name: str, kappa: float, theta: dict | None = None):
    return bind(sosalgo.load_spec(f"{SPECS}/{name}.yaml"), kappa, theta)


def _gd_closed_form(h: float, m: float, L: float) -> float:
    """x+ = x - h(qx + w): variance h^2 sigma^2 / (1 - (1 - hq)^2) = h / (q (2 - hq)) per
    coordinate; q (2 - hq) is concave in q, so the largest value is at q = m or q = L."""
    return math.sqrt(max(h / (q * (2 - h * q)) for q in (m, L)))


@pytest.mark.parametrize("kappa,hL", [(10, 1.0), (10, 2 / 1.1), (100, 1.0), (100, 0.3)])
def test_quadratic_gradient_descent_closed_form(kappa, hL):
    alg = _alg("gradient", kappa, {"h": hL / kappa})
    expected = _gd_closed_form(hL / kappa, 1.0, float(kappa))
    assert noise_quadratic(alg).gamma == pytest.approx(expected, rel=1e-10)


def _independent_quadratic(alg, points: int = 2001) -> float:
    """max over a q grid of sqrt(E X E'), X = A_q X A_q' + B B' (scipy's solver)."""
    best = 0.0
    for q in np.linspace(alg.m, alg.L, points):
        Aq = alg.A + q * alg.B @ alg.C
        if max(abs(np.linalg.eigvals(Aq))) >= 1:
            return math.inf
        X = solve_discrete_lyapunov(Aq, alg.B @ alg.B.T)
        best = max(best, float((alg.E @ X @ alg.E.T)[0, 0]))
    return math.sqrt(best)


@pytest.mark.parametrize("name", ["nesterov", "triple-momentum", "heavy-ball"])
def test_quadratic_matches_an_independent_lyapunov_solver(name):
    alg = _alg(name, 10)
    ours, grid = noise_quadratic(alg).gamma, _independent_quadratic(alg)
    assert grid <= ours * (1 + 1e-10)  # ours is the max over q, the grid's is below
    assert ours == pytest.approx(grid, rel=1e-6)


def test_unstable_on_a_quadratic_is_infinite_and_never_certified():
    alg = _alg("gradient", 10, {"h": 2.2 / 10})  # |1 - hL| > 1
    assert noise_quadratic(alg).gamma == math.inf
    assert not noise_certificate(alg, 1).certified


@pytest.mark.parametrize("kappa", [10, 100])
@pytest.mark.parametrize("lag", [0, 1])
def test_certified_gradient_descent_equals_its_quadratic_value(kappa, lag):
    """GD's worst case over F(m, L) is a quadratic: the certified upper bound meets the
    closed form on quadratics (a lower bound), up to the SDP's strictness margin."""
    cert = noise_certificate(_alg("gradient", kappa), lag)
    closed = _gd_closed_form(1 / kappa, 1.0, float(kappa))
    assert cert.certified and cert.check_kind == "float"
    assert closed <= cert.gamma <= closed * (1 + 1e-5)


@pytest.mark.parametrize("name", SEED_SPECS)
def test_certified_never_below_the_quadratic_value(name):
    alg = _alg(name, 10)
    cert = noise_certificate(alg, 1)
    assert cert.certified
    assert cert.gamma >= _independent_quadratic(alg, 401) * (1 - 1e-9)


def test_larger_lag_never_worse_on_nesterov():
    g = [noise_certificate(_alg("nesterov", 10), lag).gamma for lag in (0, 1, 2)]
    assert g[1] <= g[0] * (1 + 1e-7) and g[2] <= g[1] * (1 + 1e-7)
    assert g[2] < 0.999 * g[0]  # and the lag helps here


def _monte_carlo(alg, grad, sigma: float, rng, chains: int = 200, d: int = 20,
                 burn: int = 400, steps: int = 2000) -> tuple[float, float]:
    """Mean over time and chains of |x_k - x*|^2 / (d sigma^2) for the method run with
    u_k = grad f(y_k) + sigma w_k (coordinates relative to the fixed point, so x* = 0), and
    its standard error from the spread of the per-chain time averages."""
    n = alg.n
    xi = np.zeros((chains, n, d))
    acc = np.zeros(chains)
    for k in range(burn + steps):
        y = np.einsum("j,cjd->cd", alg.C[0], xi)
        u = grad(y) + sigma * rng.standard_normal((chains, d))
        x = np.einsum("j,cjd->cd", alg.E[0], xi)
        if k >= burn:
            acc += np.sum(x * x, axis=1) / (d * sigma**2)
        xi = np.einsum("ij,cjd->cid", alg.A, xi) + alg.B[:, 0][None, :, None] * u[:, None, :]
    per_chain = acc / steps
    return float(per_chain.mean()), float(per_chain.std(ddof=1) / math.sqrt(chains))


@pytest.mark.parametrize("name", ["gradient", "nesterov"])
def test_monte_carlo_reaches_the_worst_quadratic(name):
    alg = _alg(name, 10)
    quad = noise_quadratic(alg)
    cert = noise_certificate(alg, 1)
    mean, se = _monte_carlo(alg, lambda y: quad.q * y, 0.1, np.random.default_rng(1))
    assert abs(mean - quad.gamma**2) <= 4 * se
    assert mean <= cert.gamma**2 + 4 * se


@pytest.mark.parametrize("name", ["gradient", "nesterov", "triple-momentum"])
@pytest.mark.parametrize("inner", ["L", "m"])
def test_monte_carlo_on_huber_stays_below_the_certified_value(name, inner):
    alg = _alg(name, 10)
    # widths at which the iterates (|x| ~ 0.01 - 0.03 at sigma = 0.1) cross the kink often
    f = huber_like(1, np.random.default_rng(0), alg.m, alg.L, inner=inner,
                   width=0.01 if inner == "L" else 0.05, rotate=False)
    cert = noise_certificate(alg, 1)
    mean, se = _monte_carlo(alg, lambda y: f.grad_z(y.reshape(-1, 1)).reshape(y.shape), 0.1,
                            np.random.default_rng(2))
    assert mean <= cert.gamma**2 + 4 * se


def test_exact_verification_passes_and_fails_when_tampered():
    spec = sosalgo.load_spec(f"{SPECS}/nesterov.yaml")
    cert = noise_certificate(bind(spec, 10), 1)
    proof = verify_noise(spec, 10, cert.certificate)
    assert proof.ok, proof.reason
    assert cert.gamma <= proof.gamma_proven <= cert.gamma * (1 + 1e-8)
    low_s = dict(cert.certificate, s=cert.certificate["s"] * 0.99)  # claims a smaller gamma
    assert not verify_noise(spec, 10, low_s).ok
    small_P = dict(cert.certificate, P=np.asarray(cert.certificate["P"]) * 0.9)
    assert not verify_noise(spec, 10, small_P).ok


def test_analyze_noise_command_and_python_twin(tmp_path):
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["analyze", f"{SPECS}/gradient.yaml", "--kappa", "10",
                                   "--noise", "--json", "--no-plot", "--out", str(out)])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)["rows"][0]
    closed = _gd_closed_form(0.1, 1.0, 10.0)
    assert row["noise_quadratic"] == pytest.approx(closed, rel=1e-10)
    assert closed <= row["noise"] <= closed * (1 + 1e-5)
    assert row["noise_lag"] == 0 and row["noise_check"] == "exact"
    header = (out / "gradient-analysis-interpolation.csv").read_text().splitlines()[0].split(",")
    assert {"noise", "noise_quadratic", "noise_lag"} <= set(header)
    twin = sosalgo.noise(f"{SPECS}/gradient.yaml", 10)
    assert twin.noise == pytest.approx(row["noise"], rel=1e-6)


def test_noise_refuses_specs_without_a_noisy_gradient_in_one_line(tmp_path):
    """Douglas-Rachford only takes proximal steps: there is no gradient to perturb."""
    out = tmp_path / "never"
    res = CliRunner().invoke(cli, ["analyze", f"{SPECS}/douglas-rachford.yaml", "--noise",
                                   "--out", str(out)])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "douglas-rachford.yaml" in lines[0]
    assert "one gradient call on F(m, L)" in lines[0]
    assert not out.exists()
