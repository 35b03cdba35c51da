"""Exact verification of sublinear certificates (m: 0) against closed forms and against
an evaluation of the proven potential written out here (not the verifier's code)."""

from __future__ import annotations

import copy
import json
from fractions import Fraction

import pytest
import yaml
from click.testing import CliRunner

from sosalgo.analysis import analyze_sublinear
from sosalgo.certificates.exact_sublinear import verify_exact_sublinear
from sosalgo.cli import cli
from sosalgo.documents import verify_document
from sosalgo.spec import spec_from_dict

from .conftest import SPECS

GD = yaml.safe_load((SPECS / "gradient-convex.yaml").read_text())


def _gd(h: str) -> dict:
    return {**GD, "parameters": {"h": {"value": h, "range": [0, "2/L"]}}}


@pytest.fixture(scope="module")
def gd_row() -> dict:
    """gradient descent h = 1/L, L = 1: the analysis row as JSON would carry it."""
    return json.loads(json.dumps(analyze_sublinear(spec_from_dict(GD)).to_dict()))


def _huber_floor(hL: float) -> float:
    """Closed form (L = 1): the Huber function with threshold R/(2kh + 1) gives
    f(x_k) - f* = R^2/(4kh + 2) after k steps from |x_0 - x*| = R (Drori, Teboulle 2014),
    so every valid c >= sup_k k/(4kh + 2) = 1/(4h)."""
    return 1 / (4 * hL)


def _huber(x: Fraction) -> tuple[Fraction, Fraction]:
    """f and f' of the Huber function with threshold 1 (L = 1), minimum 0 at 0."""
    if abs(x) <= 1:
        return x * x / 2, x
    return abs(x) - Fraction(1, 2), Fraction(1 if x > 0 else -1)


def _potential(cert: dict, k: int, x: Fraction, f, measure: bool = False) -> Fraction:
    """phi_k = z'(P + kQ + k^2 R)z + (p + kq + k^2 r) psi, z = (x - x*, f'(x)), psi = f(x)
    (x* = 0, f* = 0): gradient descent's state is x and its one call is at x."""
    val, g = f(x)
    z = (x, g)
    out = Fraction(0)
    for j, (W, w) in enumerate((("P", "p"), ("Q", "q"), ("R", "r"))):
        M = [[Fraction(v) for v in row] for row in cert[W]]
        quad = sum(z[a] * M[a][b] * z[b] for a in range(2) for b in range(2))
        out += Fraction(k) ** j * (quad + Fraction(cert[w][0]) * val)
    return out


@pytest.mark.parametrize("h", ["1/L", "1.5/L"])
def test_gradient_constants_proven_exactly(h):
    spec = spec_from_dict(_gd(h))
    row = json.loads(json.dumps(analyze_sublinear(spec).to_dict()))
    res = verify_exact_sublinear(spec, row)
    assert res.ok, res.reason
    proven = Fraction(res.constant_proven)
    assert proven >= Fraction(row["constant"])  # the constant, or slightly above
    assert float(proven) <= row["constant"] * (1 + 1e-6)
    hL = Fraction(res.params["h"])
    assert hL == (Fraction(1) if h == "1/L" else Fraction(3, 2))  # exact rationals
    assert float(proven) >= _huber_floor(float(hL))  # never below the closed-form floor
    assert res.to_dict()["verified"] == "exact" and res.L == "1"


@pytest.mark.parametrize("f", [_huber, lambda x: (x * x / 2, x)], ids=["huber", "quadratic"])
def test_proven_potential_holds_along_trajectories(gd_row, f):
    """The proven rational certificate, evaluated here from its definition along exact
    trajectories of gradient descent (h = 1/L = 1): phi decreases, phi_k >= (k + b)
    (f(x_k) - f*), phi_0 <= C |x_0 - x*|^2, so f(x_k) - f* <= C |x_0|^2 / k."""
    res = verify_exact_sublinear(spec_from_dict(GD), gd_row)
    assert res.ok, res.reason
    cert, C = res.certificate, Fraction(res.constant_proven)
    b = Fraction(cert["b"][0])
    for x0 in (Fraction(1, 3), Fraction(-7, 2), Fraction(40)):
        x, phi_prev = x0, None
        assert _potential(cert, 0, x0, f) <= C * x0 * x0
        for k in range(60):
            phi = _potential(cert, k, x, f)
            assert phi >= (k + b) * f(x)[0]
            if phi_prev is not None:
                assert phi <= phi_prev
            if k >= 1:
                assert f(x)[0] <= C * x0 * x0 / k
            phi_prev, x = phi, x - f(x)[1]


def test_tampered_certificates_fail(gd_row):
    spec = spec_from_dict(GD)
    bad = copy.deepcopy(gd_row)
    bad["certificate"]["multipliers"]["eta0"]["f:y1[0]>y1[1]"] *= 0.9
    res = verify_exact_sublinear(spec, bad)
    assert not res.ok and res.verified == "failed" and res.reason
    low = copy.deepcopy(gd_row)
    low["constant"] = 0.2  # below the tight L/4: no certificate can prove it
    res = verify_exact_sublinear(spec, low)
    assert not res.ok and "block I" in res.reason
    old = copy.deepcopy(gd_row)
    del old["certificate"]["S_D"]
    assert "rerun analyze" in verify_exact_sublinear(spec, old).reason


def test_step_one_third_is_proven_with_exact_rationals():
    """h = 1/(3L), L = 1 is not a binary float; the spec's expression is exactly 1/3."""
    spec = spec_from_dict(_gd("1/(3*L)"))
    row = analyze_sublinear(spec).to_dict()
    res = verify_exact_sublinear(spec, row)
    assert res.ok, res.reason
    assert res.params["h"] == "1/3"
    assert float(Fraction(res.constant_proven)) >= _huber_floor(1 / 3)


def test_irrational_step_is_refused_with_a_reason():
    spec = spec_from_dict(_gd("1/(sqrt(2)*L)"))
    res = verify_exact_sublinear(spec, analyze_sublinear(spec).to_dict())
    assert not res.ok and "parameters.h" in res.reason and "not a rational" in res.reason


def test_design_row_with_theta_is_verified(gd_row):
    spec = spec_from_dict(GD)
    row = analyze_sublinear(spec, {"h": 1.5}).to_dict()
    doc = {"rate_type": "sublinear", "constant": row["constant"], "certified": True,
           "theta": {"h": 1.5}, "certificate": row["certificate"]}
    out = verify_document(json.loads(json.dumps(doc)), spec, simulate=False)
    check = out["results"][0]
    assert check["verified"] == "exact"
    assert float(Fraction(check["constant_proven"])) >= _huber_floor(1.5)


def test_cli_analyze_verify_and_verify_document(tmp_path):
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "gradient-convex.yaml"), "--verify",
                                   "--json", "--no-plot", "--out", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    check = doc["rows"][0]["verification"]
    assert check["verified"] == "exact" and check["simulation"]["ok"]
    assert (tmp_path / "a" / "certificates" / "gradient-convex-sublinear-certificate.json").exists()
    path = tmp_path / "result.json"
    path.write_text(res.stdout)
    ver = CliRunner().invoke(cli, ["verify", str(path), "--out", str(tmp_path / "v")])
    assert ver.exit_code == 0, ver.output
    assert "exact" in ver.stdout
    bad = copy.deepcopy(doc)
    bad["rows"][0]["certificate"]["multipliers"]["eta0"]["f:y1[0]>y1[1]"] *= 0.9
    path.write_text(json.dumps(bad))
    ver = CliRunner().invoke(cli, ["verify", str(path), "--out", str(tmp_path / "v")])
    assert ver.exit_code == 3 and "failed" in ver.stdout
    bad["rows"][0]["certificate"] = "not an object"
    path.write_text(json.dumps(bad))
    ver = CliRunner().invoke(cli, ["verify", str(path), "--out", str(tmp_path / "w")])
    assert ver.exit_code == 2 and ver.stderr.count("\n") == 1
    assert "rows[0].certificate" in ver.stderr and not (tmp_path / "w").exists()


def test_cli_analyze_verify_exits_3_when_the_proof_fails(tmp_path, monkeypatch):
    """A certificate that does not prove its constant (lowered below L/4 before the
    check): the row says failed and the command exits 3, as for linear rows."""
    import sosalgo.batch.sweeps as run

    real = run.sublinear_row

    def lowered(spec):
        row = real(spec)
        row["constant"] = 0.2
        return row

    monkeypatch.setattr(run, "sublinear_row", lowered)
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "gradient-convex.yaml"), "--verify",
                                   "--no-plot", "--out", str(tmp_path)])
    assert res.exit_code == 3 and "failed" in res.stdout


@pytest.mark.deep
def test_proximal_gradient_certificate_proven_exactly():
    pg = yaml.safe_load((SPECS / "proximal-gradient.yaml").read_text())
    data = {**pg, "m": 0, "L": 2, "measure": "function", "output": "y2", "references": {},
            "matrices": {k: v for k, v in pg["matrices"].items() if k != "E"}}
    data.pop("kappa")
    spec = spec_from_dict(data)
    row = analyze_sublinear(spec).to_dict()
    res = verify_exact_sublinear(spec, row)
    assert res.ok, res.reason
    assert float(Fraction(res.constant_proven)) >= 2 / 4  # never below the tight L/4
