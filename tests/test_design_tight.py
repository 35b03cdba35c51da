"""Design with the interpolation (tight) family: rediscovering the triple momentum method."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.analysis import analyze_spec
from sosalgo.certificates import get_family
from sosalgo.cli import cli
from sosalgo.design_search import design
from sosalgo.spec import load_spec

from .conftest import SPECS

TIGHT = get_family("interpolation", {"lag": 0})


def _tmm(kappa):
    r = 1 - 1 / np.sqrt(kappa)
    L = kappa  # m = 1 in the shipped specs
    return {"h": (1 + r) / L, "beta": r**2 / (2 - r), "gamma": r**2 / ((1 + r) * (2 - r))}


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
def test_gradient_tight_design_is_the_optimal_step(kappa):
    spec = load_spec(SPECS / "gradient.yaml")
    res = design(spec, kappa, free=["h"], family=TIGHT)
    assert res.rho_certified == pytest.approx((kappa - 1) / (kappa + 1), abs=1e-6)
    assert res.theta["h"] == pytest.approx(2 / (1 + kappa), rel=1e-3)
    assert res.lower_bound is None  # nothing proven: the floor is reported separately
    assert res.floor == pytest.approx(1 - 1 / np.sqrt(kappa))


@pytest.mark.slow
@pytest.mark.parametrize("kappa", [10.0])
def test_three_parameter_tight_design_rediscovers_tmm(kappa):
    spec = load_spec(SPECS / "three-parameter.yaml")
    res = design(spec, kappa, free=["h", "beta", "gamma"], family=TIGHT, time_limit=120)
    floor = 1 - 1 / np.sqrt(kappa)
    # never below the class lower bound (that would be a false certificate)
    assert res.rho_certified >= floor - 1e-6
    assert res.rho_certified <= floor + 5e-5
    tmm = _tmm(kappa)
    for p in ("h", "beta", "gamma"):
        assert res.theta[p] == pytest.approx(tmm[p], abs=2e-3)
    import sosalgo

    proof = sosalgo.verify(spec, res, simulate=False)  # exact rational check of (D), (P)
    assert proof["verified"] == "exact"


@pytest.mark.slow
@pytest.mark.deep  # make test-all (about 10-15 s)
def test_restriction_to_nesterov_structure_has_a_price():
    """gamma = beta (Nesterov's structure): the best tight rate stays well above the floor,
    and above the three-parameter design."""
    kappa = 10.0
    spec = load_spec(SPECS / "nesterov.yaml")
    res = design(spec, kappa, free=["h", "beta"], family=TIGHT, time_limit=120)
    floor = 1 - 1 / np.sqrt(kappa)
    assert res.rho_certified > floor + 1e-3
    own = analyze_spec(spec, kappa, family=TIGHT)  # Nesterov's own tuning
    assert res.rho_certified <= own.rho + 1e-7


def test_tight_design_cli_contract(tmp_path):
    res = CliRunner().invoke(cli, ["design", str(SPECS / "gradient-optimal.yaml"), "--kappa",
                                   "10", "--certificate", "interpolation", "--json", "--quiet",
                                   "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["family"] == "interpolation" and doc["lower_bound"] is None
    assert doc["floor"] == pytest.approx(1 - 1 / np.sqrt(10))
    # gradient descent's best rate (kappa-1)/(kappa+1) is above the class floor
    assert doc["rho_certified"] == pytest.approx(9 / 11, abs=1e-5)
    assert doc["gap_to_floor"] >= 0
    assert {"P", "p", "multipliers"} <= set(doc["certificate"])
    assert (tmp_path / "gradient-optimal-design-interpolation.csv").exists()
    bad = CliRunner().invoke(cli, ["design", str(SPECS / "gradient.yaml"), "--kappa", "10",
                                   "--certificate", "interpolation", "--method", "moment",
                                   "--out", str(tmp_path / "x")])
    assert bad.exit_code == 2 and "moment" in bad.stderr


@pytest.mark.slow
def test_fig4_runs_and_resumes(tmp_path):
    args = ["fig4", "--kappa", "2", "--time-limit", "10", "--quiet", "--json",
            "--out", str(tmp_path)]
    first = CliRunner().invoke(cli, args)
    assert first.exit_code == 0, first.output
    doc = json.loads(first.stdout)
    assert all(tmp_path.joinpath(p).exists() or __import__("os").path.exists(p)
               for p in doc["figures"])
    assert doc["designed (interpolation)"][0] <= doc["designed (Theorem 1)"][0] + 1e-9
    # a short limit (10 s: the interpolation design reaches the Theorem 1 one on a machine
    # at load 14): never below the class floor (that would be a false certificate)
    assert doc["designed (interpolation)"][0] >= 1 - 1 / np.sqrt(2.0) - 1e-6
    again = CliRunner().invoke(cli, args)  # identical settings: resumes, same numbers
    assert again.exit_code == 0
    assert json.loads(again.stdout)["designed (interpolation)"] == pytest.approx(
        doc["designed (interpolation)"], abs=1e-12)
