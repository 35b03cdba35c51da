"""Online learning (``per_step: true``: step k calls f_k, a new function of its class):
the shipped online gradient descent, follow the (regularized) leader and online
Frank-Wolfe specs against closed forms, their proofs re-checked and tampered ones refused,
a soundness suite judged by numpy alone (explicit sequences of Lipschitz convex functions
on a ball or an interval: linear functions, absolute values; the regret against points of
the set never above the proven bound, and explicit linear instances that reach it), and
bad input."""

from __future__ import annotations

import copy
import math
from fractions import Fraction

import numpy as np
import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.spec import spec_from_text
from sosalgo.worstcase.finite_sum import reprove_finite_sum

from .conftest import SPECS

METHODS = ("online-gradient-descent", "follow-the-regularized-leader", "follow-the-leader",
           "online-frank-wolfe")


def _spec(name: str, **values: str):
    text = (SPECS / f"{name}.yaml").read_text()
    for key, val in values.items():  # the parameters' values, as --set would
        lines = [ln for ln in text.splitlines() if ln.startswith(f"  {key}:")]
        text = text.replace(lines[0], f"  {key}: {val}")
    return spec_from_text(text, f"{name}.yaml")


_CACHE: dict[tuple, object] = {}


def _pep(name: str, steps: int, M: str = "1", D: str = "1/2"):
    key = (name, steps, M, D)
    if key not in _CACHE:
        _CACHE[key] = sosalgo.pep(_spec(name, M=M, D=D), None, steps)
    return _CACHE[key]


def _proven(res) -> float:
    return float(Fraction(res.certificate["tau_proven"]))


# --------------------------------------------------------------------------- closed forms
@pytest.mark.parametrize("name", ["online-gradient-descent", "follow-the-regularized-leader"])
@pytest.mark.parametrize(("steps", "M", "D"), [(2, "1", "1/2"), (3, "1", "1/2"),
                                               (2, "2", "1")])
def test_sqrt_n_regret_is_the_worst_case(name, steps, M, D):
    """With the step D/(M sqrt(N)) the regret is at most M D sqrt(N) (Orabona 2025, Hazan
    2016), reached here (and by PEPit's examples at these arguments)."""
    res = _pep(name, steps, M, D)
    want = float(Fraction(M)) * float(Fraction(D)) * math.sqrt(steps)
    assert res.status == "solved" and abs(res.tau - want) <= 1e-6 * want
    assert want * (1 - 1e-9) <= _proven(res) <= want * (1 + 1e-6)


def test_a_start_near_the_reference_is_zinkevichs_bound():
    """With |x_0 - x_ref| <= r (``--initial``), online gradient descent's regret is at
    most r^2/(2 gamma) + gamma N M^2/2 (Zinkevich 2003), attained at N = 2."""
    spec = _spec("online-gradient-descent")
    res = sosalgo.pep(spec, None, 2, initial="(x - xs)**2 <= 1/100")
    gamma = 0.5 / math.sqrt(2)
    want = 0.01 / (2 * gamma) + gamma * 2 / 2
    assert abs(res.tau - want) <= 1e-6 * want
    assert want * (1 - 1e-9) <= _proven(res) <= want * (1 + 1e-6)


@pytest.mark.parametrize("name", ["follow-the-leader", "online-frank-wolfe"])
def test_two_steps_on_a_set_of_diameter_d(name):
    """Two steps (x_1 = argmin over C of f_0 for FTL; sigma = 1, OFW's x_1 = the LMO's
    point): the worst regret is M D (2 + sqrt 3)/2, PEPit's 0.9330127 at M = 1, D = 1/2
    and 3.7320508 at M = 2, D = 1 (its value scales as M D)."""
    for M, D in (("1", "1/2"), ("2", "1")):
        res = _pep(name, 2, M, D)
        want = float(Fraction(M)) * float(Fraction(D)) * (2 + math.sqrt(3)) / 2
        assert abs(res.tau - want) <= 1e-6 * want
        assert want * (1 - 1e-9) <= _proven(res) <= want * (1 + 1e-6)


# --------------------------------------------------------------------------- proofs
@pytest.mark.parametrize("name", METHODS)
def test_the_proof_is_proven_again_and_a_tampered_one_is_refused(name):
    res, spec = _pep(name, 2), _spec(name)
    proof = res.certificate["proof"]
    assert proof["proven"]
    ok, why = reprove_finite_sum(spec, None, 2, res.measure, res.initial, proof)
    assert ok, why
    low = copy.deepcopy(proof)
    low["tau_proven"] = str(Fraction(proof["tau_proven"]) * Fraction(999, 1000))
    assert not reprove_finite_sum(spec, None, 2, res.measure, res.initial, low)[0]
    bad = copy.deepcopy(proof)  # a convexity condition of f_0 (its values: they cancel)
    top = next(k for k in bad["multipliers_exact"] if k.startswith("f1:") and k.endswith("#0"))
    bad["multipliers_exact"][top] = str(Fraction(bad["multipliers_exact"][top]) / 2)
    assert not reprove_finite_sum(spec, None, 2, res.measure, res.initial, bad)[0]
    # the same multipliers do not prove the question on a larger set
    other = _spec(name, D="1")
    assert not reprove_finite_sum(other, None, 2, res.measure, res.initial, proof)[0]


# --------------------------------------------------------------------------- soundness
# Everything below is numpy only: the methods on explicit functions, C a ball of radius
# D/2 in R^2 (diameter D) or the interval [-D/2, D/2].
M, D = 1.0, 0.5
R = D / 2


def _proj(x):
    n = np.linalg.norm(x)
    return x if n <= R else x * (R / n)


def _lmo(d, x):
    n = np.linalg.norm(d)
    return x if n == 0 else -R * d / n  # a tie: any point of C (x here)


def _argmin_1d(phi, lo=-R, hi=R):
    """The minimizer of a convex function on [lo, hi]: a grid, then golden sections."""
    grid = np.linspace(lo, hi, 401)
    k = int(np.argmin([phi(t) for t in grid]))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, 400)]
    for _ in range(80):
        c, d = b - 0.618034 * (b - a), a + 0.618034 * (b - a)
        a, b = (a, d) if phi(c) <= phi(d) else (c, b)
    return (a + b) / 2


def _run(method, fs, x0, argmin=None):
    """The iterates of ``method`` on the functions ``fs`` ((value, subgradient) pairs)."""
    N = len(fs)
    x = _proj(x0)
    first, acc, xs = x.copy(), np.zeros_like(x), []
    for k, (_, sub) in enumerate(fs):
        xs.append(x)
        g = sub(x)
        acc = acc + g
        if method == "online-gradient-descent":
            x = _proj(x - D / (M * math.sqrt(N)) * g)
        elif method == "online-frank-wolfe":
            eta, sig = D / (2 * M) * (3 / N) ** 0.75, min(1.0, math.sqrt(3 / N))
            x = (1 - sig) * x + sig * _lmo(x - first + eta * acc, x)
        else:
            x = argmin(fs[:k + 1], first)
    return xs


def _regret(fs, xs, refs):
    """max over the reference points of sum_k f_k(x_k) - f_k(ref)."""
    paid = sum(f(x) for (f, _), x in zip(fs, xs, strict=True))
    return max(paid - sum(f(y) for f, _ in fs) for y in refs)


def _linear(c):
    return (lambda x: float(c @ x)), (lambda x: c)


def _absolute(a, b):
    return (lambda x: M * abs(float(a @ x) - b)), (lambda x: M * np.sign(float(a @ x) - b) * a)


def _ball_points(rng):
    t = rng.uniform(0, 2 * np.pi, 400)
    rad = R * np.sqrt(rng.uniform(0, 1, 400))
    return [np.array([u * np.cos(v), u * np.sin(v)]) for u, v in zip(rad, t, strict=True)] + \
        [R * np.array([np.cos(v), np.sin(v)]) for v in np.linspace(0, 2 * np.pi, 400)]


def _linear_leader(method, N):
    """FTL and FTRL on linear functions, in closed form: the leader of <S, x> over the
    ball, -R S/|S|, and the projection of x_0 - eta S."""
    def argmin(fs, first):
        S = sum(sub(first) for _, sub in fs)
        if method == "follow-the-leader":
            return _lmo(S, first)
        return _proj(first - D / (M * math.sqrt(N)) * S)
    return argmin


def _interval_leader(method, N):
    """FTL and FTRL on any functions of x in [-R, R] (R^1): the minimizer by search."""
    def argmin(fs, first):
        eta = D / (M * math.sqrt(N))
        reg = 0.0 if method == "follow-the-leader" else 1 / (2 * eta)
        t = _argmin_1d(lambda t: sum(f(np.array([t])) for f, _ in fs)
                       + reg * (t - first[0]) ** 2)
        return np.array([t])
    return argmin


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("steps", [2, 3])
def test_explicit_functions_never_exceed_the_proof(method, steps):
    proven = _proven(_pep(method, steps))
    rng = np.random.default_rng(steps)
    worst = 0.0
    refs2 = _ball_points(rng)
    refs1 = [np.array([t]) for t in np.linspace(-R, R, 801)]
    for _ in range(60):  # linear functions on the ball, |c| <= M
        cs = rng.standard_normal((steps, 2))
        cs *= M / np.maximum(np.linalg.norm(cs, axis=1), M)[:, None] * rng.uniform(0.2, 1)
        fs = [_linear(c) for c in cs]
        xs = _run(method, fs, rng.standard_normal(2) * R, _linear_leader(method, steps))
        S = cs.sum(axis=0)  # the best point of C against linear functions: -R S/|S|
        paid = sum(float(c @ x) for c, x in zip(cs, xs, strict=True))
        worst = max(worst, paid + R * float(np.linalg.norm(S)))
    for _ in range(40):  # absolute values M |<a, x> - b| on the interval
        fs = [_absolute(np.array([rng.choice([-1.0, 1.0])]), rng.uniform(-2 * R, 2 * R))
              for _ in range(steps)]
        xs = _run(method, fs, rng.uniform(-2 * R, 2 * R, 1), _interval_leader(method, steps))
        worst = max(worst, _regret(fs, xs, refs1))
    if method in ("online-gradient-descent", "online-frank-wolfe"):
        for _ in range(40):  # absolute values on the ball (subgradient steps only)
            fs = [_absolute(a / np.linalg.norm(a), rng.uniform(-R, R))
                  for a in rng.standard_normal((steps, 2))]
            xs = _run(method, fs, rng.standard_normal(2) * R)
            worst = max(worst, _regret(fs, xs, refs2))
    assert 0 < worst <= proven * (1 + 1e-9)


@pytest.mark.parametrize("method", ["online-gradient-descent", "follow-the-regularized-leader"])
def test_explicit_linear_functions_reach_the_proof(method):
    """Two linear functions on the ball chosen by a local search reach the proven
    bound M D sqrt(2) (so the bound is the worst case, not only above it)."""
    from scipy.optimize import minimize

    proven = _proven(_pep(method, 2))

    def regret(z):
        cs = z[:4].reshape(2, 2)
        cs = cs * (M / np.maximum(np.linalg.norm(cs, axis=1), M))[:, None]
        xs = _run(method, [_linear(c) for c in cs], z[4:], _linear_leader(method, 2))
        paid = sum(float(c @ x) for c, x in zip(cs, xs, strict=True))
        return paid + R * float(np.linalg.norm(cs.sum(axis=0)))

    rng = np.random.default_rng(0)
    best = max(-minimize(lambda z: -regret(z), rng.standard_normal(6), method="Nelder-Mead",
                         options={"maxiter": 3000, "xatol": 1e-10, "fatol": 1e-13}).fun
               for _ in range(6))
    assert proven * (1 - 1e-6) <= best <= proven * (1 + 1e-9)


# --------------------------------------------------------------------------- bad input
def _cli(args, tmp_path):
    r = CliRunner().invoke(cli, [*args, "--out", str(tmp_path / "o")])
    return r.exit_code, [ln for ln in r.output.strip().splitlines() if ln]


@pytest.mark.parametrize(("change", "field"), [
    (("M: M, per_step: true", "M: M, per_step: 2"), "functions.f.per_step"),
    (("M: M, per_step: true", "M: M, per_step: true, count: 3"), "functions.f.per_step"),
    (("{class: convex_lipschitz, M: M, per_step: true}",
      "{class: convex_qg, per_step: true}"), "functions.f.class"),
    (("reference: free", "reference: somewhere"), "finite_sum.reference"),
    (('start: ["x = prox(h, 1, x)"]', 'start: ["x[i] = prox(h, 1, x)"]'),
     "finite_sum.start[0]"),
    (('step: ["x = prox(h, gamma, x - gamma*grad(f[i], x))"]',
      'step: ["x = prox(h, gamma, x - gamma*sum(grad(f[i], x)))"]'), "finite_sum.step[0]"),
    (('step: ["x = prox(h, gamma, x - gamma*grad(f[i], x))"]',
      'step: ["x = lmo(f[i], x)"]'), "finite_sum.step[0]"),
    (('step: ["x = prox(h, gamma, x - gamma*grad(f[i], x))"]',
      'step: ["x = prox(h + f[:i+5], gamma, x)"]'), "finite_sum.step[0]"),
    (('measure: "sum(f[i](x) - f[i](xs))"', 'measure: "sum(sum(f[i](x)))"'), "measure"),
])
def test_bad_online_input_is_one_line(tmp_path, change, field):
    text = (SPECS / "online-gradient-descent.yaml").read_text()
    assert change[0] in text
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace(change[0], change[1], 1))
    code, lines = _cli(["pep", str(bad), "--steps", "2"], tmp_path)
    assert code == 2 and len(lines) == 1 and field in lines[0], lines
    assert not (tmp_path / "o").exists()


def test_a_free_reference_needs_one_function_per_step(tmp_path):
    text = (SPECS / "sgd.yaml").read_text().replace("finite_sum:\n",
                                                     "finite_sum:\n  reference: free\n")
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    code, lines = _cli(["pep", str(bad), "--kappa", "10", "--steps", "1"], tmp_path)
    assert code == 2 and len(lines) == 1 and "finite_sum.reference" in lines[0], lines


def test_a_horizon_beyond_the_limit_is_refused(tmp_path):
    code, lines = _cli(["pep", str(SPECS / "online-gradient-descent.yaml"), "--steps", "65"],
                       tmp_path)
    assert code == 2 and len(lines) == 1 and "--steps" in lines[0], lines
