"""Exact PEP proofs over a quadratic field Q(sqrt d) (sosalgo.worstcase.field_proof).

The arithmetic is judged against mpmath at 60 digits; the proven bounds against the
closed forms of the examples (accelerated gradient flow: -sqrt(mu) and -4/3 sqrt(mu);
robust momentum: its Lyapunov rate r^2; the accelerated potential: 0), evaluated in
sympy; verify re-proves the documents and refuses tampered ones.
"""

from __future__ import annotations

import json
import random
from fractions import Fraction
from pathlib import Path

import mpmath
import numpy as np
import pytest
import sympy as sp
from click.testing import CliRunner

from sosalgo.cli import cli
from sosalgo.kernel.qfield import QSqrt, field_psd, radicand, recognize, to_field

ROOT = Path(__file__).resolve().parent.parent
CONF = ROOT / "bench" / "conformance" / "specs"


def _mp(x: QSqrt) -> mpmath.mpf:
    return mpmath.mpf(x.a.numerator) / x.a.denominator + \
        mpmath.mpf(x.b.numerator) / x.b.denominator * mpmath.sqrt(x.d)


def test_field_arithmetic_and_exact_sign_against_mpmath():
    """+, -, *, / and the sign of a + b sqrt(d), including Pell-type near-zeros
    (721 - 228 sqrt(10) ~ 7e-4, 27379 - 8658 sqrt(10) ~ 1.8e-5, its negative)."""
    rng = random.Random(5)
    with mpmath.workdps(60):
        for _ in range(200):
            d = rng.choice([2, 3, 5, 10, 37])
            x = QSqrt(Fraction(rng.randint(-50, 50), rng.randint(1, 9)),
                      Fraction(rng.randint(-50, 50), rng.randint(1, 9)), d)
            y = QSqrt(Fraction(rng.randint(-50, 50), rng.randint(1, 9)),
                      Fraction(rng.randint(-50, 50), rng.randint(1, 9)), d)
            for got, want in ((x + y, _mp(x) + _mp(y)), (x - y, _mp(x) - _mp(y)),
                              (x * y, _mp(x) * _mp(y))):
                assert abs(_mp(got) - want) < mpmath.mpf(10) ** -50
            if y:
                assert abs(_mp(x / y) - _mp(x) / _mp(y)) < mpmath.mpf(10) ** -40
            assert x.sign() == (0 if _mp(x) == 0 else (1 if _mp(x) > 0 else -1))
        for a, b in ((721, -228), (27379, -8658), (-27379, 8658), (19, -6)):
            q = QSqrt(a, b, 10)
            assert q.sign() == (1 if _mp(q) > 0 else -1)
            assert q.upper() >= q and _mp(q.upper() - q) < mpmath.mpf(10) ** -25
            assert abs(float(q) - _mp(q)) < 1e-12 * abs(_mp(q))
    assert QSqrt(19, -6, 10) > 0 and QSqrt(-19, 6, 10) < 0 and QSqrt(0, 0, 10) == 0


def test_to_field_radicand_and_recognize():
    mu = sp.Rational(1, 10)
    assert radicand([sp.sqrt(mu), 2 * sp.sqrt(10) + 1, sp.Rational(3, 7)]) == 10
    assert radicand([sp.sqrt(2), sp.sqrt(3)]) is None  # two square roots: no one field
    assert radicand([sp.cbrt(2)]) is None and radicand([sp.pi]) is None
    r = sp.Rational(1, 5) * (1 - mu) + sp.Rational(4, 5) * (1 - 1 / sp.sqrt(10))
    x = to_field(r ** 2, 10)
    with mpmath.workdps(60):
        assert abs(_mp(x) - mpmath.mpf(sp.N(r ** 2, 60))) < mpmath.mpf(10) ** -50
    with pytest.raises(ValueError):
        to_field(sp.sqrt(2), 10)
    assert recognize(float(x), 10, 10 ** 4, 1e-11) == x
    assert recognize(-float(sp.sqrt(mu)), 10, 100, 1e-9) == QSqrt(0, Fraction(-1, 10), 10)


def test_field_psd_decides_a_singular_matrix_with_an_irrational_null_vector():
    """u u' with u = (1, sqrt 2, 1 + sqrt 2) is PSD (rank one: the zero Schur complement
    is exactly 0); moving one entry by 1e-30 makes it indefinite, which balls at any
    width around the exact zero could not tell."""
    s2 = QSqrt(0, 1, 2)
    u = [QSqrt(1, 0, 2), s2, 1 + s2]
    S = [[a * b for b in u] for a in u]
    assert field_psd(S)[0]
    bad = [row[:] for row in S]
    bad[2][2] = bad[2][2] - Fraction(1, 10 ** 30)
    assert not field_psd(bad)[0]


def _pep(out: Path, spec: Path, *args: str) -> dict:
    res = CliRunner().invoke(cli, ["pep", str(spec), *args, "--json", "--out", str(out),
                                   "--no-witness", "--no-plot"])
    assert res.exit_code == 0, res.output
    doc = _json(res.output)
    return doc["rows"][-1] if "rows" in doc else doc


def _json(text: str) -> dict:
    """The JSON document in a command's output (stderr lines may follow it)."""
    return json.JSONDecoder().raw_decode(text[text.index("{"):])[0]


def _claims(path: Path) -> dict[str, str]:
    res = CliRunner().invoke(cli, ["verify", str(path), "--json"])
    doc = _json(res.output)
    found: dict[str, str] = {}

    def walk(o):  # type: ignore[no-untyped-def]
        if isinstance(o, dict):
            for c in o.get("claims", []) if isinstance(o.get("claims"), list) else []:
                for key in ("certificate.tau_proven", "tau"):  # by the field's ending
                    if c["field"].endswith("json." + key) or c["field"].endswith("." + key):
                        found.setdefault(key, c["status"])
            for v in o.values():
                walk(v)
        elif isinstance(o, list):
            for v in o:
                walk(v)
    walk(doc)
    return found


def _quadratic(rng: np.random.Generator, dim: int, m: float, L: float) -> np.ndarray:
    """A random Hessian with eigenvalues in [m, L] (ends included), rotated."""
    Q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
    ev = np.concatenate([[m, L], rng.uniform(m, L, dim - 2)])
    return Q @ np.diag(ev) @ Q.T


def _flow_never_above(tau: float, mu: float) -> None:
    """dV/dt <= tau V for the flow x'' = -2 sqrt(mu) x' - grad f, V = f - f* +
    |sqrt(mu) (x - x*) + x'|^2 / 2, on random mu-strongly convex quadratics f = x'Hx/2
    (x* = 0) and random (x, x'), every third one on the extremal f = mu |x|^2 / 2 with a
    small x' (where dV/dt = -sqrt(mu) V is reached as x' -> 0), computed in numpy alone."""
    rng = np.random.default_rng(3)
    s = np.sqrt(mu)
    for k in range(300):
        extremal = k % 3 == 0
        H = mu * np.eye(4) if extremal else _quadratic(rng, 4, mu, rng.uniform(mu, 50 * mu))
        x = rng.standard_normal(4)
        v = rng.standard_normal(4) * (rng.uniform(0, 1e-3) if extremal
                                      else rng.uniform(0.01, 10))
        g = H @ x
        acc = -2 * s * v - g
        V = x @ H @ x / 2 + (s * x + v) @ (s * x + v) / 2
        dV = g @ v + (s * x + v) @ (s * v + acc)
        assert dV <= tau * V + 1e-9 * abs(V)


def _robust_momentum_never_above(tau: float, m: float, L: float, lam: float) -> None:
    """V_2 <= tau V_1 for the robust momentum method (Cyrus et al. 2018: its alpha, beta,
    gamma from rho = r) on random quadratics of F(m, L) from two random start points, V_k
    = l |z_k|^2 + (L - m)(f(y) - m/2 |y|^2) - |grad f(y) - m y|^2 / 2 as in its paper
    (x* = 0), computed in numpy alone."""
    kappa = L / m
    r = lam * (1 - 1 / kappa) + (1 - lam) * (1 - 1 / np.sqrt(kappa))
    alpha = kappa * (1 - r) ** 2 * (1 + r) / L
    beta = kappa * r ** 3 / (kappa - 1)
    gamma = r ** 3 / ((kappa - 1) * (1 - r) ** 2 * (1 + r))
    ell = m ** 2 * (kappa - kappa * r ** 2 - 1) / (2 * r * (1 - r))
    rng = np.random.default_rng(4)

    def V(H: np.ndarray, x_new: np.ndarray, x_old: np.ndarray, y: np.ndarray) -> float:
        z = (x_new - r ** 2 * x_old) / (1 - r ** 2)
        g = H @ y
        return float(ell * z @ z + (L - m) * (y @ H @ y / 2 - m / 2 * y @ y)
                     - (g - m * y) @ (g - m * y) / 2)

    for _ in range(300):
        H = _quadratic(rng, 4, m, L)
        xs = [rng.standard_normal(4), rng.standard_normal(4)]  # x_{-1}, x_0
        ys = []
        for _k in range(2):
            y = -gamma * xs[-2] + (1 + gamma) * xs[-1]
            ys.append(y)
            xs.append(-beta * xs[-2] + (1 + beta) * xs[-1] - alpha * (H @ y))
        v1, v2 = V(H, xs[2], xs[1], ys[0]), V(H, xs[3], xs[2], ys[1])
        assert v2 <= tau * v1 + 1e-9 * abs(v1)


def _potential_never_increases(lam: float, L: float) -> None:
    """One step of the accelerated method of PEPit's potential example on random convex
    L-smooth quadratics (x* = 0, f* = 0) never increases lam^2 f(x) + L/2 |z|^2 (the
    value 0 proven), computed in numpy alone."""
    rng = np.random.default_rng(5)
    lam1 = (1 + np.sqrt(4 * lam ** 2 + 1)) / 2
    tau, eta, gamma = 1 / lam1, (lam1 ** 2 - lam ** 2) / L, 1 / L
    for _ in range(300):
        H = _quadratic(rng, 4, 0.0, L)
        x, z = rng.standard_normal(4), rng.standard_normal(4)
        y = (1 - tau) * x + tau * z
        g = H @ y
        x1, z1 = y - gamma * g, z - eta * g
        before = lam ** 2 * x @ H @ x / 2 + L / 2 * z @ z
        after = lam1 ** 2 * x1 @ H @ x1 / 2 + L / 2 * z1 @ z1
        assert after - before <= 1e-9 * before


def _below(q: Fraction, closed: sp.Expr) -> bool:
    """q < closed, decided by sympy exactly (the closed form is a quadratic surd)."""
    return bool(sp.simplify(sp.Rational(q.numerator, q.denominator) - closed).is_negative)


@pytest.mark.parametrize("spec, mu, closed", [
    ("accelerated-gradient-flow-strongly-convex.yaml", "1/10", lambda m: -sp.sqrt(m)),
    ("accelerated-gradient-flow-strongly-convex.yaml", "1/5", lambda m: -sp.sqrt(m)),
    ("accelerated-gradient-flow-strongly-convex-nonpsd.yaml", "1/10",
     lambda m: -sp.Rational(4, 3) * sp.sqrt(m)),
], ids=["psd-mu0.1", "psd-mu0.2", "nonpsd-mu0.1"])
def test_flow_rate_proven_at_its_closed_form(tmp_path, spec, mu, closed):
    """The flow's rate (PEPit: -sqrt(mu) with psd, -4/3 sqrt(mu) without) is proven in
    Q(sqrt d), never below the closed form and within 1e-9 above it."""
    row = _pep(tmp_path, CONF / spec, "--steps", "1", "--set", f"mu={mu}")
    cert = row["certificate"]
    assert cert["check_kind"] == "exact (quadratic field arithmetic)"
    q = Fraction(cert["tau_proven"])
    tight = closed(sp.Rational(mu))
    assert not _below(q, tight)
    assert float(q) - float(tight) < 1e-9 * abs(float(tight))
    assert sp.simplify(sp.sympify(cert["proof"]["tau_exact_text"]) - tight) == 0
    if "nonpsd" not in spec:
        _flow_never_above(float(q), float(sp.Rational(mu)))


def test_robust_momentum_proven_at_its_rate_and_verified(tmp_path):
    """Robust momentum (kappa = 10, lam = 1/5): the Lyapunov ratio's worst case is r^2,
    r = lam (1 - 1/kappa) + (1 - lam)(1 - 1/sqrt(kappa)) (Cyrus et al. 2018); proven
    not below it and within 1e-9; verify re-proves the document's bound and refuses it
    with a multiplier or tau_exact edited, or with the field changed."""
    row = _pep(tmp_path, CONF / "robust-momentum.yaml", "--kappa", "10", "--steps", "2",
               "--set", "lam=1/5")
    lam, kappa = sp.Rational(1, 5), 10
    r = lam * (1 - sp.Rational(1, kappa)) + (1 - lam) * (1 - 1 / sp.sqrt(kappa))
    q = Fraction(row["certificate"]["tau_proven"])
    assert not _below(q, r ** 2) and float(q) - float(r ** 2) < 1e-9
    _robust_momentum_never_above(float(q), 1.0, 10.0, 0.2)
    path = tmp_path / "robust-momentum-pep-k10-N2.json"
    assert _claims(path)["certificate.tau_proven"] == "backed"
    doc = json.loads(path.read_text())
    proof = doc["certificate"]["proof"]
    label = next(iter(proof["multipliers_exact"]))
    edits = [
        ("multipliers_exact", label, lambda v: [v[0], str(Fraction(v[1]) * Fraction(101, 100))]),
        ("tau_exact", None, lambda v: [str(Fraction(v[0]) - Fraction(1, 10 ** 6)), v[1]]),
        ("field", None, lambda v: {"sqrt": 11}),
    ]
    for key, sub, edit in edits:
        bad = json.loads(path.read_text())
        p = bad["certificate"]["proof"]
        if sub is None:
            p[key] = edit(p[key])
        else:
            p[key][sub] = edit(p[key][sub])
        out = tmp_path / f"tampered-{key}.json"
        out.write_text(json.dumps(bad))
        assert _claims(out)["certificate.tau_proven"] != "backed", key


def test_flow_tampered_tau_below_the_closed_form_is_refused(tmp_path):
    """A flow document whose tau_proven is lowered below -sqrt(mu) (its multipliers as
    proven) is refused: S is no longer PSD at it."""
    _pep(tmp_path, CONF / "accelerated-gradient-flow-strongly-convex.yaml", "--steps", "1",
         "--set", "mu=1/10")
    path = tmp_path / "accelerated-gradient-flow-strongly-convex-pep-N1.json"
    assert _claims(path)["certificate.tau_proven"] == "backed"
    doc = json.loads(path.read_text())
    lower = Fraction(-3163, 10000)  # below -sqrt(1/10) = -0.31622...
    for where in (doc["certificate"], doc["certificate"]["proof"]):
        where["tau_proven"] = f"{lower.numerator}/{lower.denominator}"
    doc["certificate"]["proof"]["tau_proven_float"] = float(lower)
    out = tmp_path / "tampered.json"
    out.write_text(json.dumps(doc))
    assert _claims(out)["certificate.tau_proven"] != "backed"


def test_accelerated_potential_proven_zero(tmp_path):
    """PEPit's accelerated potential example (lam = 3: lam+ = (1 + sqrt(37))/2): the
    potential's increase is <= 0 for every instance, proven exactly in Q(sqrt 37) and
    verified (tau = 0 has the zero instance below it)."""
    _pep(tmp_path, CONF / "accelerated-gradient-potential.yaml", "--steps", "1",
         "--set", "lam=3", "--set", "gamma=1/L")
    path = tmp_path / "accelerated-gradient-potential-pep-N1.json"
    doc = json.loads(path.read_text())
    assert doc["certificate"]["tau_proven"] == "0"
    assert doc["certificate"]["proof"]["field"] == {"sqrt": 37}
    res = CliRunner().invoke(cli, ["verify", str(path)])
    assert res.exit_code == 0, res.output
    _potential_never_increases(3.0, 1.0)
