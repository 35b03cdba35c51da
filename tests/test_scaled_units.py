"""Specs written in tiny units (m = 1e-300): the rate is scale-invariant (f is in F(m, L)
exactly when f/L is in F(m/L, 1), with the same iterates for the method with B L), so the
exact proofs go through in units where L = 1 and say so; a false rate is still refused."""

from __future__ import annotations

import json
import math

import pytest
from click.testing import CliRunner

from sosalgo.certificates import get_family
from sosalgo.cli import cli
from sosalgo.spec import load_spec

from .conftest import SPECS


def _tiny(tmp_path, name: str = "nesterov"):
    path = tmp_path / f"{name}-tiny.yaml"
    path.write_text((SPECS / f"{name}.yaml").read_text() + "m: 1e-300\n")
    return path


def _analyze(spec, tmp_path, family: str, *extra: str) -> dict:
    res = CliRunner().invoke(cli, ["analyze", str(spec), "--kappa", "10", "--certificate",
                                   family, "--out", str(tmp_path), "--json", "--quiet",
                                   "--no-plot", *extra])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


@pytest.mark.parametrize("family", ["interpolation", "theorem1"])
def test_tiny_units_are_proven_in_units_where_L_is_1(tmp_path, family):
    doc = _analyze(_tiny(tmp_path), tmp_path / "tiny", family, "--verify")
    (row,) = doc["rows"]
    check = row["verification"]
    assert check["verified"] == "exact" and check["reason"] is None
    assert check["rho_proven_float"] >= row["rho"]
    assert "f/L in F(m/L, 1)" in check["units"]
    cert = json.loads(open(check["certificate_file"]).read())
    assert cert["units"] == check["units"] and cert["L"] != "10"  # the class as written
    assert doc["vouched"] is True
    # the same method in units m = 1 (a peer run): the same rate, the proof as written
    ref = _analyze(SPECS / "nesterov.yaml", tmp_path / "ref", family, "--verify")["rows"][0]
    assert row["rho"] == pytest.approx(ref["rho"], abs=1e-5)
    assert "units" not in ref["verification"]
    # Nesterov at kappa 10: no first-order method beats 1 - 1/sqrt(kappa) on F(m, L)
    assert check["rho_proven_float"] >= 1 - 1 / math.sqrt(10)


def test_tiny_units_refuse_a_rate_below_the_lower_bound(tmp_path):
    """The certificate of the tiny spec claimed at rho = 0.68 < 1 - 1/sqrt(10): no
    certificate proves it, in any units."""
    spec_path = _tiny(tmp_path)
    (row,) = _analyze(spec_path, tmp_path, "interpolation")["rows"]
    fam = get_family("interpolation")
    spec = load_spec(spec_path)
    good = fam.exact_check(spec, 10.0, row["rho"], row["certificate"])
    assert good.verified == "exact" and good.units
    bad = fam.exact_check(spec, 10.0, 0.68, row["certificate"])
    assert bad.verified != "exact" and bad.units is None and bad.reason


def test_verify_refuses_a_tampered_tiny_result(tmp_path):
    doc = _analyze(_tiny(tmp_path), tmp_path, "interpolation")
    doc["rows"][0]["rho"] = 0.68
    path = tmp_path / "tampered.json"
    path.write_text(json.dumps(doc))
    res = CliRunner().invoke(cli, ["verify", str(path), "--out", str(tmp_path), "--json"])
    assert res.exit_code == 3, res.output
    (check,) = json.loads(res.stdout)["results"]
    assert check["verified"] != "exact" and "units" not in check
