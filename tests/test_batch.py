"""Batch layer: grids, workers, Dask, resumable output surviving SIGKILL, progress."""

from __future__ import annotations

import csv
import gc
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.optimize import minimize

from sosalgo.analysis import analyze_spec
from sosalgo.batch.sweeps import run_grid
from sosalgo.cli import cli
from sosalgo.model import parameter_box
from sosalgo.spec import load_spec
from sosalgo.store import ResumableCSV

from .conftest import SPECS

NESTEROV = SPECS / "nesterov.yaml"
ROOT = Path(__file__).resolve().parents[1]


def _grid(tmp_path, points=6, **kw):
    spec = load_spec(NESTEROV)
    box = parameter_box(spec, 10.0, ["h", "beta"])
    return run_grid(spec, NESTEROV.read_text(), 10.0, ["h", "beta"], box, points,
                    tmp_path / "g.csv", 1e-6, progress=False, **kw)


def _values(rows):
    return [(r["h"], r["beta"], r["rho"], r["certified"]) for r in rows]


def test_grid_equals_single_point_analysis(tmp_path):
    spec = load_spec(NESTEROV)
    rows = _grid(tmp_path, workers=1)
    assert len(rows) == 36
    for r in rows[::5]:
        res = analyze_spec(spec, 10.0, {"h": float(r["h"]), "beta": float(r["beta"])})
        if res.certified:
            assert float(r["rho"]) == pytest.approx(res.rho, abs=1e-12)
        else:
            assert r["certified"] == "false" and r["rho"] == ""


def test_workers_and_dask_give_the_same_rows(tmp_path):
    serial = _values(_grid(tmp_path / "a", workers=1))
    local = _values(_grid(tmp_path / "b", workers=2))
    assert serial == local
    distributed = pytest.importorskip("distributed")
    gc.collect()  # a Client left by an earlier test must not close inside this loop's start
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        dask_rows = _values(_grid(tmp_path / "c", scheduler=cluster.scheduler_address))
    assert serial == dask_rows


def test_grid_minimum_is_near_a_polished_optimum(tmp_path):
    spec = load_spec(NESTEROV)
    points = 15
    rows = _grid(tmp_path, points=points, workers=2)
    rho = np.array([float(r["rho"]) if r["rho"] else np.inf for r in rows])
    i = int(np.argmin(rho))
    h0, b0 = float(rows[i]["h"]), float(rows[i]["beta"])
    box = parameter_box(spec, 10.0, ["h", "beta"])

    def f(z):
        res = analyze_spec(spec, 10.0, {"h": float(z[0]), "beta": float(z[1])}, tol=1e-7)
        return res.rho if res.certified else 2.0

    opt = minimize(f, [h0, b0], method="Nelder-Mead", bounds=box,
                   options={"xatol": 1e-6, "fatol": 1e-9, "maxfev": 400})
    steps = [(hi - lo) / (points - 1) for lo, hi in box]
    assert abs(opt.x[0] - h0) <= steps[0] + 1e-12
    assert abs(opt.x[1] - b0) <= steps[1] + 1e-12
    assert opt.fun <= rho[i] + 1e-9


def test_settings_are_recorded_and_other_settings_kept_aside(tmp_path):
    path = tmp_path / "x.csv"
    with ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 1}) as store:
        store.write({"kappa": 2.0, "v": 1})
        store.write({"kappa": 2.0, "v": 99})  # duplicate key: ignored
    assert json.loads(path.with_name("x.csv.settings.json").read_text()) == {"a": 1}
    notes = []
    with ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 2}, notify=notes.append) as s2:
        assert not s2.is_done({"kappa": 2.0})
    assert "a: 1 -> 2" in notes[0] and "kept it aside" in notes[0]
    with ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 1}, notify=notes.append) as again:
        assert again.is_done({"kappa": 2.0}) and len(again.rows()) == 1
    path.write_text(path.read_text() + "3.0,4")  # a half-written line from a killed writer
    assert len(ResumableCSV(path, ["kappa", "v"], ["kappa"], {"a": 1}).rows()) == 1


def _grid_cmd(out: Path, points: int) -> list[str]:
    return [sys.executable, "-m", "sosalgo.cli", "grid", str(NESTEROV), "--kappa", "10",
            "--points", str(points), "--out", str(out), "--workers", "2", "--tol", "1e-5"]


def test_sigkill_then_resume_gives_each_point_once(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    points = 14
    ref_dir, dir_ = tmp_path / "ref", tmp_path / "killed"
    subprocess.run(_grid_cmd(ref_dir, points) + ["--quiet"], check=True, env=env,
                   capture_output=True, timeout=600)
    csv_path = dir_ / "nesterov-grid-k10.csv"
    proc = subprocess.Popen(_grid_cmd(dir_, points) + ["--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline:
        if csv_path.exists() and csv_path.read_text().count("\n") > 40:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    partial = csv_path.read_text().count("\n") - 1
    assert 0 < partial < points * points, partial  # really interrupted midway
    subprocess.run(_grid_cmd(dir_, points) + ["--quiet"], check=True, env=env,
                   capture_output=True, timeout=600)
    rows = list(csv.DictReader(open(csv_path)))
    keys = [(r["h"], r["beta"]) for r in rows]
    assert len(keys) == len(set(keys)) == points * points
    ref = {(r["h"], r["beta"]): r["rho"] for r in csv.DictReader(
        open(ref_dir / "nesterov-grid-k10.csv"))}
    for r in rows:
        a, b = ref[(r["h"], r["beta"])], r["rho"]
        assert (a == b == "") or abs(float(a) - float(b)) <= 1e-12


def test_grid_cli_outputs_and_json_stays_clean(tmp_path):
    res = CliRunner().invoke(cli, ["grid", str(NESTEROV), "--kappa", "10", "--points", "5",
                                   "--out", str(tmp_path), "--json", "--workers", "1"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # progress went to stderr only
    (g,) = doc["grids"]
    assert g["points"] == 25 and g["minimum"]["rho"] < 0.9
    assert "grid nesterov" in res.stderr
    for ext in ("csv", "png", "pdf"):
        assert (tmp_path / f"nesterov-grid-k10.{ext}").exists()
    one = CliRunner().invoke(cli, ["grid", str(NESTEROV), "--kappa", "10", "--points", "5",
                                   "--free", "beta", "--out", str(tmp_path / "one"), "--quiet"])
    assert one.exit_code == 0 and (tmp_path / "one" / "nesterov-grid-k10.png").exists()
    assert one.stderr == ""


def test_quiet_and_different_settings(tmp_path):
    args = ["analyze", str(SPECS / "gradient.yaml"), "--kappa", "3", "--out", str(tmp_path),
            "--no-plot"]
    res = CliRunner().invoke(cli, [*args, "--quiet"])
    assert res.exit_code == 0 and res.stderr == ""
    res = CliRunner().invoke(cli, [*args, "--tol", "1e-3"])
    assert res.exit_code == 0 and "tol: 1e-06 -> 0.001" in res.stderr


def _padded_heavy_ball(n: int) -> str:
    """Heavy ball with n - 2 shift states x_{k-2}, x_{k-3}, ... that do not act on it: a
    method whose solves are large enough for Clarabel's solver threads."""
    rows = [[0] * n for _ in range(n)]
    rows[0][1], rows[1][0], rows[1][1] = 1, "-beta", "1 + beta"
    for j in range(2, n):
        rows[j][0 if j == 2 else j - 1] = 1
    out = [[0] * n]
    out[0][1] = 1
    return json.dumps({  # JSON is YAML (without aliases)
        "name": f"heavy-ball-{n}",
        "parameters": {"h": {"value": "4/(sqrt(L) + sqrt(m))**2", "range": [0, "4/L"]},
                       "beta": {"value": "((sqrt(kappa) - 1)/(sqrt(kappa) + 1))**2",
                                "range": [0, 1]}},
        "matrices": {"A": rows, "B": [[0], ["-h"]] + [[0]] * (n - 2), "C": out, "E": out},
        "kappa": [10]})


POOL_AFTER_SOLVE = """
import sys
from pathlib import Path
from sosalgo.analysis import analyze_spec
from sosalgo.batch.executor import run_batch
from sosalgo.batch.sweeps import analysis_chunk
from sosalgo.spec import load_spec

if __name__ == "__main__":
    path = Path(sys.argv[1])
    analyze_spec(load_spec(path), 2.0)  # the solver's threads start in this process
    rows = []
    run_batch(analysis_chunk, path.read_text(), str(path), {"tol": 1e-4, "certificate": None},
              [{"kappa": 1.5 + i} for i in range(8)], rows.append, workers=2)
    print(len(rows))
"""


def test_a_pool_started_after_a_solve_does_not_deadlock(tmp_path):
    """A worker forked from a process whose solver threads run hangs in its first large
    solve (it happened with 12 states): pools never fork the caller."""
    spec = tmp_path / "hb12.yaml"
    spec.write_text(_padded_heavy_ball(12))
    script = tmp_path / "run.py"
    script.write_text(POOL_AFTER_SOLVE)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, str(script), str(spec)], env=env, timeout=300,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["8"]


def test_a_design_on_workers_keeps_its_time_limit(tmp_path):
    """The grid and the local searches run on a pool; a limit reached there stops the
    pool's work, and no worker outlives the design."""
    import multiprocessing

    from sosalgo.design_search import design

    spec = load_spec(SPECS / "three-parameter.yaml")
    limit = 6.0
    t0 = time.perf_counter()
    res = design(spec, 10.0, free=["h", "beta", "gamma"], time_limit=limit, workers=2)
    wall = time.perf_counter() - t0
    assert wall <= limit + 10.0, wall  # a wide margin: a loaded machine, a last solve
    assert res.rho_certified is not None and (res.time_limited or res.gap_met)
    grid = next(s for s in res.steps if s.startswith("grid:"))
    if not grid.startswith("grid: 343 points"):  # a cut grid says so
        assert any("cut short" in s or "parallel tasks" in s for s in res.steps), res.steps
    assert not multiprocessing.active_children()


def _descendants(pid: int) -> set[int]:
    out: set[int] = set()
    todo = [pid]
    while todo:
        p = todo.pop()
        try:
            tasks = list(Path(f"/proc/{p}/task").iterdir())
        except FileNotFoundError:
            continue
        for task in tasks:
            try:
                kids = [int(c) for c in (task / "children").read_text().split()]
            except FileNotFoundError:
                continue
            out.update(kids)
            todo += kids
    return out


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_sigkill_of_a_pool_run_leaves_no_process_behind(tmp_path):
    """Pool workers are not children of the run (a fork server starts them): they still
    end when the run is killed, busy or idle, and so does the server."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(_grid_cmd(tmp_path, 40) + ["--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    family: set[int] = set()
    while time.time() < deadline and len(family) < 4:  # tracker, server, two workers
        time.sleep(0.2)
        family = {p for p in _descendants(proc.pid) if _running(p)}
    assert len(family) >= 4, "no pool started"
    proc.kill()
    proc.wait()
    deadline = time.time() + 15
    while time.time() < deadline and any(_running(p) for p in family):
        time.sleep(0.1)
    assert not any(_running(p) for p in family)
