"""The faster lag choice and start of the interpolation search (issue 18, speed): the
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
