"""sosalgo pep on methods that change with k, against closed forms and PEPit's values.

The per-step methods are built here by hand (:class:`sosalgo.worstcase.steps.StepMethods`):
gradient descent with a per-step step size, OGM from Kim and Fessler's theta_k (computed
here in outward-rounded ball arithmetic), FISTA from Beck and Teboulle's t_k. The spec
only gives the class (L-smooth convex f, and a convex g for FISTA), the units and the
terms. Closed forms: gradient descent with h = 1/L, L/(4N + 2) (Drori, Teboulle 2014);
OGM, L/(2 theta_N^2) (Kim, Fessler 2016).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import sympy as sp
from flint import arb, ctx

from sosalgo.classes import CLASSES
from sosalgo.kernel.arb import arb_fraction
from sosalgo.kernel.exact import Ball
from sosalgo.oracles import BoundFunction, OracleMethod
from sosalgo.spec import load_spec, spec_from_text
from sosalgo.worstcase.core import pep
from sosalgo.worstcase.steps import StepMethods
from tests.conftest import spec_path

SMOOTH = CLASSES["smooth_strongly_convex"]
F_ONLY = (BoundFunction("f", SMOOTH, {"m": 0.0, "L": 1.0}),)
COMPOSITE = """
name: composite-convex
functions:
  f: {class: smooth_strongly_convex}
  g: {class: convex}
parameters:
  h: {value: 1/L}
matrices:
  A: [[1]]
  B: [[-h, -h]]
  C: [[1], [1]]
  D: [[0, 0], [-h, -h]]
oracles: [f, g]
output: y2
measure: function
m: 0
L: 1
"""

# PEPit 0.5.1 (cvxpy 1.9.3, Clarabel 0.11.1), computed once in its own virtual
# environment with PEPit's own examples at L = 1: wc_accelerated_proximal_gradient
# (mu = 0: FISTA's t_k, F(x_n) - F* at the n-th prox point) and
# wc_gradient_descent_silver_stepsize_convex (f(x_n) - f*), ``PEP.solve(wrapper="cvxpy",
# solver="CLARABEL")``. A peer's floating-point values: within the solver's accuracy.
PEPIT_FISTA = {1: 0.25000000935833927, 2: 0.12500000210562137, 3: 0.07617878835034927,
               4: 0.051673292965803024, 5: 0.037511612835015334}
PEPIT_SILVER = {1: 0.1306019385607775, 3: 0.04691816136703531, 7: 0.018421542554185252}
PEER_REL = 2e-6  # PEPit's Clarabel and SCS values differ by up to 7e-6 (FISTA n = 5)


def _ball(x: arb) -> Ball:
    return Ball(arb_fraction(x.mid()), arb_fraction(arb(x.rad()).upper()))


def _balls(rows: list[list[arb]]) -> np.ndarray:
    return np.array([[_ball(arb(v)) for v in row] for row in rows], dtype=object)


def _floats(rows: list[list[arb]]) -> np.ndarray:
    return np.array([[float(arb(v).mid()) for v in row] for row in rows])


def gradient_steps(hs: list[Fraction]) -> StepMethods:
    """x_{k+1} = x_k - h_k grad f(x_k), h_k exact rationals (in units of 1/L, L = 1)."""
    floats = [OracleMethod(np.eye(1), np.array([[-float(h)]]), np.eye(1), np.zeros((1, 1)),
                           np.eye(1), 0.0, 1.0, F_ONLY, (0,)) for h in hs]
    exact = [{"A": sp.Matrix([[1]]), "B": sp.Matrix([[-sp.Rational(h.numerator,
                                                                     h.denominator)]]),
              "C": sp.Matrix([[1]]), "E": sp.Matrix([[1]])} for h in hs]
    return StepMethods(floats, exact, schedule={"h": [str(h) for h in hs]})


def ogm_thetas(N: int) -> list[arb]:
    """theta_0 = 1, theta_{k+1} = (1 + sqrt(1 + 4 theta_k^2))/2, the last one with 8."""
    th = [arb(1)]
    for k in range(1, N + 1):
        c = 8 if k == N else 4
        th.append((1 + (1 + c * th[-1] ** 2).sqrt()) / 2)
    return th


def ogm_steps(N: int) -> StepMethods:
    """OGM in the state (x_k, z_k): y_{k+1} = x_k - g_k/L, z_{k+1} = z_k - 2 theta_k
    g_k/L, x_{k+1} = (1 - 1/theta_{k+1}) y_{k+1} + z_{k+1}/theta_{k+1}; gradient at x_k.
    Every step keeps x* = z* = x* fixed: u = (1, 1), given exactly."""
    old = ctx.prec
    ctx.prec = 600
    try:
        th = ogm_thetas(N)
        floats, exact = [], []
        for k in range(N):
            a, b = th[k], th[k + 1]
            A = [[1 - 1 / b, 1 / b], [arb(0), arb(1)]]
            B = [[-(1 - 1 / b) - 2 * a / b], [-2 * a]]
            exact.append({"A": _balls(A), "B": _balls(B), "C": sp.Matrix([[1, 0]]),
                          "E": sp.Matrix([[1, 0]])})
            floats.append(OracleMethod(_floats(A), _floats(B), np.array([[1.0, 0.0]]),
                                       np.zeros((1, 1)), np.array([[1.0, 0.0]]), 0.0, 1.0,
                                       F_ONLY, (0,)))
    finally:
        ctx.prec = old
    return StepMethods(floats, exact, fixed_point=sp.Matrix([[1], [1]]))


def ogm_bound(N: int) -> arb:
    old = ctx.prec
    ctx.prec = 600
    try:
        return 1 / (2 * ogm_thetas(N)[-1] ** 2)
    finally:
        ctx.prec = old


def fista_steps(N: int) -> StepMethods:
    """FISTA (Beck, Teboulle; PEPit's count), xi_k = (x_{k-1}, x_k), y_k = x_k + beta_k
    (x_k - x_{k-1}), beta_k = (t_{k-1} - 1)/t_k (t_0 = 1; y_0 = x_0, y_1 = x_1); call 1
    grad f(y_k), call 2 x_{k+1} = prox_{g/L}(y_k - grad f(y_k)/L)."""
    t = [sp.Integer(1)]
    for _ in range(N):
        t.append((1 + sp.sqrt(1 + 4 * t[-1] ** 2)) / 2)
    floats, exact = [], []
    for k in range(N):
        be = (t[k - 1] - 1) / t[k] if k else sp.Integer(0)
        A = sp.Matrix([[0, 1], [-be, 1 + be]])
        B = sp.Matrix([[0, 0], [-1, -1]])
        C = sp.Matrix([[-be, 1 + be], [-be, 1 + be]])
        exact.append({"A": A, "B": B, "C": C, "D": B})
        fl = [np.array(M.evalf(30).tolist(), dtype=float) for M in (A, B, C, B)]
        floats.append(OracleMethod(*fl, None, 0.0, 1.0,
                                   (BoundFunction("f", SMOOTH, {"m": 0.0, "L": 1.0}),
                                    BoundFunction("g", CLASSES["convex"], {})), (0, 1),
                                   output=1))
    return StepMethods(floats, exact)


def _proven(res) -> Fraction:
    cert = res.certificate
    assert cert["check_kind"].startswith("exact"), cert.get("proof")
    return Fraction(cert["tau_proven"])


def _above(q: Fraction, x: arb) -> bool:
    """q >= x proven (x a ball)."""
    return bool(arb(q.numerator) / q.denominator >= x)


@pytest.mark.parametrize("N", [1, 2, 3, 5, 10])
def test_gradient_constant_step_drori_teboulle(N):
    """h_k = 1/L at every step, given per step: L/(4N + 2), tight; proven above it."""
    spec = load_spec(spec_path("gradient-convex"))
    res = pep(spec, None, N, schedule=gradient_steps([Fraction(1)] * N), witness=False)
    closed = Fraction(1, 4 * N + 2)
    assert res.tau == pytest.approx(float(closed), rel=1e-6)
    assert closed <= _proven(res) <= closed * (1 + Fraction(1, 10**6))
    assert res.extra["schedule"] == {"h": ["1"] * N}


def test_gradient_schedule_bounds_the_quadratics():
    """A schedule of different steps (1, 3/2, 1/2): tau_N is at least the worst quadratic
    f = (q/2) x^2, q in [0, L], max q/2 prod (1 - h_k q)^2, and the witness proves a
    lower bound within 1e-3 of tau."""
    spec = load_spec(spec_path("gradient-convex"))
    hs = [Fraction(1), Fraction(3, 2), Fraction(1, 2)]
    res = pep(spec, None, 3, schedule=gradient_steps(hs))
    q = np.linspace(0.0, 1.0, 20001)
    quad = float(np.max(q / 2 * np.prod([(1 - float(h) * q) ** 2 for h in hs], axis=0)))
    assert res.tau >= quad * (1 - 1e-7)
    proven = _proven(res)
    check = res.witness["check"]
    assert check["verified"], check
    lower = Fraction(check["tau_lower"])
    assert lower <= proven
    assert float(lower) >= res.tau * (1 - 1e-3)


@pytest.mark.parametrize("N", [1, 2, 3, 4, 5, 8, 10, 13, 16, 20])
def test_ogm_kim_fessler(N):
    """OGM with its last step: tau_N = L/(2 theta_N^2) to 1e-6; the proof is above it
    (never below: checked in ball arithmetic against the enclosure of the closed form)."""
    spec = load_spec(spec_path("gradient-convex"))
    res = pep(spec, None, N, schedule=ogm_steps(N), witness=False)
    bound = ogm_bound(N)
    assert res.tau == pytest.approx(float(bound.mid()), rel=1e-6)
    proven = _proven(res)
    assert _above(proven, bound)
    assert float(proven) <= float(bound.mid()) * (1 + 1e-6)


def test_ogm_witness_verifies():
    """The worst case of OGM at N = 6: a checked witness within 1e-4 of L/(2 theta_N^2)
    (below it: a lower bound)."""
    spec = load_spec(spec_path("gradient-convex"))
    res = pep(spec, None, 6, schedule=ogm_steps(6))
    check = res.witness["check"]
    assert check["verified"], check
    bound = float(ogm_bound(6).mid())
    assert bound * (1 - 1e-4) <= check["tau_lower_float"] <= bound * (1 + 1e-9)


@pytest.mark.parametrize("N", [1, 2, 3, 4, 5])
def test_fista_against_pepit(N):
    """FISTA, F(x_N) - F* at the N-th prox point: PEPit's value within its accuracy; the
    proof at or above it, the witness checked below it."""
    spec = spec_from_text(COMPOSITE, "composite.yaml")
    res = pep(spec, None, N, schedule=fista_steps(N), witness=N <= 3)
    peer = PEPIT_FISTA[N]
    assert res.tau == pytest.approx(peer, rel=PEER_REL)
    proven = _proven(res)
    assert float(proven) >= peer * (1 - PEER_REL)
    if N <= 3:
        check = res.witness["check"]
        assert check["verified"], check
        assert Fraction(check["tau_lower"]) <= proven


def test_refuses_a_step_that_moves_the_fixed_point():
    """Step 1 keeps only z* = 0 fixed, step 0 (OGM's) z* = x*: one clear error."""
    from sosalgo.errors import InputError

    spec = load_spec(spec_path("gradient-convex"))
    sm = ogm_steps(2)
    other = OracleMethod(np.array([[1.0, 0.0], [0.0, 0.5]]), np.array([[-1.0], [0.0]]),
                         np.array([[1.0, 0.0]]), np.zeros((1, 1)), np.array([[1.0, 0.0]]),
                         0.0, 1.0, F_ONLY, (0,))
    moved = StepMethods([sm.floats[0], other], sm.exact, sm.fixed_point)
    with pytest.raises(InputError, match="step 1"):
        pep(spec, None, 2, schedule=moved, witness=False)


def test_no_exact_matrices_no_proof():
    """Float per-step methods alone: tau, but nothing called proven."""
    spec = load_spec(spec_path("gradient-convex"))
    sm = gradient_steps([Fraction(1)] * 2)
    res = pep(spec, None, 2, schedule=StepMethods(sm.floats), witness=True)
    assert res.tau == pytest.approx(0.1, rel=1e-6)
    assert res.certificate["tau_proven"] is None
    assert not res.certificate["check_kind"].startswith("exact")
    assert res.witness is None


# --------------------------------------------------------------------------- shipped specs


def _silver(n: int) -> list[float]:
    """Altschuler and Parrilo's silver steps (units of 1/L): 1 + rho^(nu(i) - 1), rho =
    1 + sqrt(2), nu(i) the 2-adic valuation of i = 1..n."""
    rho = 1 + math.sqrt(2)
    return [1 + rho ** (((i & -i).bit_length() - 1) - 1) for i in range(1, n + 1)]


@pytest.mark.parametrize("N", [1, 2, 3, 7, 12, 16, 20])
def test_ogm_spec_equals_kim_fessler(N):
    """``pep specs/ogm.yaml``: L/(2 theta_N^2), proven above it and within 1e-6 of it,
    the witness below it."""
    res = pep(spec_path("ogm"), None, N, witness=N <= 3)
    bound = ogm_bound(N)
    assert res.tau == pytest.approx(float(bound.mid()), rel=1e-6)
    assert _above(_proven(res), bound)
    assert float(_proven(res)) <= float(bound.mid()) * (1 + 1e-6)
    if N <= 3:
        check = res.witness["check"]
        assert check["verified"], check
        assert float(Fraction(check["tau_lower"])) <= float(bound.mid())


@pytest.mark.parametrize("N", [1, 2, 3, 4, 5])
def test_fista_spec_against_pepit(N):
    """``pep specs/fista.yaml``: PEPit's FISTA values (F at the N-th prox point)."""
    res = pep(spec_path("fista"), None, N, witness=False)
    assert res.tau == pytest.approx(PEPIT_FISTA[N], rel=PEER_REL)
    assert float(_proven(res)) >= PEPIT_FISTA[N] * (1 - PEER_REL)


@pytest.mark.parametrize("N", [1, 3, 7])
def test_silver_spec_against_pepit(N):
    """``pep specs/silver.yaml`` (its own 7 steps at N = 7, ``--set h=[...]`` otherwise):
    PEPit's silver values."""
    from sosalgo.runs.pep import pep_run

    sets = None if N == 7 else {"h": "[" + ", ".join(repr(h) for h in _silver(N)) + "]"}
    doc = pep_run(spec_path("silver"), None, N, out_dir=None, progress=False, plot=False,
                  witness=False, overrides=sets)
    assert doc["tau"] == pytest.approx(PEPIT_SILVER[N], rel=PEER_REL)
    proven = Fraction(doc["certificate"]["tau_proven"])
    assert float(proven) >= PEPIT_SILVER[N] * (1 - PEER_REL)
    assert [float(h) for h in doc["schedule"]["h"]] == pytest.approx(_silver(N), rel=1e-12)


def test_cli_pep_and_verify_on_a_schedule(tmp_path):
    """``sosalgo pep specs/gradient-schedule.yaml --steps 3 --set h=[1, 3/2, 1/2]`` writes
    a row and a witness that ``sosalgo verify`` re-proves; a tampered schedule in the
    recorded overrides does not verify."""
    import json

    from click.testing import CliRunner

    from sosalgo.cli import cli

    run = CliRunner()
    out = tmp_path / "o"
    r = run.invoke(cli, ["pep", str(spec_path("gradient-schedule")), "--steps", "3", "--set",
                         "h=[1, 3/2, 1/2]", "--out", str(out), "--json", "--quiet",
                         "--no-plot"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    doc = json.loads(r.output)
    assert doc["schedule"]["h"] == ["1.0", "1.5", "0.5"]
    for path in sorted(out.glob("*.json")):
        if path.name.endswith("settings.json"):
            continue
        v = run.invoke(cli, ["verify", str(path)], catch_exceptions=False)
        assert v.exit_code == 0, (path.name, v.output)
    w = out / "gradient-schedule-pep-N3-witness.json"
    bad = json.loads(w.read_text())
    bad["set"] = {"h": "[1, 1, 1/2]"}
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    v = run.invoke(cli, ["verify", str(tmp_path / "bad.json")], catch_exceptions=False)
    assert v.exit_code == 3, v.output
    row = json.loads((out / "gradient-schedule-pep-N3.json").read_text())
    row["schedule"]["h"][1] = "2.0"
    (tmp_path / "row.json").write_text(json.dumps(row))
    v = run.invoke(cli, ["verify", str(tmp_path / "row.json")], catch_exceptions=False)
    assert v.exit_code == 3 and "schedule" in v.output, v.output


def test_kappa_on_an_m0_schedule_is_refused(tmp_path):
    """``--kappa`` on an m: 0 spec that changes with k: one line, exit 2, nothing written."""
    from click.testing import CliRunner

    from sosalgo.cli import cli

    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(spec_path("ogm")), "--steps", "3", "--kappa",
                                 "10", "--out", str(out)])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and "--kappa" in lines[0] and "ogm.yaml" in lines[0]
    assert not out.exists()


@pytest.mark.deep
def test_ogm_spec_fifty_steps_proven():
    """OGM at N = 50 (the ball route of the exact matrices): L/(2 theta_N^2) to 1e-6,
    proven above it and within 1e-6 of it (the polished certificate)."""
    res = pep(spec_path("ogm"), None, 50, witness=False)
    bound = ogm_bound(50)
    assert res.tau == pytest.approx(float(bound.mid()), rel=1e-6)
    proven = _proven(res)
    assert _above(proven, bound)
    assert float(proven) <= float(bound.mid()) * (1 + 1e-6)
