"""design, grid, lmi, sweeps and table1 on composite / proximal specs.

Designs are judged against closed forms from the literature (Taylor, Hendrickx, Glineur
2018 for proximal gradient; 1/(1 + t m) for the proximal point method; Giselsson, Boyd
2017 for Douglas-Rachford), against brute-force grids of analyses, and their certificates
by re-running the analysis at the designed theta; never against numbers copied from
sosalgo's output.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from sosalgo.analysis import analyze_spec
from sosalgo.cli import cli
from sosalgo.design_search import design
from sosalgo.design_search.floor import class_floor
from sosalgo.model import parameter_box
from sosalgo.spec import load_spec, spec_from_dict

from .conftest import SPECS

COMPOSITE_NAMES = ["proximal-gradient", "projected-gradient", "proximal-point", "douglas-rachford",
       "accelerated-proximal-gradient"]
TOL = 1e-6


def _gb(t: float, m: float, L: float) -> float:
    """Giselsson, Boyd (2017): Douglas-Rachford (alpha = 1/2) contracts by (1 + c)/2, c the
    contraction factor max((1 - tm)/(1 + tm), (tL - 1)/(tL + 1)) of the reflected
    resolvent of t f, f in F(m, L)."""
    c = max((1 - t * m) / (1 + t * m), (t * L - 1) / (t * L + 1))
    return (1 + c) / 2


def _run(args: list[str]) -> tuple[int, str]:
    res = CliRunner().invoke(cli, [str(a) for a in args])
    return res.exit_code, res.output


def _reanalyzed(spec, doc) -> None:
    """The design's rate is what an analysis at its theta certifies (within tolerances)."""
    res = analyze_spec(spec, doc["kappa"], doc["theta"], tol=1e-7)
    assert res.certified
    assert abs(res.rho - doc["rho_certified"]) <= 3 * TOL


# --------------------------------------------------------------------------- closed forms
def test_proximal_gradient_design_is_two_over_m_plus_L():
    """h* = 2/(m + L) with rate (kappa - 1)/(kappa + 1) (distance measure; THG 2018)."""
    spec = load_spec(SPECS / "proximal-gradient.yaml")
    kappa = 10.0
    m, L = spec.mL(kappa)
    res = design(spec, kappa, free=["h"], time_limit=30)
    assert res.lower_bound is None and res.relaxation["status"] == "unsupported"
    assert res.floor == pytest.approx(1 - 1 / math.sqrt(kappa), abs=1e-12)
    assert res.rho_certified == pytest.approx((kappa - 1) / (kappa + 1), abs=2 * TOL)
    assert res.theta["h"] == pytest.approx(2 / (m + L), rel=1e-4)
    _reanalyzed(spec, res.to_dict())


def test_proximal_point_design_goes_to_the_end_of_the_range():
    """1/(1 + t m) decreases in t: no interior optimum, the design takes the largest t."""
    spec = load_spec(SPECS / "proximal-point.yaml")
    kappa = 10.0
    m, L = spec.mL(kappa)
    (lo, hi), = parameter_box(spec, kappa, ["t"])
    ts = np.linspace(hi / 8, hi, 5)
    rates = [analyze_spec(spec, kappa, {"t": t}).rho for t in ts]
    assert all(b < a for a, b in zip(rates, rates[1:], strict=False))  # decreasing in t
    res = design(spec, kappa, free=["t"], time_limit=30)
    assert res.theta["t"] >= hi * (1 - 1e-4)
    assert res.rho_certified == pytest.approx(1 / (1 + hi * m), abs=2 * TOL)
    assert res.floor is None  # prox steps on g: no floor is a theorem
    _reanalyzed(spec, res.to_dict())


def test_douglas_rachford_design_is_giselsson_boyd():
    """t* = 1/sqrt(mL), rate (1 + c)/2 = sqrt(kappa)/(sqrt(kappa) + 1), c = (sqrt(kappa) - 1)
    /(sqrt(kappa) + 1) the contraction of the reflected resolvent (Giselsson, Boyd 2017)."""
    spec = load_spec(SPECS / "douglas-rachford.yaml")
    kappa = 10.0
    m, L = spec.mL(kappa)
    res = design(spec, kappa, free=["t"], time_limit=30)
    sk = math.sqrt(kappa)
    assert _gb(1 / math.sqrt(m * L), m, L) == pytest.approx(sk / (sk + 1), abs=1e-12)
    assert res.rho_certified == pytest.approx(sk / (sk + 1), abs=2 * TOL)
    assert res.theta["t"] == pytest.approx(1 / math.sqrt(m * L), rel=1e-3)
    assert res.floor is None and res.lower_bound is None
    _reanalyzed(spec, res.to_dict())


def test_floor_only_where_it_is_a_theorem(tmp_path):
    """1 - 1/sqrt(kappa) for gradient calls on F(m, L) plus functions that may be 0; none
    with a prox on the smooth part or a strongly convex second function."""
    k = 10.0
    floors = {n: class_floor(load_spec(SPECS / f"{n}.yaml"), k) for n in COMPOSITE_NAMES}
    want = 1 - 1 / math.sqrt(k)
    assert floors["proximal-gradient"] == pytest.approx(want)
    assert floors["projected-gradient"] == pytest.approx(want)
    assert floors["accelerated-proximal-gradient"] == pytest.approx(want)
    assert floors["proximal-point"] is None and floors["douglas-rachford"] is None
    data = yaml.safe_load((SPECS / "proximal-gradient.yaml").read_text())
    data["functions"]["g"] = {"class": "strongly_convex"}
    assert class_floor(spec_from_dict(data, source="sc.yaml"), k) is None
    data["functions"]["g"] = {"class": "convex"}
    data["functions"]["f"] = {"class": "smooth_strongly_convex", "m": "m", "L": "4*L"}
    assert class_floor(spec_from_dict(data, source="f.yaml"), k) == pytest.approx(
        1 - 1 / math.sqrt(4 * k))


def test_design_sweep_over_kappa_with_workers_and_resume(tmp_path):
    """h*(kappa) = 2/(m + L) at every kappa, a figure, and a rerun reads the rows back."""
    spec_path = SPECS / "proximal-gradient.yaml"
    args = ["design", spec_path, "--kappa", "[2, 20]", "--workers", "2", "--time-limit", "20",
            "--out", tmp_path, "--json", "--quiet"]
    code, out = _run(args)
    assert code == 0, out
    doc = json.loads(out[out.index("{"):])
    assert len(doc["figures"]) == 2
    spec = load_spec(spec_path)
    for d in doc["rows"]:
        m, L = spec.mL(d["kappa"])
        assert d["theta"]["h"] == pytest.approx(2 / (m + L), rel=1e-4)
        assert d["rho_certified"] == pytest.approx((L - m) / (L + m), abs=2 * TOL)
    code, again = _run(args)
    assert code == 0
    back = json.loads(again[again.index("{"):])["rows"]
    for a, b in zip(doc["rows"], back, strict=True):
        assert b["rho_certified"] == pytest.approx(a["rho_certified"], abs=1e-12)
        assert b["floor"] == pytest.approx(a["floor"], abs=1e-12)
        assert b["relaxation"]["status"] == "unsupported"


# --------------------------------------------------------------------------- input matrix
MATRIX = [("proximal-gradient", ["h"]), ("projected-gradient", ["h"]),
          ("proximal-point", ["t"]), ("douglas-rachford", ["t"]),
          ("accelerated-proximal-gradient", ["h"]),
          ("accelerated-proximal-gradient", ["beta"]),
          ("accelerated-proximal-gradient", ["h", "beta"])]


@pytest.mark.slow
@pytest.mark.parametrize("name,free", MATRIX, ids=[f"{n}-{'+'.join(f)}" for n, f in MATRIX])
def test_every_new_spec_and_free_subset(name, free, tmp_path):
    """As a user types it, with a short limit: exit 0; the certificate re-checked by an
    analysis at theta; never worse than the spec's own values, and (unless the limit cut
    it short) than the best of a brute-force grid of analyses; never below the floor
    where there is one."""
    kappa = 10.0
    code, out = _run(["design", SPECS / f"{name}.yaml", "--kappa", kappa, "--free",
                      ",".join(free), "--time-limit", "4", "--json", "--quiet",
                      "--out", tmp_path])
    assert code == 0, out
    doc = json.loads(out[out.index("{"):])
    spec = load_spec(SPECS / f"{name}.yaml")
    assert doc["lower_bound"] is None and doc["relaxation"]["status"] == "unsupported"
    assert doc["rho_certified"] is not None and doc["rho_certified"] < 1
    _reanalyzed(spec, doc)
    if doc["floor"] is not None:
        assert doc["rho_certified"] >= doc["floor"] - 1e-9
    if doc["rho_at_values"] is not None:  # the spec's own values are certified first
        assert doc["rho_certified"] <= doc["rho_at_values"] + 1e-9
    if doc["time_limited"]:  # cut short (a loaded machine): no claim to beat the grid
        return
    box = parameter_box(spec, kappa, free)
    pts = 9 if len(free) == 1 else 5
    axes = [np.linspace(lo, hi, pts) for lo, hi in box]
    for x in np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(free), -1).T:
        r = analyze_spec(spec, kappa, dict(zip(free, x, strict=True)), tol=1e-7)
        if r.certified:
            assert doc["rho_certified"] <= r.rho + 1e-6


# --------------------------------------------------------------------------- grid
@pytest.mark.parametrize("name", COMPOSITE_NAMES)
def test_grid_on_each_new_spec(name, tmp_path):
    """CSV and figure; one-parameter grids against their closed forms."""
    code, out = _run(["grid", SPECS / f"{name}.yaml", "--kappa", "10", "--points", "5",
                      "--out", tmp_path, "--json", "--quiet"])
    assert code == 0, out
    doc = json.loads(out[out.index("{"):])
    g = doc["grids"][0]
    assert Path(g["csv"]).exists() and g["figures"]
    rows = list(csv.DictReader(open(g["csv"])))
    spec = load_spec(SPECS / f"{name}.yaml")
    m, L = spec.mL(10.0)
    assert len(rows) == 5 ** len(doc["free"])
    closed = {"proximal-gradient": lambda h: max(abs(1 - h * m), abs(1 - h * L)),
              "projected-gradient": lambda h: max(abs(1 - h * m), abs(1 - h * L)),
              "proximal-point": lambda t: 1 / (1 + t * m)}
    for r in rows:
        if r["certified"] != "true":
            continue
        rho = float(r["rho"])
        if name in closed:
            ref = closed[name](float(r[doc["free"][0]]))
            assert ref - 1e-9 <= rho <= ref + 2 * TOL
        elif name == "douglas-rachford":  # an upper bound (Giselsson, Boyd 2017)
            assert rho <= _gb(float(r["t"]), m, L) + 2 * TOL
        else:  # accelerated: no method beats the floor of F(m, L)
            assert rho >= 1 - 1 / math.sqrt(10.0) - 1e-9


# --------------------------------------------------------------------------- lmi
@pytest.mark.parametrize("name", COMPOSITE_NAMES)
def test_lmi_lists_classes_rows_and_blocks(name):
    spec = load_spec(SPECS / f"{name}.yaml")
    code, text = _run(["lmi", SPECS / f"{name}.yaml"])
    assert code == 0, text
    assert text.startswith(f"{name}: interpolation certificate (composite)")
    for fname, decl in spec.functions.items():
        assert f"{fname}: {decl.cls}" in text
    for block in ("(D)", "(P)", "V_k = ", "lifted vector w"):
        assert block in text
    code, tex = _run(["lmi", SPECS / f"{name}.yaml", "--latex"])
    assert code == 0 and "\\begin{equation*}" in tex and "\\end{equation*}" in tex
    assert tex.count("{") == tex.count("}")
    assert "smooth_strongly" not in tex.replace("% sosalgo", "")  # escaped in \text{}


def test_lmi_rows_and_pair_counts_by_hand():
    """Row maps derived by hand from the specs' matrices; pairs: every ordered pair of the
    points of one function (lag 0: two calls per function in the decrease window and x*)."""
    _, pg = _run(["lmi", SPECS / "proximal-gradient.yaml"])
    assert "y2[0] = xi - h*u1[0] - h*u2[0]" in pg  # prox_{hg}(x - h grad f(x))
    assert "12 pairs" in pg and "4 pairs" in pg  # decrease: 2 x (3 x 2); positivity: 2 x 2
    _, dr = _run(["lmi", SPECS / "douglas-rachford.yaml"])
    assert "y1[0] = xi - t*u1[0]" in dr and "y2[0] = xi - 2*t*u1[0] - t*u2[0]" in dr
    assert "f: smooth_strongly_convex (m = m, L = L); calls y1 (prox, t = t)" in dr


# --------------------------------------------------------------------------- sweeps, table1
def test_analyze_sweep_with_workers_and_resume(tmp_path):
    """The sweep on Douglas-Rachford of docs/outputs.md (Giselsson-Boyd at every kappa), then a
    resume after losing the last rows: each kappa once, the same rates."""
    spec_path = SPECS / "douglas-rachford.yaml"
    sweep = "{from: 1.5, to: 1000, points: 20, scale: log}"
    args = ["analyze", spec_path, "--kappa", sweep, "--workers", "2", "--out", tmp_path,
            "--json", "--quiet"]
    code, out = _run(args)
    assert code == 0, out
    doc = json.loads(out[out.index("{"):])
    spec = load_spec(spec_path)
    first = {}
    for r in doc["rows"]:
        m, L = spec.mL(r["kappa"])
        ref = _gb(1 / math.sqrt(m * L), m, L)
        assert r["certified"] and ref - 1e-9 <= r["rho"] <= ref + 2 * TOL
        first[r["kappa"]] = r["rho"]
    assert len(first) == 20
    path = Path(doc["csv"])
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:13]))  # header and 12 rows: an interrupted run
    code, out = _run(args)
    assert code == 0, out
    again = json.loads(out[out.index("{"):])["rows"]
    assert sorted(r["kappa"] for r in again) == sorted(first)
    for r in again:
        assert r["rho"] == pytest.approx(first[r["kappa"]], abs=2 * TOL)
        cert = r["certificate"]
        assert len(cert["p"]) == 2 * (cert["lag"] + 1)  # two oracle calls, read back
    rows = list(csv.DictReader(open(path)))
    assert len(rows) == len({r["kappa"] for r in rows}) == 20


def test_table1_runs_over_every_spec(tmp_path):
    """make table1's command: every shipped spec, the families that apply; the composite
    rows against their own closed forms."""
    code, out = _run(["table1", "--certificate", "theorem1,interpolation", "--kappa", "10",
                      "--out", tmp_path])
    assert code == 0, out
    rows = list(csv.DictReader(open(tmp_path / "table1.csv")))
    names = {r["spec"] for r in rows}
    assert set(COMPOSITE_NAMES) <= names and {"nesterov", "gradient"} <= names
    by = {r["spec"]: r for r in rows}
    assert float(by["proximal-gradient"]["rho_certified"]) == pytest.approx(0.9, abs=2 * TOL)
    assert float(by["proximal-point"]["rho_certified"]) == pytest.approx(1 / 1.1, abs=2 * TOL)
