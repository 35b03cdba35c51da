"""Sublinear rates (m: 0): the potential certificate against independent closed forms."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from sosalgo.analysis import analyze_spec, analyze_sublinear
from sosalgo.cli import cli
from sosalgo.spec import SpecError, load_spec, spec_from_dict

from .conftest import SPECS

GD = yaml.safe_load((SPECS / "gradient-convex.yaml").read_text())
PG = yaml.safe_load((SPECS / "proximal-gradient.yaml").read_text())


def _gd(h: str = "1/L", L: float = 1.0, **changes) -> dict:
    return {**GD, "L": L, "parameters": {"h": {"value": h, "range": [0, "3/L"]}}, **changes}


def _drori_teboulle(k: int, hL: float, L: float) -> float:
    """Exact worst case of f(x_k) - f* over |x_0 - x*|^2 for gradient descent with step
    h = hL/L on L-smooth convex f, hL in (0, 2) (Drori, Teboulle 2014; Taylor et al.)."""
    return L / 2 * max(1 / (2 * k * hL + 1), (1 - hL) ** (2 * k))


@pytest.mark.parametrize("L", [1.0, 3.0])
def test_gradient_step_one_over_L_between_tight_and_potential(L):
    res = analyze_sublinear(spec_from_dict(_gd(L=L)))
    assert res.certified and res.constant is not None
    assert res.constant <= L / 2  # k (f - f*) + L/2 |x - x*|^2 decreases
    assert res.constant >= L / 4  # never below the tight L/4 ...
    for k in (1, 2, 3, 5, 10, 100, 1000):  # ... nor below the worst case at any k
        assert res.constant / k >= L / (4 * k + 2)


@pytest.mark.parametrize("hL", [0.5, 1.5, 1.9])
def test_gradient_other_steps_never_below_exact_worst_case(hL):
    res = analyze_sublinear(spec_from_dict(_gd(h=f"{hL}/L")))
    assert res.certified and res.constant is not None
    for k in range(1, 400):
        assert res.constant / k >= _drori_teboulle(k, hL, 1.0)


@pytest.mark.parametrize("hL", [0.5, 0.9, 1.0])
def test_gradient_short_steps_reach_the_tight_constant(hL):
    """For h <= 1/L the worst case is L/(4khL + 2) (Drori, Teboulle 2014), so the best c
    in c/k is sup_k kL/(4khL + 2) = L/(4hL): the degree-2 potential gets within 1 %."""
    res = analyze_sublinear(spec_from_dict(_gd(h=f"{hL}/L")))
    assert res.certified and res.constant is not None
    assert 1 / (4 * hL) <= res.constant <= 1.01 / (4 * hL)


def test_constant_scales_linearly_with_L():
    c1 = analyze_sublinear(spec_from_dict(_gd(L=1.0))).constant
    c5 = analyze_sublinear(spec_from_dict(_gd(L=5.0))).constant
    assert c1 is not None and c5 is not None
    assert c5 / c1 == pytest.approx(5.0, rel=1e-4)


def test_proximal_gradient_on_convex_sum_gets_a_finite_constant():
    data = {**PG, "m": 0, "L": 2, "measure": "function", "output": "y2", "references": {},
            "matrices": {k: v for k, v in PG["matrices"].items() if k != "E"}}
    data.pop("kappa")
    res = analyze_sublinear(spec_from_dict(data))
    assert res.certified and res.constant is not None
    assert res.constant <= 2 / 2  # literature: L/2 for F(x_k) - F* (tight: L/4)
    for k in (1, 10, 100):  # g = 0 is allowed: gradient descent's worst case is a floor
        assert res.constant / k >= 2 / (4 * k + 2)


def test_divergent_step_gets_no_certificate():
    res = analyze_sublinear(spec_from_dict(_gd(h="2.5/L")))
    assert not res.certified and res.constant is None
    assert res.to_dict()["rate_type"] == "sublinear"


BAD = [
    ({"kappa": [10]}, "m", "m: 0 with kappa"),
    ({"L": None}, "L", "missing"),
    ({"parameters": {"h": {"value": "1/(kappa*m)"}}}, "parameters.h", "uses kappa"),
    ({"measure": "distance"}, "measure", "distance"),
    ({"m": 1}, "L", "only with m: 0"),
]


@pytest.mark.parametrize("changes,field,message", BAD, ids=[b[1] for b in BAD])
def test_bad_sublinear_specs_exit_2_naming_the_field(changes, field, message, tmp_path):
    data = {k: v for k, v in {**GD, **changes}.items() if v is not None}
    with pytest.raises(SpecError) as err:
        spec_from_dict(data, source="bad.yaml")
    assert err.value.field.startswith(field) and message in str(err.value)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(out)])
    assert res.exit_code == 2 and "Traceback" not in res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(path) in lines[0] and field in lines[0]
    assert not out.exists()


def test_cli_analyze_writes_rate_type_and_constant(tmp_path):
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "gradient-convex.yaml"), "--out",
                                   str(out), "--json", "--no-plot"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)["rows"][0]
    assert row["rate_type"] == "sublinear" and row["certified"]
    assert row["check_kind"] == "floating-point check"
    with (out / "gradient-convex-analysis.csv").open() as fh:
        cells = list(csv.DictReader(fh))[0]
    assert cells["rate_type"] == "sublinear"
    assert float(cells["constant"]) == pytest.approx(row["constant"], rel=1e-12)


@pytest.mark.parametrize("command", [["design", "--kappa", "10"],
                                     ["grid", "--free", "h", "--kappa", "10"]])
def test_kappa_on_a_sublinear_spec_exits_2(command, tmp_path):
    res = CliRunner().invoke(cli, [command[0], str(SPECS / "gradient-convex.yaml"),
                                   *command[1:], "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "Traceback" not in res.output and "m: 0" in res.output
    assert not (tmp_path / "o").exists()


def _huber_floor(h: float) -> float:
    """A lower bound on every valid c at step h (L = 1), by functions written out here:
    the Huber function with threshold R/(2kh + 1) gives f(x_k) - f* = R^2/(4kh + 2) at
    every k (so c >= sup_k k/(4kh + 2) = 1/(4h)), the quadratic |x|^2/2 gives
    (1 - h)^(2k)/2 (so c >= k (1 - h)^(2k)/2 for each k)."""
    ks = np.arange(1, 5000)
    return max(1 / (4 * h), float(np.max(ks * (1 - h) ** (2 * ks) / 2)))


@pytest.mark.parametrize("h", [0.2, 0.6, 1.0, 1.2, 1.4, 1.4999967575073252, 1.5, 1.55, 1.7,
                               1.9])
def test_certified_constant_never_below_the_huber_and_quadratic_floors(h):
    """Soundness (a regression: a degree-2 certificate with huge entries once passed the
    reduced check with equalities broken by rounding, certifying 0.1666661 < 1/(4h))."""
    res = analyze_sublinear(spec_from_dict(_gd(h=str(h))))
    assert res.certified and res.constant is not None
    assert res.constant >= _huber_floor(h)


def test_simulation_is_sharp_for_gradient_descent():
    """The simulation passes the certified c and catches 0.9 c (Huber is a worst case)."""
    from sosalgo.model import bind_sublinear
    from sosalgo.proofs.simulate_sublinear import simulate_sublinear

    spec = spec_from_dict(_gd())
    c = analyze_sublinear(spec).constant
    om = bind_sublinear(spec)
    assert simulate_sublinear(om, c).ok
    assert not simulate_sublinear(om, 0.9 * c).ok


def test_design_minimizes_the_constant_soundly(tmp_path):
    """The design beats the textbook step h = 1/L (c = L/4), is never below the floor at its
    step, nor below the best floor over the box; CSV written; simulation passes. The box is
    [1/L, 1.9/L] so that the first grid points already beat L/4 on a loaded machine."""
    text = (SPECS / "gradient-convex.yaml").read_text().replace("range: [0, 2/L]",
                                                                "range: [1/L, 1.9/L]")
    path = tmp_path / "gradient-convex.yaml"
    path.write_text(text)
    res = CliRunner().invoke(cli, ["design", str(path), "--out",
                                   str(tmp_path), "--time-limit", "4", "--json", "--verify"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)["rows"][0] if "rows" in json.loads(res.stdout) else \
        json.loads(res.stdout)
    h = row["theta"]["h"]
    hs = np.linspace(0.01, 1.99, 2000)
    assert row["constant"] < 0.25
    assert row["constant"] >= _huber_floor(h)
    assert row["constant"] >= min(_huber_floor(x) for x in hs) * (1 - 1e-3)
    assert row["bound_status"] == "unsupported" and row["simulation"]["ok"]
    assert row["verified"] == "exact"  # the designed constant proven in rationals
    with (tmp_path / "gradient-convex-design.csv").open() as fh:
        cells = list(csv.DictReader(fh))[0]
    assert float(cells["constant"]) == pytest.approx(row["constant"], rel=1e-12)


def test_grid_writes_the_constant_along_h(tmp_path):
    res = CliRunner().invoke(cli, ["grid", str(SPECS / "gradient-convex.yaml"), "--points",
                                   "5", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    with (tmp_path / "gradient-convex-grid.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 5
    for r in rows:
        if r["certified"] == "True":
            assert float(r["constant"]) >= _huber_floor(float(r["h"]))
        else:
            assert float(r["h"]) in (0.0, 2.0)  # h = 0 does not move, h = 2/L cycles


def test_linear_results_say_rate_type_linear():
    res = analyze_spec(load_spec(SPECS / "gradient.yaml"), 10.0)
    assert res.to_dict()["rate_type"] == "linear"


def test_a_state_depending_on_optimal_subgradients_is_refused(tmp_path):
    """Douglas-Rachford's state at the optimum is x* + t s_g*: a start at rest at x_0 is not
    the method started at z_0 = x_0, so the potential's bound would not apply: exit 2."""
    DR = yaml.safe_load((SPECS / "douglas-rachford.yaml").read_text())
    data = {**DR, "m": 0, "L": 1, "measure": "function", "references": {}, "output": "y2",
            "parameters": {"t": {"value": "1/L", "range": [0, "10/L"]}}}
    data.pop("kappa")
    path = tmp_path / "dr0.yaml"
    path.write_text(yaml.safe_dump(data))
    res = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert "functions" in res.output and "optimal subgradients" in res.output


def test_a_solver_panic_is_no_answer_not_a_crash():
    """Clarabel panics (pyo3's PanicException derives from BaseException) on this momentum
    method (found by the soundness suite): the analysis goes on and the result stays sound
    (the constant is >= the worst case on the quadratic (1/2)|x|^2 from rest at k = 1)."""
    data = {"name": "mom", "m": 0, "L": 1,
            "functions": {"f": {"class": "smooth_strongly_convex"}},
            "parameters": {"h": {"value": "(3159/4096)/L"}, "beta": {"value": "1993/4096"},
                           "eta": {"value": "2939/4096"}},
            "matrices": {"A": [[0, 1], ["-beta", "1 + beta"]], "B": [[0], ["-h"]],
                         "C": [["-eta", "1 + eta"]], "E": [[0, 1]]}}
    res = analyze_sublinear(spec_from_dict(data))
    if res.certified:
        x1 = 1 - 3159 / 4096  # one step from rest on (1/2)|x|^2, x_0 = 1
        assert res.constant >= x1 ** 2 / 2
