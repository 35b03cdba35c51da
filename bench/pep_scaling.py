"""PEP cost against the horizon (``python -m bench --only pep_scaling``): gradient descent
(dist/dist) and Nesterov (f/dist) at kappa = 10, N = 1..100 (``--quick``: a few N), each
N in a fresh process: seconds and peak resident memory of ``sosalgo.pep`` with the exact
proof and no witness, the Clarabel solves of the run by status (a spy on
``clarabel.DefaultSolver``), tau_N and how far the proven bound is above it."""

from __future__ import annotations

import sys

from bench.pep import one

SCALING = (("gradient", "dist"), ("nesterov", None))
STEPS = (1, 2, 5, 10, 20, 30, 50, 70, 100)
QUICK_STEPS = (5, 10, 20)


def solves_text(solves: dict) -> str:
    total = sum(solves.values())
    parts = [f"{n} {s}" for s, n in sorted(solves.items(), key=lambda kv: -kv[1])]
    return f"{total} ({', '.join(parts)})" if parts else "0"


def run(quick: bool = False) -> None:
    """Time, peak memory and solves against N (SDP with the exact proof, no witness)."""
    print("\nScaling, kappa = 10, SDP + exact proof, no witness\n")
    print("| method | N | seconds | peak MB | Clarabel solves (by status) | tau_N | "
          "tau_proven / tau_N - 1 |")
    print("|---|---:|---:|---:|---|---:|---:|")
    for spec, measure in SCALING:
        for N in QUICK_STEPS if quick else STEPS:
            r = one(spec, 10, N, measure, True, False)
            gap = (f"{r['tau_proven'] / r['tau'] - 1:.1e}" if r["tau_proven"] and r["tau"]
                   else "not proven")
            print(f"| {spec} | {N} | {r['seconds']:.2f} | {r['mb']:.0f} | "
                  f"{solves_text(r['solves'])} | {r['tau']:.6g} | {gap} |", flush=True)


if __name__ == "__main__":
    run("--quick" in sys.argv)
