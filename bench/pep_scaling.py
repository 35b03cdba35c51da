"""PEP cost against the horizon (``python -m bench --only pep_scaling``): gradient descent
(dist/dist) and Nesterov (f/dist) at kappa = 10, N = 1..100 (``--quick``: a few N), each
N in a fresh process: seconds and peak resident memory of ``sosalgo.pep`` with the exact
proof and no witness, the Clarabel solves of the run by status (a spy on
``clarabel.DefaultSolver``), tau_N and how far the proven bound is above it. Then
Nesterov with the witness at N = 40..80 (``--quick``: 10, 20): what the bounded witness
search costs and what it finds (a geometry of the SDP's answer, or a quadratic)."""

from __future__ import annotations

import sys

from bench.pep import one

SCALING = (("gradient", "dist"), ("nesterov", None))
STEPS = (1, 2, 5, 10, 20, 30, 50, 70, 100)
QUICK_STEPS = (5, 10, 20)
WITNESS_STEPS = (40, 50, 60, 80)


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
    witness_table((10, 20) if quick else WITNESS_STEPS)


def witness_table(steps: tuple[int, ...]) -> None:
    """Nesterov (f/dist, kappa = 10) with the exact proof and the witness: seconds, peak
    memory, the witnessed lower bound against tau and how the search ended."""
    print("\nNesterov, kappa = 10, SDP + exact proof + witness\n")
    print("| N | seconds | peak MB | tau_N | witness tau_lower / tau_N | search |")
    print("|---:|---:|---:|---:|---:|---|")
    for N in steps:
        r = one("nesterov", 10, N, None, True, True)
        low = r["tau_lower"]
        ratio = f"{low / r['tau']:.3g}" if low is not None and r["tau"] else "none"
        how = ", ".join(f"{k} {v}" for k, v in r["search"].items())
        print(f"| {N} | {r['seconds']:.1f} | {r['mb']:.0f} | {r['tau']:.6g} | {ratio} | "
              f"{how} |", flush=True)


if __name__ == "__main__":
    run("--quick" in sys.argv)
