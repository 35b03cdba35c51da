"""A 40x40 grid over (h, beta) at kappa = 10 (tol 1e-5): 1 worker, 2 workers, and a Dask
LocalCluster with 2 workers, in the same run."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from sosalgo.batch.sweeps import run_grid
from sosalgo.model import parameter_box
from sosalgo.spec import load_spec

SPEC = Path(__file__).resolve().parents[1] / "specs" / "nesterov.yaml"


def _time(points: int, **kw) -> float:
    spec = load_spec(SPEC)
    box = parameter_box(spec, 10.0, ["h", "beta"])
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        run_grid(spec, SPEC.read_text(), 10.0, ["h", "beta"], box, points,
                 Path(tmp) / "g.csv", 1e-5, progress=False, **kw)
        return time.perf_counter() - t0


def run(quick: bool = False) -> None:
    points = 20 if quick else 40
    print(f"grid {points}x{points} over (h, beta), kappa = 10, tol 1e-5")
    print("| execution | seconds | points/s | speed-up vs 1 worker |")
    print("|---|---|---|---|")
    t1 = _time(points, workers=1)
    n = points * points
    print(f"| 1 worker (in-process) | {t1:.2f} | {n / t1:.0f} | 1.00x |", flush=True)
    t2 = _time(points, workers=2)
    print(f"| 2 worker processes | {t2:.2f} | {n / t2:.0f} | {t1 / t2:.2f}x |", flush=True)
    try:
        from distributed import LocalCluster
    except ImportError:
        print("| Dask LocalCluster | not installed | | |")
        return
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        t3 = _time(points, scheduler=cluster.scheduler_address)
    print(f"| Dask LocalCluster, 2 workers (started before timing) | {t3:.2f} | {n / t3:.0f} "
          f"| {t1 / t3:.2f}x |", flush=True)
