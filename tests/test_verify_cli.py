"""`sosalgo verify`, `--verify`, and solver-failure safety inside a sweep."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from sosalgo.batch.sweeps import run_analysis_sweep
from sosalgo.cli import cli
from sosalgo.kernel.solvers import SOLVERS
from sosalgo.spec import load_spec

from .conftest import SPECS


def test_analyze_verify_reports_exact(tmp_path):
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "nesterov.yaml"), "--kappa", "10",
                                   "--out", str(tmp_path), "--json", "--verify", "--quiet"])
    assert res.exit_code == 0, res.output
    (row,) = json.loads(res.stdout)["rows"]
    v = row["verification"]
    assert v["verified"] == "exact" and v["rho_proven_float"] >= row["rho"]
    assert v["simulation"]["ok"]
    cert = json.loads(open(v["certificate_file"]).read())
    assert "/" in cert["rho_proven"] or cert["rho_proven"].isdigit()


def test_verify_command_and_a_tampered_result(tmp_path):
    out = CliRunner().invoke(cli, ["analyze", str(SPECS / "gradient-optimal.yaml"), "--kappa",
                                   "10", "--out", str(tmp_path), "--json", "--quiet"])
    doc = json.loads(out.stdout)
    good = tmp_path / "good.json"
    good.write_text(json.dumps(doc))
    res = CliRunner().invoke(cli, ["verify", str(good), "--out", str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["results"][0]["verified"] == "exact"
    doc["rows"][0]["rho"] -= 1e-3  # same P, lambda: a false claim
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    res = CliRunner().invoke(cli, ["verify", str(bad), "--out", str(tmp_path), "--no-simulate"])
    assert res.exit_code == 3
    assert "failed" in res.stdout
    res = CliRunner().invoke(cli, ["verify", str(tmp_path / "missing.json")])
    assert res.exit_code == 2


class _Liar:
    """'Solved', with a point that violates the inequality."""

    def __call__(self, problem, rho, margin):
        return "solved", np.ones(problem.nvar), "Solved"


def test_a_lying_solver_never_certifies_and_the_sweep_goes_on(tmp_path, monkeypatch):
    monkeypatch.setitem(SOLVERS, "liar", _Liar())
    spec = load_spec(SPECS / "gradient.yaml")
    text = (SPECS / "gradient.yaml").read_text()
    rows = run_analysis_sweep(spec, text, [2.0, 10.0], tmp_path / "a.csv", 1e-6, workers=1,
                              progress=False, solvers=["liar"])
    assert [r["certified"] for r in rows] == ["false", "false"]
    rows = run_analysis_sweep(spec, text, [2.0, 10.0], tmp_path / "b.csv", 1e-6, workers=1,
                              progress=False, solvers=["liar", "clarabel"])
    assert [r["solver"] for r in rows] == ["clarabel", "clarabel"]
    assert abs(float(rows[1]["rho"]) - 0.9) < 1e-5
