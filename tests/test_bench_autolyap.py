"""Pure helpers of the AutoLyap comparison (bench/autolyap.py); AutoLyap itself is not run."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench.autolyap import autolyap_job, like_for_like, rho2_tolerance
from sosalgo.certificates.interpolation import has_output_point
from sosalgo.model import bind
from sosalgo.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"


@pytest.mark.parametrize("tol", [1e-6, 1e-3, 0.05])
def test_rho2_tolerance_brackets_rho_to_tol(tol: float) -> None:
    """A bisection on r = rho^2 stopped at width w brackets rho = sqrt(r) to tol for every
    upper end hi >= rho_q^2 (worst case: hi = rho_q^2, lo = hi - w), and w is not needlessly
    small: about 2 rho_q tol, the width that gives rho to tol at rho = rho_q."""
    for rho_q in np.linspace(0.0, 1.0, 201):
        w = rho2_tolerance(float(rho_q), tol)
        for hi in np.linspace(rho_q**2, 1.0, 50):
            lo = max(hi - w, 0.0)
            assert math.sqrt(hi) - math.sqrt(lo) <= tol * (1 + 1e-9)
        assert w <= max(2 * rho_q * tol, tol * tol) * (1 + 1e-12)
        if rho_q >= 0.5:
            assert w >= 2 * rho_q * tol - 2 * tol * tol


def test_like_for_like_and_jobs() -> None:
    """Seed methods get E = C (AutoLyap's measure point); proximal gradient is passed with
    its two classes and D; a function measure on two functions has no AutoLyap match."""
    nes = bind(load_spec(SPECS / "nesterov.yaml"), 10.0)
    assert has_output_point(nes.C, nes.E)
    same = like_for_like(nes)
    assert not has_output_point(same.C, same.E)
    assert np.array_equal(same.A, nes.A) and np.array_equal(same.B, nes.B)
    job = autolyap_job(same, 1, 1, 0)
    assert job is not None and job["measure"] == "function" and job["D"] == [[0.0]]
    assert job["classes"] == [["ssc", nes.m, nes.L]]

    prox = bind(load_spec(SPECS / "proximal-gradient.yaml"), 10.0)
    assert like_for_like(prox) is prox
    job = autolyap_job(prox, 0, 0, 0)
    assert job is not None and job["measure"] == "distance"
    assert [c[0] for c in job["classes"]] == ["ssc", "convex"]
    assert np.allclose(job["D"], [[0.0, 0.0], [-0.1, -0.1]])  # h = 1/L, L = 10

    apg = bind(load_spec(SPECS / "accelerated-proximal-gradient.yaml"), 10.0)
    assert autolyap_job(apg, 0, 0, 0) is None


@pytest.mark.parametrize("mu, L, gamma, lam", [(1.0, 5.0, 0.5, 1.0), (1.0, 2.0, 0.5, 2.0)])
def test_giselsson_rate_is_attained_by_a_linear_witness(mu, L, gamma, lam):
    """The operator bench's reference (Giselsson 2017, Thm. 6.5, tight) against an
    independent computation: the slowest normal linear pair of the classes, its rate
    enclosed in ball arithmetic, reaches it (1e-7) and never exceeds it."""
    from bench.autolyap_operators import DR_GISELSSON, giselsson_rho, witness_rate
    from sosalgo.spec.loading import spec_from_text

    spec = spec_from_text(DR_GISELSSON.replace("MU", repr(mu)), "<dr>")
    lower = witness_rate(spec, L / mu, {"gamma": gamma, "lam": lam})
    closed = giselsson_rho(mu, L, gamma, lam)
    assert closed - 1e-7 <= lower <= closed + 1e-12


def _cp_step(tau: float, sigma: float, theta: float, a: float, b: float) -> np.ndarray:
    """Chambolle-Pock's step on f1 = a/2 |x|^2, f2 = b/2 |x|^2 from its prox formulas:
    x+ = (x - tau y)/(1 + tau a), y+ = prox_{sigma f2*}(w) = b w/(b + sigma) (f2* = |y|^2/(2b)),
    w = y + sigma (x+ + theta (x+ - x)); the matrix of (x, y) -> (x+, y+)."""
    cols = []
    for x, y in ((1.0, 0.0), (0.0, 1.0)):
        xp = (x - tau * y) / (1 + tau * a)
        cols.append([xp, b * (y + sigma * (xp + theta * (xp - x))) / (b + sigma)])
    return np.array(cols).T


@pytest.mark.parametrize("i, j", [(87, 3), (33, 11), (0, 88)])
def test_chambolle_pock_bench_spec_is_the_method(i: int, j: int) -> None:
    """The bench's Chambolle-Pock spec (AutoLyap's A, B, C, D) is the method: on scalar
    quadratics its closed loop has the spectrum of the step written from the prox formulas,
    and the bench's lower bound is the largest such spectral radius on its grid."""
    from bench.autolyap_operators import CP_L, CP_MU, CP_SPEC, cp_point, cp_quadratic_rate

    theta = cp_point(i, j)
    tau, th = float(theta["tau"]), float(theta["theta"])
    alg = bind(load_spec(CP_SPEC), CP_L / CP_MU, theta)
    worst = 0.0
    for a in np.linspace(CP_MU, CP_L, 9):
        for b in np.linspace(CP_MU, CP_L, 9):
            G = np.diag([a, b])
            T = alg.A + alg.B @ np.linalg.solve(np.eye(2) - G @ alg.D, G @ alg.C)
            step = _cp_step(tau, tau, th, a, b)
            assert np.sort_complex(np.linalg.eigvals(T)) == pytest.approx(
                np.sort_complex(np.linalg.eigvals(step)), abs=1e-12)
            worst = max(worst, max(abs(np.linalg.eigvals(step))))
    assert cp_quadratic_rate(tau, tau, th, CP_MU, CP_L) == pytest.approx(worst, abs=1e-12)


@pytest.mark.parametrize("i, j, published", [(87, 3, 0.880859375), (33, 11, 0.9306640625)])
def test_chambolle_pock_at_least_as_tight_as_autolyaps_published_curve(i, j, published):
    """At points of AutoLyap's published Chambolle-Pock sweep (its stored rho on
    |x_k - x*|^2): our rate is proven exactly, at most sqrt(its rho) + 1e-6, and not below
    the rate on scalar quadratics (a lower bound of every valid rate)."""
    from bench.autolyap_operators import (
        CP_L,
        CP_MU,
        CP_PUBLISHED,
        CP_SPEC,
        TOL,
        cp_point,
        cp_quadratic_rate,
    )
    from sosalgo.analysis import analyze_algorithm
    from sosalgo.certificates.interpolation import Interpolation

    assert (i, j, published) in CP_PUBLISHED
    spec, kappa, theta = load_spec(CP_SPEC), CP_L / CP_MU, cp_point(i, j)
    fam = Interpolation()
    res = analyze_algorithm(bind(spec, kappa, theta), tol=TOL, family=fam)
    proof = fam.exact_check(spec, kappa, res.rho, res.certificate, theta)
    assert proof.verified == "exact"
    assert proof.rho_proven_float <= math.sqrt(published) + 1e-6
    floor = cp_quadratic_rate(float(theta["tau"]), float(theta["sigma"]),
                              float(theta["theta"]), CP_MU, CP_L)
    assert proof.rho_proven_float >= floor - 1e-9
