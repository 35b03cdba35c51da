"""The weakly convex classes: ``weakly_convex`` (f + rho/2 |x|^2 convex) and
``smooth_weakly_convex`` (L-smooth, curvature in [-rho, L]).

PEPIT holds values computed once outside sosalgo: PEPit 0.5.1 in its own venv, cvxpy with
Clarabel, gradient descent x+ = x - gamma grad f(x) with the measure min_{0<=k<=N}
|grad f(x_k)|^2 under f(x_0) - f(x_N) <= 1, on a PEPit function class written from the
definition only (h = f + rho/2 |x|^2 is (L + rho)-smooth convex: PEPit's smooth convex
interpolation inequality on the shifted data (x, g + rho x, f + rho/2 |x|^2)). The
soundness checks run the methods on explicit functions of each class written here.
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

SPECS = Path(__file__).resolve().parents[1] / "specs"
PROX = SPECS / "proximal-point-weakly-convex.yaml"

# (L, rho, gamma, N): PEPit's value (module docstring)
PEPIT = {(1, 0.5, 1.0, 3): 0.40000088578141085,
         (1, 0.2, 1.5, 2): 0.4637684708797261,
         (2, 1.0, 0.4, 4): 0.7211553913834741}


def _pep(tmp_path: Path, spec: Path, steps: int, sets: tuple[str, ...]) -> dict:
    args = ["pep", str(spec), "--steps", str(steps), "--json", "--no-plot", "--out",
            str(tmp_path / "o")]
    for s in sets:
        args += ["--set", s]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def _gradient_spec(tmp_path: Path, L: float) -> Path:
    """specs/gradient-nonconvex.yaml on smooth_weakly_convex (rho: the parameter rw)."""
    data = yaml.safe_load((SPECS / "gradient-nonconvex.yaml").read_text(encoding="utf-8"))
    data["functions"] = {"f": {"class": "smooth_weakly_convex", "rho": "rw"}}
    data["parameters"] = {"rw": {"value": "L/2"}, "gamma": {"value": "1/L"}}
    data["L"] = L
    data.pop("references")
    out = tmp_path / f"gradient-weakly-convex-L{L}.yaml"
    out.write_text(yaml.safe_dump(data), encoding="utf-8")
    return out


def _value(q, f, X):
    return q.alpha * f + np.einsum("id,ij,jd->", X, q.Q, X) + q.constant


def test_the_inequalities_are_the_shifted_convex_ones():
    """On random pairs, each class's inequality is a positive multiple of the convex
    (resp. (L + rho)-smooth convex) interpolation inequality of the shifted data
    (x, g + rho x, f + rho/2 |x|^2); the exact twins equal the floats."""
    rng = np.random.default_rng(4)
    rho, L = 0.75, 2.0
    (wc,) = CLASSES["weakly_convex"].inequalities({"rho": rho})
    (swc,) = CLASSES["smooth_weakly_convex"].inequalities({"rho": rho, "L": L})
    for _ in range(40):
        xa, xb, ga, gb = rng.standard_normal((4, 3))
        fa, fb = rng.standard_normal(2)
        ha, hb = fa + rho / 2 * xa @ xa, fb + rho / 2 * xb @ xb
        sa, sb = ga + rho * xa, gb + rho * xb
        X = np.array([xa, xb, ga, gb])
        convex = ha - hb - sb @ (xa - xb)
        assert _value(wc, fa - fb, X) == pytest.approx(convex)
        smooth = convex - (sa - sb) @ (sa - sb) / (2 * (L + rho))
        assert _value(swc, fa - fb, X) == pytest.approx((L + rho) * smooth)
    for name, params in (("weakly_convex", {"rho": Fraction(3, 4)}),
                         ("smooth_weakly_convex", {"rho": Fraction(3, 4), "L": Fraction(2)})):
        cls = CLASSES[name]
        exact, source = exact_class_inequalities(cls, {k: Ball(v) for k, v in params.items()})
        floats = cls.tilted({k: float(v) for k, v in params.items()})
        assert source == "exact" and len(exact) == len(floats)
        for (alpha, Q), fl in zip(exact, floats, strict=True):
            assert float(alpha.c) == pytest.approx(fl.alpha) and alpha.r == 0
            assert np.allclose(np.array([[float(b.c) for b in r] for r in Q]), fl.Q)


@pytest.mark.parametrize("key", list(PEPIT))
def test_gradient_descent_agrees_with_pepit(tmp_path, key):
    """PEPit's value within its solver's accuracy; proven from above, witnessed below."""
    L, rho, gamma, steps = key
    doc = _pep(tmp_path, _gradient_spec(tmp_path, L), steps, (f"rw={rho}", f"gamma={gamma}"))
    pepit = PEPIT[key]
    assert doc["tau"] == pytest.approx(pepit, rel=1e-5)
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert pepit * (1 - 1e-5) <= upper <= pepit * (1 + 1e-5)
    check = doc["witness"]["check"]
    assert check["verified"] and Fraction(check["tau_lower"]) >= pepit * (1 - 1e-4)


def _concave_ratio(rho: float, gamma: float, steps: int) -> float:
    """|x_N - x_N-1|^2 / (f(x_0) - f(x_N)) of the proximal point method on f = -rho/2
    |x|^2 (in the class): x_k = q^k x_0 with q = 1/(1 - gamma rho)."""
    q = 1 / (1 - gamma * rho)
    return 2 * (q - 1) ** 2 * q ** (2 * steps - 2) / (rho * (q ** (2 * steps) - 1))


@pytest.mark.parametrize("rho,gamma", [(1.0, 0.5), (0.5, 1.0), (2.0, 0.2), (1.0, 0.9)])
def test_proximal_point_one_step_is_the_closed_form(tmp_path, rho, gamma):
    """N = 1: f(x_0) - f(x_1) >= gamma (1 - rho gamma/2) |u|^2 (weak convexity between
    x_0 and x_1), attained by f = -rho/2 |x|^2: tau_1 = gamma/(1 - rho gamma/2), proven."""
    doc = _pep(tmp_path, PROX, 1, (f"rho_w={rho}", f"gamma={gamma}"))
    ref = gamma / (1 - rho * gamma / 2)
    assert _concave_ratio(rho, gamma, 1) == pytest.approx(ref)
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert ref * (1 - 1e-9) <= upper <= ref * (1 + 1e-6)
    assert doc["witness"]["check"]["verified"]


def _separable_weakly_convex(rng: np.random.Generator, rho: float, d: int):
    """f(x) = sum_i a_i |z_i - c_i| + b_i z_i - r_i/2 (z_i - e_i)^2 with z = R x (R a
    rotation), r_i <= rho: rho-weakly convex, nonsmooth; (value, prox) with the prox in
    closed form for gamma r_i < 1."""
    R = np.linalg.qr(rng.standard_normal((d, d)))[0]
    a, b = rng.uniform(0, 1, d), rng.standard_normal(d)
    c, e = rng.standard_normal(d), rng.standard_normal(d)
    r = rho * rng.uniform(0, 1, d)
    r[0] = rho

    def value(x):
        z = R @ x
        return float(np.sum(a * np.abs(z - c) + b * z - r / 2 * (z - e) ** 2))

    def prox(v, gamma):
        t = gamma / (1 - gamma * r)  # the quadratics merged: one l1 prox of step t
        w = t * ((R @ v) / gamma - r * e - b)
        return R.T @ (c + np.sign(w - c) * np.maximum(np.abs(w - c) - t * a, 0))

    return value, prox


@pytest.mark.parametrize("steps", [2, 3])
def test_proximal_point_functions_never_beat_the_proven_bound(tmp_path, steps):
    """The proximal point method on random nonsmooth weakly convex functions, from random
    starts: |x_N - x_N-1|^2 <= tau_proven (f(x_0) - f(x_N)); the concave quadratic
    reaches the PEP's value at these parameters."""
    rho, gamma = 1.0, 0.5
    doc = _pep(tmp_path, PROX, steps, ())
    upper = float(Fraction(doc["certificate"]["tau_proven"]))
    assert doc["tau"] == pytest.approx(_concave_ratio(rho, gamma, steps), rel=1e-6)
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(400):
        d = int(rng.integers(1, 4))
        value, prox = _separable_weakly_convex(rng, rho, d)
        xs = [rng.standard_normal(d) * rng.uniform(0.1, 3)]
        for _ in range(steps):
            xs.append(prox(xs[-1], gamma))
        drop = value(xs[0]) - value(xs[-1])
        step = float((xs[-1] - xs[-2]) @ (xs[-1] - xs[-2]))
        assert step <= upper * drop + 1e-9 * (1 + abs(value(xs[0])))
        worst = max(worst, step / drop if drop > 1e-9 else 0.0)
    assert 0 < worst <= upper * (1 + 1e-9)


def test_gradient_functions_never_beat_the_proven_bound(tmp_path):
    """Gradient descent on random f = sum_i q_i/2 z_i^2 + s_i cos(w_i z_i) (z = R x), with
    curvature q_i + [-s_i w_i^2, s_i w_i^2] inside [-rho, L]: min_k |grad f(x_k)|^2 <=
    tau_proven (f(x_0) - f(x_N))."""
    L, rho, gamma, steps = 1.0, 0.5, 1.0, 3
    doc = _pep(tmp_path, _gradient_spec(tmp_path, L), steps, (f"rw={rho}", f"gamma={gamma}"))
    upper = float(Fraction(doc["certificate"]["tau_proven"]))
    rng = np.random.default_rng(9)
    worst = 0.0
    for _ in range(300):
        d = int(rng.integers(1, 4))
        R = np.linalg.qr(rng.standard_normal((d, d)))[0]
        q = rng.uniform(-rho, L, d)
        w = rng.uniform(0.5, 3, d)
        s = rng.uniform(0, 1, d) * np.minimum(q + rho, L - q) / w ** 2

        def f(x, R=R, q=q, w=w, s=s):
            z = R @ x
            return float(np.sum(q / 2 * z * z + s * np.cos(w * z)))

        def grad(x, R=R, q=q, w=w, s=s):
            z = R @ x
            return R.T @ (q * z - s * w * np.sin(w * z))

        xs = [rng.standard_normal(d) * rng.uniform(0.1, 3)]
        for _ in range(steps):
            xs.append(xs[-1] - gamma * grad(xs[-1]))
        drop = f(xs[0]) - f(xs[-1])
        least = min(float(grad(x) @ grad(x)) for x in xs)
        assert least <= upper * drop + 1e-9
        worst = max(worst, least / drop if drop > 1e-9 else 0.0)
    assert 0 < worst <= upper


def test_a_witness_outside_the_class_is_refused(tmp_path):
    """The N = 2 witness at rho = 1/2 (a concave quadratic of curvature -1/2) verifies;
    the same witness claimed for rho = 1/8 is outside that class: refused (exit 3)."""
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(PROX), "--steps", "2", "--set", "rho_w=0.5",
                                 "--no-plot", "--out", str(out)])
    assert r.exit_code == 0, r.output
    honest = json.loads((out / "proximal-point-weakly-convex-pep-N2-witness.json")
                        .read_text(encoding="utf-8"))
    for key in ("set", "spec_text", "source"):
        honest.pop(key, None)
    text = PROX.read_text(encoding="utf-8").replace("gamma: {value: 1/(2*rho_w)}",
                                                    "gamma: {value: 1}")
    for rho, text_rho, code in ((0.5, "1/2", 0), (0.125, "1/8", 3)):
        spec = tmp_path / f"rho{code}.yaml"
        spec.write_text(text.replace("rho_w: {value: L}", f"rho_w: {{value: {text_rho}}}"),
                        encoding="utf-8")
        doc = json.loads(json.dumps(honest))
        doc["functions"]["f"]["params"]["rho"] = rho
        doc["class"]["functions"]["f"]["params"]["rho"] = text_rho
        path = tmp_path / f"w{code}.json"
        path.write_text(json.dumps(doc), encoding="utf-8")
        res = CliRunner().invoke(cli, ["verify", str(path), "--spec", str(spec), "--out",
                                       str(tmp_path / "v")])
        assert res.exit_code == code, res.output


@pytest.mark.parametrize("args,field", [
    (["analyze"], "functions"),
    (["pep", "--steps", "2", "--set", "rho_w=-1", "--set", "gamma=1"], "functions.f.rho"),
    (["pep", "--steps", "2", "--measure", "dist"], "--measure"),
    (["pep", "--steps", "2", "--initial", "f(x_0)"], "--initial"),
])
def test_bad_input_one_line(tmp_path, args, field):
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, [args[0], str(PROX), *args[1:], "--out", str(out)])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and field in lines[0] and "Traceback" not in r.output
    assert not out.exists()


def test_smooth_rho_above_L_is_refused(tmp_path):
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(_gradient_spec(tmp_path, 1)), "--steps", "2",
                                 "--set", "rw=2", "--out", str(out)])
    assert r.exit_code == 2 and "functions.f.rho: must be at most L" in r.output
    assert len(r.output.strip().splitlines()) == 1 and not out.exists()
