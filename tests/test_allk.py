"""The bound for every N of a spec whose matrices are closed forms in k (docs/all-k.md):
Nesterov's method with momentum k/(k + 3) against the PEP's worst cases, the classical
constant 2L/(N + 1)^2 and the exact worst case 2L/((N + 2)(N + 3)); the exact check
against independent ones (an LDL at sampled k, trajectories on functions of the class);
tampered documents; the one-line refusals."""

from __future__ import annotations

import copy
import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.certificates.allk import closed_form_system, conditions
from sosalgo.certificates.exact_allk import (
    check_certificate,
    nonnegative_on_halfline,
    verify_allk_document,
)
from sosalgo.cli import cli
from sosalgo.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"
ACC = SPECS / "accelerated-k.yaml"


@pytest.fixture(scope="module")
def acc_doc(tmp_path_factory):
    from sosalgo.runs.allk import allk_run

    return allk_run(ACC, tmp_path_factory.mktemp("allk"))


def _bound(doc, N: int) -> Fraction:
    """C / a(N), exactly."""
    a = [Fraction(c) for c in doc["a"]]
    return Fraction(doc["constant_proven"]) / sum(c * N**j for j, c in enumerate(a))


def _cert(doc) -> dict[str, Fraction]:
    return {k: Fraction(v) for k, v in doc["certificate"].items()}


# --------------------------------------------------------------------------- the bound
def test_bound_is_proven_and_sits_between_the_worst_case_and_the_classical_bound(acc_doc):
    doc = acc_doc
    assert doc["certified"] and doc["verified"] == "exact" and doc["degree"] == 2
    C = Fraction(doc["constant_proven"])
    assert doc["constant"] >= C and C < Fraction(20005, 10000)  # within 0.025% of 2
    a0, a1, a2 = (Fraction(c) for c in doc["a"])
    assert a2 == 1 and a1 >= 2 and a0 >= 1  # a(N) >= (N + 1)^2
    for N in range(1, 2000):
        bound = _bound(doc, N)
        # never below the exact worst case 2L/((N + 2)(N + 3)) (the PEP's values below)
        assert bound >= Fraction(2, (N + 2) * (N + 3))
        # at most the classical 2L/(N + 1)^2 up to N = 1000, at most C/2 times it after
        assert bound <= Fraction(2, (N + 1) ** 2) * (1 if N <= 1000 else C / 2)


def test_bound_is_above_the_pep_worst_case(acc_doc):
    from sosalgo.runs.pep import pep_run

    pep = pep_run(ACC, steps="1..4", out_dir=None, progress=False, plot=False,
                  witness=False)
    rows = pep.get("rows", [pep])
    assert [r["steps"] for r in rows] == [1, 2, 3, 4]
    for r in rows:
        N = r["steps"]
        assert r["tau"] == pytest.approx(2 / ((N + 2) * (N + 3)), rel=1e-6)
        assert r["tau"] <= float(_bound(acc_doc, N))


@pytest.mark.deep
def test_bound_is_above_the_pep_worst_case_up_to_ten_steps(acc_doc):
    from sosalgo.runs.pep import pep_run

    pep = pep_run(ACC, steps="1..10", out_dir=None, progress=False, plot=False,
                  witness=False)
    for r in pep["rows"]:
        assert r["tau"] <= float(_bound(acc_doc, r["steps"]))


def test_bound_scales_with_L_between_the_closed_forms(tmp_path):
    """L = 1/2 (the proof is about f/L): the bound stays between the exact worst case
    2L/((N + 2)(N + 3)) and the classical 2L/(N + 1)^2."""
    from sosalgo.runs.allk import allk_run

    path = tmp_path / "acc.yaml"
    path.write_text(ACC.read_text().replace("\nL: 1\n", "\nL: 1/2\n"))
    doc = allk_run(path, tmp_path)
    assert doc["certified"] and doc["L"] == 0.5
    L = Fraction(1, 2)
    for N in range(1, 1000):
        assert 2 * L / ((N + 2) * (N + 3)) <= _bound(doc, N) <= 2 * L / (N + 1) ** 2


def test_gradient_method_gets_the_classical_order_1_bound(tmp_path):
    """Gradient descent with h_k = 1/L (a per-step parameter): no degree-2 potential, a
    degree-1 one: C/a(N) with a(N) >= N + 1, never below the tight L/(4N + 2) and within
    0.1% of the classical L/(2N)."""
    from sosalgo.runs.allk import allk_run

    doc = allk_run(SPECS / "gradient-schedule.yaml", tmp_path)
    assert doc["certified"] and doc["degree"] == 1
    C = Fraction(doc["constant_proven"])
    assert Fraction(1, 2) <= C <= Fraction(5005, 10000)
    for N in range(1, 3000):
        assert Fraction(1, 4 * N + 2) <= _bound(doc, N) <= Fraction(1, 2 * N) * Fraction(1001, 1000)


@pytest.mark.deep
def test_bound_at_the_extrapolated_point_is_above_the_pep(tmp_path):
    """momentum-schedule (the same method, f at the gradient's point x_N: the second form
    of (B)): proven, and above the PEP's worst case at N = 1..5."""
    from sosalgo.runs.allk import allk_run
    from sosalgo.runs.pep import pep_run

    spec = SPECS / "momentum-schedule.yaml"
    doc = allk_run(spec, tmp_path)
    assert doc["certified"] and doc["degree"] == 2
    pep = pep_run(spec, steps="1..5", out_dir=None, progress=False, plot=False,
                  witness=False)
    for r in pep["rows"]:
        assert r["tau"] <= float(_bound(doc, r["steps"]))


# --------------------------------------------------------------------------- independent
def _ldl_psd(M: list[list[Fraction]]) -> bool:
    """Whether a symmetric rational matrix is PSD: an LDL' with symmetric pivoting in
    exact fractions (a zero pivot needs a zero row)."""
    M = [row[:] for row in M]
    n = len(M)
    for i in range(n):
        j = max(range(i, n), key=lambda r: M[r][r])
        M[i], M[j] = M[j], M[i]
        for row in M:
            row[i], row[j] = row[j], row[i]
        piv = M[i][i]
        if piv < 0:
            return False
        if piv == 0:
            if any(M[i][c] != 0 for c in range(i, n)):
                return False
            continue
        for r in range(i + 1, n):
            f = M[r][i] / piv
            for c in range(i, n):
                M[r][c] -= f * M[i][c]
    return True


def test_exact_check_agrees_with_an_ldl_at_many_k(acc_doc):
    import sympy as sp

    system = closed_form_system(load_spec(ACC))
    cond = conditions(system, 2)
    sub = {v: sp.Rational(str(acc_doc["certificate"][str(v)])) for v in cond.variables}
    ks = [*range(0, 60), 97, 1000, 12345, 10**6, 10**9]
    for name in ("decrease", "bound"):
        M = cond.blocks[name].xreplace(sub)
        for k in ks:
            Mk = M.subs(system.k, k)
            neg = [[-Fraction(str(Mk[i, j])) for j in range(Mk.shape[1])]
                   for i in range(Mk.shape[0])]
            assert _ldl_psd(neg), (name, k)


def _potential(doc, k: int, xi: np.ndarray, g: np.ndarray, fval: float) -> float:
    cert = {n: float(Fraction(v)) for n, v in doc["certificate"].items()}
    s = xi.shape[0] + 1
    P = np.array([[sum(cert[f"P{min(i, j)}{max(i, j)}_{t}"] * k**t for t in range(3))
                   for j in range(s)] for i in range(s)])
    z = np.vstack([xi, g[None, :]])  # rows: the coordinates of xi, then g (d columns)
    p = sum(cert[f"p_{t}"] * k**t for t in range(3))
    return float(np.trace(z.T @ P @ z)) + p * fval


def _functions():
    """L-smooth convex functions of R^2 (L = 1) with minimizer 0 and f* = 0."""
    rng = np.random.default_rng(7)
    out = []
    for lam in ([1.0, 0.0], [1.0, 0.3], [0.05, 0.01]):
        Q, _ = np.linalg.qr(rng.normal(size=(2, 2)))
        H = Q @ np.diag(lam) @ Q.T
        out.append((lambda x, H=H: 0.5 * x @ H @ x, lambda x, H=H: H @ x))
    for delta in (0.01, 0.3):  # Huber in each coordinate
        out.append((lambda x, d=delta: float(np.sum(np.where(np.abs(x) <= d, x**2 / 2,
                                                              d * np.abs(x) - d**2 / 2))),
                    lambda x, d=delta: np.clip(x, -d, d)))
    return out


def test_potential_decreases_on_trajectories(acc_doc):
    """Independent of the proof: the certificate's phi_k on trajectories of the method on
    functions of the class never increases, and a(N) f(y_N) <= phi_0 <= C |x_0|^2."""
    C = float(Fraction(acc_doc["constant_proven"]))
    a = [float(Fraction(c)) for c in acc_doc["a"]]
    for f, grad in _functions():
        for x0 in (np.array([1.0, -2.0]), np.array([30.0, 5.0])):
            xi = np.vstack([x0, x0])  # at rest: y_0 = x_0
            g = grad(xi[1])
            phi = _potential(acc_doc, 0, xi, g, f(xi[1]))
            assert phi <= C * x0 @ x0 * (1 + 1e-9)
            for k in range(200):
                beta = k / (k + 3)
                y1 = xi[1] - g
                xi = np.vstack([y1, y1 + beta * (y1 - xi[0])])
                g = grad(xi[1])
                nxt = _potential(acc_doc, k + 1, xi, g, f(xi[1]))
                assert nxt <= phi + 1e-9 * max(1.0, abs(phi)), (k, nxt, phi)
                N = k + 1
                aN = sum(c * N**j for j, c in enumerate(a))
                assert aN * f(xi[0]) <= C * x0 @ x0 * (1 + 1e-9)
                phi = nxt


def test_nonnegative_on_halfline_against_sampling():
    import sympy as sp

    k = sp.Symbol("k")
    cases = {(k - 1) ** 2 * (k + 2): True, (k - 1) * (k - 2): False, k * (k + 1): True,
             -k: False, sp.Integer(0): True, (3 * k - 1) ** 2 * (k + 1): True,
             k**3 - k**2 / 1000: False, (k - 10**6) ** 2 + 1: True, k**2 - 2 * k + 1: True,
             -(k**2) - 1: False, k * (k - 1) ** 2 * (k - 2) ** 2: True, k - 1: False}
    grid = [Fraction(i, 7) for i in range(0, 200)] + [Fraction(10**6), Fraction(1, 3000)]
    for expr, expected in cases.items():
        poly = sp.Poly(expr, k, domain="QQ")
        assert nonnegative_on_halfline(poly) == expected, expr
        sampled = all(poly.eval(sp.Rational(q.numerator, q.denominator)) >= 0 for q in grid)
        if not sampled:
            assert expected is False


# --------------------------------------------------------------------------- tampering
def _verify(doc):
    spec = load_spec(ACC)
    return verify_allk_document(copy.deepcopy(doc), spec, "doc")[0]


def test_verify_reproves_and_refuses_tampered_documents(acc_doc):
    assert _verify(acc_doc)["verified"] == "exact"
    bad = copy.deepcopy(acc_doc)
    bad["constant"] = 1.9  # a claim below what is proven
    assert _verify(bad)["verified"] == "failed"
    bad = copy.deepcopy(acc_doc)
    bad["certificate"]["C"] = bad["constant_proven"] = "19/10"
    bad["constant"] = 1.9  # a smaller C: the initial block fails
    check = _verify(bad)
    assert check["verified"] == "failed" and "initial" in check["reason"]
    bad = copy.deepcopy(acc_doc)
    lam = Fraction(bad["certificate"]["lam01_0"])
    bad["certificate"]["lam01_0"] = str(lam * Fraction(101, 100))  # breaks an identity
    assert _verify(bad)["verified"] == "failed"
    bad = copy.deepcopy(acc_doc)
    bad["a"][1] = str(Fraction(bad["a"][1]) + 1)  # claims a larger a(N)
    assert _verify(bad)["verified"] == "failed"


def test_tampered_weights_are_judged_as_an_independent_check_judges_them(acc_doc):
    """Each tampered certificate: the verifier proves it only if an LDL at sampled k
    also finds every block PSD (a change within the margin may remain a certificate)."""
    import sympy as sp

    system = closed_form_system(load_spec(ACC))
    cond = conditions(system, 2)
    for name, factor in (("P22_2", Fraction(1, 2)), ("P00_1", Fraction(11, 10)),
                         ("P22_0", Fraction(9, 10)), ("mu10_1", Fraction(3, 2))):
        cert = _cert(acc_doc)
        cert[name] *= factor
        proof = check_certificate(cond, cert, Fraction(1), system.k)
        if proof.verified != "exact":
            continue
        sub = {v: sp.Rational(cert[str(v)].numerator, cert[str(v)].denominator)
               for v in cond.variables}
        for block in ("decrease", "bound"):
            M = cond.blocks[block].xreplace(sub)
            for k in (0, 1, 2, 5, 10, 100, 10**4, 10**8):
                Mk = M.subs(system.k, k)
                neg = [[-Fraction(str(Mk[i, j])) for j in range(Mk.shape[1])]
                       for i in range(Mk.shape[0])]
                assert _ldl_psd(neg), (name, block, k)


def test_cli_analyze_and_verify(tmp_path, acc_doc):
    res = CliRunner().invoke(cli, ["analyze", str(ACC), "--json", "--out", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["kind"] == "all-k" and doc["constant_proven"] == acc_doc["constant_proven"]
    path = tmp_path / "a" / "accelerated-k-allk.json"
    assert json.loads(path.read_text())["certificate"] == doc["certificate"]
    ver = CliRunner().invoke(cli, ["verify", str(path)])
    assert ver.exit_code == 0 and "verified" in ver.stdout, ver.output
    path = tmp_path / "acc.json"
    bad = copy.deepcopy(acc_doc)
    bad["constant"] = 1.5
    path.write_text(json.dumps(bad))
    ver = CliRunner().invoke(cli, ["verify", str(path)])
    assert ver.exit_code == 3 and "NOT verified" in ver.stdout
    bad["certificate"] = "not an object"
    path.write_text(json.dumps(bad))
    ver = CliRunner().invoke(cli, ["verify", str(path)])
    assert ver.exit_code == 2 and ver.stderr.count("\n") == 1 and "certificate" in ver.stderr


def test_unproven_bound_is_said_and_exits_3_with_verify(tmp_path, monkeypatch):
    """A spec the search finds no proof for: one line saying so, exit 0 (3 with
    --verify); its document claims nothing, and verify exits 3 on it."""
    import sosalgo.certificates.exact_allk as ex

    def failing(system, degree=2, offset=Fraction(1)):
        return ex.AllKResult(ex.AllKProof("failed", reason="no point with a margin"), None,
                             None, None, degree, 1)

    monkeypatch.setattr(ex, "prove_all_k", failing)
    res = CliRunner().invoke(cli, ["analyze", str(ACC), "--out", str(tmp_path / "a")])
    assert res.exit_code == 0 and "no bound for every N proven" in res.stdout
    res = CliRunner().invoke(cli, ["analyze", str(ACC), "--verify", "--out", str(tmp_path / "a")])
    assert res.exit_code == 3
    ver = CliRunner().invoke(cli, ["verify", str(tmp_path / "a" / "accelerated-k-allk.json")])
    assert ver.exit_code == 3 and "no bound is claimed" in ver.stdout


# --------------------------------------------------------------------------- refusals
def _refusal(tmp_path, spec: str | Path) -> str:
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["analyze", str(spec), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr
    assert not out.exists()
    return res.stderr


def _spec(tmp_path, beta: str, h: str = "1/L") -> Path:
    path = tmp_path / "s.yaml"
    path.write_text(f"""name: s
functions:
  f: {{class: smooth_strongly_convex}}
parameters:
  h: {h}
  beta: {beta}
matrices:
  A: [[0, 1], [-beta, 1 + beta]]
  B: [[-h], [-(1 + beta)*h]]
  C: [[0, 1]]
  E: [[1, 0]]
m: 0
L: 1
""")
    return path


def test_refusals_name_the_field(tmp_path):
    assert "sequences.theta.last" in _refusal(tmp_path, SPECS / "ogm.yaml")
    assert "last-step rule" in _refusal(tmp_path, SPECS / "ogm.yaml")
    schedule = _refusal(tmp_path, _spec(tmp_path, "k/(k + 3)", "[1/L, 1/L, 1/L]"))
    assert "parameters.h" in schedule and "schedule" in schedule
    assert "rational function of k" in _refusal(tmp_path, _spec(tmp_path, "sqrt(k)/(k + 3)"))
    assert "horizon N" in _refusal(tmp_path, _spec(tmp_path, "k/(k + N)"))
    assert "functions" in _refusal(tmp_path, SPECS / "fista.yaml")  # f + g
    assert "degree 4 in k" in _refusal(tmp_path, _spec(tmp_path, "k**4/(k + 3)**4"))
    assert "vanishes" in _refusal(tmp_path, _spec(tmp_path, "(k - 1)/(k - 1/2)"))
    res = CliRunner().invoke(cli, ["analyze", str(ACC), "--kappa", "10", "--out",
                                   str(tmp_path / "k")])
    assert res.exit_code == 2 and "--kappa" in res.stderr and not (tmp_path / "k").exists()
    line = _refusal(tmp_path, SPECS / "ogm.yaml")
    assert f"varies with k: use `sosalgo pep {SPECS / 'ogm.yaml'} --steps N`" in line
