"""Design (Section III, eq. 17): minimize rho over the parameters in a box Θ.

The nonconvex problem ``min rho^2 s.t. M(theta, rho, lambda, P) ⪯ 0, P ⪰ 0, lambda >= 0,
theta in Θ`` is written as a polynomial optimization problem and relaxed with the moment
hierarchy of :mod:`sosalgo.polyopt`. To make the feasible set compact without changing the
answer, the f - f* term of the Lyapunov function gets a coefficient c >= 0: M is then
homogeneous in (c, P, lambda) and the normalization ``c + tr P + lambda = 1`` (c eliminated)
keeps every Theorem 1 certificate (c = 1, rescaled), so the relaxation value is a valid
**lower bound** on the best rate Theorem 1 can certify over Θ. Only an analysis at
concrete parameters **certifies** a rate; the gap between the two is reported.

All matrices are written for the normalized class F(m/L, 1) with B scaled by L (a
congruence of Theorem 1, see :mod:`sosalgo.certificates.theorem1`).
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import sympy as sp

from sosalgo.analysis import AnalysisResult, analyze_spec
from sosalgo.certificates.theorem1 import theorem1_terms
from sosalgo.model import ModelError, bind, parameter_box
from sosalgo.polyopt import PolyProblem, solve_moment_relaxation
from sosalgo.spec import BASE_SYMBOLS, Spec

__all__ = ["DesignResult", "design", "design_problem", "relaxation_bound"]

CERT_TOL = 1e-7  # bisection tolerance of the certifying analyses


@dataclass
class DesignResult:
    """Lower bound, designed parameters, certified rate and how they were obtained."""

    spec: str
    kappa: float
    free: list[str]
    lower_bound: float | None
    theta: dict[str, float]
    rho_certified: float | None
    gap: float | None
    certificate: dict[str, Any]
    relaxation: dict[str, Any]
    seconds: float
    steps: list[str] = field(default_factory=list)
    gap_met: bool = False
    rho_at_values: float | None = None  # certified rate at the spec's own values

    def to_dict(self) -> dict[str, Any]:
        """JSON document of ``sosalgo design --json`` (a contract: extend, never rename)."""
        return {
            "spec": self.spec,
            "kappa": self.kappa,
            "free": list(self.free),
            "lower_bound": self.lower_bound,
            "theta": dict(self.theta),
            "rho_certified": self.rho_certified,
            "gap": self.gap,
            "certificate": self.certificate,
            "relaxation": self.relaxation,
            "seconds": self.seconds,
            "steps": list(self.steps),
            "gap_met": self.gap_met,
            "rho_at_values": self.rho_at_values,
        }


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
    negM = (-M).applyfunc(sp.expand)
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
class _Bound:
    rho: float | None  # sqrt of the rho^2 bound (None when the relaxation gave no bound)
    theta: dict[str, float] | None  # candidate parameters (minimizer or first moments)
    source: str
    info: dict[str, Any]


def relaxation_bound(
    spec: Spec, kappa: float, free: Sequence[str], box: Sequence[tuple[float, float]],
    order: int | None, scalarize: str, solver: str = "auto",
) -> _Bound:
    """Moment relaxation of the design problem over ``box``: lower bound and candidate."""
    prob, v = design_problem(spec, kappa, free, box, scalarize)
    k = order if order is not None else max(_min_order(prob), 3 if scalarize == "pmi" else 1)
    k = max(k, _min_order(prob))
    first, second = _solvers(solver, len(prob.variables))
    res = solve_moment_relaxation(prob, order=k, solver=first, solver_options=_OPTS[first])
    if res.status != "optimal" and second is not None and len(prob.variables) <= 5:
        res = solve_moment_relaxation(prob, order=k, solver=second, solver_options=_OPTS[second])
    info = {"scalarize": scalarize, "order": res.order, "status": res.status,
            "solver": res.solver,
            "ranks": list(res.ranks), "flat": bool(res.flat), "seconds": res.seconds}
    if res.status == "infeasible":
        return _Bound(1.0, None, "infeasible", info)  # no certificate anywhere in the box
    if res.status != "optimal" or not math.isfinite(res.bound):
        return _Bound(None, _first(res, v, free), "first moments", info)
    rho = math.sqrt(min(1.0, max(0.0, res.bound)))
    if res.minimizers:
        cands = [{p: float(mz[s]) for p, s in zip(free, v.theta, strict=True)}
                 for mz in res.minimizers]
        return _Bound(rho, cands[0], "extracted minimizer", {**info, "candidates": cands})
    return _Bound(rho, _first(res, v, free), "first moments", info)


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


def _clip(theta: dict[str, float], free, box) -> dict[str, float]:
    return {p: float(min(max(theta[p], lo), hi)) for p, (lo, hi) in zip(free, box, strict=True)}


def _certify(spec: Spec, kappa: float, theta: dict[str, float]) -> AnalysisResult | None:
    try:
        return analyze_spec(spec, kappa, theta, tol=CERT_TOL)
    except ModelError:
        return None


def _rate(res: AnalysisResult | None) -> float:
    return res.rho if (res is not None and res.certified and res.rho is not None) else math.inf


def design(
    spec: Spec,
    kappa: float,
    free: Sequence[str] | None = None,
    scalarize: str = "pmi",
    order: int | None = None,
    gap: float = 1e-4,
    time_limit: float = 120.0,
    max_order: int | None = None,
) -> DesignResult:
    """Design the free parameters at ``kappa`` (eq. 17): bound, extract, certify, refine.

    Steps: the moment relaxation over Θ gives a lower bound and a candidate θ (extracted
    minimizer when the moment matrix is flat, else first moments); an analysis at θ
    certifies a rate. If the gap exceeds ``gap``: polish θ locally (scipy on the certified
    rate within Θ), then raise the relaxation order once, then branch and bound over Θ
    (relaxation bounds per box, certified rates at box candidates, pruning) until the gap
    is met or ``time_limit`` seconds have passed. ``steps`` records what happened.
    """
    t0 = time.perf_counter()
    free = list(spec.ranged if free is None else free)
    if not free:
        raise ModelError("parameters", "nothing to design: no parameter has a range")
    spec.check_free(free)
    box = parameter_box(spec, kappa, free)
    bind(spec, kappa)  # the spec's own values must make sense here
    steps: list[str] = []
    values_res = _certify(spec, kappa, {})
    best_theta: dict[str, float] | None = None
    best: AnalysisResult | None = None

    def consider(theta: dict[str, float] | None, why: str) -> None:
        nonlocal best, best_theta
        if theta is None:
            return
        theta = _clip(theta, free, box)
        res = _certify(spec, kappa, theta)
        if _rate(res) < _rate(best):
            best, best_theta = res, theta
            steps.append(f"{why}: certified {res.rho:.8f}")

    root = relaxation_bound(spec, kappa, free, box, order, scalarize)
    relax_info = dict(root.info)
    lb = root.rho
    steps.append(
        f"relaxation order {root.info['order']} ({scalarize}): status {root.info['status']}, "
        f"flat {root.info['flat']}, bound {'-' if lb is None else f'{lb:.8f}'}"
    )
    for cand in root.info.get("candidates", [root.theta] if root.theta else []):
        consider(cand, f"theta from {root.source}")
    consider({p: values_res.params[p] for p in free} if values_res else None, "spec values")

    def gap_now() -> float:
        return math.inf if lb is None or best is None else _rate(best) - lb

    def out_of_time() -> bool:
        return time.perf_counter() - t0 > time_limit

    if gap_now() > gap and best_theta is not None:  # cheap: always allowed one polish
        polished = _polish(spec, kappa, free, box, best_theta, time.perf_counter() + 60.0)
        consider(polished, "polished locally")
    cur_order = root.info["order"]
    top = max_order if max_order is not None else cur_order + 1
    while gap_now() > gap and cur_order < top and not out_of_time():
        cur_order += 1
        nb = relaxation_bound(spec, kappa, free, box, cur_order, scalarize)
        steps.append(f"raised order to {cur_order}: status {nb.info['status']}, bound "
                     f"{'-' if nb.rho is None else f'{nb.rho:.8f}'}")
        if nb.rho is not None and (lb is None or nb.rho > lb):
            lb, relax_info = nb.rho, dict(nb.info)
        consider(nb.theta, f"theta from order {cur_order}")
    if gap_now() > gap and not out_of_time():
        lb = _branch_and_bound(spec, kappa, free, box, cur_order, scalarize, lb, consider,
                               lambda: _rate(best), gap, t0 + time_limit, steps)
    if lb is not None and best is not None and lb > _rate(best) + 1e-7:
        steps.append(f"relaxation bound {lb:.8f} exceeds a certified rate: discarded as "
                     "numerically invalid")
        lb = None
        relax_info["status"] = "inconsistent"
    rho_c = None if best is None else best.rho
    g = None if (lb is None or rho_c is None) else rho_c - lb
    cert = {} if best is None else {"P": best.P.tolist(), "lambda": best.lam,
                                    "max_eig_M": best.max_eig_M, "min_eig_P": best.min_eig_P}
    if out_of_time() and (g is None or g > gap):
        steps.append(f"time limit {time_limit:g} s reached")
    return DesignResult(
        spec=spec.name, kappa=float(kappa), free=free, lower_bound=lb,
        theta=dict(best_theta or {}), rho_certified=rho_c, gap=g, certificate=cert,
        relaxation=relax_info, seconds=time.perf_counter() - t0, steps=steps,
        gap_met=g is not None and g <= gap,
        rho_at_values=None if values_res is None else values_res.rho,
    )


def _polish(spec, kappa, free, box, theta, deadline) -> dict[str, float] | None:
    """Local minimization of the certified rate within Θ (scipy)."""
    from scipy.optimize import minimize, minimize_scalar

    def f(z: np.ndarray) -> float:
        if time.perf_counter() > deadline:
            return 2.0
        res = _certify(spec, kappa, _clip(dict(zip(free, map(float, z), strict=True)), free, box))
        r = _rate(res)
        return r if math.isfinite(r) else 2.0

    if len(free) == 1:
        lo, hi = box[0]
        width = max(hi - lo, 1e-12)
        out = minimize_scalar(lambda s: f(np.array([s])), bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-9 * width, "maxiter": 80})
        return {free[0]: float(out.x)}
    x0 = np.array([theta[p] for p in free])
    out = minimize(f, x0, method="Nelder-Mead", bounds=box,
                   options={"xatol": 1e-9, "fatol": 1e-10, "maxfev": 300})
    return dict(zip(free, map(float, out.x), strict=True))


def _branch_and_bound(spec, kappa, free, box, order, scalarize, lb, consider, best_rate,
                      gap, deadline, steps) -> float | None:
    """Split Θ into boxes: relaxation bounds per box, certified rates at box candidates,
    prune boxes whose bound exceeds the best certified rate. Returns the global bound."""
    heap: list[tuple[float, int, list[tuple[float, float]]]] = []
    counter = 0
    for half in _split(box):
        b = relaxation_bound(spec, kappa, free, half, order, scalarize)
        consider(b.theta, "theta from a sub-box")
        heapq.heappush(heap, (b.rho if b.rho is not None else -math.inf, counter, half))
        counter += 1
    boxes = 2
    while heap and time.perf_counter() < deadline:
        low, _, bx = heap[0]
        if best_rate() - low <= gap:
            break
        heapq.heappop(heap)
        if low > best_rate():  # pruned: nothing better inside
            continue
        for half in _split(bx):
            b = relaxation_bound(spec, kappa, free, half, order, scalarize)
            consider(b.theta, "theta from a sub-box")
            bound = b.rho if b.rho is not None else low
            heapq.heappush(heap, (max(bound, low), counter, half))
            counter += 1
            boxes += 1
    glob = min([h[0] for h in heap if h[0] <= best_rate()], default=best_rate())
    steps.append(f"branch and bound: {boxes} boxes, bound {glob:.8f}")
    if not math.isfinite(glob):
        return lb
    return max(glob, lb) if lb is not None else glob


def _split(box: Sequence[tuple[float, float]]) -> list[list[tuple[float, float]]]:
    widths = [hi - lo for lo, hi in box]
    i = int(np.argmax(widths))
    lo, hi = box[i]
    mid = 0.5 * (lo + hi)
    left, right = list(box), list(box)
    left[i], right[i] = (lo, mid), (mid, hi)
    return [left, right]
