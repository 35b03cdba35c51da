"""Certificate files follow the run model: a verified certificate is never overwritten or
lost, whatever is verified after it into the same folder, for every family."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

from .conftest import SPECS

GRADIENT = SPECS / "gradient-optimal.yaml"


def _run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _analysis(tmp_path, *extra):
    res = _run(["analyze", GRADIENT, "--kappa", "10", "--out", tmp_path / "a", "--json",
                "--quiet", "--no-plot", *(extra or ("--certificate", "theorem1"))])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def _verify(tmp_path, doc, name):
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(doc))
    res = _run(["verify", path, "--out", tmp_path, "--json", "--no-simulate"])
    return res.exit_code, json.loads(res.stdout)["results"]


def _files(tmp_path):
    return {p.name: json.loads(p.read_text()) for p in (tmp_path / "certificates").iterdir()}


@pytest.mark.parametrize("family", ["theorem1", "interpolation"])
def test_a_tampered_result_never_replaces_a_verified_certificate(tmp_path, family):
    doc = _analysis(tmp_path, "--certificate", family)
    code, (good,) = _verify(tmp_path, doc, "good")
    assert code == 0 and good["verified"] == "exact"
    plain = ("gradient-optimal-k10-certificate.json" if family == "theorem1"
             else "gradient-optimal-k10-interpolation-certificate.json")
    assert good["certificate_file"].endswith(plain)
    before = (tmp_path / "certificates" / plain).read_text()
    doc["rows"][0]["rho"] -= 1e-3  # same certificate parts, a false rate
    code, (bad,) = _verify(tmp_path, doc, "bad")
    assert code == 3 and bad["verified"] == "failed"
    assert (tmp_path / "certificates" / plain).read_text() == before  # the good one is kept
    files = _files(tmp_path)
    assert len(files) == 2
    assert sorted(f["verified"] for f in files.values()) == ["exact", "failed"]
    assert json.loads(open(bad["certificate_file"]).read())["verified"] == "failed"


def test_the_same_certificate_verified_again_keeps_one_file(tmp_path):
    doc = _analysis(tmp_path, "--certificate", "interpolation")
    first = _verify(tmp_path, doc, "r")[1][0]["certificate_file"]
    second = _verify(tmp_path, doc, "r")[1][0]["certificate_file"]
    assert first == second and len(_files(tmp_path)) == 1


def test_a_design_result_after_an_analysis_result_keeps_both(tmp_path):
    code, (ana,) = _verify(tmp_path, _analysis(tmp_path), "analysis")
    assert code == 0 and ana["verified"] == "exact"
    res = _run(["design", GRADIENT, "--kappa", "10", "--free", "h", "--out", tmp_path / "d",
                "--json", "--quiet", "--time-limit", "60"])
    assert res.exit_code == 0, res.output
    code, (des,) = _verify(tmp_path, json.loads(res.stdout), "design")
    assert code == 0 and des["verified"] == "exact"
    assert des["certificate_file"] != ana["certificate_file"]
    files = _files(tmp_path)
    assert len(files) == 2 and all(f["verified"] == "exact" for f in files.values())
    # the two files hold their own certificates: the analysis's at the spec's h = 2/(m+L)
    by_path = {str(tmp_path / "certificates" / k): v for k, v in files.items()}
    assert by_path[ana["certificate_file"]]["theta"] == {}
    assert set(by_path[des["certificate_file"]]["theta"]) == {"h"}
