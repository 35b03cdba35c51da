"""Questions with no initial condition (``--initial none``) and quadratic-form terms
(``inner(P, Q)``, ``g(P)``, call points at any step): potential differences."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from sosalgo.cli import cli

from .conftest import pep_json

ROOT = Path(__file__).resolve().parents[1]
GD = ROOT / "specs" / "gradient-convex.yaml"
# Bansal and Gupta (2019), Thm 3.3: V_n = n (f(x_n) - f*) + L/2 |x_n - x*|^2 does not
# increase along gradient descent with step 1/L on L-smooth convex f
LYAP1 = "11*f(x_N) + L/2*dist(x_N) - 10*f(x_0) - L/2*dist(x_0)"


def _row(doc: dict) -> dict:
    return doc["rows"][-1] if "rows" in doc else doc


def test_potential_difference_proven_zero(tmp_path: Path) -> None:
    row = _row(pep_json(GD, tmp_path, 1, "--initial", "none", "--measure", LYAP1,
                        "--no-plot"))
    assert row["tau"] == 0.0  # the theorem's value: V_{n+1} - V_n <= 0, reached at x = x*
    assert row["certificate"]["tau_proven"] == "0"
    doc = next(tmp_path.glob("gradient-convex-pep-N1.json"))
    ok = CliRunner().invoke(cli, ["verify", str(doc)])
    assert ok.exit_code == 0, ok.output
    data = json.loads(doc.read_text())
    r = _row(data)
    lab = next(iter(r["certificate"]["proof"]["multipliers_exact"]))
    r["certificate"]["proof"]["multipliers_exact"][lab] = "1/1000"  # tampered
    bad = tmp_path / "tampered.json"
    bad.write_text(json.dumps(data))
    assert CliRunner().invoke(cli, ["verify", str(bad)]).exit_code == 3


def test_positive_measure_is_unbounded(tmp_path: Path) -> None:
    # f(x_1) - f* + |x_1 - x*|^2 > 0 off x*: with no normalization it grows without bound
    row = _row(pep_json(GD, tmp_path, 1, "--initial", "none", "--measure",
                        "f(x_N) + dist(x_N)", "--no-plot", "--no-witness"))
    assert row["status"] == "unbounded" and row["tau"] == float("inf")
    assert row["certificate"] is None


def test_potential_decrease_on_explicit_functions() -> None:
    """Soundness, judged in numpy alone: gradient descent h = 1/L on random L-smooth
    convex functions (quadratics and softplus sums) never increases V_n (tau_proven = 0)."""
    rng = np.random.default_rng(7)
    L, n = 1.0, 10
    for trial in range(200):
        d = 3
        if trial % 2:
            U = np.linalg.qr(rng.normal(size=(d, d)))[0]
            H = U @ np.diag(rng.uniform(0, L, d)) @ U.T
            xs = rng.normal(size=d)

            def f(x, H=H, xs=xs):
                return 0.5 * (x - xs) @ H @ (x - xs)

            def g(x, H=H, xs=xs):
                return H @ (x - xs)
            fs = 0.0
        else:  # softplus(a x) + softplus(-a x) has its minimum at 0; curvature <= |a|^2/4
            a = rng.normal(size=d)
            a *= 2 * np.sqrt(L) / np.linalg.norm(a) * rng.uniform(0.2, 1)
            xs = np.zeros(d)

            def f(x, a=a):
                return np.logaddexp(0, a @ x) + np.logaddexp(0, -a @ x)

            def g(x, a=a):
                s = 1 / (1 + np.exp(-(a @ x)))
                return a * (2 * s - 1)
            fs = 2 * np.log(2)
        x = rng.normal(size=d) * rng.uniform(0.1, 10)
        x1 = x - g(x) / L
        v0 = n * (f(x) - fs) + L / 2 * np.sum((x - xs) ** 2)
        v1 = (n + 1) * (f(x1) - fs) + L / 2 * np.sum((x1 - xs) ** 2)
        assert v1 - v0 <= 1e-9 * (1 + abs(v0)), (trial, v1 - v0)


def test_inner_and_call_points_parse() -> None:
    from sosalgo.pep.terms import parse_terms

    terms = parse_terms("2*inner(x_0, g(y_0)) - grad(y_0) + inner(y_1, x_N)", "--measure",
                        False, 1)
    assert {(t.kind, t.point) for t in terms} == {("inner", "Gy1t0__x0"),
                                                  ("grad", "y1t0"),
                                                  ("inner", "x__y1t1")}
    assert parse_terms("none", "--initial", True, 1) == []


def test_bad_terms_exit_2(tmp_path: Path) -> None:
    for measure in ("free", "inner(x_0)", "inner(x_0, z_0)"):
        r = CliRunner().invoke(cli, ["pep", str(GD), "--steps", "1", "--initial", "none",
                                     "--measure", measure, "--out", str(tmp_path)])
        assert r.exit_code == 2, (measure, r.output)
        assert "--measure" in r.output
