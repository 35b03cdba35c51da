"""Box-wide dual certificates: every proven box is empty, checked by independent analyses."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from sosalgo.analysis import analyze_algorithm
from sosalgo.certificates import get_family
from sosalgo.design.dualbound import BoundSearch, QuadraticTest, dual_structure
from sosalgo.design.polymodel import fit_poly_lmi
from sosalgo.model import evaluate_algorithm, parameter_box
from sosalgo.spec import load_spec

from .conftest import SPECS


def _search(name, free, kappa, T, record=True, quadratic=True):
    spec = load_spec(SPECS / f"{name}.yaml")
    box = parameter_box(spec, kappa, free)
    model = fit_poly_lmi(spec, kappa, free, box, get_family("theorem1"))
    quad = QuadraticTest(lambda z: evaluate_algorithm(spec, kappa, model.theta(z)),
                         model.half) if quadratic else None
    search = BoundSearch(model, dual_structure(model), T**2, quad, record=record)
    state = search.run(time.perf_counter() + 15, lambda z, r: None)
    return spec, model, state


def _rate_at(spec, kappa, theta):
    """Independent check: the best Theorem 1 rate at θ by plain bisection (no margin
    root-finding, the default solver chain), or 1.0 when nothing below 1 is certified."""
    alg = evaluate_algorithm(spec, kappa, theta)
    res = analyze_algorithm(alg, tol=1e-7, method="bisection")
    return res.rho if res.certified else 1.0


@pytest.mark.parametrize("name,free,kappa,T", [
    ("gradient", ["h"], 10.0, 9 / 11 - 1e-4),
    ("nesterov", ["beta"], 10.0, 0.8193),
    ("nesterov", ["h"], 4.0, 0.6871),
    ("nesterov", ["h", "beta"], 10.0, 0.8163),
])
def test_proven_boxes_contain_no_certifiable_point(name, free, kappa, T):
    spec, model, state = _search(name, free, kappa, T)
    assert state.complete and state.record
    rng = np.random.default_rng(1)
    checked = 0
    for zc, w, r, how in state.record:
        for _ in range(2):
            z = zc + w * rng.uniform(-1, 1, size=zc.size)
            rho = _rate_at(spec, kappa, model.theta(z))
            # the box proves: no certificate with rho^2 < r anywhere in it
            assert rho >= math.sqrt(r) - 1e-6, (how, model.theta(z), rho, math.sqrt(r))
            checked += 1
    assert checked >= 2 * len(state.record)


def test_known_optimum_is_not_excluded():
    """With a target above the true optimum (gradient: (κ-1)/(κ+1)), the search must not
    prove Θ empty: the box with h = 2/(m+L) stays open."""
    kappa = 10.0
    _, model, state = _search("gradient", ["h"], kappa, 9 / 11 + 1e-3, record=True)
    assert not state.complete or state.lower_r() < (9 / 11 + 1e-3) ** 2
    for zc, w, r, _ in state.record:
        lo, hi = (model.theta(zc - w)["h"], model.theta(zc + w)["h"])
        if lo <= 2 / 11 <= hi:
            assert math.sqrt(r) <= 9 / 11 + 1e-7


def test_quadratic_test_only_proves_slow_boxes():
    """Boxes proven by the quadratic-mode test: the slowest visible mode on q = m or L,
    computed directly from eigenvectors, is at least T at sampled points."""
    kappa, T = 10.0, 0.8163
    spec, model, state = _search("nesterov", ["h", "beta"], kappa, T)
    quad = [(zc, w) for zc, w, _, how in state.record if how == "quadratic"]
    assert quad
    rng = np.random.default_rng(2)
    for zc, w in quad:
        z = zc + w * rng.uniform(-1, 1, size=zc.size)
        alg = evaluate_algorithm(spec, kappa, model.theta(z))
        slow = 0.0
        for q in (alg.m, alg.L):
            vals, vecs = np.linalg.eig(alg.A + q * alg.B @ alg.C)
            seen = np.abs(alg.E @ vecs).ravel() > 1e-9
            slow = max(slow, float(np.max(np.abs(vals)[seen], initial=0.0)))
        assert slow >= T - 1e-9


def test_unsupported_family_structure_gives_no_bound():
    """A family whose variables are not all in θ-independent cones has no box bound."""
    spec = load_spec(SPECS / "gradient.yaml")
    box = parameter_box(spec, 10.0, ["h"])
    model = fit_poly_lmi(spec, 10.0, ["h"], box, get_family("theorem1"))
    model.coef = [model.coef[0]]  # drop the P and lambda cone blocks
    model.names, model.strict = model.names[:1], model.strict[:1]
    assert dual_structure(model) is None
