"""One small door to the conic solvers, returning a status we trust.

``solve_lmi`` asks whether an :class:`~sosalgo.kernel.conic.LMIProblem` is feasible at a
given rho with a small margin (every block ⪯ -margin I) and answers ``feasible`` only when
the solver reports *solved* **and** the returned x passes a floating-point eigenvalue check
of every block. Anything else (inaccurate, iteration limit, numerical error, exception, a
"solved" point that violates the inequality) is ``failed``; a solver's proof of
infeasibility is ``infeasible``. Callers never read a raw solver status.

The problem data go straight to Clarabel (upper-triangular scaled svec) or SCS
(lower-triangular scaled svec), so one feasibility test costs well under a millisecond.

This module is the only one that imports Clarabel and SCS, and the door of every conic
solve: a problem modelled in cvxpy (the moment relaxations of :mod:`sosalgo.polyopt`, the
composite noise SDP) is solved by :func:`cvxpy_solve`, its status classified here too.
Conic data other than an
:class:`~sosalgo.kernel.conic.LMIProblem` (the PEP, noise, witness and dual-bound SDPs)
come as ``A x + s = b`` with cones written as ``(kind, size)`` pairs
(:func:`clarabel_cones`) and are solved by :func:`clarabel_solve` (one solve) or
:func:`solve_attempts` (a list of settings tried in turn); the statuses they return are
classified by :func:`solver_status`, and every solve stops at Ctrl-C or SIGTERM
(:mod:`sosalgo.kernel.interrupts`).
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import sys
import threading
import warnings
import weakref
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sps

from sosalgo.kernel.conic import LMIProblem, svec
from sosalgo.kernel.interrupts import native_solve, watch

__all__ = [
    "Feasibility", "Outcome", "solve_lmi", "solve_margin", "check_point", "Margin", "SOLVERS",
    "DEFAULT_SOLVERS", "margin_for", "SolverStatus", "solver_status", "SolverPanic",
    "clarabel_solve", "solve_or_raise", "clarabel_cones", "solve_attempts", "CHORDAL", "lmi_point",
    "CvxpySolve", "cvxpy_solve", "linear_program",
]

RELATIVE_MARGIN = 1e-9
DEFAULT_TOL = 1e-8  # Clarabel's default tolerances (gap, feasibility)
PRECISE_TOL = 1e-10  # ... and those of a precise margin


class Feasibility(StrEnum):
    """Trusted verdict of one feasibility test (a str: compares and serializes as one)."""

    FEASIBLE = "feasible"  # solver said solved AND the point passed the float check
    INFEASIBLE = "infeasible"  # the solver proved infeasibility
    FAILED = "failed"  # anything else: inaccurate, iteration limit, crash, failed check


class SolverStatus(StrEnum):
    """A raw Clarabel or SCS status, classified once (:func:`solver_status`)."""

    SOLVED = "solved"  # full accuracy
    ALMOST_SOLVED = "almost solved"  # a point at reduced accuracy
    INFEASIBLE = "infeasible"  # a certificate of primal infeasibility
    INACCURATE = "inaccurate"  # another reduced-accuracy end (almost infeasible, ...)
    FAILED = "failed"  # iteration or time limit, numerical error, invalid data

    @property
    def near(self) -> bool:
        """A reduced-accuracy end: the problem is (in)feasible by a hair at best."""
        return self in (SolverStatus.ALMOST_SOLVED, SolverStatus.INACCURATE)


_STATUSES = {
    "Solved": SolverStatus.SOLVED, "solved": SolverStatus.SOLVED,  # Clarabel, SCS
    "AlmostSolved": SolverStatus.ALMOST_SOLVED, "solved_inaccurate": SolverStatus.ALMOST_SOLVED,
    "PrimalInfeasible": SolverStatus.INFEASIBLE, "infeasible": SolverStatus.INFEASIBLE,
}


def solver_status(raw: object) -> SolverStatus:
    """The one mapping of Clarabel's and SCS's status names (anything else is failed)."""
    name = str(raw)
    if name in _STATUSES:
        return _STATUSES[name]
    return (SolverStatus.INACCURATE if name.startswith("Almost") or "inaccurate" in name
            else SolverStatus.FAILED)


_CVXPY_STATUSES = {  # cvxpy's status names (cvxpy.settings), classified as the others
    "optimal": SolverStatus.SOLVED, "optimal_inaccurate": SolverStatus.ALMOST_SOLVED,
    "infeasible": SolverStatus.INFEASIBLE, "infeasible_inaccurate": SolverStatus.INACCURATE,
}


class CvxpySolve(NamedTuple):
    """How a cvxpy solve ended: its status, cvxpy's own (None after an error), the error."""

    status: SolverStatus
    raw: str | None
    error: Exception | None = None


def cvxpy_solve(problem: Any, solver: str, **options: Any) -> CvxpySolve:
    """``problem.solve(solver=solver, **options)`` for a cvxpy problem, options as given.
    cvxpy's statuses are classified here (optimal: solved; optimal_inaccurate: almost
    solved; infeasible; infeasible_inaccurate: inaccurate; anything else: failed) and its
    warnings silenced (an inaccurate end is a status, not a warning). A crash, a Rust
    panic included, is a failed status with its error; Ctrl-C and SIGTERM go through."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            problem.solve(solver=solver, **options)
    except BaseException as exc:
        if not isinstance(exc, Exception) and type(exc).__name__ != "PanicException":
            raise
        err = exc if isinstance(exc, Exception) else SolverPanic(str(exc)[:200] or "panic")
        return CvxpySolve(SolverStatus.FAILED, None, err)
    raw = str(problem.status)
    return CvxpySolve(_CVXPY_STATUSES.get(raw, SolverStatus.FAILED), raw)


def linear_program(c: Any, A_eq: Any, b_eq: Any, bounds: Any, method: str = "highs") -> Any:
    """min c'x over A_eq x = b_eq and ``bounds`` with HiGHS (scipy's ``linprog``): its
    result (``status`` 0 solved, 2 infeasible; ``x``). The one door of linear programs;
    a caller proves or checks what it returns."""
    from scipy.optimize import linprog

    return linprog(c, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method=method)


def finite_data(*arrays: Any) -> bool:
    """Whether every entry is finite (solvers print errors on NaN/inf data: never sent)."""
    return all(np.all(np.isfinite(getattr(a, "data", a))) for a in arrays)


@dataclass(frozen=True)
class Outcome:
    """Trusted answer of one feasibility test."""

    status: Feasibility
    x: np.ndarray | None
    solver: str
    detail: str = ""
    near_boundary: bool = False  # failed because the point is (almost) on the boundary

    @property
    def feasible(self) -> bool:
        return self.status == Feasibility.FEASIBLE


class _ConicForm:
    """``A(rho) x + s = b(rho)``, s in a product of PSD cones, for -G_b(x) - margin I ⪰ 0.

    A and b are affine in rho^2; the sparse pattern, cones and settings are built once per
    problem, so each feasibility test only fills in numbers.
    """

    def __init__(self, problem: LMIProblem, upper: bool):
        a0, a1, b0, b1, eye, sizes = [], [], [], [], [], []
        for blk in problem.blocks:
            s = blk.size
            a0.append(svec(blk.l0, upper).T)
            a1.append(svec(blk.l1, upper).T)
            b0.append(svec(-blk.c0, upper))
            b1.append(svec(-blk.c1, upper))
            eye.append(svec(np.eye(s) if blk.strict else np.zeros((s, s)), upper))
            sizes.append(s)
        self.sizes = sizes
        a0m, a1m = np.vstack(a0), np.vstack(a1)
        self.b0, self.b1, self.eye = np.concatenate(b0), np.concatenate(b1), np.concatenate(eye)
        self.A = sps.csc_matrix((np.abs(a0m) + np.abs(a1m)) > 0, dtype=float)
        self.A.sort_indices()
        cols = np.repeat(np.arange(self.A.shape[1]), np.diff(self.A.indptr))
        self.a0 = a0m[self.A.indices, cols]
        self.a1 = a1m[self.A.indices, cols]
        self.zero_P = sps.csc_matrix((problem.nvar, problem.nvar))
        self.q = np.zeros(problem.nvar)
        self.scale = max(
            [1.0] + [float(np.abs(b.c0).max() + np.abs(b.c1).max()) for b in problem.blocks]
        )

    def data(self, rho: float, margin: float) -> tuple[sps.csc_matrix, np.ndarray]:
        r2 = rho * rho
        self.A.data = self.a0 + r2 * self.a1
        return self.A, self.b0 + r2 * self.b1 - margin * self.eye


_FORMS: weakref.WeakKeyDictionary[LMIProblem, dict[bool, _ConicForm]] = (
    weakref.WeakKeyDictionary()
)


def _form(problem: LMIProblem, upper: bool) -> _ConicForm:
    forms = _FORMS.setdefault(problem, {})
    if upper not in forms:
        forms[upper] = _ConicForm(problem, upper)
    return forms[upper]


def margin_for(problem: LMIProblem) -> float:
    """Strictness margin for the strict blocks, relative to the size of the data."""
    return RELATIVE_MARGIN * _form(problem, True).scale


def quiet_settings() -> Any:
    """Clarabel's default settings (a new object each call), silent and on one thread: on
    these problems (up to a few thousand rows) its threads cost more than they give (a
    200-unknown margin solve 22 ms instead of 37; PEP N = 20 3.6 s instead of 6.6), more
    so on a loaded machine."""
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_threads = 1
    return settings


@functools.cache
def _clarabel_settings(equilibrate: bool, refine: bool = True, precise: bool = False):
    settings = quiet_settings()
    settings.max_iter = 200
    settings.presolve_enable = False
    settings.equilibrate_enable = equilibrate
    settings.iterative_refinement_enable = refine
    if precise:  # a hundred times tighter: two or three more iterations
        settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = PRECISE_TOL
        settings.tol_ktratio = PRECISE_TOL
        settings.max_iter = 400
    return settings


def _clarabel_run(problem: LMIProblem, rho: float, margin: float, equilibrate: bool):
    import clarabel

    form = _form(problem, upper=True)
    with np.errstate(all="ignore"):
        A, b = form.data(rho, margin)
    if not finite_data(A, b):
        return "failed", None, "non-finite problem data"
    cones = [
        clarabel.NonnegativeConeT(1) if s == 1 else clarabel.PSDTriangleConeT(s)
        for s in form.sizes
    ]
    sol = clarabel_solve(form.zero_P, form.q, A, b, cones, _clarabel_settings(equilibrate))
    return _raw_answer(str(sol.status), sol.x)


class SolverPanic(RuntimeError):
    """A Rust solver (Clarabel, through pyo3) panicked: no answer. pyo3's PanicException
    derives from BaseException, which ``except Exception`` would let through."""


def solve_or_raise(solver: Any) -> Any:
    """``solver.solve()``, a panic turned into :class:`SolverPanic` (an Exception). Ctrl-C
    or SIGTERM meanwhile stops the solve at its next iteration and is raised when it
    returns (:mod:`sosalgo.kernel.interrupts`)."""
    try:
        with native_solve():
            return watch(solver).solve()
    except BaseException as exc:
        if type(exc).__name__ == "PanicException":
            raise SolverPanic(str(exc).splitlines()[0] if str(exc) else "panic") from None
        raise


def clarabel_cones(cones: Sequence[Any]) -> list:
    """Clarabel's cone objects for ``(kind, size)`` pairs, kind "zero", "nonneg" or "psd"
    (the scaled upper-triangle PSD cone of s x s matrices); cone objects pass through."""
    import clarabel

    kinds = {"zero": clarabel.ZeroConeT, "nonneg": clarabel.NonnegativeConeT,
             "psd": clarabel.PSDTriangleConeT}
    return [kinds[c[0]](c[1]) if isinstance(c, tuple) else c for c in cones]


def clarabel_solve(P: Any, q: Any, A: Any, b: Any, cones: list, settings: Any) -> Any:
    """One Clarabel solve (a panic in its setup or solve becomes :class:`SolverPanic`);
    ``cones`` as for :func:`clarabel_cones`."""
    import clarabel

    try:
        solver = clarabel.DefaultSolver(P, q, A, b, clarabel_cones(cones), settings)
    except BaseException as exc:
        if type(exc).__name__ == "PanicException":
            raise SolverPanic(str(exc).splitlines()[0] if str(exc) else "panic") from None
        raise
    return solve_or_raise(solver)


def _raw_answer(status: str, x: Any) -> tuple[str, np.ndarray | None, str]:
    """(solved | infeasible | near | failed, x when solved, the solver's own status)."""
    st = solver_status(status)
    if st == SolverStatus.SOLVED:
        return "solved", np.array(x), status
    if st == SolverStatus.INFEASIBLE:
        return "infeasible", None, status
    return ("near" if st.near else "failed"), None, status


def _clarabel_fast(problem: LMIProblem, rho: float, margin: float):
    """Clarabel without equilibration: about 4x faster on these tiny, well-scaled LMIs."""
    return _clarabel_run(problem, rho, margin, equilibrate=False)


def _clarabel(problem: LMIProblem, rho: float, margin: float):
    """Clarabel with its default (equilibrated) settings."""
    return _clarabel_run(problem, rho, margin, equilibrate=True)


def _scs(problem: LMIProblem, rho: float, margin: float):
    """SCS at tight tolerance: the independent second opinion."""
    import scs

    form = _form(problem, upper=False)
    with np.errstate(all="ignore"):
        A, b = form.data(rho, margin)
    if not finite_data(A, b):
        return "failed", None, "non-finite problem data"
    sizes = form.sizes
    n = problem.nvar
    # SCS wants the nonnegative rows first, then the PSD cones: reorder rows.
    offsets = np.cumsum([0] + [s * (s + 1) // 2 for s in sizes])
    order = [i for i, s in enumerate(sizes) if s == 1] + [i for i, s in enumerate(sizes) if s > 1]
    rows = np.concatenate([np.arange(offsets[i], offsets[i + 1]) for i in order])
    data = {"A": sps.csc_matrix(A[rows]), "b": b[rows], "c": np.zeros(n)}
    cone = {"l": sum(1 for s in sizes if s == 1), "s": [s for s in sizes if s > 1]}
    with c_stdout_to_stderr():  # SCS's C code prints some errors on stdout
        solver = scs.SCS(data, cone, verbose=False, eps_abs=1e-9, eps_rel=1e-9,
                         max_iters=5000)
        sol = solver.solve()
    return _raw_answer(str(sol["info"]["status"]), sol["x"])


@contextlib.contextmanager
def c_stdout_to_stderr():
    """Send writes to stdout (C-level file descriptor 1 and Python's sys.stdout) to stderr
    for the duration, so a solver's messages never mix into ``--json`` output."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):
        with contextlib.redirect_stdout(sys.stderr):
            yield
        return
    try:
        os.dup2(2, 1)
        with contextlib.redirect_stdout(sys.stderr):  # PySys_WriteStdout goes here
            yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def lmi_point(problem: LMIProblem, rho: float | None,
              near: bool = False) -> tuple[str, np.ndarray | None]:
    """One Clarabel solve of the blocks without margin: minimize r (= rho^2, a variable)
    when ``rho`` is None, else a feasibility point at rho (the solver's interior point).
    Returns (status, (y, r)) with y, r only when solved (or almost solved with ``near``:
    an estimate to start from, never a certificate)."""
    form = _form(problem, True)
    A, b = form.data(0.0 if rho is None else rho, 0.0)
    A, b = A.copy(), b.copy()
    q = np.zeros(problem.nvar)
    if rho is None:  # b(r) = b0 + r b1: move r into the variables
        A = sps.hstack([A, sps.csc_matrix(-form.b1[:, None])]).tocsc()
        q = np.zeros(problem.nvar + 1)
        q[-1] = 1.0
    cones = [("nonneg", 1) if s == 1 else ("psd", s) for s in form.sizes]
    zero = sps.csc_matrix((len(q), len(q)))
    try:
        sol = clarabel_solve(zero, q, A, b, cones, _clarabel_settings(True))
    except Exception as exc:  # noqa: BLE001 - a crash is no answer
        return f"exception: {type(exc).__name__}", None
    status = str(sol.status)
    kind = solver_status(status)
    if kind != SolverStatus.SOLVED and not (near and kind.near):
        return status, None
    return status, np.array(sol.x)


class _MarginForm:
    """Homogenized margin problem: max t s.t. G_h(x, c) + t I ⪯ 0 on strict blocks,
    the other blocks ⪯ 0, c >= 0 and c + sum of tr(-G_b(x)) over non-strict blocks = 1
    (for Theorem 1: c + tr P + lambda = 1), where G_h is G with its constant scaled by c.

    Every certificate of G ⪯ 0 rescales into this compact set, so t(rho) > 0 exactly when
    the LMI is strictly feasible; t(rho) is a continuous feasibility margin for root-finding.
    Variables z = (x, c, t). Clarabel's upper-triangular svec.
    """

    def __init__(self, problem: LMIProblem):
        nv = problem.nvar
        self.nz = nv + 2
        w = np.zeros(nv)
        a0, a1, eye, sizes = [], [], [], []
        blocks = problem.blocks
        i = 0
        while i < len(blocks):
            blk = blocks[i]
            s = blk.size
            if s == 1:  # a run of scalar rows (many in some families): stacked, no svec
                j = i
                while j < len(blocks) and blocks[j].size == 1:
                    j += 1
                run = blocks[i:j]
                r0 = np.column_stack([np.array([b.l0[:, 0, 0] for b in run]),
                                      [b.c0[0, 0] for b in run]])
                r1 = np.column_stack([np.array([b.l1[:, 0, 0] for b in run]),
                                      [b.c1[0, 0] for b in run]])
                strict = np.array([b.strict for b in run])
                w -= r0[~strict, :nv].sum(axis=0)
                a0.append(r0)
                a1.append(r1)
                eye.append(strict.astype(float))
                sizes += [1] * len(run)
                i = j
                continue
            i += 1
            if not blk.strict:
                w += -np.trace(blk.l0, axis1=1, axis2=2)
            a0.append(np.column_stack([svec(blk.l0, True).T, svec(blk.c0, True)]))
            a1.append(np.column_stack([svec(blk.l1, True).T, svec(blk.c1, True)]))
            eye.append(svec(np.eye(s) if blk.strict else np.zeros((s, s)), True))
            sizes.append(s)
        top0 = np.zeros((2, nv + 1))
        top0[0, :nv], top0[0, nv] = w, 1.0  # c + w.x = 1   (zero cone)
        top0[1, nv] = -1.0  # -c + s = 0, s >= 0             (c >= 0)
        a0m = np.vstack([top0] + a0)
        a1m = np.vstack([np.zeros_like(top0)] + a1)
        t_col = np.concatenate([[0.0, 0.0], np.concatenate(eye)])
        self.dense0 = np.column_stack([a0m, t_col])
        self.dense1 = np.column_stack([a1m, np.zeros_like(t_col)])
        self.b = np.zeros(self.dense0.shape[0])
        self.b[0] = 1.0
        self.q = np.zeros(self.nz)
        self.q[-1] = -1.0
        self.sizes = sizes
        self.A, self.v0, self.v1 = _csc_pattern(self.dense0, self.dense1)
        self.zero_P = _zero_csc(self.nz)
        self._cones: list | None = None
        # Clarabel solvers kept for data updates, by (rough, precise)
        self.solvers: dict[tuple[bool, bool], Any] = {}

    def cones(self) -> list:
        """Clarabel cones (built once): runs of scalar rows become one nonnegative cone."""
        if self._cones is None:
            import clarabel

            out = [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(1)]
            run = 0
            for s in self.sizes + [0]:
                if s == 1:
                    run += 1
                    continue
                if run:
                    out.append(clarabel.NonnegativeConeT(run))
                    run = 0
                if s > 1:
                    out.append(clarabel.PSDTriangleConeT(s))
            self._cones = out
        return self._cones

    def data(self, rho: float) -> sps.csc_matrix:
        self.A.data = self.v0 + rho * rho * self.v1
        return self.A

    def pattern(self, key: tuple) -> tuple:
        """What a kept Clarabel solver depends on besides A's numbers: A's sparsity pattern
        and cones (b and q follow from the shape), and the settings ``key``."""
        A = self.A
        return (key, A.shape, A.indptr.tobytes(), A.indices.tobytes(), tuple(self.sizes))


@functools.lru_cache(maxsize=32)
def _zero_csc(n: int) -> sps.csc_matrix:
    """The n x n zero matrix in CSC form (shared: Clarabel copies its data, nobody writes)."""
    return sps.csc_matrix((np.zeros(0), np.zeros(0, np.int32), np.zeros(n + 1, np.int32)),
                          shape=(n, n))


def _csc_pattern(dense0: np.ndarray, dense1: np.ndarray):
    """CSC matrix on the union of the nonzeros of two dense matrices (indices sorted), and
    the values of each at those positions (column-major order)."""
    cols, rows = np.nonzero((dense0 != 0).T | (dense1 != 0).T)
    indptr = np.zeros(dense0.shape[1] + 1, dtype=np.int32)
    np.cumsum(np.bincount(cols, minlength=dense0.shape[1]), out=indptr[1:])
    A = sps.csc_matrix((np.ones(len(rows)), rows.astype(np.int32), indptr), shape=dense0.shape)
    return A, dense0[rows, cols], dense1[rows, cols]


_MARGINS: weakref.WeakKeyDictionary[LMIProblem, _MarginForm] = weakref.WeakKeyDictionary()


@dataclass(frozen=True)
class Margin:
    """Feasibility margin t(rho) and, when t > 0 and c > 0, the rescaled certificate x/c."""

    ok: bool  # the solver reported solved
    t: float | None  # the solver's (primal) t: t(rho) >= t when ok
    x: np.ndarray | None
    detail: str = ""
    slope: float | None = None  # dt/drho from the dual solution (envelope theorem)
    t_upper: float | None = None  # the dual objective's bound: t(rho) <= t_upper (about)
    precise: bool = False  # solved at PRECISE_TOL

    def noise(self, floor: bool = True) -> float:
        """How far t(rho) may be above t: the duality gap and, with ``floor``, at least the
        solver's tolerance (where t is tiny the dual bound itself is only that accurate)."""
        gap = 0.0 if self.t is None or self.t_upper is None else max(self.t_upper - self.t, 0.0)
        return max(gap, PRECISE_TOL if self.precise else DEFAULT_TOL) if floor else gap

    def undecided(self, floor: bool = True) -> bool:
        """Whether a t <= 0 is within the solver's accuracy: t(rho) may still be > 0."""
        return self.ok and self.t is not None and self.t <= 0 < self.t + self.noise(floor)


def solve_margin(problem: LMIProblem, rho: float, rough: bool = False,
                 precise: bool = False, equilibrate: bool | None = None) -> Margin:
    """t(rho) of the homogenized margin problem (Clarabel without, then with equilibration).

    ``rough``: without Clarabel's iterative refinement of the linear solves (about 35 %
    faster, t differs in the 10th digit). Its status is still judged on residuals of the
    returned iterate, and a point becomes a certificate only through :func:`check_point`,
    so the rate search uses it for every test but the precise ones.
    ``precise``: Clarabel's tolerances at ``PRECISE_TOL`` instead of 1e-8, for a t whose
    sign the default leaves open (near the rate at large kappa, where t is tiny).
    ``equilibrate``: that one attempt only (None: without, then with equilibration)."""
    form = _MARGINS.get(problem)
    if form is None:
        form = _MARGINS[problem] = _MarginForm(problem)
    with np.errstate(all="ignore"):
        A = form.data(rho)
    if not finite_data(A):
        return Margin(False, None, None, "non-finite problem data", precise=precise)
    detail = ""
    for eq in (False, True) if equilibrate is None else (equilibrate,):
        try:
            sol = _margin_solve(form, A, eq, rough, precise)
        except Exception as exc:  # noqa: BLE001 - a crash is just "no answer"
            detail = f"exception: {type(exc).__name__}"
            continue
        detail = str(sol.status)
        if solver_status(detail) == SolverStatus.SOLVED:
            z = np.array(sol.x)
            t, c = float(z[-1]), float(z[-2])
            x = z[:-2] / c if (t > 0 and c > 0) else None
            # optimal value -t of min q'z s.t. A(r) z + s = b: d(-t)/dr = y' A1 z (y dual)
            slope = -float(np.asarray(sol.z) @ (form.dense1 @ z)) * 2.0 * rho
            upper = -float(sol.obj_val_dual)
            return Margin(True, t, x, detail, slope if np.isfinite(slope) else None,
                          upper if np.isfinite(upper) else None, precise)
    return Margin(False, None, None, detail, precise=precise)


def _margin_solve(form: _MarginForm, A: sps.csc_matrix, equilibrate: bool, rough: bool,
                  precise: bool) -> Any:
    """One Clarabel solve of the margin problem (a kept solver gets the new numbers)."""
    import clarabel

    key = (rough, precise)
    kept = form.solvers.get(key)
    if not equilibrate and kept is None:
        kept = form.solvers[key] = _shared_solvers().get(form.pattern(key))
    if not equilibrate and kept is not None:  # same pattern: update numbers
        kept.update(A=A.data.copy())
        return solve_or_raise(kept)
    solver = clarabel.DefaultSolver(form.zero_P, form.q, A, form.b, form.cones(),
                                    _clarabel_settings(equilibrate, not rough, precise))
    if not equilibrate and solver.is_data_update_allowed():
        form.solvers[key] = solver
        _shared_solvers().put(form.pattern(key), solver)
    return solve_or_raise(solver)


class _SolverCache:
    """Clarabel solvers by sparsity pattern, least recently used dropped: the margin
    problems of one method at other kappas or parameters (same pattern, other numbers) skip
    Clarabel's setup and get their numbers by ``update`` (the solve itself starts afresh)."""

    SIZE = 16

    def __init__(self) -> None:
        self.kept: OrderedDict[tuple, Any] = OrderedDict()

    def get(self, key: tuple) -> Any:
        solver = self.kept.get(key)
        if solver is not None:
            self.kept.move_to_end(key)
        return solver

    def put(self, key: tuple, solver: Any) -> None:
        self.kept[key] = solver
        if len(self.kept) > self.SIZE:
            self.kept.popitem(last=False)


_LOCAL = threading.local()  # one cache per thread: a solver is never shared across threads


def _shared_solvers() -> _SolverCache:
    cache = getattr(_LOCAL, "solvers", None)
    if cache is None:
        cache = _LOCAL.solvers = _SolverCache()
    return cache


class _Evaluator:
    """Every block of a problem evaluated at once: the scalar blocks (many in some families)
    as one matrix-vector product, the matrix blocks one by one (same sums as
    :meth:`~sosalgo.kernel.conic.AffineBlock.value`)."""

    def __init__(self, problem: LMIProblem):
        scal = [b for b in problem.blocks if b.size == 1]
        self.mats = [b for b in problem.blocks if b.size > 1]
        nv = problem.nvar
        self.s0 = np.array([b.l0[:, 0, 0] for b in scal]).reshape(len(scal), nv)
        self.s1 = np.array([b.l1[:, 0, 0] for b in scal]).reshape(len(scal), nv)
        self.c0 = np.array([b.c0[0, 0] for b in scal], dtype=float)
        self.c1 = np.array([b.c1[0, 0] for b in scal], dtype=float)
        self.has_s1 = bool(np.any(self.s1 != 0))

    def worst(self, x: np.ndarray, rho: float) -> float:
        """Largest eigenvalue over all blocks at (x, rho) (NaN when not evaluable)."""
        worst = -math.inf
        for b in self.mats:
            top = float(np.linalg.eigvalsh(b.value(x, rho))[-1])
            if top != top:
                return math.nan
            worst = top if top > worst else worst
        if len(self.c0):
            r2 = rho**2
            lin = self.s0 @ x
            if self.has_s1:
                lin = lin + r2 * (self.s1 @ x)
            vals = (self.c0 + r2 * self.c1) + lin
            top = float(vals.max())  # NaN when any entry is NaN
            if top != top:
                return math.nan
            worst = top if top > worst else worst
        return worst


_EVALUATORS: weakref.WeakKeyDictionary[LMIProblem, _Evaluator] = weakref.WeakKeyDictionary()


def check_point(problem: LMIProblem, rho: float, x: np.ndarray, solver: str) -> Outcome:
    """Trusted verdict on a candidate x: feasible only if every block passes in floats."""
    if x.shape != (problem.nvar,) or not np.all(np.isfinite(x)):
        return Outcome(Feasibility.FAILED, None, solver, "malformed point")
    x = problem.project(x)
    ev = _EVALUATORS.get(problem)
    if ev is None:
        ev = _EVALUATORS[problem] = _Evaluator(problem)
    try:
        with np.errstate(all="ignore"):
            worst = ev.worst(x, rho)
    except (np.linalg.LinAlgError, ValueError, OverflowError) as exc:
        return Outcome(Feasibility.FAILED, None, solver, f"certificate check failed ({exc})"[:200])
    if not worst <= 0.0:  # NaN fails: a check that cannot be evaluated never passes
        msg = f"certificate check failed (max eig {worst:.3g})"
        return Outcome(Feasibility.FAILED, None, solver, msg, near_boundary=True)
    return Outcome(Feasibility.FEASIBLE, x, solver, "checked")


RawSolver = Callable[[LMIProblem, float, float], tuple[str, "np.ndarray | None", str]]
SOLVERS: dict[str, RawSolver] = {
    "clarabel-fast": _clarabel_fast,
    "clarabel": _clarabel,
    "scs": _scs,
}
DEFAULT_SOLVERS: tuple[str, ...] = ("clarabel-fast", "clarabel", "scs")


def _checked(problem: LMIProblem, rho: float, name: str) -> Outcome:
    margin = margin_for(problem)
    try:
        status, x, detail = SOLVERS[name](problem, rho, margin)
    except Exception as exc:  # noqa: BLE001 - any solver crash is a failed step
        msg = f"exception: {type(exc).__name__}: {exc}"[:200]
        return Outcome(Feasibility.FAILED, None, name, msg)
    if status == "infeasible":
        return Outcome(Feasibility.INFEASIBLE, None, name, detail)
    if status != "solved" or x is None:
        return Outcome(Feasibility.FAILED, None, name, detail, near_boundary=status == "near")
    out = check_point(problem, rho, x, name)
    return out if not out.feasible else Outcome(Feasibility.FEASIBLE, out.x, name, detail)


def solve_lmi(
    problem: LMIProblem, rho: float, solvers: Sequence[str] = DEFAULT_SOLVERS
) -> Outcome:
    """Feasibility of ``problem`` at ``rho``.

    A failed step is retried with the next solver in ``solvers``. From the second solver
    on, a failure *near the boundary* (an "almost" status or a point that fails the
    eigenvalue check) ends the chain as ``failed``: the LMI is then feasible at best by
    a hair and a slower solver does not change that; hard errors go on to the next.
    """
    out = Outcome(Feasibility.FAILED, None, "", "no solver")
    for i, name in enumerate(solvers):
        out = _checked(problem, rho, name)
        if out.status != Feasibility.FAILED or (out.near_boundary and i >= 1):
            return out
    return out


# --------------------------------------------------------------------------- attempt lists


@contextlib.contextmanager
def _quiet_stderr():
    """Clarabel's Rust panics (caught below) print to file descriptor 2: hide them."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


@functools.cache
def _sdp_settings(precise: bool, reg: float, max_iter: int = 400, chordal: str = "apart",
                  equilibrate: bool = True) -> Any:
    """Settings of one attempt of :func:`solve_attempts` (tuned on PEP's dual SDPs)."""
    s = quiet_settings()
    s.max_iter = max_iter
    # off: the PEP's own scaling (powers of two on G, F and the rows) is kept as it is;
    # Clarabel's equilibration on top of it stalls the triple momentum method's duals
    s.equilibrate_enable = equilibrate
    s.static_regularization_constant = reg
    s.direct_solve_method = "faer"  # supernodal LDL: 2-4x faster on these dense rows
    # the dual form's chordal blocks kept apart with their overlaps as equalities (not
    # the compact merge): half the iterations (Nesterov N = 40: 24 instead of 44);
    # :data:`CHORDAL`: the fallbacks when Clarabel panics building the decomposition
    s.chordal_decomposition_compact = chordal == "compact"
    if chordal == "unmerged":
        s.chordal_decomposition_merge_method = "none"
    if precise:
        s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = 1e-10
        s.tol_ktratio = 1e-10
    return s


# chordal decompositions in order: blocks apart, then Clarabel's compact merge, then no
# merging (Clarabel 0.11 panics building the first on some patterns, "index out of
# bounds": gradient descent at N = 200; the others build)
CHORDAL = ("apart", "compact", "unmerged")


def solve_attempts(A: Any, q: np.ndarray, b: np.ndarray, cones: Sequence[Any],
                   attempts: tuple[tuple[Any, ...], ...], final: tuple[str, ...] = ()
                   ) -> tuple[Any, str, SolverStatus]:
    """min q'x s.t. A x + s = b, s in ``cones`` (see :func:`clarabel_cones`), tried with
    each attempt in turn: (solution or None, raw status, status) of the first attempt that
    ends solved or with a raw status in ``final`` (else the last). An attempt is (precise
    tolerances, static regularization[, max iterations or None[, equilibration]])."""
    cones = clarabel_cones(cones)
    P = sps.csc_matrix((A.shape[1], A.shape[1]))
    sol, raw, st_ = None, "no attempt ended", SolverStatus.FAILED
    for precise, reg, *rest in attempts:
        iters = [rest[0]] if rest and rest[0] else []
        equilibrate = bool(rest[1]) if len(rest) > 1 else True
        sol = _clarabel_attempt(P, q, A, b, cones, precise, reg, iters, equilibrate)
        if sol is None:
            continue
        raw = str(sol.status)
        st_ = solver_status(raw)
        if (st_ == SolverStatus.SOLVED or raw in final
                or (iters and sol.iterations >= iters[0])):  # capped: not converging
            break
    return sol, raw, st_


def _clarabel_attempt(P: Any, q: np.ndarray, A: Any, b: np.ndarray, cones: list[Any],
                      precise: bool, reg: float, iters: list[int],
                      equilibrate: bool = True) -> Any:
    """One attempt's solution, or None when Clarabel panics (Rust panics: an eigenvalue
    failure while solving; while building, the next chordal decomposition of
    :data:`CHORDAL` is tried). Ctrl-C and SIGTERM stop the solve
    (:mod:`sosalgo.kernel.interrupts`)."""
    import clarabel

    with _quiet_stderr():
        for chordal in CHORDAL:
            settings = _sdp_settings(precise, reg, *(iters or [400]), chordal, equilibrate)
            try:
                solver = clarabel.DefaultSolver(P, q, A, b, cones, settings)
            except BaseException as exc:
                _reraise_interruption(exc)
                continue
            try:
                with native_solve():
                    return watch(solver).solve()
            except BaseException as exc:
                _reraise_interruption(exc)
                return None
    return None


def _reraise_interruption(exc: BaseException) -> None:
    """Re-raise what is not a Clarabel failure: an interruption (Ctrl-C, SIGTERM), an exit,
    no memory. Rust panics surface as ``PanicException`` (a BaseException)."""
    if isinstance(exc, MemoryError) or not (isinstance(exc, Exception)
                                            or type(exc).__name__ == "PanicException"):
        raise exc
