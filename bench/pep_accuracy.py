"""How far each proven PEP bound is above the worst case (``python -m bench --only
pep_accuracy``): OGM (``specs/ogm.yaml``) against L/(2 theta_N^2), gradient descent
h = 1/L on F(1, 10) (dist/dist) against 0.9^(2N), gradient descent on L-smooth convex f
against L/(4N + 2), and Nesterov's method (f/dist, kappa = 10, no closed form) against
its float tau; each case in a fresh process (:data:`bench.pep.SOSALGO_CHILD`), the exact
proof, no witness. Columns: tau_N, tau_proven relative to the closed form (or to tau),
seconds of the whole call."""

from __future__ import annotations

import sys
from fractions import Fraction

from bench.pep import one
from bench.pep_time_varying import closed_form

# (spec, measure, kappa, steps, closed form of N or None)
CASES = (("ogm", None, None, (1, 2, 5, 10, 15, 20, 30, 50), closed_form),
         ("gradient", "dist", 10, (10, 20, 30, 40, 50), lambda N: 0.81 ** N),
         ("gradient-convex", None, None, (5, 10, 20, 40), lambda N: 1 / (4 * N + 2)),
         ("nesterov", None, 10, (10, 20, 30, 40, 50), None))
QUICK = {"ogm": (5, 20), "gradient": (40,), "gradient-convex": (20,), "nesterov": (20,)}


def run(quick: bool = False) -> None:
    print("| method | N | tau_N | reference | tau_proven / reference - 1 | seconds |")
    print("|---|---:|---:|---|---:|---:|")
    for spec, measure, kappa, steps, closed in CASES:
        for N in QUICK[spec] if quick else steps:
            r = one(spec, kappa, N, measure, True, False)
            ref = closed(N) if closed else r["tau"]
            what = "closed form" if closed else "float tau"
            rel = ("not proven" if r["tau_proven"] is None
                   else f"{float(Fraction(r['tau_proven'])) / ref - 1:.1e}")
            print(f"| {spec} | {N} | {r['tau']:.9g} | {what} | {rel} | {r['seconds']:.1f} |",
                  flush=True)


if __name__ == "__main__":
    run("--quick" in sys.argv)
