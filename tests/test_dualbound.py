"""Box-wide dual certificates: every proven box is empty, checked by independent analyses;
the exact polynomial data agree with the family's numeric data; a tampered certificate is
not proven."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from sosalgo.analysis import analyze_algorithm
from sosalgo.certificates import get_family
from sosalgo.design_search import bound_model, prove_bound
from sosalgo.design_search.dualbound import _Box, dual_structure
from sosalgo.design_search.polymodel import evaluate_tensor
from sosalgo.model import evaluate_algorithm
from sosalgo.spec import load_spec

from .conftest import SPECS


def _search(name, free, kappa, T, record=True, modes=True, seconds=15.0):
    spec = load_spec(SPECS / f"{name}.yaml")
    bm = bound_model(spec, kappa, free, get_family("theorem1"))
    if not modes:
        bm.modes = None
    search = bm.search(T**2, record=record)
    state = search.run(time.perf_counter() + seconds, lambda z, r: None)
    return spec, bm.poly, state


def _rate_at(spec, kappa, theta):
    """Independent check: the best Theorem 1 rate at θ by plain bisection (no margin
    root-finding, the default solver chain), or 1.0 when nothing below 1 is certified."""
    alg = evaluate_algorithm(spec, kappa, theta)
    res = analyze_algorithm(alg, tol=1e-7, method="bisection")
    return res.rho if res.certified else 1.0


@pytest.mark.parametrize("name,free,kappa", [
    ("gradient", ["h"], 10.0), ("nesterov", ["h", "beta"], 4.0),
    ("three-parameter", ["h", "beta", "gamma"], 10.0), ("triple-momentum", ["h"], 10.0),
])
def test_exact_data_match_the_family_numeric_data(name, free, kappa):
    """The exact polynomials (sympy, from the family's exact form) evaluated at random θ
    equal the numeric blocks the analysis builds there (a second, float, builder)."""
    spec = load_spec(SPECS / f"{name}.yaml")
    fam = get_family("theorem1")
    poly = bound_model(spec, kappa, free, fam).poly
    rng = np.random.default_rng(0)
    for _ in range(4):
        z = rng.uniform(-1, 1, size=len(free))
        prob = fam.problem(evaluate_algorithm(spec, kappa, poly.theta(z)))
        for b, blk in enumerate(prob.blocks):
            for key in ("c0", "c1", "l0", "l1"):
                got = evaluate_tensor(poly.coef[b][key], poly.degrees, z)
                want = getattr(blk, key)
                assert np.abs(got - want).max() <= 1e-12 * (1 + np.abs(want).max())


@pytest.mark.parametrize("name,free,kappa,T", [
    ("gradient", ["h"], 10.0, 9 / 11 - 1e-4),
    ("nesterov", ["beta"], 10.0, 0.8193),
    ("nesterov", ["h"], 4.0, 0.6871),
    ("nesterov", ["h", "beta"], 10.0, 0.8163),
])
def test_proven_boxes_contain_no_certifiable_point(name, free, kappa, T):
    spec, model, state = _search(name, free, kappa, T)
    assert state.complete and state.record
    assert state.refuted == 0  # every screened box was proven in ball arithmetic
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
    _, model, state = _search("gradient", ["h"], kappa, 9 / 11 + 1e-3, seconds=3.0)
    assert not state.complete
    assert state.lower_bound() <= 9 / 11 + 1e-7
    for zc, w, r, _ in state.record:
        lo, hi = (model.theta(zc - w)["h"], model.theta(zc + w)["h"])
        if lo <= 2 / 11 <= hi:
            assert math.sqrt(r) <= 9 / 11 + 1e-7


def test_mode_argument_only_proves_slow_boxes():
    """Boxes proven by the mode argument: the slowest visible mode on q = m or L,
    computed directly from eigenvectors, is at least T at sampled points."""
    kappa, T = 10.0, 0.8163
    spec, model, state = _search("nesterov", ["h", "beta"], kappa, T)
    boxes = [(zc, w) for zc, w, _, how in state.record if how == "mode"]
    assert boxes
    rng = np.random.default_rng(2)
    for zc, w in boxes:
        for _ in range(3):
            z = zc + w * rng.uniform(-1, 1, size=zc.size)
            alg = evaluate_algorithm(spec, kappa, model.theta(z))
            slow = 0.0
            for q in (alg.m, alg.L):
                vals, vecs = np.linalg.eig(alg.A + q * alg.B @ alg.C)
                seen = np.abs(alg.E @ vecs).ravel() > 1e-9
                slow = max(slow, float(np.max(np.abs(vals)[seen], initial=0.0)))
            assert slow >= T - 1e-9


def test_tampered_dual_certificate_is_not_proven():
    """The ball-arithmetic proof rejects a certificate whose margin was removed: the
    float screening's own Z with its constant term lowered until h(u) <= 0 somewhere."""
    spec = load_spec(SPECS / "gradient.yaml")
    bm = bound_model(spec, 10.0, ["h"], get_family("theorem1"))
    search = bm.search((9 / 11 - 1e-3) ** 2)
    box = _Box(np.array([0.5]), np.array([0.05]))
    T2 = search.state.target
    Zs, bd, cov = search._dual(search._box_data(box, box.w), (0.0, T2))
    assert search.prover.proves(box.zc, box.w, Zs, bd, (0.0, T2), cov)
    assert not search.prover.proves(box.zc, box.w, [[-t for t in Zs[0]]], bd, (0.0, T2))
    scaled = [[t * 0.0 for t in Zs[0]]]  # Z = 0: h = 0 is not > 0
    assert not search.prover.proves(box.zc, box.w, scaled, bd, (0.0, T2))


def test_unsupported_family_structure_gives_no_bound():
    """A family whose variables are not all in θ-independent cones has no box bound."""
    spec = load_spec(SPECS / "gradient.yaml")
    poly = bound_model(spec, 10.0, ["h"], get_family("theorem1")).poly
    poly.coef = [poly.coef[0]]  # drop the P and lambda cone blocks
    poly.names, poly.strict = poly.names[:1], poly.strict[:1]
    assert dual_structure(poly) is None
    res = prove_bound(spec, 10.0, 0.8, free=["h"], family="interpolation")
    assert res.status == "unsupported" and res.lower_bound is None


def test_prove_bound_proves_below_and_refuses_above_the_closed_form():
    """Gradient step over [0, 2/L]: the optimum is (κ-1)/(κ+1) (a closed form, attained
    as a limit). Below it the bound is proved; above it, never."""
    spec = load_spec(SPECS / "gradient.yaml")
    opt = 9 / 11
    below = prove_bound(spec, 10.0, opt - 1e-3, time_limit=20)
    assert below.status == "proved" and below.lower_bound == pytest.approx(opt - 1e-3)
    assert below.lower_bound <= opt - 1e-3
    above = prove_bound(spec, 10.0, opt + 1e-3, time_limit=2)
    assert above.status == "partial" and above.lower_bound <= opt
