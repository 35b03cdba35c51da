"""Relatively inexact proximal steps (``relative_error`` on a proximal call): the PEP of
``specs/inexact-proximal-point.yaml`` against PEPit's peer values and, at sigma = 0, the
exact proximal point's closed form; the proven bound against adversarial inexact runs
simulated here (numpy only, explicit convex functions); the witness check against
tampered answers; bad input."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "specs" / "inexact-proximal-point.yaml"

# PEPit 0.5.1, examples/inexact_proximal_methods/relatively_inexact_proximal_point_algorithm:
# wc_relatively_inexact_proximal_point_algorithm(n, gamma, sigma) with Clarabel at
# tol_gap_abs = tol_gap_rel = tol_feas = 1e-12 (its default tolerances give 1.6e-7 more
# at the first two: 0.007678415492585519, 0.013025802248252394)
PEPIT = {  # (gamma, sigma, n): PEPit's value
    (10, "13/20", 8): 0.007678412477375481,  # the example's own
    (10, "13/20", 4): 0.013025798738068152,
    (1, "3/10", 3): 0.10912878853929214,  # the same at 1e-14, and SCS at 1e-10
}


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def pep_doc(out, gamma, sigma, n, spec=SPEC):
    res = run(["pep", spec, "--steps", n, "--set", f"gamma={gamma}", "--set",
               f"sigma={sigma}", "--out", out, "--json", "--no-plot"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


@pytest.fixture(scope="module")
def docs(tmp_path_factory):
    return {key: pep_doc(tmp_path_factory.mktemp("iprox"), *key)
            for key in [*PEPIT, (1, "0", 3)]}


@pytest.mark.parametrize("key", list(PEPIT))
def test_agrees_with_pepit(docs, key):
    doc = docs[key]
    proof = doc["certificate"]["proof"]
    assert proof["proven"], proof
    proven = proof["tau_proven_float"]
    assert abs(doc["tau"] / PEPIT[key] - 1) <= 1e-6
    assert proven >= PEPIT[key] * (1 - 1e-9)
    check = doc["witness"]["check"]
    assert check["verified"], check
    assert PEPIT[key] * (1 - 1e-4) <= check["tau_lower_float"] <= proven


def test_sigma_zero_is_the_exact_proximal_point(docs):
    """Guler's tight bound 1/(4 gamma N) for the exact proximal point on convex f (the
    row -|d - g|^2 >= 0 of sigma = 0 has no interior: the solve ends 2e-4 above it)."""
    proven = docs[(1, "0", 3)]["certificate"]["proof"]["tau_proven_float"]
    assert 1 / 12 * (1 - 1e-9) <= proven <= 1 / 12 * (1 + 1e-3)


def _reachable(v, gamma, sigma, sub, grid):
    """Points y a relatively inexact prox may return from v: some g in the
    subdifferential [lo, hi] of f at y with |y - v + gamma g| <= sigma |y - v|."""
    out = []
    for y in grid:
        lo, hi = sub(y)
        r = sigma * abs(y - v) + 1e-12
        if y - v + gamma * lo <= r and y - v + gamma * hi >= -r:
            out.append(y)
    return out


def _adversarial_value(fn, x0, gamma, sigma, n, rng):
    """f(x_n) of a run from x0 whose every prox point is chosen among the reachable ones
    near the exact prox (greedily: the largest f, or at random)."""
    f, sub, prox = fn
    x = x0
    for _ in range(n):
        p = prox(x, gamma)
        grid = np.append(p + np.linspace(-2, 2, 801) * abs(x - p), p)
        ys = _reachable(x, gamma, sigma, sub, grid)
        x = max(ys, key=f) if rng.random() < 0.5 else ys[rng.integers(len(ys))]
    return f(x)


def _functions(c):
    """c/2 x^2 and c |x| (minimum 0 at 0): value, subdifferential, exact prox."""
    quad = (lambda y: c * y * y / 2, lambda y: (c * y, c * y), lambda v, g: v / (1 + g * c))
    absolute = (lambda y: c * abs(y),
                lambda y: (c * np.sign(y),) * 2 if y != 0 else (-c, c),
                lambda v, g: np.sign(v) * max(abs(v) - g * c, 0.0))
    return quad, absolute


@pytest.mark.parametrize("key", [*PEPIT, (1, "0", 3)])
def test_adversarial_runs_stay_below_the_proven_bound(docs, key):
    gamma, sigma_s, n = key
    sigma = float(Fraction(sigma_s))
    proven = docs[key]["certificate"]["proof"]["tau_proven_float"]
    rng = np.random.default_rng(3)
    worst = 0.0
    for t in (0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1, 1.5, 3):
        for fn in _functions(t / (gamma * n)):
            for _ in range(4):  # |x_0 - x*| = 1
                worst = max(worst, _adversarial_value(fn, 1.0, gamma, sigma, n, rng))
    assert worst <= proven * (1 + 1e-12)
    if sigma > 0:  # the inexactness is used: above the exact prox's worst case
        assert worst > 1 / (4 * gamma * n)


def test_witness_answers_outside_the_error_ball_are_refused(tmp_path, docs):
    from sosalgo.spec import load_spec
    from sosalgo.worstcase.check import check_witness

    wit = docs[(10, "13/20", 4)]["witness"]  # the spec's own gamma and sigma
    spec = load_spec(SPEC)
    assert check_witness(wit, spec)["verified"]
    bad = json.loads(json.dumps(wit))
    g = [Fraction(v) for v in bad["functions"]["f"]["points"][0]["g"]]
    bad["calls"][0][0] = [str(v * 3) for v in g]  # |d - g| = 2/3 |d| > 13/20 |d|
    assert not check_witness(bad, spec)["verified"]
    exact = tmp_path / "exact-twin.yaml"  # an exact prox: the answer must be a subgradient
    exact.write_text(SPEC.read_text().replace(
        "  - {function: f, relative_error: sigma}", "  - f"))
    assert not check_witness(wit, load_spec(exact))["verified"]


def test_pep_document_and_witness_verify(tmp_path):
    doc = pep_doc(tmp_path, 1, "3/10", 3)
    assert doc["class"]["inexact_proximal"] == ["oracles[0]"]
    files = sorted(tmp_path.glob("inexact-proximal-point-pep-N3*.json"))
    assert len(files) == 2
    for path in files:
        res = run(["verify", path, "--out", tmp_path / "v"])
        assert res.exit_code == 0, res.output


@pytest.mark.parametrize("old,new,field", [
    ("  sigma: {value: 13/20, range: [0, 9/10]}", "  sigma: 1", "oracles[0].relative_error"),
    ("f: {class: convex}", "f: {class: smooth_strongly_convex}\n  g: {class: convex}",
     "functions.g"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, old, new, field):
    text = SPEC.read_text()
    assert old in text
    path = tmp_path / "bad.yaml"
    path.write_text(text.replace(old, new))
    res = run(["pep", path, "--steps", "1", "--out", tmp_path / "o"])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and field in lines[0] and "bad.yaml" in lines[0], res.output


def test_analyze_refuses_an_inexact_prox(tmp_path):
    res = run(["analyze", SPEC, "--out", tmp_path / "a"])
    assert res.exit_code == 2 and "inexact-proximal-point.yaml" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1


# ----------------------------------------------------------- partially inexact Douglas-Rachford
DRS = ROOT / "specs" / "partially-inexact-douglas-rachford.yaml"
DRS_SETS = [(0.1, 5, 5, 1.4, 0.2), (0.1, 5, 3, 1.4, 0.2), (0.2, 2, 2, 1, 0.5)]  # PEPit's


def drs_theory(mu, L, n, gamma, sigma):
    """Barre, Taylor, Bach (2020), Thm. 5.1 (tight; PEPit's theoretical value)."""
    return max(((1 - sigma + gamma * mu * sigma) / (1 - sigma + gamma * mu)) ** 2,
               ((sigma + (1 - sigma) * gamma * L) / (1 + (1 - sigma) * gamma * L)) ** 2) ** n


@pytest.fixture(scope="module")
def drs_docs(tmp_path_factory):
    out = {}
    for mu, L, n, gamma, sigma in DRS_SETS:  # the spec's mu = 1/10: f, g scaled by 1/(10 mu)
        # a decimal is read exactly: 1.4 * 10 * 0.1 = 1.4000000000000001 would be a
        # method other than the spec's gamma = 7/5 (which the tamper test checks against)
        res = run(["pep", DRS, "--kappa", L / mu, "--steps", n, "--set",
                   f"gamma={round(gamma * 10 * mu, 12)!r}", "--set", f"sigma={sigma}", "--out",
                   tmp_path_factory.mktemp("drs"), "--json", "--no-plot"])
        assert res.exit_code == 0, res.output
        out[(mu, L, n, gamma, sigma)] = json.loads(res.stdout)
    return out


@pytest.mark.parametrize("key", DRS_SETS)
def test_douglas_rachford_proves_the_tight_rate(drs_docs, key):
    doc = drs_docs[key]
    proof = doc["certificate"]["proof"]
    assert proof["proven"], proof
    closed = drs_theory(*key)
    assert closed * (1 - 1e-9) <= proof["tau_proven_float"] <= closed * (1 + 1e-6)
    check = doc["witness"]["check"]
    assert check["verified"], check
    assert closed * (1 - 1e-3) <= check["tau_lower_float"] <= proof["tau_proven_float"]


def _drs_run(a, b, c, z0, mu_gamma_sigma_n, rng):
    """|z_n - z*|^2 / |z_0 - z*|^2 of the method on f = a/2 (x - b)^2, g = c |x|, every
    inexact prox x = z - gamma d chosen (greedily or at random) among grid points with
    |grad f(x) - d| <= sigma |d + h|, h = (x - gamma grad f(x) - y)/gamma, y the exact
    prox of g there."""
    gamma, sigma, n = mu_gamma_sigma_n
    xs = np.sign(b) * max(abs(b) - c / a, 0.0)  # the minimizer of f + g
    zs = xs + gamma * a * (xs - b)
    z = zs + z0
    for _ in range(n):
        p = (z + gamma * a * b) / (1 + gamma * a)  # the exact prox of f
        best = []
        for x in p + np.linspace(-1, 1, 1201) * max(abs(z - p), 1e-9):
            d, gf = (z - x) / gamma, a * (x - b)
            w = x - gamma * gf
            y = np.sign(w) * max(abs(w) - gamma * c, 0.0)
            h = (w - y) / gamma
            if abs(gf - d) <= sigma * abs(d + h) + 1e-12:
                best.append(z + y - x)
        z = (max(best, key=lambda v: abs(v - zs)) if rng.random() < 0.7
             else best[rng.integers(len(best))])
    return (z - zs) ** 2 / z0 ** 2


@pytest.mark.parametrize("key", DRS_SETS[1:])
def test_douglas_rachford_runs_stay_below_the_proof(drs_docs, key):
    mu, L, n, gamma, sigma = key
    proven = drs_docs[key]["certificate"]["proof"]["tau_proven_float"]
    rng = np.random.default_rng(5)
    worst = 0.0
    for a in (mu, L, (mu + L) / 2):
        for b, c in ((0.0, 0.0), (1.0, 0.3), (-2.0, 1.0), (0.5, 5.0)):
            for z0 in (1.0, -1.0):
                worst = max(worst, _drs_run(a, b, c, z0, (gamma, sigma, n), rng))
    assert worst <= proven * (1 + 1e-9)
    assert worst >= 0.5 * proven  # the runs come near the worst case


def test_gradient_of_a_call_elsewhere_and_relative_to_bad_input(tmp_path):
    text = DRS.read_text()
    cases = [
        ("  - {function: f, gradient_of: 1}", "  - {function: f, gradient_of: 3}",
         "oracles[1].gradient_of"),
        ("  - {function: f, gradient_of: 1}", "  - {function: g, gradient_of: 1}",
         "oracles[1].gradient_of"),
        ("relative_to: [1, 0, 1]", "relative_to: [1, 0]", "oracles[0].relative_to"),
        ("relative_to: [1, 0, 1]", "relative_to: [0, 0, 0]", "oracles[0].relative_to"),
        ("[-gamma, 0, 0], [-gamma, 0, 0]", "[-gamma, 0, 0], [-2*gamma, 0, 0]",
         "oracles[1].gradient_of"),
    ]
    for old, new, field in cases:
        assert old in text, old
        path = tmp_path / "bad.yaml"
        path.write_text(text.replace(old, new))
        res = run(["pep", path, "--kappa", 50, "--steps", 1, "--out", tmp_path / "o"])
        assert res.exit_code == 2, (new, res.output)
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and field in lines[0] and "bad.yaml" in lines[0], res.output


def test_douglas_rachford_witness_tampered_is_refused(drs_docs):
    from sosalgo.spec import load_spec
    from sosalgo.worstcase.check import check_witness

    wit = drs_docs[DRS_SETS[0]]["witness"]  # the spec's own gamma, sigma and kappa
    spec = load_spec(DRS)
    assert check_witness(wit, spec)["verified"]
    bad = json.loads(json.dumps(wit))  # the true gradient's call answers something else
    bad["calls"][0][1] = [str(Fraction(v) * 2) for v in bad["calls"][0][1]]
    assert not check_witness(bad, spec)["verified"]


def test_the_api_refuses_a_rate_for_inexact_calls():
    """A Lyapunov rate of the exact method would not bound the inexact one (the gallery
    shows these specs' PEP values instead)."""
    import sosalgo
    from sosalgo.errors import InputError

    for spec, kappa in ((DRS, 50), (ROOT / "specs" / "inexact-gradient.yaml", 10)):
        with pytest.raises(InputError, match="relative_error"):
            sosalgo.analyze(spec, kappa=kappa)
