"""The paper's design by moment relaxation (Section III, eq. 17), kept as ``--method moment``.

``min rho^2 s.t. M(theta, rho, lambda, P) ⪯ 0, P ⪰ 0, lambda >= 0, theta in Θ`` is written
as a polynomial optimization problem and relaxed with the moment hierarchy of
:mod:`sosalgo.polyopt`. The f - f* term of the Lyapunov function gets a coefficient c >= 0
so that ``c + tr P + lambda = 1`` makes the feasible set compact. That keeps every Theorem 1
certificate, so the value is a valid lower bound, but it also admits degenerate points
with c = 0 and singular P (no certificate of anything) that can sit far below the design
optimum: the bound is valid, and can be loose. :mod:`sosalgo.design_search.dualbound` has
no such face.

All matrices are written for the normalized class F(m/L, 1) with B scaled by L.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import sympy as sp

from sosalgo.certificates.theorem1 import theorem1_terms
from sosalgo.kernel.solvers import c_stdout_to_stderr
from sosalgo.polyopt import PolyProblem, RelaxationStatus, solve_moment_relaxation
from sosalgo.spec import BASE_SYMBOLS, Spec

__all__ = ["design_problem", "relaxation_bound", "relaxation_size", "MomentBound"]

@dataclass(frozen=True)
class _Vars:
    r2: sp.Symbol
    theta: list[sp.Symbol]
    lam: sp.Symbol
    P: sp.Matrix
    p_syms: list[sp.Symbol]


def design_problem(
    spec: Spec,
    kappa: float,
    free: Sequence[str],
    box: Sequence[tuple[float, float]],
    scalarize: str = "pmi",
) -> tuple[PolyProblem, _Vars]:
    """The polynomial problem (eq. 17, homogenized and normalized) over the box."""
    if scalarize not in ("pmi", "minors"):
        raise ValueError("scalarize must be 'pmi' or 'minors'")
    m, L = spec.mL(kappa)
    mats = spec.templates(free)
    base = {BASE_SYMBOLS["m"]: sp.Float(m, 30), BASE_SYMBOLS["L"]: sp.Float(L, 30),
            BASE_SYMBOLS["kappa"]: sp.Float(kappa, 30)}
    theta_syms = [spec.symbols[p] for p in free]
    A, B, C, E = (mats[k].xreplace(base).evalf(30) for k in ("A", "B", "C", "E"))
    B = B * sp.Float(L, 30)
    n = A.shape[0]
    r2, lam = sp.symbols("rho2 lambda_", real=True)
    P = sp.zeros(n, n)
    p_syms = []
    for i in range(n):
        for j in range(i, n):
            s = sp.Symbol(f"p{i + 1}{j + 1}", real=True)
            P[i, j] = P[j, i] = s
            p_syms.append(s)
    c = 1 - P.trace() - lam  # normalization c + tr P + lambda = 1
    t = theorem1_terms(A, B, C, E, sp.Float(m / L, 30), sp.Integer(1), P, symbolic=True)
    const = t["N1"] + t["N3"] + r2 * (t["N2"] - t["N3"])
    M = (c * const + t["M0P"] - r2 * t["PP"] + lam * t["N4"]).applyfunc(sp.expand)
    # M is symmetric in exact arithmetic; float coefficients can differ in the last digit
    # between M[i, j] and M[j, i], so symmetrize explicitly.
    negM = (-(M + M.T) / 2).applyfunc(sp.expand)
    variables = [r2, *theta_syms, lam, *p_syms]
    bounds: dict[sp.Symbol, tuple[float, float]] = {r2: (0.0, 1.0), lam: (0.0, 1.0)}
    for s, (lo, hi) in zip(theta_syms, box, strict=True):
        bounds[s] = (float(lo), float(hi))
    for i in range(n):
        for j in range(i, n):
            bounds[P[i, j]] = (0.0, 1.0) if i == j else (-0.5, 0.5)
    ineqs: list[sp.Expr] = [sp.expand(c), lam]
    mats_psd: list[sp.Matrix] = []
    if scalarize == "pmi":
        mats_psd = [negM, P] if n > 1 else [negM]
        if n == 1:
            ineqs.append(P[0, 0])
    else:
        ineqs += _principal_minors(negM) + _principal_minors(P)
    prob = PolyProblem(variables=variables, objective=r2, inequalities=ineqs,
                       matrix_inequalities=mats_psd, bounds=bounds)
    return prob, _Vars(r2, theta_syms, lam, P, p_syms)


def _principal_minors(M: sp.Matrix) -> list[sp.Expr]:
    """All principal minors (Sylvester's criterion for semidefiniteness)."""
    from itertools import combinations

    n = M.shape[0]
    out = []
    for k in range(1, n + 1):
        for idx in combinations(range(n), k):
            out.append(sp.expand(M.extract(list(idx), list(idx)).det(method="berkowitz")))
    return out


def _min_order(prob: PolyProblem) -> int:
    degs = [sp.Poly(g, *prob.variables).total_degree() for g in prob.inequalities]
    for G in prob.matrix_inequalities:
        degs += [sp.Poly(e, *prob.variables).total_degree() for e in G if e != 0]
    return max(1, math.ceil(max(degs) / 2))


@dataclass
class MomentBound:
    rho: float | None  # sqrt of the rho^2 bound (None when the relaxation gave no bound)
    theta: dict[str, float] | None  # candidate parameters (minimizer or first moments)
    source: str
    info: dict[str, Any]


def relaxation_size(nvars: int, order: int) -> tuple[int, int]:
    """(number of moments, side of the moment matrix) of an order-``order`` relaxation."""
    return math.comb(nvars + 2 * order, 2 * order), math.comb(nvars + order, order)


MAX_MOMENTS = 20_000  # above this the relaxation is skipped (memory: dense KKT blocks)


def _seconds_estimate(solver: str, side: int) -> float:
    """Rough solve time on 2 cores (measured: Clarabel side 35 ~1 s, SCS side 84 ~0.5 s,
    side 210 ~20 s); conservative, used only to refuse hopeless solves."""
    if solver == "clarabel":
        return (side / 35.0) ** 6
    return 0.5 * (side / 84.0) ** 4


def relaxation_bound(
    spec: Spec, kappa: float, free: Sequence[str], box: Sequence[tuple[float, float]],
    order: int | None, scalarize: str, solver: str = "auto", seconds: float = math.inf,
) -> MomentBound:
    """Moment relaxation of the design problem over ``box``: lower bound and candidate.

    The relaxation is skipped (status "skipped") when its size exceeds ``MAX_MOMENTS`` or
    its estimated time exceeds ``seconds``; otherwise the solver gets ``seconds`` as its
    own time limit.
    """
    prob, v = design_problem(spec, kappa, free, box, scalarize)
    k = order if order is not None else max(_min_order(prob), 3 if scalarize == "pmi" else 1)
    k = max(k, _min_order(prob))
    first, second = _solvers(solver, len(prob.variables))
    moments, side = relaxation_size(len(prob.variables), k)
    base = {"scalarize": scalarize, "order": k, "solver": first, "ranks": [], "flat": False,
            "seconds": 0.0, "moments": moments, "side": side}
    est = _seconds_estimate(first, side)
    if moments > MAX_MOMENTS or est > seconds:
        why = (f"{moments} moments > {MAX_MOMENTS}" if moments > MAX_MOMENTS else
               f"estimated {est:.0f} s > {seconds:.0f} s left")
        return MomentBound(None, None, "skipped",
                           {**base, "status": RelaxationStatus.SKIPPED, "why": why})
    with c_stdout_to_stderr():
        res = solve_moment_relaxation(prob, order=k, solver=first,
                                      solver_options=_options(first, seconds))
    if (res.status != RelaxationStatus.OPTIMAL and second is not None and len(prob.variables) <= 5
            and _seconds_estimate(second, side) < seconds - res.seconds):
        with c_stdout_to_stderr():
            res = solve_moment_relaxation(prob, order=k, solver=second,
                                          solver_options=_options(second, seconds - res.seconds))
    info = {**base, "order": res.order, "status": res.status, "solver": res.solver,
            "ranks": list(res.ranks), "flat": bool(res.flat), "seconds": res.seconds}
    if res.status == RelaxationStatus.INFEASIBLE:
        return MomentBound(1.0, None, "infeasible", info)  # no certificate in the box
    if res.status != RelaxationStatus.OPTIMAL or not math.isfinite(res.bound):
        return MomentBound(None, _first(res, v, free), "first moments", info)
    rho = math.sqrt(min(1.0, max(0.0, res.bound)))
    if res.minimizers:
        cands = [{p: float(mz[s]) for p, s in zip(free, v.theta, strict=True)}
                 for mz in res.minimizers]
        return MomentBound(rho, cands[0], "extracted minimizer", {**info, "candidates": cands})
    return MomentBound(rho, _first(res, v, free), "first moments", info)


def _options(solver: str, seconds: float) -> dict[str, Any] | None:
    opts = dict(_OPTS[solver] or {})
    if math.isfinite(seconds):
        key = "time_limit" if solver == "clarabel" else "time_limit_secs"
        opts[key] = max(1.0, float(seconds))
    return opts or None


_OPTS: dict[str, dict[str, Any] | None] = {"clarabel": None, "scs": {"max_iters": 20000}}


def _solvers(choice: str, nvars: int) -> tuple[str, str | None]:
    """Clarabel is accurate and fast up to 4 variables; SCS scales far better beyond
    (6 variables at order 3: 0.4 s vs 27 s). "auto" picks by size; the other one is the
    second opinion when the first does not report optimal (only up to 5 variables:
    beyond, Clarabel takes minutes)."""
    if choice == "auto":
        choice = "clarabel" if nvars <= 4 else "scs"
    if choice not in _OPTS:
        raise ValueError(f"unknown relaxation solver {choice!r}")
    return choice, ("scs" if choice == "clarabel" else "clarabel")


def _first(res, v: _Vars, free: Sequence[str]) -> dict[str, float] | None:
    try:
        return {p: float(res.first_moments[s]) for p, s in zip(free, v.theta, strict=True)}
    except (KeyError, TypeError, ValueError):
        return None


