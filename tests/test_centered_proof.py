"""Exact proofs of PEPs whose optimal dual S is singular on a large subspace
(sosalgo.worstcase.centered): a slightly larger bound proven from a certificate pushed
into the interior and projected exactly.

OGM-G (Kim and Fessler) is judged against its tight closed form 2 L (f(x_0) - f*) /
theta_0^2 (its sequence run backwards from theta_N = 1), evaluated in sympy, and against
the method run in numpy on explicit smooth convex functions; verify re-proves the
document and refuses it tampered. The per-step matrices of a schedule written as decimals
are the decimals exactly (not balls), judged against the decimals parsed as fractions.
"""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from click.testing import CliRunner

from sosalgo.cli import cli

SPECS = Path(__file__).resolve().parent.parent / "specs"


def _thetas(n: int) -> list[sp.Expr]:
    """OGM-G's theta_0..theta_N, exact: theta_N = 1, theta_i = (1 + sqrt(1 + 4
    theta_{i+1}^2)) / 2, theta_0 = (1 + sqrt(1 + 8 theta_1^2)) / 2."""
    th = [sp.Integer(1)]
    for i in range(n - 1, -1, -1):
        c = 8 if i == 0 else 4
        th.insert(0, (1 + sp.sqrt(1 + c * th[0] ** 2)) / 2)
    return th


def _schedule(n: int) -> tuple[list[str], list[str]]:
    """OGM-G's beta_k, gamma_k as the decimals of their floats, computed as PEPit's
    example does (the conformance command's): y_{k+1} = x_k - grad/L, x_{k+1} = y_{k+1} +
    beta_k (y_{k+1} - y_k) + gamma_k (y_{k+1} - x_k), beta_k = (theta_k - 1)
    (2 theta_{k+1} - 1) / (theta_k (2 theta_k - 1)), gamma_k = (2 theta_{k+1} - 1) /
    (2 theta_k - 1)."""
    th = [1.0]
    for i in range(n):
        th.append((1 + math.sqrt((8 if i == n - 1 else 4) * th[i] ** 2 + 1)) / 2)
    th.reverse()
    beta = [(th[k] - 1) * (2 * th[k + 1] - 1) / th[k] / (2 * th[k] - 1) for k in range(n)]
    gamma = [(2 * th[k + 1] - 1) / (2 * th[k] - 1) for k in range(n)]
    return [repr(v) for v in beta], [repr(v) for v in gamma]


def _json(text: str) -> dict:
    return json.JSONDecoder().raw_decode(text[text.index("{"):])[0]


def _ogmg(tmp_path: Path, n: int) -> tuple[dict, Path, list[str], list[str]]:
    beta, gamma = _schedule(n)
    res = CliRunner().invoke(cli, [
        "pep", str(SPECS / "momentum-schedule.yaml"), "--steps", str(n),
        "--set", f"beta=[{', '.join(beta)}]", "--set", f"gamma=[{', '.join(gamma)}]",
        "--measure", "grad", "--initial", "f", "--json", "--out", str(tmp_path),
        "--no-witness", "--no-plot"])
    assert res.exit_code == 0, res.output
    doc = _json(res.output)
    row = doc["rows"][-1] if "rows" in doc else doc
    return row, tmp_path / f"momentum-schedule-pep-N{n}.json", beta, gamma


def _proven_claim(path: Path) -> str:
    """verify's status of the document's certificate.tau_proven claim ("" if none)."""
    doc = _json(CliRunner().invoke(cli, ["verify", str(path), "--json"]).output)
    found: list[str] = []

    def walk(o: object) -> None:
        if isinstance(o, dict):
            for c in o.get("claims", []) if isinstance(o.get("claims"), list) else []:
                if c["field"].endswith("certificate.tau_proven"):
                    found.append(c["status"])
            for v in o.values():
                walk(v)
        elif isinstance(o, list):
            for v in o:
                walk(v)

    walk(doc)
    return found[0] if found else ""


def _run_ogmg(grad, x0: np.ndarray, beta: list[float], gamma: list[float]) -> np.ndarray:
    """x_N of OGM-G (L = 1) from y_0 = x_0, in numpy."""
    x, y = x0.copy(), x0.copy()
    for b, c in zip(beta, gamma, strict=True):
        y_next = x - grad(x)
        x = y_next + b * (y_next - y) + c * (y_next - x)
        y = y_next
    return x


def _huber(x: np.ndarray, t: float) -> tuple[float, np.ndarray]:
    """(value, gradient) of the Huber function of width t: 1-smooth, convex, min 0 at 0."""
    a = np.abs(x)
    return float(np.sum(np.where(a <= t, x * x / 2, t * a - t * t / 2))), np.clip(x, -t, t)


def _never_above(tau: float, beta: list[float], gamma: list[float]) -> None:
    """|grad f(x_N)|^2 <= tau (f(x_0) - f*) on random convex 1-smooth quadratics and
    Huber functions (x* = 0, f* = 0), computed in numpy alone."""
    rng = np.random.default_rng(7)
    for i in range(300):
        d = int(rng.integers(1, 5))
        if i % 2:
            U, _ = np.linalg.qr(rng.standard_normal((d, d)))
            H = U @ np.diag(rng.uniform(0, 1, d)) @ U.T

            def oracle(x: np.ndarray, H: np.ndarray = H) -> tuple[float, np.ndarray]:
                return 0.5 * float(x @ H @ x), H @ x
        else:
            width = float(rng.uniform(0.01, 2))

            def oracle(x: np.ndarray, t: float = width) -> tuple[float, np.ndarray]:
                return _huber(x, t)
        x0 = rng.standard_normal(d) * rng.uniform(0.1, 5)
        xn = _run_ogmg(lambda x, o=oracle: o(x)[1], x0, beta, gamma)
        g = oracle(xn)[1]
        assert g @ g <= tau * oracle(x0)[0] * (1 + 1e-9) + 1e-15


@pytest.mark.parametrize("n", [4, 6])
def test_ogmg_proven_at_its_tight_closed_form(tmp_path, n):
    """OGM-G's certificate has S = 0: proven now, not below 2 / theta_0^2 (L = 1) and
    within 1e-6 above it; explicit functions stay below the proven bound."""
    row, _, beta, gamma = _ogmg(tmp_path, n)
    cert = row["certificate"]
    assert cert["check_kind"] == "exact (rational and ball arithmetic)"
    q = Fraction(cert["tau_proven"])
    closed = 2 / _thetas(n)[0] ** 2
    # the method run is OGM-G's with its coefficients rounded to decimals: its worst
    # case is the closed form up to about 1e-15 (relative)
    assert sp.Rational(q.numerator, q.denominator) >= closed * (1 - sp.Rational(1, 10**12))
    assert float(q) <= float(closed) * (1 + 1e-6)
    _never_above(float(q), [float(b) for b in beta], [float(c) for c in gamma])


def test_ogmg_verified_and_tampered_refused(tmp_path):
    """verify re-proves the centered proof from its exact multipliers; a multiplier
    changed by 1 %, dropped, or tau_proven lowered below the closed form is refused."""
    _, path, _, _ = _ogmg(tmp_path, 4)
    assert _proven_claim(path) == "backed"
    doc = json.loads(path.read_text())
    proof = doc["certificate"]["proof"]
    labels = sorted(proof["multipliers_exact"], key=lambda k: -Fraction(
        proof["multipliers_exact"][k]))
    lower = Fraction(2) / Fraction(float(_thetas(4)[0] ** 2)) * (1 - Fraction(1, 10**9))

    def scaled(p: dict) -> None:
        p["multipliers_exact"][labels[0]] = str(Fraction(p["multipliers_exact"][labels[0]])
                                                * Fraction(101, 100))

    def dropped(p: dict) -> None:
        del p["multipliers_exact"][labels[-1]]

    def lowered(p: dict) -> None:
        p["tau_proven"] = f"{lower.numerator}/{lower.denominator}"
        p["tau_proven_float"] = float(lower)

    for name, edit in (("scaled", scaled), ("dropped", dropped), ("lowered", lowered)):
        bad = json.loads(path.read_text())
        edit(bad["certificate"]["proof"])
        if name == "lowered":
            bad["certificate"]["tau_proven"] = bad["certificate"]["proof"]["tau_proven"]
        out = tmp_path / f"tampered-{name}.json"
        out.write_text(json.dumps(bad))
        assert _proven_claim(out) != "backed", name


def test_schedule_decimals_are_exact_per_step_matrices():
    """A schedule written as decimals gives exact per-step matrices (the decimals as
    fractions), though the spec's reference sequence theta grows nested radicals."""
    from sosalgo.runs import spec_with_text
    from sosalgo.steps import exact_steps

    beta, gamma = _schedule(6)
    spec, _ = spec_with_text(SPECS / "momentum-schedule.yaml", overrides={
        "beta": f"[{', '.join(beta)}]", "gamma": f"[{', '.join(gamma)}]"}, varying=True)
    mats = exact_steps(spec, None, 6)
    assert mats is not None
    for k, step in enumerate(mats):
        b, c = Fraction(beta[k]), Fraction(gamma[k])
        assert step["A"][1, 0] == sp.Rational(-b.numerator, b.denominator)
        assert step["B"][1, 0] == sp.Rational(-(1 + b + c).numerator, (1 + b + c).denominator)
