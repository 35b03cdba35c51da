"""Time per certified rate (tol 1e-6): sosalgo's analysis vs a naive cvxpy baseline that
rebuilds the problem at every bisection step. Both run in this process, pinned to one core.
"""

from __future__ import annotations

import statistics
from pathlib import Path

import cvxpy as cp
import numpy as np

from bench.common import bisect_rate, one_core, timed
from sosalgo.analysis import analyze_spec
from sosalgo.model import Algorithm, bind
from sosalgo.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"
KAPPAS = (2.0, 10.0, 100.0)
TOL = 1e-6


def naive_feasible(alg: Algorithm, rho: float) -> bool:
    """Theorem 1 at rho written directly in cvxpy, compiled and solved from scratch."""
    A, B, C, E, m, L = alg.A, alg.B, alg.C, alg.E, alg.m, alg.L
    n = A.shape[0]
    P = cp.Variable((n, n), symmetric=True)
    lam = cp.Variable(nonneg=True)
    M0 = cp.bmat([[A.T @ P @ A - rho**2 * P, A.T @ P @ B], [B.T @ P @ A, B.T @ P @ B]])
    z, one = np.zeros((1, n)), np.ones((1, 1))
    X1 = np.block([[E @ A - C, E @ B], [z, one]])
    X2 = np.block([[C - E, 0 * one], [z, one]])
    X3 = np.block([[C, 0 * one], [z, one]])
    N1 = X1.T @ np.array([[L / 2, 0.5], [0.5, 0]]) @ X1
    N2 = X2.T @ np.array([[-m / 2, 0.5], [0.5, 0]]) @ X2
    N3 = X3.T @ np.array([[-m / 2, 0.5], [0.5, 0]]) @ X3
    N4 = X3.T @ np.array([[-m * L / (m + L), 0.5], [0.5, -1 / (m + L)]]) @ X3
    M = M0 + rho**2 * (N1 + N2) + (1 - rho**2) * (N1 + N3) + lam * N4
    prob = cp.Problem(cp.Minimize(0), [(M + M.T) / 2 << 0, P >> 0])
    try:
        prob.solve(solver=cp.CLARABEL)
    except cp.SolverError:
        return False
    return prob.status == cp.OPTIMAL


def naive_rate(alg: Algorithm, tol: float = TOL) -> float | None:
    return bisect_rate(lambda rho: naive_feasible(alg, rho), tol)


def run(quick: bool = False) -> None:
    with one_core() as core:
        _run(quick, core)


def _run(quick: bool, core: str) -> None:
    repeats, naive_repeats = (5, 1) if quick else (21, 3)
    print(f"analysis: median time per certified rate, tol {TOL:g}, {core}")
    print("| spec | kappa | rho (sosalgo) | rho (naive) | sosalgo ms | naive ms | speed-up |")
    print("|---|---|---|---|---|---|---|")
    summary = {}
    for name in ("gradient", "nesterov"):
        spec = load_spec(SPECS / f"{name}.yaml")
        ours_all, naive_all = [], []
        for k in KAPPAS:
            analyze_spec(spec, k, tol=TOL)  # warm caches (compiled templates)
            t_ours, res, _ = timed(lambda s=spec, k=k: analyze_spec(s, k, tol=TOL), repeats)
            alg = bind(spec, k)
            t_naive, rho_naive, _ = timed(lambda a=alg: naive_rate(a), naive_repeats)
            ours_all.append(t_ours)
            naive_all.append(t_naive)
            rn = "-" if rho_naive is None else f"{rho_naive:.6f}"
            print(f"| {name} | {k:g} | {res.rho:.6f} | {rn} | {t_ours * 1e3:.2f} | "
                  f"{t_naive * 1e3:.1f} | {t_naive / t_ours:.0f}x |", flush=True)
        summary[name] = (statistics.median(ours_all), statistics.median(naive_all))
    print()
    for name, (o, n) in summary.items():
        print(f"{name}: median {o * 1e3:.2f} ms per rate vs naive {n * 1e3:.1f} ms "
              f"({n / o:.0f}x faster)")
