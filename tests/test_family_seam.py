"""A certificate family plugs in by one module and one registry line (the seam of
``sosalgo.certificates``): the diagonal-P test family runs through analyze, design,
verify and the CSV/JSON writers, and its rates are never below Theorem 1's."""

from __future__ import annotations

import csv
import json

import pytest
from click.testing import CliRunner

from sosalgo.certificates import FAMILIES, register_family
from sosalgo.cli import cli

from .conftest import SPECS
from .diagonal_family import DIAGONAL


@pytest.fixture(autouse=True)
def registered():
    register_family(DIAGONAL)  # the one registry line
    yield
    FAMILIES.pop(DIAGONAL.name, None)


def _spec(tmp_path, name="gradient-optimal"):
    text = (SPECS / f"{name}.yaml").read_text() + "\ncertificate: theorem1-diagonal\n"
    path = tmp_path / f"{name}-diag.yaml"
    path.write_text(text.replace(f"name: {name}", f"name: {name}-diag"))
    return path


def test_analyze_json_csv_and_verify(tmp_path):
    spec = _spec(tmp_path)
    out = tmp_path / "o"
    res = CliRunner().invoke(cli, ["analyze", str(spec), "--kappa", "2", "--kappa", "10",
                                   "--json", "--quiet", "--out", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    rows = doc["rows"]
    for r in rows:  # gradient, h = 2/(m+L): (kappa-1)/(kappa+1), also with a diagonal P
        assert r["rho"] == pytest.approx((r["kappa"] - 1) / (r["kappa"] + 1), abs=1e-5)
        assert r["family"] == "theorem1-diagonal"
    table = list(csv.DictReader(open(doc["csv"], encoding="utf-8")))
    assert doc["csv"].endswith("gradient-optimal-diag-analysis-theorem1-diagonal.csv")
    assert len(table) == 2 and all(t["certified"] == "true" for t in table)
    result = tmp_path / "result.json"
    result.write_text(res.stdout)
    ver = CliRunner().invoke(cli, ["verify", str(result), "--json", "--out", str(tmp_path / "v")])
    assert ver.exit_code == 0, ver.output
    checks = json.loads(ver.stdout)["results"]
    for c in checks:  # the family's exact check and its Lyapunov function, by its name
        assert c["family"] == "theorem1-diagonal" and c["verified"] == "exact"
        assert c["rho_proven_float"] >= c["rho"] and c["simulation"]["ok"]
        assert c["certificate_file"].endswith("-theorem1-diagonal-certificate.json")


def test_verify_reads_rows_with_the_family_parser(tmp_path):
    """The family reads its own certificates: a full P is not a diagonal-P certificate."""
    spec = _spec(tmp_path, "nesterov")
    row = {"kappa": 10.0, "rho": 0.9, "certified": True, "P": [[1.0, 0.1], [0.1, 1.0]],
           "lambda": 1.0, "family": "theorem1-diagonal"}
    result = tmp_path / "r.json"
    result.write_text(json.dumps({"spec": "nesterov-diag", "source": str(spec), "rows": [row]}))
    bad = CliRunner().invoke(cli, ["verify", str(result), "--no-simulate", "--out",
                                   str(tmp_path)])
    assert bad.exit_code == 2
    assert "rows[0].P: expected a diagonal matrix" in bad.output
    assert not (tmp_path / "certificates").exists()


def test_design_cli_csv_json_and_verify(tmp_path):
    spec = _spec(tmp_path, "gradient")
    out = tmp_path / "o"
    res = CliRunner().invoke(cli, ["design", str(spec), "--kappa", "10", "--free", "h",
                                   "--json", "--quiet", "--out", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["family"] == "theorem1-diagonal"
    assert doc["rho_certified"] == pytest.approx(9 / 11, abs=1e-5)  # (kappa-1)/(kappa+1)
    assert doc["theta"]["h"] == pytest.approx(2 / 11, abs=1e-3)  # h = 2/(m+L), m=1, L=10
    table = list(csv.DictReader(open(out / "gradient-diag-design-theorem1-diagonal.csv",
                                     encoding="utf-8")))
    assert len(table) == 1 and float(table[0]["rho_certified"]) == pytest.approx(9 / 11,
                                                                               abs=1e-5)
    result = tmp_path / "design.json"
    result.write_text(res.stdout)
    ver = CliRunner().invoke(cli, ["verify", str(result), "--json", "--out", str(tmp_path)])
    assert ver.exit_code == 0, ver.output
    check = json.loads(ver.stdout)["results"][0]
    assert check["family"] == "theorem1-diagonal" and check["simulation"]["ok"]


def test_never_below_theorem1_and_design_bound(tmp_path):
    from sosalgo.analysis import analyze_spec
    from sosalgo.design_search import design
    from sosalgo.spec import load_spec

    spec = load_spec(_spec(tmp_path, "nesterov"))
    full = analyze_spec(spec, 10.0, family="theorem1")
    diag = analyze_spec(spec, 10.0)
    assert diag.family == "theorem1-diagonal"
    assert diag.rho is None or diag.rho >= full.rho - 1e-7  # a subset of Theorem 1
    res = design(load_spec(_spec(tmp_path, "gradient")), 10.0, free=["h"])
    assert res.family == "theorem1-diagonal"
    assert res.relaxation["status"] == "proved"  # the family's exact form gives a bound
    assert res.lower_bound is not None and res.lower_bound <= 9 / 11  # the closed form
    assert res.rho_certified == pytest.approx(9 / 11, abs=1e-5)


def _uniform_spec(tmp_path, uniform: bool | None):
    """nesterov with the diagonal family, its ``uniform`` option set (or not)."""
    flag = str(uniform).lower()
    fam = ("theorem1-diagonal" if uniform is None
           else "{family: theorem1-diagonal, uniform: " + flag + "}")
    text = (SPECS / "nesterov.yaml").read_text() + f"\ncertificate: {fam}\n"
    path = tmp_path / f"nesterov-{uniform}.yaml"
    path.write_text(text.replace("name: nesterov", "name: nesterov-diag"))
    return path


def test_a_family_option_reaches_workers_settings_file_names_and_resume(tmp_path):
    """A family option other than lag goes through the loader, the workers, the settings
    file and the file name, and a rerun resumes (nothing recomputed, nothing kept aside)."""
    out = tmp_path / "o"
    args = ["--kappa", "1.5", "--kappa", "2", "--json", "--quiet", "--no-plot", "--out",
            str(out)]
    first = CliRunner().invoke(cli, ["analyze", str(_uniform_spec(tmp_path, True)), *args])
    assert first.exit_code == 0, first.output
    doc = json.loads(first.stdout)
    assert doc["csv"].endswith("nesterov-diag-analysis-theorem1-diagonal-uniform.csv")
    settings = json.loads(open(doc["csv"] + ".settings.json").read())
    assert settings["certificate"] == {"family": "theorem1-diagonal", "uniform": True}
    plain = CliRunner().invoke(cli, ["analyze", str(_uniform_spec(tmp_path, None)), *args])
    assert plain.exit_code == 0, plain.output
    pdoc = json.loads(plain.stdout)
    assert pdoc["csv"].endswith("nesterov-diag-analysis-theorem1-diagonal.csv")
    for u, p in zip(doc["rows"], pdoc["rows"], strict=True):
        P = u["P"]  # the option reached the worker: P = p I
        assert P[0][1] == 0 and P[0][0] == pytest.approx(P[1][1], rel=1e-12)
        assert p["P"][0][0] != pytest.approx(p["P"][1][1], rel=1e-3)  # plain: not p I
        assert u["rho"] >= p["rho"] - 1e-7  # P = p I is a subset of diagonal P
        assert u["rho"] > p["rho"] + 0.05  # ... and a strict one here (kappa 2: 0.93, 0.71)
    before = open(doc["csv"], encoding="utf-8").read()
    again = CliRunner().invoke(cli, ["analyze", str(_uniform_spec(tmp_path, True)), *args])
    assert again.exit_code == 0 and "kept it aside" not in again.stderr
    assert open(doc["csv"], encoding="utf-8").read() == before  # resumed, not recomputed
    assert json.loads(again.stdout)["rows"] == doc["rows"]


def test_family_options_are_checked_by_the_family(tmp_path):
    spec = tmp_path / "bad.yaml"
    spec.write_text((SPECS / "nesterov.yaml").read_text()
                    + "\ncertificate: {family: theorem1-diagonal, uniform: 3}\n")
    res = CliRunner().invoke(cli, ["analyze", str(spec), "--out", str(tmp_path)])
    assert res.exit_code == 2
    assert "certificate.uniform: must be true or false" in res.stderr
