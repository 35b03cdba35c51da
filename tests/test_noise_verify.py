"""Noise certificates in ``sosalgo verify`` and rates proven exactly on both axes
(sosalgo.proofs.results, sosalgo.design_search.objectives, sosalgo.api.design), checked against
the closed forms of gradient descent x+ = x - h (grad f(x) + w) on F(m, L):
rate max(|1 - hm|, |1 - hL|) and gamma^2 = max over q in {m, L} of h/(q(2 - hq))."""

from __future__ import annotations

import json
import math

import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.design_search import objectives
from sosalgo.pareto import pareto_filter

from .conftest import spec_path

M, L = 1.0, 10.0  # kappa = 10 with L = kappa (the shipped specs' convention)


def _gd_gamma(h: float) -> float:
    return math.sqrt(max(h / (q * (2 - h * q)) for q in (M, L)))


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def gd_noise(tmp_path_factory):
    """``analyze specs/gradient.yaml --kappa 10 --noise --json`` written to a file."""
    out = tmp_path_factory.mktemp("noise")
    res = _run("analyze", spec_path("gradient"), "--kappa", 10, "--noise", "--json",
               "--out", out, "--quiet")
    assert res.exit_code == 0, res.output
    path = out / "gd.json"
    path.write_text(res.output)
    return out, json.loads(res.output)


def test_verify_rechecks_the_noise_of_analyze_rows(gd_noise):
    out, doc = gd_noise
    res = _run("verify", out / "gd.json", "--out", out, "--json", "--no-simulate")
    assert res.exit_code == 0, res.output
    chk = json.loads(res.output)["results"][0]
    assert chk["verified"] == "exact" and chk["noise_verified"] == "exact"
    h = 1 / L  # specs/gradient.yaml's step
    gamma = _gd_gamma(h)  # the worst case over F(m, L) is a quadratic for GD
    assert gamma * (1 - 1e-12) <= chk["noise_proven"] <= gamma * (1 + 1e-5)
    assert chk["noise_proven"] <= doc["rows"][0]["noise"]
    text = _run("verify", out / "gd.json", "--out", out, "--no-simulate")
    assert text.exit_code == 0 and "noise row 0, kappa 10: verified exact" in text.output


@pytest.mark.parametrize("edit", ["noise", "s", "drop"])
def test_verify_fails_a_tampered_noise_claim(gd_noise, edit):
    """A claim below the proven bound, a lowered s (below the closed form: impossible),
    or a missing certificate: exit code 3, the row says why."""
    out, doc = gd_noise
    row = doc["rows"][0]
    if edit == "noise":
        row["noise"] = row["noise"] * (1 - 1e-3)
    elif edit == "s":
        row["noise_certificate"]["s"] = _gd_gamma(1 / L) ** 2 * 0.99
    else:
        row["noise_certificate"] = None
    path = out / f"tampered-{edit}.json"
    path.write_text(json.dumps(doc))
    res = _run("verify", path, "--out", out, "--no-simulate")
    assert res.exit_code == 3, res.output
    assert "noise row 0, kappa 10: NOT verified" in res.output


def test_api_design_with_noise_objective_proves_both_axes():
    """``sosalgo.design(..., objective="noise", max_rate=R)`` on gradient descent: the
    proven rate is <= R and >= the closed form 1 - hm at the returned step, gamma from
    the closed form; the result re-checks on both axes."""
    spec = sosalgo.load_spec(spec_path("gradient"))
    cap = 0.85
    res = sosalgo.design(spec, kappa=10, objective="noise", max_rate=cap, time_limit=30)
    assert res.objective_status == "met" and res.rho_check == "exact"
    assert res.noise_check == "exact"
    h = res.theta["h"]
    assert 1 - h * M - 1e-12 <= res.rho_certified <= cap
    assert res.rho_certified == pytest.approx(1 - h * M, abs=1e-6)
    assert _gd_gamma(h) * (1 - 1e-12) <= res.noise <= _gd_gamma(h) * (1 + 1e-4)
    chk = sosalgo.verify(spec, res, simulate=False)
    assert chk["verified"] == "exact" and chk["noise_verified"] == "exact"


def test_api_design_with_noise_cap_and_bad_options():
    spec = sosalgo.load_spec(spec_path("gradient"))
    G = 0.25
    res = sosalgo.design(spec, kappa=10, max_noise=G, time_limit=30)
    assert res.objective == "rate" and res.objective_status == "met"
    assert res.rho_check == "exact" and res.noise <= G
    # fastest step with gamma <= G: gamma(h)^2 = h/(m(2 - hm)) = G^2 (worst q = m here)
    h = 2 * M * G**2 / (1 + M**2 * G**2)
    assert res.rho_certified == pytest.approx(1 - h * M, abs=1e-4)
    with pytest.raises(ValueError, match="max-rate"):
        sosalgo.design(spec, kappa=10, objective="noise")
    with pytest.raises(ValueError, match="scalarize"):
        sosalgo.design(spec, kappa=10, objective="noise", max_rate=0.9, scalarize="pmi")


def _fake_point(proven: bool) -> objectives.Point:
    return objectives.Point({"h": 0.1}, 0.9, 0.2, 0.2, 0, "exact",
                            rho_check="exact" if proven else "float")


def test_unproven_rates_meet_no_constraint_and_leave_the_front():
    assert objectives._meets(_fake_point(True), "noise", 0.95)
    assert not objectives._meets(_fake_point(False), "noise", 0.95)
    pts = [{"rho": 0.8, "noise": 0.3, "rho_check": "float", "noise_check": "exact"},
           {"rho": 0.85, "noise": 0.35, "rho_check": "exact", "noise_check": "exact"},
           {"rho": 0.9, "noise": 0.2, "rho_check": "exact", "noise_check": "float"}]
    assert [p["rho"] for p in pareto_filter(pts)] == [0.85]


def test_rate_recertified_when_its_own_certificate_is_not_proven(monkeypatch):
    """The analysis's certificate 'fails' its proof (patched): a margin solution at a
    slightly larger rho is proven instead, above the closed-form rate 1 - hm."""
    spec = sosalgo.load_spec(spec_path("gradient"))
    calls = []
    real = objectives._exact_rate

    def first_fails(*args):
        calls.append(args[4])
        return None if len(calls) == 1 else real(*args)

    monkeypatch.setattr(objectives, "_exact_rate", first_fails)
    fam = objectives.design_family(spec, None)
    pt = objectives.certify_point(spec, 10, {"h": 0.15}, fam)
    assert len(calls) == 2 and calls[1] > calls[0]
    assert pt.rho_check == "exact" and pt.rho >= 1 - 0.15 * M
    assert pt.rho == pytest.approx(1 - 0.15 * M, abs=1e-4)
    monkeypatch.setattr(objectives, "_exact_rate", lambda *a: None)
    pt = objectives.certify_point(spec, 10, {"h": 0.15}, fam)
    assert pt.rho_check == "float" and not pt.proven
