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
