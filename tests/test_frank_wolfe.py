"""Linear minimization calls (``oracles: [f, {function: h, lmo: 1}]``) and the shipped
``frank-wolfe.yaml`` (PEPit's ``composite_convex_minimization/frank_wolfe``).

PEPIT holds PEPit's own values, computed once outside sosalgo: PEPit 0.5.1 (its own
venv), cvxpy with Clarabel, ``wc_frank_wolfe(L, D, R=inf, center=None, n)``. The closed
form is Jaggi (2013), Theorem 1: F(x_N) - F* <= 2 L D^2 / (N + 2), an upper bound only.
The one-step value is worked out by hand in its test.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from sosalgo.cli import cli

from .conftest import pep_json

SPEC = Path(__file__).resolve().parents[1] / "specs" / "frank-wolfe.yaml"

# (L, D, N): PEPit's value (see the module)
PEPIT = {(1, "1", 2): 0.3126169926968837,
         (2, "1", 2): 0.6252339776263388,
         (1, "1/2", 3): 0.056962029723565996}


def _variant(tmp_path: Path, **changes) -> Path:
    data = yaml.safe_load(SPEC.read_text(encoding="utf-8"))
    data.update(changes)
    path = tmp_path / "frank-wolfe-variant.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def _pep(spec: Path, tmp_path: Path, steps: int, *extra: str) -> dict:
    return pep_json(spec, tmp_path / "o", steps, *extra)


@pytest.mark.parametrize("L,D,steps", sorted(PEPIT))
def test_frank_wolfe_agrees_with_pepit(tmp_path, L, D, steps):
    """The SDP's value is PEPit's; the exact proof is at or above it (never below beyond
    PEPit's accuracy) and below the closed form 2 L D^2 / (N + 2)."""
    spec = _variant(tmp_path, L=L) if L != 1 else SPEC
    doc = _pep(spec, tmp_path, steps, "--set", f"D={D}")
    pepit = PEPIT[(L, D, steps)]
    assert doc["tau"] == pytest.approx(pepit, rel=1e-5)
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert pepit * (1 - 1e-6) <= upper <= pepit * (1 + 1e-4)
    assert upper <= 2 * L * Fraction(D) ** 2 / (steps + 2)


def test_one_step_is_half_l_d_squared(tmp_path):
    """N = 1: x_1 = s_0. f(s_0) - f* <= <g_0, s_0 - x*> + L/2 |s_0 - x_0|^2 <= L D^2 / 2
    (s_0 minimizes <g_0, .> over the set; smoothness and convexity at x_0), attained by
    f = L x^2 / 2 on [0, D] from x_0 = x* = 0 (g_0 = 0: s_0 = D is a minimizer). The SDP
    finds L D^2 / 2 (no proof is asked: the problem is degenerate there)."""
    doc = _pep(SPEC, tmp_path, 1, "--no-witness")
    assert doc["tau"] == pytest.approx(0.5, rel=1e-3)  # a degenerate SDP: 2e-4 here


def _write(tmp_path: Path, oracles: object, **extra) -> Path:
    data = yaml.safe_load(SPEC.read_text(encoding="utf-8"))
    data["oracles"] = oracles
    data.update(extra)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


@pytest.mark.parametrize("oracles,field", [
    (["f", {"function": "h", "lmo": 2}], "oracles[1].lmo"),
    (["f", {"function": "h", "lmo": "y1"}], "oracles[1].lmo"),
    ([{"function": "h", "lmo": 1}, "f"], "oracles[0].lmo"),
    (["f", {"function": "h", "lmo": 1, "relative_error": "1/10"}], "oracles[1].lmo"),
])
def test_bad_lmo_entries_are_refused_in_one_line(tmp_path, oracles, field):
    """A direction that is not an earlier call, an LMO of a class that is no indicator,
    an LMO with a relative error: one line naming the file and the field, exit 2."""
    path = _write(tmp_path, oracles)
    r = CliRunner().invoke(cli, ["pep", str(path), "--steps", "2", "--out",
                                 str(tmp_path / "o")])
    assert r.exit_code == 2, r.output
    assert str(path) in r.output and field in r.output and "Traceback" not in r.output


def test_an_lmo_needs_an_indicator(tmp_path):
    path = _write(tmp_path, ["f", {"function": "h", "lmo": 1}],
                  functions={"f": {"class": "smooth_strongly_convex"},
                             "h": {"class": "smooth_strongly_convex"}})
    r = CliRunner().invoke(cli, ["pep", str(path), "--steps", "2", "--out",
                                 str(tmp_path / "o")])
    assert r.exit_code == 2 and "oracles[1].lmo" in r.output, r.output


def test_analyze_refuses_a_linear_minimization_oracle(tmp_path):
    r = CliRunner().invoke(cli, ["analyze", str(SPEC), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "Traceback" not in r.output


def test_iterates_outside_the_set_are_not_evaluated(tmp_path):
    """A step longer than 1 (x+ = x + 2 (s - x)) may leave the set: h is not evaluated at
    x_N, so the measure f (which includes h(x_N)) is refused in one line."""
    path = _write(tmp_path, ["f", {"function": "h", "lmo": 1}],
                  parameters={"D": 1, "lam": 2})
    r = CliRunner().invoke(cli, ["pep", str(path), "--steps", "2", "--out",
                                 str(tmp_path / "o")])
    assert r.exit_code == 2, r.output
    assert "h (bounded_indicator) is not evaluated" in r.output


def test_a_constant_step_below_one_is_unbounded(tmp_path):
    """x+ = (x + s)/2 on C = [0, 1], f = L/2 (x + M)^2: x* = 0, from x_0 = 1 the LMO gives
    s_0 = 0 and x_1 = 1/2, f(x_1) - f* = L/2 (M + 1/4): no bound (Frank-Wolfe needs its
    first step of length 1). The PEP says unbounded, and refuses the contraction measure
    (its two-run PEP does not model the oracle)."""
    path = _write(tmp_path, ["f", {"function": "h", "lmo": 1}],
                  parameters={"D": 1, "lam": "1/2"})
    doc = _pep(path, tmp_path, 2, "--no-witness")
    assert doc["status"] == "unbounded" and doc["tau"] == float("inf")
    r = CliRunner().invoke(cli, ["pep", str(path), "--steps", "2", "--measure", "contraction",
                                 "--out", str(tmp_path / "c")])
    assert r.exit_code == 2 and "linear minimization call" in r.output, r.output
