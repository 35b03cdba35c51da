"""PEP timings and memory: N = 10, 20, 50 steps of Nesterov's method (two states, f/dist)
and gradient descent (dist/dist) at kappa = 10; the SDP alone, with the exact
certificate, and with the witness (``python -m bench --only pep``). Each case runs in a
fresh process so that its peak resident memory is its own."""

from __future__ import annotations

import json
import subprocess
import sys

CASES = (("nesterov", None), ("gradient", "dist"))

CHILD = """
import json, resource, sys, time
from sosalgo.pep import pep
spec, N, measure, exact, witness = json.loads(sys.argv[1])
t0 = time.perf_counter()
r = pep(f"specs/{spec}.yaml", 10, N, measure, exact=exact, witness=witness)
cert = r.certificate or {}
chk = (r.witness or {}).get("check") or {}
print(json.dumps({"tau": r.tau, "seconds": time.perf_counter() - t0,
                  "proven": cert.get("check_kind", "").startswith("exact"),
                  "witness": chk.get("verified"),
                  "mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def one(spec: str, N: int, measure: str | None, exact: bool, witness: bool) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD,
                          json.dumps([spec, N, measure, exact, witness])],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> None:
    print("| method | N | tau_N | SDP only (s) | peak MB | + exact certificate (s) | "
          "+ witness (s) | witness verified |")
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    for spec, measure in CASES:
        for N in (10,) if quick else (10, 20, 50):
            a = one(spec, N, measure, False, False)
            b = one(spec, N, measure, True, False)
            c = one(spec, N, measure, True, True) if N <= 20 else None
            wt = f"{c['seconds']:.2f}" if c else "—"
            wv = str(c["witness"]) if c else "not run"
            proven = "proven" if b["proven"] else "not proven"
            print(f"| {spec}, kappa 10 | {N} | {a['tau']:.6g} | {a['seconds']:.2f} | "
                  f"{a['mb']:.0f} | {b['seconds']:.2f} ({proven}) | {wt} | {wv} |",
                  flush=True)


if __name__ == "__main__":
    run("--quick" in sys.argv)
