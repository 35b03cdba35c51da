"""Exact line search (``line_search: gamma``): the PEP of ``specs/gradient-line-search.yaml``
and ``specs/inexact-gradient-line-search.yaml`` against PEPit's peer values and the closed
forms of de Klerk, Glineur and Taylor, the proven bound against runs simulated here with a
line search of their own (numpy bisection on the derivative along the line), the witness
check against tampered steps, and bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"

# PEPit 0.5.1 (wrapper="cvxpy", solver="CLARABEL", verbose=-1), mu = m = 1/10 and
# L = kappa m in our specs:
# examples/unconstrained_convex_minimization/gradient_exact_line_search.py:
#   wc_gradient_exact_line_search(L, mu, n)[0]
# .../inexact_gradient_exact_line_search.py:
#   wc_inexact_gradient_exact_line_search(L, mu, epsilon, n)[0]
PEPIT = {  # (spec, kappa, epsilon or None, n): PEPit's value
    ("gradient-line-search", 10, None, 2): 0.4481251003098312,  # L=1, mu=.1, n=2 (example)
    ("gradient-line-search", 10, None, 4): 0.20081610459923138,  # L=1, mu=.1, n=4
    ("gradient-line-search", 5, None, 3): 0.08779144865683507,  # L=.5, mu=.1, n=3
    ("inexact-gradient-line-search", 10, "1/10", 2): 0.518916622009384,  # the example's
    ("inexact-gradient-line-search", 10, "3/10", 3): 0.5237297348721299,
    ("inexact-gradient-line-search", 5, "1/5", 2): 0.3419618885866679,
}


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def frac(text: str | None) -> float:
    if text is None:
        return 0.0
    a, _, b = text.partition("/")
    return int(a) / int(b or 1)


def closed_form(kappa: float, eps: float, n: int, mu: float = 0.1) -> float:
    """((L_eps - mu_eps)/(L_eps + mu_eps))^(2n) (eps = 0: ((L - mu)/(L + mu))^(2n))."""
    L = kappa * mu
    le, me = (1 + eps) * L, (1 - eps) * mu
    return ((le - me) / (le + me)) ** (2 * n)


@pytest.fixture(scope="module")
def docs(tmp_path_factory):
    out = {}
    for key in PEPIT:
        spec, kappa, eps, n = key
        args = ["pep", SPECS / f"{spec}.yaml", "--kappa", kappa, "--steps", n, "--json",
                "--no-plot", "--out", tmp_path_factory.mktemp("ls")]
        res = run(args + ([] if eps is None else ["--set", f"epsilon={eps}"]))
        assert res.exit_code == 0, res.output
        out[key] = json.loads(res.stdout)
    return out


@pytest.mark.parametrize("key", list(PEPIT))
def test_agrees_with_pepit_and_the_closed_form(docs, key):
    _, kappa, eps, n = key
    doc = docs[key]
    proof = doc["certificate"]["proof"]
    assert proof["proven"], proof
    proven = proof["tau_proven_float"]
    theory = closed_form(kappa, frac(eps), n)
    assert proven >= PEPIT[key] * (1 - 1e-7)
    assert proven >= theory * (1 - 1e-9)
    assert proven <= theory * (1 + 1e-5)
    check = doc["witness"]["check"]
    assert check["verified"], check
    assert theory * (1 - 1e-3) <= check["tau_lower_float"] <= proven


def line_min(f_line, hi: float = 1.0) -> float:
    """argmin_t >= 0 of a convex f_line(t) (its derivative's root by bisection)."""
    def slope(t):
        return (f_line(t + 1e-9) - f_line(t - 1e-9)) / 2e-9

    while slope(hi) < 0:
        hi *= 2
    lo = 0.0
    for _ in range(100):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if slope(mid) < 0 else (lo, mid)
    return (lo + hi) / 2


def simulated_ratio(f, grad, x0, n, eps, rng) -> float:
    """f(x_n)/f(x_0) (f* = 0) with exact line search along answers d within eps |g| of
    g (chosen greedily among (1 +- eps) g and random points of the error sphere)."""
    x = x0.copy()
    for _ in range(n):
        g = grad(x)
        cands = [g] if not eps else [(1 + eps) * g, (1 - eps) * g] + [
            g + eps * np.linalg.norm(g) * e / np.linalg.norm(e)
            for e in rng.standard_normal((30, len(g)))]
        nxt = [x - line_min(lambda t, d=d, x=x: f(x - t * d)) * d for d in cands]
        x = max(nxt, key=f)
    return f(x) / f(x0)


@pytest.mark.parametrize("key", [k for k in PEPIT if k[3] <= 3])
def test_simulated_line_searches_stay_below_the_proven_bound(docs, key):
    _, kappa, eps_s, n = key
    eps, mu = frac(eps_s), 0.1
    L = kappa * mu
    proven = docs[key]["certificate"]["proof"]["tau_proven_float"]
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(12):
        lam = np.array([mu, L])  # the extremal quadratic, random starts
        H = np.diag(lam)
        a = rng.uniform(0, np.pi)
        worst = max(worst, simulated_ratio(lambda x, H=H: 0.5 * x @ H @ x,
                                           lambda x, H=H: H @ x,
                                           np.array([np.cos(a), np.sin(a)]), n, eps, rng))
    # a smooth strongly convex non-quadratic: curvature L near 0 on the first coordinate,
    # mu beyond 1, mu on the second

    def f(x):
        t = abs(x[0])
        return 0.5 * mu * x @ x + (L - mu) * (0.5 * t ** 2 if t <= 1 else t - 0.5)

    def grad(x):
        return mu * x + (L - mu) * np.array([np.clip(x[0], -1, 1), 0.0])

    for _ in range(12):
        worst = max(worst, simulated_ratio(f, grad, rng.uniform(-4, 4, 2), n, eps, rng))
    assert worst <= proven * (1 + 1e-9)


def test_tampered_line_search_steps_are_refused(docs):
    from fractions import Fraction

    from sosalgo.spec import load_spec
    from sosalgo.worstcase.check import check_witness

    spec = load_spec(SPECS / "gradient-line-search.yaml")
    wit = docs[("gradient-line-search", 10, None, 2)]["witness"]
    assert check_witness(wit, spec)["verified"]
    bad = json.loads(json.dumps(wit))
    bad["line_search_steps"][0] = str(Fraction(bad["line_search_steps"][0]) * Fraction(101, 100))
    assert not check_witness(bad, spec)["verified"]
    bad = json.loads(json.dumps(wit))
    del bad["line_search_steps"]
    assert not check_witness(bad, spec)["verified"]


NESTEROV_LIKE = """name: bad-line-search
description: a two-state method
parameters:
  gamma: {value: 1/L}
line_search: gamma
matrices:
  A: [[0, 1], [0, 1]]
  B: [[0], [-gamma]]
  C: [[0, 1]]
  E: [[0, 1]]
"""


@pytest.mark.parametrize("text,field", [
    (NESTEROV_LIKE, "line_search"),
    (NESTEROV_LIKE.replace("line_search: gamma", "line_search: beta"), "line_search"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, text, field):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    res = run(["pep", path, "--kappa", "10", "--steps", "1", "--out", tmp_path / "o"])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and field in lines[0] and "bad.yaml" in lines[0], res.output


def test_analyze_refuses_a_line_search(tmp_path):
    res = run(["analyze", SPECS / "gradient-line-search.yaml", "--kappa", "10",
               "--out", tmp_path])
    assert res.exit_code == 2 and "line_search" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1
