"""Noise sensitivity of composite specs (docs/noise.md,
composite specs): closed forms of gradient descent, a Monte Carlo with a nonsmooth g,
the exact proof, one-line refusals."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.model import bind
from sosalgo.sensitivity.composite import (
    composite_noise_certificate,
    composite_noise_quadratic,
)
from sosalgo.sensitivity.exact import verify_composite_noise

SPECS = Path(__file__).resolve().parents[1] / "specs"
KAPPA = 10.0


def gd_gamma(h: float, m: float, L: float) -> float:
    """Closed form of gradient descent on quadratics: max_q sqrt(h / (q (2 - h q)))."""
    return max(math.sqrt(h / (q * (2 - h * q))) for q in (m, L))


@pytest.fixture(scope="module")
def prox_grad():
    return sosalgo.load_spec(SPECS / "proximal-gradient.yaml")


@pytest.mark.parametrize("hL", [1.0, 1.5])
def test_proximal_gradient_meets_gradient_descent_closed_form(prox_grad, hL):
    om = bind(prox_grad, KAPPA, {"h": hL / KAPPA})
    closed = gd_gamma(hL / om.L, om.m, om.L)
    quad, _ = composite_noise_quadratic(om)
    assert quad == pytest.approx(closed, rel=1e-10)  # g = 0 is in the class: a lower bound
    cert = composite_noise_certificate(om, 0, quad)
    assert cert.certified and cert.check_kind == "float"
    assert cert.gamma >= closed * (1 - 1e-9)  # never below the quadratic value
    assert cert.gamma <= closed * (1 + 1e-5)  # tight here: the worst case is quadratic


def test_accelerated_proximal_gradient_above_its_quadratic_value():
    spec = sosalgo.load_spec(SPECS / "accelerated-proximal-gradient.yaml")
    om = bind(spec, KAPPA)
    quad, _ = composite_noise_quadratic(om)
    c0, c1 = (composite_noise_certificate(om, lag, quad) for lag in (0, 1))
    assert c0.certified and c1.certified
    assert quad * (1 - 1e-9) <= c1.gamma <= c0.gamma * (1 + 1e-6)


def test_monte_carlo_with_l1_term_stays_below_certified(prox_grad):
    """x+ = soft(x - h (m (x - a) + w), h lam): f = (m/2)|x - a|^2, g = lam |x|; written
    here, not with sosalgo. Time-average of |x_k - x*|^2 / (d sigma^2) vs gamma^2."""
    om = bind(prox_grad, KAPPA)
    m, h, lam, sigma = om.m, 1.0 / om.L, 0.5, 0.1
    gamma = composite_noise_certificate(om, 0, gd_gamma(h, m, om.L)).gamma
    rng = np.random.default_rng(7)
    for a in (0.3, 2.0):  # x* at the kink (0), or away from it (a - lam / m)
        xstar = np.sign(a) * max(abs(a) - lam / m, 0.0)
        x = np.full(4000, xstar)
        acc = []
        for k in range(3000):
            z = x - h * (m * (x - a) + sigma * rng.standard_normal(x.shape))
            x = np.sign(z) * np.maximum(np.abs(z) - h * lam, 0.0)
            if k >= 500:
                acc.append(np.mean((x - xstar) ** 2) / sigma**2)
        acc = np.array(acc)
        batches = acc.reshape(25, -1).mean(axis=1)
        mean, se = batches.mean(), batches.std(ddof=1) / math.sqrt(len(batches))
        assert mean <= gamma**2 + 4 * se
        if a > lam / m:  # never near the kink: the loop is linear, gamma_q^2 is reached
            assert abs(mean - gd_gamma(h, m, om.L) ** 2) <= 4 * se


def test_exact_proof_passes_and_fails_when_s_lowered(prox_grad):
    om = bind(prox_grad, KAPPA)
    cert = composite_noise_certificate(om, 1, 0.23)
    proof = verify_composite_noise(prox_grad, KAPPA, cert.certificate)
    assert proof.ok and proof.gamma_proven >= cert.gamma
    assert proof.gamma_proven == pytest.approx(cert.gamma, rel=1e-8)
    low = dict(cert.certificate, s=cert.certificate["s"] * (1 - 1e-3))
    assert not verify_composite_noise(prox_grad, KAPPA, low).ok


def test_analyze_noise_on_composite_spec_json(tmp_path):
    res = sosalgo.noise(SPECS / "projected-gradient.yaml", KAPPA, lag=0)
    om = bind(sosalgo.load_spec(SPECS / "projected-gradient.yaml"), KAPPA)
    h = 1.0 / om.L  # the spec's default step
    assert res.check_kind == "exact" and res.noise_limsup is None
    assert res.noise_quadratic == pytest.approx(gd_gamma(h, om.m, om.L), rel=1e-10)
    assert res.noise >= res.noise_quadratic


def test_no_noisy_call_is_one_line(tmp_path):
    out = tmp_path / "never"
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "douglas-rachford.yaml"), "--noise",
                                   "--kappa", "10", "--out", str(out)])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "douglas-rachford.yaml" in lines[0] and "--noise" in lines[0]
    assert not out.exists()
