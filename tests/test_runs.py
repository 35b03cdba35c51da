"""The run model: reruns resume or recompute, outputs never collide, concurrent
runs are safe, bad output paths and environments fail with one line and exit code 2."""

from __future__ import annotations

import csv
import gc
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from sosalgo.cli import cli
from sosalgo.store import ResumableCSV, kappa_label

from .conftest import SPECS

ROOT = Path(__file__).resolve().parents[1]
GRADIENT = SPECS / "gradient.yaml"
NESTEROV = SPECS / "nesterov.yaml"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def run(args, **kw):
    return CliRunner().invoke(cli, [str(a) for a in args], **kw)


def rows_of(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def edited_gradient(tmp_path: Path) -> Path:
    """A copied and edited spec that keeps ``name: gradient`` (step 1.5/L instead of 1/L)."""
    path = tmp_path / "my-gradient.yaml"
    path.write_text(GRADIENT.read_text().replace("value: 1/L", "value: 1.5/L"))
    return path


def test_edited_copy_keeps_the_original_aside_and_both_resume(tmp_path):
    out = tmp_path / "out"
    args = ["--kappa", "4", "--out", out, "--no-plot", "--quiet", "--certificate", "theorem1"]
    first = run(["analyze", GRADIENT, *args])
    assert first.exit_code == 0, first.output
    original = (out / "gradient-analysis.csv").read_text()
    edited = run(["analyze", edited_gradient(tmp_path), *args])
    assert edited.exit_code == 0, edited.output
    # the message says what differs and where the old results went
    assert "spec text" in edited.stderr and "1/L" in edited.stderr
    assert "kept it aside" in edited.stderr
    aside = [p for p in (out / "kept").glob("gradient-analysis-*.csv")]
    assert len(aside) == 1 and aside[0].read_text() == original
    # closed forms: h = 1/L gives 1 - 1/kappa, h = 1.5/L gives max|1 - h*lambda| = 1 - 1.5/kappa
    rho_edit = float(rows_of(out / "gradient-analysis.csv")[0]["rho"])
    assert rho_edit == pytest.approx(1 - 1.5 / 4, abs=1e-5)
    # back to the original: its rows come back, nothing recomputed
    again = run(["analyze", GRADIENT, *args])
    assert again.exit_code == 0 and "resuming" in again.stderr
    assert (out / "gradient-analysis.csv").read_text() == original
    assert float(rows_of(out / "gradient-analysis.csv")[0]["rho"]) == pytest.approx(
        1 - 1 / 4, abs=1e-5)


def test_restart_says_it_replaces(tmp_path):
    args = ["analyze", GRADIENT, "--kappa", "4", "--out", tmp_path, "--no-plot", "--quiet",
            "--certificate", "theorem1"]
    assert run(args).exit_code == 0
    res = run([*args, "--restart"])
    assert res.exit_code == 0 and "replaced" in res.stderr
    assert len(rows_of(tmp_path / "gradient-analysis.csv")) == 1


def test_another_kappa_is_another_run_not_an_append(tmp_path):
    base = ["analyze", GRADIENT, "--out", tmp_path, "--quiet", "--certificate", "theorem1"]
    assert run([*base, "--kappa", "4", "--kappa", "8"]).exit_code == 0
    res = run([*base, "--kappa", "16"])
    assert res.exit_code == 0, res.output
    assert "kappa" in res.stderr and "kept it aside" in res.stderr
    assert [float(r["kappa"]) for r in rows_of(tmp_path / "gradient-analysis.csv")] == [16.0]
    # the figure of the first run moved aside with its CSV (a family other than analyze's
    # default: the figure is named after it)
    assert len(list((tmp_path / "kept").glob("gradient-rate-theorem1-*.png"))) == 1
    assert not list(tmp_path.glob("gradient-rate*.png"))  # one kappa: no figure


def test_identical_rerun_resumes_without_notes(tmp_path):
    args = ["analyze", GRADIENT, "--kappa", "4", "--out", tmp_path, "--no-plot", "--quiet",
            "--certificate", "theorem1"]
    assert run(args).exit_code == 0
    before = (tmp_path / "gradient-analysis.csv").read_text()
    res = run(args)
    assert res.exit_code == 0 and res.stderr == ""
    assert (tmp_path / "gradient-analysis.csv").read_text() == before


def test_grids_over_other_free_parameters_do_not_collide(tmp_path):
    base = ["grid", NESTEROV, "--kappa", "10", "--points", "3", "--out", tmp_path, "--quiet",
            "--workers", "1"]
    assert run([*base, "--free", "h"]).exit_code == 0
    res = run([*base, "--free", "beta"])
    assert res.exit_code == 0 and "free" in res.stderr
    files = sorted(p.name for p in [*tmp_path.glob("nesterov-grid-k10*.csv"),
                                    *(tmp_path / "kept").glob("nesterov-grid-k10*.csv")])
    assert len(files) == 2
    assert "beta" in rows_of(tmp_path / "nesterov-grid-k10.csv")[0]


def test_distinct_kappas_get_distinct_grid_files(tmp_path):
    res = run(["grid", NESTEROV, "--kappa", "10", "--kappa", "10.000001", "--points", "2",
               "--free", "beta", "--out", tmp_path, "--quiet", "--workers", "1"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "nesterov-grid-k10.csv").exists()
    assert (tmp_path / "nesterov-grid-k10.000001.csv").exists()
    assert kappa_label(100.0) == "100" and kappa_label(100.00001) == "100.00001"
    assert kappa_label(1e20) != kappa_label(1.0000000000000001e20 * 1.000001)


def test_two_concurrent_runs_write_each_row_once(tmp_path):
    cmd = [sys.executable, "-m", "sosalgo.cli", "analyze", str(GRADIENT), "--kappa",
           "{from: 2, to: 50, points: 300}", "--out", str(tmp_path), "--no-plot", "--quiet",
           "--workers", "1", "--certificate", "theorem1"]
    procs = [subprocess.Popen(cmd, env=ENV, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE) for _ in range(2)]
    for p in procs:
        assert p.wait(timeout=300) == 0, p.stderr.read()
    kappas = [r["kappa"] for r in rows_of(tmp_path / "gradient-analysis.csv")]
    assert len(kappas) == len(set(kappas)) == 300


def test_spec_from_a_pipe_is_read_once(tmp_path):
    cmd = [sys.executable, "-m", "sosalgo.cli", "analyze", "/dev/stdin", "--kappa", "4",
           "--out", str(tmp_path), "--no-plot", "--quiet", "--certificate", "theorem1"]
    for _ in range(2):  # the second run resumes
        res = subprocess.run(cmd, input=GRADIENT.read_text(), text=True, env=ENV,
                             capture_output=True, timeout=120)
        assert res.returncode == 0, res.stderr
    rows = rows_of(tmp_path / "gradient-analysis.csv")
    assert len(rows) == 1 and float(rows[0]["rho"]) == pytest.approx(0.75, abs=1e-5)


def test_symlink_to_a_device_is_refused(tmp_path):
    (tmp_path / "gradient-analysis.csv").symlink_to("/dev/full")
    (tmp_path / "gradient-analysis.csv.settings.json").write_text("{}")
    res = subprocess.run([sys.executable, "-m", "sosalgo.cli", "analyze", str(GRADIENT),
                          "--kappa", "4", "--out", str(tmp_path), "--no-plot", "--quiet",
                          "--certificate", "theorem1"],
                         env=ENV, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "not a regular file" in res.stderr


def test_short_and_malformed_rows_are_dropped_with_a_warning(tmp_path):
    args = ["analyze", GRADIENT, "--kappa", "4", "--kappa", "8", "--out", tmp_path,
            "--no-plot", "--quiet", "--certificate", "theorem1"]
    assert run(args).exit_code == 0
    path = tmp_path / "gradient-analysis.csv"
    lines = path.read_text().splitlines(keepends=True)
    path.write_text(lines[0] + "4.0,0.75\n" + "x,y" + "," * (lines[1].count(",") - 1) + "\n"
                    + lines[2])
    res = run(args)
    assert res.exit_code == 0, res.output
    assert "dropped 2" in res.stderr and res.stderr.count("dropped") == 1
    rows = rows_of(path)
    assert sorted(float(r["kappa"]) for r in rows) == [4.0, 8.0]
    assert all(r["rho"] for r in rows)


def test_store_drops_a_truncated_line_and_waits_for_nothing_before_writing(tmp_path):
    path = tmp_path / "x.csv"
    store = ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 1})
    with store:
        pass
    assert not path.exists()  # nothing written before the first row
    with ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 1}) as store:
        store.write({"kappa": 2.0, "v": 1})
    path.write_text(path.read_text() + "3.0,4")  # a killed writer's half line
    with ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 1}, notify=lambda m: None) as s:
        assert s.is_done({"kappa": 2.0}) and not s.is_done({"kappa": 3.0})
    assert path.read_text().endswith("2.0,1\n")


# --------------------------------------------------------------------------- exit codes
def _one_line_exit_2(res, *words):
    assert res.exit_code == 2, res.output
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr
    for w in words:
        assert w in res.stderr


def test_kappa_with_a_comma_says_what_to_write(tmp_path):
    res = run(["analyze", GRADIENT, "--kappa", "2,10", "--out", tmp_path])
    _one_line_exit_2(res, "--kappa 2 --kappa 10", "[2,10]")


def test_unwritable_out_is_exit_2_and_nothing_written(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = run(["analyze", GRADIENT, "--kappa", "4", "--out", blocker / "sub", "--quiet"])
    _one_line_exit_2(res, "--out")
    res = run(["analyze", GRADIENT, "--kappa", "4", "--out", "/proc/sosalgo-out", "--quiet"])
    _one_line_exit_2(res)


@pytest.mark.parametrize("address", ["not an address", "tcp://127.0.0.1:1", "tcp://[::"])
def test_bad_scheduler_is_exit_2_and_nothing_written(tmp_path, address, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr("sosalgo.batch.executor.CONNECT_TIMEOUT", 2.0)
    res = run(["analyze", GRADIENT, "--kappa", "4", "--out", tmp_path / "o", "--quiet",
               "--scheduler", address])
    _one_line_exit_2(res, "--scheduler")
    assert not (tmp_path / "o").exists()


def test_missing_dask_is_exit_2(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails
    res = run(["analyze", GRADIENT, "--kappa", "4", "--out", tmp_path / "o", "--quiet",
               "--scheduler", "tcp://127.0.0.1:8786"])
    _one_line_exit_2(res, "not installed")
    assert not (tmp_path / "o").exists()


_RELEASE = threading.Event()  # the in-process worker's task waits on it (not a fixed sleep)


def _slow_chunk(spec_text, source, options, chunk):
    _RELEASE.wait(60)
    return [{"kappa": t["kappa"]} for t in chunk]


def test_cluster_losing_its_last_worker_fails_instead_of_hanging(monkeypatch):
    distributed = pytest.importorskip("distributed")
    from sosalgo.batch.executor import BatchError, run_batch

    monkeypatch.setattr("sosalgo.batch.executor.NO_WORKER_TIMEOUT", 1.0)
    gc.collect()  # a Client left by an earlier test must not close inside this loop's start
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        def lose_worker():
            time.sleep(1.0)
            cluster.scale(0)

        _RELEASE.clear()
        threading.Thread(target=lose_worker, daemon=True).start()
        t0 = time.monotonic()
        try:
            with pytest.raises(BatchError, match="no workers"):
                run_batch(_slow_chunk, "", "", {}, [{"kappa": 2.0}], lambda r: None,
                          scheduler=cluster.scheduler_address)
            assert time.monotonic() - t0 < 40
        finally:
            _RELEASE.set()  # lets the orphaned task end, so the cluster closes at once


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        text = (task / "children").read_text().split()
        out += [int(c) for c in text]
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except FileNotFoundError:
        return False
    return state != "Z"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_kill_of_a_pool_run_leaves_no_worker_alive(tmp_path, sig):
    cmd = [sys.executable, "-m", "sosalgo.cli", "grid", str(NESTEROV), "--kappa", "10",
           "--points", "30", "--out", str(tmp_path), "--workers", "2", "--quiet"]
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.time() + 120
    kids: list[int] = []
    while time.time() < deadline and len(kids) < 2:
        time.sleep(0.2)
        kids = [k for k in _children(proc.pid) if _alive(k)]
    assert len(kids) >= 2, "no pool started"
    time.sleep(1.0)
    proc.send_signal(sig)
    err = proc.communicate(timeout=30)[1]
    assert proc.returncode != 0
    deadline = time.time() + 10
    while time.time() < deadline and any(_alive(k) for k in kids):
        time.sleep(0.1)
    assert not any(_alive(k) for k in kids)
    assert "Traceback" not in err and err.count("\n") <= 1, err


def test_scheduler_going_away_is_one_line_exit_2(tmp_path):
    pytest.importorskip("distributed")
    import socket

    env = {**ENV, "SOSALGO_CONNECT_TIMEOUT": "30"}
    with socket.socket() as sock:  # a free port
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                              "127.0.0.1", "--port", str(port), "--no-dashboard"], env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker",
                               address, "--nthreads", "1", "--no-dashboard"],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        run_ = subprocess.Popen([sys.executable, "-m", "sosalgo.cli", "grid", str(NESTEROV),
                                 "--kappa", "10", "--points", "120", "--out", str(tmp_path),
                                 "--scheduler", address, "--quiet"], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        from distributed import Client

        with Client(address, timeout=30) as watcher:  # until the run's task is on the worker
            deadline = time.time() + 90
            while time.time() < deadline and run_.poll() is None and not any(
                    watcher.processing().values()):
                time.sleep(0.5)
        time.sleep(1.0)
        assert run_.poll() is None, run_.stderr.read()
        sched.terminate()
        err = run_.communicate(timeout=120)[1]
        assert run_.returncode == 2, err
        lines = err.splitlines()  # one error line; a "note:" (waiting for a worker) may precede
        errors = [ln for ln in lines if not ln.startswith("note: ")]
        assert len(errors) == 1 and errors[0].startswith("error: "), err
        assert "Traceback" not in err and "--scheduler" in errors[0]
    finally:
        for p in (worker, sched):
            p.kill()
            p.wait()


def _fake_design_chunk(spec_text, source, options, chunk):
    """Stands in for the SOS design (slow): one row per kappa naming the free set."""
    return [{"kappa": float(t["kappa"]), "lower_bound": 0.5, "steps": ",".join(options["free"]),
             **{f"theta_{p}": 0.1 for p in options["free"]}} for t in chunk]


def test_design_with_another_free_set_keeps_the_first_aside(tmp_path, monkeypatch, capsys):
    from sosalgo.batch.sweeps import run_design_sweep
    from sosalgo.spec import load_spec

    monkeypatch.setattr("sosalgo.batch.sweeps.design_chunk", _fake_design_chunk)
    spec, text = load_spec(NESTEROV), NESTEROV.read_text()
    out = tmp_path / "nesterov-design.csv"
    base = {"scalarize": "pmi", "order": None, "gap": 1e-4, "time_limit": 10.0}
    for free in (["beta"], ["h", "beta"], ["beta"]):
        rows, _ = run_design_sweep(spec, text, [10.0], out, {"free": free, **base},
                                   workers=1, progress=False)
        assert rows[0]["steps"] == ",".join(free)
    notes = capsys.readouterr().err
    assert 'free: ["beta"] -> ["h", "beta"]' in notes and "kept it aside" in notes
    assert "resuming" in notes  # the third run got the first one's rows back
    assert len(list((tmp_path / "kept").glob("nesterov-design-*.csv"))) == 1


def test_outputs_without_settings_are_kept_aside_not_overwritten(tmp_path):
    path = tmp_path / "x.csv"
    notes: list[str] = []
    for content in ("kappa,v\n2.0,1\n", "kappa,v\n3.0,1\n"):  # two foreign files in turn
        path.write_text(content)
        with ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 1}, notify=notes.append) as s:
            s.write({"kappa": 5.0, "v": 2})
        path.with_name("x.csv.settings.json").unlink()
    kept = sorted(p.read_text() for p in (tmp_path / "kept").glob("x-*.csv"))
    assert kept == ["kappa,v\n2.0,1\n", "kappa,v\n3.0,1\n"]
    assert all("settings file is missing" in n for n in notes)


def test_a_file_with_other_columns_is_kept_aside(tmp_path):
    path = tmp_path / "x.csv"
    with ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 1}) as s:
        s.write({"kappa": 2.0, "v": 1})
    notes: list[str] = []
    with ResumableCSV(path, ["kappa", "v", "w"], ["kappa"], {"a": 1}, notify=notes.append) as s:
        assert not s.is_done({"kappa": 2.0})
        s.write({"kappa": 2.0, "v": 1, "w": 3})
    assert "columns differ" in notes[0]
    assert path.read_text().splitlines()[0] == "kappa,v,w"
    assert [p.read_text() for p in (tmp_path / "kept").glob("x-*.csv")] == ["kappa,v\n2.0,1\n"]


def test_quoted_multiline_cells_survive_a_resume(tmp_path):
    path = tmp_path / "x.csv"
    with ResumableCSV(path, ["kappa", "error"], ["kappa"], {"a": 1}) as s:
        s.write({"kappa": 2.0, "error": "line one\nline two, with a comma"})
    path.write_text(path.read_text() + "3.0,half")  # a killed writer's half line
    with ResumableCSV(path, ["kappa", "error"], ["kappa"], {"a": 1},
                      notify=lambda m: None) as s:
        assert s.is_done({"kappa": 2.0})
        assert s.rows()[0]["error"] == "line one\nline two, with a comma"


def test_table1_reruns_keep_other_settings_aside_and_concurrent_runs_do_not_mix(tmp_path):
    out = tmp_path / "out"
    base = ["table1", "--specs", GRADIENT, "--out", out]
    first = run([*base, "--kappa", "4"])
    assert first.exit_code == 0, first.output
    rows = rows_of(out / "table1.csv")
    assert [float(r["kappa"]) for r in rows] == pytest.approx([4.0])
    assert float(rows[0]["rho_certified"]) == pytest.approx(1 - 1 / 4, abs=1e-5)  # h = 1/L
    # identical settings: replaced by the same table, no note
    again = run([*base, "--kappa", "4"])
    assert again.exit_code == 0 and "kept it aside" not in again.stderr
    assert not list(out.glob("table1-*.csv")) and not (out / "kept").exists()
    # other settings: the old table is kept aside, the message says what differs
    other = run([*base, "--kappa", "10"])
    assert other.exit_code == 0, other.output
    assert "kept it aside" in other.stderr and "kappa" in other.stderr
    (aside,) = (out / "kept").glob("table1-*.csv")
    assert [float(r["kappa"]) for r in rows_of(aside)] == pytest.approx([4.0])
    assert [float(r["kappa"]) for r in rows_of(out / "table1.csv")] == pytest.approx([10.0])
    # two runs at once into one folder: each table is whole (never interleaved lines)
    procs = [subprocess.Popen([sys.executable, "-m", "sosalgo.cli", "table1", "--specs",
                               str(GRADIENT), "--kappa", k, "--out", str(out)], env=ENV,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for k in ("2", "3")]
    assert all(p.wait(timeout=300) == 0 for p in procs)
    tables = [*out.glob("table1*.csv"), *(out / "kept").glob("table1*.csv")]
    for path in tables:
        got = rows_of(path)
        assert len(got) == 1 and got[0]["spec"] == "gradient", path
    kappas = {float(rows_of(p)[0]["kappa"]) for p in tables}
    assert {2.0, 3.0, 4.0} <= kappas


def test_table1_of_specs_without_a_linear_rate_says_why(tmp_path):
    res = CliRunner().invoke(cli, ["table1", "--specs", str(SPECS / "ogm.yaml"), "--specs",
                                   str(SPECS / "gradient-convex.yaml"), "--out", str(tmp_path)])
    assert res.exit_code == 2
    assert "ogm.yaml" in res.output and "no spec with a linear rate" in res.output
    assert not list(tmp_path.iterdir())
