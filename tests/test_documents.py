"""Result documents and `sosalgo verify` as a thin layer over `sosalgo.verify_document`:
the spec chosen and said to differ, checking without a writable folder, extreme scales,
and usage errors on one line."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli

from .conftest import SPECS


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    """An `analyze --json` document of gradient-optimal at kappa 10 (rate 9/11)."""
    out = tmp_path_factory.mktemp("res")
    res = run(["analyze", SPECS / "gradient-optimal.yaml", "--kappa", "10", "--json",
               "--quiet", "--no-plot", "--out", out])
    assert res.exit_code == 0, res.output
    path = out / "result.json"
    path.write_text(res.stdout)
    return path


def test_verify_document_from_a_path_or_a_dict_writes_only_when_asked(result, tmp_path):
    by_path = sosalgo.verify_document(result, simulate=False)
    by_dict = sosalgo.verify_document(json.loads(result.read_text()), simulate=False)
    for doc in (by_path, by_dict):
        (check,) = doc["results"]
        assert check["verified"] == "exact" and check["rho_proven_float"] >= 9 / 11
        assert "certificate_file" not in check and doc["notes"] == []
    written = sosalgo.verify_document(result, out_dir=tmp_path / "c", simulate=False)
    assert (tmp_path / "c").is_dir() and written["results"][0]["certificate_file"]


def test_verify_checks_without_a_writable_folder(result, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    res = run(["verify", result, "--out", blocker / "sub", "--no-simulate"])
    assert res.exit_code == 0, res.output
    assert "exact" in res.stdout and "no certificate files written" in res.stdout
    assert "not writable: certificates checked, no files written" in res.stderr
    assert blocker.read_text() == "not a folder"


def test_verify_with_an_edited_spec_says_it_differs(result, tmp_path):
    text = (SPECS / "gradient-optimal.yaml").read_text()
    edited = tmp_path / "edited.yaml"
    edited.write_text(text.replace("2/(m + L)", "1.9/(m + L)").replace("2/(L + m)", "1.9/(L + m)"))
    assert edited.read_text() != text, "the edit must change the step"
    res = run(["verify", result, "--spec", edited, "--out", tmp_path, "--no-simulate"])
    assert res.exit_code == 3
    assert f"note: {edited} differs from the spec embedded in {result}" in res.stderr
    assert "with a --spec that differs from the result's own spec" in res.stderr
    same = run(["verify", result, "--spec", SPECS / "gradient-optimal.yaml", "--out",
                tmp_path, "--no-simulate"])
    assert same.exit_code == 0 and "differs" not in same.stderr


def test_a_tiny_m_analyzes_and_verifies_its_own_result(tmp_path):
    """m = 1e-300: the exact proof holds; the simulation's test functions cannot be built
    in floating point (m L underflows), so the simulation says it was skipped."""
    text = (SPECS / "gradient.yaml").read_text() + "m: 1e-300\n"
    spec = tmp_path / "tiny.yaml"
    spec.write_text(text.replace("kappa: [2, 5, 10, 20, 50, 100]", "kappa: [10]"))
    res = run(["analyze", spec, "--json", "--quiet", "--no-plot", "--out", tmp_path,
               "--certificate", "theorem1"])
    assert res.exit_code == 0, res.output
    doc = tmp_path / "tiny.json"
    doc.write_text(res.stdout)
    assert json.loads(res.stdout)["rows"][0]["rho"] == pytest.approx(0.9, abs=1e-5)
    ver = run(["verify", doc, "--json", "--out", tmp_path])
    assert ver.exit_code == 0, ver.output
    (check,) = json.loads(ver.stdout)["results"]
    assert check["verified"] == "exact" and check["rho_proven_float"] >= 0.9 - 1e-5
    assert check["simulation"]["ok"] is None and "skipped" in check["simulation"]


@pytest.mark.parametrize("args, field", [
    (["grid", SPECS / "gradient.yaml", "--kappa", "10", "--points", "1"], "--points"),
    (["analyze", SPECS / "gradient.yaml", "--workers", "0"], "--workers"),
    (["design", SPECS / "gradient.yaml", "--method", "nope"], "--method"),
    (["analyze"], "SPEC"),
])
def test_usage_errors_are_one_line(args, field, tmp_path):
    res = run([*args, "--out", tmp_path] if len(args) > 1 else args)
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and field in lines[0]
    assert not list(tmp_path.iterdir())


def test_gap_and_time_limit_are_checked_before_writing(tmp_path):
    for opt, value, msg in (("--gap", "-1", "--gap -1.0: must be positive"),
                            ("--time-limit", "inf", "--time-limit inf: must be finite")):
        res = run(["design", SPECS / "gradient.yaml", "--kappa", "10", opt, value,
                   "--out", tmp_path / "o"])
        assert res.exit_code == 2 and msg in res.stderr
    assert not (tmp_path / "o").exists()
