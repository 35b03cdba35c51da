"""What the commands print says what the numbers mean: what rho (or c) bounds in the spec's
own measure, one name per kind of bound with a legend, the solver's internals only with
--details (always in CSV and JSON), pep's class, measure and initial condition in words,
and --noise readable in 100 characters."""

from __future__ import annotations

import csv
import json

import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

from .conftest import SPECS

INTERNALS = ("max_eig_M", "min_eig_P", "solves", "seconds")


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def table_header(text: str, first: str = "kappa") -> list[str]:
    """The header line of the first table whose header starts with ``first``."""
    return next(ln for ln in text.splitlines() if ln.startswith(first))


@pytest.fixture(scope="module")
def nesterov_theorem1(tmp_path_factory):
    out = tmp_path_factory.mktemp("t1")
    plain = run("analyze", SPECS / "nesterov.yaml", "--kappa", 10, "--out", out, "--quiet",
                "--no-plot", "--certificate", "theorem1")
    detailed = run("analyze", SPECS / "nesterov.yaml", "--kappa", 10, "--out", out, "--quiet",
                   "--no-plot", "--certificate", "theorem1", "--details")
    return out, plain, detailed


def test_analyze_says_what_rho_bounds_for_theorem1(nesterov_theorem1):
    _, res, _ = nesterov_theorem1
    assert res.exit_code == 0, res.output
    assert "rho bounds: f(x_k) - f* <= rho^(2k) V_0 for every k >= 0" in res.stdout
    assert "V_0 = f(x_0) - f* + (xi_0 - xi*)'P(xi_0 - xi*)" in res.stdout
    assert "rho^(2N)" in res.stdout  # how a PEPit tau(N) compares (not rho^N)


def test_analyze_names_each_kind_of_bound_with_a_legend(nesterov_theorem1):
    _, res, _ = nesterov_theorem1
    header = table_header(res.stdout)
    # the spec's closed forms are references, not bounds sosalgo proves
    assert "reference: Nesterov's bound" in header
    assert "reference: quadratic lower bound" in header
    assert "rho: certified rate, a proven upper bound" in res.stdout
    assert "a = witnessed lower bound" in res.stdout and "b = certified rate" in res.stdout
    assert "not proven by sosalgo" in res.stdout


def test_solver_internals_only_with_details(nesterov_theorem1):
    out, plain, detailed = nesterov_theorem1
    header = table_header(plain.stdout).split()
    assert not set(INTERNALS) & set(header) and "lambda" not in header
    assert "rho" in header and "certified" in header
    full = table_header(detailed.stdout).split()
    assert set(INTERNALS) <= set(full) and "lambda" in full
    (row,) = csv.DictReader(open(out / "nesterov-analysis.csv"))
    assert set(INTERNALS) | {"lambda"} <= set(row)  # the CSV keeps them (a contract)


def test_analyze_json_keeps_the_internals(tmp_path):
    res = run("analyze", SPECS / "gradient.yaml", "--kappa", 10, "--out", tmp_path,
              "--json", "--no-plot")
    (row,) = json.loads(res.stdout)["rows"]
    assert {"max_eig_M", "min_eig_P", "solves", "seconds"} <= set(row)


def test_a_distance_measure_is_said_as_a_distance(tmp_path):
    res = run("analyze", SPECS / "proximal-gradient.yaml", "--kappa", 10, "--out", tmp_path,
              "--quiet", "--no-plot")
    assert res.exit_code == 0, res.output
    assert "rho bounds: |x_k - x*|^2 <= rho^(2k) V_0" in res.stdout
    assert "f(x_k) - f* <=" not in res.stdout


def test_a_sublinear_spec_says_what_c_bounds(tmp_path):
    res = run("analyze", SPECS / "gradient-convex.yaml", "--out", tmp_path, "--quiet",
              "--no-plot")
    assert res.exit_code == 0, res.output
    assert "c bounds: f(x_k) - f* <= c |x_0 - x*|^2 / k for every k >= 1" in res.stdout
    assert "solves" not in table_header(res.stdout, "L ").split()


def test_noise_is_readable_in_100_characters(tmp_path):
    res = run("analyze", SPECS / "nesterov.yaml", "--kappa", 10, "--out", tmp_path, "--quiet",
              "--no-plot", "--noise")
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.split()[:2] == ["kappa", "noise"])
    block = lines[start:start + 3]  # header, rule, one row
    assert all(len(ln) <= 100 for ln in block)
    assert "noise_lag" not in block[0] and "noise_check" not in block[0]
    legend = [ln for ln in lines if ln.startswith(("noise:", "noise_quadratic:",
                                                   "noise_limsup:"))]
    assert len(legend) == 3 and all(len(ln) <= 100 for ln in legend)
    assert "sigma" in legend[0]  # the unit: per noise standard deviation
    more = run("analyze", SPECS / "nesterov.yaml", "--kappa", 10, "--out", tmp_path,
               "--quiet", "--no-plot", "--noise", "--details")
    assert "noise_lag" in more.stdout and "noise_limsup_rho" in more.stdout


def test_pep_states_class_measure_initial_and_steps(tmp_path):
    res = run("pep", SPECS / "gradient.yaml", "--kappa", 10, "--steps", 2, "--out", tmp_path,
              "--quiet", "--no-plot", "--no-witness")
    assert res.exit_code == 0, res.output
    text = res.stdout
    assert "f / dist" not in text
    assert "tau = worst case of f(x_N) - f* when |x_0 - x*|^2 <= 1" in text
    assert "smooth_strongly_convex" in text and "m = 1, L = 10" in text
    assert "N steps: N iterations" in text
    assert "tau_proven: proven upper bound" in text
    assert "seconds" not in table_header(text).split()
    detailed = run("pep", SPECS / "gradient.yaml", "--kappa", 10, "--steps", 2, "--out",
                   tmp_path, "--quiet", "--no-plot", "--no-witness", "--details")
    assert "seconds" in table_header(detailed.stdout).split()


def test_pep_free_start_and_composite_classes_in_words(tmp_path):
    res = run("pep", SPECS / "douglas-rachford.yaml", "--kappa", 10, "--steps", 1, "--out",
              tmp_path, "--quiet", "--no-plot", "--no-witness")
    assert res.exit_code == 0, res.output
    assert "when |xi_0 - xi*|^2 <= 1" in res.stdout  # sdist: the whole state is free
    assert "g: convex" in res.stdout and "f: smooth_strongly_convex" in res.stdout


def test_design_legend_names_the_proven_lower_bound_only_when_it_is_proven():
    from sosalgo.report.design import design_legend

    assert "lower_bound: proven lower bound" in design_legend("dual")
    moment = design_legend("moment")
    assert "proven lower bound" not in moment and "floating point" in moment


def test_verify_says_what_its_columns_mean_in_100_characters(tmp_path):
    """verify's table is followed by a legend: exact re-proof, the proven rate, and the
    simulation as evidence (not a proof), in lines of at most 100 characters."""
    doc = tmp_path / "g.json"
    res = run("analyze", SPECS / "gradient.yaml", "--kappa", 10, "--out", tmp_path, "--quiet",
              "--no-plot", "--json")
    doc.write_text(res.output)
    out = run("verify", doc, "--out", tmp_path / "v")
    assert out.exit_code == 0, out.output
    text = out.output
    assert "re-proven (rational or outward-rounded" in text and "rho_proven" in text
    assert "evidence, not a proof" in text
    legend = [ln for ln in text.splitlines()
              if any(w in ln for w in ("re-proven (", "rho_proven:", "not a proof"))]
    assert legend and all(len(line) <= 100 for line in legend)
