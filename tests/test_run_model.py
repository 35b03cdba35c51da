"""The run model for every command and spec kind: a killed run resumes without
recomputing its finished rows and ends with the rows of an uninterrupted run; a run with
other settings keeps the old results aside; concurrent runs into one folder both succeed
and leave a well-formed file; no lock file is left behind; a witness carries the spec as
read at the start; a one-worker Dask cluster delivers rows as chunks finish."""

from __future__ import annotations

import csv
import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from .conftest import SPECS

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
RESULT_TIMEOUT = 600  # seconds a subprocess may take on a loaded machine


@dataclass(frozen=True)
class Case:
    """A command whose output is one resumable CSV: ``args`` (before ``--out``), the key
    columns, ``other`` (the same command with other settings), ``exact``: whether two
    runs give the same cells (all but timings; False for time-limited searches)."""

    name: str
    args: tuple[str, ...]
    key: tuple[str, ...]
    other: tuple[str, ...]
    exact: bool = True
    volatile: tuple[str, ...] = ("seconds",)
    marks: tuple = field(default_factory=tuple)


def _spec(name: str) -> str:
    return str(SPECS / f"{name}.yaml")


KAPPAS = "{from: 2, to: 50, points: 120}"
CASES = [
    Case("analyze-rate", ("analyze", _spec("gradient"), "--kappa", KAPPAS, "--no-plot"),
         ("kappa",), ("analyze", _spec("gradient"), "--kappa", "4", "--no-plot")),
    Case("analyze-composite", ("analyze", _spec("proximal-gradient"), "--kappa",
                               "{from: 2, to: 50, points: 40}", "--no-plot"),
         ("kappa",), ("analyze", _spec("proximal-gradient"), "--kappa", "4", "--no-plot"),
         marks=(pytest.mark.deep,)),
    Case("grid-rate", ("grid", _spec("nesterov"), "--kappa", "10", "--free", "beta",
                       "--points", "40"),
         ("beta",), ("grid", _spec("nesterov"), "--kappa", "10", "--free", "beta",
                     "--points", "3"), marks=(pytest.mark.deep,)),
    Case("grid-composite", ("grid", _spec("douglas-rachford"), "--kappa", "10", "--points",
                            "16"),
         ("t",), ("grid", _spec("douglas-rachford"), "--kappa", "10", "--points", "3"),
         marks=(pytest.mark.deep,)),
    Case("grid-sublinear", ("grid", _spec("gradient-convex"), "--points", "6"),
         ("h",), ("grid", _spec("gradient-convex"), "--points", "2")),
    Case("design-rate", ("design", _spec("gradient"), "--kappa", "4", "--kappa", "8",
                         "--kappa", "16", "--time-limit", "3"),
         ("kappa",), ("design", _spec("gradient"), "--kappa", "4", "--time-limit", "2"),
         exact=False, marks=(pytest.mark.deep,)),
    Case("pep", ("pep", _spec("gradient"), "--kappa", "10", "--steps", "1..4"),
         ("kappa", "steps"), ("pep", _spec("gradient"), "--kappa", "10", "--steps", "1",
                              "--no-witness"),
         volatile=("seconds", "document")),
    Case("pep-sublinear", ("pep", _spec("gradient-convex"), "--steps", "1..4"),
         ("kappa", "steps"), ("pep", _spec("gradient-convex"), "--steps", "2", "--no-witness"),
         volatile=("seconds", "document"), marks=(pytest.mark.deep,)),
    Case("pareto", ("pareto", _spec("nesterov"), "--kappa", "10", "--points", "3",
                    "--time-limit", "20"),
         ("index",), ("pareto", _spec("nesterov"), "--kappa", "10", "--points", "2",
                      "--time-limit", "10"),
         exact=False, marks=(pytest.mark.deep,)),
]
ONE_ROW = [  # one row: nothing to resume mid-run, but a rerun reads it back
    Case("analyze-sublinear", ("analyze", _spec("gradient-convex")), ("L",), ()),
    Case("design-sublinear", ("design", _spec("gradient-convex"), "--time-limit", "2"),
         ("L",), (), marks=(pytest.mark.deep,)),
]


def _params(cases: list[Case]) -> list:
    return [pytest.param(c, id=c.name, marks=c.marks) for c in cases]


def _cmd(args: tuple[str, ...], out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "sosalgo.cli", *args, "--out", str(out), "--workers", "1",
            *extra]


def _run(args: tuple[str, ...], out: Path, *extra: str) -> subprocess.CompletedProcess:
    res = subprocess.run(_cmd(args, out, *extra), env=ENV, capture_output=True, text=True,
                         timeout=RESULT_TIMEOUT)
    assert res.returncode == 0, res.stderr
    return res


def _csvs(out: Path) -> list[Path]:
    """The run's CSVs in a folder (not the kept-aside ones, which end in a hash)."""
    return sorted(p for p in out.glob("*.csv") if not re.search(r"-[0-9a-f]{8}\.csv$", p.name))


def _table(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    """(header, rows) of a CSV, checking that it is well formed: every row complete, the
    file ending with a whole line."""
    text = path.read_text(encoding="utf-8")
    assert text.endswith("\n"), f"{path}: ends with half a line"
    records = list(csv.reader(io.StringIO(text)))
    header, body = records[0], records[1:]
    assert all(len(r) == len(header) for r in body), f"{path}: a row of the wrong length"
    return header, [dict(zip(header, r, strict=True)) for r in body]


def _keyed(case: Case, rows: list[dict[str, str]]) -> dict[tuple[str, ...], dict[str, str]]:
    out = {tuple(r[k] for k in case.key): r for r in rows}
    assert len(out) == len(rows), "a key written twice"
    return out


def _without_timings(value):
    """A cell (or a JSON document) without its timings, which differ between runs."""
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def _same_results(case: Case, a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    if not case.exact:
        return
    for key in a:
        ra, rb = a[key], b[key]
        for col in ra:
            if col == "document":
                assert _without_timings(json.loads(ra[col])) == _without_timings(
                    json.loads(rb[col])), (key, col)
            elif col not in case.volatile:
                assert ra[col] == rb[col], (key, col, ra[col], rb[col])


def _complete_lines(path: Path) -> list[str]:
    """The whole lines of a file a killed writer may have left half a line in."""
    text = path.read_text(encoding="utf-8")
    return text[: text.rfind("\n") + 1].splitlines(keepends=True)


def _kill_after_first_row(args: tuple[str, ...], out: Path) -> list[str]:
    """Start the command, SIGKILL it as soon as its CSV holds a whole data row (polling
    the file), and return the file's whole data lines at that moment."""
    proc = subprocess.Popen(_cmd(args, out, "--quiet"), env=ENV, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + RESULT_TIMEOUT
        while time.monotonic() < deadline and proc.poll() is None:
            found = _csvs(out) if out.exists() else []
            if found and len(_complete_lines(found[0])) >= 2:
                break
            time.sleep(0.01)
        assert proc.poll() is None, f"the run ended before it could be killed: {proc.stderr}"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return _complete_lines(_csvs(out)[0])[1:]


def _no_locks_left(out: Path) -> None:
    assert not list(out.rglob(".*.lock")), sorted(p.name for p in out.rglob(".*.lock"))


@pytest.mark.parametrize("case", _params(CASES))
def test_kill_resume_concurrency_and_keep_aside(case, tmp_path):
    # two identical runs at once into one folder: both succeed, each row once, whole rows
    ref = tmp_path / "ref"
    procs = [subprocess.Popen(_cmd(case.args, ref, "--quiet"), env=ENV,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    for p in procs:
        err = p.communicate(timeout=RESULT_TIMEOUT)[1]
        assert p.returncode == 0, err
        assert "Traceback" not in err
    (path,) = _csvs(ref)
    _, ref_rows = _table(path)
    reference = _keyed(case, ref_rows)
    _no_locks_left(ref)

    # killed after its first row, then rerun: the rows written are kept, not recomputed
    out = tmp_path / "out"
    written = _kill_after_first_row(case.args, out)
    assert 1 <= len(written) < len(reference)
    rerun = _run(case.args, out)
    done = int(rerun.stderr.split("resumed: ")[1].split(" of ")[0])
    assert len(written) <= done < len(reference), rerun.stderr
    final = out / path.name
    text = final.read_text(encoding="utf-8")
    for line in written:  # verbatim, timings included: read back, not computed again
        assert line in text
    _same_results(case, reference, _keyed(case, _table(final)[1]))
    _no_locks_left(out)

    # other settings: computed anew, the old results kept aside (whole), then restored
    before = final.read_text(encoding="utf-8")
    other = _run(case.other, out, "--quiet")
    assert "kept it aside" in other.stderr, other.stderr
    aside = [p for p in out.glob(f"{final.stem}-*.csv") if p.read_text() == before]
    assert len(aside) == 1
    back = _run(case.args, out, "--quiet")
    assert "resuming" in back.stderr
    assert final.read_text(encoding="utf-8") == before
    _no_locks_left(out)


@pytest.mark.parametrize("case", _params(ONE_ROW))
def test_one_row_outputs_resume_keep_aside_and_run_concurrently(case, tmp_path):
    out = tmp_path / "out"
    procs = [subprocess.Popen(_cmd(case.args, out, "--json"), env=ENV, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    docs = []
    for p in procs:
        stdout, err = p.communicate(timeout=RESULT_TIMEOUT)
        assert p.returncode == 0 and "Traceback" not in err, err
        docs.append(json.loads(stdout))
    (path,) = _csvs(out)
    header, rows = _table(path)
    assert len(rows) == 1
    # one of the two computed the row, the other read it back: the same document
    assert _without_timings(docs[0]) == _without_timings(docs[1])
    before = path.read_text(encoding="utf-8")
    again = _run(case.args, out)
    assert "resumed: 1 of 1" in again.stderr and path.read_text() == before
    edited = tmp_path / "gradient-convex.yaml"  # the same name, another step
    edited.write_text(Path(_spec("gradient-convex")).read_text().replace("value: 1/L",
                                                                         "value: 1.5/L"))
    other = _run(tuple(str(edited) if a == _spec("gradient-convex") else a
                       for a in case.args), out, "--quiet")
    assert "kept it aside" in other.stderr, other.stderr
    assert [p.read_text() for p in out.glob(f"{path.stem}-*.csv")] == [before]
    assert "note: resuming the results" in _run(case.args, out, "--quiet").stderr
    assert path.read_text() == before
    _no_locks_left(out)
