"""One schema, one API: what the commands write (CSV), print (JSON) and what the Python
API returns agree field by field and value by value, for analyze, design and grid and for
both shipped families; the API refuses what the command line refuses."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.certificates import get_family
from sosalgo.cli import cli
from sosalgo.model import parameter_values
from sosalgo.schema import analysis_columns, design_columns, grid_columns

from .conftest import SPECS

FAMILIES = ["theorem1", "interpolation"]
SCALARS = ["rho", "certified", "lambda", "max_eig_M", "min_eig_P", "rho_infeasible"]


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def read_csv(path):
    with open(path, encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def cell(value: str):
    return {"true": True, "false": False, "": None}.get(value, value)


def same(a, b) -> bool:
    """Equal values: numbers to 1e-9 relative (CSV text is repr-exact)."""
    a, b = cell(a) if isinstance(a, str) else a, cell(b) if isinstance(b, str) else b
    if a is None or b is None or isinstance(a, bool) or isinstance(b, bool):
        return a == b
    return float(a) == pytest.approx(float(b), rel=1e-9, abs=1e-12)


def p_matrix(row: dict, n: int) -> np.ndarray:
    return np.array([[float(row[f"P{min(i, j) + 1}{max(i, j) + 1}"]) for j in range(n)]
                     for i in range(n)])


@pytest.mark.parametrize("family", FAMILIES)
def test_analyze_csv_json_and_api_agree(tmp_path, family):
    spec = SPECS / "nesterov.yaml"
    res = run(["analyze", spec, "--kappa", "2", "--kappa", "10", "--json", "--quiet",
               "--no-plot", "--out", tmp_path, "--certificate", family])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    table = read_csv(doc["csv"])
    loaded = sosalgo.load_spec(spec)
    fam = get_family(family)
    assert list(table[0]) == analysis_columns(loaded, fam)  # the schema's columns, in order
    api = sosalgo.analyze(spec, kappa=[2, 10], certificate=family)  # computed anew
    for row, line, res_ in zip(doc["rows"], table, api, strict=True):
        mine = res_.to_dict()
        for k in SCALARS:
            assert same(row[k], line[k]) and same(row[k], mine[k]), (family, k)
        P = np.array(row["P"])
        assert np.allclose(P, p_matrix(line, len(P)), rtol=1e-12)
        assert np.allclose(P, res_.P, rtol=1e-9, atol=1e-15)
        for name, value in row["references"].items():
            assert same(value, line[name])
        if family == "interpolation":  # the family's own parts: JSON, CSV and API
            cert = row["certificate"]
            assert cert["lag"] == int(line["lag"]) == res_.certificate["lag"]
            for j, pj in enumerate(cert["p"]):
                assert same(pj, line[f"p{j}"]) and same(pj, res_.certificate["p"][j])
            assert json.loads(line["multipliers"]) == cert["multipliers"]


@pytest.mark.parametrize("family", FAMILIES)
def test_design_csv_json_and_api_agree(tmp_path, family):
    spec = SPECS / "gradient.yaml"
    res = run(["design", spec, "--kappa", "10", "--free", "h", "--json", "--quiet",
               "--time-limit", "60", "--out", tmp_path, "--certificate", family])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    suffix = "" if family == "theorem1" else f"-{family}"
    (line,) = read_csv(tmp_path / f"gradient-design{suffix}.csv")
    loaded = sosalgo.load_spec(spec)
    fam = get_family(family)
    assert list(line) == design_columns(loaded, ["h"], fam)
    api = sosalgo.design(spec, 10, free=["h"], family=family, time_limit=60).to_dict()
    assert set(api) <= set(doc)  # the document is the API's, plus source and spec_text
    for k in ("rho_certified", "lower_bound", "gap", "gap_met", "rho_at_values", "floor"):
        assert same(doc[k], line[k]), k
        assert same(doc[k], api[k]) or k in ("lower_bound", "gap"), k  # bounds: timing
    assert same(doc["theta"]["h"], line["theta_h"]) and same(doc["theta"]["h"], api["theta"]["h"])
    assert doc["rho_certified"] == pytest.approx(9 / 11, abs=1e-5)  # (kappa-1)/(kappa+1)
    assert doc["family"] == api["family"] == family


@pytest.mark.parametrize("family", FAMILIES)
def test_grid_csv_json_and_api_agree(tmp_path, family):
    spec = SPECS / "nesterov.yaml"
    res = run(["grid", spec, "--kappa", "10", "--free", "h", "--points", "3", "--json",
               "--quiet", "--out", tmp_path, "--certificate", family])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    (g,) = doc["grids"]
    table = read_csv(g["csv"])
    loaded = sosalgo.load_spec(spec)
    fam = get_family(family)
    assert list(table[0]) == grid_columns(loaded, ["h"], fam)
    beta = parameter_values(loaded, 10)["beta"]
    assert doc["fixed"] == ["beta"] and g["fixed"]["beta"] == pytest.approx(beta)
    rates = []
    for line in table:  # the fixed parameter recorded, the rate recomputed by the API
        assert float(line["beta"]) == pytest.approx(beta)
        one = sosalgo.analyze(spec, 10, theta={"h": float(line["h"])}, certificate=family)
        assert same(line["rho"], one.rho) and same(line["certified"], one.certified)
        rates.append(one.rho)
    best = min(r for r in rates if r is not None)
    assert g["minimum"]["rho"] == pytest.approx(best, rel=1e-9)
    assert g["points"] == 3 and g["certified"] == sum(r is not None for r in rates)


@pytest.mark.parametrize("call, message", [
    (lambda s: sosalgo.design(s, 10, free=["h"], gap=-1), "gap -1: must be positive"),
    (lambda s: sosalgo.design(s, 10, free=["h"], time_limit=float("inf")), "must be finite"),
    (lambda s: sosalgo.design(s, 10, free=["h"], time_limit=0), "must be positive"),
    (lambda s: sosalgo.design(s, 10, method="moment", family="interpolation"), "moment"),
    (lambda s: sosalgo.design(s, 10, free=["nope"]), "unknown parameter"),
    (lambda s: sosalgo.analyze(s, 10, tol=0.7), "tol 0.7: must be in (0, 0.5)"),
    (lambda s: sosalgo.analyze(s, 10, certificate="theorem1", options={"lag": 1}), "--lag"),
    (lambda s: sosalgo.analyze(s, 10, certificate="interpolation", options={"lag": 9}),
     "lag: must be an integer in 0..8"),
    (lambda s: sosalgo.lmi(s, certificate="nope"), "unknown family"),
])
def test_the_api_refuses_what_the_commands_refuse(call, message):
    spec = sosalgo.load_spec(SPECS / "gradient.yaml")
    with pytest.raises(ValueError) as err:
        call(spec)
    assert message in str(err.value)


def test_batch_runs_need_the_spec_text(tmp_path):
    spec = sosalgo.load_spec(SPECS / "gradient.yaml")
    with pytest.raises(ValueError, match="needs the spec's text"):
        sosalgo.analyze_run(spec, 10, out_dir=tmp_path)
    text = (SPECS / "gradient.yaml").read_text()
    doc = sosalgo.analyze_run(spec, 10, out_dir=tmp_path, spec_text=text, progress=False)
    assert doc["rows"][0]["rho"] == pytest.approx(0.9, abs=1e-5)  # 1 - 1/kappa


def test_lmi_latex_is_a_complete_snippet():
    """Ready to paste: amsmath noted, one equation* around one aligned, \\sqrt and \\frac,
    Greek letters as commands, every row but the last ending in \\\\."""
    for name, family in (("triple-momentum", None), ("nesterov", "interpolation")):
        text = sosalgo.lmi(SPECS / f"{name}.yaml", latex=True, certificate=family)
        lines = text.splitlines()
        assert any("\\usepackage{amsmath}" in x for x in lines if x.startswith("%"))
        body = [x for x in lines if not x.startswith("%")]
        assert body[:2] == [r"\begin{equation*}", r"\begin{aligned}"]
        assert body[-2:] == [r"\end{aligned}", r"\end{equation*}"]
        rows = body[2:-2]
        assert all(r.endswith(",\\\\") for r in rows[:-1]) and rows[-1].endswith(".")
        assert all(r.count("&=") == 1 for r in rows)
        assert text.count("{") == text.count("}")
        assert "\\begin{bmatrix}" in text and "matrix}\\right" not in text
    tm = sosalgo.lmi(SPECS / "triple-momentum.yaml", latex=True)
    assert "\\sqrt{" in tm and "\\frac{" in tm and "\\rho" in tm and "\\lambda" in tm
    assert "sqrt(" not in tm and "rho^2 M" not in tm.split("\n", 1)[1]


def test_api_page_schema_table_matches_the_schema_module():
    """The Python API page's result-schema table names the columns sosalgo.schema builds
    (nesterov)."""
    from pathlib import Path

    import sosalgo
    from sosalgo import schema

    readme = (Path(__file__).resolve().parents[1] / "docs" / "api.md").read_text()
    row = next(line for line in readme.splitlines()
               if line.startswith("| analyze, Theorem 1 |"))
    listed = [c.strip() for c in row.split("|")[3].split(",")]
    assert listed == schema.analysis_columns(sosalgo.example("nesterov"))
    grid = next(line for line in readme.splitlines() if line.startswith("| grid |"))
    assert "one column per fixed parameter" in grid
    assert schema.grid_columns(sosalgo.example("nesterov"), ["beta"])[-1] == "h"
