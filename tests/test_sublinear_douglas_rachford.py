"""O(1/k) state-change constants of Douglas-Rachford on two maximally monotone operators
(m: 0, several operators): the sublinear family bounds |w_{k+1} - w_k|^2 <= c |w_0 - w*|^2
/ k from any start w_0 (w* = x* + alpha s_B*, a fixed point that moves with the optimal
answers), against closed forms (Lieder's tight Krasnosel'skii-Mann worst cases, which
Douglas-Rachford reaches: T = (1 - theta/2) I + theta/2 R_A R_B, and any nonexpansive map
is R_A R_B with B = 0), against ``sosalgo pep`` at N = 1..5, against DR run in numpy on
random monotone affine operators and projections, and proven exactly."""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.spec import spec_from_text
from sosalgo.spec.overrides import apply_overrides

SPEC = Path(__file__).resolve().parent.parent / "specs" / "douglas-rachford-monotone.yaml"
HORIZON = range(1, 400)


def _spec(**values: str):
    return spec_from_text(apply_overrides(SPEC.read_text(), values, str(SPEC)), str(SPEC))


def _worst_step(k: int, theta: float) -> float:
    """Tight worst |w_{k+1} - w_k|^2 / |w_0 - w*|^2: w+ = w - gamma (w - N w), gamma =
    theta/2, N = R_A R_B nonexpansive; Lieder (2018), Thm. 4.9, for |w_k - N w_k|^2,
    times gamma^2. At theta = 1: ((N - 1)/N)^(N - 1)/N with N = k + 1 steps."""
    g = theta / 2
    if g <= 0.5 * (1 + math.sqrt(k / (k + 1))):
        return g * g * (k / (k + 1)) ** k / ((k + 1) * g * (1 - g))
    return g * g * 4 * (2 * g - 1) ** (2 * k)


def _constant(spec, theta=None):
    from sosalgo.analysis import analyze_sublinear
    from sosalgo.certificates.exact_sublinear import verify_exact_sublinear

    res = analyze_sublinear(spec, theta)
    assert res.certified and res.measure == "state_change"
    proof = verify_exact_sublinear(spec, json.loads(json.dumps(res.to_dict())), theta)
    assert proof.ok, proof.reason
    assert proof.to_dict()["statement"].startswith("|xi_k+1 - xi_k|^2 <= C |xi_0 - xi*|^2")
    return res.constant, float(Fraction(proof.constant_proven))


@pytest.mark.parametrize("alpha, theta", [("1", "1"), ("2", "1"), ("1/2", "1"),
                                          ("1", "1/2"), ("1", "3/2")])
def test_constant_between_closed_forms(alpha, theta):
    """c >= sup_k k * (the tight worst case at k) (else a worst case breaks the bound) and
    c <= theta/(2 - theta) (the elementary potential: |w_{k+1} - w*|^2 <= |w_k - w*|^2 -
    (2 - theta)/theta |w_{k+1} - w_k|^2 and the steps nonincreasing); c does not depend on
    alpha (DR with alpha on A, B is DR with 1 on alpha A, alpha B)."""
    t = float(Fraction(theta))
    c, proven = _constant(_spec(alpha=alpha, theta=theta))
    floor = max(k * _worst_step(k, t) for k in HORIZON)
    for value in (c, proven):
        assert value >= floor * (1 - 1e-12)
        assert value <= t / (2 - t) * (1 + 1e-5)
    assert proven >= c * (1 - 1e-9)


def test_constant_never_below_pep():
    """``sosalgo pep`` (|w_N - w_{N-1}|^2 from a free start |w_0 - w*|^2 <= 1) at
    N = 1..5 proves the closed form ((N - 1)/N)^(N - 1)/N (computed here), and the
    certified c bounds it: |w_N - w_{N-1}|^2 <= c / (N - 1) for N >= 2 (k = N - 1)."""
    spec = _spec()
    c, proven = _constant(spec)
    for N in range(1, 6):
        closed = ((N - 1) / N) ** (N - 1) / N
        tau = float(Fraction(sosalgo.pep(spec, None, N).certificate["tau_proven"]))
        assert tau == pytest.approx(closed, rel=1e-6) and tau >= closed * (1 - 1e-9)
        if N >= 2:
            assert min(c, proven) / (N - 1) >= tau


def _affine_monotone(rng, d: int, x_star: np.ndarray, s: np.ndarray):
    """The resolvent of A x = M (x - x*) - s, M = S S' + K - K' (monotone), A x* = -s."""
    S, K = rng.standard_normal((d, d)), rng.standard_normal((d, d))
    M = S @ S.T * rng.uniform(0, 2) + (K - K.T) * rng.uniform(0, 3)

    def resolvent(v: np.ndarray, alpha: float) -> np.ndarray:
        return np.linalg.solve(np.eye(d) + alpha * M, v + alpha * (M @ x_star + s))
    return resolvent


def _problem(rng, d: int, kind: str):
    """(J_B, J_A, x*, s): B at x* has s, A has -s, both maximally monotone."""
    x_star = rng.standard_normal(d)
    if kind == "box":  # B = the normal cone of [-1, 1]^d, x* on its boundary
        x_star = np.clip(x_star, -1, 1)
        x_star[0] = 1.0
        s = np.zeros(d)
        s[0] = rng.uniform(0.1, 3)

        def JB(v: np.ndarray, alpha: float) -> np.ndarray:
            return np.clip(v, -1, 1)
    elif kind == "subspace":  # B = the normal cone of x* + V, s in V^perp
        Q = np.linalg.qr(rng.standard_normal((d, d)))[0]
        V, W = Q[:, : d // 2], Q[:, d // 2:]
        s = W @ rng.standard_normal(W.shape[1])

        def JB(v: np.ndarray, alpha: float) -> np.ndarray:
            return x_star + V @ (V.T @ (v - x_star))
    elif kind == "rotation":  # B = s (constant), A a rotation generator: near-worst cases
        s = rng.standard_normal(d)
        G = np.zeros((d, d))
        G[0, 1], G[1, 0] = -1.0, 1.0
        M = G * 10.0 ** rng.uniform(-2, 1)

        def JB(v: np.ndarray, alpha: float) -> np.ndarray:
            return v - alpha * s

        def JA(v: np.ndarray, alpha: float) -> np.ndarray:  # A x = M (x - x*) - s
            return np.linalg.solve(np.eye(d) + alpha * M, v + alpha * (M @ x_star + s))
        return JB, JA, x_star, s
    else:  # B affine monotone too
        s = rng.standard_normal(d) * 3
        JB = _affine_monotone(rng, d, x_star, -s)  # B x* = s
    return JB, _affine_monotone(rng, d, x_star, s), x_star, s


@pytest.mark.parametrize("kind", ["affine", "subspace", "box", "rotation"])
def test_soundness_on_random_operators(kind):
    """DR run in numpy on random maximally monotone pairs (affine monotone maps, normal
    cones of subspaces and boxes, a constant B with a rotation generator A; the solution's
    answers s, -s nonzero, so w* = x* + alpha s moves with them), from random starts:
    k |w_{k+1} - w_k|^2 / |w_0 - w*|^2 <= c for k = 1..150, c the proven constant; w* is
    checked to be a fixed point first."""
    alpha, theta = 1.3, 1.0
    c, proven = _constant(_spec(alpha="13/10"))
    bound = min(c, proven)
    rng = np.random.default_rng(7)
    worst = 0.0
    for trial in range(30):
        d = 2 + trial % 5
        JB, JA, x_star, s = _problem(rng, d, kind)

        def step(w: np.ndarray, JB=JB, JA=JA) -> np.ndarray:
            x = JB(w, alpha)
            return w - theta * (x - JA(2 * x - w, alpha))

        w_star = x_star + alpha * s
        assert np.allclose(step(w_star), w_star, atol=1e-9)
        w = w_star + rng.standard_normal(d) * 10.0 ** rng.uniform(-2, 2)
        r0 = float(np.sum((w - w_star) ** 2))
        w = step(w)  # w_1
        for k in range(1, 151):
            nxt = step(w)
            worst = max(worst, k * float(np.sum((nxt - w) ** 2)) / r0)
            w = nxt
    assert 0 < worst <= bound * (1 + 1e-9)
    if kind == "rotation":  # slow rotations nearly reach the tight worst case: a sharp check
        assert worst >= 0.9 * max(k * _worst_step(k, theta) for k in range(1, 151))


def test_analyze_cli_verifies_the_state_change_constant(tmp_path):
    """``analyze --verify --json`` on the shipped spec: exit 0, the measure is the state
    change, proven exactly; ``verify`` backs it and contradicts a constant below the
    tight worst case's floor; the legend says what c bounds."""
    args = ["analyze", str(SPEC), "--verify", "--json", "--out", str(tmp_path),
            "--no-plot", "--quiet", "--workers", "1"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    row = json.loads(r.stdout)["rows"][0]
    assert row["measure"] == "state_change" and row["verified"] == "exact"
    assert row["constant"] <= 1 + 1e-5
    doc = tmp_path / "dr.json"
    doc.write_text(r.stdout)
    v = CliRunner().invoke(cli, ["verify", str(doc)])
    assert v.exit_code == 0 and "0 contradicted" in v.output, v.output
    false = json.loads(r.stdout)
    false["rows"][0]["constant"] = 0.3  # below max_k k ((k/(k + 1))^k/(k + 1)) (about 0.36)
    assert 0.3 < max(k * _worst_step(k, 1.0) for k in HORIZON)
    doc.write_text(json.dumps(false))
    v = CliRunner().invoke(cli, ["verify", str(doc)])
    assert v.exit_code == 3, v.output
    r = CliRunner().invoke(cli, ["analyze", str(SPEC), "--out", str(tmp_path / "t"),
                                 "--no-plot"])
    assert r.exit_code == 0, r.output
    assert "c bounds: |xi_k+1 - xi_k|^2 <= c |xi_0 - xi*|^2 / k" in r.output
