"""Exact (rational) verification of a sublinear certificate (``m: 0``,
:mod:`sosalgo.certificates.sublinear`): ``measure(x_k) <= C |x_0 - x*|^2 / k`` for k >= 1.

The certificate (P, Q, R, p, q, r, b, the multipliers' coefficients, the S-procedure
auxiliaries S, K of degree 2 and the constant C) is checked in original units without
floating point in the proof path:

1. The method is made exact: L is the exact binary value of the spec's L, m = 0, the
   parameters and matrices are the spec's expressions evaluated by sympy (``theta``: the
   exact binary values of the given floats); every entry and class parameter must be a
   rational number (else: not proven, with the entry named). The fixed point u of x* = 1
   (the start at rest) is solved exactly and must be unique.
2. The windows (points, tilted class inequalities of every ordered pair, measure) are
   those of :func:`sosalgo.certificates.exact_composite.exact_window`, on these exact numbers.
3. The conditions are written here from their definition (docs/sublinear.md), as
   affine forms in the certificate's variables (:class:`Lin`): (D) phi_{k+1} - phi_k +
   sum eta(k) q <= 0 and (P) (k + b) measure + sum lam(k) q - phi_k <= 0 as polynomials in
   k (degree 2: ``[[A0, Y], [Y', A2]] <= 0``, Y = (A1 + S)/2 + K, S >= 0, K skew), (I)
   phi_0 + sum nu q <= C |x_0|^2 started at rest; coefficient rows on the function values
   <= 0, multipliers' coefficients >= 0, b >= 0.
4. With m = 0 some directions are singular for every certificate (the minimizer moving
   with zero gradients: the exact direction v = (u, 0)) and some rows are at 0. The other
   directions are those the analysis imposed (``certificate.kernels``; for a certificate
   without them: found at the float certificate, |eigenvalue| <= 1e-11 relative, snapped
   within 1e-9 to small fractions by :func:`sosalgo.certificates.base.snap_basis`);
   the rows at 0 are found at the float certificate. All are imposed as exact equalities
   G K = 0 and row = 0 (any basis is sound: G K = 0 exactly and the exact LDL^T below
   decide G <= 0 together): the rounded certificate is moved onto them by an
   exact rational solve (the moved values must stay within 1e-8 of the given ones: a
   repair of rounding, not a new certificate). Then every block is proven <= 0 by an exact
   LDL^T (:func:`sosalgo.kernel.exact.prove_psd` of -G, which decides semidefiniteness
   exactly) and every row <= 0 exactly; C is raised by a relative 1e-12 .. 1e-6 when the
   initial block needs it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from fractions import Fraction
from math import comb
from typing import Any

import numpy as np
import scipy.linalg as sla
import sympy as sp

from sosalgo.certificates.composite import STATE_CHANGE
from sosalgo.certificates.exact_composite import exact_class_inequalities, exact_window
from sosalgo.certificates.exact_interpolation import Refused
from sosalgo.exact_method import ball_method
from sosalgo.kernel.exact import Ball, Verdict, fraction_str, prove_psd
from sosalgo.kernel.expr.parse import to_sympy
from sosalgo.oracles import BoundFunction, Method
from sosalgo.spec.types import BASE_SYMBOLS, ORACLE_MATRIX_NAMES, Spec, value_order

__all__ = ["Lin", "SublinearExactResult", "exact_sublinear_method", "verify_exact_sublinear"]

KERNEL_TOL = 1e-11  # eigenvalue / row above -tol * scale at the float certificate: at 0
MOVE_TOL = 1e-8  # largest move (relative to max(1, |x|)) the exact projection may make
SNAP_TOL = 1e-9  # kernel entries this close to a small fraction (denominator <= 16) are it
CONSTANT_STEPS = (0.0, 1e-12, 1e-10, 1e-8, 1e-6)  # relative increases of C tried
STATEMENT = ("measure(x_k) <= C |x_0 - x*|^2 / k for every k >= 1, every x* minimizing the "
             "sum of the functions (an operator's zero: measure residual, sum_i |u_i|^2 of "
             "the calls at step k) and every function of the classes, the method started at "
             "rest at x_0 (xi_0 - xi* = u (x_0 - x*)), C = constant_proven")
STATE_STATEMENT = ("|xi_k+1 - xi_k|^2 <= C |xi_0 - xi*|^2 / k for every k >= 1, every start "
                   "xi_0, every zero x* of the sum of the operators with its answers s_j* "
                   "(sum 0) and xi* the fixed point they give (measure state_change: several "
                   "operators), and every operator of the classes, C = constant_proven")


@dataclass
class SublinearExactResult:
    """Outcome of :func:`verify_exact_sublinear` (``to_dict``: plain values)."""

    spec: str
    verified: Verdict
    constant_requested: float | None
    constant_proven: str | None = None
    constant_proven_float: float | None = None
    reason: str | None = None
    seconds: float = 0.0
    L: str = ""
    params: dict[str, str] = field(default_factory=dict)
    degree: int | None = None
    measure: str | None = None  # the measure proven (residual: an operator's calls;
    # state_change: |xi_k+1 - xi_k|^2 of several operators, from a free start)
    equalities: int = 0  # rank of the exact equalities imposed
    kernels: dict[str, int] = field(default_factory=dict)  # dimension per block
    moved: float | None = None  # largest change made by the exact projection
    proofs: dict[str, str] = field(default_factory=dict)
    attempts: int = 0
    certificate: dict[str, Any] | None = None  # the proven certificate, exact strings

    @property
    def ok(self) -> bool:
        return self.verified == Verdict.EXACT

    def to_dict(self) -> dict[str, Any]:
        return {"certificate_family": "sublinear potential (weights polynomial in k)",
                "spec": self.spec, "verified": str(self.verified),
                "constant_requested": self.constant_requested,
                "constant_proven": self.constant_proven,
                "constant_proven_float": self.constant_proven_float, "reason": self.reason,
                "seconds": self.seconds, "L": self.L, "m": "0", "params": dict(self.params),
                "degree": self.degree, "measure": self.measure,
                "equalities": self.equalities,
                "kernels": dict(self.kernels), "moved": self.moved,
                "proofs": dict(self.proofs), "attempts": self.attempts,
                "statement": (STATE_STATEMENT if self.measure == STATE_CHANGE
                              else STATEMENT), "certificate": self.certificate}


# --------------------------------------------------------------------------- affine forms


class Lin:
    """An exact affine form ``c + sum_i t[i] x_i`` in the certificate's variables."""

    __slots__ = ("c", "t")

    def __init__(self, c: Fraction | int = 0, t: dict[int, Fraction] | None = None):
        self.c = Fraction(c)
        self.t = t if t is not None else {}

    @staticmethod
    def var(i: int) -> Lin:
        return Lin(0, {i: Fraction(1)})

    def __add__(self, o: Any) -> Lin:
        if not isinstance(o, Lin):
            return Lin(self.c + o, self.t)
        t = dict(self.t)
        for k, v in o.t.items():
            s = t.get(k, 0) + v
            if s:
                t[k] = s
            else:
                t.pop(k, None)
        return Lin(self.c + o.c, t)

    __radd__ = __add__

    def __neg__(self) -> Lin:
        return Lin(-self.c, {k: -v for k, v in self.t.items()})

    def __sub__(self, o: Any) -> Lin:
        return self + (-o)

    def __rsub__(self, o: Any) -> Lin:
        return (-self) + o

    def __mul__(self, o: Any) -> Lin:
        if isinstance(o, Lin):
            raise TypeError("a product of two affine forms is not affine")
        o = Fraction(o)
        return Lin(self.c * o, {k: v * o for k, v in self.t.items()} if o else {})

    __rmul__ = __mul__

    def at(self, x: list[Fraction]) -> Fraction:
        """The exact value at x."""
        return self.c + sum((v * x[k] for k, v in self.t.items()), Fraction(0))

    def at_float(self, x: np.ndarray) -> float:
        return float(self.c) + sum(float(v) * x[k] for k, v in self.t.items())


def _lin(v: Any) -> Lin:
    return v if isinstance(v, Lin) else Lin(v)


# --------------------------------------------------------------------------- the method


def _rational_of(expr: sp.Expr, where: str) -> Fraction:
    val = sp.sympify(expr)  # spec literals are exact (decimals are decimal rationals)
    if not val.is_Rational:
        raise Refused(f"{where} = {expr} is not a rational number (exact verification of "
                      "sublinear certificates needs rational data)")
    return Fraction(int(val.p), int(val.q))


def exact_sublinear_method(spec: Spec, theta: Mapping[str, float] | None = None,
                           ) -> Method:
    """The method of a sublinear spec on exact rationals (m = 0, L the binary value of the
    spec's L, ``theta`` as exact binary values); :class:`Refused` when an entry or a class
    parameter is not rational."""
    from sosalgo.classes import CLASSES

    if spec.has_condition_number or spec.L is None:
        raise Refused("not a sublinear spec (m: 0, L given)")
    Lq = Fraction(spec.L)
    values: dict[sp.Symbol, sp.Expr] = {BASE_SYMBOLS["m"]: sp.Integer(0),
                                        BASE_SYMBOLS["L"]: sp.Rational(Lq.numerator,
                                                                       Lq.denominator)}
    params: dict[str, sp.Expr] = {}
    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        if theta is not None and p in theta:
            q = Fraction(float(theta[p]))
            val: sp.Expr = sp.Rational(q.numerator, q.denominator)
        else:
            val = to_sympy(par.tied if par.is_tied else par.value).xreplace(values)
        params[p] = sp.Rational(*_rational_of(val, f"parameters.{p}").as_integer_ratio())
        values[spec.symbols[p]] = params[p]
    mats, balls = {}, {}
    for k in (k for k in ORACLE_MATRIX_NAMES if k in spec.sympy_matrices()):
        mats[k] = spec.sympy_matrices()[k].xreplace(values)
        balls[k] = np.array([[Ball(_rational_of(mats[k][i, j], f"matrices.{k}[{i}][{j}]"))
                              for j in range(mats[k].shape[1])]
                             for i in range(mats[k].shape[0])], dtype=object)
    funcs = tuple(BoundFunction(f, CLASSES[d.cls],
                                {k: Ball(_rational_of(to_sympy(e).xreplace(values),
                                                      f"functions.{f}.{k}"))
                                 for k, e in d.params.items()})
                  for f, d in spec.functions.items())
    return ball_method(spec, balls, Fraction(0), Lq, funcs, params, mats, {})


def _exact(M: np.ndarray) -> np.ndarray:
    """Ball entries of radius 0 as Fractions (every entry here is rational)."""
    out = np.empty(M.shape, dtype=object)
    for idx, b in np.ndenumerate(M):
        b = Ball.of(b)
        if b.r:
            raise Refused("an inexact entry in the windows")
        out[idx] = b.c
    return out


def _fixed_point(om: Method) -> list[Fraction]:
    """u with (I - A) u = 0, C u = 1 (every call at x* = 1) and the output at 1: unique."""
    n = om.n
    A = sp.Matrix(om.A.shape[0], om.A.shape[1], [b.c for b in om.A.ravel()])
    C = sp.Matrix(om.p, n, [b.c for b in om.C.ravel()])
    out = (C[om.output, :] if om.output is not None
           else sp.Matrix(1, n, [b.c for b in om.E.ravel()]))
    lhs = sp.Matrix.vstack(sp.eye(n) - A, C, out)
    rhs = sp.Matrix([0] * n + [1] * (om.p + 1))
    try:
        sol, free = lhs.gauss_jordan_solve(rhs)
    except ValueError:
        raise Refused("the method has no fixed point at x* = 1") from None
    if free.shape[0]:
        raise Refused("the start at rest (fixed point of x* = 1) is not unique")
    return [Fraction(int(v.p), int(v.q)) for v in sol]


def _moving(om: Method, dec: Any, pos: Any) -> tuple[np.ndarray, np.ndarray]:
    """Exact (decrease, positivity) window directions of a stationary point moved with the
    optimal answers, as :func:`sosalgo.certificates.sublinear._moving_directions` (several
    operators, measured by the state change): (A - I) xi + B u = 0, C xi + D u = 0, the
    same answers at every time, on whose span every class form vanishes."""
    n = om.n
    none = (np.zeros((dec.width, 0), dtype=object), np.zeros((pos.width, 0), dtype=object))

    def mat(M: np.ndarray) -> sp.Matrix:
        return sp.Matrix(M.shape[0], M.shape[1], [Ball.of(b).c for b in M.ravel()])

    M = sp.Matrix.vstack(sp.Matrix.hstack(mat(om.A) - sp.eye(n), mat(om.B)),
                         sp.Matrix.hstack(mat(om.C), mat(om.D)))
    base = M.nullspace()
    if not base:
        return none
    Bm = sp.Matrix.hstack(*base)

    def lift(steps: int) -> sp.Matrix:
        return sp.Matrix.vstack(Bm[:n, :], *([Bm[n:, :]] * steps))

    Wd = lift(2)
    forms = [Wd.T * sp.Matrix(Mq.tolist()) * Wd for Mq in dec.Mq]
    keep = sp.Matrix.vstack(*forms).nullspace() if forms else [sp.eye(Wd.shape[1])]
    if not keep:
        return none
    K = sp.Matrix.hstack(*keep)

    def frac(A: sp.Matrix) -> np.ndarray:
        return np.array([[Fraction(int(sp.fraction(v)[0]), int(sp.fraction(v)[1]))
                          for v in row] for row in A.tolist()], dtype=object)

    return frac(Wd * K), frac(lift(1) * K)


def _windows(om: Method, float_om: Any) -> tuple[Any, Any, Method]:
    """The decrease (times 0, 1) and positivity (time 0) windows of lag 0, with the output
    point shared with its call when the float builder shares it (E = C_i, D_i = 0)."""
    from sosalgo.certificates.composite import output_call

    oc = output_call(float_om)
    if om.output is None and oc is not None:
        same = all(om.E[0, j].c == om.C[oc, j].c for j in range(om.n)) and not any(
            b.c for b in om.D[oc])
        if not same:
            raise Refused(f"the output is call y{oc + 1} in floating point, not exactly")
        om = replace(om, output=oc)
    found = [exact_class_inequalities(c, pr) for _, c, pr in om.functions]
    if any(not src.startswith("exact") for _, src in found):
        raise Refused("a function class without exact inequalities")
    ineqs = [i for i, _ in found]
    return exact_window(om, 0, 2, ineqs), exact_window(om, 0, 1, ineqs), om


# --------------------------------------------------------------------------- the unknowns

WEIGHTS, VALUES = ("P", "Q", "R"), ("p", "q", "r")


def _unknowns(nz: int, npi: int, dec: Any, pos: Any, deg: int) -> dict[str, tuple[str, int]]:
    """Name -> (kind, size) of every unknown in order (sym/skew: square matrices)."""
    out = {WEIGHTS[j]: ("sym", nz) for j in range(deg + 1)}
    out |= {VALUES[j]: ("vec", npi) for j in range(deg + 1)}
    out["b"] = ("vec", 1)
    for j in range(deg + 1):
        out |= {f"eta{j}": ("vec", len(dec.labels)), f"lam{j}": ("vec", len(pos.labels))}
    out["nu"] = ("vec", len(pos.labels))
    if deg == 2:
        out |= {"S_D": ("sym", dec.width), "K_D": ("skew", dec.width),
                "S_P": ("sym", pos.width), "K_P": ("skew", pos.width)}
    out["C"] = ("vec", 1)  # the constant: fixed, never moved
    return out


def _pairs(kind: str, n: int) -> list[tuple[int, int]]:
    if kind == "vec":
        return [(i, 0) for i in range(n)]
    return [(i, j) for i in range(n) for j in range(i + (kind == "skew"), n)]


def _symbols(unk: dict[str, tuple[str, int]]) -> tuple[dict[str, np.ndarray], int]:
    """Each unknown as an array of :class:`Lin` (matrices symmetric or skew), and the count."""
    out, k = {}, 0
    for name, (kind, n) in unk.items():
        arr = np.full((n,) if kind == "vec" else (n, n), Lin(), dtype=object)
        for i, j in _pairs(kind, n):
            if kind == "vec":
                arr[i] = Lin.var(k)
            else:
                arr[i, j] = Lin.var(k)
                arr[j, i] = -arr[i, j] if kind == "skew" else arr[i, j]
            k += 1
        out[name] = arr
    return out, k


def _read(cert: Mapping[str, Any], unk: dict[str, tuple[str, int]], labels: dict[str, list],
          C: float) -> np.ndarray:
    """The certificate's values in the order of :func:`_unknowns` (floats)."""
    vals: list[float] = []
    for name, (kind, n) in unk.items():
        if name in ("S_D", "K_D", "S_P", "K_P") and name not in cert:
            raise Refused(f"certificate has no {name} (the S-procedure auxiliaries, written "
                          "since exact verification exists: rerun analyze)")
        if name == "C":
            vals.append(float(C))
        elif name == "b":
            vals.append(float(cert["b"]))
        elif kind == "vec" and name in VALUES:
            vec = [float(v) for v in cert[name]]
            if len(vec) != n:
                raise Refused(f"certificate {name} has {len(vec)} entries, expected {n}")
            vals += vec
        elif kind == "vec":
            got = cert["multipliers"][name]
            group = "eta" if name.startswith("eta") else "lam" if name.startswith("lam") else "nu"
            if set(got) != set(labels[group]):
                raise Refused(f"certificate multipliers.{name}: labels are not the windows'")
            vals += [float(got[lab]) for lab in labels[group]]
        else:
            M = np.asarray(cert[name], dtype=float)
            if M.shape != (n, n):
                raise Refused(f"certificate {name} has shape {M.shape}, expected {(n, n)}")
            M = 0.5 * (M + M.T) if kind == "sym" else 0.5 * (M - M.T)
            vals += [float(M[i, j]) for i, j in _pairs(kind, n)]
    x = np.array(vals)
    if not np.all(np.isfinite(x)):
        raise Refused("the certificate has a value that is not finite")
    return x


# --------------------------------------------------------------------------- the conditions


def _quad(Z: np.ndarray, W: np.ndarray) -> np.ndarray:
    return Z.T @ W @ Z


def _combo(coef: np.ndarray, items: list[np.ndarray]) -> Any:
    """sum_e coef[e] items[e] (0 when empty)."""
    return sum((np.asarray(it) * c for c, it in zip(coef, items, strict=True)), 0)


def _polys(dec: Any, pos: Any, X: dict[str, np.ndarray], deg: int) -> dict[str, list]:
    """Coefficients of k^j (matrix part, part on the function values) of (D)
    phi_{k+1} - phi_k + sum eta(k) q and of (P) (k + b) measure + sum lam(k) q - phi_k,
    with phi_k = z'(sum_j k^j W_j) z + (sum_j k^j v_j)'psi and (k+1)^i = sum_j C(i,j) k^j."""
    W = [X[WEIGHTS[j]] for j in range(deg + 1)]
    v = [X[VALUES[j]] for j in range(deg + 1)]
    Z0, Z1, Zp = dec.Z[0], dec.Z[1], pos.Z[0]
    F0, F1, Fp = dec.F[0], dec.F[1], pos.F[0]
    out: dict[str, list] = {"Dm": [], "Dv": [], "Pm": [], "Pv": []}
    b = X["b"][0]
    for j in range(deg + 1):
        grow = range(j, deg + 1)
        out["Dm"].append(sum((_quad(Z1, W[i]) * comb(i, j) for i in grow), 0)
                         - _quad(Z0, W[j]) + _combo(X[f"eta{j}"], dec.Mq))
        out["Dv"].append(sum((F1.T @ v[i] * comb(i, j) for i in grow), 0) - F0.T @ v[j]
                         + _combo(X[f"eta{j}"], dec.mq))
        pm = _combo(X[f"lam{j}"], pos.Mq) - _quad(Zp, W[j])
        pv = _combo(X[f"lam{j}"], pos.mq) - Fp.T @ v[j]
        if j == 0:
            pm, pv = pm + pos.meas_quad * b, pv + pos.meas_lin * b
        if j == 1:
            pm, pv = pm + pos.meas_quad, pv + pos.meas_lin
        out["Pm"].append(pm)
        out["Pv"].append(pv)
    return out


def _halfline(name: str, A: list, S: np.ndarray, K: np.ndarray) -> list[tuple[str, Any]]:
    """A0 + k A1 + k^2 A2 <= 0 on k >= 0 from [[A0, Y], [Y', A2]] <= 0, Y = (A1 + S)/2 + K,
    S >= 0, K skew: [I; kI]'(...)[I; kI] = A(k) + k S."""
    Y = (A[1] + S) * Fraction(1, 2) + K
    return [(name, np.block([[A[0], Y], [Y.T, A[2]]])), (f"{name}-S", -S)]


def _conditions(dec: Any, pos: Any, u: list[Fraction], X: dict[str, np.ndarray],
                deg: int, n: int, moving: tuple[np.ndarray, np.ndarray] | None = None,
                ) -> tuple[list, list, dict[str, np.ndarray]]:
    """Matrix blocks (each <= 0), rows (each <= 0) and the exact directions every
    certificate's block is singular along (the minimizer moving with zero gradients, and
    with the optimal answers: ``moving``, whose presence also frees the start: the initial
    block bounds phi_0 by C |xi_0 - xi*|^2 on the whole positivity window)."""
    P = _polys(dec, pos, X, deg)
    wd, wp = dec.width, pos.width
    vd = np.array(u + [Fraction(0)] * (wd - n), dtype=object)[:, None]
    vp = np.array(u + [Fraction(0)] * (wp - n), dtype=object)[:, None]
    free = moving is not None
    if free:
        vd, vp = np.hstack([vd, moving[0]]), np.hstack([vp, moving[1]])
    zd, zp = vd * 0, vp * 0
    if deg == 2:
        blocks = _halfline("D", P["Dm"], X["S_D"], X["K_D"]) + _halfline("P", P["Pm"],
                                                                         X["S_P"], X["K_P"])
        known = {"D": np.hstack([np.vstack([vd, zd]), np.vstack([zd, vd])]),
                 "D-S": vd, "P": np.vstack([zp, vp]), "P-S": vp}
    else:
        blocks = [(f"{t}{j}", P[f"{t}m"][j]) for t in "DP" for j in (0, 1)]
        known = {"D0": vd, "D1": vd, "P1": vp}
    head = n if free else 1  # the state xi_0 - xi* (a free start), or x_0 - x*
    T = np.full((wp, wp - n + head), Fraction(0), dtype=object)  # (start, rest) -> window
    for i in range(n):
        T[i, i if free else 0] = Fraction(1) if free else u[i]
    for i in range(wp - n):
        T[n + i, head + i] = Fraction(1)
    Im = T.T @ (_quad(pos.Z[0], X["P"]) + _combo(X["nu"], pos.Mq)) @ T
    for i in range(head):
        Im[i, i] = Im[i, i] - X["C"][0]
    blocks.append(("I", Im))
    Iv = pos.F[0].T @ X["p"] + _combo(X["nu"], pos.mq)
    rows = [(f"{t}{j}-f[{i}]", e) for t in "DP" for j in range(deg + 1)
            for i, e in enumerate(P[f"{t}v"][j])]
    rows += [(f"I-f[{i}]", e) for i, e in enumerate(Iv)] + [("b", -X["b"][0])]
    rows += [(f"{g}[{i}]", -e) for g in [f"eta{j}" for j in range(deg + 1)]
             + [f"lam{j}" for j in range(deg + 1)] + ["nu"] for i, e in enumerate(X[g])]
    return blocks, rows, known


@dataclass
class _Win:
    """A window of :func:`exact_window` with its entries as Fractions."""

    width: int
    labels: list[str]
    Z: dict[int, np.ndarray]
    F: dict[int, np.ndarray]
    Mq: list[np.ndarray]
    mq: list[np.ndarray]
    meas_lin: np.ndarray
    meas_quad: np.ndarray


def _win(w: Any) -> _Win:
    return _Win(w.width, list(w.labels), {t: _exact(M) for t, M in w.Z.items()},
                {t: _exact(M) for t, M in w.F.items()}, [_exact(M) for M in w.Mq],
                [_exact(np.asarray(m, dtype=object)) for m in w.mq], _exact(w.meas_lin),
                _exact(w.meas_quad))


# --------------------------------------------------------------------------- equalities


def _values(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A matrix of affine forms at the float point x."""
    return np.vectorize(lambda e: _lin(e).at_float(x), otypes=[float])(M)


def _rationals(K: np.ndarray) -> np.ndarray:
    """Snapped entries as their small fractions, the others as their binary values."""
    def one(v: float) -> Fraction:
        f = Fraction(v).limit_denominator(16)
        return f if float(f) == v else Fraction(v)
    return np.vectorize(one, otypes=[object])(K)


def _kernels(blocks: list, known: dict[str, np.ndarray], x: np.ndarray,
             ) -> dict[str, np.ndarray]:
    """Per block: the exact known directions and, on their complement, the eigenvectors of
    the float certificate's block with |eigenvalue| <= KERNEL_TOL * scale (snapped; a
    clearly positive one is a violation, left for the exact check to report)."""
    from sosalgo.certificates.base import snap_basis

    out = {}
    for name, M in blocks:
        G = _values(M, x)
        K0 = known.get(name, np.zeros((G.shape[0], 0), dtype=object))
        K0f = K0.astype(float)
        R = sla.null_space(K0f.T) if K0.shape[1] else np.eye(G.shape[0])
        w, V = np.linalg.eigh(R.T @ G @ R)
        scale = max(1.0, float(np.abs(w).max(initial=0.0)), float(np.abs(x).max()))
        found = snap_basis(R @ V[:, np.abs(w) <= KERNEL_TOL * scale], tol=SNAP_TOL)
        K = np.hstack([K0, _rationals(found)]) if found.shape[1] else K0
        if K.shape[1]:
            out[name] = K
    return out


def _given_kernels(given: Mapping[str, Any], known: dict[str, np.ndarray],
                   blocks: list) -> dict[str, np.ndarray]:
    """The kernels the analysis imposed (``certificate.kernels``, original units, the known
    directions first): the known columns replaced by the exact ones, the others as
    rationals (snapped fractions or binary values). Any basis is sound: it only chooses
    which equalities the exact solve imposes."""
    size = {name: M.shape[0] for name, M in blocks}
    out = dict(known)
    for name, cols in given.items():
        K = np.asarray(cols, dtype=float)
        if name not in size or K.ndim != 2 or K.shape[0] != size[name]:
            raise Refused(f"certificate kernels.{name}: not a kernel basis of a block")
        k0 = known.get(name, np.zeros((size[name], 0), dtype=object))
        out[name] = np.hstack([k0, _rationals(K[:, k0.shape[1]:])])
    return out


def _equalities(blocks: list, rows: list, kernels: dict[str, np.ndarray],
                x: np.ndarray) -> list[Lin]:
    """G K = 0 for every block's kernel K, and the rows at 0 at the float certificate
    (|row| <= KERNEL_TOL * scale)."""
    eqs = []
    for name, M in blocks:
        if name in kernels:
            eqs += [_lin(e) for e in (M @ kernels[name]).ravel()]
    vals = np.array([_lin(e).at_float(x) for _, e in rows])
    scale = max(1.0, float(np.abs(x).max()))
    eqs += [_lin(rows[i][1]) for i in np.flatnonzero(np.abs(vals) <= KERNEL_TOL * scale)]
    return [e for e in eqs if e.t or e.c]


def _project(eqs: list[Lin], x: np.ndarray, fixed: int,
             value: Fraction) -> tuple[list[Fraction], int, float]:
    """x rounded to rationals (binary values) and moved exactly onto ``eqs`` (affine forms
    = 0; variable ``fixed``, the constant, is set to ``value`` and not moved): the moves
    are on pivot columns chosen by a pivoted QR of the float system. Returns (x, rank,
    largest move)."""
    import flint

    xq = [Fraction(float(v)) for v in x]
    xq[fixed] = value
    if not eqs:
        return xq, 0, 0.0
    free = [k for k in range(len(x)) if k != fixed]
    Ef = np.zeros((len(eqs), len(free)))
    col = {k: i for i, k in enumerate(free)}
    for r, e in enumerate(eqs):
        for k, v in e.t.items():
            if k != fixed:
                Ef[r, col[k]] = float(v)
    _, _, piv = sla.qr(Ef, pivoting=True, mode="economic")
    order = [free[i] for i in piv]
    where = {k: i for i, k in enumerate(order)}
    aug = flint.fmpq_mat(len(eqs), len(order) + 1)
    for r, e in enumerate(eqs):
        res = -e.at(xq)  # the move d must satisfy sum_k t[k] d[k] = -e(xq)
        for k, v in e.t.items():
            if k != fixed:
                aug[r, where[k]] = flint.fmpq(v.numerator, v.denominator)
        aug[r, len(order)] = flint.fmpq(res.numerator, res.denominator)
    red, rank = aug.rref()
    moved = 0.0
    for r in range(rank):
        c = next(j for j in range(len(order) + 1) if red[r, j] != 0)
        if c == len(order):
            raise Refused("the equalities (kernels and rows at 0 found at the float "
                          "certificate) have no exact solution: a kernel is not exact")
        d = red[r, len(order)]
        xq[order[c]] += Fraction(int(d.p), int(d.q))
        moved = max(moved, abs(float(d)))
    return xq, rank, moved


# --------------------------------------------------------------------------- the proof


def _exact_values(M: np.ndarray, x: list[Fraction]) -> list[list[Fraction]]:
    return [[_lin(e).at(x) for e in row] for row in M]


def _check(blocks: list, rows: list, x: list[Fraction]) -> tuple[dict[str, str], list[str]]:
    """Every block proven <= 0 (exact LDL^T of -G) and every row <= 0; (proofs, failures)."""
    proofs, bad = {}, []
    for name, M in blocks:
        G = _exact_values(M, x)
        pr = prove_psd([[-v for v in row] for row in G])
        if pr.psd:
            proofs[name] = f"negative {pr.kind} ({pr.method})"
        else:
            bad.append(f"block {name} is not <= 0 ({pr.detail})")
    worst = [(name, _lin(e).at(x)) for name, e in rows]
    bad += [f"row {name} = {float(v):.3g} > 0" for name, v in worst if v > 0]
    proofs["rows"] = f"{len(rows)} rows <= 0 (exact)" if not any(v > 0 for _, v in worst) \
        else "violated"
    return proofs, bad


def _constants(C: float) -> list[Fraction]:
    """C and rationals slightly above it (C can only help the initial block)."""
    from sosalgo.kernel.exact import rational_at_least

    out: list[Fraction] = []
    for step in CONSTANT_STEPS:
        c = rational_at_least(Fraction(C) * (1 + Fraction(step)), 10**15)
        if c not in out:
            out.append(c)
    return out


def _inputs(obj: Mapping[str, Any], theta: Mapping[str, float] | None,
            constant: float | None) -> tuple[Mapping[str, Any], float, Any]:
    """(certificate, constant, theta) from an analysis or design row or a certificate."""
    cert = obj.get("certificate") if isinstance(obj.get("certificate"), Mapping) else obj
    C = constant if constant is not None else obj.get("constant", cert.get("constant"))
    if theta is None and isinstance(obj.get("theta"), Mapping):
        theta = obj["theta"]
    if cert.get("family") != "sublinear":
        raise Refused("not a sublinear certificate (family: sublinear)")
    if not isinstance(C, int | float) or isinstance(C, bool) or not math.isfinite(C) or C <= 0:
        raise Refused(f"constant {C!r} is not a positive number")
    return cert, float(C), theta


@dataclass
class _Setup:
    blocks: list  # (name, matrix of Lin): each <= 0
    rows: list  # (name, Lin): each <= 0
    known: dict[str, np.ndarray]  # exact kernel directions of every certificate
    x: np.ndarray  # the certificate's float values
    unk: dict[str, tuple[str, int]]
    u: list[Fraction]  # the start at rest: xi_0 - xi* = u (x_0 - x*)

    @property
    def ic(self) -> int:
        """Index of the constant C (the last unknown)."""
        return len(self.x) - 1


def _setup(res: SublinearExactResult, spec: Spec, cert: Mapping[str, Any], C: float,
           theta: Any) -> _Setup:
    """The exact method, its windows, the conditions in the certificate's unknowns and the
    certificate's float values."""
    from sosalgo.errors import ModelError
    from sosalgo.method import bind

    om = exact_sublinear_method(spec, theta)
    res.L = fraction_str(om.L)
    res.params = {k: str(v) for k, v in om.params.items()}
    try:
        fom = bind(spec, None, theta)
    except (ModelError, ValueError) as exc:
        raise Refused(f"the method cannot be evaluated: {exc}") from None
    for k in (k for k in ORACLE_MATRIX_NAMES if k in om.balls):
        cen = np.array([[float(b.c) for b in row] for row in om.balls[k]])
        if not np.allclose(cen, getattr(fom, k), rtol=1e-9, atol=1e-12):
            raise Refused(f"exact matrix {k} differs from the float method")
    from sosalgo.certificates.composite import residual_measured

    dec, pos, om = _windows(residual_measured(om), residual_measured(fom))
    res.measure = om.measure
    dec, pos = _win(dec), _win(pos)
    deg = cert.get("degree")
    if deg not in (1, 2):
        raise Refused(f"certificate degree {deg!r} is not 1 or 2")
    res.degree = deg
    unk = _unknowns(om.n + om.p, pos.F[0].shape[0], dec, pos, deg)
    X, _ = _symbols(unk)
    x = _read(cert, unk, {"eta": dec.labels, "lam": pos.labels, "nu": pos.labels}, C)
    u = _fixed_point(om)
    moving = _moving(om, dec, pos) if om.measure == STATE_CHANGE else None
    blocks, rows, known = _conditions(dec, pos, u, X, deg, om.n, moving)
    return _Setup(blocks, rows, known, x, unk, u)


def verify_exact_sublinear(spec: Spec, row_or_certificate: Mapping[str, Any],
                           theta: Mapping[str, float] | None = None, *,
                           constant: float | None = None) -> SublinearExactResult:
    """Prove exactly that a sublinear certificate (an analysis or design row, or the
    certificate with ``constant``) gives measure(x_k) <= C' |x_0 - x*|^2 / k for all
    k >= 1, C' its constant or a rational slightly above (module doc). A refusal or a
    failed proof is a result (``verified: failed`` with ``reason``), never an exception."""
    start = time.perf_counter()
    res = SublinearExactResult(spec.name, Verdict.FAILED, None)
    try:
        cert, C, theta = _inputs(row_or_certificate, theta, constant)
        res.constant_requested = C
        su = _setup(res, spec, cert, C, theta)
        kernels = (_given_kernels(cert["kernels"], su.known, su.blocks)
                   if cert.get("kernels") else _kernels(su.blocks, su.known, su.x))
        res.kernels = {k: int(K.shape[1]) for k, K in kernels.items()}
        res.reason = _prove(res, su, _equalities(su.blocks, su.rows, kernels, su.x), C)
    except Refused as exc:
        res.reason = str(exc)
    except (KeyError, TypeError, ValueError) as exc:
        res.reason = f"malformed certificate: {type(exc).__name__}: {exc}"
    res.seconds = time.perf_counter() - start
    return res


def _prove(res: SublinearExactResult, su: _Setup, eqs: list[Lin], C: float) -> str | None:
    """Project, prove; retry with C raised while only the initial block fails."""
    first = None
    for Cq in _constants(C):
        res.attempts += 1
        xe, rank, moved = _project(eqs, su.x, su.ic, Cq)
        res.equalities, res.moved = rank, moved
        if moved > MOVE_TOL * max(1.0, float(np.abs(su.x).max())):
            return (f"the certificate is not on its equalities: the exact projection moved "
                    f"a value by {moved:.3g} (tampered, or not the solver's point)")
        proofs, bad = _check(su.blocks, su.rows, xe)
        if not bad:
            res.verified, res.proofs = Verdict.EXACT, proofs
            res.constant_proven, res.constant_proven_float = fraction_str(Cq), float(Cq)
            res.certificate = _exact_certificate(su, xe)
            return None
        first = first or "; ".join(bad[:3])
        if any(not b.startswith("block I ") for b in bad):
            break
    return first


def _exact_certificate(su: _Setup, x: list[Fraction]) -> dict[str, Any]:
    """The proven certificate by unknown (matrices whole), with the start at rest u."""
    out: dict[str, Any] = {"u": [fraction_str(v) for v in su.u]}
    k = 0
    for name, (kind, n) in su.unk.items():
        vals = x[k: k + len(_pairs(kind, n))]
        k += len(vals)
        if kind == "vec":
            out[name] = [fraction_str(v) for v in vals]
            continue
        M = [[Fraction(0)] * n for _ in range(n)]
        for (i, j), v in zip(_pairs(kind, n), vals, strict=True):
            M[i][j], M[j][i] = v, (-v if kind == "skew" else v)
        out[name] = [[fraction_str(v) for v in row] for row in M]
    return out
