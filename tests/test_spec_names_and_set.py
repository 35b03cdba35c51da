"""Names that work (a shipped example named without a path; a missing file's error names
the closest shipped example) and ``--set NAME=EXPR`` (a parameter fixed from the command
line, recorded in the result and applied again by ``verify``)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from sosalgo.cli import cli
from sosalgo.inputs import free_names
from sosalgo.spec import spec_from_text
from sosalgo.spec.overrides import apply_overrides

from .conftest import SPECS


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def analyze_json(*args) -> dict:
    res = run("analyze", *args, "--json", "--no-plot", "--quiet")
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


# --------------------------------------------------------------------------- names
def test_a_shipped_example_is_found_by_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no file named nesterov here
    doc = analyze_json("nesterov", "--kappa", 10, "--out", tmp_path / "o")
    ref = analyze_json(SPECS / "nesterov.yaml", "--kappa", 10, "--out", tmp_path / "p")
    assert doc["spec"] == "nesterov"
    assert doc["rows"][0]["rho"] == ref["rows"][0]["rho"]
    assert doc["spec_text"] == (SPECS / "nesterov.yaml").read_text()


def test_a_file_that_exists_wins_over_a_shipped_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "nesterov").write_text((SPECS / "gradient.yaml").read_text())
    doc = analyze_json("nesterov", "--kappa", 10, "--out", tmp_path / "o")
    assert doc["spec"] == "gradient"


@pytest.mark.parametrize("command", ["analyze", "design", "grid", "pep", "pareto", "lmi"])
def test_a_missing_file_names_the_closest_example(tmp_path, monkeypatch, command):
    monkeypatch.chdir(tmp_path)
    extra = ["--kappa", "10", "--out", str(tmp_path / "o")] if command != "lmi" else []
    res = run(command, "specs/nesterv.yaml", *extra)
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "specs/nesterv.yaml: no such file" in lines[0]
    assert "closest shipped example: nesterov" in lines[0] and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()


def test_lmi_takes_a_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = run("lmi", "gradient")
    assert res.exit_code == 0 and "M11" in res.stdout


# --------------------------------------------------------------------------- --set
def test_set_gives_the_closed_form_of_gradient_descent(tmp_path):
    """h = 1/L: rate 1 - 1/kappa; h = 2/(m + L): (kappa - 1)/(kappa + 1) (Polyak's closed
    forms), starting from a spec whose own step is neither."""
    path = tmp_path / "slow.yaml"
    path.write_text((SPECS / "gradient.yaml").read_text().replace("value: 1/L",
                                                                     "value: 0.3/L"))
    for expr, closed in (("1/L", lambda k: 1 - 1 / k),
                         ("2/(m + L)", lambda k: (k - 1) / (k + 1))):
        doc = analyze_json(path, "--kappa", 10, "--kappa", 50, "--set", f"h={expr}",
                           "--out", tmp_path / expr.replace("/", "_"))
        assert doc["set"] == {"h": expr}
        for row in doc["rows"]:
            assert row["certified"]
            assert closed(row["kappa"]) <= row["rho"] <= closed(row["kappa"]) + 1e-5


def test_set_equals_the_spec_edited_by_hand(tmp_path):
    value = "(sqrt(kappa) - 1)/(sqrt(kappa) + 1)"
    edited = tmp_path / "nesterov.yaml"
    edited.write_text((SPECS / "nesterov.yaml").read_text().replace(
        f"beta: {{value: {value}, range: [0, 1]}}", "beta: 1/2"))
    assert "beta: 1/2" in edited.read_text()
    by_hand = analyze_json(edited, "--kappa", 5, "--kappa", 20, "--out", tmp_path / "a")
    by_set = analyze_json(SPECS / "nesterov.yaml", "--kappa", 5, "--kappa", 20, "--set",
                          "beta=1/2", "--out", tmp_path / "b")
    for a, b in zip(by_hand["rows"], by_set["rows"], strict=True):
        assert a["certified"] == b["certified"]
        assert b["rho"] == pytest.approx(a["rho"], abs=1e-9)


def test_set_fixes_a_parameter_that_was_free_in_a_design():
    text = (SPECS / "nesterov.yaml").read_text()
    assert free_names(spec_from_text(text, "n"), None) == ["h", "beta"]
    fixed = spec_from_text(apply_overrides(text, {"beta": "1/2"}, "n"), "n")
    assert free_names(fixed, None) == ["h"]


@pytest.mark.parametrize("option,words", [
    ("x=1", ["--set x", "unknown parameter"]),
    ("h=1/", ["--set h", "cannot parse"]),
    ("h=foo(L)", ["--set h", "'foo'"]),
    ("h=h", ["--set h", "cycle"]),
    ("h", ["--set h", "NAME=EXPR"]),
])
@pytest.mark.parametrize("command", ["analyze", "grid", "pep", "design", "pareto"])
def test_a_bad_set_is_one_line_naming_it(tmp_path, command, option, words):
    out = tmp_path / "o"
    res = run(command, SPECS / "nesterov.yaml", "--kappa", 10, "--set", option, "--out", out)
    assert res.exit_code == 2 and "Traceback" not in res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and all(w in lines[0] for w in words), lines
    assert not out.exists()


def test_verify_applies_the_recorded_set_and_refuses_a_tampered_one(tmp_path):
    doc = analyze_json(SPECS / "gradient.yaml", "--kappa", 10, "--set", "h=2/(m + L)",
                       "--out", tmp_path / "o")
    assert doc["rows"][0]["rho"] == pytest.approx(9 / 11, abs=1e-5)
    good = tmp_path / "good.json"
    good.write_text(json.dumps(doc))
    assert run("verify", good, "--out", tmp_path / "v").exit_code == 0
    doc["set"] = {"h": "1.5/L"}
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    res = run("verify", bad, "--out", tmp_path / "v")
    assert res.exit_code == 3 and "set" in res.output
    # against the spec file, the tampered override is applied: the certificate fails
    res = run("verify", bad, "--spec", SPECS / "gradient.yaml", "--out", tmp_path / "v")
    assert res.exit_code == 3


def test_pep_records_set_and_verify_rechecks_it(tmp_path):
    res = run("pep", SPECS / "gradient.yaml", "--kappa", 10, "--steps", 2, "--set",
              "h=2/(m + L)", "--out", tmp_path / "o", "--json", "--quiet", "--no-plot")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["set"] == {"h": "2/(m + L)"}
    # f(x_2) - f* <= L/2 |x_2 - x*|^2 <= L/2 ((kappa - 1)/(kappa + 1))^4 |x_0 - x*|^2,
    # tight on the quadratic of curvature L: the closed form
    assert doc["tau"] == pytest.approx(10 / 2 * (9 / 11) ** 4, rel=1e-6)
    path = tmp_path / "pep.json"
    path.write_text(json.dumps(doc))
    assert run("verify", path).exit_code == 0
    doc["set"] = {"h": "1/L"}
    path.write_text(json.dumps(doc))
    assert run("verify", path).exit_code == 3


def test_grid_records_set(tmp_path):
    res = run("grid", SPECS / "nesterov.yaml", "--kappa", 10, "--points", 3, "--set",
              "beta=1/2", "--out", tmp_path, "--json", "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["set"] == {"beta": "1/2"} and doc["free"] == ["h"]
    assert doc["grids"][0]["points"] == 3


def test_design_with_set_designs_the_other_parameters(tmp_path):
    res = run("design", SPECS / "nesterov.yaml", "--kappa", 10, "--set", "beta=1/2",
              "--time-limit", 5, "--out", tmp_path, "--json", "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["free"] == ["h"] and doc["set"] == {"beta": "1/2"}
    assert set(doc["theta"]) == {"h"}


def test_design_with_every_range_fixed_by_set_says_so(tmp_path):
    """gradient.yaml has one ranged parameter; fixing it leaves nothing to design: one line
    naming the parameters and --set, exit 2, nothing written."""
    res = CliRunner().invoke(cli, ["design", str(SPECS / "gradient.yaml"), "--kappa", "10",
                                   "--set", "h=1/L", "--out", str(tmp_path / "d")])
    assert res.exit_code == 2
    assert "parameters" in res.output and "--set" in res.output
    assert not (tmp_path / "d").exists() or not any((tmp_path / "d").iterdir())


def test_lmi_takes_set_and_substitutes_the_value(tmp_path):
    """lmi --set h=1/L: the step is gone from the printed matrix and M22 of Theorem 1 for
    gradient descent is L h^2/2 + h^2 p - h - lambda/(L+m) at h = 1/L (the independent
    expansion by sympy below), so the printed entry equals it."""
    import sympy as sp

    free = run("lmi", SPECS / "gradient.yaml")
    fixed = run("lmi", SPECS / "gradient.yaml", "--set", "h=1/L")
    assert free.exit_code == 0 and fixed.exit_code == 0, fixed.output
    assert "h" in free.output.split("M22 = ")[1].splitlines()[0]
    m22 = fixed.output.split("M22 = ")[1].splitlines()[0]
    L, m, p, lam, h = sp.symbols("L m p lambda h")
    expected = (L * h**2 / 2 + h**2 * p - h - lam / (L + m)).subs(h, 1 / L)
    printed = sp.sympify(m22.replace("lambda", "lam"), locals={"lam": lam, "L": L, "m": m,
                                                               "p": p})
    assert sp.simplify(printed - expected) == 0
    bad = run("lmi", SPECS / "gradient.yaml", "--set", "q=1")
    assert bad.exit_code == 2 and "--set q" in bad.output
