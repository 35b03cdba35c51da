"""Large condition numbers: 1 - rho is resolved to a few digits, every certified rate comes
with a certificate that holds exactly, and where the solver cannot decide the result says so.

The references are closed forms: gradient descent with h = 2/(m+L) has the rate
(kappa-1)/(kappa+1), with h = 1/L the rate 1 - 1/kappa (Theorem 1 is tight for both), and
Nesterov's own bound sqrt(1 - 1/sqrt(kappa)) is certified by Theorem 1.
"""

from __future__ import annotations

import math
from fractions import Fraction

import pytest

from sosalgo.analysis import DEFAULT_TOL, analyze_spec
from sosalgo.spec import load_spec

from .conftest import SPECS

KAPPAS = [1e4, 1e6, 1e7]


def _theorem1_holds_exactly(res, h: float, m: float, L: float) -> bool:
    """Theorem 1's inequality for the one-state gradient method x+ = x - h f'(x), written
    out by hand (M = M0 + N1 + (1 - rho^2) N3 + lambda N4), in exact rational arithmetic
    at the reported floats: -M is PSD, p >= 0, lambda >= 0."""
    p, lam = Fraction(float(res.P[0][0])), Fraction(res.lam)
    h, m, L, r2 = Fraction(h), Fraction(m), Fraction(L), Fraction(res.rho) ** 2
    m11 = p * (1 - r2) - (1 - r2) * m / 2 - lam * m * L / (m + L)
    m12 = -h * p + (1 - r2) / 2 + lam / 2
    m22 = h * h * p + L * h * h / 2 - h - lam / (m + L)
    return p >= 0 and lam >= 0 and m11 <= 0 and m22 <= 0 and m11 * m22 - m12 * m12 >= 0


@pytest.mark.parametrize("family", ["theorem1", "interpolation"])
@pytest.mark.parametrize("kappa", KAPPAS)
def test_gradient_with_the_optimal_step_resolves_one_minus_rho(kappa, family):
    res = analyze_spec(load_spec(SPECS / "gradient-optimal.yaml"), kappa, family=family)
    assert res.certified and res.warning is None
    exact = 2 / (kappa + 1)  # 1 - (kappa-1)/(kappa+1)
    assert res.rho >= 1 - exact - 1e-15  # no certificate beats the true rate
    assert abs((1 - res.rho) - exact) <= 5e-3 * exact  # 1 - rho to two or three digits
    if family == "theorem1":
        assert _theorem1_holds_exactly(res, res.params["h"], 1.0, kappa)


@pytest.mark.parametrize("kappa", KAPPAS)
def test_gradient_with_step_one_over_L_resolves_one_minus_rho(kappa):
    res = analyze_spec(load_spec(SPECS / "gradient.yaml"), kappa)
    assert res.certified and res.warning is None
    exact = 1 / kappa
    assert res.rho >= 1 - exact - 1e-15
    assert abs((1 - res.rho) - exact) <= 5e-3 * exact
    assert _theorem1_holds_exactly(res, res.params["h"], 1.0, kappa)


def test_nesterov_reaches_its_own_bound_at_kappa_1e4():
    """Nesterov's textbook Lyapunov function satisfies Theorem 1 at sqrt(1 - 1/sqrt(kappa)):
    the search must not stop far above it (it stopped 1.4e-5 above, 14 tolerances)."""
    kappa = 1e4
    res = analyze_spec(load_spec(SPECS / "nesterov.yaml"), kappa)
    assert res.certified
    assert res.rho <= math.sqrt(1 - 1 / math.sqrt(kappa)) + DEFAULT_TOL


@pytest.mark.parametrize("name", ["gradient-optimal", "nesterov"])
def test_beyond_the_solver_accuracy_the_result_says_so(name):
    """At kappa = 1e12 no double-precision margin decides the rate: the answer carries a
    warning (a certified rate, if any, is still a checked certificate)."""
    res = analyze_spec(load_spec(SPECS / f"{name}.yaml"), 1e12, tol=1e-12)
    assert res.warning is not None
    if res.certified:
        assert res.max_eig_M <= 0 and res.min_eig_P >= 0


def test_warning_reaches_the_csv_json_and_terminal(tmp_path):
    """The accuracy warning is a column of the CSV, a field of the JSON rows and a line on
    stderr after the table."""
    import csv
    import json

    from click.testing import CliRunner

    from sosalgo.cli import cli

    spec = str(SPECS / "gradient-optimal.yaml")
    res = CliRunner().invoke(cli, ["analyze", spec, "--kappa", "1e12", "--json", "--quiet",
                                   "--out", str(tmp_path / "a"), "--certificate", "theorem1"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["rows"][0]["warning"]
    with open(tmp_path / "a" / "gradient-optimal-analysis.csv") as fh:
        assert next(csv.DictReader(fh))["warning"]
    res = CliRunner().invoke(cli, ["analyze", spec, "--kappa", "1e12", "--out",
                                   str(tmp_path / "b"), "--certificate", "theorem1"])
    assert res.exit_code == 0 and "warning at kappa 1e+12" in res.stderr
