"""Methods that change with k: the spec syntax (k, N, sequences, per-step schedules), its
errors, and the binding step by step (:mod:`sosalgo.steps`), checked against plain numpy
iterations of OGM, FISTA and gradient descent written here from the papers' formulas."""

from __future__ import annotations

import math
from pathlib import Path

import mpmath
import numpy as np
import pytest
import sympy as sp
from click.testing import CliRunner

from sosalgo.cli import cli
from sosalgo.errors import InputError
from sosalgo.spec import SpecError, load_spec, spec_from_text
from sosalgo.spec.overrides import apply_overrides
from sosalgo.steps import (
    ball_steps,
    exact_steps,
    float_steps,
    horizon,
    reference_values,
    sequence_values,
)

SPECS = Path(__file__).resolve().parents[1] / "specs"
VARYING = ("ogm", "fista", "gradient-schedule", "momentum-schedule", "silver", "heavy-ball-qg",
           "gradient-qg-decreasing", "accelerated-k", "halpern",
           "operator-accelerated-proximal-point", "ogm-k", "frank-wolfe",
           "inexact-proximal-point", "optimistic-gradient", "past-extragradient")
GD = """
name: t
functions:
  f: {class: smooth_strongly_convex}
parameters:
  h: {value: 1/L, range: [0, 3/L], per_step: true}
matrices: {A: [[1]], B: [[-h]], C: [[1]], E: [[1]]}
m: 0
L: 1
"""


def spec(name: str):
    return load_spec(SPECS / f"{name}.yaml")


# --------------------------------------------------------------------------- independent
def ogm_theta(N: int) -> list[float]:
    """Kim-Fessler's theta_0..theta_N (the last by the 8 theta^2 rule)."""
    th = [1.0]
    for i in range(N):
        c = 8 if i == N - 1 else 4
        th.append((1 + math.sqrt(1 + c * th[-1] ** 2)) / 2)
    return th


def ogm(grad, x0: np.ndarray, N: int, L: float = 1.0) -> np.ndarray:
    th = ogm_theta(N)
    x, y = x0.copy(), x0.copy()
    for i in range(N):
        y_new = x - grad(x) / L
        x = y_new + (th[i] - 1) / th[i + 1] * (y_new - y) + th[i] / th[i + 1] * (y_new - x)
        y = y_new
    return x


def fista(grad, prox, x0: np.ndarray, N: int, L: float = 1.0) -> np.ndarray:
    """PEPit's accelerated proximal gradient example (PEPit 0.5.1), loop for loop: lam =
    1; each step lam_old = lam, lam = (1 + sqrt(4 lam_old^2 + 1))/2, x_new = prox(y -
    grad/L), y = x_new + (lam_old - 1)/lam (x_new - x_old); x_N the last prox point."""
    lam, y, x_new = 1.0, x0.copy(), x0.copy()
    for _ in range(N):
        lam_old = lam
        lam = (1 + math.sqrt(4 * lam_old**2 + 1)) / 2
        x_old = x_new
        x_new = prox(y - grad(y) / L, 1 / L)
        y = x_new + (lam_old - 1) / lam * (x_new - x_old)
    return x_new


def gradient_descent(grad, x0: np.ndarray, steps: list[float]) -> np.ndarray:
    x = x0.copy()
    for h in steps:
        x = x - h * grad(x)
    return x


def run_bound(methods, oracles, x0: np.ndarray) -> np.ndarray:
    """Iterate the bound per-step systems (⊗ I_d) from xi_0 = u x0 and return the output:
    call i evaluates v_i = C_i xi + sum_{j<i} D_ij u_j, then a gradient (D_ii = 0) or a prox
    with t = -D_ii (y_i = prox_t(v_i), u_i = (v_i - y_i)/t)."""
    u0 = np.ones(methods[0].n)  # the shipped specs start at rest: xi_0 = (x0, ..., x0)
    xi = np.outer(u0, x0)
    for om in methods:
        ys, us = [], []
        for i in range(om.p):
            v = om.C[i] @ xi + sum(om.D[i, j] * us[j] for j in range(i))
            grad, prox = oracles[om.oracles[i]]
            t = -om.D[i, i]
            y = v if t == 0 else prox(v, t)
            us.append(grad(y) if t == 0 else (v - y) / t)
            ys.append(y)
        xi = om.A @ xi + om.B @ np.array(us)
    out = methods[-1]
    return ys[out.output] if out.output is not None else (out.E @ xi)[0]


def quadratic(d: int = 6, seed: int = 0, L: float = 1.0):
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((d, d)))
    H = Q @ np.diag(np.linspace(0, L, d)) @ Q.T
    return lambda x: H @ x


def huber(d: int = 6, seed: int = 1, delta: float = 0.3):
    """The gradient of sum_i huber_delta(a_i . x - b_i), 1-smooth (|A| = 1)."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((8, d))
    A /= np.linalg.norm(A, 2)
    b = rng.standard_normal(8)
    return lambda x: A.T @ np.clip(A @ x - b, -delta, delta)


def soft(v: np.ndarray, t: float, lam: float = 0.2) -> np.ndarray:
    return np.sign(v) * np.maximum(np.abs(v) - lam * t, 0.0)


# --------------------------------------------------------------------------- the five specs
@pytest.mark.parametrize("name", VARYING)
def test_shipped_varying_specs_load(name):
    s = spec(name)
    assert s.time_varying and s.sublinear and s.references


def test_time_invariant_specs_are_not_varying():
    for path in SPECS.glob("*.yaml"):
        if path.stem not in VARYING:
            assert not load_spec(path).time_varying, path


@pytest.mark.parametrize("N", [1, 2, 5, 12])
@pytest.mark.parametrize("grad", [quadratic(), huber()], ids=["quadratic", "huber"])
def test_ogm_iterates(N, grad):
    x0 = np.linspace(-1, 2, 6)
    got = run_bound(float_steps(spec("ogm"), None, N), [(grad, None)], x0)
    assert np.allclose(got, ogm(grad, x0, N), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("N", [1, 2, 6])
@pytest.mark.parametrize("grad", [quadratic(seed=2), huber(seed=3)], ids=["quadratic", "huber"])
def test_fista_iterates(N, grad):
    x0 = np.linspace(-2, 1, 6)
    oracles = [(grad, None), (None, soft)]
    got = run_bound(float_steps(spec("fista"), None, N), oracles, x0)
    assert np.allclose(got, fista(grad, soft, x0, N), rtol=1e-12, atol=1e-12)


def test_silver_and_schedules_iterates():
    grad, x0 = quadratic(seed=4), np.linspace(-1, 1, 6)
    r2 = math.sqrt(2)
    silver = [r2, 2, r2, 2 + r2, r2, 2, r2]  # 1 + rho^(nu(i) - 1), rho = 1 + sqrt(2)
    assert np.allclose(run_bound(float_steps(spec("silver"), None, 7), [(grad, None)], x0),
                       gradient_descent(grad, x0, silver), rtol=1e-12, atol=1e-12)
    hs = [0.5, 1.5, 2.5, 1.0]
    s = spec("gradient-schedule")
    for methods in (float_steps(s, None, 4, {"h": hs}),
                    float_steps(_set(s, "h", "[1/2, 1.5/L, 5/(2*L), 1]"), None, 4)):
        assert np.allclose(run_bound(methods, [(grad, None)], x0),
                           gradient_descent(grad, x0, hs), rtol=1e-12, atol=1e-12)
    assert np.allclose(run_bound(float_steps(s, None, 3), [(grad, None)], x0),
                       gradient_descent(grad, x0, [1, 1, 1]), rtol=1e-12, atol=1e-12)


def test_momentum_schedule_contains_ogm_and_nesterov():
    s, N = spec("momentum-schedule"), 6
    grad, x0 = huber(seed=5), np.linspace(0, 3, 6)
    th = ogm_theta(N)
    beta = [(th[i] - 1) / th[i + 1] for i in range(N)]
    gamma = [th[i] / th[i + 1] for i in range(N)]
    got = run_bound(float_steps(s, None, N, {"beta": beta, "gamma": gamma}), [(grad, None)], x0)
    assert np.allclose(got, ogm(grad, x0, N), rtol=1e-12, atol=1e-12)
    x, y = x0.copy(), x0.copy()  # the default: Nesterov's y+ + k/(k+3) (y+ - y)
    for i in range(N):
        y_new = x - grad(x)
        x, y = y_new + i / (i + 3) * (y_new - y), y_new
    assert np.allclose(run_bound(float_steps(s, None, N), [(grad, None)], x0), x, rtol=1e-12)


def test_references_and_sequences():
    for N in (1, 3, 20):
        th = ogm_theta(N)
        assert sequence_values(spec("ogm"), None, N)["theta"] == pytest.approx(th, rel=1e-14)
        ref = reference_values(spec("ogm"), None, N)
        assert list(ref.values()) == [pytest.approx(1 / (2 * th[N] ** 2), rel=1e-14)]
    assert list(reference_values(spec("gradient-schedule"), None, 5).values()) == \
        [pytest.approx(1 / 22)]


# --------------------------------------------------------------------------- exact and balls
@pytest.mark.parametrize("name,N", [("ogm", 4), ("fista", 3), ("silver", 7),
                                    ("gradient-schedule", 2)])
def test_exact_agrees_with_float(name, N):
    s = spec(name)
    ex, fl = exact_steps(s, None, N), float_steps(s, None, N)
    assert ex is not None and len(ex) == N
    for mats, om in zip(ex, fl, strict=True):
        for key, M in mats.items():
            got = np.array(M.evalf(30).tolist(), dtype=float)
            want = om.E if key == "E" else getattr(om, key)
            assert np.allclose(got, want, rtol=1e-12, atol=1e-12), (key, got, want)


def test_exact_gives_way_to_balls_when_closed_forms_grow():
    s = spec("ogm")
    assert exact_steps(s, None, 50) is None
    balls, fl = ball_steps(s, None, 50), float_steps(s, None, 50)
    for mats, om in zip(balls, fl, strict=True):
        for key, M in mats.items():
            want = getattr(om, key)
            for (i, j), b in np.ndenumerate(M):
                assert b.r < 1e-60
                assert abs(float(b.c) - want[i, j]) <= b.r + 1e-13 * (1 + abs(want[i, j]))


def test_balls_hold_the_exact_values():
    """At N = 4 every ball holds the exact (sympy) entry, evaluated at 80 digits."""
    s = spec("ogm")
    ex, balls = exact_steps(s, None, 4), ball_steps(s, None, 4)
    assert ex is not None
    mpmath.mp.dps = 80
    for mats, bmats in zip(ex, balls, strict=True):
        for key, M in mats.items():
            for (i, j), b in np.ndenumerate(bmats[key]):
                v = mpmath.mpf(sp.N(M[i, j], 80))
                lo = mpmath.mpf(b.lo.numerator) / b.lo.denominator
                hi = mpmath.mpf(b.hi.numerator) / b.hi.denominator
                assert lo <= v <= hi, (key, i, j)
    mpmath.mp.dps = 15


# --------------------------------------------------------------------------- errors
def _set(s, name: str, expr: str):
    return spec_from_text(apply_overrides((SPECS / f"{s.name}.yaml").read_text(), {name: expr},
                                          s.source), s.source)


def _load_error(text: str) -> SpecError:
    with pytest.raises(SpecError) as err:
        spec_from_text(text, "t.yaml")
    return err.value


def test_sequence_dividing_by_zero_names_k():
    text = GD.replace("parameters:", "sequences:\n  s: {first: 1, next: 1/(k - 2)}\n"
                      "parameters:").replace("[[-h]]", "[[-h*s]]")
    err = _load_error(text)
    assert str(err).startswith("t.yaml: sequences.s.next:") and "at k=2" in str(err)


@pytest.mark.parametrize("snippet,field,words", [
    ("  h: {value: 1/L, per_step: 3}", "parameters.h.per_step", "true or false"),
    ("  h: [1/L, 1/L]\n  g: [1/L]", "parameters.g", "1 values, but parameters.h has 2"),
    ("  h: theta[k+2]", "parameters.h", "write theta[k] or theta[k+1]"),
    ("  h: {value: 'h2[k]'}", "parameters.h.value", "only a sequence can be indexed"),
    ("  h: {value: 1/L}\n  theta_next: 1", "parameters.theta_next", "a sequence has"),
    ("  h: {value: [1/L, 4/L], range: [0, 3/L]}", "parameters.h.value",
     "4 is outside its range [0, 3] at k=1"),
])
def test_errors_name_file_and_field(snippet, field, words):
    text = GD.replace("  h: {value: 1/L, range: [0, 3/L], per_step: true}", snippet)
    text = text.replace("parameters:", "sequences:\n  theta: {first: 1, next: theta + 1}\n"
                        "parameters:")
    err = _load_error(text)
    assert err.field == field and words in err.message and "\n" not in str(err)


def test_sequence_fields_are_checked():
    base = GD.replace("parameters:", "sequences:\n  s: {first: 1, nxt: 2}\nparameters:")
    assert _load_error(base).field == "sequences.s.nxt"
    assert _load_error(base.replace("nxt: 2", "last: 2")).field == "sequences.s.next"
    err = _load_error(base.replace("s: {first: 1, nxt: 2}", "k: {first: 1, next: 2}"))
    assert err.field == "sequences.k" and "reserved" in err.message


def test_schedule_length_must_match_the_horizon():
    s = spec("silver")
    assert horizon(s, None) == 7 and horizon(s, 7) == 7
    with pytest.raises(SpecError) as err:
        float_steps(s, None, 3)
    assert err.value.field == "parameters.h"
    assert "7 values" in err.value.message and "N = 3" in err.value.message
    with pytest.raises(SpecError, match="--steps"):
        horizon(spec("ogm"), None)
    with pytest.raises(SpecError, match="2 values given for a horizon of N = 3"):
        float_steps(spec("gradient-schedule"), None, 3, {"h": [1, 1]})


def test_fixed_point_must_not_change_with_k():
    err = _load_error(GD.replace("E: [[1]]", "E: [[1 + k]]"))
    assert err.field == "matrices" and "k=1" in err.message


def test_set_a_schedule():
    s = _set(spec("gradient-schedule"), "h", "[1.5/L, 2/L]")
    assert s.parameters["h"].schedule is not None and horizon(s, None) == 2
    with pytest.raises(InputError, match="--set h"):
        _set(spec("gradient-schedule"), "h", "[1/L, q]")
    plain = _set(spec("silver"), "h", "1/L")  # one value for every step (a tie)
    assert plain.parameters["h"].is_tied and horizon(plain, 3) == 3


@pytest.mark.parametrize("args", [
    ["analyze", "ogm.yaml"], ["design", "momentum-schedule.yaml"],
    ["grid", "gradient-schedule.yaml"], ["lmi", "silver.yaml"], ["pareto", "fista.yaml"],
    ["analyze", "nesterov.yaml", "--kappa", "10", "--set", "h=k/L"],
])
def test_other_commands_refuse_in_one_line(args, tmp_path):
    path = str(SPECS / args[1])
    out = [] if args[0] == "lmi" else ["--out", str(tmp_path / "o")]
    res = CliRunner().invoke(cli, [args[0], path, *args[2:], *out])
    lines = [ln for ln in res.output.strip().splitlines() if ln]
    assert res.exit_code == 2, res.output
    assert len(lines) == 1 and f"varies with k: use `sosalgo pep {path} --steps N`" in lines[0]
    assert not (tmp_path / "o").exists()
