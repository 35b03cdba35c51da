"""sosalgo pep: the worst case after N steps against closed forms (not our own output)."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli

SPECS = Path(__file__).resolve().parent.parent / "specs"


def _run(*args: str):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


@pytest.mark.parametrize("N", [1, 2, 3, 4, 5])
def test_gradient_convex_drori_teboulle(N):
    """h = 1/L on L-smooth convex f, f(x_N) - f* <= L |x_0 - x*|^2 / (4N + 2), tight."""
    res = sosalgo.pep(SPECS / "gradient-convex.yaml", None, N, witness=False)
    L = 1.0
    assert res.status == "solved"
    assert res.tau == pytest.approx(L / (4 * N + 2), rel=1e-6)
    cert = res.certificate
    assert cert["check_kind"].startswith("exact")
    proven = Fraction(cert["tau_proven"])
    assert proven >= Fraction(res.tau)
    assert float(proven) == pytest.approx(L / (4 * N + 2), rel=1e-5)


def _worst_quadratic(m: float, L: float, h: float, N: int) -> float:
    """max over f = (q/2)|x|^2, q in [m, L], of |x_N|^2/|x_0|^2 = (1 - hq)^(2N)."""
    q = np.linspace(m, L, 2001)
    return float(np.max((1 - h * q) ** (2 * N)))


@pytest.mark.parametrize("kappa,N", [(10.0, 2), (4.0, 3)])
def test_gradient_distance(kappa, N):
    """Gradient descent h = 1/L on F(m, L), |x_N - x*|^2 / |x_0 - x*|^2 =
    max(|1 - hm|, |1 - hL|)^(2N); at least the worst quadratic; at most rho^(2N) for the
    rate certified for the same step by the interpolation family (distance measure)."""
    m, L = 1.0, kappa
    h = 1 / L
    res = sosalgo.pep(SPECS / "gradient.yaml", kappa, N, measure="dist", witness=False)
    closed = max(abs(1 - h * m), abs(1 - h * L)) ** (2 * N)
    assert res.tau == pytest.approx(closed, rel=1e-6)
    assert res.tau >= _worst_quadratic(m, L, h, N) - 1e-7
    rate = sosalgo.analyze(SPECS / "proximal-gradient.yaml", kappa)
    assert rate.certified
    assert res.tau <= rate.rho ** (2 * N) * (1 + 1e-6)
    proven = res.certificate["tau_proven"]
    assert Fraction(proven) >= Fraction(res.tau)
    assert float(Fraction(proven)) == pytest.approx(closed, rel=1e-5)


def test_proximal_gradient_taylor_hendrickx_glineur():
    """Proximal gradient, distance: max(|1 - hm|, |1 - hL|)^(2N) (THG 2018)."""
    res = sosalgo.pep(SPECS / "proximal-gradient.yaml", 10.0, 2, witness=False)
    assert res.measure == "dist"
    assert res.tau == pytest.approx(0.9 ** 4, rel=1e-6)
    assert float(Fraction(res.certificate["tau_proven"])) == pytest.approx(0.9 ** 4, rel=1e-5)


def test_witness_verifies_and_tampering_fails(tmp_path):
    """The witness JSON passes `sosalgo verify` and proves tau_N within 1e-4; one changed
    gradient makes it fail (exit 3)."""
    out = tmp_path / "o"
    r = _run("pep", str(SPECS / "gradient-convex.yaml"), "--steps", "2", "--out", str(out),
             "--json", "--quiet", "--no-plot")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.output)
    for key in ("spec", "kappa", "steps", "tau", "measure", "initial", "certificate",
                "witness"):
        assert key in doc
    path = out / "gradient-convex-pep-N2-witness.json"
    r = _run("verify", str(path), "--json")
    assert r.exit_code == 0, r.output
    chk = json.loads(r.output)["results"][0]
    assert chk["verified"]
    assert abs(chk["tau_lower_float"] - 1 / 10) <= 1e-4
    assert Fraction(chk["tau_lower"]) <= Fraction(doc["certificate"]["tau_proven"])
    w = json.loads(path.read_text())
    g = Fraction(w["calls"][1][0][0])
    w["calls"][1][0][0] = str(g * Fraction(11, 10) + Fraction(1, 100))
    bad = tmp_path / "tampered.json"
    bad.write_text(json.dumps(w))
    r = _run("verify", str(bad))
    assert r.exit_code == 3
    assert "not verified" in r.output


def test_steps_range_writes_csv_and_rows(tmp_path):
    r = _run("pep", str(SPECS / "gradient.yaml"), "--kappa", "10", "--steps", "1..3",
             "--measure", "dist", "--out", str(tmp_path), "--json", "--quiet",
             "--no-witness")
    assert r.exit_code == 0, r.output
    rows = json.loads(r.output)["rows"]
    assert [d["steps"] for d in rows] == [1, 2, 3]
    for d in rows:
        assert d["tau"] == pytest.approx(0.81 ** d["steps"], rel=1e-6)
    assert (tmp_path / "gradient-pep.csv").is_file()
    assert (tmp_path / "gradient-pep-k10.png").is_file()


@pytest.mark.parametrize("args,field", [
    (["gradient.yaml", "--kappa", "10", "--steps", "0"], "--steps"),
    (["gradient.yaml", "--kappa", "10", "--measure", "f + foo"], "--measure"),
    (["proximal-point.yaml", "--kappa", "10", "--measure", "grad"], "--measure"),
    (["gradient-convex.yaml", "--kappa", "10"], "--kappa"),
])
def test_bad_input(tmp_path, args, field):
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(SPECS / args[0]), *args[1:], "--out", str(out)])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and field in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("spec", sorted(p.name for p in SPECS.glob("*.yaml")))
def test_every_spec_runs(spec):
    """Every shipped spec has a finite worst case after two steps (Douglas-Rachford
    through its default free start, ``sdist``; a listed schedule: its own length; a
    finite sum, a one-step question: one)."""
    s = sosalgo.load_spec(SPECS / spec)
    kappa = None if s.m == 0 else 10.0  # m: 0: L given
    lists = [len(p.schedule) for p in s.parameters.values() if p.schedule is not None]
    steps = lists[0] if lists else 1 if s.finite_sum is not None else 2  # one-step questions
    res = sosalgo.pep(SPECS / spec, kappa, steps, exact=False, witness=False)
    assert res.status == "solved"
    assert np.isfinite(res.tau) and res.tau >= 0 and res.gap is not None
    assert res.certificate["multipliers"]


def test_douglas_rachford_free_start():
    """Douglas-Rachford (t = 1/sqrt(mL)) from a free start, |x_2 - x*|^2 / |z_0 - z*|^2:
    finite, and at least its value on f = (q/2) x^2, g = 0, where z+ = z / (1 + t q) and
    x_N = z_N / (1 + t q): max over q in [m, L] of (1 + t q)^(-2(N + 1)) (computed here);
    the proven upper bound and the checked witness bracket it."""
    m, L, N = 1.0, 10.0, 2
    t = 1 / np.sqrt(m * L)
    quad = float(np.max((1 + t * np.linspace(m, L, 1001)) ** (-2 * (N + 1))))
    res = sosalgo.pep(SPECS / "douglas-rachford.yaml", L / m, N)
    assert res.initial == "sdist" and res.status == "solved"
    assert res.tau >= quad * (1 - 1e-6)
    proven = Fraction(res.certificate["tau_proven"])
    assert float(proven) >= quad * (1 - 1e-12)
    chk = res.witness["check"]
    assert chk["verified"]
    assert Fraction(chk["tau_lower"]) <= proven
    assert chk["tau_lower_float"] >= quad * (1 - 1e-3)


def test_sdist_needs_no_free_start_for_one_state():
    """GD has one state: |xi_0 - xi*|^2 is |x_0 - x*|^2, so sdist and dist agree
    (0.9^(2N) for h = 1/L, kappa = 10)."""
    res = sosalgo.pep(SPECS / "gradient.yaml", 10.0, 3, measure="dist", initial="sdist",
                      witness=False)
    assert res.tau == pytest.approx(0.81 ** 3, rel=1e-6)


@pytest.mark.deep  # about 5-8 s: N = 20 (the default tests cover N <= 10)
def test_long_horizon_closed_forms():
    """The sparse basis at N = 20: GD on F(1, 10), dist: 0.9^40; h = 1/L on L-smooth
    convex f: L / (4N + 2), proven within 1e-6 above the closed form."""
    res = sosalgo.pep(SPECS / "gradient.yaml", 10.0, 20, measure="dist", witness=False)
    assert res.tau == pytest.approx(0.81 ** 20, rel=1e-5)
    assert float(Fraction(res.certificate["tau_proven"])) >= 0.81 ** 20 * (1 - 1e-12)
    res = sosalgo.pep(SPECS / "gradient-convex.yaml", None, 20, witness=False)
    assert res.tau == pytest.approx(1 / 82, rel=1e-5)
    assert res.certificate["check_kind"].startswith("exact")
    proven = Fraction(res.certificate["tau_proven"])
    assert Fraction(1, 82) <= proven <= Fraction(1, 82) * (1 + Fraction(1, 10**6))


def test_past_long_horizon_gradient_closed_form():
    """N = 40 (past the horizon where the constraint generation stops at violations of
    1e-6 and the margins start at 1e-5): gradient descent h = 1/L on F(1, 10), dist/dist,
    has the worst case 0.9^(2N) (Taylor, Hendrickx and Glineur); the proven bound holds
    it, at most 1e-6 above (the polished certificate), and the float tau is within 1e-5
    of it."""
    N = 40
    res = sosalgo.pep(SPECS / "gradient.yaml", 10.0, N, measure="dist", witness=False)
    closed = Fraction(81, 100) ** N
    assert res.tau == pytest.approx(float(closed), rel=1e-5)
    assert res.certificate["check_kind"].startswith("exact")
    proven = Fraction(res.certificate["tau_proven"])
    assert closed <= proven <= closed * (1 + Fraction(1, 10**6))


@pytest.mark.deep  # about 7-12 s: the SDP, three margin solves and the witness search
def test_nesterov_twenty_steps_witness():
    """N = 20 of Nesterov's method with its witness (45 s before the rank reductions were
    capped): proven, and a verified witness within 1e-3 below the proven bound."""
    res = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, 20)
    chk = res.witness["check"]
    assert res.certificate["check_kind"].startswith("exact") and chk["verified"]
    lower, upper = Fraction(chk["tau_lower"]), Fraction(res.certificate["tau_proven"])
    assert lower <= upper <= lower * (1 + Fraction(1, 10**3))


@pytest.mark.deep  # about 10 s: the margin ladder up to 1e-4
def test_sixteen_steps_proven():
    """Nesterov and the triple momentum method at N = 16, where the float dual's error in
    one direction exceeds the margins up to 1e-6: proven at a larger margin."""
    for name in ("nesterov", "triple-momentum"):
        res = sosalgo.pep(SPECS / f"{name}.yaml", 10.0, 16, witness=False)
        cert = res.certificate
        assert cert["check_kind"].startswith("exact"), name
        assert float(Fraction(cert["tau_proven"])) == pytest.approx(res.tau, rel=2e-4)


def _vfista_on_quadratics(m: float, L: float, N: int) -> float:
    """max over f = (q/2) x^2, q in [m, L], and g = 0 of (f(x_N) - f*) / |x_0|^2 for
    V-FISTA (h = 1/L, beta = (sqrt(kappa) - 1)/(sqrt(kappa) + 1), x_{-1} = x_0 = 1):
    the output after N steps is the prox point x_{N+1} (``output: y2``), computed here
    by the recurrence itself."""
    h, k = 1 / L, L / m
    beta = (np.sqrt(k) - 1) / (np.sqrt(k) + 1)
    q = np.linspace(m, L, 2001)
    prev, x = np.ones_like(q), np.ones_like(q)
    for _ in range(N + 1):
        y = x + beta * (x - prev)
        prev, x = x, y - h * q * y
    return float(np.max(q / 2 * x ** 2))


@pytest.mark.parametrize("N", [1, 3])
def test_accelerated_proximal_gradient_proven(N):
    """V-FISTA with ``output: y2`` (the prox point, where g is queried): f(x_N) + g(x_N)
    reads g at its own call exactly, so the dual certificate is proven (it was only a
    floating-point check); the proven bound is at least the worst quadratic (g = 0) and
    at least the verified witness's lower bound, which is within 1e-3 of it."""
    res = sosalgo.pep(SPECS / "accelerated-proximal-gradient.yaml", 10.0, N)
    cert, chk = res.certificate, res.witness["check"]
    assert cert["check_kind"].startswith("exact") and chk["verified"]
    upper, lower = Fraction(cert["tau_proven"]), Fraction(chk["tau_lower"])
    assert float(upper) >= _vfista_on_quadratics(1.0, 10.0, N) * (1 - 1e-12)
    assert lower <= upper <= lower * (1 + Fraction(1, 10**3))


NESTEROV_AT_Y = """\
name: nesterov-at-y
description: Nesterov's method whose output is the gradient's point y (E = C)
parameters:
  h:    {value: 1/L, range: [0, 2/L]}
  beta: {value: (sqrt(kappa) - 1)/(sqrt(kappa) + 1), range: [0, 1]}
matrices:
  A: [[0, 1], [-beta, 1 + beta]]
  B: [[0], [-h]]
  C: [[-beta, 1 + beta]]
  E: [[-beta, 1 + beta]]
"""


def test_output_equal_to_a_call_is_that_call(tmp_path):
    """E = C (irrational entries at kappa = 10): the output is the call's point exactly,
    so f(x_N) reads the call and the certificate is proven and the witness verified
    (before: "the exact structure differs", "not provably the point"); its value agrees with
    Nesterov's own spec measured at y_N (another path: a term naming the call)."""
    path = tmp_path / "nesterov-at-y.yaml"
    path.write_text(NESTEROV_AT_Y)
    res = sosalgo.pep(path, 10.0, 3, measure="f + dist(y_N)")
    assert res.certificate["check_kind"].startswith("exact")
    assert res.witness["check"]["verified"]  # the check reads f at the call, too
    ref = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, 3, measure="f(y_N) + dist(y_N)",
                      witness=False)
    assert res.tau == pytest.approx(ref.tau, rel=1e-6)
    assert float(Fraction(res.certificate["tau_proven"])) >= ref.tau * (1 - 1e-6)


@pytest.mark.deep
def test_nesterov_thirty_steps():
    """N = 30 of a two-state method: solved, proven, and below the N = 20 value."""
    r20 = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, 20, witness=False)
    r30 = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, 30, witness=False)
    assert r30.status == "solved" and r30.certificate["check_kind"].startswith("exact")
    assert 0 < r30.tau < r20.tau


def test_ten_step_witnesses_bracket_the_closed_form():
    """N = 10 (no witness was verified before the interior-point mix): gradient descent,
    dist/dist, 0.81^10 lies between the verified witness's lower bound (within 1e-3) and
    the proven upper bound; Nesterov f/dist: witness <= tau_proven, both near tau."""
    gd = sosalgo.pep(SPECS / "gradient.yaml", 10.0, 10, measure="dist")
    closed = Fraction(81, 100) ** 10
    chk = gd.witness["check"]
    assert chk["verified"]
    lower, upper = Fraction(chk["tau_lower"]), Fraction(gd.certificate["tau_proven"])
    assert lower <= closed <= upper
    assert float(lower) >= float(closed) * (1 - 1e-3)
    nes = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, 10)
    chk = nes.witness["check"]
    assert chk["verified"] and nes.certificate["check_kind"].startswith("exact")
    lower, upper = Fraction(chk["tau_lower"]), Fraction(nes.certificate["tau_proven"])
    assert lower <= upper and float(lower) >= nes.tau * (1 - 1e-3)


def test_exact_certificate_refuses_a_smaller_tau():
    """The ball-arithmetic proof of S ⪰ 0, c_F >= 0 fails for tau 0.1% below the SDP's
    (the true worst case is above it) and for a perturbed largest multiplier."""
    from sosalgo.worstcase.core import pep_problem
    from sosalgo.worstcase.exact import prove_certificate
    from sosalgo.worstcase.sdp import pep_data, solve_pep

    spec = sosalgo.load_spec(SPECS / "gradient.yaml")
    mt, st, mterms, iterms, _ = pep_problem(spec, 10.0, 3, "dist", None)
    data = pep_data(mt, st)
    ans = solve_pep(data)
    cand = solve_pep(data, margin=1e-8 / max(1.0, ans.size), unit=ans.primal)
    ok = prove_certificate(spec, 10.0, st, mterms, iterms, cand.tau, cand.lam, data.w)
    assert ok["proven"] and Fraction(ok["tau_proven"]) >= Fraction(81, 100) ** 3
    low = prove_certificate(spec, 10.0, st, mterms, iterms, 0.999 * 0.81 ** 3, cand.lam,
                            data.w)
    assert not low["proven"]
    lam = cand.lam.copy()
    lam[int(np.argmax(lam))] *= 1.05
    assert not prove_certificate(spec, 10.0, st, mterms, iterms, cand.tau, lam, data.w)["proven"]


@pytest.mark.deep  # about 1-2 minutes: the SDP at N = 50 and one margin solve
def test_nesterov_fifty_steps_proven():
    """N = 50 of a two-state method: the exact dual certificate holds (margin 1e-5 or
    1e-4 of tau, ball-arithmetic Cholesky on the scaled S, c_F repaired), within 2e-4."""
    res = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, 50, witness=False)
    cert = res.certificate
    assert res.status == "solved" and cert["check_kind"].startswith("exact")
    proven = Fraction(cert["tau_proven"])
    assert Fraction(res.tau) <= proven <= Fraction(res.tau) * (1 + Fraction(2, 10**4))


@pytest.mark.deep  # minutes: the SDP at N = 60 and the margin solves
def test_nesterov_sixty_steps_proven():
    """N = 60, where beta's enclosure at a fixed 50 decimals widens past what the proof
    needs (tau ~ 2e-14): with the enclosures' precision grown with N, the certificate is
    proven exactly, within 2e-4 above the SDP's tau and below Nesterov's bound
    (1 - 1/sqrt(kappa))^N (L + m)/2 (m = 1, L = 10)."""
    N = 60
    res = sosalgo.pep(SPECS / "nesterov.yaml", 10.0, N, witness=False)
    cert = res.certificate
    assert res.status == "solved" and cert["check_kind"].startswith("exact")
    upper = Fraction(cert["tau_proven"])
    assert Fraction(res.tau) <= upper <= Fraction(res.tau) * (1 + Fraction(2, 10**4))
    assert float(upper) <= (1 - 10 ** -0.5) ** N * (10 + 1) / 2
