"""Convex M-Lipschitz functions (class ``convex_lipschitz``: an inhomogeneous condition
|g|^2 <= M^2), the ``minf`` measure and PEPit's subgradient method example
(specs/subgradient.yaml).

Closed form: PEPit's example docstring (Drori and Teboulle 2016; Nesterov 2004): with
gamma = 1/(M sqrt(N + 1)) and |x_0 - x*| <= 1, min_{k <= N} f(x_k) - f* <= M/sqrt(N + 1),
tight. PEPIT holds PEPit's own values, computed once outside sosalgo: PEPit 0.5.1 (pip,
its own venv), cvxpy with Clarabel, calling
``PEPit.examples.unconstrained_convex_minimization.subgradient_method.
wc_subgradient_method(M, n, gamma)``. The soundness checks use code written here (the
subgradient method on explicit piecewise-linear M-Lipschitz functions, the class's
conditions as PEPit's ConvexLipschitzFunction writes them), not sosalgo's.
"""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from sosalgo.certificates.exact_composite import exact_class_inequalities
from sosalgo.classes import CLASSES
from sosalgo.cli import cli
from sosalgo.kernel.exact import Ball

SPEC = Path(__file__).resolve().parents[1] / "specs" / "subgradient.yaml"

# (M, n, gamma as written for --set): PEPit's value (PEPit 0.5.1, cvxpy/Clarabel; see the
# module); the first is the example's own call, the first two at gamma = 1/(M sqrt(n + 1))
PEPIT = {(2, 6, "1/(2*sqrt(7))"): 0.7559289419913365,
         (3, 3, "1/6"): 1.5000035661359816,
         (1, 4, "3/10"): 0.4489616015014164}
TUNED = {(2, 6, "1/(2*sqrt(7))"), (3, 3, "1/6")}


def _pep(tmp_path: Path, steps: int, *extra: str) -> dict:
    r = CliRunner().invoke(cli, ["pep", str(SPEC), "--steps", str(steps), *extra, "--json",
                                 "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def test_the_class_inequalities_are_pepits_lipschitz_conditions():
    """On random data the two inequalities are PEPit's convexity f_a - f_b >= <g_b, x_a -
    x_b> and M^2 - |g_a|^2 >= 0 (the second only between a point and x*); the exact twins
    are the float ones at rational parameters."""
    cls = CLASSES["convex_lipschitz"]
    M = 1.7
    convex, bound = cls.inequalities({"M": M})
    assert (convex.scope, bound.scope) == ("pairs", "optimum")
    rng = np.random.default_rng(0)
    for _ in range(50):
        xa, xb, ga, gb = rng.standard_normal((4, 3))
        fa, fb = rng.standard_normal(2)
        X = np.array([xa, xb, ga, gb])

        def value(q, X=X, fa=fa, fb=fb):
            return q.alpha * (fa - fb) + np.einsum("id,ij,jd->", X, q.Q, X) + q.constant

        assert value(convex) == pytest.approx(fa - fb - gb @ (xa - xb), abs=1e-12)
        assert value(bound) == pytest.approx(M * M - ga @ ga, abs=1e-12)
    params = {"M": Ball(Fraction(3, 2))}
    exact, source = exact_class_inequalities(cls, params)
    floats = cls.tilted({"M": 1.5})
    assert source == "exact" and len(exact) == len(floats) == 2
    for (alpha, Q), fl in zip(exact, floats, strict=True):
        assert float(alpha.c) == fl.alpha and alpha.r == 0
        assert np.array_equal(np.array([[float(b.c) for b in r] for r in Q]), fl.Q)
    const = Ball.of(cls.exact_constants(params)[1])
    assert (const.c, const.r) == (Fraction(9, 4), 0)


@pytest.mark.parametrize("M,steps,gamma", sorted(PEPIT))
def test_pep_answers_pepits_question(tmp_path, M, steps, gamma):
    """``sosalgo pep specs/subgradient.yaml --steps n --set M=.. --set gamma=..``: the
    value of PEPit's example (and the closed form M/sqrt(n + 1) at its step), proven from
    above exactly (never below PEPit beyond 1e-7), a verified witness from below."""
    doc = _pep(tmp_path, steps, "--set", f"M={M}", "--set", f"gamma={gamma}")
    assert doc["measure"] == "minf" and doc["initial"] == "dist(x_0)"
    pepit = PEPIT[(M, steps, gamma)]
    tuned = (M, steps, gamma) in TUNED
    ref = M / math.sqrt(steps + 1) if tuned else pepit
    if tuned:
        assert pepit == pytest.approx(ref, rel=1e-5)
    assert doc["tau"] == pytest.approx(ref, rel=1e-6)
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert doc["certificate"]["proof"]["proven"]
    assert upper >= ref * (1 - 1e-7) and upper >= pepit * (1 - 1e-5)
    assert upper <= ref * (1 + 1e-5)
    check = doc["witness"]["check"]
    assert check["verified"]
    assert ref * (1 - 1e-4) <= Fraction(check["tau_lower"]) <= upper


def _subgradient_min(pieces: np.ndarray, x0: np.ndarray, gamma: float, steps: int) -> float:
    """min_{k <= N} f(x_k) - f* for f(x) = max_i <a_i, x> (f* = 0 at x* = 0: 0 is in the
    convex hull of the a_i) and the subgradient method with the active piece's a_i."""
    x, best = x0, np.inf
    for k in range(steps + 1):
        vals = pieces @ x
        best = min(best, float(vals.max()))
        if k < steps:
            x = x - gamma * pieces[int(np.argmax(vals))]
    return best


def _pieces(rng: np.random.Generator, M: float, d: int) -> np.ndarray:
    """Slopes a_1..a_k (|a_i| <= M) and a_{k+1} = -c sum a_i (|a_{k+1}| <= M): 0 is a
    positive combination of them, so max_i <a_i, x> >= 0 = f(0); M-Lipschitz."""
    k = int(rng.integers(1, 2 * d + 1))
    A = rng.standard_normal((k, d))
    A *= (M * rng.uniform(0.2, 1.0, k) / np.linalg.norm(A, axis=1))[:, None]
    s = A.sum(axis=0)
    last = -s * (M * rng.uniform(0.2, 1.0) / max(np.linalg.norm(s), 1e-12))
    return np.vstack([A, last])


@pytest.mark.parametrize("seed", [0, 1])
def test_random_lipschitz_functions_never_beat_the_proven_bound(tmp_path, seed):
    """Random (M, gamma, N); the subgradient method on random piecewise-linear M-Lipschitz
    convex functions and on M|x| in 1-D, from starts on the unit sphere: min_k f(x_k) - f*
    stays below the proven bound."""
    rng = np.random.default_rng(seed)
    M = float(rng.choice([0.5, 1.0, 2.5]))
    steps = int(rng.integers(1, 5))
    gamma = float(rng.choice([0.1, 0.3, 0.7])) / M
    doc = _pep(tmp_path, steps, "--set", f"M={M}", "--set", f"gamma={gamma}")
    upper = float(Fraction(doc["certificate"]["tau_proven"]))
    best = 0.0
    for _ in range(400):
        d = int(rng.integers(1, 5))
        x0 = rng.standard_normal(d)
        x0 /= np.linalg.norm(x0)
        best = max(best, _subgradient_min(_pieces(rng, M, d), x0, gamma, steps))
    best = max(best, _subgradient_min(np.array([[M], [-M]]), np.ones(1), gamma, steps))
    assert 0 < best <= upper * (1 + 1e-9)


def test_the_witness_is_a_lipschitz_trajectory_by_independent_code(tmp_path):
    """The witness's points, read as exact rationals: subgradient steps x_{k+1} = x_k -
    gamma g_k, |g_k| <= M at every point and convexity between every pair (so a convex
    M-Lipschitz function interpolates them, Taylor et al. 2017, Thm. 3.5), |x_0| <= 1,
    and its min_k f(x_k) - f* within 1e-4 of M/sqrt(N + 1)."""
    steps, M = 3, 2
    doc = _pep(tmp_path, steps, "--set", f"M={M}", "--set", "gamma=1/4")
    pts = doc["witness"]["functions"]["f"]["points"]
    X = [np.array([Fraction(v) for v in p["x_exact"]], dtype=object) for p in pts]
    G = [np.array([Fraction(v) for v in p["g"]], dtype=object) for p in pts]
    H = [Fraction(p["h"]) for p in pts]
    X.append(0 * X[0])
    G.append(0 * G[0])
    H.append(Fraction(0))  # x* = 0, f* = 0
    labels = [p["label"] for p in pts]
    order = [labels.index(f"y{k}") if f"y{k}" in labels else labels.index(f"x{k}")
             for k in range(steps)]
    order.append(next(i for i, lab in enumerate(labels) if lab in (f"x{steps}", "x")))
    for k in range(steps):
        a, b = order[k], order[k + 1]
        assert all(X[b] == X[a] - Fraction(1, 4) * G[a])
    assert X[order[0]] @ X[order[0]] <= 1
    for a in range(len(X)):
        assert G[a] @ G[a] <= M * M
        for b in range(len(X)):
            if a != b:
                assert H[a] - H[b] - G[b] @ (X[a] - X[b]) >= 0
    low = min(H[i] for i in order)
    assert abs(float(low) - M / math.sqrt(steps + 1)) <= 1e-4


def test_verify_reproves_and_refuses_a_lower_bound(tmp_path):
    """``verify`` re-proves the document; with tau_proven lowered below the worst case it
    refuses it (the constants' part of the bound is counted)."""
    doc = _pep(tmp_path, 2, "--set", "gamma=1/4")
    path = tmp_path / "r.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    ok = CliRunner().invoke(cli, ["verify", str(path)])
    assert ok.exit_code == 0, ok.output
    cert = doc["certificate"]
    low = Fraction(cert["tau_proven"]) * Fraction(99, 100)
    cert["tau_proven"] = cert["proof"]["tau_proven"] = f"{low.numerator}/{low.denominator}"
    path.write_text(json.dumps(doc), encoding="utf-8")
    bad = CliRunner().invoke(cli, ["verify", str(path)])
    assert bad.exit_code != 0


def _variant(tmp_path: Path, drop: tuple[str, ...] = (), **changes) -> Path:
    data = yaml.safe_load(SPEC.read_text(encoding="utf-8"))
    data.update(changes)
    for key in drop:
        data.pop(key)
    path = tmp_path / "variant.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def _two_functions(tmp_path: Path) -> Path:
    return _variant(tmp_path, functions={"f": {"class": "convex_lipschitz", "M": "M"},
                                         "g": {"class": "convex"}},
                    matrices={"A": [[1]], "B": [["-gamma", "-gamma"]], "C": [[1], [1]],
                              "E": [[1]]},
                    oracles=["f", "g"], measure="distance", m=1, drop=("L",),
                    pep={"measure": "dist", "initial": "dist(x_0)"})


@pytest.mark.parametrize("case,args,field", [
    ("spec", ["analyze"], "functions"),
    ("spec", ["analyze", "--certificate", "interpolation"], "functions"),
    ("spec", ["pep", "--steps", "2", "--measure", "grad"], "--measure"),
    ("spec", ["pep", "--steps", "2", "--measure", "-1*minf"], "--measure"),
    ("spec", ["pep", "--steps", "2", "--initial", "minf"], "--initial"),
    ("prox", ["pep", "--steps", "2"], "matrices.D"),
    ("two", ["pep", "--steps", "2", "--kappa", "2"], "functions"),
    ("perstep", ["pep", "--steps", "2"], "functions.f.M"),
])
def test_bad_input_one_line(tmp_path, case, args, field):
    """analyze refuses the class (no Lyapunov family takes an inhomogeneous condition);
    pep refuses a gradient measure (no gradient oracle), a minimum bounded from below or
    in the initial condition, a proximal step (no proximal oracle), and the class beside
    another function (its conditions bound the function, not its tilt), and a class
    parameter naming a parameter that changes with k."""
    spec = {"spec": lambda: SPEC,
            "prox": lambda: _variant(tmp_path, matrices={"A": [[1]], "B": [["-gamma"]],
                                                         "C": [[1]], "D": [["-gamma"]],
                                                         "E": [[1]]}),
            "two": lambda: _two_functions(tmp_path),
            "perstep": lambda: _variant(tmp_path, parameters={"M": {"value": "2 + k"},
                                                              "gamma": {"value": "1/4"}}),
            }[case]()
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, [args[0], str(spec), *args[1:], "--out", str(out)])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and field in lines[0] and "Traceback" not in r.output
    assert not out.exists()
