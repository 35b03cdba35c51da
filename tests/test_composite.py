"""The oracle model end to end: composite and proximal specs against closed forms from the
literature (never against sosalgo's own output), and every bad input of the loader."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from sosalgo.analysis import analyze_spec, quadratic_rate
from sosalgo.cli import cli
from sosalgo.model import bind
from sosalgo.spec import SpecError, load_spec, spec_from_dict

from .conftest import SPECS

PG = yaml.safe_load((SPECS / "proximal-gradient.yaml").read_text())
TOL = 1e-6


def _spec(**changes) -> dict:
    data = json.loads(json.dumps(PG))
    for key, val in changes.items():
        if val is None:
            data.pop(key, None)
        else:
            data[key] = val
    return data


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
@pytest.mark.parametrize("frac", [0.3, 1.0, 1.5, 1.9])
def test_proximal_gradient_distance_is_taylor_hendrickx_glineur(kappa, frac):
    """Prox-grad on F(m, L) + convex, distance: max(|1 - hm|, |1 - hL|) (THG 2018)."""
    spec = load_spec(SPECS / "proximal-gradient.yaml")
    m, L = spec.mL(kappa)
    h = frac / L
    res = analyze_spec(spec, kappa, {"h": h})
    assert res.certified
    ref = max(abs(1 - h * m), abs(1 - h * L))
    assert ref - 1e-9 <= res.rho <= ref + 2 * TOL


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
@pytest.mark.parametrize("tm", [0.1, 1.0, 5.0])
def test_proximal_point_contracts_by_one_over_one_plus_tm(kappa, tm):
    spec = load_spec(SPECS / "proximal-point.yaml")
    res = analyze_spec(spec, kappa, {"t": tm / spec.m})
    assert res.certified
    ref = 1 / (1 + tm)
    assert ref - 1e-9 <= res.rho <= ref + 2 * TOL


@pytest.mark.parametrize("kappa", [2.0, 10.0, 50.0])
def test_adding_a_convex_g_never_certifies_less(kappa):
    """Gradient descent on f alone vs proximal gradient on f + g (g convex), same measure."""
    alone = _spec(functions={"f": {"class": "smooth_strongly_convex"}}, oracles=["f"],
                  matrices={"A": [[1]], "B": [["-h"]], "C": [[1]], "E": [[1]]})
    for frac in (0.5, 1.0, 1.8):
        theta = {"h": frac / (kappa * 1.0)}
        r_f = analyze_spec(spec_from_dict(alone), kappa, theta)
        r_fg = analyze_spec(spec_from_dict(PG), kappa, theta)
        assert r_f.certified and r_fg.certified
        assert r_fg.rho >= r_f.rho - 2 * TOL


@pytest.mark.parametrize("name", ["proximal-gradient", "projected-gradient", "proximal-point",
                                  "douglas-rachford", "accelerated-proximal-gradient"])
def test_composite_rates_lie_between_quadratics_and_the_references(name):
    """Every rate >= the rate when every function is a quadratic of its class (g = 0), and
    <= the closed-form upper bound of the spec's first reference."""
    spec = load_spec(SPECS / f"{name}.yaml")
    for kappa in (2.0, 10.0, 100.0):
        res = analyze_spec(spec, kappa)
        assert res.certified
        assert res.rho >= quadratic_rate(bind(spec, kappa)) - 1e-7
        m, L = spec.mL(kappa)
        first = next(iter(spec.references))
        ref = {"max(|1 - hm|, |1 - hL|)": 1 - m / L, "1/(1 + t m)": 1 / (1 + m / L),
               "(1 + c)/2": (1 + (math.sqrt(L / m) - 1) / (math.sqrt(L / m) + 1)) / 2,
               "V-FISTA bound sqrt(1 - 1/sqrt(kappa))": math.sqrt(1 - kappa ** -0.5)}[first]
        assert res.rho <= ref + 2 * TOL


def test_douglas_rachford_equals_giselsson_boyd_at_the_optimal_step():
    """t = 1/sqrt(mL): the rate (1 + c)/2 is attained on quadratics, so it is tight."""
    spec = load_spec(SPECS / "douglas-rachford.yaml")
    for kappa in (2.0, 10.0, 100.0):
        q = math.sqrt(kappa)
        ref = (1 + (q - 1) / (q + 1)) / 2
        assert analyze_spec(spec, kappa).rho == pytest.approx(ref, abs=2 * TOL)


BAD = [
    (dict(functions={"f": {"class": "smooth_strongly_convex"}, "g": {"class": "nope"}}),
     "functions.g.class", "unknown class"),
    (dict(functions={"f": {"class": "smooth_strongly_convex"}, "g": {"class": "smooth"}}),
     "matrices.D[1][1]", "has no proximal oracle"),
    (dict(functions={"f": {"class": "smooth_strongly_convex"}, "g": {"class": "convex"}},
          matrices={**PG["matrices"], "D": [[0, "-h"], ["-h", "-h"]]}),
     "matrices.D[0][1]", "lower triangular"),
    (dict(matrices={**PG["matrices"], "D": [[0, 0], ["-h", "h"]]}),
     "matrices.D[1][1]", "t >= 0"),
    (dict(oracles=["f", "k"]), "oracles[1]", "names no function"),
    (dict(m=0), "m", "m: 0 with kappa"),
    (dict(matrices={**PG["matrices"], "B": [["-h", "-2*h"]]}), "matrices",
     "not a fixed point"),
    (dict(measure="function"), "measure", "not evaluated at the output"),
    (dict(certificate="theorem1"), "certificate", "theorem1 applies only"),
]


@pytest.mark.parametrize("changes,field,message", BAD, ids=[b[1] for b in BAD])
def test_bad_oracle_specs_name_file_and_field(changes, field, message, tmp_path):
    with pytest.raises(SpecError) as err:
        spec_from_dict(_spec(**changes), source="bad.yaml")
    assert err.value.field == field and message in str(err.value)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_spec(**changes)))
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(out)])
    assert res.exit_code == 2 and "Traceback" not in res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(path) in lines[0] and field in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("args", [["analyze", "--certificate", "theorem1"]])
def test_unsupported_commands_exit_2_with_one_line(args, tmp_path):
    out = tmp_path / "out"
    spec = str(SPECS / "proximal-gradient.yaml")
    res = CliRunner().invoke(cli, [args[0], spec, *args[1:], "--out", str(out)])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert len([ln for ln in res.output.splitlines() if ln.strip()]) == 1
    assert not out.exists()


def test_analyze_writes_csv_json_and_figure(tmp_path):
    out = tmp_path / "o"
    spec = str(SPECS / "accelerated-proximal-gradient.yaml")
    res = CliRunner().invoke(cli, ["analyze", spec, "--kappa", "2", "--kappa", "10", "--out",
                                   str(out), "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output[res.output.index("{"):])
    assert [r["certified"] for r in doc["rows"]] == [True, True]
    for r in doc["rows"]:
        cert = r["certificate"]
        assert len(cert["p"]) == 2 * (cert["lag"] + 1) and cert["multipliers"]["decrease"]
        assert r["rho"] <= math.sqrt(1 - r["kappa"] ** -0.5)
    assert Path(doc["csv"]).exists() and doc["figures"]


def test_seed_specs_stay_in_the_seed_setting():
    for name in ("gradient", "nesterov", "heavy-ball", "triple-momentum"):
        spec = load_spec(SPECS / f"{name}.yaml")
        assert not spec.composite and spec.certificate == "theorem1"
