"""The spec field ``initial_state:`` (xi_0 = u x0 + b g0) and ``pep`` from that start,
against closed forms: gradient descent started one step ahead is gradient descent with
one more step."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.spec import SpecError, load_spec

SPECS = Path(__file__).resolve().parent.parent / "specs"

GD = """name: gd-ahead
parameters:
  h: {value: 1/L, range: [0, 2/L]}
matrices:
  A: [[1]]
  B: [[-h]]
  C: [[1]]
  E: [[1]]
initial_state: [INIT]
kappa: [10]
"""

GD_CONVEX = """name: gdc-ahead
m: 0
L: 1
parameters:
  h: 1/L
matrices:
  A: [[1]]
  B: [[-h]]
  C: [[1]]
  E: [[1]]
initial_state: [x0 - h*g0]
"""

NESTEROV = (SPECS / "nesterov.yaml").read_text()


def _spec(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_parsed_as_linear_coefficients(tmp_path):
    spec = load_spec(_spec(tmp_path, GD.replace("INIT", "x0 - h*g0")))
    assert spec.initial_state is not None and len(spec.initial_state) == 1
    assert load_spec(SPECS / "gradient.yaml").initial_state is None


@pytest.mark.parametrize("N", [1, 3])
def test_gradient_one_step_ahead_distance(tmp_path, N):
    """x_0' = x_0 - g0/L: |x_N - x*|^2 <= 0.81^(N+1) |x_0 - x*|^2 at kappa 10, tight
    (h = 1/L on F(1, 10): max(|1 - h m|, |1 - h L|) = 0.9); proven upper bound and
    verified witness bracket it."""
    path = _spec(tmp_path, GD.replace("INIT", "x0 - h*g0"))
    res = sosalgo.pep(path, 10, N, measure="dist")
    closed = 0.81 ** (N + 1)
    assert res.tau == pytest.approx(closed, rel=1e-6)
    proven = Fraction(res.certificate["tau_proven"])
    assert float(proven) == pytest.approx(closed, rel=1e-5) and proven >= Fraction(closed)
    chk = res.witness["check"]
    assert chk["verified"]
    assert Fraction(chk["tau_lower"]) <= Fraction(closed)
    assert chk["tau_lower_float"] == pytest.approx(closed, rel=1e-3)


def test_gradient_convex_one_step_ahead(tmp_path):
    """m = 0: N steps from x_0 - g0/L are N + 1 steps of h = 1/L: L / (4(N + 1) + 2)
    (Drori-Teboulle)."""
    N = 2
    res = sosalgo.pep(_spec(tmp_path, GD_CONVEX), None, N)
    assert res.tau == pytest.approx(1 / (4 * (N + 1) + 2), rel=1e-6)
    assert float(Fraction(res.certificate["tau_proven"])) == pytest.approx(1 / 14, rel=1e-5)
    assert res.witness["check"]["verified"]


def test_witness_checks_the_start(tmp_path):
    """`sosalgo verify` recomputes xi_0 = u x0 + b g0 from the spec: the witness of the
    shifted start verifies; the same document against the default start fails."""
    path = _spec(tmp_path, GD.replace("INIT", "x0 - h*g0"))
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(path), "--kappa", "10", "--steps", "2",
                                 "--measure", "dist", "--out", str(out), "--quiet",
                                 "--no-plot"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    wpath = out / "gd-ahead-pep-k10-N2-witness.json"
    r = CliRunner().invoke(cli, ["verify", str(wpath), "--json"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["results"][0]["verified"]
    doc = json.loads(wpath.read_text())
    doc["spec_text"] = doc["spec_text"].replace("initial_state: [x0 - h*g0]\n", "")
    bad = tmp_path / "default-start.json"
    bad.write_text(json.dumps(doc))
    r = CliRunner().invoke(cli, ["verify", str(bad)])
    assert r.exit_code == 3


def test_nesterov_one_step_ahead_is_one_more_step(tmp_path):
    """Nesterov from xi_0 = (x0, x0 - h g0) is Nesterov from (x0, x0) after its first
    step (y_0 = x_0): the same worst case with one step more."""
    text = NESTEROV.replace("kappa:", "initial_state: [x0, x0 - h*g0]\nkappa:", 1)
    res = sosalgo.pep(_spec(tmp_path, text), 10, 2, witness=False)
    ref = sosalgo.pep(SPECS / "nesterov.yaml", 10, 3, exact=False, witness=False)
    assert res.tau == pytest.approx(ref.tau, rel=1e-6)


@pytest.mark.parametrize("init,why", [
    ("x0*g0", "not a sum"),
    ("2*x0 - h*g0", "fixed-point direction"),
    ("x0 + 1", "constant term"),
    ("x0 - h*g0 + y0", "unknown name"),
])
def test_bad_initial_state(tmp_path, init, why):
    path = _spec(tmp_path, GD.replace("INIT", init))
    with pytest.raises(SpecError) as exc:
        load_spec(path)
    assert "initial_state" in str(exc.value)
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(path), "--kappa", "10", "--out", str(out)])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and "initial_state" in lines[0] and path.name in lines[0]
    assert why.split()[0] in lines[0] or why in lines[0].lower()
    assert not out.exists()


def test_wrong_length(tmp_path):
    text = NESTEROV.replace("kappa:", "initial_state: [x0]\nkappa:", 1)
    with pytest.raises(SpecError, match="initial_state"):
        load_spec(_spec(tmp_path, text))
