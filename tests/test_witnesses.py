"""Non-convergence witnesses (cycles) and rate brackets (sosalgo.witnesses), checked
against closed forms and an independent re-check in plain fractions."""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.analysis import analyze_spec
from sosalgo.cli import cli
from sosalgo.kernel.arb import arb_of
from sosalgo.witnesses.brackets import (
    bracketed,
    has_root_outside,
    quadratic_bracket,
    rate_bracket,
)
from sosalgo.witnesses.cycles import check_cycle, find_cycle

SPECS = Path(__file__).resolve().parents[1] / "specs"


def spec(name: str):
    return sosalgo.load_spec(SPECS / f"{name}.yaml")


def vec(v: list[str]) -> list[Fraction]:
    return [Fraction(x) for x in v]


def dot(a, b) -> Fraction:
    return sum((x * y for x, y in zip(a, b, strict=True)), Fraction(0))


def sub(a, b) -> list[Fraction]:
    return [x - y for x, y in zip(a, b, strict=True)]


def interpolable(points, grads, values, m: Fraction, L: Fraction) -> bool:
    """Taylor, Hendrickx, Glineur (2017): data (x_i, g_i, f_i) come from some f in
    F(m, L) iff for every ordered pair f_i >= f_j + <g_j, x_i - x_j> + |g_i - g_j|^2/(2L)
    + m/(2(1 - m/L)) |x_i - x_j - (g_i - g_j)/L|^2 (written out here, not imported)."""
    for i in range(len(points)):
        for j in range(len(points)):
            if i == j:
                continue
            dx, dg = sub(points[i], points[j]), sub(grads[i], grads[j])
            w = [a - b / L for a, b in zip(dx, dg, strict=True)]
            rhs = (values[j] + dot(grads[j], dx) + dot(dg, dg) / (2 * L)
                   + m / (2 * (1 - m / L)) * dot(w, w))
            if values[i] < rhs:
                return False
    return True


def heavy_ball_cycle_holds(cyc: dict, m: Fraction, L: Fraction) -> bool:
    """x_{k+1} = x_k + beta (x_k - x_{k-1}) - h grad f(x_k) around the cycle, with the
    quadratic tuning h = 4/(sqrt(L) + sqrt(m))^2, beta = ((sqrt(k) - 1)/(sqrt(k) + 1))^2
    (Lessard, Recht, Packard 2016; sqrt(25) = 5), F(m, L) interpolation with x* = 0,
    and some point other than x*."""
    sk = 5
    h = Fraction(4, (sk + 1) ** 2) / m  # sqrt(L) + sqrt(m) = sqrt(m) (sqrt(k) + 1)
    beta = Fraction(sk - 1, sk + 1) ** 2
    x = [vec(p) for p in cyc["points"]]
    g = [vec(p) for p in cyc["gradients"]]
    f = [Fraction(v) for v in cyc["values"]]
    K = len(x)
    for k in range(K):
        nxt = [a + beta * (a - b) - h * c for a, b, c in zip(x[k], x[k - 1], g[k], strict=True)]
        if nxt != x[(k + 1) % K]:
            return False
    zero = [Fraction(0)] * len(x[0])
    return (interpolable(x + [zero], g + [zero], f + [Fraction(0)], m, L)
            and any(p != zero for p in x))


@pytest.fixture(scope="module")
def hb25():
    return find_cycle(spec("heavy-ball"), 25.0)


def test_heavy_ball_quadratic_tuning_cycles_at_kappa_25(hb25):
    assert hb25 is not None and hb25["exact"] and hb25["checked"]
    assert 2 <= hb25["length"] <= 8
    m = Fraction(spec("heavy-ball").m)
    assert heavy_ball_cycle_holds(hb25, m, 25 * m)  # independent re-check
    assert check_cycle(spec("heavy-ball"), 25.0, hb25) == (True, "ok")


@pytest.mark.parametrize("field", ["values", "points", "gradients"])
def test_a_tampered_cycle_fails_the_check(hb25, field):
    bad = json.loads(json.dumps(hb25))
    entry = bad[field][0]
    if field == "values":
        bad[field][0] = str(Fraction(entry) - 10**6)  # f_0 far below: interpolation fails
    else:
        entry[0] = str(Fraction(entry[0]) + 1)
    ok, why = check_cycle(spec("heavy-ball"), 25.0, bad)
    assert not ok and why != "ok"
    m = Fraction(spec("heavy-ball").m)
    assert not heavy_ball_cycle_holds(bad, m, 25 * m)


def test_the_fixed_point_is_no_cycle(hb25):
    zero = json.loads(json.dumps(hb25))
    for key in ("points", "gradients", "outputs"):
        zero[key] = [["0"] * len(v) for v in zero[key]]
    zero["states"] = [[["0"] * len(v) for v in s] for s in zero["states"]]
    zero["values"] = ["0"] * len(zero["values"])
    assert check_cycle(spec("heavy-ball"), 25.0, zero) == (False, "every output point is x*")


def test_irrational_tuning_gets_a_ball_checked_cycle():
    cyc = find_cycle(spec("heavy-ball"), 20.0)  # sqrt(20): enclosures of the real cycle
    assert cyc is not None and not cyc["exact"] and "balls" in cyc["check"]


def test_convergent_method_has_no_cycle():
    assert find_cycle(spec("gradient"), 10.0, seconds=2.0) is None


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
@pytest.mark.parametrize("hL", [1.0, 1.8])
def test_gradient_bracket_closed_form(kappa, hL):
    s = spec("gradient")
    m = s.m
    L = kappa * m
    h = hL / L
    lower, wit = quadratic_bracket(bracketed(s, kappa, {"h": h}))
    closed = max(abs(1 - h * m), abs(1 - h * L))
    assert closed - 1e-9 <= lower <= closed  # proven below the closed form, within 1e-9
    assert wit["kind"] == "quadratic"
    if hL == 1.0:
        res = analyze_spec(s, kappa)
        assert res.certified and lower <= res.rho and res.rho - lower <= 1e-5


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
def test_triple_momentum_bracket_closes(kappa):
    s = spec("triple-momentum")
    lower = quadratic_bracket(bracketed(s, kappa))[0]
    res = analyze_spec(s, kappa, family="interpolation")
    rate = 1 - 1 / math.sqrt(kappa)
    assert res.certified and lower <= res.rho
    assert res.rho - lower <= 1e-5 and abs(lower - rate) <= 1e-5


# a finite sum (one function drawn per step) is a program, not a matrix method: no bracket
LINEAR = sorted(p.stem for p in SPECS.glob("*.yaml")
                if not spec(p.stem).sublinear and spec(p.stem).finite_sum is None)


@pytest.mark.parametrize("name", LINEAR)
def test_lower_bound_below_certified_rate(name):
    s = spec(name)
    lower = quadratic_bracket(bracketed(s, 10.0))
    res = analyze_spec(s, 10.0)
    assert lower is not None  # every shipped class has quadratics
    if res.certified:
        assert lower[0] <= res.rho


@pytest.mark.parametrize("name", ["proximal-gradient", "projected-gradient"])
def test_composite_lower_bound_is_the_smooth_parts_quadratic_rate(name):
    """g convex (or the indicator of the whole space) is 0 on quadratics: the bound is
    gradient descent's max(|1 - hm|, |1 - hL|) with h = 1/L."""
    kappa = 10.0
    lower = quadratic_bracket(bracketed(spec(name), kappa))[0]
    assert 1 - 1 / kappa - 1e-9 <= lower <= 1 - 1 / kappa


def test_schur_cohn_against_known_roots():
    def poly(*roots_quads):  # product of (z - a) and (z^2 + b z + c) factors
        c = [Fraction(1)]
        for f in roots_quads:
            f = [Fraction(v) for v in f]
            out = [Fraction(0)] * (len(c) + len(f) - 1)
            for i, a in enumerate(c):
                for j, b in enumerate(f):
                    out[i + j] += a * b
            c = out
        return [arb_of(v) for v in c]

    real = poly([Fraction(-3, 4), 1], [Fraction(1, 2), -1, 1])  # 3/4, 1/2 +- i/2
    cplx = poly([Fraction(-1, 4), 1], [Fraction(9, 16), 0, 1])  # 1/4, +-3i/4
    for p in (real, cplx):
        assert has_root_outside(p, Fraction(74, 100))
        assert has_root_outside(p, Fraction(3, 4))  # on the circle counts
        assert not has_root_outside(p, Fraction(76, 100))
    assert not has_root_outside(poly([Fraction(1, 2), 0, 1]), Fraction(3, 4))  # |+-i/sqrt2|


def test_rate_bracket_below_a_cycle_is_one(hb25):
    lo, kind, _ = rate_bracket(bracketed(spec("heavy-ball"), 25.0), None)
    assert kind == "quadratic" and lo == pytest.approx(2 / 3, abs=1e-9)  # sqrt(beta)


def test_analyze_says_does_not_converge(tmp_path):
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "heavy-ball.yaml"), "--kappa", "2",
                                   "--kappa", "25", "--quiet", "--out", str(tmp_path),
                                   "--certificate", "theorem1"])
    assert res.exit_code == 0, res.output
    assert "kappa 25: does not converge: cycle of length" in res.output
    assert "kappa 2: worst-case rate in [0.171573, 0.414214]" in res.output
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "heavy-ball.yaml"), "--kappa", "2",
                                   "--kappa", "25", "--quiet", "--out", str(tmp_path),
                                   "--json", "--no-plot", "--certificate", "theorem1"])
    rows = json.loads(res.stdout)["rows"]
    assert rows[0]["cycle"] is None and rows[0]["rho_lower_kind"] == "quadratic"
    cyc = rows[1]["cycle"]
    assert set(cyc) >= {"length", "points", "gradients", "values"}
    assert rows[1]["rho_lower"] == 1.0 and rows[1]["rho_lower_kind"] == "cycle"
    assert check_cycle(spec("heavy-ball"), 25.0, cyc) == (True, "ok")


def test_bad_brackets_option_is_one_line(tmp_path):
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "gradient.yaml"), "--kappa", "2",
                                   "--brackets", "cubic", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "--brackets" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()


@pytest.mark.deep
def test_self_similar_trajectory_beats_the_quadratic_bound():
    s = spec("heavy-ball")
    ctx = bracketed(s, 10.0)
    quad = quadratic_bracket(ctx)[0]
    upper = analyze_spec(s, 10.0, family="interpolation").rho
    lo, kind, wit = rate_bracket(ctx, upper, self_similar=True, seconds=10.0)
    assert kind == "self-similar" and quad < lo <= upper
    assert Fraction(wit["rho_lower"]) == Fraction(str(lo))


@pytest.mark.parametrize("kappa", [2.0, 10.0])
@pytest.mark.parametrize("hL", [1.0, 1.8])
def test_two_state_gradient_form_gets_its_bracket(kappa, hL):
    """three-parameter with beta = gamma = 0 is gradient descent on two states whose first
    is never read (the observability matrix is singular): the bracket comes from the
    states that reach the output, max(|1 - hm|, |1 - hL|) (closed form)."""
    s = spec("three-parameter")
    m, L = s.m, kappa * s.m
    h = hL / L
    lower, wit = quadratic_bracket(bracketed(s, kappa, {"h": h, "beta": 0.0, "gamma": 0.0}))
    closed = max(abs(1 - h * m), abs(1 - h * L))
    assert closed - 1e-9 <= lower <= closed
    assert "reach the output" in wit["check"]


def test_api_analyze_fills_the_witness_fields():
    """`sosalgo.analyze(..., brackets=..., cycle_seconds=...)` gives what `analyze` prints:
    Nesterov's quadratic bound at kappa 10, 1 - 1/sqrt(kappa) (at q = m the closed loop
    z^2 - (1 + beta)(1 - 1/kappa) z + beta (1 - 1/kappa) has the double root
    sqrt(beta (1 - 1/kappa)) = 1 - 1/sqrt(kappa)), and heavy ball's cycle at kappa 25; by
    default nothing."""
    res = sosalgo.analyze(spec("nesterov"), kappa=10, brackets="quadratic")
    closed = 1 - 1 / math.sqrt(10)
    assert res.rho_lower_kind == "quadratic" and abs(res.rho_lower - closed) <= 1e-9
    assert res.rho_lower <= res.rho
    assert sosalgo.analyze(spec("nesterov"), kappa=10).rho_lower is None
    hb = sosalgo.analyze(spec("heavy-ball"), kappa=25, cycle_seconds=5)
    assert not hb.certified and hb.rho_lower == 1.0 and hb.cycle["length"] >= 2
    with pytest.raises(ValueError, match="--brackets"):
        sosalgo.analyze(spec("nesterov"), kappa=10, brackets="cubic")
