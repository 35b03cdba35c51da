"""kappa proven as written: ``10/3`` is 10/3 (not the float nearest it), the decimal ``3.3``
is 33/10, an irrational kappa is enclosed in a ball that holds it. Judges: closed forms of
gradient descent computed here in fractions."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest
from click.testing import CliRunner

from sosalgo.cli import cli
from sosalgo.exact_method import exact_algorithm
from sosalgo.kernel.kappa import exact_kappa
from sosalgo.spec import load_spec, spec_from_text

SPECS = Path(__file__).resolve().parent.parent / "specs"
TENTHIRDS = Fraction(10, 3)


def _run(*args: str):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def _gradient_text(kappa: str, h: str = "2/(m+L)") -> str:
    """gradient.yaml with step ``h`` and the kappa list ``kappa``."""
    text = (SPECS / "gradient.yaml").read_text()
    text = text.replace("h: {value: 1/L, range: [0, 2/L]}", f"h: {{value: {h}}}")
    assert f"h: {{value: {h}}}" in text
    return text.replace("kappa: [2, 5, 10, 20, 50, 100]", f"kappa: {kappa}")


def test_spec_kappas_are_their_written_values():
    spec = spec_from_text(_gradient_text('[10/3, 1e3, 3.3, 2.5, "sqrt(2)*5"]'))
    vals = [exact_kappa(k) for k in spec.kappa]
    assert vals[:4] == [TENTHIRDS, 1000, Fraction(33, 10), Fraction(5, 2)]
    assert vals[4] ** 2 == 50 and vals[4] > 0  # exactly sqrt(50), not a float
    assert [float(k) for k in spec.kappa][:2] == [10 / 3, 1000.0]  # the floats unchanged


def test_range_points_are_decimals_of_their_floats():
    spec = spec_from_text(_gradient_text("{from: 10/3, to: 30, points: 3, scale: linear}"))
    mid = (10 / 3 + 30) / 2  # numpy's linspace midpoint, the float
    assert [float(k) for k in spec.kappa] == pytest.approx([10 / 3, mid, 30], rel=1e-15)
    assert exact_kappa(spec.kappa[0]) == TENTHIRDS and exact_kappa(spec.kappa[2]) == 30
    assert exact_kappa(spec.kappa[1]) == Fraction(repr(float(spec.kappa[1])))


def test_exact_algorithm_takes_kappa_as_written():
    spec = spec_from_text(_gradient_text("[10/3]"))
    ex = exact_algorithm(spec, spec.kappa[0])
    assert ex.kappa == TENTHIRDS and ex.L == TENTHIRDS
    h = ex.params["h"]
    assert h == Fraction(2, 1) / (1 + TENTHIRDS)  # 2/(m+L) = 6/13 exactly
    # a float: the shortest decimal that reads back as it; a Fraction: itself
    assert exact_algorithm(spec, 10 / 3).kappa == Fraction("3.3333333333333335")
    assert exact_algorithm(spec, 3.3).kappa == Fraction(33, 10)
    assert exact_algorithm(spec, Fraction(3.3)).kappa == Fraction(3.3) != Fraction(33, 10)
    with pytest.raises(ValueError, match="irrational"):
        exact_algorithm(spec, spec_from_text(_gradient_text('["sqrt(2)*5"]')).kappa[0])


def _analyze(tmp_path: Path, spec: str, *extra: str) -> dict:
    res = _run("analyze", spec, "--out", str(tmp_path / "out"), "--verify", "--json",
               "--quiet", "--no-plot", *extra)
    assert res.exit_code == 0, res.output
    return json.loads(res.output)


def _check_gradient_row(doc: dict) -> None:
    """h = 2/(m+L): the rate is (kappa - 1)/(kappa + 1) = 7/13 at kappa = 10/3; the proven
    rate is at least that, and the proof is about kappa = 10/3 exactly."""
    (row,) = doc["rows"]
    assert row["kappa_exact"] == "10/3"
    closed = (TENTHIRDS - 1) / (TENTHIRDS + 1)
    assert closed == Fraction(7, 13)
    ver = row["verification"]
    assert ver["verified"] == "exact"
    proven = Fraction(ver["rho_proven"])
    assert proven >= closed
    assert float(proven) == pytest.approx(float(closed), rel=1e-5)
    cert = json.loads(Path(ver["certificate_file"]).read_text())
    assert cert["kappa"] == "10/3" and cert["L"] == "10/3"


def test_analyze_spec_kappa_ten_thirds(tmp_path):
    path = tmp_path / "gradient.yaml"
    path.write_text(_gradient_text("[10/3]"))
    _check_gradient_row(_analyze(tmp_path, str(path)))


def test_analyze_cli_kappa_ten_thirds_and_verify(tmp_path):
    doc = _analyze(tmp_path, str(SPECS / "gradient.yaml"), "--kappa", "10/3",
                   "--set", "h=2/(m+L)")
    _check_gradient_row(doc)
    path = tmp_path / "doc.json"
    path.write_text(json.dumps(doc))
    ok = _run("verify", str(path), "--out", str(tmp_path / "v"))
    assert ok.exit_code == 0, ok.output
    old = json.loads(json.dumps(doc))
    del old["rows"][0]["kappa_exact"]  # a document written before rows recorded it
    path.write_text(json.dumps(old))
    assert _run("verify", str(path), "--out", str(tmp_path / "v")).exit_code == 0
    doc["rows"][0]["kappa_exact"] = "3"  # not the number kappa is the float of
    path.write_text(json.dumps(doc))
    bad = _run("verify", str(path), "--out", str(tmp_path / "v"))
    assert bad.exit_code == 2
    assert "kappa_exact" in bad.output and "Traceback" not in bad.output


def _pep(tmp_path: Path, kappa: str, steps: str, *extra: str) -> dict:
    res = _run("pep", str(SPECS / "gradient.yaml"), "--kappa", kappa, "--steps", steps,
               "--measure", "dist", "--json", "--quiet", "--no-plot",
               "--out", str(tmp_path / "pep"), *extra)
    assert res.exit_code == 0, res.output
    return json.loads(res.output)


def test_pep_kappa_ten_thirds(tmp_path):
    """|x_2 - x*|^2 <= ((kappa - 1)/(kappa + 1))^4 |x_0 - x*|^2 for h = 2/(m+L), tight."""
    doc = _pep(tmp_path, "10/3", "2", "--set", "h=2/(m+L)")
    closed = ((TENTHIRDS - 1) / (TENTHIRDS + 1)) ** 4
    proven = Fraction(doc["certificate"]["tau_proven"])
    assert proven >= closed
    assert float(proven) == pytest.approx(float(closed), rel=1e-5)
    assert doc["kappa_exact"] == "10/3"
    assert doc["class"]["kappa"] == "10/3" and doc["class"]["L"] == "10/3"
    assert doc["class"]["functions"]["f"]["params"]["L"] == "10/3"
    path = tmp_path / "pep.json"
    path.write_text(json.dumps(doc))
    assert _run("verify", str(path)).exit_code == 0
    doc["kappa_exact"] = repr(10 / 3)  # the float's decimal: another class than claimed
    path.write_text(json.dumps(doc))
    assert _run("verify", str(path)).exit_code != 0


def test_pep_irrational_kappa_over_a_ball(tmp_path):
    """kappa = sqrt(2)*5 = sqrt(50): h = 1/L, |x_1 - x*|^2 <= (1 - 1/kappa)^2 |x_0 - x*|^2."""
    doc = _pep(tmp_path, "sqrt(2)*5", "1")
    lo, hi = (Fraction(v) for v in doc["kappa_enclosure"])
    assert lo < hi and lo * lo <= 50 <= hi * hi and hi - lo < Fraction(1, 10**20)
    assert doc["class"]["kappa"] == "5*sqrt(2)"
    proven = Fraction(doc["certificate"]["tau_proven"])
    below = Fraction(7071, 1000)  # 7.071^2 < 50: (1 - 1/kappa)^2 grows with kappa
    assert below * below < 50
    assert proven >= (1 - 1 / below) ** 2
    assert float(proven) == pytest.approx((1 - 50 ** -0.5) ** 2, rel=1e-5)
    path = tmp_path / "pep.json"
    path.write_text(json.dumps(doc))
    assert _run("verify", str(path)).exit_code == 0


def test_shipped_spec_plain_kappas_unchanged():
    """Plain numbers are their decimals: the shipped list is exactly the integers."""
    spec = load_spec(SPECS / "gradient.yaml")
    assert [exact_kappa(k) for k in spec.kappa] == [2, 5, 10, 20, 50, 100]
