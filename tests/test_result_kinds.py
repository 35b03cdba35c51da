"""Result kinds: every document a command writes names its ``kind`` (the command's, and
the one its content shows); ``sosalgo verify`` dispatches on it, refuses a kind the
content contradicts (exit code 3, naming the field) or does not know (exit code 2), and
still verifies a document written without ``kind``."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.documents import KINDS, document_kind, sniff_kind
from sosalgo.errors import InputError, VerificationError

from .conftest import SPECS, timeless


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def run_json(args) -> dict:
    res = run([*args, "--json", "--quiet"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


@pytest.fixture(scope="module")
def docs(tmp_path_factory) -> dict:
    """One document of each cheap command, and the files written beside them."""
    out = tmp_path_factory.mktemp("kinds")
    got = {
        "analysis": run_json(["analyze", SPECS / "gradient-optimal.yaml", "--kappa", "10",
                              "--out", out, "--no-plot", "--certificate", "theorem1"]),
        "sublinear": run_json(["analyze", SPECS / "gradient-convex.yaml", "--out", out,
                               "--no-plot"]),
        "pep": run_json(["pep", SPECS / "gradient.yaml", "--kappa", "10", "--steps", "1",
                         "--out", out, "--no-plot"]),
        "peps": run_json(["pep", SPECS / "gradient.yaml", "--kappa", "10", "--steps",
                          "1..2", "--out", out / "two", "--no-plot"]),
        "grid": run_json(["grid", SPECS / "heavy-ball.yaml", "--kappa", "10", "--points",
                          "3", "--out", out]),
        "design": run_json(["design", SPECS / "gradient.yaml", "--kappa", "10",
                            "--time-limit", "3", "--out", out, "--workers", "1"]),
    }
    witness = out / "gradient-pep-k10-N1-witness.json"
    got["witness"] = json.loads(witness.read_text())
    (out / "analysis.json").write_text(json.dumps(got["analysis"]))
    res = run(["verify", out / "analysis.json", "--out", out / "v", "--no-simulate",
               "--json"])
    assert res.exit_code == 0, res.output
    got["verification"] = json.loads(res.stdout)
    cert = next((out / "v" / "certificates").glob("*-certificate.json"))
    got["certificate"] = json.loads(cert.read_text())
    from sosalgo.runs import _design_certificates  # what design writes beside its CSV

    _design_certificates(out / "g-design.csv", {
        "kappa": 10.0, "lower_bound": 0.5, "rho_at_values": 0.8, "theta": {"h": 0.1},
        "free": ["h"], "values_certificate": {"P": [[1.0]], "lambda": 0.5}})
    got["design-certificates"] = json.loads((out / "g-design-k10-certificates.json")
                                            .read_text())
    got["table1"] = sosalgo.table1_run([SPECS / "gradient-optimal.yaml"], [10.0],
                                       out_dir=out / "t")
    return {"out": out, **got}


EXPECTED = {"analysis": "analysis", "sublinear": "analysis", "pep": "pep", "peps": "pep",
            "grid": "grid", "design": "design", "witness": "pep-witness",
            "verification": "verification", "certificate": "certificate",
            "design-certificates": "design-certificates", "table1": "table1"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_every_document_names_its_kind(docs, name):
    doc = docs[name]
    assert doc["kind"] == EXPECTED[name]
    without = {k: v for k, v in doc.items() if k != "kind"}
    assert sniff_kind(without) == EXPECTED[name]  # the content shows the same kind
    assert doc["kind"] in KINDS


def test_fig4_json_names_its_kind(monkeypatch):
    """fig4 --json (its sweeps replaced: only the printed document is tested)."""
    import sosalgo.runs.fig4 as fig4

    data = {"kappa": [2.0], "designed (interpolation)": [0.5], "designed (Theorem 1)": [0.6],
            "Nesterov's tuning (interpolation)": [0.7], "Nesterov's tuning (Theorem 1)": [0.8]}
    monkeypatch.setattr(fig4, "fig4", lambda *a, **k: ([], data))
    doc = run_json(["fig4", "--kappa", "2", "--time-limit", "1"])
    assert doc["kind"] == "fig4" and sniff_kind(doc) == "fig4"


@pytest.mark.parametrize("name, forged", [
    ("analysis", "design"), ("analysis", "pep"), ("analysis", "pareto"),
    ("design", "analysis"), ("pep", "analysis"), ("witness", "pep"),
    ("sublinear", "design"), ("peps", "pep-witness"),
])
def test_a_kind_the_content_contradicts_is_refused(docs, tmp_path, name, forged):
    path = tmp_path / "forged.json"
    path.write_text(json.dumps(docs[name] | {"kind": forged}))
    res = run(["verify", path, "--out", tmp_path / "v", "--no-simulate"])
    assert res.exit_code == 3, res.output
    line = res.output.strip().splitlines()[-1]
    assert "kind" in line and repr(forged) in line and "Traceback" not in res.output
    with pytest.raises(VerificationError, match="kind"):
        sosalgo.verify_document(path, simulate=False)


@pytest.mark.parametrize("kind", ["banana", 3, ["analysis"]])
def test_an_unknown_kind_is_bad_input(docs, tmp_path, kind):
    path = tmp_path / "unknown.json"
    path.write_text(json.dumps(docs["analysis"] | {"kind": kind}))
    res = run(["verify", path, "--no-simulate"])
    assert res.exit_code == 2, res.output
    assert "kind" in res.output and "Traceback" not in res.output


@pytest.mark.parametrize("name", ["grid", "table1", "certificate", "verification"])
def test_kinds_without_claims_are_refused_by_verify(docs, tmp_path, name):
    """verify checks analysis, design, pareto, pep and witness documents; the others say
    so in one line (exit code 2)."""
    path = tmp_path / "other.json"
    path.write_text(json.dumps(docs[name]))
    res = run(["verify", path, "--no-simulate"])
    assert res.exit_code == 2, res.output
    assert f"kind: a {EXPECTED[name]} document" in res.output


@pytest.mark.parametrize("name", ["analysis", "sublinear", "design", "pep", "peps"])
def test_a_document_without_kind_verifies_as_before(docs, tmp_path, name):
    """A document written before documents named their kind: recognised by its fields,
    the same verdicts and the same claims (the ledger less its entry for ``kind``)."""
    with_kind, without = tmp_path / "with.json", tmp_path / "without.json"
    with_kind.write_text(json.dumps(docs[name]))
    without.write_text(json.dumps({k: v for k, v in docs[name].items() if k != "kind"}))
    a = sosalgo.verify_document(with_kind, simulate=False, name="result.json")
    b = sosalgo.verify_document(without, simulate=False, name="result.json")
    assert document_kind(json.loads(without.read_text())).name == EXPECTED[name]
    assert timeless(a["results"]) == timeless(b["results"])
    if "ledger" in a:
        assert timeless([e for e in a["ledger"] if e["field"] != "kind"]) == timeless(
            b["ledger"])
        assert a["vouched"] == b["vouched"]
    codes = [run(["verify", p, "--out", tmp_path / "v", "--no-simulate"]).exit_code
             for p in (with_kind, without)]
    assert codes[0] == codes[1] and codes[0] in (0, 3)


def test_document_kind_reads_the_field_first():
    """A document without any known content keeps its declared kind (its checks then
    name what is missing), and an unknown one is an InputError naming ``kind``."""
    assert document_kind({"kind": "design"}).name == "design"
    assert document_kind({}).name == "analysis"  # no kind, no content: as before
    with pytest.raises(InputError, match="kind"):
        document_kind({"kind": "nonsense"}, "x.json")


def test_the_results_page_names_every_kind():
    """docs/results.md has a table line for each registered kind."""
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "results.md").read_text()
    for name in KINDS:
        assert f"| `{name}` |" in page, name
