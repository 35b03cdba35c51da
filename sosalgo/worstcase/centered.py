"""Exact proofs of PEPs whose optimal dual S is singular (an optimum of high degree).

At the optimum tau* the dual slack S = tau I0 - M - sum lambda_k Q_k is often singular
on a large subspace (the whole space when the certificate has S = 0, as for OGM-G), and
tau* is algebraic of high degree: no rational or quadratic-field multipliers reach it,
and rounding the solver's multipliers breaks S ⪰ 0. A slightly larger bound
tau' = tau (1 + rel) is proven instead, from a certificate pushed into the interior:

1. :func:`centered_multipliers`: the float SDP at the fixed bound tau', maximizing the
   least eigenvalue t of the scaled S on the complement of its structural null space
   (the basis directions no form has a square of, where S is 0 whatever the multipliers,
   :func:`sosalgo.worstcase.sdp.linear_only`), with c_F >= 0;
2. :func:`projected_multipliers`: the multipliers as rationals, moved exactly (in
   rationals, the largest ones solved from the others) onto the affine space where S's
   structural rows are exactly 0 and the value residuals the float certificate leaves at
   about 0 are exactly 0; a multiplier that this makes negative is dropped, a value
   residual it makes negative is held at 0, and the step repeated;
3. the exact check of :func:`sosalgo.worstcase.exact.prove_at`, nothing repaired: every
   multiplier >= 0, c_F >= 0 and S ⪰ 0 (a Cholesky factor with a ball residual, or LDL^T
   in exact rationals when S keeps its structural zero rows).

Any guess is safe: step 3 decides, in exact or outward-rounded arithmetic.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.worstcase.sdp import PEPData, linear_only, residual, value_residual
from sosalgo.worstcase.structure import PEPFrame, PEPStructure

# the bounds tau' = tau (1 + rel) tried, in order: within 1e-6 of tau (relative)
CENTER_RELS = (1e-8, 1e-7, 5e-7)
# value residuals at most this (relative to the largest |c_F|, scaled) are made exactly 0
ZERO_VALUES = (1e-9, 1e-7, 1e-5)
DROP = 1e-14  # multipliers below this share of the largest are left out (0)
PROJECTIONS = 12  # projections repeated (a multiplier made negative dropped, a c_F
# made negative held at 0)
CENTER_TOLS = (1e-10, None)  # Clarabel's tolerances of the centered solve (None: default)
CENTER_MAX_PAIRS = 2000  # rows of the centered SDP (all pairs up to this, else the active)


def centerable(data: PEPData) -> bool:
    """Whether the centered proof applies: a PEP with x*, an initial condition, no
    constants (the bound is tau itself), no block multipliers, and a basis of at most
    RATIONAL_MAX_D columns (the exact check's; the centered SDP holds every Q_k dense)."""
    from sosalgo.worstcase.exact import RATIONAL_MAX_D

    st = data.st
    return not (st.bare or st.free_values or st.constants is not None or data.blocks
                or np.any(data.consts()) or st.d > RATIONAL_MAX_D)


def centered_multipliers(data: PEPData, tau: float, values: bool
                         ) -> tuple[np.ndarray, float] | None:
    """(lambda, t): multipliers of the bound ``tau`` with the scaled S ⪰ t P (P the
    projector on the directions some form has a square of) and the scaled c_F >= t
    (``values``; else >= 0), t as large as possible (at most the size of S's data);
    None when the solve fails or t <= 0."""
    import cvxpy as cp

    st, d = data.st, data.st.d
    rows = (np.arange(st.count) if st.count <= CENTER_MAX_PAIRS
            else np.union1d(data.active, np.arange(len(st.pairs), st.count)))
    ww = np.outer(data.w, data.w)
    Q = [_dense(data, k) * ww for k in rows]
    norms = np.array([max(float(np.abs(q).max()), float(np.abs(data.a[k] * data.v).max(
        initial=0.0))) for q, k in zip(Q, rows, strict=True)])
    keep = norms > 0  # a row with no coefficient (0 >= 0) has nothing to give
    rows, norms = rows[keep], norms[keep]
    Q = [q for q, k in zip(Q, keep, strict=True) if k]
    base = (tau * st.init_q.astype(float) - st.meas_q.astype(float)) * ww
    size = max(float(np.abs(base).max()), float(norms.max(initial=0.0)), 1e-300)
    flat = np.stack([(q / n).ravel(order="F") for q, n in zip(Q, norms, strict=True)], 1)
    mu, t = cp.Variable(len(rows), nonneg=True), cp.Variable()
    S = cp.reshape(base.ravel(order="F") / size - flat @ mu, (d, d), order="F")
    a = data.a[rows] / norms[:, None] * size  # lambda_k = mu_k size / norm_k
    cF = (tau * st.init_f.astype(float) - st.meas_f.astype(float)) * data.v
    cons = [0.5 * (S + S.T) >> t * np.diag(linear_only(data)),
            cF / size - (a * data.v).T @ mu / size >= (t if values else 0), t <= 1]
    problem = cp.Problem(cp.Maximize(t), cons)
    for tol in CENTER_TOLS:  # tight first; Clarabel may fail there, not at its defaults
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "may be inaccurate": the proof decides
                problem.solve(solver="CLARABEL", **({} if tol is None else {
                    "tol_gap_abs": tol, "tol_gap_rel": tol, "tol_feas": tol}))
        except (cp.error.SolverError, ValueError, ArithmeticError):
            continue
        if mu.value is not None and t.value is not None and t.value > 0:
            break
    else:
        return None
    lam = np.zeros(st.count)
    lam[rows] = np.maximum(np.asarray(mu.value), 0.0) * size / norms
    return lam, float(t.value)


def _dense(data: PEPData, k: int) -> np.ndarray:
    """Q_k (unscaled) as a dense symmetric matrix: S's change per unit of lambda_k."""
    lam = np.zeros(data.st.count)
    lam[k] = 1.0
    return -residual(data, 0.0, lam) - data.st.meas_q.astype(float)


def projected_multipliers(mt: PEPFrame, st: PEPStructure, lam: np.ndarray, tq: Fraction,
                          cf: np.ndarray, units: list[int], zero: float
                          ) -> list[Fraction] | None:
    """Exact multipliers >= 0 near ``lam`` with S e_u = 0 for each u of ``units`` and
    c_F[i] = 0 where the float ``cf`` (c_F at tq) is at most ``zero`` of its largest
    entry, or where a projection left c_F[i] < 0 (step 2 of the module); None when the
    data are not exact rationals or the system has no solution on the multipliers'
    support."""
    from sosalgo.kernel.exact import rational
    from sosalgo.worstcase.exact import exact_pair_parts, fraction_matrix

    top = float(np.max(lam, initial=0.0))
    support = [k for k, v in enumerate(lam) if v > DROP * top]
    fi, fm = fraction_matrix([st.init_f]), fraction_matrix([st.meas_f])
    if not support or fi is None or fm is None:
        return None
    rhs_f = [tq * a - b for a, b in zip(fi[0], fm[0], strict=True)]  # c_F = rhs_f - A lam
    values = {k: rational(float(lam[k])) for k in support}
    tight = {i for i in range(st.nF) if cf[i] <= zero * max(1.0, float(np.abs(cf).max()))}
    for _ in range(PROJECTIONS):
        parts = exact_pair_parts(mt, st, support)
        eqs = None if parts is None else _unit_rows(st, parts[0], units, tq)
        if eqs is None:
            return None
        lins = parts[1]  # type: ignore[index]
        for i in sorted(tight):
            eqs[0].append([a[i] for a in lins])
            eqs[1].append(rhs_f[i])
        got = _pivot_projection(*eqs, [values[k] for k in support])
        if got is None:
            return None
        values = dict(zip(support, got, strict=True))
        low = {i for i in range(st.nF) if i not in tight and rhs_f[i] < sum(
            (values[k] * a[i] for k, a in zip(support, lins, strict=True)), Fraction(0))}
        if low or any(values[k] < 0 for k in support):  # again without the multipliers
            support = [k for k in support if values[k] > 0]  # made <= 0 (a 0 has no
            tight |= low  # weight), with c_F held at 0 where it went negative
            continue
        out = [Fraction(0)] * len(lam)
        for k in support:
            out[k] = values[k]
        return out
    return None


def _unit_rows(st: PEPStructure, quads: list[Any], units: list[int], tq: Fraction
               ) -> tuple[list[list[Fraction]], list[Fraction]] | None:
    """The equations S e_u = 0 (u in ``units``), linear in the multipliers of ``quads``;
    None when the data are not exact or a row reads 0 = nonzero."""
    from sosalgo.worstcase.exact import fraction_matrix, null_equations

    I0, M = fraction_matrix(st.init_q), fraction_matrix(st.meas_q)
    if I0 is None or M is None:
        return None
    if not units:
        return [], []
    null = [[Fraction(int(j == u)) for j in range(st.d)] for u in units]
    eqs, rhs = null_equations(st, quads, null, tq, I0, M)
    return None if eqs is None else (eqs, rhs)


def _pivot_projection(eqs: list[Any], rhs: list[Fraction],
                      x: list[Fraction]) -> list[Fraction] | None:
    """A solution of ``eqs`` x = ``rhs`` near x, in exact rationals: the reduced row
    echelon form with the columns in decreasing order of x, so that the pivots (solved
    from the others, which keep their values) are the largest multipliers, whose
    relative change is the least; the denominators stay those of the data and of x.
    None when the system is inconsistent."""
    from sosalgo.kernel.exact import solve_affine

    if not eqs:
        return list(x)
    order = sorted(range(len(x)), key=lambda c: -x[c])
    rows = [row if isinstance(row, Mapping) else dict(enumerate(row)) for row in eqs]
    got = solve_affine([{i: row[c] for i, c in enumerate(order) if c in row} for row in rows],
                       rhs, len(x),
                       lambda i: x[order[i]])
    if got is None:
        return None
    out = [Fraction(0)] * len(x)
    for i, c in enumerate(order):
        out[c] = got[i]
    return out


def prove_centered(mt: PEPFrame, st: PEPStructure, data: PEPData, lam: np.ndarray,
                   tq: Fraction) -> tuple[bool, list[Fraction], Fraction, str]:
    """(proven, multipliers, delta, detail) of measure <= tq from the centered ``lam``
    (steps 2 and 3 of the module): rounded as they are when S has no structural zero
    row, then projected at each of :data:`ZERO_VALUES` until one proves."""
    units = [c for c, v in enumerate(linear_only(data)) if v == 0]
    from sosalgo.kernel.exact import rational
    from sosalgo.worstcase.exact import prove_at

    if not units:  # S ≻ 0 on every direction: rounded, c_F repaired, in ball arithmetic
        ok, lq, delta, why = prove_at(mt, st, [rational(v) if v > 0 else Fraction(0)
                                               for v in lam], tq, data.w, repair=True)
        if ok:
            return ok, lq, delta, f"centered certificate; {why}"
    cf = value_residual(data, float(tq), lam) * data.v
    why = "the centered multipliers have no exact projection"
    for zero in ZERO_VALUES:
        exact_lam = projected_multipliers(mt, st, lam, tq, cf, units, zero)
        if exact_lam is None:
            continue
        ok, lq, delta, why = prove_at(mt, st, exact_lam, tq, data.w, repair=False)
        if ok:
            return ok, lq, delta, f"centered certificate, projected exactly; {why}"
    return False, [], Fraction(0), why
