"""The support-function class ``convex_support``: f(x) = sup_{c in C} <c, x - o>.

PEPIT holds values computed once outside sosalgo: PEPit 0.5.1 in its own venv, cvxpy with
Clarabel, with PEPit's ConvexSupportFunction (M = inf): the proximal point method
(``proximal_step`` n times from x_0, f(x_n) - f* when |x_0 - x*|^2 <= 1) and proximal
gradient on f + h, f (mu, L)-smooth strongly convex, h a support function
(|x_n - x*|^2 when |x_0 - x*|^2 <= 1). The closed forms are 1/(4 gamma N) (Guler 1991;
attained by c|x|, a support function) and max(|1 - gamma mu|, |1 - gamma L|)^(2N)
(Taylor, Hendrickx, Glineur 2018; attained with h = 0). The soundness check runs the
proximal point method on support functions of random rotated boxes written here.
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

ROOT = Path(__file__).resolve().parents[1]

# (gamma, N): PEPit's value, proximal point
PEPIT_PPM = {(1, 1): 0.24999999777597484, (1, 2): 0.12500000041334255,
             (2, 3): 0.041666667128866484}
# (L, mu, gamma, N): PEPit's value, proximal gradient with h a support function
PEPIT_PGM = {(1, 0.1, 1.5, 2): 0.5220062526273768, (1, 0.2, 1.0, 1): 0.6400000021660863,
             (2, 0.1, 0.9, 3): 0.5678692565259341}


def _run(args: list[str]) -> dict:
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def _ppm_spec(tmp_path: Path) -> Path:
    text = (ROOT / "bench/conformance/specs/proximal-point-convex.yaml").read_text(
        encoding="utf-8")
    out = tmp_path / "proximal-point-support.yaml"
    text = text.replace("{class: convex}", "{class: convex_support}")
    out.write_text(text.replace("name: proximal-point-convex", "name: proximal-point-support"),
                   encoding="utf-8")
    return out


def _pgm_spec(tmp_path: Path, mu: float) -> Path:
    data = yaml.safe_load((ROOT / "specs/proximal-gradient.yaml").read_text(encoding="utf-8"))
    data["functions"]["g"] = {"class": "convex_support"}
    data["m"] = mu
    data.pop("kappa")
    data.pop("references")
    out = tmp_path / f"proximal-gradient-support-{mu}.yaml"
    out.write_text(yaml.safe_dump(data), encoding="utf-8")
    return out


def test_the_inequalities_are_the_support_conditions():
    """On random data (x*, s* = 0): the convex inequality and, with b = o, f_a - f(o) -
    <g_a, x_a - o> (f(o) = 0): together f_a = <g_a, x_a - o> (Cor. 3.7); exact twins."""
    rng = np.random.default_rng(1)
    convex, anchor = CLASSES["convex_support"].inequalities({})
    assert (convex.scope, anchor.scope) == ("pairs", "anchor")
    for _ in range(30):
        xa, o, ga = rng.standard_normal((3, 3))
        fa = rng.standard_normal()
        X = np.array([xa, o, ga, 0 * ga])
        value = anchor.alpha * fa + np.einsum("id,ij,jd->", X, anchor.Q, X)
        assert value == pytest.approx(fa - ga @ (xa - o))
    exact, source = exact_class_inequalities(CLASSES["convex_support"], {})
    assert source == "exact"
    for (alpha, Q), fl in zip(exact, (convex, anchor), strict=True):
        assert float(alpha.c) == pytest.approx(fl.alpha) and alpha.r == 0
        assert np.allclose(np.array([[float(Ball.of(b).c) for b in r] for r in Q]), fl.Q)


@pytest.mark.parametrize("key", list(PEPIT_PPM))
def test_proximal_point_agrees_with_pepit(tmp_path, key):
    gamma, steps = key
    doc = _run(["pep", str(_ppm_spec(tmp_path)), "--steps", str(steps), "--set",
                f"gamma={gamma}", "--json", "--no-plot", "--out", str(tmp_path / "o")])
    ref = 1 / (4 * gamma * steps)
    assert PEPIT_PPM[key] == pytest.approx(ref, rel=1e-6)
    assert doc["tau"] == pytest.approx(ref, rel=1e-6)
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert ref * (1 - 1e-9) <= upper <= ref * (1 + 1e-6)
    check = doc["witness"]["check"]
    assert check["verified"] and Fraction(check["tau_lower"]) >= ref * (1 - 1e-4)


@pytest.mark.parametrize("key", list(PEPIT_PGM))
def test_proximal_gradient_agrees_with_pepit(tmp_path, key):
    """Proven and witnessed at every set (at h = 0.9 the points are recomputed in
    rationals: in balls h_a = <g_a, x_a - o> could not be proven)."""
    L, mu, gamma, steps = key
    doc = _run(["pep", str(_pgm_spec(tmp_path, mu)), "--kappa", str(L / mu), "--steps",
                str(steps), "--set", f"h={gamma}", "--json", "--no-plot", "--out",
                str(tmp_path / "o")])
    ref = max(abs(1 - gamma * mu), abs(1 - gamma * L)) ** (2 * steps)
    assert PEPIT_PGM[key] == pytest.approx(ref, rel=1e-6)
    assert doc["tau"] == pytest.approx(ref, rel=1e-6)
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert ref * (1 - 1e-9) <= upper <= ref * (1 + 1e-6)
    check = doc["witness"]["check"]
    assert check["verified"] and Fraction(check["tau_lower"]) >= ref * (1 - 1e-4)


def _box_support(rng: np.random.Generator, d: int):
    """f(x) = sigma_C(x - o), C = R [l, u] (a rotated box with l < 0 < u, so f >= 0 =
    f(o)): (value, prox) with prox_{gamma f}(v) = v - gamma P_C((v - o)/gamma)."""
    R = np.linalg.qr(rng.standard_normal((d, d)))[0]
    lo, hi = -rng.uniform(0, 2, d), rng.uniform(0, 2, d)
    o = rng.standard_normal(d)

    def value(x):
        z = R.T @ (x - o)
        return float(np.sum(np.maximum(lo * z, hi * z)))

    def prox(v, gamma):
        w = R.T @ ((v - o) / gamma)
        return v - gamma * (R @ np.clip(w, lo, hi))

    return value, prox, o


def test_support_functions_never_beat_the_proven_bound(tmp_path):
    """The proximal point method (gamma = 1, N = 2) on support functions of random rotated
    boxes, from starts at distance 1 of the minimizer o: f(x_N) - f* <= tau_proven."""
    steps = 2
    doc = _run(["pep", str(_ppm_spec(tmp_path)), "--steps", str(steps), "--json",
                "--no-plot", "--out", str(tmp_path / "o")])
    upper = float(Fraction(doc["certificate"]["tau_proven"]))
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(400):
        d = int(rng.integers(1, 4))
        value, prox, o = _box_support(rng, d)
        u = rng.standard_normal(d)
        x = o + u / np.linalg.norm(u)
        for _ in range(steps):
            x = prox(x, 1.0)
        worst = max(worst, value(x))
    assert 0 < worst <= upper * (1 + 1e-9)


def test_a_witness_with_its_origin_moved_is_refused(tmp_path):
    """The honest witness verifies; the same points with the origin o moved (or o's value
    made nonzero) are no support function's data: refused (exit 3)."""
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(_ppm_spec(tmp_path)), "--steps", "2",
                                 "--no-plot", "--out", str(out)])
    assert r.exit_code == 0, r.output
    path = out / "proximal-point-support-pep-N2-witness.json"
    honest = json.loads(path.read_text(encoding="utf-8"))
    origin = next(p for p in honest["functions"]["f"]["points"] if p["label"] == "o_f")
    assert origin["h"] == "0"
    moved = json.loads(json.dumps(honest))
    for p in moved["functions"]["f"]["points"]:
        if p["label"] == "o_f":
            p["x"][0] += 0.25
            p.pop("x_exact", None)
    valued = json.loads(json.dumps(honest))
    for p in valued["functions"]["f"]["points"]:
        if p["label"] == "o_f":
            p["h"] = "1/100"
    for doc, code in ((honest, 0), (moved, 3), (valued, 3)):
        f = tmp_path / "w.json"
        f.write_text(json.dumps(doc), encoding="utf-8")
        res = CliRunner().invoke(cli, ["verify", str(f), "--out", str(tmp_path / "v")])
        assert res.exit_code == code, res.output


@pytest.mark.parametrize("args,field", [
    (["analyze"], "functions"),
    (["pep", "--steps", "2", "--measure", "f(x_0)"], "--measure"),
])
def test_bad_input_one_line(tmp_path, args, field):
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, [args[0], str(_ppm_spec(tmp_path)), *args[1:], "--out",
                                 str(out)])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and field in lines[0] and "Traceback" not in r.output
    assert not out.exists()
