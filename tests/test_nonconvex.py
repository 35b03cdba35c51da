"""L-smooth, possibly nonconvex functions (class ``smooth``) and the ``mingrad`` measure:
PEPit's nonconvex gradient descent example (specs/gradient-nonconvex.yaml).

Closed form: PEPit's example docstring (after Taylor 2017, p. 190, and Abbaszadehpeivasti,
de Klerk, Zamani 2021): at gamma = 1/L, min_{k <= N} |grad f(x_k)|^2 <= 4L/(3N) (f(x_0) -
f(x_N)), tight. PEPIT holds PEPit's own values, computed once outside sosalgo: PEPit 0.5.1
(pip, its own venv), cvxpy 1.9.3 with Clarabel, calling
``PEPit.examples.nonconvex_optimization.gradient_descent.wc_gradient_descent(L=1, gamma, n)``.
The soundness checks use code written here (the interpolation inequality as PEPit's
SmoothFunction writes it, gradient descent on explicit functions), not sosalgo's.
"""

from __future__ import annotations

import json
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

SPEC = Path(__file__).resolve().parents[1] / "specs" / "gradient-nonconvex.yaml"

# (N, gamma with L = 1): PEPit's value (PEPit 0.5.1, cvxpy/Clarabel; see the module)
PEPIT = {(1, 1.0): 1.3333333335291473, (2, 1.0): 0.666666667288835,
         (3, 1.0): 0.4444444447820326, (5, 1.0): 0.2666666666896785,
         (3, 0.5): 0.7619047637171203, (4, 1.5): 0.3809523815316143,
         (2, 1.8): 1.584789256337654}


def _smooth_ineq(L: float, xa, xb, ga, gb, fa, fb) -> float:
    """PEPit's SmoothFunction constraint, as a slack: f_a - f_b - (-L/4 |x_a - x_b|^2 +
    1/2 <g_a + g_b, x_a - x_b> + |g_a - g_b|^2 / (4L)) >= 0 (Taylor, Hendrickx, Glineur
    2017, Thm. 3.10 with mu = -L)."""
    dx, dg = xa - xb, ga - gb
    return fa - fb - (-L / 4 * dx @ dx + 0.5 * (ga + gb) @ dx + dg @ dg / (4 * L))


def test_the_class_inequality_is_thg_smooth_interpolation():
    """At m = -L the class's inequality is (L - m) times PEPit's, on random data; its exact
    twin is the float one at rational parameters."""
    cls = CLASSES["smooth"]
    L = 1.7
    (ineq,) = cls.inequalities({"m": -L, "L": L})
    rng = np.random.default_rng(0)
    for _ in range(50):
        xa, xb, ga, gb = rng.standard_normal((4, 3))
        fa, fb = rng.standard_normal(2)
        X = np.array([xa, xb, ga, gb])
        ours = ineq.alpha * (fa - fb) + np.einsum("id,ij,jd->", X, ineq.Q, X)
        assert ours == pytest.approx(2 * L * _smooth_ineq(L, xa, xb, ga, gb, fa, fb),
                                     abs=1e-9)
    exact, source = exact_class_inequalities(cls, {"m": Ball(Fraction(-1, 2)),
                                                   "L": Ball(Fraction(3, 2))})
    floats = cls.tilted({"m": -0.5, "L": 1.5})
    assert source == "exact" and len(exact) == len(floats) == 1
    alpha, Q = exact[0]
    assert float(alpha.c) == floats[0].alpha and alpha.r == 0
    assert np.array_equal(np.array([[float(b.c) for b in r] for r in Q]), floats[0].Q)


def test_the_inequality_holds_on_smooth_nonconvex_functions_and_fails_beyond():
    """f(x) = a cos(w x) + q/2 x^2 with |q| + a w^2 <= L is L-smooth (|f''| <= L): every
    pair passes; with curvature 1.5 L somewhere, some pair fails."""
    L = 1.0
    cls = CLASSES["smooth"]
    (ineq,) = cls.inequalities({"m": -L, "L": L})

    def worst(a, w, q):
        xs = np.linspace(-4, 4, 41)
        f = a * np.cos(w * xs) + q / 2 * xs**2
        g = -a * w * np.sin(w * xs) + q * xs
        out = np.inf
        for i in range(len(xs)):
            for j in range(len(xs)):
                X = np.array([xs[i], xs[j], g[i], g[j]])
                out = min(out, ineq.alpha * (f[i] - f[j]) + X @ ineq.Q @ X)
        return out

    assert worst(0.5, 1.0, -0.5) >= -1e-12 and worst(0.3, 1.5, 0.3) >= -1e-12
    assert worst(1.5, 1.0, 0.0) < 0  # f'' reaches 1.5 L


def _pep(tmp_path: Path, steps: int, *extra: str) -> dict:
    r = CliRunner().invoke(cli, ["pep", str(SPEC), "--steps", str(steps), *extra, "--json",
                                 "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


@pytest.mark.parametrize("steps,gamma", sorted(PEPIT))
def test_pep_answers_pepits_question(tmp_path, steps, gamma):
    """``sosalgo pep specs/gradient-nonconvex.yaml --steps N --set gamma=G``: the value of
    PEPit's example (and its closed form 4L/(3N) at gamma = 1/L), proven from above
    exactly, a verified witness from below."""
    doc = _pep(tmp_path, steps, "--set", f"gamma={gamma}")
    assert doc["measure"] == "mingrad" and doc["initial"] == "f(x_0) - f(x_N)"
    pepit = PEPIT[(steps, gamma)]
    if gamma == 1.0:
        assert pepit == pytest.approx(4 / (3 * steps), rel=1e-8)
        ref = 4 / (3 * steps)
    else:
        ref = pepit
    assert doc["tau"] == pytest.approx(ref, rel=2e-7)
    proof = doc["certificate"]["proof"]
    assert proof["proven"]
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert ref * (1 - 1e-8) <= upper <= ref * (1 + 1e-5)
    check = doc["witness"]["check"]
    assert check["verified"]
    assert ref * (1 - 1e-4) <= Fraction(check["tau_lower"]) <= upper




def _gd_ratio(f, grad, x0: np.ndarray, gamma: float, steps: int) -> float | None:
    x, gs, f0 = x0, [], f(x0)
    for _ in range(steps + 1):
        gs.append(grad(x))
        if len(gs) <= steps:
            x = x - gamma * gs[-1]
    drop = f0 - f(x)
    return None if drop <= 1e-12 else min(float(g @ g) for g in gs) / drop


@pytest.mark.parametrize("gamma", [1.0, 1.5])
def test_random_smooth_functions_never_beat_the_proven_bound(tmp_path, gamma):
    """Gradient descent on random L-smooth nonconvex functions (sums of a cos(<w, x> + c)
    and an indefinite quadratic, |f''| <= L by construction): the ratio min_k
    |grad f(x_k)|^2 / (f(x_0) - f(x_N)) stays below the proven tau."""
    steps, L = 3, 1.0
    upper = float(Fraction(_pep(tmp_path, steps, "--set", f"gamma={gamma}")
                           ["certificate"]["tau_proven"]))
    rng = np.random.default_rng(7)
    best = 0.0
    for _ in range(300):
        d = 3
        W = rng.standard_normal((4, d))
        W /= np.linalg.norm(W, axis=1, keepdims=True)
        amp = rng.uniform(0, 1, 4)
        qd = rng.uniform(-1, 1, d)
        scale = L / (np.abs(qd).max() + (amp * 1.0).sum())  # |f''| <= L (|w_i| = 1)
        amp, qd = amp * scale, qd * scale
        c = rng.uniform(0, 2 * np.pi, 4)

        def f(x, W=W, amp=amp, qd=qd, c=c):
            return float(amp @ np.cos(W @ x + c) + 0.5 * qd @ (x * x))

        def grad(x, W=W, amp=amp, qd=qd, c=c):
            return -(amp * np.sin(W @ x + c)) @ W + qd * x

        r = _gd_ratio(f, grad, rng.standard_normal(d) * 3, gamma, steps)
        if r is not None:
            best = max(best, r)
    assert 0 < best <= upper * (1 + 1e-9)


def test_the_witness_is_an_l_smooth_trajectory_by_independent_code(tmp_path):
    """The witness document's points, read as exact rationals: gradient descent steps
    (x_{k+1} = x_k - gamma g_k), every pair passes PEPit's smoothness inequality (so an
    L-smooth function interpolates them, Thm. 3.10), and its min |g_k|^2 / (f_0 - f_N)
    is within 1e-4 of 4L/(3N)."""
    steps = 3
    doc = _pep(tmp_path, steps)
    wit = doc["witness"]
    pts = wit["functions"]["f"]["points"]
    X = [np.array([Fraction(v) for v in p["x_exact"]], dtype=object) for p in pts]
    G = [np.array([Fraction(v) for v in p["g"]], dtype=object) for p in pts]
    H = [Fraction(p["h"]) for p in pts]
    labels = [p["label"] for p in pts]
    order = [labels.index(f"y{k}") if f"y{k}" in labels else labels.index(f"x{k}")
             for k in range(steps + 1)]
    for k in range(steps):
        a, b = order[k], order[k + 1]
        assert all(X[b] == X[a] - G[a])  # gamma = 1/L = 1
    for a in range(len(pts)):
        for b in range(len(pts)):
            if a != b:
                assert _smooth_ineq(Fraction(1), X[a], X[b], G[a], G[b], H[a], H[b]) >= 0
    ratio = min(g @ g for g in (G[i] for i in order)) / (H[order[0]] - H[order[-1]])
    assert abs(float(ratio) - 4 / (3 * steps)) <= 1e-4


def test_verify_reproves_and_refuses_a_weaker_bound(tmp_path):
    """``verify`` re-proves the mingrad bound; a document whose measure_bound weights sum
    to less than 1 is refused (it would not bound the minimum)."""
    doc = _pep(tmp_path, 2)
    path = tmp_path / "r.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    ok = CliRunner().invoke(cli, ["verify", str(path)])
    assert ok.exit_code == 0, ok.output
    bound = doc["certificate"]["proof"]["measure_bound"]
    assert bound.count("grad(x_") == 3
    doc["certificate"]["proof"]["measure_bound"] = "(1)*1/2*grad(x_0) + (1)*1/4*grad(x_N)"
    path.write_text(json.dumps(doc), encoding="utf-8")
    bad = CliRunner().invoke(cli, ["verify", str(path)])
    assert bad.exit_code != 0 and "measure_bound" in bad.output


@pytest.mark.parametrize("args,field", [
    (["analyze"], "nonconvex"),
    (["analyze", "--certificate", "interpolation"], "nonconvex"),
    (["pep", "--steps", "2", "--measure", "dist"], "--measure"),
    (["pep", "--steps", "2", "--initial", "f(x_0)"], "--initial"),
    (["pep", "--steps", "2", "--initial", "mingrad"], "--initial"),
    (["pep", "--steps", "2", "--measure", "-1*mingrad"], "--measure"),
    (["pep", "--steps", "2", "--measure", "grad(x_5)"], "--measure"),
])
def test_bad_input_one_line(tmp_path, args, field):
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, [args[0], str(SPEC), *args[1:], "--out", str(out)])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and field in lines[0] and "Traceback" not in r.output
    assert not out.exists()


def test_a_bad_pep_field_names_file_and_field(tmp_path):
    data = yaml.safe_load(SPEC.read_text(encoding="utf-8"))
    for pep, field in (({"measure": 3}, "pep"),
                       ({"measure": "mingrad", "initial": "dist(x_0)"}, "pep.initial")):
        path = tmp_path / "bad.yaml"
        path.write_text(yaml.safe_dump(data | {"pep": pep}), encoding="utf-8")
        r = CliRunner().invoke(cli, ["pep", str(path), "--steps", "1", "--out",
                                     str(tmp_path / "o")])
        assert r.exit_code == 2
        lines = [ln for ln in r.output.strip().splitlines() if ln]
        assert len(lines) == 1 and "bad.yaml" in lines[0] and field in lines[0], r.output


@pytest.mark.parametrize("steps", [1, 3])
def test_mingrad_on_a_convex_class_is_the_closed_form(tmp_path, steps):
    """Gradient descent with step 1/L on L-smooth convex f: min_k |grad f(x_k)|^2 =
    |grad f(x_N)|^2 <= L^2 |x_0 - x*|^2 / (N + 1)^2, tight (Taylor, Hendrickx, Glineur
    2017); the gradient norm does not increase, so the minimum is the last one."""
    spec = SPEC.parent / "gradient-convex.yaml"
    r = CliRunner().invoke(cli, ["pep", str(spec), "--steps", str(steps), "--measure",
                                 "mingrad", "--initial", "dist", "--json", "--out",
                                 str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    ref = 1 / (steps + 1) ** 2
    assert doc["tau"] == pytest.approx(ref, rel=1e-6)
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert ref * (1 - 1e-9) <= upper <= ref * (1 + 1e-5)
    assert ref * (1 - 1e-4) <= Fraction(doc["witness"]["check"]["tau_lower"]) <= upper


def test_a_hypoconvex_class_is_below_the_nonconvex_one(tmp_path):
    """F(-L/2, L) is inside F(-L, L): its proven worst case is at most the nonconvex one's
    (4/9 at N = 3), proven and witnessed."""
    data = yaml.safe_load(SPEC.read_text(encoding="utf-8"))
    data["functions"] = {"f": {"class": "smooth", "m": "-L/2"}}
    path = tmp_path / "hypo.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    r = CliRunner().invoke(cli, ["pep", str(path), "--steps", "3", "--json", "--out",
                                 str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    lower = Fraction(doc["witness"]["check"]["tau_lower"])
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert doc["witness"]["check"]["verified"] and lower <= upper
    assert upper < Fraction(4, 9) * (1 - Fraction(1, 100))


def test_a_witness_about_f_star_of_a_nonconvex_class_is_refused(tmp_path):
    """The witness's values are known up to a shift (no f* in a nonconvex PEP): a document
    whose initial condition is f(x_0) - f* is not verified (else shifting h would make
    any ratio)."""
    from sosalgo import load_spec
    from sosalgo.worstcase import check_witness

    wit = _pep(tmp_path, 2)["witness"]
    assert check_witness(dict(wit), load_spec(SPEC))["verified"]
    bad = check_witness(dict(wit) | {"initial": "f(x_0)"}, load_spec(SPEC))
    assert not bad["verified"] and "f - f*" in bad["detail"]
