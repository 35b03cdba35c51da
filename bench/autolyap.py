"""Per-rate cost against AutoLyap (GPL, never a dependency of sosalgo), at equal accuracy.

AutoLyap runs only in a subprocess, so this interpreter never imports GPL code. Its
interpreter is ``$SOSALGO_AUTOLYAP_PYTHON``, else ``.venv-autolyap/bin/python`` in the
repository (``make bench-autolyap`` creates it), else this interpreter when ``autolyap``
is importable here; without any, the suite prints one line and is skipped.

Both tools get the same method (our spec bound at kappa, passed to AutoLyap as a custom
``Algorithm`` with our A, B, C, D), the same function classes and one core. AutoLyap:
``IterationIndependent.LinearConvergence.bisection_search_rho`` (CVXPY + Clarabel at its
defaults), alpha = 0 (a one-step decrease V_{k+1} <= rho V_k, as ours), measure
f(y_k) - f* at the gradient point y = C xi (``get_parameters_function_value_suboptimality``,
one function only) or, for proximal gradient, |y_k - y*|^2 at the first call
(``get_parameters_distance_to_solution``).

What AutoLyap's h is (read in ``autolyap/iteration_independent.py``, ``_compute_Thetas``
and ``_build_iteration_independent_problem_cvxpy``, and ``autolyap/algorithms/
algorithm.py``, ``_generate_X_k``/``_generate_U``): V(k) is a quadratic form in
(xi_k, u_k, u_{k+1}, ..., u_{k+h}, y*) plus a linear form in f(y_k), ..., f(y_{k+h}), f*;
(C1) V(k + alpha + 1) <= rho V(k) on the window xi_0, u_0..u_{h+alpha+1}; (C2) V(k) >=
measure at the window's point tau (default 0, the oldest). Re-indexed at j = k + h this is
our lag-h V_j on (xi_j, u_j, ..., u_{j-h}) (module docstring of
:mod:`sosalgo.certificates.interpolation`): xi_j is a linear function of xi_{j-h} and the
u's, and conversely when A is invertible (every method here), so the quadratic parts are
the same set; the function-value parts are the same points; both use all ordered pairs of
the window and the optimum. With tau = h (the newest point, our (P)) and E = C (our measure
at y), AutoLyap's h = l and our lag l are the same certificate class: the like-for-like
table. Its rho is our rho^2; its bisection on rho^2 is closed to :func:`rho2_tolerance`
so that its rho is bracketed to ``TOL`` as ours. Its "solves" are the
``cvxpy.Problem.solve`` calls of one search; "in solver" the share of its time inside
Clarabel (cvxpy's ``solver_stats.solve_time``).
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.common import one_core, timed
from sosalgo.analysis import analyze_algorithm, quadratic_rate
from sosalgo.certificates.interpolation import Interpolation
from sosalgo.model import Algorithm, bind
from sosalgo.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"
TOL = 1e-6
METHODS = ("nesterov", "triple-momentum", "gradient-optimal")
KAPPAS = (10.0, 100.0)
LIKE_LAGS = (0, 1)  # like for like: sosalgo lag l (E = C) against AutoLyap h = l, tau = h
TWO_ORACLE = ("proximal-gradient",)  # f + g, a proximal step on g, distance measure
LAG_CHECK = ("nesterov", "triple-momentum", "heavy-ball")  # rates only, at LAG_KAPPA
LAG_CHECK_LAGS = (0, 1, 2)
LAG_KAPPA = 10.0
AUTOLYAP_CLASSES = {"smooth_strongly_convex": "ssc", "convex": "convex"}

# Runs in AutoLyap's interpreter: reads jobs (JSON) on stdin, writes results (JSON).
WORKER = r'''
import json, os, statistics, sys, time, warnings
import numpy as np
import cvxpy
from importlib.metadata import version
from autolyap import IterationIndependent, SolverOptions
from autolyap.algorithms.algorithm import Algorithm
from autolyap.problemclass import Convex, InclusionProblem, SmoothStronglyConvex

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
    """Our A, B, C, D; one call per function, function i = component i."""
    def __init__(self, A, B, C, D):
        self.mats = tuple(np.array(M, dtype=float) for M in (A, B, C, D))
        k = len(self.mats[3])
        super().__init__(len(A), k, [1] * k, list(range(1, k + 1)), [])

    def get_ABCD(self, k):
        return self.mats

def one_rate(job):
    algo = Given(job["A"], job["B"], job["C"], job["D"])
    prob = InclusionProblem([SmoothStronglyConvex(c[1], c[2]) if c[0] == "ssc" else Convex()
                             for c in job["classes"]])
    h, tau = job["h"], job["tau"]
    if job["measure"] == "distance":
        P, p, T, t = LC.get_parameters_distance_to_solution(algo, h=h, i=1, j=1, tau=tau)
    else:
        P, p, T, t = LC.get_parameters_function_value_suboptimality(algo, h=h, tau=tau)
    return LC.bisection_search_rho(prob, algo, P, T, p, t, h=h, tol=job["tol"],
                                   solver_options=OPTS, verbosity=0)

def measure(job):
    if job["repeats"] == 0:  # the rate only, no timing
        STATS.update(solves=0, solver=0.0)
        res = one_rate(job)
        return {"status": res["status"], "rho2": res["rho"], "solves": STATS["solves"]}
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


def rho2_tolerance(rho_q: float, tol: float) -> float:
    """Bisection width on r = rho^2 that brackets rho to ``tol``, for every rate >= rho_q.

    A bracket [lo, hi] on r with hi >= rho_q^2 and hi - lo <= w has sqrt(hi) - sqrt(lo) =
    (hi - lo) / (sqrt(hi) + sqrt(lo)) <= w / (rho_q + sqrt(rho_q^2 - w)); with
    w = tol (rho_q + sqrt(max(rho_q^2 - 2 tol rho_q, 0))) <= 2 tol rho_q that is <= tol.
    Never below tol^2 (then sqrt(hi) - sqrt(lo) <= sqrt(hi - lo) <= tol)."""
    w = tol * (rho_q + math.sqrt(max(rho_q * rho_q - 2.0 * tol * rho_q, 0.0)))
    return max(w, tol * tol)


def like_for_like(alg: Any) -> Any:
    """``alg`` measured where AutoLyap measures: a seed :class:`Algorithm` with E = C
    (f(y_k) - f*, no x-points in our LMI); an oracle-model method is returned as it is."""
    if not isinstance(alg, Algorithm):
        return alg
    return Algorithm(A=alg.A, B=alg.B, C=alg.C, E=alg.C, m=alg.m, L=alg.L, params=alg.params)


def autolyap_job(alg: Any, h: int, tau: int, repeats: int) -> dict | None:
    """One job for the worker: AutoLyap's h, tau, our A, B, C, D, the classes and the
    measure; the tolerance on rho^2 is :func:`rho2_tolerance` at the rate on quadratics
    (a lower bound of every rate). None when AutoLyap's API has no matching measure: an
    oracle-model method must call each of its functions once, in order, on the supported
    classes, and measure the distance at the first call's point (E = C_1, D_1 = 0)."""
    job = {"h": h, "tau": tau, "repeats": repeats, "A": alg.A.tolist(), "B": alg.B.tolist(),
           "C": alg.C.tolist(), "tol": rho2_tolerance(quadratic_rate(alg), TOL)}
    if isinstance(alg, Algorithm):  # AutoLyap measures at y = C xi whatever our E
        return job | {"D": [[0.0]], "measure": "function",
                      "classes": [["ssc", alg.m, alg.L]]}
    names = [AUTOLYAP_CLASSES.get(fn.cls.name) for fn in alg.functions]
    if (None in names or tuple(alg.oracles) != tuple(range(len(names)))
            or alg.measure != "distance" or alg.output is not None
            or not np.array_equal(alg.E[0], alg.C[0]) or np.any(alg.D[0] != 0)):
        return None
    classes = [[n, fn.params.get("m"), fn.params.get("L")]
               for n, fn in zip(names, alg.functions, strict=True)]
    return job | {"D": alg.D.tolist(), "measure": "distance", "classes": classes}


def autolyap_rates(python: str, jobs: list[dict], worker: str = WORKER,
                   timeout: int = 900) -> dict:
    """AutoLyap's results for ``jobs`` (one subprocess running ``worker``, the jobs as JSON
    on its input): version, cores, one dict per job."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    try:
        out = subprocess.run([python, "-c", worker], input=json.dumps(jobs), text=True,
                             capture_output=True, env=env, check=False, timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        raise RuntimeError(f"AutoLyap worker timed out ({timeout} s)") from exc
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
            _tables(python, origin, repeats, core, quick)
        except RuntimeError as exc:  # AutoLyap's side failed: one line, no table
            print(f"skipped: {exc}")


def timed_rate(alg: Any, fam: Interpolation, repeats: int) -> tuple[float, Any, float]:
    """(median seconds, result, median processor seconds of this thread) of one analysis
    at ``TOL`` after a warm-up; (nan, result, nan) with no timing when ``repeats`` is 0."""
    res = analyze_algorithm(alg, tol=TOL, family=fam)
    if repeats == 0:
        return math.nan, res, math.nan
    cpu: list[float] = []

    def one() -> object:
        c0 = time.thread_time()
        out = analyze_algorithm(alg, tol=TOL, family=fam)
        cpu.append(time.thread_time() - c0)
        return out

    t, res, _ = timed(one, repeats)
    return t, res, statistics.median(cpu)


def _measure_rows(python: str, repeats: int, quick: bool) -> list[dict]:
    """Per (method, kappa), row by row so that both tools see the same load: sosalgo at
    its own measure (lag chosen, lag 0), at AutoLyap's (lags ``LIKE_LAGS``), and AutoLyap
    at h = tau = l (h = 0 is also the first table's AutoLyap column)."""
    rows = []
    for name in METHODS + TWO_ORACLE:
        for k in (10.0,) if quick else KAPPAS:
            alg = bind(load_spec(SPECS / f"{name}.yaml"), k)
            same = like_for_like(alg)
            jobs = [autolyap_job(same, h, h, repeats) for h in LIKE_LAGS]
            if None in jobs:
                continue
            row: dict[str, Any] = {"name": name, "k": k, "seed": name in METHODS}
            if row["seed"]:
                row["auto"] = timed_rate(alg, Interpolation(), repeats)
                row["lag0"] = timed_rate(alg, Interpolation(0), repeats)
            row["like"] = [timed_rate(same, Interpolation(h), repeats) for h in LIKE_LAGS]
            row["theirs"] = autolyap_rates(python, jobs)
            rows.append(row)
    return rows


def _tables(python: str, origin: str, repeats: int, core: str, quick: bool) -> None:
    load = os.getloadavg()[0]
    rows = _measure_rows(python, repeats, quick)
    info = rows[0]["theirs"]
    print(f"AutoLyap {info['version']} ({origin}) against sosalgo, median time per "
          f"certified rate over {repeats} repeats, {core} (AutoLyap's subprocess on cores "
          f"{info['cores']})")
    print(f"(load average at start: {load:.1f}, at the end: {os.getloadavg()[0]:.1f}; "
          "ρ AutoLyap = √(its rho); "
          f"tol: {TOL:g} on ρ for sosalgo, on √(its rho) for AutoLyap (its bisection on "
          "rho closed to 2ρ_Q·tol at most, ρ_Q the rate on quadratics))")
    print("(CPU: median processor time of one rate, both tools; the CPU ratios are the ones "
          "that hold on a loaded machine)")
    print("\nNot like for like (sosalgo's default): sosalgo bounds f(x_k) − f* (x = Eξ; "
          "for Nesterov E ≠ C: extra x-points in its LMI), AutoLyap f(y_k) − f* with h = 0 "
          "(the runs of the like-for-like rows ℓ = h = 0).")
    print("| method | κ | ρ sosalgo (lag) | ρ AutoLyap | AutoLyap − sosalgo | solves sosalgo | "
          "solves AutoLyap | sosalgo ms | lag 0 ms | AutoLyap ms | in solver | "
          "ratio | ratio lag 0 | CPU ms sosalgo / lag 0 / AutoLyap | CPU ratio | "
          "CPU ratio lag 0 |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    ratios: dict[tuple[str, str], list[float]] = {}
    for row in rows:
        if row["seed"]:
            _row(row["name"], row["k"], row, row["theirs"]["results"][0], ratios)
    print(LEGEND)
    print("| method | κ | ℓ = h | ρ sosalgo (E = C) | ρ AutoLyap (τ = h) | AutoLyap − sosalgo | "
          "solves sosalgo | solves AutoLyap | sosalgo ms | AutoLyap ms | ratio | "
          "CPU ms sosalgo / AutoLyap | CPU ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    like: dict[tuple[str, int], list[tuple[float, float]]] = {}
    for row in rows:
        for i, h in enumerate(LIKE_LAGS):
            like.setdefault((row["name"], h), []).append(_like_row(row, i, h))
    print()
    for (name, which), rs in ratios.items():
        print(f"{name}, sosalgo {which}: AutoLyap / sosalgo per rate = "
              f"{min(rs):.1f}–{max(rs):.1f}x")
    for (name, h), pairs in like.items():
        wall, cpu = [p[0] for p in pairs], [p[1] for p in pairs]
        print(f"{name}, like for like ℓ = h = {h}: AutoLyap / sosalgo per rate = "
              f"{min(wall):.1f}–{max(wall):.1f}x, CPU {min(cpu):.1f}–{max(cpu):.1f}x")
    _lag_check(python)


LEGEND = (
    "\nLike for like: sosalgo at AutoLyap's measure (E = C: f(y_k) − f*, the gradient "
    "point; proximal gradient: |x_k − x*|² for both) with lag ℓ against AutoLyap's h = ℓ, "
    "α = 0, τ = h. The classes are the same: AutoLyap's V on (ξ_k, u_k … u_{k+h}) is our "
    "lag-h V on (ξ_{k+h}, u_{k+h} … u_k) re-indexed (A invertible), same function values, "
    "same interpolation pairs, V bounding the measure at the window's newest point.")


def _fmt_rho(res: dict) -> tuple[str, float | None]:
    """AutoLyap's rate as printed, and as a number (None unless feasible)."""
    if res["status"] != "feasible":
        return res["status"], None
    rho = res["rho2"] ** 0.5
    return f"{rho:.7f}", rho


def _row(name: str, k: float, mine: dict, res: dict, ratios: dict) -> None:
    t, ours, c = mine["auto"]
    t0, _, c0 = mine["lag0"]
    rho = "-" if ours.rho is None else f"{ours.rho:.7f} ({ours.lag})"
    rt, theirs = _fmt_rho(res)
    diff = "-" if ours.rho is None or theirs is None else f"{theirs - ours.rho:+.1e}"
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


def _like_row(row: dict, i: int, h: int) -> tuple[float, float]:
    """One like-for-like row: sosalgo lag h at AutoLyap's measure against its h = tau = h;
    returns the ratios AutoLyap / sosalgo (wall, CPU)."""
    t, ours, c = row["like"][i]
    res = row["theirs"]["results"][i]
    rt, theirs = _fmt_rho(res)
    rho = "-" if ours.rho is None else f"{ours.rho:.7f}"
    diff = "-" if ours.rho is None or theirs is None else f"{theirs - ours.rho:+.1e}"
    ratio, cratio = res["median"] / t, res["cpu"] / c
    print(f"| {row['name']} | {row['k']:g} | {h} | {rho} | {rt} | {diff} | {ours.solves} | "
          f"{res['solves']:g} | {t * 1e3:.1f} | {res['median'] * 1e3:.0f} | {ratio:.1f}x | "
          f"{c * 1e3:.1f} / {res['cpu'] * 1e3:.0f} | {cratio:.1f}x |", flush=True)
    return ratio, cratio


def _lag_check(python: str) -> None:
    """Rates only: sosalgo lag l at E = C against AutoLyap h = l with tau = h (the same
    class) and tau = 0 (its default: V bounds the oldest point of the window)."""
    algs = [(n, like_for_like(bind(load_spec(SPECS / f"{n}.yaml"), LAG_KAPPA)))
            for n in LAG_CHECK]
    cases = [(n, a, h, tau) for n, a in algs for h in LAG_CHECK_LAGS for tau in sorted({h, 0})]
    jobs = [autolyap_job(a, h, tau, 0) for _, a, h, tau in cases]
    theirs = dict(zip([(n, h, tau) for n, _, h, tau in cases],
                      autolyap_rates(python, jobs)["results"], strict=True))
    print(f"\nLag against h (rates only, κ = {LAG_KAPPA:g}, sosalgo at E = C; heavy ball "
          "separates the lags):")
    print("| method | ℓ = h | ρ sosalgo | ρ AutoLyap τ = h | AutoLyap − sosalgo | "
          "ρ AutoLyap τ = 0 |")
    print("|---|---|---|---|---|---|")
    for name, alg in algs:
        for h in LAG_CHECK_LAGS:
            ours = analyze_algorithm(alg, tol=TOL, family=Interpolation(h)).rho
            same, rho = _fmt_rho(theirs[(name, h, h)])
            oldest, _ = _fmt_rho(theirs[(name, h, 0)])
            diff = "-" if ours is None or rho is None else f"{rho - ours:+.1e}"
            print(f"| {name} | {h} | {'-' if ours is None else f'{ours:.7f}'} | {same} | "
                  f"{diff} | {oldest} |", flush=True)


if __name__ == "__main__":
    run(quick="--quick" in sys.argv)
