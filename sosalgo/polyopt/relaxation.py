"""Lasserre's moment relaxation of a polynomial optimization problem, solved with cvxpy.

Order-k relaxation (Lasserre 2001, "Global optimization with polynomials and the problem
of moments"; Henrion-Lasserre 2006 for matrix inequalities)::

    min_y  L_y(f)
    s.t.   y_0 = 1,  M_k(y) ⪰ 0,
           M_{k - ceil(deg g_i / 2)}(g_i y) ⪰ 0           for every g_i(x) >= 0,
           M_{k - ceil(deg G / 2)}(G y) ⪰ 0               for every G(x) ⪰ 0,
           L_y(h_j x^alpha) = 0, |alpha| <= 2k - deg h_j   for every h_j(x) = 0.

Its value is a lower bound on the POP's minimum; flatness of the optimal moment matrix
certifies exactness and yields the minimizers (:mod:`sosalgo.polyopt.extraction`).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np
import sympy as sp

from .extraction import extract_atoms, flat_orders, numerical_rank
from .moment import MomentIndex
from .polynomial import abs_evaluate, evaluate
from .problem import CompiledProblem, PolyProblem, compile_problem, constraint_violation

__all__ = ["RelaxationResult", "solve_moment_relaxation", "DEFAULT_SOLVER_OPTIONS"]

#: Solver settings used unless overridden by ``solver_options``. Clarabel's default
#: regularization fails with NumericalError on many moment relaxations; 1e-7 fixes it.
DEFAULT_SOLVER_OPTIONS: dict[str, dict[str, Any]] = {
    "CLARABEL": {"static_regularization_constant": 1e-7},
    "SCS": {"eps_abs": 1e-8, "eps_rel": 1e-8, "max_iters": 100_000},
}

_STATUS = {
    cp.OPTIMAL: "optimal",
    cp.OPTIMAL_INACCURATE: "inaccurate",
    cp.INFEASIBLE: "infeasible",
    cp.INFEASIBLE_INACCURATE: "infeasible",
}


@dataclass
class RelaxationResult:
    """Outcome of :func:`solve_moment_relaxation`.

    Attributes:
        bound: lower bound on the POP's minimum, up to the solver's accuracy (``nan``
            unless status is "optimal" or "inaccurate"; treat "inaccurate" bounds with care).
        status: "optimal", "inaccurate", "infeasible" (the relaxation, hence the POP, is
            infeasible) or "failed" (solver error, unbounded relaxation, iteration limit).
        order: relaxation order k.
        ranks: numerical ranks of ``M_1(y), ..., M_k(y)``.
        flat: flat extension detected (``rank M_s == rank M_{s-d}`` for some s, with
            ``d = max(1, ceil(deg/2))`` over the constraints): the bound is the global
            minimum (meaningful only when status is "optimal").
        minimizers: extracted global minimizers (original coordinates) when flat; only
            points passing the feasibility/objective checks are listed, so it may be
            empty even when ``flat`` is True (numerical extraction failure).
        first_moments: ``y_{e_i}`` in original coordinates (the mean of the optimal
            measure; equals the minimizer when it is unique and the relaxation is exact).
        seconds: wall time of build, solve and extraction.
        solver: solver name as given to cvxpy.
        solver_status: raw cvxpy status, or the exception text if the solver raised.
        flat_order: the order s at which flatness was detected (None if not flat).
    """

    bound: float
    status: str
    order: int
    ranks: list[int] = field(default_factory=list)
    flat: bool = False
    minimizers: list[dict[sp.Symbol, float]] = field(default_factory=list)
    first_moments: dict[sp.Symbol, float] = field(default_factory=dict)
    seconds: float = 0.0
    solver: str = ""
    solver_status: str = ""
    flat_order: int | None = None


def _build(compiled: CompiledProblem, order: int) -> tuple[MomentIndex, cp.Problem, cp.Variable]:
    """Assemble the order-``order`` moment relaxation as a cvxpy problem in ``y``."""
    index = MomentIndex(compiled.n, order)
    y = cp.Variable(index.size, name="y")
    constraints: list[cp.Constraint] = [y[0] == 1]

    def psd(S: Any, dim: int) -> None:
        if dim == 1:
            constraints.append(S @ y >= 0)
        else:
            constraints.append(cp.reshape(S @ y, (dim, dim), order="F") >> 0)

    psd(index.moment_map(order), index.basis_size(order))
    for g in compiled.inequalities:
        t = order - math.ceil(max(sum(e) for e in g) / 2)
        psd(index.localizing_map(g, t), index.basis_size(t))
    for G in compiled.matrix_inequalities:
        dG = max((sum(e) for row in G for entry in row for e in entry), default=0)
        t = order - math.ceil(dG / 2)
        psd(index.matrix_localizing_map(G, t), len(G) * index.basis_size(t))
    for h in compiled.equalities:
        constraints.append(index.equality_map(h) @ y == 0)
    objective = cp.Minimize(index.linear_functional(compiled.objective) @ y)
    return index, cp.Problem(objective, constraints), y


def solve_moment_relaxation(
    problem: PolyProblem,
    order: int | None = None,
    solver: str = "clarabel",
    solver_options: dict[str, Any] | None = None,
    rank_tol: float = 1e-4,
    scale: bool = True,
    feas_tol: float = 1e-4,
    seed: int = 0,
) -> RelaxationResult:
    """Solve the order-``order`` Lasserre moment relaxation of ``problem``.

    Args:
        problem: the POP.
        order: relaxation order k; None picks the minimal admissible order
            ``max(1, ceil(deg / 2))`` over objective and constraints. A smaller order
            raises ValueError.
        solver: "clarabel" (default) or "scs" (any other installed cvxpy solver name is
            passed through without default options).
        solver_options: keyword arguments for the solver, overriding
            :data:`DEFAULT_SOLVER_OPTIONS` (e.g. ``{"verbose": True}``).
        rank_tol: an eigenvalue of ``M_s(y)`` counts towards the rank when it exceeds
            ``rank_tol`` times the largest eigenvalue.
        scale: substitute ``x = (lo + hi)/2 + (hi - lo)/2 * z``, ``z in [-1, 1]``, for
            every bounded variable (results are mapped back to ``x``).
        feas_tol: an extracted point is kept only if its relative constraint violation
            (in the scaled coordinates) is at most ``feas_tol`` and its objective value is
            within ``10 * feas_tol`` (relative) of the relaxation's value.
        seed: seed of the random combination of multiplication matrices.

    Never raises on solver failure: the status is "failed" and the bound ``nan``.
    """
    t0 = time.perf_counter()
    compiled = compile_problem(problem, scale=scale)
    k_min = compiled.minimal_order()
    if order is None:
        order = k_min
    if int(order) != order or order < k_min:
        raise ValueError(f"relaxation order must be an integer >= {k_min}, got {order}")
    order = int(order)
    name = solver.upper()
    if name not in cp.installed_solvers():
        raise ValueError(f"solver {solver!r} is not installed ({cp.installed_solvers()})")
    opts = dict(DEFAULT_SOLVER_OPTIONS.get(name, {}))
    opts.update(solver_options or {})

    index, prob, y = _build(compiled, order)
    result = RelaxationResult(bound=math.nan, status="failed", order=order, solver=name)
    try:
        with warnings.catch_warnings():
            # cvxpy warns on inaccurate solutions; the status field reports that instead.
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            prob.solve(solver=name, **opts)
        result.solver_status = str(prob.status)
    except Exception as exc:  # noqa: BLE001 - solver failures must not raise
        result.solver_status = f"{type(exc).__name__}: {exc}"
        result.seconds = time.perf_counter() - t0
        return result
    status = _STATUS.get(prob.status, "failed")
    yv = None if y.value is None else np.asarray(y.value, dtype=float)
    if status in ("optimal", "inaccurate") and (yv is None or not np.all(np.isfinite(yv))):
        status = "failed"
    result.status = status
    if status not in ("optimal", "inaccurate"):
        result.seconds = time.perf_counter() - t0
        return result

    value = float(prob.value)
    result.bound = compiled.objective_constant + compiled.objective_scale * value
    first = compiled.to_original(yv[1 : compiled.n + 1])
    result.first_moments = dict(zip(compiled.variables, map(float, first), strict=True))

    ranks = [1] + [
        numerical_rank(index.moment_matrix(yv, s), rank_tol) for s in range(1, order + 1)
    ]
    result.ranks = ranks[1:]
    shift = compiled.flatness_shift()
    flats = flat_orders(ranks, shift)
    if flats:
        result.flat = True
        result.flat_order = flats[-1]
        rng = np.random.default_rng(seed)
        best: list[np.ndarray] = []
        for s in reversed(flats):  # keep the order whose extraction passes most checks
            atoms = extract_atoms(index, yv, s, shift, ranks[s], rng)
            if atoms is None:
                continue
            good = [z for z in atoms if _acceptable(compiled, z, value, feas_tol)]
            if len(good) > len(best):
                best, result.flat_order = good, s
        result.minimizers = [
            dict(zip(compiled.variables, map(float, compiled.to_original(z)), strict=True))
            for z in best
        ]
    result.seconds = time.perf_counter() - t0
    return result


def _acceptable(compiled: CompiledProblem, z: np.ndarray, value: float, tol: float) -> bool:
    """Is ``z`` feasible (relative ``tol``) and is its objective within ``10 tol`` of ``value``?

    A global minimizer attains the relaxation's value exactly when the relaxation is exact,
    so a point far from it (above *or below*) reveals a wrong rank or an inaccurate solve.
    """
    if constraint_violation(compiled, z) > tol:
        return False
    gap = abs(evaluate(compiled.objective, z) - value)
    return gap <= 10.0 * tol * max(1.0, abs(value), abs_evaluate(compiled.objective, z))
