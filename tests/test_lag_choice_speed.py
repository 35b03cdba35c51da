"""The faster lag choice and start of the interpolation search: the
largest lag of a window is tested first, a certificate within the tolerance of the rate
on quadratics closes the bracket, the quadratic bound is computed once and batched. The
rates must be those of the plain definitions: every lag searched on its own, and closed
forms."""

from __future__ import annotations

import math

import pytest

from sosalgo.analysis import analyze_algorithm, quadratic_rate
from sosalgo.certificates.interpolation import Interpolation
from sosalgo.model import bind
from sosalgo.spec import load_spec

from .conftest import SPECS

TOL = 1e-6


@pytest.mark.parametrize(("name", "kappa"), [("nesterov", 10.0), ("heavy-ball", 10.0)])
def test_chosen_lag_is_the_best_of_every_lag_searched_alone(name, kappa):
    alg = bind(load_spec(SPECS / f"{name}.yaml"), kappa)
    auto = analyze_algorithm(alg, tol=TOL, family=Interpolation())
    alone = {lag: analyze_algorithm(alg, tol=TOL, family=Interpolation(lag)).rho
             for lag in Interpolation().auto_lags(alg.n)}
    best = min(r for r in alone.values() if r is not None)
    assert auto.certified and abs(auto.rho - best) <= 2 * TOL
    assert auto.max_eig_M <= 0 and auto.min_eig_P >= 0


@pytest.mark.parametrize("kappa", [10.0, 100.0])
def test_triple_momentum_closes_at_the_quadratic_bound(kappa):
    """Its rate is 1 - 1/sqrt(kappa) (Van Scoy, Freeman, Lynch 2018): the bracket is
    [bound, bound + tol] from a lower bound and one certified point."""
    alg = bind(load_spec(SPECS / "triple-momentum.yaml"), kappa)
    res = analyze_algorithm(alg, tol=TOL, family=Interpolation())
    closed = 1 - 1 / math.sqrt(kappa)
    assert res.certified and closed - 1e-9 <= res.rho <= closed + TOL
    assert res.rho_infeasible is not None and res.rho - res.rho_infeasible <= TOL
    assert res.solves <= 4


def test_batched_composite_quadratic_rate_is_the_closed_form():
    """Proximal gradient on f + g with g = 0 quadratics: max(|1 - hm|, |1 - hL|)."""
    spec = load_spec(SPECS / "proximal-gradient.yaml")
    for kappa in (2.0, 10.0, 100.0):
        om = bind(spec, kappa)
        h = 1 / om.L  # the spec's value
        assert quadratic_rate(om) == pytest.approx(max(abs(1 - h * om.m), abs(1 - h * om.L)),
                                                   abs=1e-12)


PROX_HEAVY_BALL = """
name: proximal-heavy-ball
description: heavy ball with a proximal step on g (two oracle calls)
functions:
  f: {class: smooth_strongly_convex}
  g: {class: convex}
parameters:
  h:    {value: 4/(sqrt(L) + sqrt(m))**2}
  beta: {value: ((sqrt(kappa) - 1)/(sqrt(kappa) + 1))**2}
matrices:
  A: [[0, 1], [-beta, 1 + beta]]
  B: [[0, 0], [-h, -h]]
  C: [[0, 1], [-beta, 1 + beta]]
  D: [[0, 0], [-h, -h]]
oracles: [f, g]
output: y2
measure: distance
kappa: [18]
"""


def _lags_built(monkeypatch) -> list[int]:
    """The lags whose LMI the analysis builds (a spy on the family's problem)."""
    built: list[int] = []
    original = Interpolation.problem

    def spy(self, alg):
        built.append(self.lag_for(alg.n))
        return original(self, alg)

    monkeypatch.setattr(Interpolation, "problem", spy)
    return built


def test_two_call_method_keeps_its_first_certified_lag(monkeypatch):
    """With two oracle calls the first lag that certifies is kept: the chosen-lag analysis
    builds only the lag n - 1 LMI (and its lag-0 guess), and gives that lag's rate."""
    alg = bind(load_spec(SPECS / "accelerated-proximal-gradient.yaml"), 10.0)
    alone = analyze_algorithm(alg, tol=TOL, family=Interpolation(alg.n - 1))
    built = _lags_built(monkeypatch)
    auto = analyze_algorithm(alg, tol=TOL, family=Interpolation())
    assert auto.certified and auto.lag == alg.n - 1
    assert auto.rho == pytest.approx(alone.rho, abs=1e-12)
    assert set(built) <= {0, alg.n - 1}
    # the V-FISTA bound sqrt(1 - 1/sqrt(kappa)) is a valid rate, the quadratic one a floor
    assert 1 - 1 / math.sqrt(10) < auto.rho <= math.sqrt(1 - 1 / math.sqrt(10)) + TOL


def test_two_call_method_tries_larger_lags_while_none_certifies(monkeypatch, tmp_path):
    """Heavy ball with a proximal step at kappa = 18 (beyond what lag 1 certifies): the
    choice goes on to larger lags since no lag has certified a rate yet."""
    path = tmp_path / "phb.yaml"
    path.write_text(PROX_HEAVY_BALL)
    alg = bind(load_spec(path), 18.0)
    built = _lags_built(monkeypatch)
    res = analyze_algorithm(alg, tol=TOL, family=Interpolation())
    assert max(built) > alg.n - 1
    assert res.rho is None or res.lag > alg.n - 1
