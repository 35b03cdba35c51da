"""The certified bound on the limsup itself, ``noise_limsup`` (docs/noise.md, "The limsup itself"),
checked against closed forms, scipy's Lyapunov solver and Monte Carlo runs written here."""

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
from sosalgo.sensitivity.limsup import noise_limsup_certificate

SPECS = "specs"


def _spec_alg(name: str, kappa: float):
    spec = sosalgo.load_spec(f"{SPECS}/{name}.yaml")
    return spec, bind(spec, kappa)


def _worst_quadratic_variance(alg, points: int = 201) -> float:
    """max over a grid of q in [m, L] of E X E', X = A_q X A_q' + B B' (scipy), the limit
    of E|x_k - x*|^2 / (d sigma^2) on (q/2)|x - x*|^2."""
    out = 0.0
    for q in np.linspace(alg.m, alg.L, points):
        Aq = alg.A + q * alg.B @ alg.C
        assert max(abs(np.linalg.eigvals(Aq))) < 1
        out = max(out, float((alg.E @ solve_discrete_lyapunov(Aq, alg.B @ alg.B.T)
                              @ alg.E.T)[0, 0]))
    return out


@pytest.mark.parametrize("kappa", [10, 100])
@pytest.mark.parametrize("lag", [0, 1])
def test_gradient_descent_meets_its_closed_form(kappa, lag):
    """x+ = x - h(qx + w), h = 1/L: the variance tends to h^2 / (1 - (1 - hq)^2), largest at
    q = m; the limsup bound over F(m, L) must meet it (rho at the rate 1 - h m)."""
    h = 1.0 / kappa
    closed = math.sqrt(max(h * h / (1 - (1 - h * q) ** 2) for q in (1.0, float(kappa))))
    cert = noise_limsup_certificate(_spec_alg("gradient", kappa)[1], lag)
    assert cert.certified and cert.check_kind == "float"
    assert closed <= cert.gamma <= closed * (1 + 1e-5)
    assert cert.rho == pytest.approx(1 - h, abs=1e-5)


@pytest.mark.parametrize("name", ["nesterov", "triple-momentum", "heavy-ball",
                                  "three-parameter"])
def test_never_below_the_quadratic_value(name):
    alg = _spec_alg(name, 10)[1]
    cert = noise_limsup_certificate(alg, 1)
    assert cert.certified
    assert cert.gamma**2 >= _worst_quadratic_variance(alg) * (1 - 1e-9)


def _per_time_variance(alg, grad, sigma: float, rng, chains: int = 100, d: int = 20,
                       burn: int = 300, blocks: int = 12, block: int = 100) -> tuple[float, float]:
    """The largest, over blocks of ``block`` steps after ``burn``, of the chain mean of
    |x_k - x*|^2 / (d sigma^2) (a per-time estimate of the limsup, not a time average over
    the whole run), with that block's standard error from the per-chain block means.
    Started away from x* (xi_0 = 0.05 in every entry); x* = 0 in these coordinates."""
    B, Cr, Er = alg.B[:, 0], alg.C[0], alg.E[0]
    xi = np.full((alg.n, chains * d), 0.05)
    worst, worst_se = -math.inf, 0.0
    for k in range(burn + blocks * block):
        if k >= burn and (k - burn) % block == 0:
            acc = np.zeros(chains)
        u = grad(Cr @ xi) + sigma * rng.standard_normal(chains * d)
        if k >= burn:
            x = (Er @ xi).reshape(chains, d)
            acc += np.sum(x * x, axis=1) / (d * sigma**2 * block)
            if (k - burn) % block == block - 1 and acc.mean() > worst:
                worst, worst_se = float(acc.mean()), float(acc.std(ddof=1) / math.sqrt(chains))
        xi = alg.A @ xi + np.outer(B, u)
    return worst, worst_se


@pytest.mark.parametrize("name", ["nesterov", "triple-momentum"])
@pytest.mark.parametrize("inner", ["L", "m"])
def test_monte_carlo_on_non_quadratic_functions_stays_below(name, inner):
    alg = _spec_alg(name, 10)[1]
    f = huber_like(1, np.random.default_rng(3), alg.m, alg.L, inner=inner,
                   width=0.01 if inner == "L" else 0.05, rotate=False)
    cert = noise_limsup_certificate(alg, 1)
    worst, se = _per_time_variance(
        alg, lambda y: f.grad_z(y.reshape(-1, 1)).reshape(y.shape), 0.1,
        np.random.default_rng(4))
    assert worst <= cert.gamma**2 + 4 * se


def test_monte_carlo_reaches_the_bound_for_gradient_descent():
    """On its worst quadratic (q = m) GD's per-time variance is the certified limsup."""
    alg = _spec_alg("gradient", 10)[1]
    cert = noise_limsup_certificate(alg, 1)
    worst, se = _per_time_variance(alg, lambda y: alg.m * y, 0.1, np.random.default_rng(5))
    assert worst <= cert.gamma**2 + 4 * se
    assert worst >= cert.gamma**2 - 8 * se  # the largest of 12 blocks, each near the limit


def test_exact_proof_passes_and_fails_when_tampered():
    spec, alg = _spec_alg("nesterov", 10)
    cert = noise_limsup_certificate(alg, 1)
    proof = verify_noise(spec, 10, cert.certificate, limsup=True)
    assert proof.ok, proof.reason
    assert cert.gamma <= proof.gamma_proven <= cert.gamma * (1 + 1e-8)
    low_s = dict(cert.certificate, s=cert.certificate["s"] * 0.99)
    assert not verify_noise(spec, 10, low_s, limsup=True).ok
    low_rho = dict(cert.certificate, rho=cert.certificate["rho"] * 0.99)
    assert not verify_noise(spec, 10, low_rho, limsup=True).ok
    one = verify_noise(spec, 10, dict(cert.certificate, rho=1.0), limsup=True)
    assert not one.ok and "rho" in one.reason
    assert not verify_noise(spec, 10, cert.certificate).ok  # not a certificate of `noise`


def test_analyze_verify_and_python_twin(tmp_path):
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["analyze", f"{SPECS}/triple-momentum.yaml", "--kappa", "10",
                                   "--noise", "--json", "--no-plot", "--out", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    row = doc["rows"][0]
    assert row["noise_limsup_check"] == "exact" and 0 < row["noise_limsup_rho"] < 1
    assert row["noise_limsup"] ** 2 >= _worst_quadratic_variance(bind(
        sosalgo.load_spec(f"{SPECS}/triple-momentum.yaml"), 10)) * (1 - 1e-9)
    header = (out / "triple-momentum-analysis-interpolation.csv").read_text().splitlines()[0]
    header = header.split(",")
    assert header[-4:] == ["noise_limsup", "noise_limsup_rho", "noise_limsup_check",
                           "noise_limsup_certificate"]
    good, bad = tmp_path / "good.json", tmp_path / "bad.json"
    good.write_text(json.dumps(doc))
    claimed = row["noise_limsup"]
    row["noise_limsup"] *= 0.99  # a claim below what the certificate proves
    bad.write_text(json.dumps(doc))
    ok = CliRunner().invoke(cli, ["verify", str(good), "--no-simulate", "--out",
                                  str(tmp_path / "v")])
    assert ok.exit_code == 0, ok.output
    assert "noise_limsup row 0, kappa 10: verified exact" in ok.output
    no = CliRunner().invoke(cli, ["verify", str(bad), "--no-simulate", "--out",
                                  str(tmp_path / "v")])
    assert no.exit_code == 3 and "noise_limsup row 0, kappa 10: NOT verified" in no.output
    twin = sosalgo.noise(f"{SPECS}/triple-momentum.yaml", 10)
    assert twin.noise_limsup == pytest.approx(claimed, rel=1e-4)


def test_bad_input_is_one_line(tmp_path):
    never = tmp_path / "never"
    res = CliRunner().invoke(cli, ["analyze", f"{SPECS}/douglas-rachford.yaml", "--noise",
                                   "--out", str(never)])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1
    assert not never.exists()
    res = CliRunner().invoke(cli, ["analyze", f"{SPECS}/gradient.yaml", "--kappa", "10",
                                   "--noise", "--json", "--no-plot", "--out",
                                   str(tmp_path / "o")])
    doc = json.loads(res.stdout)
    doc["rows"][0]["noise_limsup_certificate"] = "not an object"
    path = tmp_path / "malformed.json"
    path.write_text(json.dumps(doc))
    res = CliRunner().invoke(cli, ["verify", str(path), "--out", str(never)])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "noise_limsup_certificate" in lines[0]
    assert not never.exists()
