"""The method made exact: the one :class:`~sosalgo.oracles.Method` over balls, the spec's
templates at rational kappa, m, L (and rational parameter values), with exact sympy
entries and rational ball enclosures of the irrational ones, every function's class
parameters enclosed (:func:`exact_algorithm`), and its fixed point of eq. (11) proven
exactly (:func:`exact_fixed_point`). The exact twin of :func:`sosalgo.model.bind`, used by
every family's exact check and by the noise proofs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from fractions import Fraction
from typing import Any

import numpy as np
import sympy as sp

from sosalgo.classes import CLASSES, SEED_CLASS
from sosalgo.errors import ModelError
from sosalgo.kernel.exact import (
    DEFAULT_DIGITS,
    Ball,
    enclose,
    is_zero,
    object_matrix,
    rational,
)
from sosalgo.kernel.expr.parse import to_sympy
from sosalgo.oracles import BoundFunction, Method, seed_functions
from sosalgo.spec.types import (
    BASE_SYMBOLS,
    ORACLE_MATRIX_NAMES,
    Spec,
    value_order,
)

__all__ = ["ExactAlgorithm", "ExactOracleMethod", "ParameterBox", "ball_method",
           "check_polynomial", "exact_algorithm", "exact_fixed_point", "exact_oracle_method",
           "polynomial_method", "scaled_method", "units_far_from_one"]


# the method over balls: the one :class:`~sosalgo.oracles.Method` (names kept for the
# code and pages that call it by them)
ExactAlgorithm = ExactOracleMethod = Method


def exact_algorithm(
    spec: Spec, kappa: float | Fraction, theta: Mapping[str, float] | None = None,
    digits: int = DEFAULT_DIGITS,
) -> Method:
    """The spec's method over balls (``numbers="ball"``) at rational kappa (as written:
    :func:`sosalgo.kernel.kappa.exact_kappa`; ``10/3`` is 10/3, a float its shortest
    decimal, 3.3 is 33/10), m = spec.m, L = kappa m, and ``theta`` (rational): exact sympy
    entries in ``matrices`` (A, B, C, E of eq. 10; and D where the spec has one), their
    rational ball enclosures as the matrices A, B, C, D (zero when the spec has none), E
    (None with ``output: y<i>``), and every function's class parameters enclosed. The
    exact twin of :func:`sosalgo.model.bind`. ValueError for an irrational kappa or when
    it cannot be built."""
    kq = _rational_kappa(kappa)
    if not kq > 1:
        raise ValueError(f"condition number must be > 1, got {kappa}")
    mq = rational(spec.m)
    Lq = kq * mq
    base = {
        BASE_SYMBOLS["m"]: sp.Rational(mq.numerator, mq.denominator),
        BASE_SYMBOLS["L"]: sp.Rational(Lq.numerator, Lq.denominator),
        BASE_SYMBOLS["kappa"]: sp.Rational(kq.numerator, kq.denominator),
    }
    theta_q: dict[str, Fraction] = {}
    for p, v in (theta or {}).items():
        if p not in spec.parameters:
            raise ValueError(f"unknown parameter {p!r}")
        if spec.parameters[p].is_tied:
            raise ValueError(f"parameter {p!r} is tied to other parameters; it cannot be set")
        theta_q[p] = rational(v)
    values: dict[sp.Symbol, sp.Expr] = dict(base)
    params: dict[str, sp.Expr] = {}
    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        if p in theta_q:
            val: sp.Expr = sp.Rational(theta_q[p].numerator, theta_q[p].denominator)
        else:
            expr = par.tied if par.is_tied else par.value
            assert expr is not None
            val = to_sympy(expr).xreplace(values)
        if val.free_symbols:
            raise ValueError(f"parameter {p} did not evaluate to a number: {val}")
        params[p] = val
        values[spec.symbols[p]] = val
    mats: dict[str, sp.Matrix] = {}
    balls: dict[str, np.ndarray] = {}
    # A, B, C, E; on the oracle model also D, and no E with ``output: y<i>``
    for k in (k for k in ORACLE_MATRIX_NAMES if k in spec.sympy_matrices()):
        mat = spec.sympy_matrices()[k].xreplace(values)
        mats[k] = mat
        balls[k] = object_matrix([[enclose(mat[i, j], digits) for j in range(mat.shape[1])]
                                  for i in range(mat.shape[0])])
    functions = _ball_functions(spec, values, lambda e, _where: enclose(e, digits))
    return ball_method(spec, balls, mq, Lq, functions, params, mats, theta_q)


def ball_method(spec: Spec, balls: Mapping[str, np.ndarray], m: Fraction, L: Fraction,
                functions: tuple[BoundFunction, ...], params: dict[str, sp.Expr],
                matrices: dict[str, sp.Matrix], theta: dict[str, Fraction]) -> Method:
    """The method over balls from the enclosures ``balls`` of the spec's exact
    ``matrices`` (object arrays; D zero when the spec has none)."""
    p = spec.p
    D = balls["D"] if "D" in balls else object_matrix([[Ball(0)] * p] * p)
    names = list(spec.functions)
    return Method(balls["A"], balls["B"], balls["C"], D, balls.get("E"), m, L, functions,
                  tuple(names.index(f) for f in spec.oracles), spec.output, spec.measure,
                  params, numbers="ball", matrices=matrices, theta=theta)


def _ball_functions(spec: Spec, values: Mapping[sp.Symbol, sp.Expr],
                    ball: Any) -> tuple[BoundFunction, ...]:
    """The spec's functions with their class parameters (which may name m, L, kappa and
    the spec's parameters, ``values``) as balls, ``ball(expr, field)``."""
    return tuple(BoundFunction(fname, CLASSES[decl.cls],
                               {k: ball(to_sympy(e).xreplace(values), f"functions.{fname}.{k}")
                                for k, e in decl.params.items()})
                 for fname, decl in spec.functions.items())


def scaled_method(ex: Method, s: Fraction) -> Method:
    """The method run on f/s (s > 0 rational): f is in F(m, L) exactly when f/s is in
    F(m/s, L/s), and B s (and D s) applied to the gradients of f/s give the same iterates,
    so every rate is the same. Exact (the enclosures' radii scale with their centres). In
    the seed's form only (ValueError otherwise: other classes' parameters scale otherwise)."""
    if any(f.cls is not SEED_CLASS for f in ex.functions):
        raise ValueError("a method in other units: the seed's form only (f in F(m, L))")
    k = sp.Rational(s.numerator, s.denominator)
    gain = [name for name in ("B", "D") if name in ex.matrices]  # the maps of the gradients
    functions = tuple(BoundFunction(f.name, f.cls, {q: b * (1 / s) for q, b in f.params.items()})
                      for f in ex.functions)  # m/s and L/s
    return replace(ex, m=ex.m / s, L=ex.L / s, functions=functions,
                   matrices={**ex.matrices, **{g: ex.matrices[g] * k for g in gain}},
                   **{g: object_matrix([[b * s for b in row] for row in ex.balls[g]])
                      for g in gain})


def units_far_from_one(ex: Method) -> bool:
    """Whether m or L is far from 1 (m < 1/1024 or L > 2^20): a certificate written in
    such units may not round to rationals that prove it, where it would in units with
    L = 1 (:func:`scaled_method`). Near 1 a failed proof is not a matter of units."""
    return ex.m < Fraction(1, 1024) or ex.L > 2**20


def _rational_kappa(kappa: float | Fraction, takes: str = "the exact check takes a "
                    "rational kappa (the PEP proofs enclose it in a ball)") -> Fraction:
    """kappa's exact value as written, a rational (ValueError when it is irrational: these
    proofs take rational m and L; ``takes`` says which)."""
    from sosalgo.kernel.kappa import exact_kappa

    val = exact_kappa(kappa)
    if not val.is_Rational:
        raise ValueError(f"kappa {val} is irrational: {takes}")
    return Fraction(int(val.p), int(val.q))


def exact_fixed_point(ex: Method, u_float: np.ndarray | None) -> list[sp.Expr] | None:
    """u of eq. (11) with (I - A)u = 0, C u = 1, E u = 1 proven exactly, or None."""
    if u_float is None:
        return None
    u = [sp.nsimplify(float(v), rational=True, tolerance=1e-10) for v in u_float]
    uv = sp.Matrix(u)
    A, C, E = ex.matrices["A"], ex.matrices["C"], ex.matrices["E"]
    res = list((sp.eye(A.shape[0]) - A) * uv) + [(C * uv)[0] - 1, (E * uv)[0] - 1]
    return u if all(is_zero(r) for r in res) else None


# the exact method of a composite spec: the same binding
exact_oracle_method = exact_algorithm


# --------------------------------------------------------------------------- polynomials
@dataclass(frozen=True)
class ParameterBox:
    """The box of the free parameters of a method over ``poly``: θ = mid + half·z for z
    in [-1, 1]^k, the coordinates ``zs`` (sympy symbols); ``mid``/``half`` are exact
    (dyadic) and the box mid ± half contains the parameters' ranges."""

    free: list[str]
    zs: list[sp.Symbol]
    mid: list[Fraction]
    half: list[Fraction]

    @property
    def k(self) -> int:
        return len(self.free)

    def theta(self, z: Sequence[float]) -> dict[str, float]:
        """The parameter values at the box coordinates ``z``."""
        return {p: float(mi + hi * Fraction(float(zi)))
                for p, mi, hi, zi in zip(self.free, self.mid, self.half, z, strict=True)}


def _rat(x: float | Fraction) -> sp.Rational:
    q = Fraction(x)
    return sp.Rational(q.numerator, q.denominator)


def _outward(lo: sp.Expr, hi: sp.Expr) -> tuple[Fraction, Fraction]:
    """Float ends lo_f <= lo and hi_f >= hi of an exact interval."""
    a, b = enclose(lo), enclose(hi)
    lo_f, hi_f = float(a.lo), float(b.hi)
    if Fraction(lo_f) > a.lo:
        lo_f = float(np.nextafter(lo_f, -np.inf))
    if Fraction(hi_f) < b.hi:
        hi_f = float(np.nextafter(hi_f, np.inf))
    return Fraction(lo_f), Fraction(hi_f)


def polynomial_method(spec: Spec, kappa: float, free: Sequence[str]) -> Method:
    """The spec in the seed's form at ``kappa`` over ``poly``: the ``free`` parameters as
    polynomials in the coordinates of their box (``box``, a :class:`ParameterBox`), exact
    entries (A, B, C, E sympy matrices in ``box.zs``, also in ``matrices``); kappa and m
    are the rationals of their binary values, fixed parameters keep their exact values
    (e.g. (√κ − 1)/(√κ + 1)). ModelError when an entry is not polynomial in them,
    ValueError for an irrational kappa."""
    check_polynomial(spec, free)
    free = list(free)
    kq = _rational_kappa(kappa, "the lower bound takes a rational kappa")
    mq = Fraction(float(spec.m))
    base = {BASE_SYMBOLS["m"]: _rat(mq), BASE_SYMBOLS["L"]: _rat(kq * mq),
            BASE_SYMBOLS["kappa"]: _rat(kq)}
    sym = spec.symbols
    values: dict[sp.Symbol, sp.Expr] = dict(base)
    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        if p in free:
            values[sym[p]] = sym[p]
            continue
        values[sym[p]] = to_sympy(par.tied if par.is_tied else par.value).xreplace(values)
    zs = [sp.Symbol(f"z{i}", real=True) for i in range(len(free))]
    mid, half = [], []
    for p in free:
        lo_e, hi_e = (to_sympy(e).xreplace(values) for e in spec.parameters[p].range)
        lo, hi = _outward(lo_e, hi_e)
        mid.append((lo + hi) / 2)
        half.append((hi - lo) / 2)
    scaled = {sym[p]: _rat(mi) + _rat(hi) * z
              for p, mi, hi, z in zip(free, mid, half, zs, strict=True)}
    mats = {k: mat.xreplace(values).xreplace(scaled)
            for k, mat in spec.sympy_matrices().items()}  # D too in the oracle model
    m, L = _rat(mq), _rat(kq * mq)
    # in the oracle model with an output call (no E), the seed-form fields below are not
    # read: the matrices the spec gives are in ``matrices``
    E = mats["E"] if "E" in mats else sp.zeros(1, mats["A"].shape[0])
    return Method(mats["A"], mats["B"], mats["C"], sp.zeros(1, 1), E, m, L,
                  seed_functions(m, L), (0,), numbers="poly", matrices=mats,
                  box=ParameterBox(free, zs, mid, half))


def check_polynomial(spec: Spec, free: Sequence[str]) -> None:
    """Raise ModelError unless every template entry is a polynomial in the free parameters.

    Tied parameters are checked first (naming the parameter and its expression), then the
    matrix entries (other input parameters keep their ``value``).
    """
    syms = [spec.symbols[p] for p in free]
    symset = set(syms)
    for name, expr in spec.tied_closure().items():
        if expr.free_symbols & symset and not expr.is_polynomial(*syms):
            raise ModelError(
                f"parameters.{name}",
                f"{name} = {_show(to_sympy(spec.parameters[name].tied))} is not polynomial "
                f"in the free parameter(s) {_names(free, syms, expr)}; design needs "
                "polynomial dependence",
            )
    for key, mat in spec.templates(free).items():
        for (i, j), entry in np.ndenumerate(np.array(mat.tolist(), dtype=object)):
            entry = sp.sympify(entry)
            if entry.free_symbols & symset and not entry.is_polynomial(*syms):
                raise ModelError(
                    f"matrices.{key}[{i}][{j}]",
                    f"{_show(entry)} is not polynomial in the free parameter(s) "
                    f"{_names(free, syms, entry)}; design needs polynomial dependence",
                )


def _names(free: Sequence[str], syms: Sequence[sp.Symbol], expr: sp.Expr) -> str:
    return ", ".join(p for p, s in zip(free, syms, strict=True) if s in expr.free_symbols)


def _show(expr: sp.Basic, n: int = 80) -> str:
    """An expression as a spec would write it (min, max, abs in lower case)."""
    text = str(expr)
    for a, b in (("Min(", "min("), ("Max(", "max("), ("Abs(", "abs(")):
        text = text.replace(a, b)
    return text if len(text) <= n else text[: n - 3] + "..."
