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


# ----------------------------------------------------------- pareto, fig4, table1, grid
def _spy_exact_kappa(monkeypatch) -> list:
    """Every exact value the proofs take kappa at (:func:`exact_kappa`, which each exact
    check calls on the kappa it is given), recorded as they run (one process)."""
    import sosalgo.kernel.kappa as kmod

    seen: list = []
    real = kmod.exact_kappa

    def spy(kappa):
        val = real(kappa)
        seen.append(val)
        return val

    monkeypatch.setattr(kmod, "exact_kappa", spy)
    return seen


def _about_ten_thirds(seen: list) -> None:
    """Some proof ran near kappa = 10/3, and every one about 10/3 itself (the float
    3.3333333333333335 would read as its shortest decimal, another rational)."""
    near = [v for v in seen if abs(float(v) - 10 / 3) < 1e-9]
    assert near, "no exact check saw the kappa"
    assert all(v == TENTHIRDS for v in near), {str(v) for v in near}


def test_pareto_kappa_ten_thirds(tmp_path, monkeypatch):
    """gradient descent's front at kappa = 10/3: the fast end is h = 2/(m+L), rate 7/13;
    every exact proof is about 10/3; verify re-proves about kappa_exact."""
    seen = _spy_exact_kappa(monkeypatch)
    res = _run("pareto", str(SPECS / "gradient.yaml"), "--kappa", "10/3", "--points", "2",
               "--time-limit", "60", "--workers", "1", "--json", "--quiet", "--no-plot",
               "--out", str(tmp_path / "par"))
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    _about_ten_thirds(seen)
    assert doc["kappa_exact"] == "10/3"
    fast = doc["points"][0]
    assert fast["rho_check"] == "exact"
    proven = Fraction(fast["rho_proven"])
    assert proven >= Fraction(7, 13) and float(proven) == pytest.approx(7 / 13, rel=1e-5)
    settings = json.loads(Path(doc["csv"] + ".settings.json").read_text())
    assert settings["kappa_exact"] == ["10/3"]  # a rerun at the float does not resume it
    path = tmp_path / "pareto.json"
    path.write_text(json.dumps(doc))
    seen.clear()
    ok = _run("verify", str(path), "--out", str(tmp_path / "v"))
    assert ok.exit_code == 0, ok.output
    _about_ten_thirds(seen)
    doc["kappa_exact"] = "3"  # not the number kappa is the float of
    path.write_text(json.dumps(doc))
    bad = _run("verify", str(path), "--out", str(tmp_path / "v"))
    assert bad.exit_code != 0 and "kappa_exact" in bad.output


def test_grid_and_table1_kappa_ten_thirds(tmp_path, monkeypatch):
    """grid and table1 at --kappa 10/3: every point is analysed at the Kappa as written
    (the float for the solver, 10/3 for anything exact), and the documents record it;
    gradient descent's rate at h = 2/(m+L) is 7/13 (the spec's closed form, for h = 1/L,
    is 1 - 1/kappa)."""
    import sosalgo.batch.sweeps as sweeps
    import sosalgo.runs.table1 as t1

    given: list = []

    def spy(real):
        def analyze(spec, kappa, *args, **kw):
            given.append(exact_kappa(kappa))
            return real(spec, kappa, *args, **kw)
        return analyze

    monkeypatch.setattr(sweeps, "analyze_spec", spy(sweeps.analyze_spec))
    monkeypatch.setattr(t1, "analyze_spec", spy(t1.analyze_spec))
    res = _run("grid", str(SPECS / "gradient.yaml"), "--kappa", "10/3", "--points", "3",
               "--workers", "1", "--json", "--quiet", "--out", str(tmp_path / "grid"))
    assert res.exit_code == 0, res.output
    (grid,) = json.loads(res.output)["grids"]
    assert grid["kappa_exact"] == "10/3" and len(given) == 3
    assert all(v == TENTHIRDS for v in given)
    settings = json.loads(Path(grid["csv"] + ".settings.json").read_text())
    assert settings["kappa_exact"] == ["10/3"]
    given.clear()
    path = tmp_path / "gradient.yaml"
    path.write_text(_gradient_text("[2]"))
    from sosalgo.runs import table1_run

    doc = table1_run([str(path)], ["10/3"], out_dir=tmp_path / "t1")
    (row,) = doc["rows"]
    assert row["kappa_exact"] == "10/3" and given == [TENTHIRDS]
    assert row["closed_form_rate"] == pytest.approx(1 - 3 / 10, rel=1e-12)  # 1 - 1/kappa
    assert row["rho_certified"] == pytest.approx(7 / 13, rel=1e-5)


def test_fig4_carries_kappa_as_written(tmp_path, monkeypatch):
    """fig4's sweeps get the Kappa as written (the design's lower bound and the exact
    checks prove about it) and its data record the exact values."""
    import sosalgo.runs.fig4 as f4

    given: list = []

    def design(name, family, kappas, *a, **kw):
        given.append([exact_kappa(k) for k in kappas])
        return [{"rho_certified": 0.5, "theta": {}} for _ in kappas]

    def analysis(name, family, kappas, *a, **kw):
        given.append([exact_kappa(k) for k in kappas])
        return [{"rho": 0.5} for _ in kappas]

    monkeypatch.setattr(f4, "_design", design)
    monkeypatch.setattr(f4, "_analysis", analysis)
    monkeypatch.setattr(f4, "fig4_figure", lambda stem, data: [])
    spec = spec_from_text(_gradient_text('[10/3, 2, "7/2"]'))
    _, data = f4.fig4(tmp_path, spec.kappa)
    assert data["kappa"] == [2.0, 10 / 3, 3.5]
    assert data["kappa_exact"] == ["2", "10/3", "7/2"]
    assert given == [[2, TENTHIRDS, Fraction(7, 2)]] * 4
