"""The bound for every N of a method on the recurrence theta_{k+1}^2 - theta_{k+1} =
theta_k^2 (docs/all-k.md): OGM without its last step against Kim and Fessler's
L/(4 theta_{N-1}^2), the PEP's worst cases and trajectories; their certificate checked
by the exact proof; the growth lemma; tampered documents; the one-line refusals; Nesterov's
method on the same recurrence against Beck and Teboulle's L/(2 t_{N-1}^2)."""

from __future__ import annotations

import copy
import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.certificates.allk import closed_form_system, conditions
from sosalgo.certificates.allk_recurrence import W0, Recurrence, check_lemma, make
from sosalgo.certificates.exact_allk import check_certificate, verify_allk_document
from sosalgo.cli import cli
from sosalgo.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"
OGMK = SPECS / "ogm-k.yaml"


@pytest.fixture(scope="module")
def ogm_doc(tmp_path_factory):
    from sosalgo.runs.allk import allk_run

    return allk_run(OGMK, tmp_path_factory.mktemp("ogmk"))


def _thetas(n: int) -> list[float]:
    out = [1.0]
    for _ in range(n):
        out.append((1 + math.sqrt(1 + 4 * out[-1] ** 2)) / 2)
    return out


def _bound(doc, theta: float) -> float:
    a = [float(Fraction(c)) for c in doc["a"]]
    return float(Fraction(doc["constant_proven"])) / sum(c * theta**j for j, c in enumerate(a))


# --------------------------------------------------------------------------- the bound
def test_ogm_bound_is_kim_and_fesslers_and_above_the_pep(ogm_doc):
    from sosalgo.runs.pep import pep_run

    doc = ogm_doc
    assert doc["certified"] and doc["verified"] == "exact" and doc["degree"] == 2
    assert doc["sequence"] == "theta" and doc["argument"] == "theta_{N-1}"
    # L/(4 theta_{N-1}^2) (Kim, Fessler), theta_{N-1} >= (N + 1)/2: L/(N + 1)^2
    assert Fraction(doc["constant_proven"]) == Fraction(1, 4)
    assert [Fraction(c) for c in doc["a"]] == [0, 0, 1]
    th = _thetas(12)
    pep = pep_run(OGMK, steps="1..10", out_dir=None, progress=False, plot=False,
                  witness=False, workers=1)
    assert [r["steps"] for r in pep["rows"]] == list(range(1, 11))
    for r in pep["rows"]:
        N = r["steps"]
        bound = _bound(doc, th[N - 1])
        assert r["tau"] <= bound * (1 + 1e-9)
        assert bound <= 1 / (N + 1) ** 2 * (1 + 1e-12)
    assert pep["rows"][-1]["tau"] >= 0.98 * _bound(doc, th[9])  # tight as N grows


def test_potential_bound_holds_on_trajectories(ogm_doc):
    """OGM without its last step run on convex quadratics and a Huber function (L = 1):
    f(y_N) <= C |x_0|^2 / a(theta_{N-1}) at every N."""
    rng = np.random.default_rng(3)
    th = _thetas(60)
    grads = []
    for _ in range(3):
        Q = np.linalg.qr(rng.standard_normal((6, 6)))[0]
        H = Q @ np.diag(rng.uniform(0, 1, 6) ** 3) @ Q.T
        grads.append((lambda x, H=H: x @ H @ x / 2, lambda x, H=H: H @ x))
    huber = (lambda x: float(np.sum(np.where(abs(x) <= 1, x**2 / 2, abs(x) - 0.5))),
             lambda x: np.clip(x, -1, 1))
    for f, g in [*grads, huber]:
        x0 = rng.standard_normal(6) * 5
        y, x = x0.copy(), x0.copy()
        for k in range(60):
            y_new = x - g(x)
            beta, gamma = (th[k] - 1) / th[k + 1], th[k] / th[k + 1]
            x = y_new + beta * (y_new - y) + gamma * (y_new - x)
            y = y_new
            assert f(y) <= _bound(ogm_doc, th[k]) * (x0 @ x0) * (1 + 1e-9)


def _kim_fessler(cond) -> dict[str, Fraction]:
    """The classical potential theta^2 (f(x) - |g|^2/2) + |z_{k+1}|^2/4, z_{k+1} = theta x
    - (theta - 1) y - 2 theta g, with the multipliers theta_k^2 (x_k, x_{k+1}) and
    theta_{k+1} (x*, x_{k+1}); C = 1/4, a(t) = t^2."""
    cert = {str(v): Fraction(0) for v in cond.variables}
    v = [(-1, 1), (1, 0), (-2, 0)]  # (coefficient of theta, constant) of z: y, x, g
    for i in range(3):
        for j in range(i, 3):
            (ai, bi), (aj, bj) = v[i], v[j]  # P_ij = v_i v_j / 4
            P = [Fraction(bi * bj, 4), Fraction(ai * bj + aj * bi, 4), Fraction(ai * aj, 4)]
            if i == j == 2:
                P[2] -= Fraction(1, 2)
            for t in range(3):
                cert[f"P{i}{j}_{t}"] = P[t]
    cert.update({"p_2": Fraction(1), "C": Fraction(1, 4), "lam01_2": Fraction(1),
                 "lam21n_1": Fraction(1), "nu_1": Fraction(1)})
    return cert


def test_the_classical_certificate_is_proven_and_a_lower_constant_is_not():
    system = closed_form_system(load_spec(OGMK))
    cond = conditions(system, 2)
    cert = _kim_fessler(cond)
    proof = check_certificate(cond, cert, Fraction(0), system.k)
    assert proof.verified == "exact" and proof.constant == Fraction(1, 4)
    lower = cert | {"C": Fraction(6, 25)}
    assert check_certificate(cond, lower, Fraction(0), system.k).verified == "failed"
    bad = cert | {"lam21n_1": Fraction(1, 2), "lam20n_1": Fraction(1, 2)}
    assert check_certificate(cond, bad, Fraction(0), system.k).verified == "failed"


def test_growth_lemma_and_the_parametrization():
    import sympy as sp

    s = sp.Symbol("s", real=True)
    rec = make("theta", s)
    assert check_lemma(rec) is None
    th = _thetas(2000)
    for k in range(2000):
        assert th[k] >= 1 + k / 2
        w = th[k] + th[k + 1] - 0.5  # the point of the hyperbola at step k
        assert w >= float(W0)
        assert float(rec.at.subs(s, w - float(W0))) == pytest.approx(th[k], rel=1e-12)
        assert float(rec.next.subs(s, w - float(W0))) == pytest.approx(th[k + 1], rel=1e-12)
    # a start past theta_0 = 1 (w >= 17/8: theta >= 273/272) is refused
    w = sp.Rational(17, 8) + s
    late = Recurrence("theta", s, w, (4 * w**2 - 1) / (8 * w), (2 * w + 1) ** 2 / (8 * w))
    assert "theta_k(W0) > theta_0" in check_lemma(late)
    wrong = Recurrence("theta", s, rec.w, rec.at, rec.next + 1 / (8 * rec.w))
    assert "fails" in check_lemma(wrong)


# --------------------------------------------------------------------------- verify
def test_verify_reproves_and_refuses_tampered_documents(ogm_doc):
    spec = load_spec(OGMK)
    ok = verify_allk_document(copy.deepcopy(ogm_doc), spec, "doc")[0]
    assert ok["verified"] == "exact"
    bad = copy.deepcopy(ogm_doc) | {"a": ["1/10", "0", "1"]}  # a larger a(t)
    assert verify_allk_document(bad, spec, "doc")[0]["verified"] == "failed"
    bad = copy.deepcopy(ogm_doc)
    bad["certificate"]["C"] = "6/25"
    assert verify_allk_document(bad, spec, "doc")[0]["verified"] == "failed"


def test_cli_verify(tmp_path, ogm_doc):
    res = CliRunner().invoke(cli, ["verify", ogm_doc["file"]])
    assert res.exit_code == 0, res.output
    bad = copy.deepcopy(ogm_doc)
    bad["certificate"]["lam01_2"] = "1/2"
    path = tmp_path / "bad-allk.json"
    path.write_text(json.dumps(bad))
    res = CliRunner().invoke(cli, ["verify", str(path)])
    assert res.exit_code == 3 and "NOT verified" in res.output


# --------------------------------------------------------------------------- refusals
def _refusal(tmp_path, text: str) -> str:
    spec = tmp_path / "s.yaml"
    spec.write_text(text)
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["analyze", str(spec), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr
    assert not out.exists()
    return res.stderr


def _ogm(first: str = "1", nxt: str = "(1 + sqrt(1 + 4*theta**2))/2",
         beta: str = "(theta[k] - 1)/theta[k+1]", C: str = "[[0, 1]]",
         extra: str = "") -> str:
    return f"""name: s
functions:
  f: {{class: smooth_strongly_convex}}
sequences:
  theta: {{first: {first}, next: {nxt}}}
{extra}parameters:
  h: 1/L
  beta: {beta}
  gamma: theta[k]/theta[k+1]
matrices:
  A: [[0, 1], [-beta, 1 + beta]]
  B: [[-h], [-(1 + beta + gamma)*h]]
  C: {C}
  E: [[1, 0]]
m: 0
L: 1
"""


def test_refusals_name_the_field(tmp_path):
    assert "sequences.theta.last: a last-step rule" in _refusal(
        tmp_path, (SPECS / "ogm.yaml").read_text())
    assert "sequences.theta: theta is given by a recurrence that is not" in _refusal(
        tmp_path, _ogm(nxt="theta + 1/2"))
    assert "sequences.theta: theta is given by a recurrence that is not" in _refusal(
        tmp_path, _ogm(first="2"))
    assert "uses k beside a sequence" in _refusal(tmp_path, _ogm(beta="k/(k + 3)*theta"))
    assert "matrices.C: uses theta" in _refusal(tmp_path, _ogm(C="[[1 - 1/theta, 1/theta]]"))
    two = _refusal(tmp_path, _ogm(beta="(r[k] - 1)/theta[k+1]",
                                  extra="  r: {first: 1, next: r + 1}\n"))
    assert "the all-k bound takes one sequence" in two


@pytest.mark.deep
def test_nesterov_on_the_recurrence_gets_beck_and_teboulles_constant(tmp_path):
    """Nesterov's method with t_k from the recurrence (FISTA without g): L/(2 t_{N-1}^2)
    (Beck, Teboulle), above the PEP's worst cases."""
    from sosalgo.runs.allk import allk_run
    from sosalgo.runs.pep import pep_run

    text = (SPECS / "accelerated-k.yaml").read_text()
    text = text.replace("beta: k/(k + 3)", "beta: (t[k] - 1)/t[k+1]").replace(
        "parameters:", "sequences:\n  t: {first: 1, next: (1 + sqrt(1 + 4*t**2))/2}\n"
        "parameters:")
    spec = tmp_path / "agm.yaml"
    spec.write_text(text)
    doc = allk_run(spec, tmp_path / "out")
    assert doc["certified"] and doc["sequence"] == "t"
    C = Fraction(doc["constant_proven"])
    assert Fraction(1, 4) < C <= Fraction(1, 2)
    th = _thetas(12)
    pep = pep_run(spec, steps="1..10", out_dir=None, progress=False, plot=False,
                  witness=False, workers=1)
    for r in pep["rows"]:
        N = r["steps"]
        assert r["tau"] <= _bound(doc, th[N - 1]) * (1 + 1e-9)
        assert _bound(doc, th[N - 1]) <= 1 / (2 * th[N - 1] ** 2) * (1 + 1e-12)
