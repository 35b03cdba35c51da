"""A class parameter that names a spec parameter (``functions: {B: {class: cocoercive,
beta: beta}}``): ``--set beta=VALUE`` changes the class exactly for ``pep``, its proof, the
witness and ``verify``; ``analyze`` carries a fixed value; a free one and bad input are
refused (exit 2, one line)."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

SPECS = Path(__file__).resolve().parent.parent / "specs"
DAVIS_YIN = str(SPECS / "davis-yin.yaml")

# PEPit (wrapper="cvxpy", solver="CLARABEL", verbose=-1), computed once:
#   wc_three_operator_splitting(L, mu, beta, alpha, theta)
#   (examples/monotone_inclusions_variational_inequalities/three_operator_splitting.py)
# Scaled to the spec's m = 1/10 (every operator times 1/(10 mu)): kappa = L/mu, the
# resolvent step 10 mu alpha, B's cocoercivity 10 mu beta; a contraction factor is unchanged.
PEPIT = [  # (kappa, alpha, theta, beta) as set, PEPit's (L, mu, beta, alpha, theta), tau
    (("10", "9/10", "13/10", "1/20"), (1, 0.1, 0.05, 0.9, 1.3), 0.8688822558089871),
    (("5", "1", "1", "2"), (1, 0.2, 1, 0.5, 1), 0.8100000046201556),
    (("20", "3/2", "4/5", "3/10"), (2, 0.1, 0.3, 1.5, 0.8), 1.960000051677804),
]
PEPIT_ACCURACY = 1e-7


def _pep(out: Path, kappa: str, alpha: str, theta: str, beta: str, *extra: str):
    return CliRunner().invoke(cli, [
        "pep", DAVIS_YIN, "--kappa", kappa, "--steps", "1", "--measure", "contraction",
        "--set", f"alpha={alpha}", "--set", f"theta={theta}", "--set", f"beta={beta}",
        "--out", str(out), *extra])


def _document(out: Path, kappa: str) -> dict:
    return json.loads((out / f"davis-yin-pep-k{kappa}-N1.json").read_text())


@pytest.mark.parametrize("args, pepit_args, pepit_tau", PEPIT,
                         ids=["beta1/20", "beta2", "beta3/10"])
def test_set_class_parameter_against_pepit(tmp_path, args, pepit_args, pepit_tau):
    """The scaled argument set agrees with PEPit's tau, proven not below it, and the
    proof's class records B's beta exactly as set."""
    res = _pep(tmp_path, *args)
    assert res.exit_code == 0, res.output
    doc = _document(tmp_path, args[0])
    _, mu, beta, alpha, theta = pepit_args
    set_alpha, set_theta, set_beta = (Fraction(a) for a in args[1:])  # the scaling
    assert (float(set_alpha), float(set_theta), float(set_beta)) == pytest.approx(
        (10 * mu * alpha, theta, 10 * mu * beta), rel=1e-12)
    proven = float(Fraction(doc["certificate"]["tau_proven"]))
    assert doc["tau"] == pytest.approx(pepit_tau, rel=1e-6)
    assert proven >= pepit_tau * (1 - PEPIT_ACCURACY)
    assert proven == pytest.approx(pepit_tau, rel=1e-6)
    assert doc["class"]["functions"]["B"]["params"]["beta"] == args[3]
    assert doc["certificate"]["proof"]["class"]["functions"]["B"]["params"]["beta"] == args[3]


def test_verify_rebuilds_the_class_as_set_and_refuses_a_tampered_parameter(tmp_path):
    """verify accepts the document as written; with B's beta edited in the recorded class
    (the overrides still saying beta = 2) it is refused."""
    res = _pep(tmp_path, "5", "1", "1", "2")
    assert res.exit_code == 0, res.output
    path = tmp_path / "davis-yin-pep-k5-N1.json"
    ok = CliRunner().invoke(cli, ["verify", str(path)])
    assert ok.exit_code == 0, ok.output
    doc = json.loads(path.read_text())
    assert doc["set"]["beta"] == "2"
    for where in (doc["class"], doc["certificate"]["proof"]["class"]):
        where["functions"]["B"]["params"]["beta"] = "3"
    tampered = tmp_path / "tampered.json"
    tampered.write_text(json.dumps(doc))
    bad = CliRunner().invoke(cli, ["verify", str(tampered)])
    assert bad.exit_code != 0
    assert "NOT verified" in bad.output or "not verified" in bad.output


def test_analyze_carries_a_fixed_class_parameter(tmp_path):
    """analyze with --set beta=1/20 certifies (exact check) a slower rate than at the
    spec's beta = 1: the class it certifies is the one as set. At beta = 1/20 the one-step
    contraction is PEPit's 0.86888 (above), so no rate below its square root holds for
    |w_1 - w_1'|; the certified rate is at least that."""
    rows = {}
    for beta in ("1", "1/20"):
        out = tmp_path / beta.replace("/", "_")
        res = CliRunner().invoke(cli, ["analyze", DAVIS_YIN, "--set", f"beta={beta}",
                                       "--verify", "--json", "--out", str(out)])
        assert res.exit_code == 0, res.output
        doc = json.loads(res.output[res.output.index("{"):])
        rows[beta] = doc["rows"][0] if "rows" in doc else doc
    assert rows["1/20"]["rho"] > rows["1"]["rho"] + 0.03


@pytest.mark.parametrize("args, message", [
    (["pep", DAVIS_YIN, "--kappa", "10", "--steps", "1", "--set", "beta=x"], "beta"),
    (["pep", DAVIS_YIN, "--kappa", "10", "--steps", "1", "--set", "beta=-1"], "beta"),
    (["pep", DAVIS_YIN, "--kappa", "10", "--steps", "1", "--set", "gamma=1"], "gamma"),
])
def test_bad_input_exits_2(tmp_path, args, message):
    res = CliRunner().invoke(cli, [*args, "--out", str(tmp_path)])
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and message in res.output
    assert not list(tmp_path.iterdir())


def test_a_free_class_parameter_is_refused_by_design(tmp_path):
    text = (SPECS / "davis-yin.yaml").read_text().replace(
        "  beta: {value: 1}", "  beta: {value: 1, range: [1/2, 2]}")
    spec = tmp_path / "dy.yaml"
    spec.write_text(text)
    res = CliRunner().invoke(cli, ["design", str(spec), "--free", "beta", "--out",
                                   str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    assert "functions.B.beta" in res.output and "free parameter beta" in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_a_class_parameter_naming_a_per_step_or_unknown_name_is_refused(tmp_path):
    base = (SPECS / "davis-yin.yaml").read_text()
    for old, new, field in [
        ("beta: beta}", "beta: gamma}", "functions.B.beta"),
        ("  beta: {value: 1}", "  beta: {value: 1, per_step: true}", "functions.B.beta"),
    ]:
        spec = tmp_path / "dy.yaml"
        spec.write_text(base.replace(old, new, 1))
        res = CliRunner().invoke(cli, ["pep", str(spec), "--kappa", "10", "--steps", "1",
                                       "--out", str(tmp_path / "o")])
        assert res.exit_code == 2, res.output
        assert field in res.output
