"""The commands as a user types them: outputs, JSON, exit codes, malformed specs."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

from .conftest import SPECS

NESTEROV = (SPECS / "nesterov.yaml").read_text()


def run(args, **kw):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False, **kw)


def test_analyze_writes_csv_plot_and_prints_table(tmp_path):
    res = run(["analyze", SPECS / "nesterov.yaml", "--kappa", "10", "--kappa", "100",
               "--out", tmp_path, "--quiet", "--certificate", "theorem1"])
    assert res.exit_code == 0, res.output
    assert "Nesterov's bound" in res.stdout and "rho" in res.stdout
    rows = list(csv.DictReader(open(tmp_path / "nesterov-analysis.csv")))
    assert [float(r["kappa"]) for r in rows] == [10.0, 100.0]
    for col in ("rho", "certified", "lambda", "P11", "P12", "P22", "max_eig_M", "min_eig_P",
                "solves", "seconds", "Nesterov's bound", "quadratic lower bound"):
        assert col in rows[0]
    assert float(rows[0]["rho"]) < float(rows[0]["Nesterov's bound"])
    assert {r["family"] for r in rows} == {"theorem1"}
    assert "certificate family: Theorem 1" in res.stdout
    for ext in ("png", "pdf"):
        # the figure of a family other than analyze's default is named after it
        assert (tmp_path / f"nesterov-rate-theorem1.{ext}").stat().st_size > 1000


def test_analyze_defaults_to_the_tightest_family_and_names_it(tmp_path):
    """Nesterov at kappa 10: the default is the interpolation family, whose rate matches
    AutoLyap's 0.7518212 (an independent tool, same family) within 1e-6; the printed
    line, the CSV column and the JSON rows name it. Theorem 1 is one flag away and gives
    a slower rate (its certificates are a special case)."""
    res = run(["analyze", SPECS / "nesterov.yaml", "--kappa", "10", "--out", tmp_path,
               "--quiet", "--json"])
    assert res.exit_code == 0, res.output
    (row,) = json.loads(res.stdout)["rows"]
    assert row["family"] == "interpolation" and row["certified"]
    assert row["rho"] == pytest.approx(0.7518212, abs=1e-6)
    (csv_row,) = csv.DictReader(open(tmp_path / "nesterov-analysis-interpolation.csv"))
    assert csv_row["family"] == "interpolation"
    text = run(["analyze", SPECS / "nesterov.yaml", "--kappa", "10", "--out", tmp_path,
                "--quiet"]).stdout
    assert "certificate family: interpolation" in text
    t1 = run(["analyze", SPECS / "nesterov.yaml", "--kappa", "10", "--out", tmp_path,
              "--quiet", "--json", "--certificate", "theorem1"])
    (t1_row,) = json.loads(t1.stdout)["rows"]
    assert t1_row["family"] == "theorem1" and t1_row["rho"] > row["rho"] + 0.05


def test_analyze_json_is_the_only_stdout(tmp_path):
    res = run(["analyze", SPECS / "gradient.yaml", "--kappa", "10", "--out", tmp_path, "--json"])
    assert res.exit_code == 0
    doc = json.loads(res.stdout)
    assert doc["spec"] == "gradient"
    (row,) = doc["rows"]
    assert row["kappa"] == 10.0 and row["certified"] is True
    assert abs(row["rho"] - 0.9) < 1e-5
    assert set(row) >= {"P", "lambda", "max_eig_M", "min_eig_P", "references"}
    assert row["references"]["1 - 1/kappa"] == pytest.approx(0.9)
    assert row["P"][0][0] > 0


def test_uncertified_is_a_result_not_an_error(tmp_path):
    res = run(["analyze", SPECS / "heavy-ball.yaml", "--kappa", "25", "--out", tmp_path,
               "--json", "--no-plot"])
    assert res.exit_code == 0
    (row,) = json.loads(res.stdout)["rows"]
    assert row["certified"] is False and row["rho"] is None


def test_rerun_resumes_and_recomputes_other_settings(tmp_path):
    args = ["analyze", SPECS / "gradient.yaml", "--kappa", "2", "--kappa", "10", "--out", tmp_path,
            "--quiet", "--no-plot", "--certificate", "theorem1"]
    assert run(args).exit_code == 0
    before = (tmp_path / "gradient-analysis.csv").read_text()
    assert run(args).exit_code == 0
    assert (tmp_path / "gradient-analysis.csv").read_text() == before  # nothing recomputed
    res = CliRunner().invoke(cli, [str(a) for a in args] + ["--tol", "1e-4"])
    assert res.exit_code == 0 and "tol: 1e-06 -> 0.0001" in res.stderr
    assert len(list((tmp_path / "kept").glob("gradient-analysis-*.csv"))) == 1  # kept aside
    assert run([*args, "--tol", "1e-4", "--restart"]).exit_code == 0


def test_lmi_command():
    res = run(["lmi", SPECS / "gradient.yaml"])
    assert res.exit_code == 0 and "M22" in res.stdout
    res = run(["lmi", SPECS / "nesterov.yaml", "--latex"])
    assert res.exit_code == 0 and "M_{33}" in res.stdout


BAD_SPECS = {
    "bad-yaml": ("name: x\nmatrices: [[[\n", "line"),
    "missing-A": (NESTEROV.replace("  A: [[0, 1], [-beta, 1 + beta]]\n", ""), "matrices.A"),
    "shape-mismatch": (NESTEROV.replace("B: [[0], [-h]]", "B: [[0], [-h], [1]]"), "matrices.B"),
    "unknown-symbol": (NESTEROV.replace("B: [[0], [-h]]", "B: [[0], [-eta]]"), "matrices.B"),
    "injection": (NESTEROV.replace("1/L, range", "__import__('os').system('touch PWNED'), range"),
                  "parameters.h.value"),
    "kappa-le-1": (NESTEROV.replace("kappa: [2, 5,", "kappa: [1, 5,"), "kappa[0]"),
    "range-lo-gt-hi": (NESTEROV.replace("range: [0, 1]", "range: [1, 0]"),
                       "parameters.beta.range"),
    "non-numeric": (NESTEROV.replace("E: [[0, 1]]", "E: [[0, [1]]]"), "matrices.E[0][1]"),
    "tie-cycle": (NESTEROV.replace("gamma: beta", "gamma: delta\n  delta: gamma"),
                  "parameters."),
    "no-fixed-point": (NESTEROV.replace("E: [[0, 1]]", "E: [[0, 2]]"), "matrices"),
    "python-tag": ("name: !!python/object/apply:os.system ['touch PWNED']\n", "line"),
    "path-escape": (NESTEROV.replace("name: nesterov", "name: ../../escape"), "name"),
    "not-a-mapping": ("- 1\n- 2\n", "spec must be a YAML mapping"),
    "empty-file": ("", "spec must be a YAML mapping"),
    "unknown-field": (NESTEROV + "colour: red\n", "colour"),
    "zero-division": (NESTEROV.replace("1/L, range", "1/(L - L), range"), "parameters.h.value"),
    "sqrt-negative": (NESTEROV.replace("1/L, range", "sqrt(-L), range"), "parameters.h.value"),
}


@pytest.mark.parametrize("case", sorted(BAD_SPECS))
def test_malformed_specs_exit_2_with_one_line(case, tmp_path):
    text, field = BAD_SPECS[case]
    spec = tmp_path / f"{case}.yaml"
    spec.write_text(text)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.run(
        [sys.executable, "-m", "sosalgo.cli", "analyze", str(spec), "--out", str(out)],
        capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert str(spec) in lines[0] and field in lines[0], lines[0]
    assert proc.stdout == ""
    assert not out.exists()  # nothing half-written
    assert not (tmp_path / "PWNED").exists()  # the injected command never ran


def test_bad_kappa_and_tol_options(tmp_path):
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "gradient.yaml"), "--kappa", "0.5",
                                   "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "--kappa" in res.stderr
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "gradient.yaml"), "--tol", "-1",
                                   "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "--tol" in res.stderr
    assert not (tmp_path / "o").exists()
    res = CliRunner().invoke(cli, ["analyze", str(tmp_path / "missing.yaml")])
    assert res.exit_code == 2 and "no such file" in res.stderr


def test_closed_stdout_is_a_quiet_exit(tmp_path):
    """`sosalgo ... | head`: no traceback and no 'internal error' when the reader leaves."""
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "sosalgo.cli", "analyze", str(SPECS / "nesterov.yaml"),
         "--kappa", "2", "--kappa", "10", "--no-plot", "--quiet", "--out", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before anything is printed
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) in (0, 141)
    assert "internal error" not in err and "Traceback" not in err
