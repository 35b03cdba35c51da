"""``analyze --verify`` and ``design --verify`` vouch for every claim of the document they
print, with the claim ledger of ``sosalgo verify``: a claim tampered with between the
computation and the check is refused (exit code 3, one line naming the field)."""

from __future__ import annotations

import json

from click.testing import CliRunner

import sosalgo.runs
from sosalgo.cli import cli

from .conftest import SPECS


def _invoke(*args: str):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _tamper(monkeypatch, field: str, value) -> None:
    """Every row the run assembles gets ``field`` = ``value`` before its checks."""
    real = sosalgo.runs.record_kappas

    def tampered(rows, kappas):
        for r in rows:
            r[field] = value
        return real(rows, kappas)

    monkeypatch.setattr(sosalgo.runs, "record_kappas", tampered)


def test_analyze_verify_vouches_for_its_document(tmp_path):
    res = _invoke("analyze", SPECS / "nesterov.yaml", "--kappa", "10", "--out", tmp_path,
                  "--json", "--verify", "--quiet", "--no-plot")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["vouched"] is True and doc["unbacked"] == []
    assert doc["claims"]["backed"] > 0 and doc["claims"]["contradicted"] == 0
    # sosalgo verify on the printed document agrees with the run's own ledger
    path = tmp_path / "doc.json"
    path.write_text(res.stdout)
    again = _invoke("verify", path, "--out", tmp_path, "--json")
    assert again.exit_code == 0, again.output
    claims = json.loads(again.stdout)["claims"]
    assert {k: v for k, v in claims.items() if k != "context"} == {
        k: v for k, v in doc["claims"].items() if k != "context"}  # + claims, vouched...


def test_analyze_verify_refuses_a_raised_lower_bound(tmp_path, monkeypatch):
    """rho_lower raised to 0.74 (the true worst-case rate of Nesterov's method at kappa 10
    is above 1 - 1/sqrt(10) = 0.6838 but no witness proves 0.74): the certificate still
    proves rho, the witness does not prove the raised bound."""
    _tamper(monkeypatch, "rho_lower", 0.74)
    res = _invoke("analyze", SPECS / "nesterov.yaml", "--kappa", "10", "--out", tmp_path,
                  "--verify", "--quiet", "--no-plot")
    assert res.exit_code == 3, res.output
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("error: claim contradicted: row 0: rho_lower = 0.74"), last


def test_analyze_verify_refuses_an_unknown_claim(tmp_path, monkeypatch):
    _tamper(monkeypatch, "rate_for_every_kappa", 0.1)
    res = _invoke("analyze", SPECS / "gradient.yaml", "--kappa", "10", "--out", tmp_path,
                  "--verify", "--quiet", "--no-plot", "--json")
    assert res.exit_code == 3, res.output
    doc = json.loads(res.stdout)
    assert doc["vouched"] is False
    assert [e["field"] for e in doc["unbacked"]] == ["rate_for_every_kappa"]
    assert doc["unbacked"][0]["status"] == "unsupported"


def test_design_verify_refuses_a_lower_bound_above_the_rate(tmp_path, monkeypatch):
    """Gradient descent at kappa 10: the best step certifies (kappa - 1)/(kappa + 1) =
    9/11; a lower bound claimed above it cannot be re-proven from its certificate."""
    _tamper(monkeypatch, "lower_bound", 0.9)
    res = _invoke("design", SPECS / "gradient.yaml", "--kappa", "10", "--out", tmp_path,
                  "--verify", "--quiet", "--time-limit", "20")
    assert res.exit_code == 3, res.output
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("error: claim contradicted: row 0: lower_bound = 0.9"), last


def test_design_verify_vouches_for_each_design(tmp_path):
    res = _invoke("design", SPECS / "gradient.yaml", "--kappa", "10", "--out", tmp_path,
                  "--verify", "--quiet", "--time-limit", "20", "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # one kappa: the design document itself
    assert doc["vouched"] is True and doc["unbacked"] == []
    assert abs(doc["rho_certified"] - 9 / 11) < 1e-4
