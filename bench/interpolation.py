"""Interpolation certificate family: time per certified rate (tol 1e-6) against a cvxpy
model of the same family rebuilt and solved (Clarabel) at every bisection step, both in
this process, pinned to one core, and the default (lag chosen by the analysis); then the
rates of both families on four methods, with lags 1, 0 and chosen.
"""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

import cvxpy as cp
import numpy as np

from bench.common import bisect_rate, one_core, timed
from sosalgo.analysis import analyze_algorithm
from sosalgo.certificates.interpolation import Interpolation, has_output_point, structure
from sosalgo.model import Algorithm, bind
from sosalgo.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"
TOL = 1e-6


def naive_feasible(alg: Algorithm, rho: float, lag: int) -> bool:
    """The family at rho written directly in cvxpy (normalized to F(m/L, 1)), from scratch."""
    st = structure(alg.A, alg.B * alg.L, alg.C, alg.E, alg.m / alg.L, 1.0, lag,
                   has_output_point(alg.C, alg.E))
    d, p = st.dec, st.pos
    P = cp.Variable((st.nz, st.nz), symmetric=True)
    pi = cp.Variable(st.npi)
    eta = cp.Variable(len(d.labels), nonneg=True)
    lam = cp.Variable(len(p.labels), nonneg=True)
    r = rho**2
    Z1, Z0, Zp = d.Z[lag + 1], d.Z[lag], p.Z[lag]
    D = Z1.T @ P @ Z1 - r * (Z0.T @ P @ Z0) + sum(eta[k] * M for k, M in enumerate(d.Mq))
    Df = d.F[lag + 1].T @ pi - r * (d.F[lag].T @ pi) + np.array(d.mq).T @ eta
    Pq = Zp.T @ P @ Zp - sum(lam[k] * M for k, M in enumerate(p.Mq))
    Pf = p.F[lag].T @ pi - st.norm - np.array(p.mq).T @ lam
    cons = [(D + D.T) / 2 << 0, Df <= 0, (Pq + Pq.T) / 2 >> 0, Pf >= 0]
    prob = cp.Problem(cp.Minimize(0), cons)
    try:
        prob.solve(solver=cp.CLARABEL)
    except cp.SolverError:
        return False
    return prob.status == cp.OPTIMAL


def naive_rate(alg: Algorithm, lag: int, tol: float = TOL) -> float | None:
    return bisect_rate(lambda rho: naive_feasible(alg, rho, lag), tol)


def proxy_solves(alg: Algorithm, fam: Interpolation) -> int:
    """How many of an analysis's solves were on the family's cheap proxy (an untimed run
    that counts the margin solves of a problem of the proxy's size)."""
    import sosalgo.analysis as an

    guess = fam.guess_problem(alg)
    size = None if guess is None else guess.nvar
    orig, count = an.solve_margin, 0

    def counting(problem, rho, **options):
        nonlocal count
        count += problem.nvar == size
        return orig(problem, rho, **options)

    an.solve_margin = counting
    try:
        analyze_algorithm(alg, tol=TOL, family=fam)
    finally:
        an.solve_margin = orig
    return count


def run(quick: bool = False) -> None:
    with one_core() as core:
        _speed(quick, core)
        _rates(quick)


def _speed(quick: bool, core: str) -> None:
    repeats, naive_repeats = (5, 1) if quick else (21, 3)
    print(f"interpolation family: median time per certified rate, tol {TOL:g}, {core}")
    print(f"(load average at start: {os.getloadavg()[0]:.1f}; min ms = fastest repeat)")
    print("solves: all conic solves of one rate (of them on the lag-0 proxy)")
    print("| spec | κ | lag | ρ (sosalgo) | ρ (cvxpy) | solves | sosalgo ms | min ms | "
          "cvxpy ms | speed-up |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    ours_all: dict[int, list[float]] = {1: [], 0: []}
    naive_all: dict[int, list[float]] = {1: [], 0: []}
    spec = load_spec(SPECS / "nesterov.yaml")
    for k in (10.0,) if quick else (2.0, 10.0, 100.0):
        alg = bind(spec, k)
        for lag in (1, 0):
            fam = Interpolation(lag)
            analyze_algorithm(alg, tol=TOL, family=fam)  # warm imports
            t_ours, res, t_min = timed(
                lambda a=alg, f=fam: analyze_algorithm(a, tol=TOL, family=f), repeats)
            t_naive, rho_naive, _ = timed(lambda a=alg, g=lag: naive_rate(a, g), naive_repeats)
            ours_all[lag].append(t_ours)
            naive_all[lag].append(t_naive)
            rn = "-" if rho_naive is None else f"{rho_naive:.6f}"
            proxy = proxy_solves(alg, fam)
            print(f"| nesterov | {k:g} | {lag} | {res.rho:.6f} | {rn} | {res.solves} ({proxy}) | "
                  f"{t_ours * 1e3:.1f} | {t_min * 1e3:.1f} | {t_naive * 1e3:.0f} | "
                  f"{t_naive / t_ours:.0f}x |", flush=True)
        _auto_row(alg, k, repeats, ours_all)
    print()
    for lag in (1, 0):
        o, n = statistics.median(ours_all[lag]), statistics.median(naive_all[lag])
        print(f"lag {lag}: median {o * 1e3:.1f} ms per rate vs cvxpy {n * 1e3:.0f} ms "
              f"({n / o:.0f}x faster)")
    print(f"lag chosen (default): median {statistics.median(ours_all[-1]) * 1e3:.1f} ms "
          "per rate")


def _auto_row(alg: Algorithm, k: float, repeats: int, ours_all: dict) -> None:
    """The default family (lag chosen by the analysis): its row of the speed table."""
    fam = Interpolation()
    analyze_algorithm(alg, tol=TOL, family=fam)
    t_ours, res, t_min = timed(lambda: analyze_algorithm(alg, tol=TOL, family=fam), repeats)
    ours_all.setdefault(-1, []).append(t_ours)
    print(f"| nesterov | {k:g} | chosen ({res.lag}) | {res.rho:.6f} | - | {res.solves} | "
          f"{t_ours * 1e3:.1f} | {t_min * 1e3:.1f} | - | - |", flush=True)


def _rates(quick: bool) -> None:
    kappas = (10.0,) if quick else (2.0, 10.0, 100.0, 1000.0)
    print()
    print(f"certified rates (tol {TOL:g}); '-' = not certified; ms per rate; "
          "chosen = the default (lag chosen by the analysis, ℓ in parentheses)")
    print("| method | κ | Theorem 1 | ms | interpolation lag 1 | ms | lag 0 | ms | chosen | ms | "
          "1 − 1/√κ | quadratic bound |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in ("gradient", "nesterov", "triple-momentum", "heavy-ball"):
        spec = load_spec(SPECS / f"{name}.yaml")
        for k in kappas:
            alg = bind(spec, k)
            cells = []
            for fam in ("theorem1", Interpolation(1), Interpolation(0), Interpolation()):
                t0 = time.perf_counter()
                res = analyze_algorithm(alg, tol=TOL, family=fam)
                ms = (time.perf_counter() - t0) * 1e3
                rho = "-" if res.rho is None else f"{res.rho:.6f}"
                chosen = fam != "theorem1" and fam.lag is None and res.lag is not None
                cells += [f"{rho} ({res.lag})" if chosen else rho, f"{ms:.0f}"]
            qs = np.linspace(alg.m, alg.L, 2001)
            quad = max(np.abs(np.linalg.eigvals(alg.A + q * alg.B @ alg.C)).max() for q in qs)
            print(f"| {name} | {k:g} | " + " | ".join(cells)
                  + f" | {1 - k ** -0.5:.6f} | {quad:.6f} |", flush=True)
