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

from .conftest import SPECS, timeless

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
    uncounted: int = 0  # rows written before the sweep the progress bar counts


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
    Case("design-composite", ("design", _spec("douglas-rachford"), "--kappa", "4", "--kappa",
                              "8", "--kappa", "16", "--time-limit", "3"),
         ("kappa",), ("design", _spec("douglas-rachford"), "--kappa", "4", "--time-limit",
                      "2"), exact=False, marks=(pytest.mark.deep,)),
    Case("pep", ("pep", _spec("gradient"), "--kappa", "10", "--steps", "1..4"),
         ("kappa", "steps"), ("pep", _spec("gradient"), "--kappa", "10", "--steps", "1",
                              "--no-witness"),
         volatile=("seconds", "document")),
    Case("pep-sublinear", ("pep", _spec("gradient-convex"), "--steps", "1..4"),
         ("kappa", "steps"), ("pep", _spec("gradient-convex"), "--steps", "2", "--no-witness"),
         volatile=("seconds", "document"), marks=(pytest.mark.deep,)),
    Case("pep-composite", ("pep", _spec("proximal-gradient"), "--kappa", "10", "--steps",
                           "1..4"),
         ("kappa", "steps"), ("pep", _spec("proximal-gradient"), "--kappa", "10", "--steps",
                              "1", "--no-witness"),
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


def _document(folder: Path, cell: str):
    """The document a pep row's ``document`` cell names (its file beside the CSV)."""
    return json.loads((folder / cell).read_text(encoding="utf-8"))


def _same_results(case: Case, a: dict, b: dict, folders: tuple[Path, Path]) -> None:
    assert a.keys() == b.keys()
    if not case.exact:
        return
    for key in a:
        ra, rb = a[key], b[key]
        for col in ra:
            if col == "document":
                assert timeless(_document(folders[0], ra[col])) == timeless(
                    _document(folders[1], rb[col])), (key, col)
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
    said = rerun.stderr.split("resumed: ")
    done = int(said[1].split(" of ")[0]) if len(said) > 1 else 0
    assert len(written) - case.uncounted <= done < len(reference), rerun.stderr
    final = out / path.name
    text = final.read_text(encoding="utf-8")
    for line in written:  # verbatim, timings included: read back, not computed again
        assert line in text
    _same_results(case, reference, _keyed(case, _table(final)[1]), (ref, out))
    _no_locks_left(out)

    # other settings: computed anew, the old results kept aside (whole), then restored
    before = final.read_text(encoding="utf-8")
    other = _run(case.other, out, "--quiet")
    assert "kept it aside" in other.stderr, other.stderr
    aside = [p for p in (out / "kept").glob(f"{final.stem}-*.csv") if p.read_text() == before]
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
    docs, errs = [], []
    for p in procs:
        stdout, err = p.communicate(timeout=RESULT_TIMEOUT)
        assert p.returncode == 0 and "Traceback" not in err, err
        docs.append(json.loads(stdout))
        errs.append(err)
    assert sum("resumed: 1 of 1" in e for e in errs) == 1  # the second read the row back
    (path,) = _csvs(out)
    header, rows = _table(path)
    assert len(rows) == 1
    # one of the two computed the row, the other read it back: the same document
    assert timeless(docs[0]) == timeless(docs[1])
    before = path.read_text(encoding="utf-8")
    edited = tmp_path / "gradient-convex.yaml"  # the same name, another step
    edited.write_text(Path(_spec("gradient-convex")).read_text().replace("value: 1/L",
                                                                         "value: 1.5/L"))
    other = _run(tuple(str(edited) if a == _spec("gradient-convex") else a
                       for a in case.args), out, "--quiet")
    assert "kept it aside" in other.stderr, other.stderr
    assert [p.read_text() for p in (out / "kept").glob(f"{path.stem}-*.csv")] == [before]
    assert "note: resuming the results" in _run(case.args, out, "--quiet").stderr
    assert path.read_text() == before
    _no_locks_left(out)


# --------------------------------------------------------------------------- in-process
def _hold_lock_repeatedly(path: str, marker: str, rounds: int) -> None:
    """Take the output lock ``rounds`` times; inside, create ``marker`` exclusively (it
    fails if another process is inside too) and remove it again."""
    from sosalgo.store import output_lock

    for _ in range(rounds):
        with output_lock(Path(path), notify=lambda m: None):
            fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            os.close(fd)
            time.sleep(0.001)  # long enough for the others to queue on the lock file
            os.unlink(marker)


def test_lock_files_are_removed_and_the_lock_stays_exclusive(tmp_path):
    """Each holder removes the lock file before letting go; runs waiting on the removed
    file must not enter beside a run that locked the new one."""
    import multiprocessing

    path, marker = tmp_path / "x.csv", str(tmp_path / "inside")
    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_hold_lock_repeatedly, args=(str(path), marker, 200))
             for _ in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=RESULT_TIMEOUT)
    assert [p.exitcode for p in procs] == [0, 0, 0, 0]  # no one found another inside
    _no_locks_left(tmp_path)


def test_sublinear_grid_resume_computes_only_the_missing_points(tmp_path, monkeypatch):
    import sosalgo.analysis
    from sosalgo.runs import grid_run

    calls: list[dict] = []
    real = sosalgo.analysis.analyze_sublinear

    def counted(spec, theta=None, *args, **kw):
        calls.append(dict(theta))
        return real(spec, theta, *args, **kw)

    monkeypatch.setattr(sosalgo.analysis, "analyze_sublinear", counted)
    spec = _spec("gradient-convex")
    first = grid_run(spec, None, tmp_path, points=4, workers=1, progress=False)
    assert len(calls) == 4
    path = Path(first["csv"])
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:3]) + lines[3][:5])  # two rows lost, one half written
    calls.clear()
    again = grid_run(spec, None, tmp_path, points=4, workers=1, progress=False)
    assert [c["h"] for c in calls] == [float(lines[3].split(",")[0]),
                                       float(lines[4].split(",")[0])]
    now = path.read_text().splitlines(keepends=True)
    assert now[:3] == lines[:3]  # kept verbatim
    assert [ln.rsplit(",", 1)[0] for ln in now] == [ln.rsplit(",", 1)[0] for ln in lines]
    assert again["best"] == first["best"]


def test_witness_holds_the_spec_as_read_at_the_start(tmp_path, monkeypatch):
    """The spec edited while the run works (and a spec read from a pipe): every witness
    embeds the text the run read, so that verify judges what was computed."""
    import sosalgo.runs.pep as pep_run_module

    spec = tmp_path / "gradient.yaml"
    original = Path(_spec("gradient")).read_text()
    spec.write_text(original)
    real = pep_run_module.pep_chunk

    def editing(*args):
        spec.write_text(original.replace("value: 1/L", "value: 1.5/L"))
        return real(*args)

    monkeypatch.setattr(pep_run_module, "pep_chunk", editing)
    doc = pep_run_module.pep_run(spec, 10.0, "1..2", out_dir=tmp_path / "out", workers=1,
                                 progress=False, plot=False)
    witnesses = [f for f in doc["files"] if f.endswith("-witness.json")]
    assert len(witnesses) == 2
    for f in witnesses:
        assert json.loads(Path(f).read_text())["spec_text"] == original


def test_witness_of_a_spec_from_a_pipe_verifies(tmp_path):
    out = tmp_path / "out"
    res = subprocess.run([sys.executable, "-m", "sosalgo.cli", "pep", "/dev/stdin", "--kappa",
                          "10", "--steps", "2", "--out", str(out), "--quiet", "--no-plot"],
                         input=Path(_spec("gradient")).read_text(), env=ENV, text=True,
                         capture_output=True, timeout=RESULT_TIMEOUT)
    assert res.returncode == 0, res.stderr
    (witness,) = out.glob("*-witness.json")
    assert json.loads(witness.read_text())["spec_text"] == Path(_spec("gradient")).read_text()
    check = subprocess.run([sys.executable, "-m", "sosalgo.cli", "verify", str(witness),
                            "--out", str(out)], env=ENV, text=True, capture_output=True,
                           timeout=RESULT_TIMEOUT)
    assert check.returncode == 0, check.stdout + check.stderr


_CHUNKS: list[int] = []  # sizes of the chunks the in-process Dask worker ran
_DELIVERED: list[int] = []  # chunks started when each row reached the caller


def _recording_chunk(spec_text, source, options, chunk):
    _CHUNKS.append(len(chunk))
    return [{"kappa": t["kappa"]} for t in chunk]


def test_one_dask_worker_gets_the_work_in_chunks(tmp_path):
    """One worker: the sweep is cut into chunks, so rows reach the file as chunks finish
    (a worker lost mid-run loses one chunk), not all at the end."""
    distributed = pytest.importorskip("distributed")
    import gc

    from sosalgo.batch.executor import run_batch

    gc.collect()  # a Client left by an earlier test must not close inside this loop's start
    _CHUNKS.clear()
    _DELIVERED.clear()
    tasks = [{"kappa": float(k)} for k in range(2, 42)]
    rows: list[dict] = []

    def on_row(row):
        rows.append(row)
        _DELIVERED.append(len(_CHUNKS))

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        run_batch(_recording_chunk, "", "", {}, tasks, on_row,
                  scheduler=cluster.scheduler_address)
    assert sorted(r["kappa"] for r in rows) == [t["kappa"] for t in tasks]
    assert len(_CHUNKS) >= 8 and sum(_CHUNKS) == len(tasks)
    assert max(_CHUNKS) <= len(tasks) // 8 + 1


def test_chunks_of_long_tasks_hold_one_task():
    from sosalgo.batch.executor import _largest_chunk, chunk_size
    from sosalgo.batch.sweeps import analysis_chunk, design_chunk, sublinear_grid_chunk
    from sosalgo.runs.pareto import pareto_chunk
    from sosalgo.runs.pep import pep_chunk

    for fn in (design_chunk, pep_chunk, pareto_chunk, sublinear_grid_chunk):
        assert chunk_size(400, 1, _largest_chunk(fn)) == 1
    assert chunk_size(400, 1, _largest_chunk(analysis_chunk)) == 50  # eight chunks
    assert chunk_size(10_000, 2, _largest_chunk(analysis_chunk)) == 64


@pytest.mark.deep
def test_killing_the_only_dask_worker_keeps_the_finished_rows(tmp_path):
    """A grid on a one-worker cluster (worker processes): rows reach the file before the
    end; SIGKILL of the worker after the first row loses at most its chunk, the nanny's
    new worker finishes the run, and the rows written before are kept verbatim."""
    distributed = pytest.importorskip("distributed")
    import gc

    gc.collect()
    args = ("grid", _spec("gradient-convex"), "--points", "8")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        (pid,) = client.run(os.getpid).values()
        out = tmp_path / "out"
        proc = subprocess.Popen([sys.executable, "-m", "sosalgo.cli", *args, "--out", str(out),
                                 "--quiet", "--scheduler", cluster.scheduler_address], env=ENV,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        path = out / "gradient-convex-grid.csv"
        deadline = time.monotonic() + RESULT_TIMEOUT
        while time.monotonic() < deadline and proc.poll() is None and not (
                path.exists() and len(_complete_lines(path)) >= 2):
            time.sleep(0.01)
        written = _complete_lines(path)[1:]
        assert proc.poll() is None and 1 <= len(written) < 8
        os.kill(pid, signal.SIGKILL)
        err = proc.communicate(timeout=RESULT_TIMEOUT)[1]
    assert proc.returncode == 0, err
    _, rows = _table(path)
    assert len(rows) == 8 and len({r["h"] for r in rows}) == 8
    text = path.read_text()
    assert all(line in text for line in written)
