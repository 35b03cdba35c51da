"""How ``sosalgo pep`` persists its rows: plain columns in the CSV (one row per (kappa,
N)), each document in its own JSON file named in the row's ``document`` cell; a rerun
resumes from them, and from a CSV written when the cell held the document itself."""

from __future__ import annotations

import csv
import json
from fractions import Fraction

from click.testing import CliRunner

from sosalgo.cli import cli
from sosalgo.runs.pep import FILE_FIELDS

from .conftest import SPECS, timeless

ARGS = ["pep", str(SPECS / "gradient-convex.yaml"), "--steps", "1..2", "--no-plot", "--json"]


def _pep(out, *extra: str):
    res = CliRunner().invoke(cli, [*ARGS, "--out", str(out), *extra])
    assert res.exit_code == 0, res.output
    return res


def _rows(out) -> list[dict[str, str]]:
    with open(out / "gradient-convex-pep.csv", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_rows_are_plain_and_documents_have_their_own_files(tmp_path):
    first = json.loads(_pep(tmp_path).stdout)
    rows = _rows(tmp_path)
    assert [r["document"] for r in rows] == ["gradient-convex-pep-N1.json",
                                             "gradient-convex-pep-N2.json"]
    for r, doc in zip(rows, first["rows"], strict=True):
        kept = json.loads((tmp_path / r["document"]).read_text())
        assert kept["kind"] == "pep" and "spec_text" in kept
        assert {k: v for k, v in kept.items() if k not in FILE_FIELDS} == doc
        # gradient descent, h = 1/L, L = 1: tau_N = 1/(4N + 2) (Drori and Teboulle 2014)
        proven = float(r["tau_proven"])
        assert proven == float(Fraction(doc["certificate"]["tau_proven"]))
        assert 1 / (4 * doc["steps"] + 2) <= proven <= (1 + 1e-5) / (4 * doc["steps"] + 2)
        ver = CliRunner().invoke(cli, ["verify", str(tmp_path / r["document"])])
        assert ver.exit_code == 0, ver.output  # the file alone: spec text, witness, proof
    again = _pep(tmp_path)
    assert "resumed: 2 of 2" in again.stderr
    assert timeless(json.loads(again.stdout)["rows"]) == timeless(first["rows"])


def test_a_csv_with_documents_in_its_cells_still_resumes(tmp_path):
    first = json.loads(_pep(tmp_path, "--no-witness").stdout)
    path = tmp_path / "gradient-convex-pep.csv"
    rows = _rows(tmp_path)
    for r in rows:  # the cell as it was: the document's JSON text, no file
        doc = json.loads((tmp_path / r["document"]).read_text())
        (tmp_path / r["document"]).unlink()
        r["document"] = json.dumps({k: v for k, v in doc.items() if k not in FILE_FIELDS})
    with open(path, "w", encoding="utf-8", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    again = _pep(tmp_path, "--no-witness")
    assert "resumed: 2 of 2" in again.stderr
    assert timeless(json.loads(again.stdout)["rows"]) == timeless(first["rows"])


def test_a_missing_document_file_leaves_the_plain_columns_with_a_note(tmp_path):
    first = json.loads(_pep(tmp_path, "--no-witness").stdout)
    (tmp_path / "gradient-convex-pep-N2.json").unlink()
    again = _pep(tmp_path, "--no-witness")
    assert "gradient-convex-pep-N2.json: unreadable" in again.stderr
    one, two = json.loads(again.stdout)["rows"]
    assert timeless(one) == timeless(first["rows"][0])
    assert two["certificate"] is None and two["tau"] == first["rows"][1]["tau"]
