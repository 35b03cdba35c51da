"""Soundness of the design lower bound against an independent judge.

``design``'s ``lower_bound`` (and ``prove_bound``'s) claims that no theta in the box is
certified by Theorem 1 below it. The judge (``tests/independent.py``, which shares no
code with sosalgo) finds certified rates over the box by sampling, root-finding and
polishing, each with a certificate it re-checked itself; a bound above one of them is a
soundness bug. First the judge is tested against closed forms and the Lyapunov
decrease it claims; then generated specs (crossterm-like products of free parameters,
hidden slow modes, 2- and 3-state momentum methods) are checked.

SOSALGO_SOUNDNESS_CASES sets the number of generated cases (default 12; ``make
soundness`` runs 300). Cases and judge results are deterministic and cached per session;
the judge runs in SOSALGO_SOUNDNESS_WORKERS background processes (default 1, 0 for none)
while sosalgo's time-limited calls run in the test process.
"""

from __future__ import annotations

import math
import multiprocessing
import os
from concurrent.futures import Future, ProcessPoolExecutor
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from .independent import (
    Best,
    Case,
    best_rate,
    certify,
    judge,
    judge_key,
    make_case,
    method_rate,
    theorem1_matrix,
)

# under pytest-xdist (make test) every case runs on one worker: the judges are computed once
pytestmark = pytest.mark.xdist_group("soundness")

CASES = max(1, int(os.environ.get("SOSALGO_SOUNDNESS_CASES", "12")))
SEEDS = list(range(CASES))
DESIGN_SEEDS = [s for s in SEEDS if s % 10 == 0]  # design() is the slower call
SLACK = 1e-6  # a bound may exceed the judge's rate by this (its rates are within ~1e-6)
PROVE_LIMIT = 2.0  # seconds for prove_bound per case
DESIGN_LIMIT = 3.0  # seconds for design per case
WORKERS = max(0, int(os.environ.get("SOSALGO_SOUNDNESS_WORKERS", "1")))
FIXED_KEYS = ["crossterm", "hidden"]  # named adversarial cases, always run
_FUTURES: dict = {}  # case key -> Future of the judge's Best, and "pool"


# ---------------------------------------------------------------- the comparison


def bound_violation(bound: float | None, best: Best, case: Case, what: str) -> str | None:
    """None when a claimed lower bound is consistent with the judge, else the report.

    Consistent: no bound, or a bound at most the judge's certified rate (+ SLACK); when
    the judge certified nothing in the box, any bound up to 1.
    """
    if bound is None:
        return None
    if not math.isfinite(best.rho):
        if bound <= 1.0 + 1e-9:
            return None
        return f"{what}: lower_bound {bound!r} > 1\n--- spec ---\n{case.yaml}"
    if bound <= best.rho + SLACK:
        return None
    theta = dict(zip(case.free, (float(t) for t in best.theta), strict=True))
    return (f"{what}: lower_bound {bound!r} is above the judge's certified rate {best.rho!r} "
            f"at theta_J = {theta} (kappa {case.kappa}, free {list(case.free)}; "
            f"certificate max eig M {best.cert.max_eig_M:.3g}, lambda {best.cert.lam:.6g}, "
            f"P = {best.cert.P.tolist()})\n--- spec ---\n{case.yaml}")


def _judges() -> dict[int | str, Future]:
    """Submit every case to the background judges (once per module run)."""
    if not _FUTURES and WORKERS > 0:
        pool = ProcessPoolExecutor(WORKERS, mp_context=multiprocessing.get_context("spawn"))
        _FUTURES.update({key: pool.submit(judge_key, key) for key in [*FIXED_KEYS, *SEEDS]})
        _FUTURES["pool"] = pool
    return _FUTURES


@pytest.fixture(scope="module", autouse=True)
def _background_judges():
    _judges()
    yield
    pool = _FUTURES.pop("pool", None)
    if pool is not None:  # a partial selection (-k) leaves work that nobody will read
        pool.shutdown(wait=True, cancel_futures=True)
    _FUTURES.clear()


@cache
def judged(key: int | str) -> tuple[Case, Best]:
    """The case (a seed or a fixed name) and the judge's best rate, once per session."""
    case = make_case(key)
    future = _FUTURES.get(key)
    if future is not None and (future.running() or future.done() or not future.cancel()):
        return case, future.result()
    return case, judge(case)


def _load(case: Case, best: Best, tmp_path: Path):
    """The case's YAML through sosalgo's loader, after checking that sosalgo reads the
    same method as the judge (at the judge's theta, or the box center)."""
    from sosalgo.model import bind
    from sosalgo.spec import load_spec

    path = tmp_path / f"{case.name}.yaml"
    path.write_text(case.yaml)
    spec = load_spec(path)
    lo, hi = case.box()
    theta = best.theta if best.theta is not None else (lo + hi) / 2
    alg = bind(spec, case.kappa, dict(zip(case.free, map(float, theta), strict=True)))
    for ours, theirs in zip(case.method(theta), (alg.A, alg.B, alg.C, alg.E), strict=True):
        np.testing.assert_allclose(np.asarray(theirs, dtype=float).reshape(ours.shape), ours,
                                   rtol=1e-12, atol=1e-12, err_msg=case.yaml)
    assert alg.m == pytest.approx(case.m) and alg.L == pytest.approx(case.L)
    return spec


def _check_certificate(case: Case, best: Best) -> None:
    """The judge's own certificate satisfies Theorem 1 at its theta (float64)."""
    if best.cert is None:
        return
    M = theorem1_matrix(*case.method(best.theta), case.m, case.L, best.cert.P, best.cert.lam,
                        best.rho)
    slack = 1e-12 * (1 + np.abs(M).max()) if best.cert.reduced else 0.0
    assert np.linalg.eigvalsh(M).max() <= slack
    assert np.linalg.eigvalsh(best.cert.P).min() >= -slack and best.cert.lam >= 0


# ---------------------------------------------------------------- the judge itself


def _gd(h: float) -> tuple[np.ndarray, ...]:
    return np.eye(1), np.array([[-h]]), np.eye(1), np.eye(1)


def _gradient_M(h, rho, lam, p, m, L) -> np.ndarray:
    """Theorem 1's M for x+ = x - h grad f(x), expanded by hand."""
    M11 = p * (1 - rho**2) - (1 - rho**2) * m / 2 - lam * m * L / (m + L)
    M12 = -h * p + (1 - rho**2) / 2 + lam / 2
    M22 = h**2 * p + L * h**2 / 2 - h - lam / (m + L)
    return np.array([[M11, M12], [M12, M22]])


def test_theorem1_matrix_matches_the_gradient_expansion():
    rng = np.random.default_rng(0)
    for _ in range(20):
        m, kappa = rng.uniform(0.1, 3), rng.uniform(1.5, 200)
        L, h, rho = m * kappa, rng.uniform(0, 2) / (m * kappa), rng.uniform(0, 1)
        lam, p = rng.uniform(0, 5), rng.uniform(0, 5)
        np.testing.assert_allclose(theorem1_matrix(*_gd(h), m, L, [[p]], lam, rho),
                                   _gradient_M(h, rho, lam, p, m, L), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("m", [1.0, 0.5])
@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
def test_gradient_rates(kappa, m):
    L = kappa * m
    for hL in (0.5, 1.0, 1.5, 2 * kappa / (kappa + 1), 1.9375):
        h = hL / L
        exact = max(abs(1 - h * m), abs(1 - h * L))
        rho, cert = method_rate(*_gd(h), m, L)
        assert exact - 1e-9 <= rho <= exact + 2e-6, (kappa, m, hL, rho, exact)
        assert cert is not None and cert.max_eig_M <= 0 and cert.min_eig_P >= 0
        ok, *_ = certify(*_gd(h), m, L, exact - 1e-4)
        assert not ok  # never below the true rate
    assert method_rate(*_gd(2.5 / L), m, L)[1] is None  # divergent: nothing certified


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
def test_best_gradient_step(kappa):
    best = best_rate(lambda t: _gd(t[0]), 1.0, kappa, [0.0], [2 / kappa])
    assert best.rho == pytest.approx((kappa - 1) / (kappa + 1), abs=2e-6)
    assert best.theta[0] == pytest.approx(2 / (1 + kappa), rel=1e-3)


def _random_method(rng: np.random.Generator, n: int, kappa: float) -> tuple[np.ndarray, ...]:
    """A perturbed momentum method with the fixed point xi* = e_1 x*."""
    h, beta, gamma = rng.uniform(0.3, 1.8) / kappa, rng.uniform(0, 0.8), rng.uniform(-0.3, 0.8)
    A = np.zeros((n, n))
    A[0, 0] = 1.0
    A[:2, 1] = beta
    A[:, 1:] += rng.normal(0, 0.05, (n, n - 1))
    B = -h * np.ones((n, 1)) + rng.normal(0, 0.02 / kappa, (n, 1))
    C = np.concatenate([[1.0, gamma], rng.normal(0, 0.2, n - 2)])[None]
    E = np.concatenate([[1.0], rng.normal(0, 0.2, n - 1)])[None]
    return A, B, C, E


def _output_radius(A, B, C, E, q: float) -> float:
    """Largest |eigenvalue| of A + q B C among the modes the output x = E xi sees."""
    w, V = np.linalg.eig(A + q * B @ C)
    seen = np.abs(E @ V)[0] > 1e-8 * np.abs(V).max(axis=0)
    return float(np.abs(w[seen]).max()) if seen.any() else 0.0


def test_rates_respect_the_quadratic_bound():
    rng = np.random.default_rng(1)
    certified = 0
    for i in range(24):
        kappa = (2.0, 10.0, 100.0)[i % 3]
        mats = _random_method(rng, 2 + i % 2, kappa)
        rho, cert = method_rate(*mats, 1.0, kappa)
        if cert is None:
            continue
        certified += 1
        bound = max(_output_radius(*mats, q) for q in np.linspace(1.0, kappa, 17))
        assert rho >= bound - 1e-7, (i, rho, bound)
    assert certified >= 12


def _simulate_decrease(mats, m: float, L: float, cert, seed: int) -> None:
    """V_{k+1} <= rho^2 V_k along trajectories on f = m x^2/2 + (L - m) log cosh x."""
    A, B, C, E = mats
    rng = np.random.default_rng(seed)

    def f(x):
        return m * x * x / 2 + (L - m) * (np.logaddexp(x, -x) - math.log(2))

    def V(xi):
        return f(float((E @ xi)[0])) + float(xi @ cert.P @ xi)

    for _ in range(20):
        xi = rng.normal(0, rng.choice([0.1, 1.0, 10.0]), A.shape[0])
        for _ in range(30):
            y = float((C @ xi)[0])
            nxt = A @ xi + B[:, 0] * (m * y + (L - m) * math.tanh(y))
            v0, v1 = V(xi), V(nxt)
            assert v1 <= cert.rho**2 * v0 + 1e-9 * (1 + v0), (v1, v0, cert.rho)
            xi = nxt


def test_certificates_decrease_the_lyapunov_function():
    rng = np.random.default_rng(2)
    done = 0
    for i in range(10):
        kappa = (2.0, 10.0)[i % 2]
        mats = _random_method(rng, 2 + i % 2, kappa)
        rho, cert = method_rate(*mats, 1.0, kappa)
        if cert is not None:
            _check_matrix(mats, 1.0, kappa, cert)
            _simulate_decrease(mats, 1.0, kappa, cert, i)
            done += 1
    assert done >= 5


def _check_matrix(mats, m: float, L: float, cert) -> None:
    M = theorem1_matrix(*mats, m, L, cert.P, cert.lam, cert.rho)
    assert np.allclose(cert.P, cert.P.T) and cert.lam >= 0
    assert np.linalg.eigvalsh(cert.P).min() >= 0 and np.linalg.eigvalsh(M).max() <= 0


def test_hidden_mode_certified_only_where_unobservable():
    """x+ = x - h grad f(x + p z), z+ = 0.9375 z: the slow z counts unless p = 0."""
    kappa, h = 10.0, 1.5 / 10.0

    def mats(p):
        return (np.array([[1.0, 0.0], [0.0, 0.9375]]), np.array([[-h], [0.0]]),
                np.array([[1.0, p]]), np.array([[1.0, 0.0]]))

    rho0, cert0 = method_rate(*mats(0.0), 1.0, kappa)
    assert rho0 == pytest.approx(0.85, abs=2e-6) and cert0.reduced
    _simulate_decrease(mats(0.0), 1.0, kappa, cert0, 0)
    rho1, _ = method_rate(*mats(1e-3), 1.0, kappa)
    assert rho1 >= 0.9375 - 1e-7
    best = best_rate(lambda t: mats(t[0]), 1.0, kappa, [-0.25], [0.5])
    assert best.rho == pytest.approx(0.85, abs=2e-6) and best.theta[0] == 0.0


def test_fixed_cases_judged():
    """crossterm reaches 0.826407 (b g ~ 0.0066); hidden is (kappa-1)/(kappa+1) at p = 0."""
    _, cross = judged("crossterm")
    assert 0.8264 < cross.rho < 0.82642
    _, hidden = judged("hidden")
    assert hidden.rho == pytest.approx(9 / 11, abs=2e-6) and hidden.theta[1] == 0.0
    assert hidden.cert.reduced


def test_comparison_flags_a_wrong_bound():
    """Mutation test: a bound above a rate the judge certifies is reported."""
    case, best = judged("crossterm")
    assert best.rho < 0.83  # crossterm: (b, g) with b g ~ 0.0066 reaches 0.8264
    report = bound_violation(0.89995, best, case, "mutant")  # the value of the known bug
    assert report is not None and "crossterm" in report and "theta_J" in report
    assert bound_violation(best.rho + 1e-4, best, case, "mutant") is not None
    assert bound_violation(best.rho - 1e-4, best, case, "ok") is None
    assert bound_violation(None, best, case, "none") is None
    nothing = Best()
    assert bound_violation(1.0, nothing, case, "uncertified") is None
    assert bound_violation(1.5, nothing, case, "uncertified") is not None


# ---------------------------------------------------------------- sosalgo's bounds


def _refusal_skips(fn, *args, **kwargs):
    """fn(*args, **kwargs); an input refusal (e.g. a degree limit) is a skip, not a bound."""
    from sosalgo.errors import InputError

    try:
        return fn(*args, **kwargs)
    except InputError as exc:
        pytest.skip(f"sosalgo refused the case: {exc}")


def _prove(key: int | str, tmp_path: Path, limit: float = PROVE_LIMIT) -> None:
    from sosalgo.design_search import prove_bound

    case, best = judged(key)
    _check_certificate(case, best)
    spec = _load(case, best, tmp_path)
    target = min(best.rho + 0.03, 1.0) if math.isfinite(best.rho) else 1.0
    res = _refusal_skips(prove_bound, spec, case.kappa, target=target, free=list(case.free),
                         time_limit=limit)
    assert str(getattr(res.status, "value", res.status)) in {"proved", "partial", "unsupported"}
    report = bound_violation(res.lower_bound, best, case, f"prove_bound(target={target:.6f})")
    assert report is None, report


def _design(key: int | str, tmp_path: Path, limit: float = DESIGN_LIMIT) -> None:
    from sosalgo.design_search import design

    case, best = judged(key)
    spec = _load(case, best, tmp_path)
    res = _refusal_skips(design, spec, case.kappa, free=list(case.free), time_limit=limit)
    report = bound_violation(res.lower_bound, best, case, f"design(time_limit={limit})")
    assert report is None, report


@pytest.mark.parametrize("key", FIXED_KEYS)
def test_fixed_prove_bound(key, tmp_path):
    _prove(key, tmp_path)


@pytest.mark.parametrize("key,limit", [("crossterm", DESIGN_LIMIT), ("crossterm", 0.3),
                                       ("hidden", DESIGN_LIMIT)])
def test_fixed_design(key, limit, tmp_path):
    """Crossterm also with a short time limit: a weak search leaves the bound a high
    target (the known bug of the Chebyshev-fitted bound: 0.89995 against 0.8264)."""
    _design(key, tmp_path, limit)


@pytest.mark.parametrize("seed", SEEDS)
def test_prove_bound_below_judge(seed, tmp_path):
    _prove(seed, tmp_path)


@pytest.mark.parametrize("seed", DESIGN_SEEDS)
def test_design_bound_below_judge(seed, tmp_path):
    _design(seed, tmp_path)


def test_generated_cases_are_mostly_convergent():
    finite = [s for s in SEEDS if math.isfinite(judged(s)[1].rho)]
    assert len(finite) >= 0.7 * len(SEEDS)
