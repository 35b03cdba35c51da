"""PEP timings and memory (``python -m bench --only pep``), each case in a fresh process so
that its peak resident memory is its own.

N = 10, 20, 50 steps of Nesterov's method (two states, f/dist) and gradient descent
(dist/dist) at kappa = 10, gradient descent on L-smooth convex f (m = 0, f/dist) and
accelerated proximal gradient (output at the prox point) at N = 10, 20: the SDP alone,
with the exact certificate, and with the witness.
The scaling against N (1..100) and the solves of each run: :mod:`bench.pep_scaling`.
"""

from __future__ import annotations

import json
import subprocess
import sys

# (spec, measure, kappa, steps)
CASES = (("nesterov", None, 10, (10, 20, 50)), ("gradient", "dist", 10, (10, 20, 50)),
         ("gradient-convex", None, None, (10, 20)),
         ("accelerated-proximal-gradient", None, 10, (10, 20)))

# One case: spec, kappa, N, measure, exact, witness -> one JSON line (time, peak MB,
# the proven bound, the Clarabel solves by status).
SOSALGO_CHILD = """
import collections, json, sys, time
import clarabel
solves = collections.Counter()
Solver = clarabel.DefaultSolver
class Spy:
    def __init__(self, *args):
        self.inner = Solver(*args)
    def solve(self):
        sol = self.inner.solve()
        solves[str(sol.status)] += 1
        return sol
clarabel.DefaultSolver = Spy
from sosalgo.worstcase import pep
spec, kappa, N, measure, exact, witness = json.loads(sys.argv[1])
t0 = time.perf_counter()
r = pep(f"specs/{spec}.yaml", kappa, N, measure, exact=exact, witness=witness)
cert = r.certificate or {}
proof = cert.get("proof") or {}
chk = (r.witness or {}).get("check") or {}
hwm = [int(x.split()[1]) for x in open('/proc/self/status') if x.startswith('VmHWM:')][0]
print(json.dumps({"tau": r.tau, "seconds": time.perf_counter() - t0,
                  "proven": cert.get("check_kind", "").startswith("exact"),
                  "tau_proven": proof.get("tau_proven_float") if proof.get("proven") else None,
                  "witness": chk.get("verified"), "solves": dict(solves),
                  "tau_lower": chk.get("tau_lower_float"),
                  "search": (r.witness or {}).get("search") or {},
                  "mb": hwm / 1024}))
"""


def one(spec: str, kappa: float | None, N: int, measure: str | None, exact: bool,
        witness: bool) -> dict:
    out = subprocess.run([sys.executable, "-c", SOSALGO_CHILD,
                          json.dumps([spec, kappa, N, measure, exact, witness])],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> None:
    print("| method | N | tau_N | SDP only (s) | peak MB | + exact certificate (s) | "
          "+ witness (s) | witness verified |")
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    for spec, measure, kappa, steps in CASES:
        for N in (10,) if quick else steps:
            a = one(spec, kappa, N, measure, False, False)
            b = one(spec, kappa, N, measure, True, False)
            c = one(spec, kappa, N, measure, True, True) if N <= 20 else None
            wt = f"{c['seconds']:.2f}" if c else "—"
            wv = str(c["witness"]) if c else "not run"
            proven = "proven" if b["proven"] else "not proven"
            where = "m = 0" if kappa is None else f"kappa {kappa:g}"
            print(f"| {spec}, {where} | {N} | {a['tau']:.6g} | {a['seconds']:.2f} | "
                  f"{a['mb']:.0f} | {b['seconds']:.2f} ({proven}) | {wt} | {wv} |",
                  flush=True)


if __name__ == "__main__":
    run("--quick" in sys.argv)
