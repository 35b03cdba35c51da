"""Soundness of the noise sensitivity against an independent judge: ``noise_certificate``
per lag, ``verify_noise`` and ``analyze_noise`` on random and adversarial momentum methods
(``tests/momentum_cases.py``) >= the judge's gamma on quadratics, and >= a Monte Carlo
estimate on Huber-type f; the bound on the limsup likewise."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from .independent_momentum import (
    Momentum,
    gamma_quadratic,
    noise_monte_carlo,
    noise_monte_carlo_late,
)
from .momentum_cases import (
    CASES,
    REL,
    SPECS,
    F,
    case_of,
    dyadic,
    record,
    same_method,
)

pytestmark = pytest.mark.xdist_group("soundness-momentum")


# ---------------------------------------------------------------- noise bounds

NOISE_KEYS = [*range(2 * CASES), "triple-momentum-k16", "heavy-ball-k25", "beta-0.999"]


@cache
def judged_gamma(key: int | str) -> tuple[float, float]:
    return gamma_quadratic(case_of(key, False).meth)


@pytest.mark.parametrize("key", NOISE_KEYS)
def test_noise_bound_above_quadratic_gamma(key):
    """Every lag's certified gamma, and its exact proof, >= the judge's gamma on
    quadratics; nothing certified when some quadratic is unstable."""
    from sosalgo.model import bind
    from sosalgo.sensitivity import noise_certificate, verify_noise

    case = case_of(key, False)
    spec = case.spec()
    same_method(case, spec)
    gq, q = judged_gamma(key)
    alg = bind(spec, case.kappa)
    for lag in (0, 1, 2):
        cert = noise_certificate(alg, lag)
        record("noise", case.name, lag=lag, judge=gq, gamma=cert.gamma, q=q)
        if not cert.certified:
            continue
        assert math.isfinite(gq) and cert.gamma >= gq * (1 - 1e-7), (
            f"{case.meth}, lag {lag}: certified gamma {cert.gamma!r} < judge {gq!r} at q {q}")
        proof = verify_noise(spec, case.kappa, cert.certificate)
        record("noise-exact", case.name, lag=lag, judge=gq, proven=proof.gamma_proven)
        if proof.ok:
            assert proof.gamma_proven >= gq * (1 - REL), (
                f"{case.meth}, lag {lag}: proven gamma {proof.gamma_proven!r} < judge {gq!r}")


@pytest.mark.parametrize("key", [0, "triple-momentum-k16"])
def test_analyze_noise_above_monte_carlo(key):
    """analyze_noise's bound >= gamma on quadratics and >= a Monte Carlo estimate of
    the long-run E|x_k - x*|^2 / (d sigma^2) on both Huber-type functions (curvature L
    inside a kink at gamma_q / 2; m inside a kink at 2 gamma_q), within 4 standard errors."""
    from sosalgo.sensitivity import analyze_noise

    case = case_of(key, False)
    res = analyze_noise(case.spec(), case.kappa)
    gq, _ = judged_gamma(key)
    if res.noise is None:
        return
    assert res.noise >= gq * (1 - REL)
    for flip, kink in ((False, 0.5), (True, 2.0)):
        mean, se = noise_monte_carlo(case.meth, kink * gq, flip, 1.0, seed=int(flip))
        record("noise-mc", case.name, flip=flip, mc=mean, se=se, gamma2=res.noise**2)
        assert mean <= res.noise**2 + 4 * se, (
            f"{case.meth}: Monte Carlo {mean} +- {se} above certified gamma^2 {res.noise**2}")



@pytest.mark.parametrize("key", [*range(CASES), "triple-momentum-k16", "heavy-ball-k25"])
def test_noise_limsup_above_judge(key):
    """noise_limsup (lag 1) and its exact proof >= the judge's gamma on quadratics, and
    >= the judge's Monte Carlo of E|x_k - x*|^2 / (d sigma^2) at single late times (not
    averaged over time) on both Huber-type functions, within 4 standard errors."""
    from sosalgo.model import bind
    from sosalgo.sensitivity import noise_limsup_certificate, verify_noise

    case = case_of(key, False)
    spec = case.spec()
    same_method(case, spec)
    gq, q = judged_gamma(key)
    cert = noise_limsup_certificate(bind(spec, case.kappa), 1)
    record("noise-limsup", case.name, judge=gq, gamma=cert.gamma, rho=cert.rho, q=q)
    if not cert.certified:
        return
    assert math.isfinite(gq) and cert.gamma >= gq * (1 - 1e-7), (
        f"{case.meth}: noise_limsup {cert.gamma!r} < judge {gq!r} at q {q}")
    proof = verify_noise(spec, case.kappa, cert.certificate, limsup=True)
    record("noise-limsup-exact", case.name, judge=gq, proven=proof.gamma_proven)
    if proof.ok:
        assert proof.gamma_proven >= gq * (1 - REL)
    for flip, kink in ((False, 0.5), (True, 2.0)):
        late, se = noise_monte_carlo_late(case.meth, kink * gq, flip, 1.0, seed=int(flip))
        record("noise-limsup-mc", case.name, flip=flip, mc=late, se=se, gamma2=cert.gamma**2)
        assert late <= cert.gamma ** 2 + 4 * se, (
            f"{case.meth}: late-time Monte Carlo {late} +- {se} above noise_limsup^2 "
            f"{cert.gamma ** 2}")



@pytest.mark.parametrize("seed", range(CASES))
def test_composite_noise_above_smooth_part(seed):
    """Accelerated proximal gradient with noisy gradients, random dyadic h, beta, kappa:
    g = 0 is in the convex class, so the certified gamma (and its exact proof) of the
    composite method is >= the judge's gamma on quadratics of the smooth-only method
    (the judge's momentum method with eta = beta; the prox point y2 is x_{k+1})."""
    import yaml

    from sosalgo.sensitivity import analyze_noise
    from sosalgo.spec import spec_from_dict

    rng = np.random.default_rng(900 + seed)
    kappa = dyadic(float(np.exp(rng.uniform(math.log(1.5), math.log(300)))), 64)
    hL, beta = dyadic(rng.uniform(0.2, 1.6)), dyadic(rng.uniform(0.0, 0.95))
    doc = yaml.safe_load((SPECS / "accelerated-proximal-gradient.yaml").read_text())
    doc["parameters"] = {"h": str(hL / kappa), "beta": str(beta)}
    doc["kappa"] = [float(kappa)]
    spec = spec_from_dict(doc)
    meth = Momentum(hL, beta, beta, F(1), kappa)
    gq, q = gamma_quadratic(meth)
    res = analyze_noise(spec, float(kappa))
    record("noise-composite", f"apg-{seed}", judge=gq, gamma=res.noise, q=q,
           check=res.check_kind)
    if res.noise is None:
        return
    assert math.isfinite(gq) and res.noise >= gq * (1 - 1e-7), (
        f"h L {hL}, beta {beta}, kappa {kappa}: certified {res.noise!r} < judge {gq!r}")
