"""Exact (rational) verification of a composite certificate (the interpolation family on
the oracle model, :mod:`sosalgo.certificates.composite`).

The certificate (rho, P, p, c, multipliers) of a method with several oracle calls,
proximal steps and other function classes is checked in original units, without floating
point in the proof path:

1. The method is made exact (:func:`sosalgo.exact_method.exact_algorithm`): rational kappa,
   m, L (exact binary values of the floats), rational balls around irrational entries of
   A, B, C, D, E; every function's class parameters from the spec's expressions, likewise.
   D is checked lower triangular with diagonal entries <= 0, and the fixed point of every
   optimal point (x* = 1, s* = 0; x* = 0 with each free optimal subgradient) is solved and
   proven with sympy.
2. The windows (row maps, points of each function, tilted class inequalities of every
   ordered pair, measure) are rebuilt here on exact numbers, independently of the float
   builder, with the same labels. The classes' inequalities come from exact formulas for
   the shipped classes; a class with an ``exact_tilted(params)`` method gives its own; any
   other class's float data is enclosed at relative radius 2^-40 (said in the proofs).
3. P, p, c and the multipliers are rounded to rationals; negative multipliers become 0 and
   the weights p (or c) are raised where the positivity function-value rows need it (a
   larger weight of a nonnegative value only increases V). Then (D) ⪯ 0, (Df) <= 0,
   (Pq) ⪰ 0 and (Pf) >= 0 are proven (exact LDL^T with the enclosure radius, as for the
   seed's interpolation family, :mod:`sosalgo.certificates.exact_interpolation`) at rho or a
   rational slightly above it.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np
import sympy as sp

from sosalgo.certificates.exact_interpolation import (
    InterpolationExactResult,
    Refused,
    float_entry,
    rational_near,
    settle,
    symmetric_matrix,
)
from sosalgo.exact_method import ExactOracleMethod, exact_oracle_method
from sosalgo.kernel.exact import (
    DEFAULT_DIGITS,
    DEFAULT_MAX_DEN,
    DEFAULT_RHO_STEPS,
    Ball,
    Verdict,
    fraction_str,
    is_zero,
    prove_definite,
    rational,
    rho_candidates,
    symmetrize_balls,
)
from sosalgo.model import bind
from sosalgo.spec.types import ORACLE_MATRIX_NAMES, Spec

__all__ = ["CompositeExactResult", "ExactOracleMethod", "exact_class_inequalities",
           "exact_oracle_method", "fixed_point_failure", "verify_exact_composite"]

FLOAT_CLASS_RADIUS = Fraction(1, 2**40)  # relative radius of a class's float data


@dataclass
class CompositeExactResult(InterpolationExactResult):
    """Outcome of :func:`verify_exact_composite` (``to_dict``: what a re-check needs)."""

    model: dict[str, Any] = field(default_factory=dict)  # measure, oracles, output, classes

    def to_dict(self) -> dict[str, Any]:
        doc = super().to_dict()
        doc["certificate_family"] = ("interpolation on the oracle model (Lyapunov function "
                                     "with function values, tilted class inequalities)")
        return doc | self.model


# --------------------------------------------------------------------------- class data


def exact_class_inequalities(cls: Any, params: Mapping[str, Ball], pinned: bool = False,
                             ) -> tuple[list[tuple[Ball, np.ndarray]], str]:
    """(alpha, Q) of every tilted inequality of a class at exact parameters (the class's
    :meth:`~sosalgo.classes.base.FunctionClass.exact_tilted`, every entry as a ball), and
    where they come from ("exact" or the float enclosure). ``pinned``: its optimal
    subgradient is 0 (:meth:`~sosalgo.classes.base.FunctionClass.exact_pinned`)."""
    exact = cls.exact_pinned(params) if pinned else cls.exact_tilted(params)
    if exact is not None:
        return [(Ball.of(a), np.vectorize(Ball.of, otypes=[object])(np.asarray(Q, object)))
                for a, Q in exact], "exact"
    fl = (cls.pinned if pinned else cls.tilted)({k: float(b.c) for k, b in params.items()})

    def widen(v: float) -> Ball:
        q = Fraction(float(v))
        return Ball(q, abs(q) * FLOAT_CLASS_RADIUS)

    out = [(widen(i.alpha), np.vectorize(widen, otypes=[object])(np.asarray(i.Q, float)))
           for i in fl]
    return out, "float data enclosed at relative 2^-40"


# --------------------------------------------------------------------------- windows


@dataclass
class _Pt:
    func: int
    label: str
    x: np.ndarray  # row on w (object)
    g: np.ndarray
    psi: int | None


@dataclass
class ExactWindow:
    """One window on exact numbers (as :class:`sosalgo.certificates.composite.CWindow`)."""

    width: int
    nphi: int
    Z: dict[int, np.ndarray]
    F: dict[int, np.ndarray]
    labels: list[str]
    Mq: list[np.ndarray]
    mq: list[np.ndarray]
    meas_lin: np.ndarray
    meas_quad: np.ndarray


def _zeros(*shape: int) -> np.ndarray:
    return np.full(shape, Ball(0), dtype=object)


def _eye(k: int, width: int, start: int = 0) -> np.ndarray:
    out = _zeros(k, width)
    for i in range(k):
        out[i, start + i] = Ball(1)
    return out


def _window_points(om: ExactOracleMethod, steps: int, lag: int):
    """Rows (output points per time) and the points of every function in the order of the
    float builder (calls by time and call, output points, the optimum)."""
    n, p, J = om.n, om.p, len(om.functions)
    x_times: list[int] = []
    extra: list[int] = []
    if om.measure == "function":
        x_times = [t for t in (steps - 2, steps - 1) if t >= lag]
        out_f = None if om.output is None else om.oracles[om.output]
        extra = [j for j in range(J) if j != out_f]
    width = n + p * steps + len(extra) * len(x_times)
    U = [_eye(p, width, n + p * t) for t in range(steps)]
    Xi = [_eye(n, width)]
    for t in range(steps - 1):
        Xi.append(om.A @ Xi[t] + om.B @ U[t])
    Y = [om.C @ Xi[t] + om.D @ U[t] for t in range(steps)]
    out = {t: Y[t][om.output] if om.output is not None else (om.E @ Xi[t])[0]
           for t in range(steps)}
    pts: list[list[_Pt]] = [[] for _ in range(J)]
    k = 0
    valued = [getattr(cls, "has_values", True) for _, cls, _ in om.functions]  # operator: none
    for t in range(steps):
        for i, j in enumerate(om.oracles):
            pts[j].append(_Pt(j, f"y{i + 1}[{t}]", Y[t][i], U[t][i], k if valued[j] else None))
            k += valued[j]
    col = n + p * steps
    for t in x_times:
        for j in extra:
            pts[j].append(_Pt(j, f"x[{t}]", out[t], _eye(1, width, col)[0], k))
            k += 1
            col += 1
    for j in range(J):
        pts[j].append(_Pt(j, "*", _zeros(width), _zeros(width), None))
    return {"Xi": Xi, "U": U, "out": out, "width": width}, pts, k


def _window_inequalities(om: ExactOracleMethod, pts: list[list[_Pt]], nphi: int,
                         ineqs: list[list[tuple[Ball, np.ndarray]]]):
    """Labels, quadratic and phi parts of every tilted inequality of every ordered pair."""
    labels, Mq, mq = [], [], []
    for j, (fname, _, _) in enumerate(om.functions):
        for a, pa in enumerate(pts[j]):
            for b, pb in enumerate(pts[j]):
                if a == b:
                    continue
                X = np.vstack([pa.x, pb.x, pa.g, pb.g])
                for r, (alpha, Q) in enumerate(ineqs[j]):
                    lin = _zeros(nphi)
                    if pa.psi is not None:
                        lin[pa.psi] = lin[pa.psi] + alpha
                    if pb.psi is not None:
                        lin[pb.psi] = lin[pb.psi] - alpha
                    tag = "" if len(ineqs[j]) == 1 else f"#{r}"
                    labels.append(f"{fname}:{pa.label}>{pb.label}{tag}")
                    Mq.append(X.T @ (Q @ X))
                    mq.append(lin)
    return labels, Mq, mq


def exact_window(om: ExactOracleMethod, lag: int, steps: int,
                 ineqs: list[list[tuple[Ball, np.ndarray]]]) -> ExactWindow:
    """The window of times 0..steps-1 (decrease: lag + 2 steps; positivity: lag + 1)."""
    rows, pts, nphi = _window_points(om, steps, lag)
    labels, Mq, mq = _window_inequalities(om, pts, nphi, ineqs)
    psi_of = {pt.label: pt.psi for fp in pts for pt in fp if pt.psi is not None}
    has_x = any(pt.label.startswith("x[") for fp in pts for pt in fp)
    Z, F = {}, {}
    for t in range(lag, steps):
        Z[t] = np.vstack([rows["Xi"][t]] + [rows["U"][t - tau] for tau in range(lag + 1)])
        sel = [[psi_of[lab]] if (lab := f"y{i + 1}[{t - tau}]") in psi_of else []
               for tau in range(lag + 1) for i in range(om.p)]  # []: an operator's call
        if has_x:
            sel.append([pt.psi for fp in pts for pt in fp if pt.label == f"x[{t}]"])
        Ft = _zeros(len(sel), nphi)
        for r, cols in enumerate(sel):
            for q in cols:
                Ft[r, q] = Ball(1)
        F[t] = Ft
    t = steps - 1
    meas_lin, meas_quad = _zeros(nphi), _zeros(rows["width"], rows["width"])
    if om.measure == "distance":
        xo = rows["out"][t]
        meas_quad = np.outer(xo, xo)
    elif om.measure == "residual":  # sum_i |u_i|^2 of the calls at t
        meas_quad = rows["U"][t].T @ rows["U"][t]
    elif om.measure == "state_change":  # |xi_t+1 - xi_t|^2 (several operators)
        dx = om.A @ rows["Xi"][t] - rows["Xi"][t] + om.B @ rows["U"][t]
        meas_quad = dx.T @ dx
    else:
        here = {f"x[{t}]"} | ({f"y{om.output + 1}[{t}]"} if om.output is not None else set())
        for pt in (pt for fp in pts for pt in fp if pt.label in here):
            meas_lin[pt.psi] = Ball(1)
    return ExactWindow(rows["width"], nphi, Z, F, labels, Mq, mq, meas_lin, meas_quad)


# --------------------------------------------------------------------------- the proof


@dataclass
class _CCert:
    lag: int
    P: np.ndarray  # object array of Fractions
    pi: list[Fraction]  # p (p calls x (lag + 1)), then c when the method has one
    eta: list[Fraction]
    lam: list[Fraction]


def verify_exact_composite(
    spec: Spec, kappa: float, rho: float, cert: Mapping[str, Any],
    theta: Mapping[str, float] | None = None, *, max_den: int = DEFAULT_MAX_DEN,
    rho_steps: tuple[float, ...] = DEFAULT_RHO_STEPS, digits: int = DEFAULT_DIGITS,
    **_: Any,
) -> CompositeExactResult:
    """Prove in exact arithmetic that ``cert`` certifies ``rho`` (or a rational slightly
    above it) for the exact method of the composite ``spec`` at ``kappa`` (module doc)."""
    start = time.perf_counter()
    res = CompositeExactResult(spec=spec.name, verified=Verdict.FAILED,
                               rho_requested=float(rho))
    try:
        om = _exact_method(spec, kappa, theta, digits, res)
        lag = _lag(cert, spec)
        ineqs, sources = zip(*(exact_class_inequalities(c, pr) for _, c, pr in om.functions),
                             strict=True)
        dec = exact_window(om, lag, lag + 2, list(ineqs))
        pos = exact_window(om, lag, lag + 1, list(ineqs))
        c = _read(cert, om, lag, dec, pos, max_den)
        if not np.isfinite(float(rho)) or not 0 < rational(rho) <= 1:
            raise Refused(f"rho = {rho!r} is not in (0, 1]")
        _raise_weights(pos, c)
        res.certificate = _rational(c, dec, pos, om.p)
        res.model["classes"] = {f: f"{cls.name}: {src}" for (f, cls, _), src
                                in zip(om.functions, sources, strict=True)}
        res.reason = _prove(res, dec, pos, c, rational(rho), rho_steps, max_den)
    except Refused as exc:
        res.reason = str(exc)
    res.seconds = time.perf_counter() - start
    return res


def _exact_method(spec: Spec, kappa: float, theta: Mapping[str, float] | None, digits: int,
                  res: CompositeExactResult) -> ExactOracleMethod:
    """The exact method, checked against the float one, D well posed, fixed points proven."""
    try:
        om = exact_oracle_method(spec, kappa, theta, digits)
        alg = bind(spec, float(kappa), theta)
    except ValueError as exc:
        raise Refused(f"the exact method cannot be built: {exc}") from None
    res.kappa, res.m, res.L = fraction_str(om.kappa), fraction_str(om.m), fraction_str(om.L)
    res.params = {k: str(v) for k, v in om.params.items()}
    res.enclosures = om.enclosures()
    res.model = {"measure": om.measure, "inputs": om.p, "oracles": list(spec.oracles),
                 "output": None if om.output is None else f"y{om.output + 1}",
                 "functions": {f: {"class": c.name, **{k: [fraction_str(b.lo), fraction_str(
                     b.hi)] for k, b in pr.items()}} for f, c, pr in om.functions}}
    for k in (k for k in ORACLE_MATRIX_NAMES if k in om.balls):
        cen = np.array([[float(b.c) for b in row] for row in om.balls[k]])
        if not np.allclose(cen, getattr(alg, k), rtol=1e-9, atol=1e-9):
            raise Refused(f"exact matrix {k} differs from sosalgo.model.bind")
    for i in range(om.p):
        if om.D[i, i].hi > 0 or any(om.D[i, j].lo != 0 or om.D[i, j].hi != 0
                                    for j in range(i + 1, om.p)):
            raise Refused(f"D is not lower triangular with diagonal <= 0 (row {i + 1})")
    bad = fixed_point_failure(om, alg)
    if bad:
        raise Refused(bad)
    return om


def fixed_point_failure(om: ExactOracleMethod, alg: Any) -> str | None:
    """None when xi* exists exactly for x* = 1 (s* = 0) and for x* = 0 with each free
    optimal subgradient (sympy, algebraic entries); else why not."""
    mats = om.matrices
    n, p = om.n, om.p
    S = sp.Matrix(alg.optimal_map().astype(int).tolist()) if alg.optimal_map().size else \
        sp.zeros(p, 0)
    D = mats.get("D", sp.zeros(p, p))
    if om.output is None:
        erow, drow = mats["E"], sp.zeros(1, p)
    else:
        erow, drow = mats["C"][om.output, :], D[om.output, :]
    lhs = sp.Matrix.vstack(sp.eye(n) - mats["A"], mats["C"], erow)
    cols = [sp.Matrix([0] * n + [1] * (p + 1))]
    for j in range(S.shape[1]):
        s = S[:, j]
        cols.append(sp.Matrix.vstack(mats["B"] * s, -D * s, -drow * s))
    for k, rhs in enumerate(cols):
        try:
            sol, free = lhs.gauss_jordan_solve(rhs)
            sol = sol.subs({t: 0 for t in free})
        except ValueError:
            return f"fixed point {k} (x* = {1 if k == 0 else 0}) has no solution"
        if not all(is_zero(r) for r in lhs * sol - rhs):
            return f"fixed point {k} (x* = {1 if k == 0 else 0}) not proven"
    return None


def _lag(cert: Mapping[str, Any], spec: Spec) -> int:
    try:
        lag = int(cert["lag"])
    except (KeyError, TypeError, ValueError) as exc:
        raise Refused(f"malformed certificate: lag: {exc}") from None
    if not 0 <= lag <= 8:
        raise Refused(f"lag {lag} not in 0..8")
    for key, want in (("measure", spec.measure), ("inputs", spec.p)):
        if cert.get(key) is not None and cert[key] != want:
            raise Refused(f"certificate {key} {cert[key]!r} is not the spec's {want!r}")
    return lag


def _read(cert: Mapping[str, Any], om: ExactOracleMethod, lag: int, dec: ExactWindow,
          pos: ExactWindow, max_den: int) -> _CCert:
    """P (symmetrized), the weights and the multipliers as rationals (negatives as 0)."""
    nz = om.n + om.p * (lag + 1)
    npv = om.p * (lag + 1)
    has_c = pos.F[lag].shape[0] > npv
    try:
        P = symmetric_matrix(cert["P"], nz, float_entry(max_den))
        p = list(cert["p"])
        if len(p) != npv:
            raise Refused(f"p has {len(p)} weights, expected {npv}")
        if has_c != (cert.get("c") is not None):
            raise Refused("c " + ("missing: the measure needs f at the output point" if has_c
                                   else "given but the method has no output-point term"))
        pi = [rational_near(v, max_den) for v in p + ([cert["c"]] if has_c else [])]
        mult = cert["multipliers"]
        eta = [max(Fraction(0), rational_near(mult["decrease"][k], max_den)) for k in dec.labels]
        lam = [max(Fraction(0), rational_near(mult["positivity"][k], max_den)) for k in pos.labels]
    except KeyError as exc:
        raise Refused(f"malformed certificate: missing {exc}") from None
    except (TypeError, ValueError, OverflowError) as exc:
        raise Refused(f"malformed certificate: {type(exc).__name__}: {exc}") from None
    return _CCert(lag, P, pi, eta, lam)


def _raise_weights(pos: ExactWindow, c: _CCert) -> None:
    """Raise p (or c) until every positivity function-value row holds (upper ends)."""
    Fp = pos.F[c.lag]
    for q in range(pos.nphi):
        owners = [r for r in range(Fp.shape[0]) if Fp[r, q].c == 1]
        if not owners:
            continue
        need = Ball.of(pos.meas_lin[q]) + sum(
            (lv * mv[q] for lv, mv in zip(c.lam, pos.mq, strict=True)), Ball(0))
        # the row is pi[owner] - need >= 0 (other owners of column q are raised too)
        others = sum((c.pi[r] for r in owners[1:]), Fraction(0))
        c.pi[owners[0]] = max(c.pi[owners[0]], _ceil(need.hi - others))


def _ceil(x: Fraction, max_den: int = 10**15) -> Fraction:
    """A rational >= x with a bounded denominator."""
    y = x.limit_denominator(max_den)
    return y if y >= x else y + Fraction(1, max_den)


def _rational(c: _CCert, dec: ExactWindow, pos: ExactWindow, p: int) -> dict[str, Any]:
    nz = c.P.shape[0]
    npv = p * (c.lag + 1)
    return {"lag": c.lag, "P": [[fraction_str(c.P[i, j]) for j in range(nz)] for i in range(nz)],
            "p": [fraction_str(v) for v in c.pi[:npv]],
            "c": fraction_str(c.pi[npv]) if len(c.pi) > npv else None,
            "multipliers": {
                "decrease": dict(zip(dec.labels, map(fraction_str, c.eta), strict=True)),
                "positivity": dict(zip(pos.labels, map(fraction_str, c.lam), strict=True))}}


def _parts(dec: ExactWindow, pos: ExactWindow, c: _CCert) -> dict[str, Any]:
    """The rho-free pieces: D = G1 - r G0, Df = g1 - r g0, Pq, Pf."""
    lag, pi = c.lag, np.array(c.pi, dtype=object)
    Z1, Z0, Zp = dec.Z[lag + 1], dec.Z[lag], pos.Z[lag]
    G1 = Z1.T @ c.P @ Z1
    for e, M in zip(c.eta, dec.Mq, strict=True):
        if e:
            G1 = G1 + M * e
    g1 = dec.F[lag + 1].T @ pi
    for e, mv in zip(c.eta, dec.mq, strict=True):
        if e:
            g1 = g1 + mv * e
    Pq = Zp.T @ c.P @ Zp - pos.meas_quad
    Pf = pos.F[lag].T @ pi - pos.meas_lin
    for lv, M, mv in zip(c.lam, pos.Mq, pos.mq, strict=True):
        if lv:
            Pq = Pq - M * lv
            Pf = Pf - mv * lv
    return {"G1": G1, "G0": Z0.T @ c.P @ Z0, "g1": g1, "g0": dec.F[lag].T @ pi, "Pq": Pq,
            "Pf": Pf}


def _prove(res: CompositeExactResult, dec: ExactWindow, pos: ExactWindow, c: _CCert,
           rho: Fraction, rho_steps: tuple[float, ...], max_den: int) -> str | None:
    """Try rho and rationals slightly above it; the first proven one goes into ``res``."""
    pt = _parts(dec, pos, c)
    bad_pf = [i for i, b in enumerate(map(Ball.of, pt["Pf"])) if b.lo < 0]
    ok_p, delta_p, det_p = prove_definite(symmetrize_balls(pt["Pq"]), +1)
    first_fail = None
    for rq in rho_candidates(rho, list(rho_steps), max_den):
        res.attempts += 1
        r = rq * rq
        D = pt["G1"] - pt["G0"] * r
        bad_df = [i for i, b in enumerate(map(Ball.of, pt["g1"] - pt["g0"] * r)) if b.hi > 0]
        ok_d, delta_d, det_d = prove_definite(symmetrize_balls(D), -1)
        why = settle(res, rq, bad_df, bad_pf, (ok_d, delta_d, det_d), (ok_p, delta_p, det_p))
        if why is None:
            res.proofs["classes"] = "; ".join(f"{k}: {v}" for k, v in
                                              res.model.get("classes", {}).items())
            return None
        first_fail = first_fail or why
    return first_fail
