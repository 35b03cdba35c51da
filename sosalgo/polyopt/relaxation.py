"""Lasserre's moment relaxation of a polynomial optimization problem, solved with cvxpy.

Order-k relaxation (Lasserre 2001, "Global optimization with polynomials and the problem
of moments"; Henrion-Lasserre 2006 for matrix inequalities)::

    min_y  L_y(f)
    s.t.   y_0 = 1,  M_k(y) ⪰ 0,
           M_{k - ceil(deg g_i / 2)}(g_i y) ⪰ 0           for every g_i(x) >= 0,
           M_{k - ceil(deg G / 2)}(G y) ⪰ 0               for every G(x) ⪰ 0,
           L_y(h_j x^alpha) = 0, |alpha| <= 2k - deg h_j   for every h_j(x) = 0.

Its value is a lower bound on the POP's minimum. The solver's value is not trusted: the
reported bound is the one its dual *proves* (:mod:`sosalgo.polyopt.certificate`). Flatness
of the optimal moment matrix certifies exactness and yields the minimizers
(:mod:`sosalgo.polyopt.extraction`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from enum import StrEnum
from fractions import Fraction
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sps
import sympy as sp

from sosalgo.kernel.solvers import SolverStatus, cvxpy_solve

from .certificate import DualData, certified_bound, interior_dual, newton_keep
from .exact import exact_sos_bound
from .extraction import RANK_GAP, extract_atoms, flat_orders, numerical_rank, rank_gap
from .moment import MomentIndex
from .polynomial import PolyDict, evaluate
from .problem import (
    CompiledProblem,
    PolyProblem,
    compile_problem,
    constraint_violation,
    equilibrating_scale,
)

__all__ = ["RelaxationResult", "RelaxationStatus", "solve_moment_relaxation",
           "DEFAULT_SOLVER_OPTIONS", "CAUTIOUS_OPTIONS"]

#: Solver settings used unless overridden by ``solver_options``. Clarabel's default
#: regularization fails with NumericalError on many moment relaxations; 1e-7 fixes it.
DEFAULT_SOLVER_OPTIONS: dict[str, dict[str, Any]] = {
    "CLARABEL": {"static_regularization_constant": 1e-7},
    "SCS": {"eps_abs": 1e-8, "eps_rel": 1e-8, "max_iters": 100_000},
}

#: Clarabel settings of a second solve when the first stops short of full accuracy
#: ("AlmostSolved": cvxpy's "optimal_inaccurate"). Shorter steps keep the iterates further
#: inside the PSD cones; on the moment relaxations measured (GloptiPoly's example with a
#: box at order 4, Floudas-Pardalos 2.1 with a box at order 3) this turned a stall at
#: ~2e-8 dual residual into a full-accuracy solve.
CAUTIOUS_OPTIONS: dict[str, dict[str, Any]] = {"CLARABEL": {"max_step_fraction": 0.9}}

#: Re-solves of an inaccurate relaxation with unbounded variables, each centred at the
#: previous first moments with equilibrated variable scales.
_REFINE_PASSES = 2

#: Back-off levels of the interior dual, as fractions of the allowed gap below the value.
_BACKOFF = (0.05, 0.5)



class RelaxationStatus(StrEnum):
    """Outcome of a moment relaxation (a str: compares and serializes as one).

    The first four are :func:`solve_moment_relaxation`'s (see :class:`RelaxationResult`);
    the design's moment bound adds the last two."""

    OPTIMAL = "optimal"
    INACCURATE = "inaccurate"
    INFEASIBLE = "infeasible"
    FAILED = "failed"
    SKIPPED = "skipped"  # not solved: too large for the memory or the time left
    INCONSISTENT = "inconsistent"  # its bound exceeds a certified rate: discarded


_STATUS = {  # the solver door's statuses (cvxpy's optimal, optimal_inaccurate,
    # infeasible, infeasible_inaccurate)
    SolverStatus.SOLVED: RelaxationStatus.OPTIMAL,
    SolverStatus.ALMOST_SOLVED: RelaxationStatus.INACCURATE,
    SolverStatus.INFEASIBLE: RelaxationStatus.INFEASIBLE,
    SolverStatus.INACCURATE: RelaxationStatus.INFEASIBLE,
}


@dataclass
class RelaxationResult:
    """Outcome of :func:`solve_moment_relaxation` (docs/polyopt.md, "Result").

    Attributes:
        bound: "optimal": a lower bound on the POP's minimum proven by the dual
            certificate (:mod:`sosalgo.polyopt.certificate`). "inaccurate": the proven bound
            if ``certified``, else the solver's unverified value (possibly above the
            minimum). ``nan`` for "infeasible" and "failed".
        status: "optimal" (certified, and bound, solver value and primal point agree within
            ``gap_tol * max(1, |value|)``), "inaccurate" (anything short of that),
            "infeasible" (the relaxation, hence the POP, is infeasible) or "failed" (solver
            error, unbounded relaxation, iteration limit).
        order: relaxation order k.
        ranks: numerical ranks of ``M_1(y), ..., M_k(y)``.
        flat: only with status "optimal": flat extension ``rank M_s == rank M_{s-d}``
            (``d = max(1, ceil(deg/2))`` over the constraints) with both ranks separated by
            a factor :data:`~sosalgo.polyopt.extraction.RANK_GAP`, and a consistent
            extraction (exactly ``rank M_s`` feasible points attaining the bound). Then the
            relaxation is exact: ``bound <= min <= f(minimizer)``.
        minimizers: the extracted global minimizers (original coordinates); non-empty
            exactly when ``flat``.
        first_moments: ``y_{e_i}`` in original coordinates (the mean of the optimal
            measure; equals the minimizer when it is unique and the relaxation is exact).
        seconds: wall time of build, solves, certificate and extraction.
        solver: solver name as given to cvxpy.
        solver_status: raw cvxpy status, or the exception text if the solver raised.
        flat_order: the order s at which flatness was detected (None if not flat).
        certified: ``bound`` is proven by the dual certificate.
        solver_bound: the solver's own value of the relaxation, in the problem's units.
    """

    bound: float
    status: RelaxationStatus
    order: int
    ranks: list[int] = field(default_factory=list)
    flat: bool = False
    minimizers: list[dict[sp.Symbol, float]] = field(default_factory=list)
    first_moments: dict[sp.Symbol, float] = field(default_factory=dict)
    seconds: float = 0.0
    solver: str = ""
    solver_status: str = ""
    flat_order: int | None = None
    certified: bool = False
    solver_bound: float = math.nan


def _build(
    compiled: CompiledProblem, order: int
) -> tuple[MomentIndex, cp.Problem, cp.Variable, _Parts]:
    """Assemble the order-``order`` moment relaxation as a cvxpy problem in ``y``."""
    index = MomentIndex(compiled.n, order)
    y = cp.Variable(index.size, name="y")
    first = y[0] == 1
    constraints: list[cp.Constraint] = [first]
    parts = _Parts(c=np.zeros(0), c_error=np.zeros(0), y0=first)

    def psd(S: Any, dim: int, E: Any = None) -> None:
        if dim == 1:
            con = S @ y >= 0
        else:
            con = cp.reshape(S @ y, (dim, dim), order="F") >> 0
        constraints.append(con)
        parts.psd.append((S, dim, con, E))

    psd(index.moment_map(order), index.basis_size(order))
    ineq_errs = _errors(compiled.inequality_errors, compiled.inequalities)
    for g, err in zip(compiled.inequalities, ineq_errs, strict=True):
        t = order - math.ceil(max(sum(e) for e in g) / 2)
        E = index.localizing_map(err, t) if err else None
        psd(index.localizing_map(g, t), index.basis_size(t), E)
    pmi_errs = _errors(compiled.matrix_inequality_errors, compiled.matrix_inequalities)
    for G, Gerr in zip(compiled.matrix_inequalities, pmi_errs, strict=True):
        dG = max((sum(e) for row in G for entry in row for e in entry), default=0)
        t = order - math.ceil(dG / 2)
        E = None
        if Gerr and any(entry for row in Gerr for entry in row):
            E = index.matrix_localizing_map(Gerr, t)
        psd(index.matrix_localizing_map(G, t), len(G) * index.basis_size(t), E)
    eq_errs = _errors(compiled.equality_errors, compiled.equalities)
    for h, err in zip(compiled.equalities, eq_errs, strict=True):
        A = index.equality_map(h)
        con = A @ y == 0
        constraints.append(con)
        E = _equality_error_map(index, h, err) if err else None
        parts.eq.append((A, con, E))
    parts.c_error = np.zeros(index.size)
    for e, u in compiled.objective_error.items():
        parts.c_error[index.index_of(e)] += u
    parts.c = index.linear_functional(compiled.objective)
    objective = cp.Minimize(parts.c @ y)
    return index, cp.Problem(objective, constraints), y, parts


def _errors(errs: list, polys: list) -> list:
    """Error bounds aligned with ``polys`` (empty ones when the compiled problem has none)."""
    return errs if len(errs) == len(polys) else [{} for _ in polys]


def _equality_error_map(index: MomentIndex, h: PolyDict, err: PolyDict) -> sps.csr_array:
    """Rows ``L_y(err x^alpha)`` for the same ``alpha`` as ``index.equality_map(h)``."""
    dh = max(sum(e) for e in h)
    padded = {**err, **{e: err.get(e, 0.0) for e in h}}
    padded = {e: u for e, u in padded.items() if sum(e) <= dh}
    if not padded:
        return sps.csr_array((index.basis_size(2 * index.order - dh), index.size))
    top = next(e for e in h if sum(e) == dh)
    padded.setdefault(top, 0.0)
    return index.equality_map(padded)


@dataclass
class _Parts:
    """The relaxation's constraints with their linear maps, to read the dual back.

    ``E`` maps (or None) are the maps of the coefficient error bounds of the same
    constraint (see :class:`~sosalgo.polyopt.problem.CompiledProblem`).
    """

    c: np.ndarray
    c_error: np.ndarray
    y0: cp.Constraint
    psd: list[tuple[Any, int, cp.Constraint, Any]] = field(default_factory=list)
    eq: list[tuple[Any, cp.Constraint, Any]] = field(default_factory=list)

    def dual(self) -> DualData | None:
        """The solver's dual as :class:`DualData`, or None if some dual is missing."""
        if self.y0.dual_value is None:
            return None
        duals = []
        for _, dim, con, _ in self.psd:
            if con.dual_value is None:
                return None
            duals.append(np.reshape(np.asarray(con.dual_value, dtype=float), (dim, dim)))
        eq_map = eq_dual = eq_err = None
        if self.eq:
            if any(con.dual_value is None for _, con, _ in self.eq):
                return None
            eq_map = sps.vstack([A for A, _, _ in self.eq]).tocsr()
            eq_dual = np.concatenate([np.ravel(con.dual_value) for _, con, _ in self.eq])
            eq_err = sps.vstack(
                [E if E is not None else sps.csr_array(A.shape) for A, _, E in self.eq]
            ).tocsr()
        return DualData(
            c=self.c,
            psd_maps=[sps.csr_array(S) for S, _, _, _ in self.psd],
            psd_duals=duals,
            eq_map=eq_map,
            eq_dual=eq_dual,
            y0_dual=float(np.ravel(self.y0.dual_value)[0]),
            c_error=self.c_error,
            psd_error_maps=[None if E is None else sps.csr_array(E) for _, _, _, E in self.psd],
            eq_error_map=eq_err,
        )


def solve_moment_relaxation(
    problem: PolyProblem,
    order: int | None = None,
    solver: str = "clarabel",
    solver_options: dict[str, Any] | None = None,
    rank_tol: float = 1e-4,
    scale: bool = True,
    feas_tol: float = 1e-4,
    seed: int = 0,
    gap_tol: float = 1e-5,
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
            :data:`DEFAULT_SOLVER_OPTIONS` (e.g. ``{"verbose": True}``). A solve that
            stops short of full accuracy is repeated once with :data:`CAUTIOUS_OPTIONS`.
        rank_tol: an eigenvalue of ``M_s(y)`` counts towards the rank when it exceeds
            ``rank_tol`` times the largest eigenvalue.
        scale: substitute ``x = (lo + hi)/2 + (hi - lo)/2 * z``, ``z in [-1, 1]``, for
            every variable with bounds, stated or implied by the linear constraints
            (results are mapped back to ``x``); when a result is
            "inaccurate" and some variable is unbounded, also re-solve (at most
            :data:`_REFINE_PASSES` times) centred at the first moments with equilibrated
            scales (:func:`~sosalgo.polyopt.problem.equilibrating_scale`).
        feas_tol: an extracted point is kept only if its relative constraint violation
            (in the scaled coordinates) is at most ``feas_tol`` and its objective value is
            within ``10 * feas_tol * max(1, |bound|)`` of the bound (problem units).
        seed: seed of the random combination of multiplication matrices.
        gap_tol: status "optimal" needs the certified bound, the solver's value of the
            relaxation and the primal point's infeasibility cost to agree within
            ``gap_tol * max(1, |value|)`` (problem units).

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

    args = (rank_tol, feas_tol, seed, gap_tol)
    result = _solve_accurately(compiled, order, (name, opts), args)
    if scale and result.status == RelaxationStatus.INACCURATE and compiled.radius is None:
        result = _recentred(problem, result, order, (name, opts), args)
    result.seconds = time.perf_counter() - t0
    return result


def _recentred(
    problem: PolyProblem,
    result: RelaxationResult,
    order: int,
    solver: tuple[str, dict[str, Any]],
    args: tuple[float, float, int, float],
) -> RelaxationResult:
    """Re-solve up to :data:`_REFINE_PASSES` times centred at the first moments with
    equilibrated scales (:func:`~sosalgo.polyopt.problem.equilibrating_scale`); the best
    result is kept."""
    for _ in range(_REFINE_PASSES):
        center = np.array([result.first_moments.get(v, math.nan) for v in problem.variables])
        if not np.all(np.isfinite(center)):
            break
        again = compile_problem(problem, True, center, equilibrating_scale(problem, center))
        retry = _solve_accurately(again, order, solver, args)
        if _rank(retry) > _rank(result):
            result = retry
        if result.status == RelaxationStatus.OPTIMAL or not retry.first_moments:
            break
    return result


def _solve_accurately(
    compiled: CompiledProblem,
    order: int,
    solver: tuple[str, dict[str, Any]],
    args: tuple[float, float, int, float],
) -> RelaxationResult:
    """:func:`_solve_once`, and once more with :data:`CAUTIOUS_OPTIONS` if the solver
    stopped short of full accuracy (cvxpy's "optimal_inaccurate"); the better one is kept.

    Skipped when the caller set one of those options itself; a ``time_limit`` is reduced
    by the time already spent.
    """
    t0 = time.perf_counter()
    result = _solve_once(compiled, order, solver, *args)
    name, opts = solver
    cautious = CAUTIOUS_OPTIONS.get(name, {})
    if result.solver_status != cp.OPTIMAL_INACCURATE or not cautious or cautious.keys() & opts:
        return result
    again = {**opts, **cautious}
    if "time_limit" in opts:
        again["time_limit"] = float(opts["time_limit"]) - (time.perf_counter() - t0)
        if again["time_limit"] < 1.0:
            return result
    retry = _solve_once(compiled, order, (name, again), *args)
    return retry if _rank(retry) > _rank(result) else result


def _infeasibility_cost(parts: _Parts, yv: np.ndarray) -> float:
    """Estimated effect of the primal point's infeasibility on its objective value.

    ``sum_i max(0, -lambda_min(M_i(y))) tr(Z_i) + |A y| . |nu|`` (normalized units): how
    much ``L_y(f)`` could move when ``y`` is repaired to feasibility, so that the gap
    between the certified bound and ``L_y(f)`` is only trusted when this is small too.
    """
    cost = 0.0
    for S, dim, con, _ in parts.psd:
        Z = con.dual_value
        if Z is None:
            return math.inf
        M = np.reshape(S @ yv, (dim, dim), order="F")
        lam = float(np.linalg.eigvalsh(0.5 * (M + M.T))[0])
        if lam < 0.0:
            Zm = np.reshape(np.asarray(Z, dtype=float), (dim, dim))
            cost += -lam * max(float(np.trace(Zm)), 0.0)
    for A, con, _ in parts.eq:
        if con.dual_value is None:
            return math.inf
        cost += float(np.abs(A @ yv) @ np.abs(np.ravel(con.dual_value)))
    cost += abs(yv[0] - 1.0) * abs(float(np.ravel(parts.y0.dual_value)[0]))
    return cost


def _rank(res: RelaxationResult) -> tuple[bool, bool, float]:
    """Order of preference between two solves of the same relaxation."""
    return (res.status == RelaxationStatus.OPTIMAL, res.certified,
            res.bound if res.certified else -math.inf)


def _solve_once(
    compiled: CompiledProblem,
    order: int,
    solver: tuple[str, dict[str, Any]],
    rank_tol: float,
    feas_tol: float,
    seed: int,
    gap_tol: float,
) -> RelaxationResult:
    """Build, solve, certify and (when optimal) extract, in ``compiled``'s coordinates."""
    name, opts = solver
    index, prob, y, parts = _build(compiled, order)
    result = RelaxationResult(bound=math.nan, status=RelaxationStatus.FAILED, order=order,
                              solver=name)
    end = cvxpy_solve(prob, name, **opts)  # an inaccurate end is its status
    if end.error is not None:  # solver failures must not raise
        result.solver_status = f"{type(end.error).__name__}: {end.error}"
        return result
    result.solver_status = end.raw
    status = _STATUS.get(end.status, RelaxationStatus.FAILED)
    yv = None if y.value is None else np.asarray(y.value, dtype=float)
    solved = (RelaxationStatus.OPTIMAL, RelaxationStatus.INACCURATE)
    if status in solved and (yv is None or not np.all(np.isfinite(yv))):
        status = RelaxationStatus.FAILED
    result.status = status
    if status not in solved:
        return result

    value = float(prob.value)
    to_orig = compiled.objective_constant, compiled.objective_scale
    result.solver_bound = to_orig[0] + to_orig[1] * value
    first = compiled.to_original(yv[1 : compiled.n + 1])
    result.first_moments = dict(zip(compiled.variables, map(float, first), strict=True))
    result.ranks = [
        numerical_rank(index.moment_matrix(yv, s), rank_tol) for s in range(1, order + 1)
    ]

    allowed = gap_tol * max(1.0, abs(result.solver_bound))
    target = value - allowed / compiled.objective_scale
    # the interior dual (extra SDP solves) only when "optimal" is still within reach
    cert = _certify(index, parts, compiled, value, target, solver,
                    status == RelaxationStatus.OPTIMAL)
    result.certified = math.isfinite(cert)
    result.bound = cert if result.certified else result.solver_bound
    slack = compiled.objective_scale * _infeasibility_cost(parts, yv)
    accurate = result.certified and abs(result.solver_bound - cert) + slack <= allowed
    result.status = (RelaxationStatus.OPTIMAL if status == RelaxationStatus.OPTIMAL and accurate
                     else RelaxationStatus.INACCURATE)
    if result.status == RelaxationStatus.OPTIMAL:
        _flat_and_minimizers(result, compiled, index, yv, rank_tol, feas_tol, seed)
    return result


def _certify(
    index: MomentIndex,
    parts: _Parts,
    compiled: CompiledProblem,
    value: float,
    target: float,
    solver: tuple[str, dict[str, Any]],
    interior: bool = True,
) -> float:
    """Rigorous lower bound (original units) from the solver's dual; -inf if none.

    See :mod:`sosalgo.polyopt.certificate`. ``value`` is the solver's value and ``target``
    the level the bound must reach for status "optimal" (both in the relaxation's
    normalized units). When some variable is unbounded and the solver's own dual falls
    short (and ``interior`` is set), interior duals are tried (:func:`_interior_bound`).
    The map back ``constant + scale * b`` is rounded down by a few ulps.
    """
    data = parts.dual()
    if data is None:
        return -math.inf
    unconstrained = not (
        compiled.inequalities or compiled.equalities or compiled.matrix_inequalities
    )
    support = list(compiled.objective) if unconstrained else None
    radius = compiled.box_radius()
    exact = -math.inf
    try:
        # search on for a tighter bound until 1 % of the allowed gap (cheap: no solves)
        b, _ = certified_bound(index, data, radius, value - 0.01 * (value - target), support)
        if interior and b < target and radius is None and math.isfinite(target):
            b, exact = _interior_bound(index, data, compiled, value, target, solver, b)
    except (np.linalg.LinAlgError, ValueError):
        return -math.inf
    if not math.isfinite(b):
        return exact
    const, scale = compiled.objective_constant, compiled.objective_scale
    out = const + scale * float(b)
    out -= 4.0 * float(np.finfo(float).eps) * (abs(const) + abs(scale * float(b)))
    return max(out, exact)


def _interior_bound(
    index: MomentIndex,
    data: DualData,
    compiled: CompiledProblem,
    value: float,
    target: float,
    solver: tuple[str, dict[str, Any]],
    b: float,
) -> tuple[float, float]:
    """``(b, exact)``: bounds from interior duals a little below ``value``.

    At the levels ``value - frac (value - target)`` (``frac`` in :data:`_BACKOFF`, closest
    first) a dual whose Gram matrix is as far inside the PSD cone as possible is computed
    (:func:`~sosalgo.polyopt.certificate.interior_dual`) and checked in floating point
    (``b``, normalized units, the best so far). For an unconstrained problem with exact
    coefficients, a Gram matrix that is singular on every certificate is checked in exact
    arithmetic instead (:func:`~sosalgo.polyopt.exact.exact_sos_bound`); ``exact`` is
    that bound in problem units (-inf if none).
    """
    unconstrained = not (
        compiled.inequalities or compiled.equalities or compiled.matrix_inequalities
    )
    keep = newton_keep(index, list(compiled.objective)) if unconstrained else None
    keeps = [keep] if keep is not None else None
    exact = -math.inf
    for frac in _BACKOFF:
        level = value - frac * (value - target)
        interior = interior_dual(index, data, level, keep, solver[0], solver[1])
        if interior is not None:
            b = max(b, certified_bound(index, interior, None, target, None, keeps)[0])
            if b < target and keep is not None and compiled.exact_objective is not None:
                top = value + (value - target)  # the solver's value may be low, too
                exact = max(exact, _exact_bound(index, compiled, interior.psd_duals[0],
                                                keep, level, top))
        if b >= target or exact > -math.inf:
            break
    return b, exact


def _exact_bound(
    index: MomentIndex, compiled: CompiledProblem, Z: np.ndarray, keep: np.ndarray,
    level: float, top: float,
) -> float:
    """Largest ``G`` (rounded down; problem units) with ``f - G`` proven SOS exactly.

    Tried at ``constant + scale * level`` first (``Z`` is a Gram matrix there), then
    bisected towards ``top`` (normalized units, like ``level``); -inf if none is proven.
    """
    if compiled.exact_objective is None or not np.all(np.isfinite(Z)):
        return -math.inf
    const, scale = Fraction(compiled.objective_constant), Fraction(compiled.objective_scale)
    Zp = compiled.objective_scale * np.asarray(Z, dtype=float)
    G = exact_sos_bound(index, Zp, keep, compiled.exact_objective,
                        const + scale * Fraction(level), const + scale * Fraction(top))
    if G is None:
        return -math.inf
    out = float(G)
    return out if Fraction(out) <= G else math.nextafter(out, -math.inf)


def _flat_and_minimizers(
    result: RelaxationResult,
    compiled: CompiledProblem,
    index: MomentIndex,
    yv: np.ndarray,
    rank_tol: float,
    feas_tol: float,
    seed: int,
) -> None:
    """Set ``flat``, ``flat_order`` and ``minimizers`` (only called when status is optimal).

    ``flat`` needs (i) ``rank M_s == rank M_{s-d}`` with both ranks separated from the
    discarded eigenvalues by a factor :data:`RANK_GAP`, and (ii) a consistent extraction:
    exactly ``rank M_s`` atoms, each feasible and attaining the bound (``_acceptable``).
    """
    ranks = [1] + list(result.ranks)
    robust = [True] + [
        rank_gap(index.moment_matrix(yv, s), ranks[s]) >= RANK_GAP
        for s in range(1, result.order + 1)
    ]
    shift = compiled.flatness_shift()
    flats = [s for s in flat_orders(ranks, shift) if robust[s] and robust[s - shift]]
    rng = np.random.default_rng(seed)
    for s in reversed(flats):
        atoms = extract_atoms(index, yv, s, shift, ranks[s], rng)
        if atoms is None or len(atoms) != ranks[s]:
            continue
        if not all(_acceptable(compiled, z, result.bound, feas_tol) for z in atoms):
            continue
        result.flat, result.flat_order = True, s
        result.minimizers = [
            dict(zip(compiled.variables, map(float, compiled.to_original(z)), strict=True))
            for z in atoms
        ]
        return


def _acceptable(compiled: CompiledProblem, z: np.ndarray, bound: float, tol: float) -> bool:
    """Is ``z`` feasible (relative ``tol``) and is ``f(z)`` within ``10 tol`` of ``bound``?

    Measured in the problem's own units, relative to ``max(1, |bound|)``: a global
    minimizer attains the bound when the relaxation is exact, so a point far from it (above
    *or below*) reveals a wrong rank or an inaccurate solve.
    """
    if constraint_violation(compiled, z) > tol:
        return False
    fz = compiled.objective_constant + compiled.objective_scale * evaluate(compiled.objective, z)
    return abs(fz - bound) <= 10.0 * tol * max(1.0, abs(bound))
