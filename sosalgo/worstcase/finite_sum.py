"""``sosalgo pep`` of a finite-sum spec (``finite_sum:``): the worst case of the measure,
an expectation over the draws, after N steps (:mod:`sosalgo.worstcase.finite_sum_build` builds
the tree of outcomes exactly), its dual certificate proven in exact arithmetic, and
:func:`reprove_finite_sum` for ``sosalgo verify``.

The dual: measure <= t for every Gram matrix G and function values F of the PEP when
``t - measure - sum_k lambda_k form_k = <S, G>`` identically, lambda >= 0, S ⪰ 0; so
``t = m0 + sum_k lambda_k r_k`` (the constants), ``sum_k lambda_k q_k = -m_F`` (the
function values: equalities) and ``S = -M - sum_k lambda_k Q_k``. The proof takes the
solver's multipliers (from a solve with S ⪰ margin I) as rationals, solves the
equalities exactly on the largest ones, proves S ⪰ 0 in ball arithmetic for every
matrix of its enclosure, and rounds t up."""

from __future__ import annotations

import math
import time
from fractions import Fraction
from typing import Any

import numpy as np
import sympy as sp

from sosalgo.errors import InputError
from sosalgo.kernel.exact import Ball, enclose, fraction_str, prove_definite, rational
from sosalgo.spec import Spec
from sosalgo.worstcase.finite_sum_build import (
    NO_INITIAL,
    Form,
    PointSet,
    Problem,
    build_problem,
    check_own_conditions,
)

__all__ = ["MAX_COUNT", "exact_problem", "finite_sum_pep", "finite_sum_sizes",
           "reprove_finite_sum"]

MAX_COUNT = 64  # functions in the sum at most
MARGINS = (1e-9, 1e-8, 1e-7, 1e-6, 1e-5)  # S ⪰ margin * tau * I, in order
LOOSE = 1e-4  # a proof further above tau (relative) is not taken
MAX_MISSES = 2  # margins whose S fails the floating-point pre-check before giving up
NO_WITNESS = ("no worst-case witness for a finite sum (tau_proven is the proven upper "
              "bound)")


def _env(spec: Spec, kappa: float | None, steps: int) -> dict[Any, sp.Expr]:
    """m, L, kappa, the horizon N (the number of steps) and every parameter's value,
    exactly, by symbol."""
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.spec.types import value_order
    from sosalgo.worstcase.exact import exact_base

    env = dict(exact_base(spec, kappa))
    if "N" not in spec.parameters:
        env[sp.Symbol("N", real=True)] = sp.Integer(steps)
    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        env[spec.symbols[p]] = to_sympy(par.tied if par.is_tied else par.value).xreplace(env)
    return env


def _count(spec: Spec, env: dict[Any, sp.Expr], steps: int) -> int:
    from sosalgo.kernel.expr.parse import to_sympy

    fs = spec.finite_sum
    if fs.per_step:  # f_1..f_N: one function per step
        if not 1 <= steps <= MAX_COUNT:
            raise InputError(f"--steps: must be in 1..{MAX_COUNT} (one function per step, "
                             f"functions.{fs.function}.per_step), got {steps}")
        return steps
    n = to_sympy(fs.count).xreplace(env)
    n = sp.nsimplify(n) if getattr(n, "is_Float", False) else n
    if not (n.is_Integer and 1 <= int(n) <= MAX_COUNT):
        where = "finite_sum.blocks" if fs.blocks else f"functions.{fs.function}.count"
        raise InputError(f"{spec.source}: {where}: must be an integer in 1..{MAX_COUNT} "
                         f"here, got {n}")
    return int(n)


def _point_sets(spec: Spec, subs: dict[Any, sp.Expr], n: int) -> list[PointSet]:
    from sosalgo.classes import CLASSES
    from sosalgo.kernel.expr.parse import to_sympy

    fs = spec.finite_sum
    out = []
    drawn = [f for f in [fs.function] if f] + [f for f in spec.functions if f != fs.function]
    for name in drawn:
        decl = spec.functions[name]
        cls = CLASSES[decl.cls]
        if fs.per_step:
            check_own_conditions(cls, spec.source, name)
        elif not (cls.has_values and cls.tilt_invariant and cls.homogeneous) or \
                cls.exact_tilted({k: Ball(1) for k in cls.parameters}) is None:
            raise InputError(f"{spec.source}: functions.{name}.class: {decl.cls} is not "
                             "taken in a finite sum (convex classes with values and "
                             "homogeneous interpolation conditions)")
        params = {k: enclose(to_sympy(e).xreplace(subs)) for k, e in decl.params.items()}
        copies = [f"{name}{j + 1}" for j in range(n)] if name == fs.function else [name]
        out += [PointSet(label, cls, params) for label in copies]
    return out


def exact_problem(spec: Spec, kappa: float | None, steps: int, measure: str,
                  initial: str) -> Problem:
    """The exact PEP of the finite-sum ``spec`` (InputError for bad input)."""
    env = _env(spec, kappa, steps)
    n = _count(spec, env, steps)
    named = {str(k): v for k, v in env.items()}
    return build_problem(spec.finite_sum, n, named, _point_sets(spec, env, n), steps,
                         measure, initial, spec.source)


def _matrix(form: Form, d: int) -> np.ndarray:
    M = np.zeros((d, d))
    for (a, b), v in form.g.items():
        if a == b:
            M[a, a] += float(v.c)
        else:
            M[a, b] += float(v.c) / 2
            M[b, a] += float(v.c) / 2
    return M


def _vector(form: Form, nv: int) -> np.ndarray:
    out = np.zeros(nv)
    for k, v in form.v.items():
        out[k] += float(v.c)
    return out


def null_directions(pb: Problem) -> list[int]:
    """Basis vectors no term squares (no diagonal entry in any constraint nor in the
    measure: a free vector, a normal vector of an indicator): S ⪰ 0 needs their rows of S
    zero, so the margin leaves them out and the proof checks them exactly zero."""
    diag = {a for f in [*pb.forms, pb.measure] for (a, b) in f.g if a == b}
    return [a for a in range(pb.d) if a not in diag]


def _pruned(pb: Problem, lam: list[Fraction], top: float) -> list[Fraction]:
    """``lam`` with the multipliers of the constraints that touch a null direction set to
    0 where they are solver noise (below 1e-4 of the largest: a constraint touching a
    null direction only through cross terms must have multiplier 0 for S ⪰ 0)."""
    null = set(null_directions(pb))
    if not null:
        return lam
    out = list(lam)
    for k, f in enumerate(pb.forms):
        if out[k] and float(out[k]) < 1e-4 * top and any(a in null or b in null
                                                         for a, b in f.g):
            out[k] = Fraction(0)
    return out


def _solve(pb: Problem, margin: float) -> tuple[str, float | None, np.ndarray | None]:
    """:func:`_solve_once` at tolerances 1e-10, then at Clarabel's defaults."""
    got = _solve_once(pb, margin, True)
    return got if got[0] != "failed" else _solve_once(pb, margin, False)


def _solve_once(pb: Problem, margin: float, precise: bool
                ) -> tuple[str, float | None, np.ndarray | None]:
    """(status, t, lambda) of the dual with S ⪰ margin I; "unbounded" when no
    certificate exists. Clarabel on (lambda, svec S): min r'lambda with the value
    equalities, svec(S) + sum lambda svec(Q) = svec(-M - margin I), lambda >= 0, S in the
    PSD cone (S a variable of its own: the form with S eliminated stalls on degenerate
    duals, point SAGA's)."""
    import scipy.sparse as sps

    from sosalgo.kernel.conic import svec
    from sosalgo.kernel.solvers import (
        SolverStatus,
        clarabel_solve,
        quiet_settings,
        solver_status,
    )

    K, d, nv = len(pb.forms), pb.d, pb.nv
    T = d * (d + 1) // 2
    Q = np.array([_matrix(f, d) for f in pb.forms])
    qv = np.array([_vector(f, nv) for f in pb.forms]).reshape(K, nv)
    r = np.array([float(f.const.c) for f in pb.forms])
    M, mv = _matrix(pb.measure, d), _vector(pb.measure, nv)
    # the basis scaled by powers of two that even out the diagonals (S' = W S W: the
    # same multipliers; a point SAGA with L = 0.1 and c = 1000 is solved to 1e-6 else)
    diag = np.abs(Q).sum(axis=0).diagonal() + np.abs(M).diagonal()
    w = 2.0 ** -np.round(np.log2(np.sqrt(np.where(diag > 0, diag, 1.0))))
    Q, M = Q * np.outer(w, w), M * np.outer(w, w)
    csc = sps.csc_matrix
    A = sps.vstack([sps.hstack([csc(qv.T), csc((nv, T))]),
                    sps.hstack([csc(svec(Q).T), sps.eye(T)]),
                    sps.hstack([-sps.eye(K), csc((K, T))]),
                    sps.hstack([csc((T, K)), -sps.eye(T)])]).tocsc()
    ident = np.eye(d)
    ident[null_directions(pb), null_directions(pb)] = 0.0
    b = np.concatenate([-mv, svec(-M - margin * ident), np.zeros(K + T)])
    settings = quiet_settings()
    if precise:
        settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-10
        settings.tol_ktratio = 1e-10
        settings.max_iter = 60  # a degenerate dual stalls there: the defaults next
    sol = clarabel_solve(csc((K + T, K + T)), np.concatenate([r, np.zeros(T)]), A, b,
                         [("zero", nv + T), ("nonneg", K), ("psd", d)], settings)
    st = solver_status(str(sol.status))
    if st == SolverStatus.INFEASIBLE:
        return "unbounded", None, None
    if st not in (SolverStatus.SOLVED, SolverStatus.ALMOST_SOLVED):
        return "failed", None, None
    lam = np.maximum(np.asarray(sol.x, float)[:K], 0.0)
    return "solved", float(r @ lam) + float(pb.measure.const.c), lam


def _pivots(rows: list[list[Fraction]], order: list[int]) -> list[int]:
    """Columns (in ``order``) independent in the exact matrix ``rows``, up to its rank."""
    chosen: list[int] = []
    basis: list[list[Fraction]] = []  # reduced columns with their pivot rows
    pivrow: list[int] = []
    for c in order:
        v = [row[c] for row in rows]
        for b, pr in zip(basis, pivrow, strict=True):
            if v[pr]:
                f = v[pr] / b[pr]
                v = [x - f * y for x, y in zip(v, b, strict=True)]
        nz = next((k for k, x in enumerate(v) if x), None)
        if nz is not None:
            chosen.append(c)
            basis.append(v)
            pivrow.append(nz)
    return chosen


def _solve_exact(A: list[list[Fraction]], rhs: list[Fraction]) -> list[Fraction] | None:
    """x with A x = rhs exactly (A: rows x cols, cols independent), None if none."""
    rows = [list(r) + [b] for r, b in zip(A, rhs, strict=True)]
    ncol = len(A[0]) if A else 0
    r0 = 0
    where = []
    for c in range(ncol):
        p = next((k for k in range(r0, len(rows)) if rows[k][c]), None)
        if p is None:
            return None
        rows[r0], rows[p] = rows[p], rows[r0]
        piv = rows[r0][c]
        rows[r0] = [x / piv for x in rows[r0]]
        for k in range(len(rows)):
            if k != r0 and rows[k][c]:
                f = rows[k][c]
                rows[k] = [x - f * y for x, y in zip(rows[k], rows[r0], strict=True)]
        where.append(r0)
        r0 += 1
    if any(row[-1] for row in rows[r0:]):
        return None
    return [rows[w][-1] for w in where]


def _balanced(pb: Problem, lam: list[Fraction]) -> list[Fraction] | None:
    """``lam`` with the value equalities made exact on its largest entries (None: not
    possible with them nonnegative, or a value coefficient is not exact)."""
    if not pb.nv:
        return lam
    if any(v.r for f in [*pb.forms, pb.measure] for v in f.v.values()):
        return None
    E = [[Fraction(0)] * len(pb.forms) for _ in range(pb.nv)]
    for k, f in enumerate(pb.forms):
        for i, v in f.v.items():
            E[i][k] += v.c
    target = [-pb.measure.v[i].c if i in pb.measure.v else Fraction(0) for i in range(pb.nv)]
    order = sorted(range(len(lam)), key=lambda k: -lam[k])
    piv = _pivots(E, [k for k in order if lam[k] > 0])
    rest = [sum((E[i][k] * lam[k] for k in range(len(lam)) if k not in piv), Fraction(0))
            for i in range(pb.nv)]
    sol = _solve_exact([[E[i][k] for k in piv] for i in range(pb.nv)],
                       [t - r for t, r in zip(target, rest, strict=True)])
    if sol is None or any(v < 0 for v in sol):
        return None
    out = list(lam)
    for k, v in zip(piv, sol, strict=True):
        out[k] = v
    return out


def prove(pb: Problem, lam: list[Fraction]) -> tuple[bool, Fraction | None, str]:
    """(proven, t's upper end, detail) for exact multipliers ``lam`` >= 0 that make the
    value equalities hold exactly: S = -M - sum lambda Q proven ⪰ 0."""
    if any(v < 0 for v in lam):
        return False, None, "a negative multiplier"
    for i in range(pb.nv):
        tot = sum((lam[k] * f.v[i].c for k, f in enumerate(pb.forms) if i in f.v),
                  Fraction(0))
        want = -pb.measure.v[i].c if i in pb.measure.v else Fraction(0)
        if tot != want or any(i in f.v and f.v[i].r and lam[k]
                              for k, f in enumerate(pb.forms)):
            return False, None, f"the function values do not cancel (value {i})"
    S = pb.measure.times(Ball(-1))
    t = pb.measure.const
    for k, f in enumerate(pb.forms):
        if lam[k]:
            S = S.plus(f.times(Ball(lam[k])), -1)
            t = t + Ball(lam[k]) * f.const
    half = Fraction(1, 2)
    mat = [[Ball(0) for _ in range(pb.d)] for _ in range(pb.d)]
    for (a, b), v in S.g.items():
        if a == b:
            mat[a][a] = mat[a][a] + v
        else:
            mat[a][b] = mat[a][b] + v * half
            mat[b][a] = mat[b][a] + v * half
    # a row exactly 0 (centre and radius) leaves S ⪰ 0 to the others
    keep = [a for a in range(pb.d) if any(x.c or x.r for x in mat[a])]
    mat = [[mat[a][b] for b in keep] for a in keep]
    if not mat:
        return True, t.hi, "S = 0, the values cancel exactly"
    ok, delta, why = prove_definite(mat, 1)
    if not ok:
        return False, None, f"S is not proven PSD: {why}"
    return True, t.hi, f"S ⪰ {float(delta):.3g} I ({why}), the values cancel exactly"


def _attempts(per_step: bool) -> list[tuple[float, bool | None]]:
    """(margin, solver tolerances) in order: a per-step program tries each margin at
    tolerance 1e-10, then at Clarabel's defaults (the first stops early on its larger
    PEPs); the others :func:`_solve` (the defaults only where the first fails)."""
    if per_step:
        return [(rel, precise) for rel in MARGINS for precise in (True, False)]
    return [(rel, None) for rel in MARGINS]


def _certificate(pb: Problem, tau: float, spec: Spec, kappa: float | None
                 ) -> dict[str, Any]:
    from sosalgo.worstcase.exact import class_description, decimal_up

    cert: dict[str, Any] = {"tau": tau, "check_kind": "floating-point check",
                            "tau_proven": None, "proof": None}
    t0 = time.perf_counter()
    detail = "no certificate solved"
    inexact = any(v.r for f in [*pb.forms, pb.measure] for v in f.g.values())
    misses = 0
    per_step = spec.finite_sum.per_step  # its null rows are handled: every margin tried
    for rel, precise in _attempts(per_step):
        status, t, lam = (_solve(pb, rel * max(tau, 1e-12)) if precise is None else
                          _solve_once(pb, rel * max(tau, 1e-12), precise))
        if status != "solved" or lam is None:
            continue
        top = float(lam.max(initial=0.0))
        lq = _pruned(pb, [rational(v) if v > 1e-13 * top else Fraction(0) for v in lam],
                     top)
        lq2 = _balanced(pb, lq)
        if lq2 is None:
            detail = "the value equalities cannot be made exact with multipliers >= 0"
            continue
        S = -_matrix(pb.measure, pb.d) - sum(
            (float(v) * _matrix(f, pb.d) for v, f in zip(lq2, pb.forms, strict=True) if v),
            np.zeros((pb.d, pb.d)))
        live = [a for a in range(pb.d) if np.any(S[a])]
        low = float(np.linalg.eigvalsh(S[np.ix_(live, live)])[0]) if live else 0.0
        # the exact proof would fail: a semidefinite S is proven only in rationals
        if low < (1e-12 if inexact else -1e-12) * max(1.0, float(np.abs(S).max())):
            detail = f"floating-point pre-check: S is not PSD (least eigenvalue {low:.3g})"
            misses += 1
            # S singular whatever the margin: no S > 0 exists
            if misses >= MAX_MISSES and not per_step:
                break
            continue
        ok, upper, detail = prove(pb, lq2)
        if not ok or upper is None:
            continue
        if float(upper) > tau * (1 + LOOSE):  # true, but not this worst case's bound
            detail = f"the certificate proves only {float(upper):.10g}"
            continue
        tq = decimal_up(upper)
        cert["multipliers"] = {lab: float(v) for lab, v in zip(pb.labels, lq2, strict=True)
                               if v}
        proof = {"proven": True, "tau_proven": fraction_str(tq),
                 "tau_proven_float": float(tq), "detail": detail,
                 "multipliers_exact": {lab: fraction_str(v) for lab, v in
                                       zip(pb.labels, lq2, strict=True) if v},
                 "class": class_description(spec, kappa), "leaves": pb.leaves,
                 "seconds": time.perf_counter() - t0}
        cert.update(check_kind="exact (rational and ball arithmetic)",
                    tau_proven=proof["tau_proven"], proof=proof, margin=rel * tau)
        break
    if cert["tau_proven"] is None:
        cert["proof"] = {"proven": False, "tau_proven": None, "detail": detail}
    cert["basis"] = pb.basis
    return cert


def finite_sum_pep(spec: Spec, kappa: float | None, steps: int, measure: str | None,
                   initial: str | None, exact: bool = True) -> dict[str, Any]:
    """The PEP of the finite-sum ``spec``: the fields of a
    :class:`~sosalgo.worstcase.core.PEPResult` (measure, initial, status, tau, gap,
    certificate, extra)."""
    measure, initial = _terms(spec, measure, initial)
    pb = exact_problem(spec, kappa, steps, measure, initial)
    status, tau, lam = _solve(pb, 0.0)
    out: dict[str, Any] = {"measure": measure, "initial": initial, "status": status,
                           "tau": tau, "gap": None, "certificate": None,
                           "extra": {"outcomes": pb.leaves}}
    if spec.finite_sum.per_step:  # step k calls f_k: one outcome, no draw
        out["extra"]["per_step"] = spec.finite_sum.function
    if status == "unbounded":
        out["tau"] = math.inf
        out["extra"]["note"] = "the measure is unbounded for this initial condition"
    elif status == "solved" and tau is not None:
        out["gap"] = 0.0
        out["certificate"] = _certificate(pb, tau, spec, kappa) if exact else {
            "tau": tau, "check_kind": "floating-point check", "tau_proven": None,
            "proof": None, "basis": pb.basis}
        if "multipliers" not in out["certificate"] and lam is not None:
            top = float(lam.max(initial=0.0))
            out["certificate"]["multipliers"] = {
                lab: float(v) for lab, v in zip(pb.labels, lam, strict=True)
                if v > 1e-12 * top}
        out["extra"]["note"] = NO_WITNESS
    return out


def finite_sum_sizes(spec: Spec, kappas: list[float | None], steps: list[int],
                     measure: str | None, initial: str | None) -> list[tuple[int, int]]:
    """Every input error before anything is written, and the (constraints, basis) sizes
    of each PEP of a run (for the memory budget)."""
    from sosalgo.worstcase.bind import has_kappa

    m, i = _terms(spec, measure, initial)
    out = []
    for k in kappas:
        if (k is None) == has_kappa(spec):
            raise InputError(f"{spec.source}: --kappa: " + (
                "required (the condition number L/m)" if k is None else
                "an m: 0 spec has no condition number"))
        for n in steps:
            pb = exact_problem(spec, k, n, m, i)
            out.append((len(pb.forms), pb.d))
    return out


def _terms(spec: Spec, measure: str | None, initial: str | None) -> tuple[str, str]:
    m = measure or spec.pep.get("measure")
    i = initial or spec.pep.get("initial")
    if spec.finite_sum.per_step and m and not i:  # the class's constants give the scale
        return m, NO_INITIAL
    if not m or not i:
        raise InputError(f"{spec.source}: pep: a finite-sum spec gives its measure and "
                         "initial condition (pep: {measure: 'E[...]', initial: ...})")
    return m, i


def reprove_finite_sum(spec: Spec, kappa: float | None, steps: int, measure: str,
                       initial: str, proof: dict[str, Any]) -> tuple[bool, str]:
    """(proven, detail): measure <= ``proof["tau_proven"]`` proven again from the proof's
    exact multipliers (by label) on the exact PEP rebuilt here; nothing is solved."""
    lab = proof.get("multipliers_exact")
    if not isinstance(lab, dict) or not isinstance(proof.get("tau_proven"), str):
        return False, "the proof carries no exact multipliers (multipliers_exact)"
    try:
        tq = Fraction(proof["tau_proven"])
        pb = exact_problem(spec, kappa, int(steps), measure, initial)
        index = {name: k for k, name in enumerate(pb.labels)}
        unknown = [k for k in lab if k not in index]
        if unknown:
            return False, f"multiplier {unknown[0]!r} is not a constraint of this PEP"
        lam = [Fraction(0)] * len(pb.labels)
        for name, v in lab.items():
            lam[index[name]] = Fraction(v)
    except (ValueError, TypeError, ZeroDivisionError, ArithmeticError, KeyError) as exc:
        return False, f"malformed proof: {type(exc).__name__}: {exc}"
    ok, upper, why = prove(pb, lam)
    if not ok or upper is None:
        return False, why
    if upper > tq:
        return False, f"the certificate proves {float(upper):.10g}, above {proof['tau_proven']}"
    return True, why
