"""Soundness of the proof-producing features of issues 18-20 against an independent judge.

Random gradient methods with momentum (``tests/independent_new.py``: x+ = x - h grad f(x +
eta (x - x_prev)) + beta (x - x_prev); random h, beta, eta, near-divergent and degenerate
ones, tuned ones, kappa in [1.5, 1e4]; every parameter an exact dyadic rational, so that
the judge's fractions and sosalgo's exact arithmetic read the same method) and
adversarial ones are written as specs and judged:

1. sublinear constants (``analyze_sublinear``, ``verify_exact_sublinear``) >= the judge's
   floor max_k k (f(x_k) - f*) / |x_0 - x*|^2 on quadratics and Huber functions;
2. noise sensitivity (``noise_certificate`` per lag, ``verify_noise``, ``analyze_noise``)
   >= the judge's gamma on quadratics, and >= a Monte Carlo estimate on Huber-type f;
3. PEP: ``tau_proven`` >= the judge's worst instance, the verified witness <= tau_proven
   and re-checked by the judge; gradient descent against its closed forms, exactly;
4. rate brackets: ``rho_lower`` <= every certified rho, <= the judge's largest spectral
   radius on quadratics + 1e-9, its curvature re-checked; cycles re-checked in fractions
   and never beside a certified rate.

SOSALGO_NEW_CASES sets the number of random cases per feature (default 2; ``make
soundness`` runs NEW_CASES). SOSALGO_NEW_REPORT, a file path: every comparison is
appended to it as one JSON line (the margins reported in README).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from fractions import Fraction
from functools import cache

import numpy as np
import pytest

from .independent_new import (
    Momentum,
    check_cycle,
    check_pep_witness,
    frac,
    gamma_quadratic,
    gd_tau_convex,
    gd_tau_strong,
    max_radius,
    noise_monte_carlo,
    observable,
    pep_floor,
    radius,
    sublinear_floor,
)

pytestmark = pytest.mark.xdist_group("soundness-new")

CASES = max(1, int(os.environ.get("SOSALGO_NEW_CASES", "2")))
REPORT = os.environ.get("SOSALGO_NEW_REPORT")
DEN = 4096  # parameters are multiples of 1/DEN (exact in binary and in decimal)
REL = 1e-9  # relative room for the judge's own float rounding (its bounds are floats)
CYCLE_SECONDS = 1.0
F = Fraction


def record(feature: str, case: str, **numbers: object) -> None:
    """One comparison, appended to SOSALGO_NEW_REPORT (when set) as a JSON line."""
    if REPORT:
        with open(REPORT, "a") as fh:
            fh.write(json.dumps({"feature": feature, "case": case, **numbers}) + "\n")


# ---------------------------------------------------------------- the cases


@dataclass(frozen=True)
class Case:
    name: str
    meth: Momentum

    @property
    def kappa(self) -> float:
        return float(self.meth.L / self.meth.m) if self.meth.m else math.nan

    def spec(self):
        """The method as a sosalgo spec (seed spec on F(1, kappa), or m: 0, L = 1)."""
        from sosalgo.spec import spec_from_dict

        mt = self.meth
        d: dict = {"name": self.name,
                   "parameters": {"h": {"value": f"({mt.hL})/L"},
                                  "beta": {"value": str(mt.beta)},
                                  "eta": {"value": str(mt.eta)}},
                   "matrices": {"A": [[0, 1], ["-beta", "1 + beta"]], "B": [[0], ["-h"]],
                                "C": [["-eta", "1 + eta"]], "E": [[0, 1]]}}
        if mt.m == 0:
            d |= {"m": 0, "L": 1, "functions": {"f": {"class": "smooth_strongly_convex"}}}
        else:
            d["kappa"] = [self.kappa]
        return spec_from_dict(d)


def dyadic(x: float, den: int = DEN) -> Fraction:
    return F(round(x * den), den)


def boundary(beta: Fraction, eta: Fraction) -> Fraction:
    """h L at which the loop at q = L has the root -1: 2 (1 + beta) / (1 + 2 eta)."""
    return 2 * (1 + beta) / (1 + 2 * eta)


def tuned(kappa: float, which: int) -> tuple[Fraction, Fraction, Fraction]:
    """(beta, eta, h L) of Nesterov (0), heavy ball (1), triple momentum (2) at kappa."""
    s = math.sqrt(kappa)
    if which == 0:
        b = dyadic((s - 1) / (s + 1))
        return b, b, F(1)
    if which == 1:
        return dyadic(((s - 1) / (s + 1)) ** 2), F(0), dyadic(4 * kappa / (1 + s) ** 2)
    r = 1 - 1 / s  # triple momentum: rho = 1 - 1/sqrt(kappa)
    return dyadic(r * r / (2 - r)), dyadic(r * r / ((1 + r) * (2 - r))), dyadic(1 + r)


def make_case(seed: int, sublinear: bool) -> Case:
    """Random (kind seed % 5): free, near-divergent, degenerate, tuned, extreme kappa."""
    rng = np.random.default_rng(10_000 + seed + (50_000 if sublinear else 0))
    kappa = dyadic(float(np.exp(rng.uniform(math.log(1.5), math.log(1e4)))), 64)
    kind = seed % 5
    beta, eta = dyadic(rng.uniform(0, 1)), dyadic(rng.uniform(0, 1.5))
    hL = dyadic(rng.uniform(0.01, 1.0) * float(boundary(beta, eta)))
    if kind == 1:  # just inside the boundary at q = L, or beta near 1
        if rng.uniform() < 0.5:
            hL = boundary(beta, eta) * (1 - F(1, int(rng.choice([64, 1024]))))
        else:
            beta = 1 - F(1, int(rng.choice([32, 256])))
    elif kind == 2:  # gradient descent, heavy ball, Nesterov form, tiny step
        beta, eta = [(F(0), F(0)), (beta, F(0)), (beta, beta), (beta, eta)][seed // 5 % 4]
        hL = hL if seed // 5 % 4 != 3 else F(1, DEN)
    elif kind == 3:  # Nesterov, heavy ball, triple momentum tunings, rounded to dyadics
        beta, eta, hL = tuned(float(kappa) if not sublinear else 1e6, seed // 5 % 3)
    elif kind == 4:
        kappa = F(10_000) if seed // 5 % 2 == 0 else F(3, 2)
    m, L = (F(0), F(1)) if sublinear else (F(1), kappa)
    return Case(f"mom-{'sub' if sublinear else 'lin'}-{seed}", Momentum(hL, beta, eta, m, L))


ADVERSARIAL = {
    "gd-1-over-L": (F(1), F(0), F(0)),
    "gd-near-2-over-L": (F(2) - F(1, 1024), F(0), F(0)),
    "heavy-ball-k25": (F(25, 9), F(4, 9), F(0)),  # cycles at kappa 25 (Lessard et al.)
    "triple-momentum-k16": (F(7, 4), F(9, 20), F(9, 35)),  # rho = 1 - 1/4 on F(1, 16)
    "beta-0.999": (F(1, 2), F(999, 1000), F(1, 2)),
    "eta-large": (F(1, 8), F(1, 2), F(4)),
}


def adversarial(name: str, sublinear: bool = False) -> Case:
    kappa = {"heavy-ball-k25": F(25), "triple-momentum-k16": F(16)}.get(name, F(100))
    m, L = (F(0), F(1)) if sublinear else (F(1), kappa)
    return Case(name, Momentum(*ADVERSARIAL[name], m, L))


def case_of(key: int | str, sublinear: bool) -> Case:
    return make_case(key, sublinear) if isinstance(key, int) else adversarial(key, sublinear)


def same_method(case: Case, spec) -> None:
    """sosalgo reads the judge's method (matrices, m, L) from the case's spec."""
    from sosalgo.model import bind, bind_sublinear

    mt = case.meth
    alg = bind_sublinear(spec) if mt.m == 0 else bind(spec, case.kappa)
    A, B, C, E = mt.matrices()
    for ours, theirs in zip((A, B, C, E), (alg.A, alg.B, alg.C, alg.E), strict=True):
        np.testing.assert_allclose(np.asarray(theirs, dtype=float), ours, rtol=1e-13,
                                   atol=1e-15, err_msg=case.name)
    assert float(alg.m) == float(mt.m) and float(alg.L) == pytest.approx(float(mt.L))


# ---------------------------------------------------------------- the judge itself


def test_judge_against_closed_forms():
    """The judge's floors on gradient descent and heavy ball against closed forms."""
    gd = Momentum(F(1), F(0), F(0), F(0), F(1))
    c, _ = sublinear_floor(gd)
    assert 0.2499 <= c <= 0.25  # sup_k k/(4k + 2) = L/4 (Drori-Teboulle), k <= 2000
    for N in (1, 3):
        v, what = pep_floor(gd, N, "f")
        assert 0.999 * gd_tau_convex(1.0, N) <= v <= gd_tau_convex(1.0, N) * (1 + 1e-12), what
    for hL in (F(1, 2), F(1), F(19, 10)):
        g = Momentum(hL, F(0), F(0), F(1), F(10))
        v, _ = pep_floor(g, 3, "dist")
        assert v == pytest.approx(gd_tau_strong(float(g.h), 1.0, 10.0, 3), rel=1e-12)
        h = float(g.h)
        gam, _ = gamma_quadratic(g)  # gamma_q^2 = h / (q (2 - h q)), largest at q = m or L
        assert gam**2 == pytest.approx(max(h / (q * (2 - h * q)) for q in (1.0, 10.0)),
                                       rel=1e-10)
        assert max_radius(g)[0] == pytest.approx(max(abs(1 - h), abs(1 - 10 * h)), rel=1e-12)
    s = 5.0  # heavy ball tuned for quadratics, kappa 25: every mode at sqrt(beta) = 2/3
    hb = Momentum(F(25, 9), F(4, 9), F(0), F(1), F(25))
    assert max_radius(hb)[0] == pytest.approx((s - 1) / (s + 1), rel=1e-7)
    mean, se = noise_monte_carlo(Momentum(F(1, 2), F(0), F(0), F(1), F(4)), 1e9, False, 0.1)
    h = 1 / 8  # f = 2 x^2 (delta beyond reach): h / (L (2 - h L))
    assert abs(mean - h / (4 * (2 - h * 4))) <= 5 * se


def test_judge_rejects_tampered_cycle():
    """A hand-made 2-cycle of x+ = x - h f'(x), h L = 2, on f = 2 x^2 of F(1, 4) (points
    1, -1, gradients 4, -4, values 2): accepted; a changed value or gradient is refused."""
    meth = Momentum(F(2), F(0), F(0), F(1), F(4))
    cyc = {"length": 2, "factor": "1", "points": [["1"], ["-1"]], "gradients": [["4"], ["-4"]],
           "values": ["2", "2"], "states": [[["-1"], ["1"]], [["1"], ["-1"]]]}
    assert check_cycle(meth, cyc) is None
    assert check_cycle(meth, cyc | {"values": ["2", "1"]}) is not None
    assert check_cycle(meth, cyc | {"gradients": [["4"], ["-3"]]}) is not None


# ---------------------------------------------------------------- 1. sublinear

# seeds from 1: seed 0 (17 solves, about 10 s) runs in make soundness only
SUB_KEYS = [*range(1, 1 + max(1, CASES // 2)), "gd-1-over-L", "gd-near-2-over-L"]


@pytest.mark.parametrize("key", SUB_KEYS)
def test_sublinear_constant_above_floor(key):
    from sosalgo.analysis import analyze_sublinear
    from sosalgo.verify.exact_sublinear import verify_exact_sublinear

    case = case_of(key, True)
    spec = case.spec()
    same_method(case, spec)
    floor, where = sublinear_floor(case.meth)
    res = analyze_sublinear(spec)
    record("sublinear", case.name, floor=floor, constant=res.constant, where=where)
    if not res.certified:
        return
    assert math.isfinite(floor) and res.constant >= floor * (1 - REL), (
        f"{case.meth}: certified c = {res.constant!r} < judge floor {floor!r} ({where})")
    proof = verify_exact_sublinear(spec, json.loads(json.dumps(res.to_dict())))
    record("sublinear-exact", case.name, floor=floor, proven=proof.constant_proven,
           ok=proof.ok)
    if proof.ok:
        assert float(F(proof.constant_proven)) >= floor * (1 - REL), (
            f"{case.meth}: proven c = {proof.constant_proven} < judge floor {floor!r} "
            f"({where})")


# ---------------------------------------------------------------- 2. noise

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


# ---------------------------------------------------------------- 3. PEP

PEP_KEYS = [*range(CASES), "triple-momentum-k16", "heavy-ball-k25", "eta-large"]


def _pep_checks(case: Case, res, floor: float, where: str, measure: str,
                exact: float | Fraction | None = None) -> None:
    """tau_proven >= the judge's floor (and >= ``exact``, a closed form); a verified
    witness <= tau_proven (and <= ``exact``), re-checked by the judge."""
    cert, wit = res.certificate or {}, res.witness or {}
    proven = F(cert["tau_proven"]) if cert.get("tau_proven") else None
    check = wit.get("check") or {}
    lower = F(check["tau_lower"]) if check.get("verified") else None
    record("pep", case.name, steps=res.steps, measure=measure, floor=floor, tau=res.tau,
           proven=None if proven is None else float(proven),
           lower=None if lower is None else float(lower), where=where)
    if proven is not None:
        assert float(proven) >= floor * (1 - REL), (
            f"{case.meth}, N = {res.steps}: tau_proven {float(proven)!r} < {floor!r} ({where})")
        assert exact is None or proven >= exact, f"tau_proven {proven} < closed form {exact}"
    if lower is None:
        return
    assert proven is None or lower <= proven, f"witness {lower} > tau_proven {proven}"
    assert exact is None or lower <= exact, f"witness {lower} > closed form {exact}"
    ratio, why = check_pep_witness(case.meth, wit, measure)
    assert ratio is not None, f"{case.meth}: verified witness fails the judge: {why}"
    assert ratio >= lower, f"witness ratio {ratio} < its claimed lower bound {lower}"


@pytest.mark.parametrize("key", PEP_KEYS)
def test_pep_bound_above_bad_instances(key):
    import sosalgo

    case = case_of(key, False)
    N = 1 + (len(key) % 3 if isinstance(key, str) else key % 4)
    measure = "f" if (key if isinstance(key, int) else len(key)) % 2 == 0 else "dist"
    res = sosalgo.pep(case.spec(), case.kappa, N, measure=measure)
    floor, where = pep_floor(case.meth, N, measure)
    _pep_checks(case, res, floor, where, measure)


@pytest.mark.parametrize("seed", range(CASES + 1))
def test_pep_gradient_closed_forms(seed):
    """Gradient descent: dist/dist on F(1, kappa) is max(|1 - h|, |1 - hL|)^(2N) and
    f/dist with h = 1/L on F(0, L) is L/(4N + 2), exactly: tau_proven >= it >= witness."""
    import sosalgo

    rng = np.random.default_rng(777 + seed)
    N = int(rng.integers(1, 5))
    kappa = dyadic(float(np.exp(rng.uniform(math.log(1.5), math.log(1e4)))), 64)
    hL = dyadic(rng.uniform(0.05, 1.99)) if seed % 3 else 2 / (1 + 1 / kappa)  # h = 2/(m+L)
    strong = Case(f"gd-{seed}", Momentum(hL, F(0), F(0), F(1), kappa))
    closed = max(abs(1 - strong.meth.h), abs(1 - hL)) ** (2 * N)
    assert float(closed) == pytest.approx(gd_tau_strong(float(strong.meth.h), 1, float(kappa),
                                                        N), rel=1e-12)
    res = sosalgo.pep(strong.spec(), strong.kappa, N, measure="dist")
    _pep_checks(strong, res, float(closed), "closed form", "dist", closed)
    convex = Case("gd-convex", Momentum(F(1), F(0), F(0), F(0), F(1)))
    res = sosalgo.pep(convex.spec(), None, N)
    closed = F(1, 4 * N + 2)
    assert float(closed) == pytest.approx(gd_tau_convex(1.0, N), rel=1e-15)
    _pep_checks(convex, res, float(closed), "closed form", "f", closed)


# ---------------------------------------------------------------- 4. brackets and cycles

BRACKET_KEYS = [*range(3 * CASES), *ADVERSARIAL]


@pytest.mark.parametrize("key", BRACKET_KEYS)
def test_rate_bracket_below_rates(key):
    """rho_lower <= every certified rho (Theorem 1, interpolation) and <= the judge's
    largest radius on quadratics + 1e-9; its curvature re-checked; a cycle re-checked in
    fractions and never beside a certified rate."""
    import sosalgo
    from sosalgo.witnesses.rows import witness_fields

    case = case_of(key, False)
    spec = case.spec()
    rates = {fam: sosalgo.analyze(spec, case.kappa, certificate=fam)
             for fam in ("theorem1", "interpolation")}
    t1 = rates["theorem1"]
    w = witness_fields(spec, case.kappa, None, t1.certified, t1.rho if t1.certified else None,
                       cycle_seconds=CYCLE_SECONDS)
    top, q_top = max_radius(case.meth)
    certified = {f: r.rho for f, r in rates.items() if r.certified}
    record("bracket", case.name, rho_lower=w["rho_lower"], kind=w["rho_lower_kind"],
           judge=top, q=q_top, rates=certified)
    if w["cycle"] is not None:
        assert not certified, f"{case.meth}: a cycle beside certified rates {certified}"
        text = json.dumps([w["cycle"][k] for k in ("points", "gradients", "values", "states")])
        record("cycle", case.name, exact=w["cycle"].get("exact"), balls="+-" in text)
        assert not (w["cycle"].get("exact") and "+-" in text), "balls in an exact cycle"
        if w["cycle"].get("exact"):  # plain fractions: the judge re-checks them
            why = check_cycle(case.meth, w["cycle"])
            assert why is None, f"{case.meth}: cycle fails the judge: {why}"
        return
    lo = w["rho_lower"]
    if lo is None:
        return
    for fam, rho in certified.items():
        assert lo <= rho, f"{case.meth}: rho_lower {lo!r} > {fam} rho {rho!r}"
    if w["rho_lower_kind"] == "quadratic":
        assert lo <= top + 1e-9, f"{case.meth}: rho_lower {lo!r} > judge {top!r} at q {q_top}"
        q = frac(w["rho_lower_witness"]["curvatures"]["f"])
        assert radius(case.meth, float(q)) >= lo * (1 - 1e-12)
        m_ = case.meth  # every mode shows in x_k, or beta = eta = 0 (gradient descent on
        # two states, the first never read): x_{k+1} = (1 - q h) x_k, one mode
        assert observable(m_, q) or (m_.beta == 0 and m_.eta == 0
                                     and abs(1 - q * m_.h) >= lo * (1 - 1e-12))


def test_heavy_ball_cycle_rechecked():
    """Heavy ball tuned for quadratics at kappa 25: a cycle is found (issue 19) and the
    judge re-checks it; tampering breaks it."""
    from sosalgo.witnesses.rows import witness_fields

    case = adversarial("heavy-ball-k25")
    w = witness_fields(case.spec(), case.kappa, None, False, None, cycle_seconds=5.0)
    cyc = w["cycle"]
    assert cyc is not None and cyc["exact"]
    assert check_cycle(case.meth, cyc) is None
    bad = cyc | {"values": ["0", *cyc["values"][1:]]}  # f(y_0) = f* with y_0 != x*
    assert check_cycle(case.meth, bad) is not None


@pytest.mark.deep
@pytest.mark.parametrize("key", ["heavy-ball-k10", "triple-momentum-k16"])
def test_self_similar_bracket_below_rates(key):
    """The self-similar bracket (a trajectory decaying by rho^K per period) <= the
    interpolation family's certified rate."""
    import sosalgo
    from sosalgo.witnesses.rows import witness_fields

    if key == "heavy-ball-k10":  # h = 4/(1 + sqrt 10)^2, beta = ((sqrt 10 - 1)/(sqrt 10 + 1))^2
        s = math.sqrt(10)
        case = Case(key, Momentum(dyadic(40 / (1 + s) ** 2), dyadic(((s - 1) / (s + 1)) ** 2),
                                  F(0), F(1), F(10)))
    else:
        case = adversarial(key)
    spec = case.spec()
    res = sosalgo.analyze(spec, case.kappa, certificate="interpolation")
    w = witness_fields(spec, case.kappa, None, res.certified, res.rho if res.certified else None,
                       brackets="self-similar", cycle_seconds=3.0)
    record("bracket-self-similar", case.name, rho_lower=w["rho_lower"],
           kind=w["rho_lower_kind"], rho=res.rho if res.certified else None)
    if res.certified and w["rho_lower"] is not None:
        assert w["rho_lower"] <= res.rho
