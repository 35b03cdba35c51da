"""The interpolation family's rate search with its cheap proxy (lag 0, no output point):
the proxy only guesses where to look, so the certified rate must agree with the search
without it (to the tolerance, with overlapping brackets), whether the proxy's rate is the
family's (Nesterov, triple momentum) or not (heavy ball with lag 1)."""

from __future__ import annotations

import numpy as np
import pytest

from sosalgo.analysis import analyze_algorithm
from sosalgo.certificates.interpolation import Interpolation
from sosalgo.model import Algorithm, bind
from sosalgo.spec import load_spec

from .conftest import SPECS

TOL = 1e-6


class _NoProxy(Interpolation):
    """The same family searched without a proxy (the plain near-start search)."""

    def guess_problem(self, alg):
        return None


@pytest.mark.parametrize(("name", "kappa", "lag"), [
    ("nesterov", 2.0, 1), ("nesterov", 10.0, 0), ("nesterov", 100.0, 1),
    ("heavy-ball", 10.0, 1), ("heavy-ball", 2.0, 1), ("triple-momentum", 10.0, 1),
])
def test_proxy_changes_the_path_not_the_rate(name, kappa, lag):
    alg = bind(load_spec(SPECS / f"{name}.yaml"), kappa)
    fast = analyze_algorithm(alg, tol=TOL, family=Interpolation(lag))
    plain = analyze_algorithm(alg, tol=TOL, family=_NoProxy(lag))
    assert fast.certified and plain.certified
    assert abs(fast.rho - plain.rho) <= TOL
    # both brackets [rho_infeasible, rho] hold the family's threshold: they must overlap
    assert fast.rho >= plain.rho_infeasible and plain.rho >= fast.rho_infeasible
    assert fast.rho - fast.rho_infeasible <= TOL
    assert fast.max_eig_M <= 0 and fast.min_eig_P >= 0


@pytest.mark.parametrize("lag", [0, 1])
def test_proxy_keeps_heavy_ball_uncertified_at_25(lag):
    alg = bind(load_spec(SPECS / "heavy-ball.yaml"), 25.0)
    res = analyze_algorithm(alg, tol=TOL, family=Interpolation(lag))
    assert not res.certified and res.rho is None


def test_guess_problem_is_smaller_or_absent():
    nest = bind(load_spec(SPECS / "nesterov.yaml"), 10.0)  # has an output point
    grad = bind(load_spec(SPECS / "gradient.yaml"), 10.0)  # x = y
    assert Interpolation(0).guess_problem(grad) is None  # it would be the family itself
    for alg in (nest, grad):
        full = Interpolation(1).problem(alg)
        proxy = Interpolation(1).guess_problem(alg)
        assert proxy is not None and proxy.nvar < full.nvar
        assert max(b.size for b in proxy.blocks) < max(b.size for b in full.blocks)
    proxy = Interpolation(0).guess_problem(nest)
    assert proxy is not None and proxy.nvar < Interpolation(0).problem(nest).nvar


def test_random_methods_agree_with_and_without_proxy():
    """Seeded random 2-state methods (as in the family's tests): same certification
    verdict, rates within the tolerance."""
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(12):
        kappa = float(np.exp(rng.uniform(np.log(1.5), np.log(50))))
        h, b, g = rng.uniform(0, 2 / kappa), rng.uniform(0, 1), rng.uniform(0, 1)
        alg = Algorithm(np.array([[0, 1], [-b, 1 + b]]), np.array([[0], [-h]]),
                        np.array([[-g, 1 + g]]), np.array([[0.0, 1.0]]), 1.0, kappa)
        fast = analyze_algorithm(alg, tol=TOL, family=Interpolation(0))
        plain = analyze_algorithm(alg, tol=TOL, family=_NoProxy(0))
        assert fast.certified == plain.certified
        if fast.certified:
            assert abs(fast.rho - plain.rho) <= TOL
            checked += 1
    assert checked >= 3
