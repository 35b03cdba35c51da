"""PEP timings: N = 10 and N = 50 steps of Nesterov's method (two states) at kappa = 10,
the SDP alone and with the exact certificate (``python -m bench --only pep``)."""

from __future__ import annotations

import time

from sosalgo.pep import pep


def run(quick: bool = False) -> None:
    print("| method | N | tau_N | SDP only (s) | SDP + exact certificate (s) |")
    print("|---|---:|---:|---:|---:|")
    pep("specs/gradient.yaml", 10, 1, witness=False)  # imports (sympy, Clarabel) warm
    for N in (10,) if quick else (10, 50):
        t0 = time.perf_counter()
        r = pep("specs/nesterov.yaml", 10, N, exact=False, witness=False)
        t1 = time.perf_counter()
        pep("specs/nesterov.yaml", 10, N, witness=False)
        t2 = time.perf_counter()
        print(f"| nesterov, kappa 10 | {N} | {r.tau:.6g} | {t1 - t0:.2f} | {t2 - t1:.2f} |")
