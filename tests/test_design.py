"""Design by moment relaxation: closed forms, bound/certificate consistency, CLI contract."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.analysis import analyze_spec
from sosalgo.cli import cli
from sosalgo.design import CERT_TOL, design, design_problem
from sosalgo.model import parameter_box
from sosalgo.spec import load_spec

from .conftest import SPECS


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
def test_gradient_design_recovers_optimal_step(kappa):
    spec = load_spec(SPECS / "gradient.yaml")
    res = design(spec, kappa, free=["h"])
    m, L = 1.0, kappa
    assert res.theta["h"] == pytest.approx(2 / (m + L), abs=1e-4)
    assert res.rho_certified == pytest.approx((kappa - 1) / (kappa + 1), abs=1e-4)
    assert res.gap is not None and 0 <= res.gap + 1e-7 and res.gap <= 1e-4
    assert res.lower_bound <= (kappa - 1) / (kappa + 1) + 1e-7  # a valid lower bound
    _consistent(spec, res)


def test_nesterov_beta_design_at_10():
    spec = load_spec(SPECS / "nesterov.yaml")
    res = design(spec, 10.0, free=["beta"])
    own = analyze_spec(spec, 10.0)  # Nesterov's own beta, certified
    assert res.lower_bound <= res.rho_certified <= own.rho
    assert res.rho_certified <= np.sqrt(1 - 1 / np.sqrt(10))
    _consistent(spec, res)


def _consistent(spec, res):
    assert res.lower_bound is None or res.lower_bound <= res.rho_certified + 1e-7
    fresh = analyze_spec(spec, res.kappa, res.theta, tol=CERT_TOL)
    assert fresh.rho == pytest.approx(res.rho_certified, abs=1e-12)
    M_ok = res.certificate["max_eig_M"] <= 0 and res.certificate["min_eig_P"] >= 0
    assert M_ok


def test_minors_scalarization_is_sylvester():
    """'minors' states -M ⪰ 0 and P ⪰ 0 by all principal minors: at a certified point they
    are nonnegative, at a point with rho below the optimum one of them is negative."""
    spec = load_spec(SPECS / "gradient.yaml")
    kappa = 10.0
    box = parameter_box(spec, kappa, ["h"])
    prob, v = design_problem(spec, kappa, ["h"], box, scalarize="minors")
    assert not prob.matrix_inequalities
    assert len(prob.inequalities) == 2 + 3 + 1  # c, lambda; minors of the 2x2 M; of p
    res = analyze_spec(spec, kappa, {"h": 2 / 11})
    p = res.P[0, 0] / kappa
    s = 1 + p + res.lam
    point = {v.r2: res.rho**2, v.theta[0]: 2 / 11, v.lam: res.lam / s, v.p_syms[0]: p / s}
    assert all(float(g.evalf(subs=point)) >= -1e-12 for g in prob.inequalities)
    point[v.r2] = 0.5
    assert min(float(g.evalf(subs=point)) for g in prob.inequalities) < 0


def test_normalization_keeps_every_certificate():
    """A Theorem 1 certificate at the optimum, rescaled by c + tr P + lambda, satisfies the
    constraints of the design problem (so its value is a lower bound)."""
    spec = load_spec(SPECS / "nesterov.yaml")
    kappa = 10.0
    box = parameter_box(spec, kappa, ["beta"])
    prob, v = design_problem(spec, kappa, ["beta"], box)
    res = analyze_spec(spec, kappa)
    L = kappa
    Pn = res.P / L  # normalized coordinates
    s = 1 + np.trace(Pn) + res.lam
    point = {v.r2: res.rho**2, v.theta[0]: res.params["beta"], v.lam: res.lam / s}
    for sym, val in zip(v.p_syms, [Pn[0, 0] / s, Pn[0, 1] / s, Pn[1, 1] / s], strict=True):
        point[sym] = val
    G = np.array(prob.matrix_inequalities[0].evalf(subs=point), dtype=float)
    assert np.linalg.eigvalsh(G).min() >= -1e-9
    for g in prob.inequalities:
        assert float(g.evalf(subs=point)) >= -1e-12


def test_design_cli_json_contract(tmp_path):
    res = CliRunner().invoke(cli, ["design", str(SPECS / "gradient-optimal.yaml"), "--kappa",
                                   "10", "--out", str(tmp_path), "--json", "--quiet"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    for key in ("spec", "kappa", "free", "lower_bound", "theta", "rho_certified", "gap",
                "certificate", "relaxation", "seconds"):
        assert key in doc
    for key in ("scalarize", "order", "status", "ranks", "flat"):
        assert key in doc["relaxation"]
    assert set(doc["certificate"]) >= {"P", "lambda"}
    assert doc["free"] == ["h"] and abs(doc["rho_certified"] - 9 / 11) < 1e-4


def test_design_cli_errors(tmp_path):
    res = CliRunner().invoke(cli, ["design", str(SPECS / "nesterov.yaml"), "--kappa", "10",
                                   "--free", "gamma", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "gamma" in res.stderr
    assert not (tmp_path / "o").exists()
