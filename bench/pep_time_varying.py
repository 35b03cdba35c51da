"""PEP of a method that changes with k against PEPit (``python -m bench --only
pep_time_varying``): OGM (``specs/ogm.yaml``, Kim and Fessler's theta_k with the last
step, L = 1, (f(x_N) - f*) / |x_0 - x*|^2), time against N, each case in a fresh process,
PEPit in its own interpreter as in :mod:`bench.pepit` (never a dependency of sosalgo).

sosalgo: ``sosalgo.pep`` with the exact proof of the certificate, without and with the
witness. PEPit: its own ``wc_optimized_gradient`` loop, ``PEP.solve(wrapper="cvxpy")``
with Clarabel and with its default solver; its time is the ``solve`` call. N grows while
the previous sosalgo case took at most :data:`BUDGET` seconds. Each value is printed
beside L/(2 theta_N^2), the closed form.
"""

from __future__ import annotations

import math
import sys

from bench.pep import SOSALGO_CHILD
from bench.pepit import SOLVE_AND_REPORT, pepit_python, run_child

STEPS, QUICK_STEPS = (5, 10, 20, 30, 40, 50, 60, 80, 100), (5, 10)
BUDGET = 600.0  # seconds: no larger N once a case took longer
SOLVERS = ("CLARABEL", "default")

WORKER = r'''
import json, math, sys, time, warnings
warnings.simplefilter("ignore")
from PEPit import PEP
from PEPit.functions import SmoothConvexFunction

N, solver = json.loads(sys.argv[1])
problem = PEP()
func = problem.declare_function(SmoothConvexFunction, L=1.0)
xs = func.stationary_point()
fs = func(xs)
x0 = problem.set_initial_point()
problem.set_initial_condition((x0 - xs) ** 2 <= 1)
theta_new, x_new, y = 1.0, x0, x0
for i in range(N):
    x_old = x_new
    x_new = y - func.gradient(y)
    theta_old = theta_new
    c = 4 if i < N - 1 else 8
    theta_new = (1 + math.sqrt(c * theta_new ** 2 + 1)) / 2
    y = x_new + (theta_old - 1) / theta_new * (x_new - x_old) + theta_old / theta_new * (x_new - y)
problem.set_performance_metric(func(y) - fs)
''' + SOLVE_AND_REPORT


def closed_form(N: int) -> float:
    """L/(2 theta_N^2), L = 1."""
    theta = 1.0
    for k in range(1, N + 1):
        theta = (1 + math.sqrt(1 + (8 if k == N else 4) * theta ** 2)) / 2
    return 1 / (2 * theta ** 2)


def _rel(value: float | None, ref: float) -> str:
    return "—" if value is None else f"{value:.9g} ({value / ref - 1:+.1e})"


def run(quick: bool = False) -> None:
    python, origin = pepit_python()
    print(f"OGM, L = 1; PEPit from {origin or 'nowhere'}; one thread each; same run\n")
    print("| N | L/(2 theta_N^2) | sosalgo s (SDP + exact proof) | MB | tau_proven (rel.) | "
          "+ witness s | witness verified | PEPit Clarabel s | tau (rel.) | PEPit default s "
          "| tau (rel.) |")
    print("|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|")
    for N in QUICK_STEPS if quick else STEPS:
        ref = closed_form(N)
        a = run_child(sys.executable, SOSALGO_CHILD, ["ogm", None, N, None, True, False],
                      timeout=2 * BUDGET)
        b = (run_child(sys.executable, SOSALGO_CHILD, ["ogm", None, N, None, True, True],
                       timeout=2 * BUDGET) if N <= 20 else {"error": "not run"})
        cells = [str(N), f"{ref:.9g}"]
        if "error" in a:
            cells += [a["error"], "—", "—"]
        else:
            cells += [f"{a['seconds']:.1f}", f"{a['mb']:.0f}", _rel(a["tau_proven"], ref)]
        cells += ([f"{b['seconds']:.1f}", str(b.get("witness"))] if "error" not in b
                  else [b["error"], "—"])
        for s in SOLVERS:
            t = (run_child(python, WORKER, [N, s], timeout=2 * BUDGET) if python
                 else {"error": "PEPit not installed"})
            cells += ([f"{t['seconds']:.1f}", f"{_rel(t['tau'], ref)}, {t['status']}"]
                      if "error" not in t else [t["error"], "—"])
        print("| " + " | ".join(cells) + " |", flush=True)
        if "error" in a or a["seconds"] > BUDGET:
            break


if __name__ == "__main__":
    run("--quick" in sys.argv)
