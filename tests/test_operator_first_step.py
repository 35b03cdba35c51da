"""Variational inequalities with a start step unlike the others (F + indicator of C):
optimistic gradient and past extragradient (PEPit's examples: the start projects x_0 and
evaluates F there) and Korpelevich's extragradient, against PEPit and against the methods
run on explicit monotone Lipschitz operators and boxes."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import sosalgo
from sosalgo.spec import spec_from_text
from sosalgo.spec.overrides import apply_overrides

SPECS = Path(__file__).resolve().parent.parent / "specs"

# PEPit 0.5.1, cvxpy's Clarabel (wrapper="cvxpy", solver="CLARABEL", verbose=-1), L = 1:
#   wc_optimistic_gradient(n, gamma, L), wc_past_extragradient(n, gamma, L)
#   (examples/monotone_inclusions_variational_inequalities); extragradient: the PEPit
#   program of bench/extragradient_pepit.py. Keys: (spec, gamma, PEPit's n).
PEPIT = {
    ("optimistic-gradient", "1/4", 1): 1.062499843113375,
    ("optimistic-gradient", "1/4", 2): 0.3332679677058236,
    ("past-extragradient", "1/4", 5): 0.06026637706247196,
    ("past-extragradient", "1/4", 2): 0.2803783973657615,
    ("extragradient", "1/4", 1): 1.0041479711912298,
    # optima of high degree: proven from a centered certificate (sosalgo.worstcase.centered)
    ("optimistic-gradient", "1/4", 5): 0.06631415077628079,
    ("extragradient", "1/4", 2): 0.28037532145806765,
}
PEPIT_ACCURACY = 1e-7  # Clarabel's relative accuracy (as in tests/test_operators.py)


def _spec(name: str, gamma: str):
    path = SPECS / f"{name}.yaml"
    return spec_from_text(apply_overrides(path.read_text(), {"gamma": gamma}, str(path)),
                          str(path))


def _steps(name: str, n: int) -> int:
    """sosalgo's horizon for PEPit's n: the start is step k = 0 of the two specs that
    have one (extragradient has none)."""
    return n if name == "extragradient" else n + 1


@pytest.mark.parametrize("key", sorted(PEPIT))
def test_proven_against_pepit(key):
    name, gamma, n = key
    res = sosalgo.pep(_spec(name, gamma), None, _steps(name, n))
    assert res.status == "solved" and res.certificate["check_kind"].startswith("exact")
    proven = float(Fraction(res.certificate["tau_proven"]))
    assert proven >= PEPIT[key] * (1 - PEPIT_ACCURACY)
    assert proven == pytest.approx(PEPIT[key], rel=1e-6)


def _instance(rng: np.random.Generator):
    """A box C = [-1, 1]^d, a solution x* on its boundary and F(x) = M (x - x*) + F*,
    M monotone with |M| <= 1 (F monotone, 1-Lipschitz), -F* a normal vector of C at x*:
    x* solves the variational inequality."""
    d = int(rng.integers(2, 5))
    S = rng.standard_normal((d, d))
    P = rng.standard_normal((d, d))
    M = (S - S.T) + rng.uniform(0, 1) * P @ P.T
    M /= np.linalg.norm(M, 2)
    xs = rng.uniform(-1, 1, d)
    face = rng.integers(0, d)
    xs[face] = rng.choice([-1.0, 1.0])
    Fs = np.zeros(d)
    Fs[face] = -xs[face] * rng.uniform(0, 3)  # -F* points out of C at x*
    return (lambda x: M @ (x - xs) + Fs), (lambda v: np.clip(v, -1, 1)), xs, d


def _run(name: str, gamma: float, n: int, rng: np.random.Generator) -> float:
    F, P, xs, d = _instance(rng)
    x0 = xs + rng.standard_normal(d) * rng.uniform(0.1, 3)
    x = P(x0)
    if name == "optimistic-gradient":
        xt, V = x, F(x)
        for _ in range(n):
            prev = xt
            xt = P(x - gamma * V)
            V, Vp = F(xt), V
            x = xt + gamma * (Vp - V)
        last = xt
    elif name == "past-extragradient":
        V = F(x)
        for _ in range(n):
            xt = P(x - gamma * V)
            V = F(xt)
            prev, x = x, P(x - gamma * V)
        last = x
    else:
        for _ in range(n):
            xt = P(x - gamma * F(x))
            prev, x = x, P(x - gamma * F(xt))
        last = x
    return float(np.sum((last - prev) ** 2) / np.sum((x0 - xs) ** 2))


@pytest.mark.parametrize("key", sorted(PEPIT))
def test_explicit_instances_stay_below_the_proven_bound(key):
    name, gamma, n = key
    res = sosalgo.pep(_spec(name, gamma), None, _steps(name, n), witness=False)
    proven = float(Fraction(res.certificate["tau_proven"]))
    rng = np.random.default_rng(3)
    worst = max(_run(name, float(Fraction(gamma)), n, rng) for _ in range(300))
    assert 0 < worst <= proven * (1 + 1e-9)


def test_the_start_step_is_a_projection_and_an_evaluation():
    """Step k = 0 of optimistic gradient: y = x_0 (the normal vector's point, no step),
    x_1 = x_0 and V_1 = F(x_0); later steps: y = x - gamma V - gamma u1."""
    from sosalgo.steps import float_steps

    oms = float_steps(_spec("optimistic-gradient", "1/4"), None, 3)
    assert np.allclose(oms[0].C, [[1, 0, 0], [1, 0, 0]]) and np.allclose(oms[0].D, 0)
    assert np.allclose(oms[1].C, [[1, -0.25, 0], [1, -0.25, 0]])
    assert np.allclose(oms[1].D, [[-0.25, 0], [-0.25, 0]])
    assert np.allclose(oms[0].B[0], 0) and np.allclose(oms[1].B[0], [-0.25, -0.25])


def test_witness_lower_bound_reaches_pepit_value():
    """The start calls the indicator twice at x_0 (two normal vectors): their pair's
    inequalities hold with equality, so the witness search asks no slack of them, and
    its verified lower bound comes within 1e-4 of PEPit's value (never above it)."""
    key = ("past-extragradient", "1/4", 2)
    res = sosalgo.pep(_spec(*key[:2]), None, _steps(key[0], key[2]))
    check = res.witness["check"]
    assert check["verified"]
    low = float(Fraction(check["tau_lower"]))
    assert PEPIT[key] * (1 - 1e-4) <= low <= PEPIT[key] * (1 + PEPIT_ACCURACY)
