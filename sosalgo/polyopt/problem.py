"""Polynomial optimization problems (POPs) and their numeric, scaled form.

A :class:`PolyProblem` is stated with sympy; :func:`compile_problem` converts it once into
dictionary polynomials (see :mod:`sosalgo.polyopt.polynomial`) in the variables used by
the relaxation, optionally after the affine change of variables
``x = (lo + hi)/2 + (hi - lo)/2 * z`` that maps every bounded variable onto ``z in [-1, 1]``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
import sympy as sp

from sosalgo.kernel.expr import ExprError, parse_expression

from .polynomial import (
    Exponent,
    PolyDict,
    abs_evaluate,
    affine_substitute,
    degree,
    evaluate,
    exact_affine_substitute,
    from_sympy_with_error,
    max_abs_coefficient,
    rational_affine_substitute,
    scaled,
)

__all__ = [
    "PolyProblem",
    "CompiledProblem",
    "compile_problem",
    "constraint_violation",
    "implied_bounds",
]

_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class PolyProblem:
    """``min f(x)  s.t.  g_i(x) >= 0,  G_j(x) ⪰ 0,  h_l(x) = 0,  lo <= x <= hi``.

    Attributes:
        variables: the decision variables (distinct sympy Symbols).
        objective: polynomial to minimize.
        inequalities: polynomials ``g_i`` constrained by ``g_i(x) >= 0``.
        matrix_inequalities: square symmetric sympy matrices ``G(x)`` with polynomial
            entries, constrained by ``G(x) ⪰ 0`` (polynomial matrix inequalities, PMIs).
        equalities: polynomials ``h_l`` constrained by ``h_l(x) == 0``.
        bounds: optional ``{variable: (lo, hi)}`` boxes. They are added as the constraints
            ``(x - lo)(hi - x) >= 0`` and used to rescale the variable to ``[-1, 1]``.

    The data are validated and expanded into coefficient dictionaries once, here; a
    ``ValueError`` names anything that is not a real polynomial in ``variables``.
    """

    variables: Sequence[sp.Symbol]
    objective: sp.Expr | float
    inequalities: Sequence[sp.Expr] = ()
    matrix_inequalities: Sequence[sp.MatrixBase] = ()
    equalities: Sequence[sp.Expr] = ()
    bounds: Mapping[sp.Symbol, tuple[float, float]] = field(default_factory=dict)
    _polys: _ExpandedData = field(init=False, repr=False, compare=False)
    _errors: _ExpandedData = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        variables = tuple(self.variables)
        if not variables:
            raise ValueError("a PolyProblem needs at least one variable")
        for v in variables:
            if not isinstance(v, sp.Symbol):
                raise ValueError(f"variables must be sympy Symbols, got {v!r}")
        if len(set(variables)) != len(variables):
            raise ValueError("variables must be distinct")
        names = {str(v): v for v in variables}
        mats = []
        for G in self.matrix_inequalities:
            M = _as_matrix(G, names)
            if M.rows != M.cols:
                raise ValueError(f"matrix inequality must be square, got shape {M.shape}")
            if not (M - M.T).expand().is_zero_matrix:
                raise ValueError("matrix inequality must be symmetric")
            mats.append(M)
        bounds: dict[sp.Symbol, tuple[float, float]] = {}
        for v, (lo, hi) in dict(self.bounds).items():
            if v not in variables:
                raise ValueError(f"bound given for {v}, which is not a variable")
            lo_f, hi_f = float(lo), float(hi)
            if not (math.isfinite(lo_f) and math.isfinite(hi_f) and lo_f < hi_f):
                raise ValueError(f"bounds of {v} must be finite with lo < hi, got {(lo, hi)}")
            bounds[v] = (lo_f, hi_f)
        setattr_ = object.__setattr__
        setattr_(self, "variables", variables)
        setattr_(self, "objective", _as_expr(self.objective, names, "objective"))
        setattr_(
            self,
            "inequalities",
            tuple(_as_expr(g, names, f"inequality {i}") for i, g in enumerate(self.inequalities)),
        )
        setattr_(
            self,
            "equalities",
            tuple(_as_expr(h, names, f"equality {i}") for i, h in enumerate(self.equalities)),
        )
        setattr_(self, "matrix_inequalities", tuple(mats))
        setattr_(self, "bounds", bounds)

        def conv(expr: object) -> tuple[PolyDict, PolyDict]:
            return from_sympy_with_error(expr, variables)

        obj = conv(self.objective)
        ineqs = [conv(g) for g in self.inequalities]
        eqs = [conv(h) for h in self.equalities]
        pmis = [[[conv(M[a, b]) for b in range(M.cols)] for a in range(M.rows)] for M in mats]

        def pick(i: int) -> _ExpandedData:
            return _ExpandedData(
                objective=obj[i],
                inequalities=[g[i] for g in ineqs],
                equalities=[h[i] for h in eqs],
                matrix_inequalities=[[[e[i] for e in row] for row in G] for G in pmis],
            )

        setattr_(self, "_polys", pick(0))
        setattr_(self, "_errors", pick(1))


def _as_expr(obj: object, names: Mapping[str, sp.Symbol], what: str = "expression") -> sp.Expr:
    """A sympy expression from a sympy object, a real number or a string.

    Strings are *parsed* by :func:`sosalgo.kernel.expr.parse_expression` over the variables'
    names (never ``sympify``-ed: that evaluates Python code); anything else must be a
    sympy object or a number that sympy converts without parsing (``strict=True``).
    """
    if isinstance(obj, str):
        try:
            return parse_expression(obj, names)
        except ExprError as exc:
            raise ValueError(f"{what}: {exc}") from exc
    if isinstance(obj, sp.Basic):
        return obj
    try:
        return sp.sympify(obj, strict=True)
    except (sp.SympifyError, TypeError, ValueError) as exc:
        raise TypeError(
            f"{what}: expected a sympy expression, a number or a string, "
            f"got {type(obj).__name__}"
        ) from exc


def _as_matrix(G: object, names: Mapping[str, sp.Symbol]) -> sp.ImmutableMatrix:
    """A sympy matrix from a sympy matrix or a nested sequence of :func:`_as_expr` entries."""
    if isinstance(G, sp.MatrixBase):
        return sp.ImmutableMatrix(G)
    if isinstance(G, str) or not isinstance(G, Sequence):
        raise TypeError(f"a matrix inequality must be a sympy Matrix, got {type(G).__name__}")
    rows = []
    for row in G:
        if isinstance(row, str) or not isinstance(row, Sequence):
            raise TypeError("a matrix inequality given as a list must be a list of rows")
        rows.append([_as_expr(e, names, "matrix inequality entry") for e in row])
    return sp.ImmutableMatrix(rows)


@dataclass(frozen=True)
class _ExpandedData:
    """A :class:`PolyProblem`'s data as coefficient dictionaries, original coordinates."""

    objective: PolyDict
    inequalities: list[PolyDict]
    equalities: list[PolyDict]
    matrix_inequalities: list[list[list[PolyDict]]]


@dataclass
class CompiledProblem:
    """Numeric form of a :class:`PolyProblem` in the relaxation's variables ``z``.

    ``x = offset + width * z`` componentwise (``offset = 0, width = 1`` for variables that
    are not rescaled). Every constraint is divided by its largest absolute coefficient
    (a positive factor, so the feasible set is unchanged); the objective is stored as
    ``objective_constant + objective_scale * objective`` with ``objective`` normalized and
    without constant term.

    The ``*_error`` fields bound, coefficient by coefficient, how far the stored (rounded)
    polynomials may be from the exact ones (same normalization; the objective's includes
    the constant term, relative to ``objective_scale``). The certificate
    (:mod:`sosalgo.polyopt.certificate`) charges them, so a certified bound holds for the
    problem as stated, not only for its floating-point image. ``exact_objective`` is the
    objective in ``z`` in exact rational arithmetic (constant included, not normalized)
    when the stated coefficients are exact floats, else None.
    """

    variables: list[sp.Symbol]
    offset: np.ndarray
    width: np.ndarray
    objective: PolyDict
    objective_constant: float
    objective_scale: float
    objective_degree: int
    inequalities: list[PolyDict]
    equalities: list[PolyDict]
    matrix_inequalities: list[list[list[PolyDict]]]
    radius: np.ndarray | None = None
    objective_error: PolyDict = field(default_factory=dict)
    inequality_errors: list[PolyDict] = field(default_factory=list)
    equality_errors: list[PolyDict] = field(default_factory=list)
    matrix_inequality_errors: list[list[list[PolyDict]]] = field(default_factory=list)
    exact_objective: dict[Exponent, Fraction] | None = None

    @property
    def n(self) -> int:
        """Number of variables."""
        return len(self.variables)

    def constraint_degrees(self) -> list[int]:
        """Degrees of all constraints (inequalities, PMIs by entry degree, equalities)."""
        degs = [degree(g) for g in self.inequalities]
        degs += [degree(h) for h in self.equalities]
        degs += [_matrix_degree(G) for G in self.matrix_inequalities]
        return degs

    def minimal_order(self) -> int:
        """Smallest admissible relaxation order ``max(1, ceil(deg/2))`` over all data."""
        degs = [self.objective_degree, *self.constraint_degrees()]
        return max([1, *(math.ceil(d / 2) for d in degs)])

    def flatness_shift(self) -> int:
        """``d_K = max(1, ceil(deg/2))`` over the constraints (Henrion-Lasserre 2005)."""
        return max([1, *(math.ceil(d / 2) for d in self.constraint_degrees())])

    def box_radius(self) -> np.ndarray | None:
        """``rho`` with ``|z_i| <= rho_i`` on the feasible set, or None if a variable is free.

        Every variable with bounds, stated or implied by the linear constraints
        (:func:`implied_bounds`), has ``|z| <= 1`` when rescaled, ``|x| <= max(|lo|, |hi|)``
        otherwise (the constraints implying it are part of the problem, so this holds on K).
        """
        return None if self.radius is None else self.radius.copy()

    def to_original(self, z: np.ndarray) -> np.ndarray:
        """Map relaxation coordinates ``z`` back to the problem's ``x``."""
        return self.offset + self.width * np.asarray(z, dtype=float)


def _matrix_degree(G: list[list[PolyDict]]) -> int:
    return max((degree(e) for row in G for e in row), default=0)


def compile_problem(
    problem: PolyProblem,
    scale: bool = True,
    center: np.ndarray | None = None,
    var_scale: np.ndarray | None = None,
) -> CompiledProblem:
    """Convert ``problem`` to dictionary polynomials, rescaling bounded variables if asked.

    With ``scale=True`` each variable with bounds ``(lo, hi)`` is replaced by
    ``x = c + w z`` with ``c = (lo + hi)/2``, ``w = (hi - lo)/2``, and the box becomes
    ``1 - z^2 >= 0``; otherwise the box is kept as ``(x - lo)(hi - x) >= 0``.

    Both are the same constraint up to an affine change of variables and a positive factor,
    and moment relaxations are invariant under affine changes of variables, so the bound is
    the same in exact arithmetic; numerically, moments of ``[-1, 1]`` are far better
    conditioned than those of ``[0, 1]`` (whose moment matrix is a Hilbert matrix). The
    quadratic box implies the two linear ones ``1 - z >= 0``, ``1 + z >= 0`` at every order
    (``2(1 - z) = (1 - z)^2 + (1 - z^2)``), so it is at least as tight and needs one
    localizing matrix per variable instead of two.

    Variables without ``bounds`` whose range is implied by the linear constraints
    (:func:`implied_bounds`) are rescaled the same way, but no constraint is added: the
    relaxation is the stated one, in better-conditioned coordinates, and the box
    certificate applies (:meth:`CompiledProblem.box_radius`).

    ``center`` and ``var_scale`` (arrays over all variables, used only with ``scale=True``
    and only for variables *without* bounds) substitute ``x = center + var_scale * z``: the
    same kind of affine change, used to re-solve an inaccurate relaxation around an
    estimated minimizer with equilibrated coefficients (see :func:`equilibrating_scale`).
    """
    ranges = _variable_ranges(problem)
    offset, width = _substitution(problem, ranges, scale, center, var_scale)
    conv = _Converter(offset, width, scale)
    data, data_err = problem._polys, problem._errors
    obj, obj_err, obj_const, obj_scale = _compile_objective(conv, data.objective,
                                                           data_err.objective)
    ineqs, ineq_err = _compile_inequalities(problem, conv, scale)
    eqs, eq_err = _compile_equalities(conv, data.equalities, data_err.equalities)
    pmis, pmi_err = _compile_matrix_inequalities(
        conv, data.matrix_inequalities, data_err.matrix_inequalities
    )
    return CompiledProblem(
        exact_objective=_exact_objective(conv, data.objective, data_err.objective),
        radius=_radius(problem, ranges, scale),
        variables=list(problem.variables),
        offset=offset,
        width=width,
        objective=obj,
        objective_constant=obj_const,
        objective_scale=obj_scale,
        objective_degree=degree(obj),
        inequalities=ineqs,
        equalities=eqs,
        matrix_inequalities=pmis,
        objective_error=obj_err,
        inequality_errors=ineq_err,
        equality_errors=eq_err,
        matrix_inequality_errors=pmi_err,
    )


# -- variable ranges and the change of variables -----------------------------------------


def implied_bounds(problem: PolyProblem, rounds: int = 8) -> dict[sp.Symbol, tuple[float, float]]:
    """Ranges of variables *without* ``bounds`` implied by the linear constraints.

    Interval propagation (each linear inequality ``b + a . x >= 0``, and each linear
    equality as two of them, bounds every variable by the ranges of the others; at most
    ``rounds`` sweeps) in exact rational arithmetic over the stored coefficients; only
    constraints whose coefficients are exact (no conversion error) take part, so every
    range holds on the feasible set. The ranges are rounded outwards to floats; ranges
    reaching beyond ``1e30`` are ignored. E.g.
    ``x2 >= 0, x3 >= 0, 6 - 3 x2 - x3 >= 0`` gives ``x2 in [0, 2]``.
    """
    rows = _linear_rows(problem)
    variables = list(problem.variables)
    box: list[list[Fraction | None]] = [[None, None] for _ in variables]
    for i, v in enumerate(variables):
        if v in problem.bounds:
            box[i] = [Fraction(b) for b in problem.bounds[v]]
    for _ in range(rounds if rows else 0):
        if not any([_tighten(b, a, box) for b, a in rows]):  # a list: every row, each sweep
            break
    out = {}
    for i, v in enumerate(variables):
        lo, hi = box[i]
        if v in problem.bounds or lo is None or hi is None or not lo < hi:
            continue
        if max(abs(lo), abs(hi)) <= _MAX_IMPLIED:
            out[v] = (_round_down(lo), -_round_down(-hi))
    return out


#: Implied ranges reaching beyond this are ignored (a huge width would overflow the
#: substituted coefficients).
_MAX_IMPLIED = Fraction(10) ** 30


def _linear_rows(problem: PolyProblem) -> list[tuple[Fraction, list[Fraction]]]:
    """``(b, a)`` with ``b + a . x >= 0`` for every exact linear constraint (equalities twice)."""
    n = len(problem.variables)
    data, errs = problem._polys, problem._errors
    pairs = [(g, e, 1) for g, e in zip(data.inequalities, errs.inequalities, strict=True)]
    for h, e in zip(data.equalities, errs.equalities, strict=True):
        pairs += [(h, e, 1), (h, e, -1)]
    rows = []
    for p, err, sign in pairs:
        if not p or degree(p) > 1 or any(u > 0.0 for u in err.values()):
            continue
        a = [Fraction(0)] * n
        b = Fraction(0)
        for e, c in p.items():
            if sum(e) == 0:
                b = sign * Fraction(c)
            else:
                a[e.index(1)] = sign * Fraction(c)
        rows.append((b, a))
    return rows


def _tighten(b: Fraction, a: list[Fraction], box: list[list[Fraction | None]]) -> bool:
    """Tighten ``box`` (in place) with ``b + a . x >= 0``; True if some bound moved."""
    tops: list[Fraction | None] = []  # max of a_k x_k over the box (None: unbounded)
    for ak, (lo, hi) in zip(a, box, strict=True):
        if ak == 0:
            tops.append(Fraction(0))
        else:
            end = hi if ak > 0 else lo
            tops.append(None if end is None else ak * end)
    missing = [k for k, t in enumerate(tops) if t is None]
    if len(missing) > 1:
        return False
    total = b + sum(t for t in tops if t is not None)
    moved = False
    for i, ai in enumerate(a):
        if ai == 0 or (missing and missing != [i]):
            continue
        rest = total - (tops[i] if tops[i] is not None else 0)  # max of b + others
        limit = -rest / ai  # a_i x_i >= -rest
        side = 0 if ai > 0 else 1
        old = box[i][side]
        if old is None or (limit > old if side == 0 else limit < old):
            box[i][side] = limit
            moved = True
    return moved


def _round_down(q: Fraction) -> float:
    """The largest float <= ``q``."""
    f = float(q)
    return f if Fraction(f) <= q else math.nextafter(f, -math.inf)


def _variable_ranges(problem: PolyProblem) -> dict[sp.Symbol, tuple[float, float]]:
    """Stated bounds, completed by :func:`implied_bounds` for the other variables."""
    return {**implied_bounds(problem), **problem.bounds}


def _substitution(
    problem: PolyProblem,
    ranges: Mapping[sp.Symbol, tuple[float, float]],
    scale: bool,
    center: np.ndarray | None,
    var_scale: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(offset, width)`` of ``x = offset + width z``: ranges onto ``[-1, 1]``, others as given."""
    n = len(problem.variables)
    offset = np.zeros(n)
    width = np.ones(n)
    if not scale:
        return offset, width
    if center is not None:
        offset = np.array(center, dtype=float)
    if var_scale is not None:
        width = np.array(var_scale, dtype=float)
    for i, v in enumerate(problem.variables):
        if v in ranges:
            lo, hi = ranges[v]
            offset[i] = 0.5 * (lo + hi)
            # rounded outwards, so that the z-box covers [lo, hi] in exact arithmetic
            width[i] = 0.5 * (hi - lo) * (1 + 4 * _EPS) + 4 * _EPS * abs(offset[i])
    return offset, width


def _radius(
    problem: PolyProblem, ranges: Mapping[sp.Symbol, tuple[float, float]], scale: bool
) -> np.ndarray | None:
    """``|z_i| <= radius_i`` on the feasible set, or None if some variable has no range."""
    variables = list(problem.variables)
    if not all(v in ranges for v in variables):
        return None
    if scale:
        return np.ones(len(variables))
    return np.array([max(abs(b) for b in ranges[v]) for v in variables])


# -- polynomials in the new variables, normalized, with error bounds ---------------------


@dataclass(frozen=True)
class _Converter:
    """Substitutes ``x = offset + width z`` and normalizes, tracking coefficient errors."""

    offset: np.ndarray
    width: np.ndarray
    scale: bool

    def __call__(self, p: PolyDict, perr: PolyDict) -> tuple[PolyDict, PolyDict]:
        """The substituted polynomial and a bound on its coefficients' errors.

        Errors: the rounding of the substitution (exact arithmetic, one rounding per
        coefficient, unless the polynomial is too large) plus the conversion errors
        ``perr`` of the input coefficients carried through the substitution.
        """
        if not self.scale:
            return dict(p), dict(perr)
        offset, width = self.offset, self.width
        if _combos(p) <= _EXACT_LIMIT:
            q, err = exact_affine_substitute(p, offset, width)
        else:
            q, err = affine_substitute(p, offset, width), _substitution_error(p, offset, width)
        if perr:
            carried = affine_substitute(perr, np.abs(offset), np.abs(width))
            slack = 1 + 4 * (degree(perr) + 3) * _EPS
            for e, u in carried.items():
                err[e] = err.get(e, 0.0) + u * slack
        return q, err

    @staticmethod
    def normalized(p: PolyDict, err: PolyDict, m: float) -> tuple[PolyDict, PolyDict]:
        """``p / m`` and its error bounds (the division's rounding included)."""
        out = scaled(p, 1.0 / m)
        return out, {e: (u / m + _EPS * abs(out.get(e, 0.0))) * (1 + _EPS) for e, u in
                     {**{e: 0.0 for e in p}, **err}.items()}


def _compile_objective(
    conv: _Converter, f: PolyDict, ferr: PolyDict
) -> tuple[PolyDict, PolyDict, float, float]:
    """``(objective, error, constant, scale)``: ``f = constant + scale * objective``."""
    obj, obj_err = conv(f, ferr)
    zero = (0,) * len(conv.offset)
    obj_const = obj.pop(zero, 0.0)
    obj_scale = max_abs_coefficient(obj)
    obj_scale = obj_scale if obj_scale > 0 else 1.0
    obj, obj_err = conv.normalized(obj, obj_err, obj_scale)
    return obj, obj_err, obj_const, obj_scale


def _exact_objective(
    conv: _Converter, f: PolyDict, ferr: PolyDict
) -> dict[Exponent, Fraction] | None:
    """``f`` in ``z``, exactly; None if its coefficients are inexact or it is too large."""
    if ferr or _combos(f) > _EXACT_LIMIT:
        return None
    if not conv.scale:
        return {e: Fraction(c) for e, c in f.items()}
    return rational_affine_substitute(f, conv.offset, conv.width)


def _compile_inequalities(
    problem: PolyProblem, conv: _Converter, scale: bool
) -> tuple[list[PolyDict], list[PolyDict]]:
    """The inequalities, then one box constraint per variable with ``bounds``.

    A constant constraint is kept only if it is violated (the solver then reports the
    relaxation infeasible); satisfied constants carry no information.
    """
    variables = list(problem.variables)
    n = len(variables)
    zero = (0,) * n
    data, data_err = problem._polys, problem._errors
    out: list[PolyDict] = []
    errs: list[PolyDict] = []
    for g, gerr in zip(data.inequalities, data_err.inequalities, strict=True):
        p, err = conv(g, gerr)
        if p and not (degree(p) == 0 and p[zero] >= 0):
            q, qe = conv.normalized(p, err, max_abs_coefficient(p))
            out.append(q)
            errs.append(qe)
    for i, v in enumerate(variables):
        if v not in problem.bounds:
            continue
        e1 = tuple(1 if j == i else 0 for j in range(n))
        e2 = tuple(2 if j == i else 0 for j in range(n))
        if scale:
            out.append({zero: 1.0, e2: -1.0})  # 1 - z^2, exact
            errs.append({})
        else:
            lo, hi = problem.bounds[v]
            box = {e2: -1.0, e1: lo + hi, zero: -lo * hi}  # (x - lo)(hi - x)
            box = {e: c for e, c in box.items() if c != 0.0}
            q, qe = conv.normalized(box, {e: _EPS * abs(c) for e, c in box.items()},
                                    max_abs_coefficient(box))
            out.append(q)
            errs.append(qe)
    return out, errs


def _compile_equalities(
    conv: _Converter, hs: list[PolyDict], herrs: list[PolyDict]
) -> tuple[list[PolyDict], list[PolyDict]]:
    """The nonzero equalities, normalized."""
    out: list[PolyDict] = []
    errs: list[PolyDict] = []
    for h, herr in zip(hs, herrs, strict=True):
        p, err = conv(h, herr)
        if p:
            q, qe = conv.normalized(p, err, max_abs_coefficient(p))
            out.append(q)
            errs.append(qe)
    return out, errs


def _compile_matrix_inequalities(
    conv: _Converter, Gs: list[list[list[PolyDict]]], Gerrs: list[list[list[PolyDict]]]
) -> tuple[list[list[list[PolyDict]]], list[list[list[PolyDict]]]]:
    """The nonzero PMIs, each divided by its entries' largest coefficient."""
    pmis: list[list[list[PolyDict]]] = []
    pmi_err: list[list[list[PolyDict]]] = []
    for G, Gerr in zip(Gs, Gerrs, strict=True):
        entries = [
            [conv(e, u) for e, u in zip(row, urow, strict=True)]
            for row, urow in zip(G, Gerr, strict=True)
        ]
        m = max((max_abs_coefficient(e) for row in entries for e, _ in row), default=0.0)
        if m == 0.0:
            continue
        pairs = [[conv.normalized(e, err, m) for e, err in row] for row in entries]
        pmis.append([[q for q, _ in row] for row in pairs])
        pmi_err.append([[qe for _, qe in row] for row in pairs])
    return pmis, pmi_err


_EXACT_LIMIT = 200_000  # products in a substitution done in exact rational arithmetic


def _combos(p: PolyDict) -> int:
    """Number of products in ``affine_substitute(p, ...)``."""
    return sum(math.prod(a + 1 for a in e) for e in p)


def _substitution_error(p: PolyDict, offset: np.ndarray, width: np.ndarray) -> PolyDict:
    """Bound on the rounding error of each coefficient of ``affine_substitute(p, ...)``.

    Each output coefficient is a sum of products ``c C(a, j) o^(a-j) w^j``; the error of
    such a floating-point sum is at most (number of operations) x eps x the same sum with
    absolute values, which is ``affine_substitute(|p|, |o|, |w|)``. The input coefficients'
    own conversion to float (relative eps) is one more operation.
    """
    if not p:
        return {}
    ops = 4 * (degree(p) + 3) + sum(math.prod(a + 1 for a in e) for e in p)
    mags = affine_substitute({e: abs(c) for e, c in p.items()}, np.abs(offset), np.abs(width))
    return {e: 2.0 * ops * _EPS * v for e, v in mags.items()}


def equilibrating_scale(problem: PolyProblem, center: np.ndarray) -> np.ndarray:
    """Powers of two ``s`` for the unbounded variables that equilibrate the coefficients.

    After ``x = center + s z`` a coefficient ``c_alpha`` becomes ``c_alpha s^alpha``. The
    exponents ``t = log2 s`` minimize ``sum (log2 |c_alpha| + alpha . t - m_p)^2`` over all
    non-constant terms of the objective and all terms of the constraints, with one free
    level ``m_p`` per polynomial (least squares, minimum norm; variables with stated or
    implied bounds keep ``s = 1`` here, they are rescaled by their box). Powers of two
    keep the substitution exact in floating point.
    """
    variables = list(problem.variables)
    n = len(variables)
    ranges = _variable_ranges(problem)
    free = np.array([v not in ranges for v in variables])
    data = problem._polys
    polys = [data.objective, *data.inequalities, *data.equalities]
    polys += [{e: c for row in G for entry in row for e, c in entry.items()}
              for G in data.matrix_inequalities]
    rows, rhs = [], []
    for k, p in enumerate(polys):
        q = affine_substitute(p, center, np.ones(n))
        if k == 0:
            q.pop((0,) * n, None)
        for e, c in q.items():
            if c == 0.0:
                continue
            row = np.zeros(n + len(polys))
            row[:n] = np.where(free, e, 0)
            row[n + k] = -1.0
            rows.append(row)
            rhs.append(-math.log2(abs(c)))
    if not rows:
        return np.ones(n)
    t, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
    t = np.clip(np.round(t[:n]), -60, 60)
    return np.where(free, 2.0**t, 1.0)


def constraint_violation(compiled: CompiledProblem, z: np.ndarray) -> float:
    """Largest relative violation of the compiled constraints at ``z``.

    A violation is divided by ``max(1, sum_alpha |c_alpha| |z^alpha|)`` of its polynomial
    (for a PMI: summed over the entries), i.e. measured relative to the size of the terms.
    """
    worst = 0.0
    for g in compiled.inequalities:
        worst = max(worst, -evaluate(g, z) / max(1.0, abs_evaluate(g, z)))
    for h in compiled.equalities:
        worst = max(worst, abs(evaluate(h, z)) / max(1.0, abs_evaluate(h, z)))
    for G in compiled.matrix_inequalities:
        vals = np.array([[evaluate(e, z) for e in row] for row in G])
        lam = float(np.linalg.eigvalsh(0.5 * (vals + vals.T))[0])
        norm = max(1.0, sum(abs_evaluate(e, z) for row in G for e in row))
        worst = max(worst, -lam / norm)
    return worst
