"""Epsilon-subgradient calls (``oracles: [{function: f, epsilon: eps}]``) and constraints
with constant terms (``pep.constraints: ["grad(x_k) <= M**2"]``): PEPit's
``epsilon_subgradient_method`` (``specs/epsilon-subgradient.yaml``) against PEPit's
values and Millan and Machado's bound; the proven bound against runs of the method built
here in numpy (explicit eps-subgradient oracles on M-Lipschitz convex functions); the
certificate re-proven by verify and a tampered one refused; bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "specs" / "epsilon-subgradient.yaml"
# PEPit 0.5.1 (Clarabel), unconstrained_convex_minimization/epsilon_subgradient_method at
# its three argument sets of the conformance suite: (M, n, gamma, eps, R) -> tau
PEPIT = {(2, 6, 0.3779644730092272, 0.1, 1): 1.019156384500334,
         (2, 3, 0.5, 0.1, 1): 1.2938330123118076,
         (1, 4, 0.4472135954999579, 0.2, 1): 0.6018655418048526}
FAST = (2, 3, 0.5, 0.1, 1)


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def theory(M, n, gamma, eps, R):
    """Millan and Machado (2019), Lemma 2: an upper bound."""
    return (R ** 2 + 2 * (n + 1) * gamma * eps + (n + 1) * gamma ** 2 * M ** 2) / (
        2 * (n + 1) * gamma)


def pep_doc(out, M, n, gamma, eps, R, spec=SPEC):
    res = run(["pep", spec, "--steps", n, "--set", f"M={M}", "--set", f"gamma={gamma!r}",
               "--set", f"eps={eps}", "--set", f"R={R}", "--out", out, "--json",
               "--no-plot"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


@pytest.fixture(scope="module")
def fast_doc(tmp_path_factory):
    out = tmp_path_factory.mktemp("eps")
    return out, pep_doc(out, *FAST)


def _check(doc, key):
    proof = doc["certificate"]["proof"]
    assert proof["proven"], proof
    proven = proof["tau_proven_float"]
    assert abs(doc["tau"] / PEPIT[key] - 1) <= 1e-6
    assert proven >= PEPIT[key] * (1 - 1e-8)  # PEPit's solver accuracy
    assert proven <= PEPIT[key] * (1 + 1e-6)
    assert proven <= theory(*key)
    assert doc["witness"] is None and "epsilon" in doc["note"]


def test_agrees_with_pepit_proven(fast_doc):
    _check(fast_doc[1], FAST)
    labels = fast_doc[1]["certificate"]["proof"]["multipliers_exact"]
    assert any(k.startswith("epsilon:") for k in labels)
    assert any(k.startswith("constraint[0]k") for k in labels)


@pytest.mark.deep
@pytest.mark.parametrize("key", [k for k in PEPIT if k != FAST])
def test_agrees_with_pepit_proven_other_sets(tmp_path, key):
    _check(pep_doc(tmp_path, *key), key)


def _claims(path, out):
    res = run(["verify", path, "--out", out, "--json"])
    claims = json.loads(res.stdout)["results"][0]["claims"]
    return next(c["status"] for c in claims if c["field"].endswith("certificate.tau_proven"))


def test_verify_reproves_and_refuses_tampering(fast_doc, tmp_path):
    out, _ = fast_doc
    path = next(out.glob("epsilon-subgradient-pep-N3.json"))
    assert _claims(path, tmp_path / "v") == "backed"
    doc = json.loads(path.read_text())
    proof = doc["certificate"]["proof"]
    for key in [k for k in proof["multipliers_exact"] if k.startswith("epsilon:")]:
        proof["multipliers_exact"][key] = "0"  # no eps-subgradient rows: not a proof
    bad = tmp_path / "no-eps.json"
    bad.write_text(json.dumps(doc))
    assert _claims(bad, tmp_path / "v2") != "backed"
    doc = json.loads(path.read_text())  # the bound without the constants' share
    from fractions import Fraction

    cert = doc["certificate"]
    low_q = Fraction(cert["proof"]["tau_proven"]) * Fraction(9, 10)
    cert["tau_proven"] = (str(low_q) if isinstance(cert["tau_proven"], str)
                          else float(low_q))
    cert["proof"]["tau_proven"] = str(low_q)
    low = tmp_path / "low.json"
    low.write_text(json.dumps(doc))
    assert _claims(low, tmp_path / "v3") != "backed"


# -- soundness: runs of the method on explicit functions (numpy only) ---------------------

def _huber(M, delta):
    """f(x) = M (|x| - delta/2) outside the ball of radius delta, M |x|^2/(2 delta) inside:
    convex, M-Lipschitz, minimum 0 at 0."""
    def f(x):
        r = np.linalg.norm(x)
        return M * (r - delta / 2) if r > delta else M * r * r / (2 * delta)

    def grad(x):
        r = np.linalg.norm(x)
        return M * x / r if r > delta else M * x / delta
    return f, grad


def _maxaffine(M, rng, d):
    """f(x) = max_i <a_i, x> - min over the a_i's cone: pieces |a_i| <= M through 0 whose
    convex hull holds 0 (minimum 0 at 0)."""
    A = rng.normal(size=(d + 2, d))
    A -= A.mean(axis=0)  # 0 in the convex hull: f >= 0 = f(0)
    A *= M / np.linalg.norm(A, axis=1).max()

    def f(x):
        return float(np.max(A @ x))

    def grad(x):
        return A[int(np.argmax(A @ x))]
    return f, grad


def _eps_subgradient(f, grad, x, eps, rng, M, pick):
    """An eps-subgradient at x: the gradient g at a point z with f(x) - f(z) - <g, x - z>
    <= eps (then f(y) >= f(z) + <g, y - z> >= f(x) + <g, y - x> - eps for every y), chosen
    among random z near x by ``pick`` (the one the adversary likes best)."""
    best, cands = grad(x), [grad(x)]
    for _ in range(40):
        z = x + rng.normal(size=x.shape) * rng.uniform(0, 3)
        g = grad(z)
        if f(x) - f(z) - g @ (x - z) <= eps * (1 - 1e-12) and np.linalg.norm(g) <= M:
            cands.append(g)
    best = max(cands, key=pick)
    return best


@pytest.mark.parametrize("seed", range(6))
def test_runs_stay_below_the_proven_bound(fast_doc, seed):
    M, n, gamma, eps, R = FAST
    proven = fast_doc[1]["certificate"]["proof"]["tau_proven_float"]
    rng = np.random.default_rng(seed)
    worst = 0.0
    for trial in range(30):
        d = int(rng.integers(1, 4))
        f, grad = (_huber(M, rng.uniform(0.05, 1.0)) if trial % 2 else
                   _maxaffine(M, rng, d))
        x = rng.normal(size=d)
        x *= R / np.linalg.norm(x)  # |x_0 - x*| = R
        vals = [f(x)]
        for _ in range(n):
            g = _eps_subgradient(f, grad, x, eps, rng, M,
                                 lambda g, x=x, f=f: f(x - gamma * g))  # worst next value
            x = x - gamma * g
            vals.append(f(x))
        worst = max(worst, min(vals))
        assert min(vals) <= proven * (1 + 1e-12), (trial, vals)
    assert worst > 0.3 * proven  # the runs are not trivial


def test_one_dimensional_adversary(fast_doc):
    """f = M|x|: at x > 0 the eps-subgradients are [max(-M, M - eps/x), M]; the adversary
    takes the smallest (the shortest step toward 0, or a step away)."""
    M, n, gamma, eps, R = FAST
    proven = fast_doc[1]["certificate"]["proof"]["tau_proven_float"]
    x, vals = R, [M * R]
    for _ in range(n):
        g = max(-M, M - eps / abs(x)) * math.copysign(1, x) if x else M
        x = x - gamma * g
        vals.append(M * abs(x))
    assert min(vals) <= proven


# -- bad input --------------------------------------------------------------------------

def _bad(tmp_path, old, new, cmd="pep"):
    text = SPEC.read_text()
    assert old in text
    path = tmp_path / "bad.yaml"
    path.write_text(text.replace(old, new))
    args = [cmd, path, "--out", tmp_path / "o"] + (["--steps", 2] if cmd == "pep" else [])
    return run(args)


@pytest.mark.parametrize("old,new,field", [
    ("f: {class: convex}", "f: {class: monotone}", "oracles[0].epsilon"),
    ("{function: f, epsilon: eps}", "{function: f, epsilon: eps, relative_error: 0.1}",
     "oracles[0].epsilon"),
    ("eps: {value: 1/10}", "eps: {value: -1/10}", "oracles[0].epsilon"),
    ("    - grad(x_k) <= M**2", "    - grad(x_k) >= M**2", "pep.constraints[0]"),
    ("    - grad(x_k) <= M**2", "    - grad(x_k) == M**2", "pep.constraints[0]"),
    ("  measure: minf", "  measure: f(x_k)", "pep.measure"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, old, new, field):
    res = _bad(tmp_path, old, new)
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and field in lines[0] and "bad.yaml" in lines[0], res.output
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_analyze_refuses_an_epsilon_call():
    res = run(["analyze", SPEC, "--out", "/tmp/never-written"])
    assert res.exit_code == 2
    assert "oracles[0].epsilon" in res.output and len(res.output.strip().splitlines()) == 1
