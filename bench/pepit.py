"""PEP time against PEPit (never a dependency of sosalgo), on the same case in the same run.

PEPit runs only in a subprocess, in its own interpreter: ``$SOSALGO_PEPIT_PYTHON``, else
``.venv-pepit/bin/python`` in the repository (``make bench-pepit`` creates it), else this
interpreter when ``PEPit`` is importable here; without any, the suite prints one line
and is skipped.

Cases: gradient descent (h = 1/L, |x_N - x*|^2 / |x_0 - x*|^2) and Nesterov's method
(h = 1/L, beta = (sqrt(kappa) - 1)/(sqrt(kappa) + 1), (f(x_N) - f*) / |x_0 - x*|^2) on
L-smooth mu-strongly convex f, mu = 1, L = kappa = 10 (our ``specs/gradient.yaml`` and
``specs/nesterov.yaml``), written in PEPit's own terms. sosalgo: ``sosalgo.pep`` with the
exact proof, no witness (a fresh process per case: its peak memory is its own). PEPit:
``PEP.solve(wrapper="cvxpy")`` with its default solver (SCS here, without MOSEK) and with
Clarabel; its time is the ``solve`` call (problem building excluded, to its advantage).
The accuracy each reaches is printed beside its time: PEPit's value against sosalgo's
proven bound (sosalgo's value is an exact upper bound; PEPit's is a float, above or
below the true value by its solver's accuracy), with each run's peak memory and
sosalgo's Clarabel solves. N = 10 ... 100; a case past ``SOSALGO_BENCH_CASE_SECONDS``
(1800) is reported as such; ``SOSALGO_BENCH_METHODS`` (``gradient,nesterov``) and
``SOSALGO_BENCH_STEPS`` (``50,70``) choose the cases.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

from bench.pep import SOSALGO_CHILD

ROOT = Path(__file__).resolve().parents[1]
KAPPA = 10.0
CASES = (("gradient", "dist"), ("nesterov", None))
STEPS, QUICK_STEPS = (10, 20, 30, 50, 70, 100), (10, 20)
SOLVERS = ("default", "CLARABEL")
# seconds allowed to one case (one tool, one method, one N): a case past it prints
# "over ... s" and the run goes on (``SOSALGO_BENCH_CASE_SECONDS`` changes it)
CASE_SECONDS = float(os.environ.get("SOSALGO_BENCH_CASE_SECONDS", "1800"))

# The end of every PEPit worker script: solve (``solver`` and ``problem`` set by the script),
# then print the value, time, status, solver and peak memory as one JSON line.
SOLVE_AND_REPORT = r'''kw = {} if solver == "default" else {"solver": solver}
t0 = time.perf_counter()
tau = problem.solve(wrapper="cvxpy", verbose=0, **kw)
seconds = time.perf_counter() - t0
w = getattr(problem, "wrapper", None)
hwm = [int(x.split()[1]) for x in open("/proc/self/status") if x.startswith("VmHWM:")][0]
print(json.dumps({"tau": tau, "seconds": seconds,
                  "status": str(getattr(getattr(w, "prob", None), "status", None)),
                  "solver": str(getattr(w, "solver_name", None) or solver),
                  "mb": hwm / 1024}))
'''

# Runs in PEPit's interpreter: one case, one JSON line out.
WORKER = r'''
import json, math, sys, time, warnings
warnings.simplefilter("ignore")
from PEPit import PEP
from PEPit.functions import SmoothStronglyConvexFunction

method, N, kappa, solver = json.loads(sys.argv[1])
mu, L = 1.0, float(kappa)
problem = PEP()
func = problem.declare_function(SmoothStronglyConvexFunction, mu=mu, L=L)
xs = func.stationary_point()
fs = func(xs)
x0 = problem.set_initial_point()
problem.set_initial_condition((x0 - xs) ** 2 <= 1)
h = 1 / L
if method == "gradient":
    x = x0
    for _ in range(N):
        x = x - h * func.gradient(x)
    problem.set_performance_metric((x - xs) ** 2)
else:
    beta = (math.sqrt(kappa) - 1) / (math.sqrt(kappa) + 1)
    xp, x = x0, x0
    for _ in range(N):
        y = x + beta * (x - xp)
        xp, x = x, y - h * func.gradient(y)
    problem.set_performance_metric(func(x) - fs)
''' + SOLVE_AND_REPORT


def pepit_python() -> tuple[str | None, str]:
    """(interpreter that imports PEPit, where it came from), or (None, why not)."""
    env = os.environ.get("SOSALGO_PEPIT_PYTHON")
    local = ROOT / ".venv-pepit" / "bin" / "python"
    if env:  # an explicit choice is used alone
        candidates = [(env, "SOSALGO_PEPIT_PYTHON")]
    else:
        candidates = [(str(local), ".venv-pepit")] if local.exists() else []
        if importlib.util.find_spec("PEPit") is not None:
            candidates.append((sys.executable, "this interpreter, in a subprocess"))
    for python, origin in candidates:
        try:
            probe = subprocess.run([python, "-c", "import PEPit"], capture_output=True)
        except OSError:
            continue
        if probe.returncode == 0:
            return python, origin
    if env:
        return None, f"SOSALGO_PEPIT_PYTHON={env} cannot import PEPit"
    return None, ("PEPit not installed (make bench-pepit, or set SOSALGO_PEPIT_PYTHON to "
                  "a Python that has it)")


def run_child(python: str, code: str, job: list, timeout: float = CASE_SECONDS) -> dict:
    """One case in a fresh process: its JSON line, or {"error": ...}."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    try:
        out = subprocess.run([python, "-c", code, json.dumps(job)], capture_output=True,
                             text=True, timeout=timeout, cwd=ROOT, env=env)
    except subprocess.TimeoutExpired:
        return {"error": f"over {timeout:g} s"}
    lines = out.stdout.strip().splitlines()
    if out.returncode or not lines:
        tail = (out.stderr.strip().splitlines() or ["no output"])[-1]
        return {"error": tail[:80]}
    return json.loads(lines[-1])


def run(quick: bool = False) -> None:
    python, origin = pepit_python()
    if python is None:
        print(f"skipped: {origin}")
        return
    print(f"PEPit from {origin}; kappa = {KAPPA:g}; one thread each; same run, same machine\n")
    print("| method | N | sosalgo s (SDP + exact proof) | sosalgo MB | sosalgo solves | "
          "tau proven | PEPit SCS s | PEPit SCS MB | PEPit SCS tau (rel. to proven), "
          "status | PEPit Clarabel s | PEPit Clarabel MB | PEPit Clarabel tau (rel.), "
          "status | PEPit SCS s / sosalgo s | PEPit Clarabel s / sosalgo s |")
    print("|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    only = os.environ.get("SOSALGO_BENCH_METHODS")  # e.g. "gradient": those cases only
    steps = os.environ.get("SOSALGO_BENCH_STEPS")  # e.g. "50,70": those N only
    for spec, measure in CASES:
        if only and spec not in only.split(","):
            continue
        for N in ([int(n) for n in steps.split(",")] if steps
                  else QUICK_STEPS if quick else STEPS):
            ours = run_child(sys.executable, SOSALGO_CHILD,
                             [spec, KAPPA, N, measure, True, False])
            theirs = {s: run_child(python, WORKER, [spec, N, KAPPA, s]) for s in SOLVERS}
            print(row(spec, N, ours, theirs), flush=True)


def _rel(value: float | None, ref: float | None) -> str:
    if value is None or not ref:
        return "—"
    return f"{value:.6g} ({value / ref - 1:+.1e})"


def row(spec: str, N: int, ours: dict, theirs: dict) -> str:
    if "error" in ours:
        return f"| {spec} | {N} | {ours['error']} |"
    from bench.pep_scaling import solves_text

    ref = ours.get("tau_proven")
    cells = [spec, str(N), f"{ours['seconds']:.2f}", f"{ours['mb']:.0f}",
             solves_text(ours.get("solves") or {}), f"{ref:.9g}" if ref else "not proven"]
    for s in SOLVERS:
        t = theirs[s]
        if "error" in t:
            cells += [t["error"], "—", "—"]
            continue
        cells += [f"{t['seconds']:.2f}", f"{t['mb']:.0f}",
                  f"{_rel(t['tau'], ref)}, {t['status']}"]
    for s in SOLVERS:
        t = theirs[s]
        cells.append(f"{t['seconds'] / ours['seconds']:.2f}" if "seconds" in t else "—")
    return "| " + " | ".join(cells) + " |"


if __name__ == "__main__":
    run("--quick" in sys.argv)
