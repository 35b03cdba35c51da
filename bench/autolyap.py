"""Per-rate cost against AutoLyap (GPL, never a dependency of sosalgo), at equal accuracy.

AutoLyap runs only in a subprocess, so this interpreter never imports GPL code. Its
interpreter is ``$SOSALGO_AUTOLYAP_PYTHON``, else ``.venv-autolyap/bin/python`` in the
repository (``make bench-autolyap`` creates it), else this interpreter when ``autolyap``
is importable here; without any, the suite prints one line and is skipped.

Both tools get the same method (our spec bound at kappa, passed to AutoLyap as a custom
``Algorithm`` with our A, B, C and D = 0), the same F(m, L) and one core. sosalgo: the
interpolation family with the lag chosen (the default) and with lag 0, tol 1e-6 on rho.
AutoLyap: ``IterationIndependent.LinearConvergence.bisection_search_rho`` with h = 0,
alpha = 0, the function-value measure f(y_k) - f* (its only function measure; ours is
f(x_k) - f*), CVXPY + Clarabel with its defaults, bisecting its rho (= our rho squared)
on [0, 1] to 1e-6, i.e. our rho to 1e-6 / (2 rho) <= 1e-6 for rho >= 1/2. Its "solves"
are the ``cvxpy.Problem.solve`` calls of one search; "in solver" is the share of its time
inside Clarabel (cvxpy's ``solver_stats.solve_time``).
"""

from __future__ import annotations

import importlib.util
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from bench.common import one_core, timed
from sosalgo.analysis import analyze_algorithm
from sosalgo.certificates.interpolation import Interpolation
from sosalgo.model import Algorithm, bind
from sosalgo.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"
TOL = 1e-6
METHODS = ("nesterov", "triple-momentum", "gradient-optimal")
KAPPAS = (10.0, 100.0)

# Runs in AutoLyap's interpreter: reads jobs (JSON) on stdin, writes results (JSON).
WORKER = r'''
import json, os, statistics, sys, time, warnings
import numpy as np
import cvxpy
from importlib.metadata import version
from autolyap import IterationIndependent, SolverOptions
from autolyap.algorithms.algorithm import Algorithm
from autolyap.problemclass import InclusionProblem, SmoothStronglyConvex

warnings.simplefilter("ignore")
LC = IterationIndependent.LinearConvergence
OPTS = SolverOptions(backend="cvxpy", cvxpy_solver="CLARABEL")
STATS = {"solves": 0, "solver": 0.0}
_solve = cvxpy.Problem.solve

def counting_solve(self, *args, **kwargs):
    STATS["solves"] += 1  # every attempt, also those ending in a SolverError
    before = self.solver_stats
    try:
        return _solve(self, *args, **kwargs)
    finally:
        st = self.solver_stats
        if st is not None and st is not before:  # a failed solve leaves the old stats
            STATS["solver"] += st.solve_time or 0.0

cvxpy.Problem.solve = counting_solve

class Given(Algorithm):
    def __init__(self, A, B, C):
        self.mats = tuple(np.array(M, dtype=float) for M in (A, B, C))
        super().__init__(len(A), 1, [1], [1], [])

    def get_ABCD(self, k):
        A, B, C = self.mats
        return A, B, C, np.zeros((1, 1))

def one_rate(job):
    algo = Given(job["A"], job["B"], job["C"])
    prob = InclusionProblem([SmoothStronglyConvex(job["m"], job["L"])])
    P, p, T, t = LC.get_parameters_function_value_suboptimality(algo, h=job["h"])
    return LC.bisection_search_rho(prob, algo, P, T, p, t, h=job["h"], tol=job["tol"],
                                   solver_options=OPTS, verbosity=0)

def measure(job):
    one_rate(job)  # warm-up: imports, cvxpy's first canonicalization
    times, cpus, solves, solver = [], [], [], []
    for _ in range(job["repeats"]):
        STATS.update(solves=0, solver=0.0)
        t0, c0 = time.perf_counter(), time.process_time()
        res = one_rate(job)
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        solves.append(STATS["solves"])
        solver.append(STATS["solver"])
    return {"status": res["status"], "rho2": res["rho"], "median": statistics.median(times),
            "min": min(times), "solves": statistics.median(solves),
            "solver": statistics.median(solver), "cpu": statistics.median(cpus)}

jobs = json.load(sys.stdin)
print(json.dumps({"version": version("autolyap"), "results": [measure(j) for j in jobs],
                  "cores": sorted(os.sched_getaffinity(0))}))
'''


def autolyap_python() -> tuple[str | None, str]:
    """(interpreter that imports autolyap, where it came from), or (None, why not)."""
    env = os.environ.get("SOSALGO_AUTOLYAP_PYTHON")
    local = ROOT / ".venv-autolyap" / "bin" / "python"
    if env:  # an explicit choice is used alone
        candidates = [(env, "SOSALGO_AUTOLYAP_PYTHON")]
    else:
        candidates = [(str(local), ".venv-autolyap")] if local.exists() else []
        if importlib.util.find_spec("autolyap") is not None:
            candidates.append((sys.executable, "this interpreter, in a subprocess"))
    for python, origin in candidates:
        try:
            probe = subprocess.run([python, "-c", "import autolyap"], capture_output=True)
        except OSError:
            continue
        if probe.returncode == 0:
            return python, origin
    if env:
        return None, f"SOSALGO_AUTOLYAP_PYTHON={env} cannot import autolyap"
    return None, ("autolyap not installed (make bench-autolyap, or set "
                  "SOSALGO_AUTOLYAP_PYTHON to a Python that has it)")


def autolyap_rates(python: str, algs: list[Algorithm], repeats: int, h: int = 0) -> dict:
    """AutoLyap's results for ``algs`` (one subprocess): version and one dict per method."""
    jobs = [{"A": a.A.tolist(), "B": a.B.tolist(), "C": a.C.tolist(), "m": a.m, "L": a.L,
             "h": h, "tol": TOL, "repeats": repeats} for a in algs]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    try:
        out = subprocess.run([python, "-c", WORKER], input=json.dumps(jobs), text=True,
                             capture_output=True, env=env, check=False, timeout=900)
    except subprocess.TimeoutExpired as exc:
        raise RuntimeError("AutoLyap worker timed out (900 s)") from exc
    if out.returncode != 0:
        tail = out.stderr.strip().splitlines()[-1:] or ["no message"]
        raise RuntimeError(f"AutoLyap worker failed: {tail[0]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> None:
    python, origin = autolyap_python()
    if python is None:
        print(f"skipped: {origin}")
        return
    repeats = 3 if quick else 15
    with one_core() as core:
        try:
            _table(python, origin, repeats, core, quick)
        except RuntimeError as exc:  # AutoLyap's side failed: one line, no table
            print(f"skipped: {exc}")


def _table(python: str, origin: str, repeats: int, core: str, quick: bool) -> None:
    algs = [(n, k, bind(load_spec(SPECS / f"{n}.yaml"), k))
            for n in METHODS for k in ((10.0,) if quick else KAPPAS)]
    ours, theirs = [], []
    for _, _, alg in algs:  # row by row, so that both tools see the same load
        ours.append(_ours(alg, repeats))
        theirs.append(autolyap_rates(python, [alg], repeats))
    print(f"AutoLyap {theirs[0]['version']} ({origin}) against sosalgo, median time per "
          f"certified rate over {repeats} repeats, tol {TOL:g}, {core} "
          f"(AutoLyap's subprocess on cores {theirs[0]['cores']})")
    print(f"(load average at start: {os.getloadavg()[0]:.1f}; ρ AutoLyap = √(its rho))")
    print("(CPU: median processor time of one rate, both tools; the CPU ratios are the ones "
          "that hold on a loaded machine)")
    print("| method | κ | ρ sosalgo (lag) | ρ AutoLyap | AutoLyap − sosalgo | solves sosalgo | "
          "solves AutoLyap | sosalgo ms | lag 0 ms | AutoLyap ms | in solver | "
          "ratio | ratio lag 0 | CPU ms sosalgo / lag 0 / AutoLyap | CPU ratio | "
          "CPU ratio lag 0 |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    ratios: dict[tuple[str, str], list[float]] = {}
    for (name, k, _), mine, res in zip(algs, ours, theirs, strict=True):
        _row(name, k, mine, res["results"][0], ratios)
    print()
    for (name, which), rs in ratios.items():
        print(f"{name}, sosalgo {which}: AutoLyap / sosalgo per rate = "
              f"{min(rs):.1f}–{max(rs):.1f}x")


def _ours(alg: Algorithm, repeats: int) -> dict:
    """sosalgo's default (lag chosen) and lag 0: (median seconds, result, median processor
    seconds of this thread)."""
    out = {}
    for key, fam in (("auto", Interpolation()), ("lag0", Interpolation(0))):
        analyze_algorithm(alg, tol=TOL, family=fam)  # warm-up
        cpu: list[float] = []

        def one(f: Interpolation = fam, cpu: list[float] = cpu) -> object:
            c0 = time.thread_time()
            res = analyze_algorithm(alg, tol=TOL, family=f)
            cpu.append(time.thread_time() - c0)
            return res

        t, res, _ = timed(one, repeats)
        out[key] = (t, res, statistics.median(cpu))
    return out


def _row(name: str, k: float, mine: dict, res: dict, ratios: dict) -> None:
    t, ours, c = mine["auto"]
    t0, _, c0 = mine["lag0"]
    rho = "-" if ours.rho is None else f"{ours.rho:.7f} ({ours.lag})"
    if res["status"] == "feasible":
        theirs = res["rho2"] ** 0.5
        diff = "-" if ours.rho is None else f"{theirs - ours.rho:+.1e}"
        rt = f"{theirs:.7f}"
    else:
        rt, diff = res["status"], "-"
    share = res["solver"] / res["median"]
    ratio, ratio0 = res["median"] / t, res["median"] / t0
    ratios.setdefault((name, "lag chosen"), []).append(ratio)
    ratios.setdefault((name, "lag 0"), []).append(ratio0)
    print(f"| {name} | {k:g} | {rho} | {rt} | {diff} | {ours.solves} | {res['solves']:g} | "
          f"{t * 1e3:.1f} | {t0 * 1e3:.1f} | {res['median'] * 1e3:.0f} | {share:.0%} | "
          f"{ratio:.1f}x | {ratio0:.1f}x | {c * 1e3:.1f} / {c0 * 1e3:.1f} / "
          f"{res['cpu'] * 1e3:.0f} | {res['cpu'] / c:.1f}x | {res['cpu'] / c0:.1f}x |",
          flush=True)
    ratios.setdefault((name, "lag chosen, CPU"), []).append(res["cpu"] / c)
    ratios.setdefault((name, "lag 0, CPU"), []).append(res["cpu"] / c0)


if __name__ == "__main__":
    run(quick="--quick" in sys.argv)
