"""Operator rates against AutoLyap (GPL, never a dependency of sosalgo), point by point.

AutoLyap runs only in a subprocess (its interpreter found as in :mod:`bench.autolyap`).
Both tools get the same method at the same point, the same operator classes and one core:

- **Douglas-Rachford** as in AutoLyap's published example (``douglas_rachford_operator_
  giselsson``): ``v = J_{gamma G1}(x)``, ``w = J_{gamma G2}(2 v - x)``,
  ``x+ = x + lambda (w - v)``, ``G1`` maximally monotone, ``G2`` mu-strongly monotone and
  L-Lipschitz (AutoLyap: ``[StronglyMonotone(mu), LipschitzOperator(L)]``; sosalgo:
  ``lipschitz_strongly_monotone``, the same two pairwise conditions), measure
  ``|v_k - v*|^2`` (AutoLyap's ``get_parameters_distance_to_solution``, ours ``distance``
  at the output ``v``), h = 0, and AutoLyap's options of that example (``S_equals_T``,
  ``s_equals_t``, ``remove_C3``). Its closed form (Giselsson 2017, Thm. 6.5, tight) is
  ``rho^2 = (|1 - lambda/2| + lambda/2 delta)^2``, ``delta = sqrt(1 - 4 gamma mu /
  (1 + 2 gamma mu + gamma^2 L^2))``. The grid: AutoLyap's sweep (mu = 1, L = 2,
  lambda = 2, gamma in (0, 5]) and a grid in (mu, L, gamma, lambda) around it.
- **Chambolle-Pock** as in AutoLyap's published example (``chambolle_pock/
  smooth_strongly_convex``): the identity-operator case ``x+ = prox_{tau f1}(x - tau y)``,
  ``y+ = prox_{sigma f2*}(y + sigma (x+ + theta (x+ - x)))``, ``f1`` and ``f2`` both
  0.05-strongly convex and 50-smooth, tau = sigma, measure ``|x_k - x*|^2`` at f1's point
  (AutoLyap's ``get_parameters_distance_to_solution(i=1)``), h = 0, its default options;
  ours: ``bench/chambolle-pock-autolyap.yaml`` (AutoLyap's A, B, C, D; not
  ``specs/chambolle-pock.yaml``, which is the convex case with a linear operator M and a
  fixed-point-residual measure). The points: a spread of AutoLyap's published sweep (100
  values of tau = sigma on [0.5, 1.75], 100 of theta on [0, 8], rho from a bisection to
  1e-3 with MOSEK), its published rho stored beside each; ours must be proven at most its
  square root + ``TOL``.
- **Davis-Yin** (``specs/davis-yin.yaml``: ``A`` maximally monotone, ``B`` beta-cocoercive,
  ``C`` smooth strongly convex) passed to AutoLyap as a custom ``Algorithm`` with our
  A, B, C, D (components in our call order, ``C`` a function, ``A`` and ``B`` operators),
  distance at the first call's point, h = 0, its default options.

Our rate: :func:`sosalgo.analysis.analyze_algorithm` with the interpolation family at
``TOL`` on rho, then the exact proof (``Interpolation.exact_check``) of the certificate;
AutoLyap's: ``bisection_search_rho`` on rho^2 with its bracket closed to
:func:`bench.autolyap.rho2_tolerance` at a lower bound of the rate (so that its rho is
bracketed to ``TOL`` as ours). Times are medians of ``repeats`` runs after a warm-up.
"""

from __future__ import annotations

import math
import os
import statistics
import sys
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from bench.autolyap import autolyap_python, autolyap_rates, rho2_tolerance, timed_rate
from bench.common import one_core
from sosalgo.certificates.interpolation import Interpolation
from sosalgo.model import bind
from sosalgo.spec import load_spec
from sosalgo.spec.loading import spec_from_text
from sosalgo.spec.overrides import apply_overrides

TOL = 1e-6

# AutoLyap's example: G1 maximally monotone, G2 strongly monotone and Lipschitz, G2 second.
DR_GISELSSON = """
name: douglas-rachford-giselsson
description: Douglas-Rachford, G1 monotone, G2 mu-strongly monotone and L-Lipschitz
functions:
  G1: {class: monotone}
  G2: {class: lipschitz_strongly_monotone}
parameters:
  gamma: {value: 1, range: [0, 10]}
  lam: {value: 2, range: [0, 2]}
matrices:
  A: [[1]]
  B: [[-gamma*lam, -gamma*lam]]
  C: [[1], [1]]
  D: [[-gamma, 0], [-2*gamma, -gamma]]
oracles: [G1, G2]
output: y1
measure: distance
m: MU
kappa: [2]
"""

# AutoLyap's Chambolle-Pock example: f1, f2 in F_{0.05, 50}, tau = sigma = 1/2 + (5/4) i / 99,
# theta = 8 j / 99 (its sweep's grid, i, j = 0..99); (i, j, its published rho on
# |x_k - x*|^2) at a spread of the feasible points, from its docs' data
# (``docs/source/data/chambolle_pock_smooth_strongly_convex/tau_theta_rho.csv``, AutoLyap
# 0.2.1), the smallest published rho (87, 3) among them.
CP_SPEC = Path(__file__).resolve().parent / "chambolle-pock-autolyap.yaml"
CP_MU, CP_L = 0.05, 50.0
CP_PUBLISHED = ((87, 3, 0.880859375), (0, 0, 0.966796875), (33, 11, 0.9306640625),
                (66, 0, 0.9814453125), (0, 88, 0.9638671875), (11, 33, 0.9521484375),
                (22, 22, 0.94140625), (44, 0, 0.9482421875), (11, 55, 0.953125),
                (55, 11, 0.9111328125))
CP_QUICK = 4

# Runs in AutoLyap's interpreter: reads jobs (JSON) on stdin, writes results (JSON).
WORKER = r'''
import json, os, statistics, sys, time, warnings
import numpy as np
from importlib.metadata import version
from autolyap import IterationIndependent, SolverOptions
from autolyap.algorithms import ChambollePock, DouglasRachford
from autolyap.algorithms.algorithm import Algorithm
from autolyap.problemclass import (Cocoercive, InclusionProblem, LipschitzOperator,
                                   MaximallyMonotone, SmoothStronglyConvex, StronglyMonotone)

warnings.simplefilter("ignore")
LC = IterationIndependent.LinearConvergence
OPTS = SolverOptions(backend="cvxpy", cvxpy_solver="CLARABEL")

class Given(Algorithm):
    """Our A, B, C, D; one call per component, component i = our call i."""
    def __init__(self, A, B, C, D, funcs):
        self.mats = tuple(np.array(M, dtype=float) for M in (A, B, C, D))
        k = len(self.mats[3])
        ids = list(range(1, k + 1))
        super().__init__(len(A), k, [1] * k, [i for i in ids if i in funcs],
                         [i for i in ids if i not in funcs])

    def get_ABCD(self, k):
        return self.mats

def component(c):
    kind = c[0]
    if kind == "monotone":
        return MaximallyMonotone()
    if kind == "cocoercive":
        return Cocoercive(c[1])
    if kind == "lsm":
        return [StronglyMonotone(c[1]), LipschitzOperator(c[2])]
    return SmoothStronglyConvex(c[1], c[2])

def one_rate(job):
    prob = InclusionProblem([component(c) for c in job["classes"]])
    if job["method"] == "dr":
        algo = DouglasRachford(gamma=job["gamma"], lambda_value=job["lam"], type="operator")
        P, T = LC.get_parameters_distance_to_solution(algo)
        return LC.bisection_search_rho(prob, algo, P, T, S_equals_T=True, s_equals_t=True,
                                       remove_C3=True, tol=job["tol"], solver_options=OPTS,
                                       verbosity=0)
    if job["method"] == "cp":
        algo = ChambollePock(tau=job["tau"], sigma=job["sigma"], theta=job["theta"])
        P, p, T, t = LC.get_parameters_distance_to_solution(algo, i=1)
        return LC.bisection_search_rho(prob, algo, P, T, p=p, t=t, tol=job["tol"],
                                       solver_options=OPTS, verbosity=0)
    algo = Given(job["A"], job["B"], job["C"], job["D"], job["funcs"])
    P, p, T, t = LC.get_parameters_distance_to_solution(algo)
    return LC.bisection_search_rho(prob, algo, P, T, p, t, tol=job["tol"],
                                   solver_options=OPTS, verbosity=0)

def measure(job):
    if job["repeats"] == 0:
        res = one_rate(job)
        return {"status": res["status"], "rho2": res["rho"]}
    one_rate(job)  # warm-up
    times, cpus = [], []
    for _ in range(job["repeats"]):
        t0, c0 = time.perf_counter(), time.process_time()
        res = one_rate(job)
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return {"status": res["status"], "rho2": res["rho"], "median": statistics.median(times),
            "cpu": statistics.median(cpus)}

jobs = json.load(sys.stdin)
print(json.dumps({"version": version("autolyap"), "results": [measure(j) for j in jobs]}))
'''


def giselsson_rho(mu: float, L: float, gamma: float, lam: float) -> float:
    """sqrt of Giselsson (2017) Thm. 6.5's tight factor: the rate on |x_k - x*|."""
    a = lam / 2.0
    delta = math.sqrt(1.0 - 4.0 * gamma * mu / (1.0 + 2.0 * gamma * mu + (gamma * L) ** 2))
    return abs(1.0 - a) + a * delta


def dr_points(quick: bool) -> list[tuple[float, float, float, float]]:
    """(mu, L, gamma, lambda): AutoLyap's published sweep (mu = 1, L = 2, lambda = 2,
    gamma in (0, 5]) and a grid in all four around it."""
    sweep = [0.25, 0.5, 1.0, 2.0, 5.0] if quick else [0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0,
                                                       3.0, 4.0, 5.0]
    pts = [(1.0, 2.0, g, 2.0) for g in sweep]
    grid = ([(1.0, 5.0, 0.5, 1.0), (0.5, 2.0, 1.0, 1.5)] if quick else
            [(mu, L, g, lam) for mu, L in ((1.0, 2.0), (1.0, 5.0), (0.5, 4.0))
             for g in (0.5, 1.0, 2.0) for lam in (0.5, 1.0, 1.5)])
    return pts + grid


def dy_points(quick: bool) -> list[tuple[float, float, float, float]]:
    """(kappa, beta, alpha, theta) for specs/davis-yin.yaml (m = 1/10)."""
    pts = [(10.0, 1.0, 0.9, 1.3), (10.0, 1.0, 0.5, 1.0), (10.0, 1.0, 1.5, 0.8)]
    return pts if quick else pts + [(5.0, 2.0, 1.0, 1.0), (20.0, 0.5, 0.5, 1.5)]


def witness_rate(spec: Any, kappa: float, theta: dict) -> float:
    """A proven lower bound of the true rate at ``theta``: the slowest normal linear
    instance of the classes found (:mod:`sosalgo.design_search.witness`), its |T|^2
    enclosed in ball arithmetic at the point; 0 when none is proven."""
    from sosalgo.design_search.witness import WitnessBound

    free = list(theta)
    wb = WitnessBound(spec, kappa, free)
    z = [float((Fraction(theta[p]) - mid) / half) if half else 0.0
         for p, mid, half in zip(free, wb.method.box.mid, wb.method.box.half, strict=True)]
    val = wb.proven(z, [0.0] * len(z), wb.instance(z, None))
    return math.sqrt(val) if val > 0 else 0.0


def _ours(alg: Any, spec: Any, kappa: float, theta: dict, repeats: int) -> dict:
    """Our rate, its exact proof, and (median wall, median CPU) seconds of one rate."""
    fam = Interpolation()
    t, res, cpu = timed_rate(alg, fam, repeats)
    proof = fam.exact_check(spec, kappa, res.rho, res.certificate, theta)
    return {"rho": res.rho, "proven": str(proof.verified), "rho_proven": proof.rho_proven_float,
            "median": t, "cpu": cpu}


def _dr_cases(quick: bool, repeats: int) -> list[dict]:
    cases = []
    for mu, L, gamma, lam in dr_points(quick):
        spec = spec_from_text(DR_GISELSSON.replace("MU", repr(mu)), source="<dr>")
        theta = {"gamma": gamma, "lam": lam}
        ref = giselsson_rho(mu, L, gamma, lam)
        job = {"method": "dr", "gamma": gamma, "lam": lam, "repeats": repeats,
               "classes": [["monotone"], ["lsm", mu, L]], "tol": rho2_tolerance(ref, TOL)}
        cases.append({"label": f"μ={mu:g} L={L:g} γ={gamma:g} λ={lam:g}", "ref": ref,
                      "spec": spec, "kappa": L / mu, "theta": theta, "job": job,
                      "witness": witness_rate(spec, L / mu, theta)})
    return cases


def _dy_cases(quick: bool, repeats: int) -> list[dict]:
    path = os.path.join(os.path.dirname(__file__), "..", "specs", "davis-yin.yaml")
    cases = []
    for kappa, beta, alpha, theta_ in dy_points(quick):
        # the class parameter beta set in the spec (a class is fixed for a whole run)
        spec = spec_from_text(apply_overrides(Path(path).read_text(), {"beta": repr(beta)},
                                              path), path)
        m = float(spec.m)
        theta = {"alpha": alpha, "theta": theta_}
        alg = bind(spec, kappa, theta)
        # the scalar lower bound: A = 0, B = b I, C = c/2 |x|^2 at the box's vertices
        ref = max(abs(1 - theta_ * alpha * (b + c) / (1 + alpha * b))
                  for b in (0.0, 1.0 / beta) for c in (m, kappa * m))
        job = {"method": "given", "repeats": repeats, "A": alg.A.tolist(),
               "B": alg.B.tolist(), "C": alg.C.tolist(), "D": alg.D.tolist(), "funcs": [2],
               "classes": [["cocoercive", beta], ["ssc", m, kappa * m], ["monotone"]],
               "tol": rho2_tolerance(ref, TOL)}
        cases.append({"label": f"κ={kappa:g} β={beta:g} α={alpha:g} θ={theta_:g}",
                      "ref": ref, "spec": spec, "kappa": kappa, "theta": theta, "job": job,
                      "witness": witness_rate(spec, kappa, theta)})
    return cases


def cp_point(i: int, j: int) -> dict[str, Fraction]:
    """The parameters (tau, sigma, theta) of point (i, j) of AutoLyap's Chambolle-Pock sweep."""
    tau = Fraction(1, 2) + Fraction(5, 4) * i / 99
    return {"tau": tau, "sigma": tau, "theta": Fraction(8) * j / 99}


def cp_quadratic_rate(tau: float, sigma: float, theta: float, mu: float, L: float) -> float:
    """A lower bound of Chambolle-Pock's rate on |x_k - x*| over F_{mu, L} x F_{mu, L}: the
    largest spectral radius of the iteration on f1 = a/2 |x|^2, f2 = b/2 |x|^2 (a, b on a
    grid of [mu, L], its ends included), from AutoLyap's A, B, C, D, in floating point:
    the witness column of these rows and the floor that sizes AutoLyap's bisection."""
    A = np.array([[1.0, -tau], [0.0, 0.0]])
    B = np.array([[-tau, 0.0], [0.0, 1.0]])
    C = np.array([[1.0, -tau], [1.0, 1.0 / sigma - tau * (1.0 + theta)]])
    D = np.array([[-tau, 0.0], [-tau * (1.0 + theta), -1.0 / sigma]])
    worst = 0.0
    for a in np.linspace(mu, L, 9):
        for b in np.linspace(mu, L, 9):
            G = np.diag([a, b])
            T = A + B @ np.linalg.solve(np.eye(2) - G @ D, G @ C)
            worst = max(worst, float(max(abs(np.linalg.eigvals(T)))))
    return worst


def _cp_cases(quick: bool, repeats: int) -> list[dict]:
    spec = load_spec(CP_SPEC)
    kappa = CP_L / CP_MU
    cases = []
    for i, j, published in CP_PUBLISHED[:CP_QUICK] if quick else CP_PUBLISHED:
        theta = cp_point(i, j)
        tau, th = float(theta["tau"]), float(theta["theta"])
        floor = cp_quadratic_rate(tau, tau, th, CP_MU, CP_L)
        job = {"method": "cp", "tau": tau, "sigma": tau, "theta": th, "repeats": repeats,
               "classes": [["ssc", CP_MU, CP_L], ["ssc", CP_MU, CP_L]],
               "tol": rho2_tolerance(floor, TOL)}
        cases.append({"label": f"τ=σ={tau:.4f} θ={th:.4f}", "ref": math.sqrt(published),
                      "spec": spec, "kappa": kappa, "theta": theta, "job": job,
                      "witness": floor, "published": True})
    return cases


def _autolyap(python: str, jobs: list[dict]) -> dict:
    return autolyap_rates(python, jobs, WORKER, timeout=1800)


def run(quick: bool = False) -> None:
    python, origin = autolyap_python()
    if python is None:
        print(f"skipped: {origin}")
        return
    repeats = 3 if quick else 7
    with one_core() as core:
        try:
            _table(python, origin, repeats, core, quick)
        except RuntimeError as exc:
            print(f"skipped: {exc}")


def _table(python: str, origin: str, repeats: int, core: str, quick: bool) -> None:
    load = os.getloadavg()[0]
    ratios: dict[str, list[float]] = {}
    published: list[bool] = []
    header = True
    for name, cases in (("Douglas-Rachford", _dr_cases(quick, repeats)),
                        ("Davis-Yin", _dy_cases(quick, repeats)),
                        ("Chambolle-Pock", _cp_cases(quick, repeats))):
        for case in cases:  # case by case, so that both tools see the same load
            ours = _ours(bind(case["spec"], case["kappa"], case["theta"]), case["spec"],
                         case["kappa"], case["theta"], repeats)
            info = _autolyap(python, [case["job"]])
            if header:
                _print_header(info["version"], origin, core, repeats, load)
                header = False
            ratios.setdefault(name, []).append(_row(name, case, ours, info["results"][0]))
            if case.get("published"):
                published.append(ours["proven"] == "exact" and ours["rho_proven"] is not None
                                 and ours["rho_proven"] <= case["ref"] + TOL)
    print(f"\n(load average at the end: {os.getloadavg()[0]:.1f})")
    if published:
        print(f"Chambolle-Pock: {sum(published)} of {len(published)} points proven exactly at "
              f"most √(AutoLyap's published rho) + {TOL:g}")
    for name, rs in ratios.items():
        rs = [r for r in rs if math.isfinite(r)]
        print(f"{name}: AutoLyap / sosalgo per rate = {min(rs):.1f}–{max(rs):.1f}x "
              f"(median {statistics.median(rs):.1f}x)")


def _print_header(version: str, origin: str, core: str, repeats: int, load: float) -> None:
    print(f"AutoLyap {version} ({origin}) against sosalgo on operator rates, median time per "
          f"rate over {repeats} repeats, {core}; load average at start {load:.1f}")
    print("(ρ AutoLyap = √(its rho); reference: Douglas-Rachford Giselsson (2017) Thm. 6.5 "
          "(tight), Davis-Yin the rate on scalar operators (a lower bound), Chambolle-Pock "
          "√(AutoLyap's published rho) (an upper bound from its docs' sweep); ρ proven: the "
          "rational rate our certificate is proven for, exactly)")
    print("(witness: the rate of the slowest normal linear instance of the classes found, "
          "proven in ball arithmetic: no valid rate is below it; Chambolle-Pock: the largest "
          "spectral radius on f1 = a/2 |x|^2, f2 = b/2 |x|^2, a, b in [mu, L], in floating "
          "point)")
    print("| method | point | reference | witness | ρ sosalgo | proof | ρ proven | "
          "ρ AutoLyap | AutoLyap − proven | sosalgo ms | AutoLyap ms | ratio | CPU ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def _row(name: str, case: dict, ours: dict, res: dict) -> float:
    theirs = res["rho2"] ** 0.5 if res["status"] == "feasible" else None
    proven = ours["rho_proven"]
    diff = "-" if theirs is None or proven is None else f"{theirs - proven:+.1e}"
    witness = case["witness"]
    if theirs is not None and witness is not None and theirs < witness:
        diff += " (AutoLyap below the witness)"
    if case.get("published") and (proven is None or proven > case["ref"] + TOL):
        diff += " (sosalgo above the published rho)"
    ratio = res["median"] / ours["median"]
    cratio = res["cpu"] / ours["cpu"] if ours["cpu"] > 0 else math.nan
    print(f"| {name} | {case['label']} | {case['ref']:.7f} | "
          f"{'-' if witness is None else f'{witness:.7f}'} | "
          f"{ours['rho']:.7f} | "
          f"{ours['proven']} | {'-' if proven is None else f'{proven:.7f}'} | "
          f"{'-' if theirs is None else f'{theirs:.7f}'} | {diff} | "
          f"{ours['median'] * 1e3:.1f} | {res['median'] * 1e3:.0f} | {ratio:.1f}x | "
          f"{cratio:.1f}x |", flush=True)
    return ratio


if __name__ == "__main__":
    run(quick="--quick" in sys.argv)
