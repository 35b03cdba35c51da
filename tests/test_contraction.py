"""The two-trajectory contraction measure (``--measure contraction``): gradient descent and
Douglas-Rachford against PEPit's peer values and the closed forms, the proven bound
against pairs of runs simulated here (numpy: quadratics, a Huber-like function, soft
thresholding), and bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"

# Douglas-Rachford as PEPit's example runs it: the prox of the convex g first
DR_G_FIRST = """name: dr-g-first
description: Douglas-Rachford, prox of g then of f (PEPit's contraction example)
functions:
  f: {class: smooth_strongly_convex}
  g: {class: convex}
parameters:
  alpha: {value: 3}
matrices:
  A: [[1]]
  B: [[-alpha, -alpha]]
  C: [[1], [1]]
  D: [[-alpha, 0], [-2*alpha, -alpha]]
oracles: [g, f]
output: y1
m: 1/10
kappa: [10]
pep: {measure: contraction}
"""

# PEPit 0.5.1 (wrapper="cvxpy", solver="CLARABEL", verbose=-1):
# tutorials/gradient_descent_contraction.py: wc_gradient_descent_contraction(L, mu, gamma, n);
# gradient.yaml has m = 1, L = kappa: PEPit's example (L=1, mu=.1, gamma=1, n=1) is the same
# question scaled (L=10, mu=1, gamma=.1)
GD = {  # (kappa, h or None, N): (PEPit's value, its call)
    (10, None, 1): 0.8100000058232638,  # (L=1, mu=.1, gamma=1, n=1), scaled
    (10, None, 2): 0.6561000044223606,  # (L=10, mu=1, gamma=.1, n=2)
    (10, "0.15", 3): 0.37714951563847066,  # (L=10, mu=1, gamma=.15, n=3)
}
# composite_convex_minimization/douglas_rachford_splitting_contraction.py:
# wc_douglas_rachford_splitting_contraction(mu, L, alpha, theta=1, n); DR_G_FIRST has
# mu = 1/10, L = kappa/10
DR = {  # (kappa, alpha, N): PEPit's value
    (10, "3", 2): 0.3501278218595927,  # (mu=.1, L=1, alpha=3, n=2): the example's
    (10, "1", 3): 0.5644739305916743,  # (mu=.1, L=1, alpha=1, n=3)
    (5, "4", 1): 0.5102040953438118,  # (mu=.2, L=1, alpha=2, n=1), scaled
}
# the shipped douglas-rachford.yaml (prox of f first, t = 1/sqrt(m L)) at kappa 10, N = 2:
# PEPit's PEP() with SmoothStronglyConvexFunction(mu=1, L=10), ConvexFunction, two starts,
# (w0 - w0')^2 <= 1, n = 2 steps y1 = prox_{t f}(w), y2 = prox_{t g}(2 y1 - w),
# w += y2 - y1, metric (w - w')^2, t = 1/sqrt(10)
DR_SHIPPED = 0.33317761596384593


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def pep_doc(tmp_path, spec, kappa, n, *extra):
    kap = [] if kappa is None else ["--kappa", kappa]
    res = run(["pep", spec, *kap, "--steps", n, "--out", tmp_path, "--json", "--no-plot",
               *extra])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def proven(doc) -> float:
    proof = doc["certificate"]["proof"]
    assert proof["proven"], proof
    return proof["tau_proven_float"]


@pytest.mark.parametrize("key", list(GD))
def test_gradient_descent_agrees_with_pepit_and_the_closed_form(tmp_path, key):
    kappa, h, n = key
    extra = ["--measure", "contraction"] + ([] if h is None else ["--set", f"h={h}"])
    tau = proven(pep_doc(tmp_path, SPECS / "gradient.yaml", kappa, n, *extra))
    gamma, m, L = (float(h) if h else 1 / kappa), 1.0, float(kappa)
    theory = max(abs(1 - gamma * m), abs(1 - gamma * L)) ** (2 * n)
    assert tau >= GD[key] * (1 - 1e-7) and tau >= theory * (1 - 1e-9)
    assert tau <= theory * (1 + 1e-6)


@pytest.fixture
def dr_spec(tmp_path):
    path = tmp_path / "dr-g-first.yaml"
    path.write_text(DR_G_FIRST)
    return path


@pytest.mark.parametrize("key", list(DR))
def test_douglas_rachford_agrees_with_pepit_and_the_closed_form(tmp_path, dr_spec, key):
    kappa, alpha, n = key
    tau = proven(pep_doc(tmp_path, dr_spec, kappa, n, "--set", f"alpha={alpha}"))
    mu, L, a = 0.1, kappa / 10, float(alpha)
    theory = max(1 / (1 + mu * a), a * L / (1 + a * L)) ** (2 * n)
    assert tau >= DR[key] * (1 - 1e-7) and tau >= theory * (1 - 1e-9)
    assert tau <= theory * (1 + 1e-6)


def test_the_shipped_douglas_rachford_agrees_with_pepit(tmp_path):
    doc = pep_doc(tmp_path, SPECS / "douglas-rachford.yaml", 10, 2, "--measure",
                  "contraction")
    tau = proven(doc)
    assert DR_SHIPPED * (1 - 1e-7) <= tau <= DR_SHIPPED * (1 + 1e-6)
    assert doc["initial"] == "contraction"


def _gd_pair(grad, x, xp, gamma, n):
    for _ in range(n):
        x, xp = x - gamma * grad(x), xp - gamma * grad(xp)
    return x, xp


def test_gradient_descent_pairs_stay_below_the_proven_bound(tmp_path):
    kappa, n = 10, 3
    tau = proven(pep_doc(tmp_path, SPECS / "gradient.yaml", kappa, n, "--measure",
                         "contraction", "--set", "h=0.15"))
    m, L, gamma = 1.0, 10.0, 0.15
    rng = np.random.default_rng(3)
    worst = 0.0
    for trial in range(40):
        dim = 1 + trial % 3
        lam = rng.uniform(m, L, dim)
        lam[0] = L if trial % 2 else m
        Q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
        H = Q @ np.diag(lam) @ Q.T
        x, xp = rng.standard_normal(dim), rng.standard_normal(dim)
        a, b = _gd_pair(lambda v, H=H: H @ v, x, xp, gamma, n)
        worst = max(worst, np.sum((a - b) ** 2) / np.sum((x - xp) ** 2))

    def grad(v):  # Huber-like: curvature L on [-1, 1], m beyond (smooth, m-convex)
        return m * v + (L - m) * np.clip(v, -1, 1)

    for _ in range(200):
        x, xp = rng.uniform(-3, 3, 1), rng.uniform(-3, 3, 1)
        a, b = _gd_pair(grad, x, xp, gamma, n)
        worst = max(worst, float(np.sum((a - b) ** 2) / np.sum((x - xp) ** 2)))
    assert worst <= tau * (1 + 1e-12)
    assert worst >= 0.999 * tau  # the extremal quadratic attains it


def test_douglas_rachford_pairs_stay_below_the_proven_bound(tmp_path, dr_spec):
    """w+ = w + prox_{a f}(2 prox_{a g}(w) - w) - prox_{a g}(w) with f quadratic (curvature
    in [mu, L]) and g = lam |.|_1 (soft thresholding), two random starts."""
    tau = proven(pep_doc(tmp_path, dr_spec, 10, 2))
    mu, L, a = 0.1, 1.0, 3.0
    rng = np.random.default_rng(5)
    worst = 0.0
    for trial in range(300):
        dim = 1 + trial % 2
        lam_f = rng.uniform(mu, L, dim)
        lam_f[0] = (mu, L)[trial % 2]
        weight = rng.uniform(0, 2)

        def step(w, lam_f=lam_f, weight=weight):
            x = np.sign(w) * np.maximum(np.abs(w) - a * weight, 0)  # prox_{a g}
            y = (2 * x - w) / (1 + a * lam_f)  # prox_{a f}, f = sum lam_f x^2 / 2
            return w + y - x

        w, wp = rng.uniform(-3, 3, dim), rng.uniform(-3, 3, dim)
        a0 = np.sum((w - wp) ** 2)
        for _ in range(2):
            w, wp = step(w), step(wp)
        worst = max(worst, float(np.sum((w - wp) ** 2) / a0))
    assert worst <= tau * (1 + 1e-12)


@pytest.mark.parametrize("extra,field", [
    (["--measure", "contraction", "--initial", "dist"], "--initial"),
    (["--measure", "contraction + f"], "--measure"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, extra, field):
    res = run(["pep", SPECS / "gradient.yaml", "--kappa", "10", "--steps", "1", "--out",
               tmp_path, *extra])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and field in lines[0] and "contraction" in lines[0], res.output


def test_contraction_of_an_inexact_method_is_refused(tmp_path):
    res = run(["pep", SPECS / "inexact-gradient.yaml", "--kappa", "10", "--steps", "1",
               "--measure", "contraction", "--out", tmp_path])
    assert res.exit_code == 2, res.output
    assert len(res.output.strip().splitlines()) == 1 and "contraction" in res.output


def test_witnesses_verify_and_tampering_is_refused(tmp_path, dr_spec):
    from fractions import Fraction

    from sosalgo.spec import load_spec
    from sosalgo.worstcase.check import check_witness

    doc = pep_doc(tmp_path, dr_spec, 10, 2)
    wit = doc["witness"]
    tau = proven(doc)
    check = wit["check"]
    assert check["verified"], check
    assert DR[(10, "3", 2)] * (1 - 1e-4) <= check["tau_lower_float"] <= tau
    path = tmp_path / "doc.json"
    path.write_text(json.dumps(doc))
    res = run(["verify", path, "--spec", dr_spec, "--out", tmp_path / "v"])
    assert res.exit_code == 0, res.output
    spec = load_spec(dr_spec)
    bad = json.loads(json.dumps(wit))  # an answer that is not its point's gradient
    u = Fraction(bad["calls_second"][1][1][0])
    bad["calls_second"][1][1] = [str(u * Fraction(11, 10) + Fraction(1, 1000))]
    assert not check_witness(bad, spec)["verified"]
    bad = json.loads(json.dumps(wit))  # a start farther out than the runs say
    bad["xi0_second"] = [[str(Fraction(v[0]) * 2)] for v in bad["xi0_second"]]
    assert not check_witness(bad, spec)["verified"]
    bad = json.loads(json.dumps(wit))  # a contraction witness for another measure
    bad["measure"] = "dist"
    assert not check_witness(bad, spec)["verified"]


# the shipped specs named after PEPit's examples, at the examples' parameters and others
SHIPPED = {  # (spec, kappa, N, --set ...): PEPit's value
    # wc_gradient_descent_contraction(L=1, mu=.1, gamma=1, n=1): the example's
    ("gradient-descent-contraction", 10, 1, ()): 0.8100000058232638,
    # wc_douglas_rachford_splitting_contraction(mu=.1, L=1, alpha=3, theta=1, n=2): the
    # example's; theta=1.5; alpha=1, theta=.5
    ("douglas-rachford-contraction", 10, 2, ()): 0.3501278218595927,
    ("douglas-rachford-contraction", 10, 2, ("theta=1.5",)): 0.18276889977697766,
    ("douglas-rachford-contraction", 10, 2, ("theta=0.5", "alpha=1")): 0.8302071263040188,
}


@pytest.mark.parametrize("key", list(SHIPPED))
def test_shipped_contraction_specs_agree_with_pepit(tmp_path, key):
    spec, kappa, n, sets = key
    extra = [a for s in sets for a in ("--set", s)]
    doc = pep_doc(tmp_path, SPECS / f"{spec}.yaml", kappa, n, *extra)
    tau = proven(doc)
    assert SHIPPED[key] * (1 - 1e-7) <= tau <= SHIPPED[key] * (1 + 1e-6)
    assert doc["witness"]["check"]["verified"]
    assert doc["witness"]["check"]["tau_lower_float"] >= SHIPPED[key] * (1 - 1e-3)


def test_a_nonconvex_class_and_the_spec_initial_yielding(tmp_path):
    """Class-agnostic: on L-smooth nonconvex f, gradient steps 1/L expand by
    max_{q in [-L, L]} |1 - q/L| = 2 per step (the spec's own pep.initial, a difference of
    values, gives way to the contraction's)."""
    doc = pep_doc(tmp_path, SPECS / "gradient-nonconvex.yaml", None, 2, "--measure",
                  "contraction")
    assert doc["initial"] == "contraction"
    tau = proven(doc)
    assert 16 * (1 - 1e-9) <= tau <= 16 * (1 + 1e-6)
    assert doc["witness"]["check"]["verified"]
    assert doc["witness"]["check"]["tau_lower_float"] >= 16 * (1 - 1e-3)
