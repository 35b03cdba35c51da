"""Bind a spec to numbers: kappa (m, L) and parameter values -> numeric A, B, C, E.

Also checks the fixed-point conditions of eq. (11): there must be a u with
(I - A) u = 0, C u = 1 and E u = 1, so that xi* = u ⊗ x* is a fixed point with
y* = x* (Remark 1 reduction).
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping
from typing import Any

import numpy as np

from sosalgo.errors import ModelError
from sosalgo.kernel.expr.compile import NumericError, compile_expression, compile_matrix
from sosalgo.oracles import (
    OracleMethod,
    check_magnitudes,
    fixed_point_basis,
    make_method,
    seed_functions,
)
from sosalgo.spec.types import BASE_NAMES, MATRIX_NAMES, Spec, SpecError, value_order

__all__ = ["Algorithm", "ModelError", "bind", "bind_sublinear", "design_box", "evaluate_algorithm",
           "fixed_point"]

FIXED_POINT_TOL = 1e-8
MAX_DESIGN_ENTRY = 1e50  # largest parameter value or matrix entry a design box may reach


class Algorithm(OracleMethod):
    """The seed's form of the one float method (:class:`~sosalgo.oracles.OracleMethod`):
    numeric reduced templates (Remark 1) of a method with one gradient call on f in
    F(m, L), D = 0, x = E xi, ``measure: function``.

    A, B, C, E may be given as nested lists or arrays; they are stored as float arrays of
    shapes n x n, n x 1, 1 x n, 1 x n. As in the spec loader, a method without the fixed
    point of eq. (11) is refused with a :class:`ModelError` (``require_fixed_point=False``
    skips that check, for algebraic tests only).
    """

    has_seed_form = True
    require_fixed_point: bool

    def __init__(self, A: Any, B: Any, C: Any, E: Any, m: float, L: float,
                 params: dict[str, float] | None = None,
                 require_fixed_point: bool = True) -> None:
        mats = _seed_matrices({"A": A, "B": B, "C": C, "E": E})
        m, L = float(m), float(L)
        if not (np.isfinite(m) and np.isfinite(L) and 0 < m < L):
            raise ModelError("m, L", f"need 0 < m < L (finite), got m={m:g}, L={L:g}")
        fields_ = {**mats, "D": np.zeros((1, 1)), "m": m, "L": L,
                   "functions": seed_functions(m, L), "oracles": (0,), "output": None,
                   "measure": "function", "params": {} if params is None else params,
                   "require_fixed_point": require_fixed_point}
        for k, v in fields_.items():
            object.__setattr__(self, k, v)
        if require_fixed_point and fixed_point(self) is None:
            raise ModelError(
                "matrices",
                "no fixed point: eq. (11) needs u with (I - A) u = 0, C u = 1, E u = 1",
            )


def _seed_matrices(given: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """A, B, C, E as float arrays of shapes n x n, n x 1, 1 x n, 1 x n (ModelError else)."""
    mats = {}
    for k in MATRIX_NAMES:
        try:
            mats[k] = np.array(given[k], dtype=float, ndmin=2)
        except (TypeError, ValueError):
            raise ModelError(f"matrices.{k}", "must be a matrix of numbers") from None
        check_magnitudes(k, mats[k])
    n = mats["A"].shape[0]
    shapes = {"A": (n, n), "B": (n, 1), "C": (1, n), "E": (1, n)}
    for k, shape in shapes.items():
        if mats[k].shape != shape:
            raise ModelError(f"matrices.{k}", f"must be {shape[0]}x{shape[1]}, "
                             f"got {mats[k].shape[0]}x{mats[k].shape[1]}")
    return mats


class _Compiled:
    """Per-spec compiled evaluators (built once, reused at every kappa / grid point)."""

    def __init__(self, spec: Spec):
        self.names = list(spec.parameters)
        syms = list(BASE_NAMES) + self.names
        self.order = value_order(spec.parameters, spec.source)
        self.param_fns = {}
        for p, par in spec.parameters.items():
            field_ = f"parameters.{p}" + ("" if par.is_tied else ".value")
            expr = par.tied if par.is_tied else par.value
            self.param_fns[p] = _compile(expr, syms, field_)
        self.matrix_fns = {}
        for k in spec.matrices:  # A, B, C and E (or the output), D when given
            try:
                self.matrix_fns[k] = compile_matrix(spec.matrices[k], syms)
            except NumericError as exc:
                raise ModelError(f"matrices.{k}", str(exc)) from None
        base = list(BASE_NAMES)
        self.range_fns = {
            p: (
                _compile(par.range[0], base, f"parameters.{p}.range"),
                _compile(par.range[1], base, f"parameters.{p}.range"),
            )
            for p, par in spec.parameters.items()
            if par.range is not None
        }


def _compile(expr, symbols, field_: str):
    try:
        return compile_expression(expr, symbols)
    except NumericError as exc:
        raise ModelError(field_, str(exc)) from None


_CACHE: weakref.WeakKeyDictionary[Spec, _Compiled] = weakref.WeakKeyDictionary()


def _compiled(spec: Spec) -> _Compiled:
    if spec.time_varying:  # one method per step: sosalgo.steps binds it
        from sosalgo.spec.types import VARIES

        raise SpecError(spec.source, "", VARIES.format(source=spec.source))
    comp = _CACHE.get(spec)
    if comp is None:
        comp = _CACHE[spec] = _Compiled(spec)
    return comp


def parameter_values(
    spec: Spec, kappa: float, theta: Mapping[str, float] | None = None
) -> dict[str, float]:
    """Numeric values of every parameter at ``kappa``; ``theta`` overrides input parameters."""
    comp = _compiled(spec)
    m, L = spec.mL(kappa)
    theta = dict(theta or {})
    for p in theta:
        if p not in spec.parameters:
            raise ModelError(f"parameters.{p}", "unknown parameter")
        if spec.parameters[p].is_tied:
            raise ModelError(f"parameters.{p}", "is tied to other parameters; it cannot be set")
    values = [m, L, kappa] + [0.0] * len(comp.names)
    pos = {p: 3 + i for i, p in enumerate(comp.names)}
    for p in comp.order:
        if p in theta:
            val = float(theta[p])
            if not np.isfinite(val):
                raise ModelError(f"parameters.{p}", "value is not finite")
        else:
            try:
                val = comp.param_fns[p](values)
            except NumericError as exc:
                what = "" if spec.parameters[p].is_tied else ".value"
                raise ModelError(f"parameters.{p}{what}", str(exc)) from None
        values[pos[p]] = val
    return {p: values[pos[p]] for p in comp.names}


def parameter_box(spec: Spec, kappa: float, names: list[str]) -> list[tuple[float, float]]:
    """Numeric (lo, hi) of each named parameter's range at ``kappa``."""
    comp = _compiled(spec)
    m, L = spec.mL(kappa)
    out = []
    for p in names:
        if p not in comp.range_fns:
            raise ModelError(f"parameters.{p}.range", "missing")
        lo_fn, hi_fn = comp.range_fns[p]
        try:
            lo, hi = lo_fn([m, L, kappa]), hi_fn([m, L, kappa])
        except NumericError as exc:
            raise ModelError(f"parameters.{p}.range", str(exc)) from None
        if lo > hi:
            raise ModelError(f"parameters.{p}.range", f"empty box [{lo:g}, {hi:g}]")
        out.append((lo, hi))
    return out


def design_box(spec: Spec, kappa: float, names: list[str]) -> list[tuple[float, float]]:
    """:func:`parameter_box`, refused with a :class:`ModelError` naming the parameter when a
    range is too large for design: an end beyond ``MAX_DESIGN_ENTRY`` in size, or one (the
    other parameters at their box centres) where the method's matrices have an entry
    that large or not finite. The grid, the solvers and the bound would then work on
    overflowing numbers; ends where the method cannot be evaluated otherwise (a domain
    error) are left to the search, which skips such points."""
    box = parameter_box(spec, kappa, names)
    centre = {p: 0.5 * lo + 0.5 * hi for p, (lo, hi) in zip(names, box, strict=True)}
    for p, (lo, hi) in zip(names, box, strict=True):
        for end in (lo, hi):
            size = abs(end) if abs(end) > MAX_DESIGN_ENTRY else _matrix_size(
                spec, kappa, {**centre, p: end})
            if size is not None and not size <= MAX_DESIGN_ENTRY:
                raise ModelError(
                    f"parameters.{p}.range",
                    f"[{lo:g}, {hi:g}] is too large for design: at {p} = {end:g} the "
                    f"method's numbers reach {size:.3g} (design needs them below "
                    f"{MAX_DESIGN_ENTRY:g}); narrow the range")
    return box


def _matrix_size(spec: Spec, kappa: float, theta: Mapping[str, float]) -> float | None:
    """Largest |entry| of A, B, C, E at ``theta`` (inf when one overflows; None when the
    point cannot be evaluated for another reason)."""
    comp = _compiled(spec)
    m, L = spec.mL(kappa)
    try:
        params = parameter_values(spec, kappa, theta)
        values = [m, L, kappa] + [params[p] for p in comp.names]
        with np.errstate(all="ignore"):
            return max(float(np.max(np.abs(fn(values)))) for fn in comp.matrix_fns.values())
    except OverflowError:
        return float("inf")
    except (NumericError, ModelError) as exc:
        return float("inf") if "finite" in str(exc) else None


def bind(spec: Spec, kappa: float, theta: Mapping[str, float] | None = None) -> OracleMethod:
    """The spec's method at condition number ``kappa`` (m = spec.m, L = kappa m): the one
    float method, :class:`~sosalgo.oracles.OracleMethod`, in the seed's form an
    :class:`Algorithm` (``has_seed_form``).

    ``theta`` sets input parameters (others keep their ``value``; tied ones follow).
    The fixed-point conditions of eq. (11) are checked on creation.
    """
    return evaluate_algorithm(spec, kappa, theta)


def evaluate_algorithm(
    spec: Spec, kappa: float, theta: Mapping[str, float] | None = None
) -> OracleMethod:
    """The numeric templates at ``kappa`` and ``theta`` as the one float method (an
    :class:`Algorithm` for a spec in the seed's form), which refuses a method without the
    fixed point of eq. (11) (:class:`ModelError`)."""
    if not (np.isfinite(kappa) and kappa > 1):
        raise ModelError("kappa", f"condition number must be > 1, got {kappa:g}")
    comp = _compiled(spec)
    m, L = spec.mL(kappa)
    if not np.isfinite(L):
        raise ModelError("kappa", f"L = kappa * m overflows at kappa={kappa:g}")
    params = parameter_values(spec, kappa, theta)
    mats = _matrices(comp, [m, L, kappa] + [params[p] for p in comp.names])
    if spec.has_seed_form:
        return Algorithm(mats["A"], mats["B"], mats["C"], mats["E"], m, L, params)
    return make_method(spec, mats, m, L, kappa, params)


def fixed_point(alg: OracleMethod, tol: float = FIXED_POINT_TOL) -> np.ndarray | None:
    """The u of eq. (11) (least-squares solution), or None if the conditions fail: the
    method's xi* for x* = 1 with zero optimal subgradients
    (:func:`sosalgo.oracles.fixed_point_basis`; in the seed's form (I - A) u = 0,
    C u = 1, E u = 1)."""
    basis = fixed_point_basis(alg, tol)
    return None if basis is None else basis[:, 0]


def bind_sublinear(spec: Spec, theta: Mapping[str, float] | None = None,
                   moving_optimum: bool = False) -> OracleMethod:
    """The :class:`OracleMethod` of a sublinear spec (``m: 0``, L given, no kappa) at its
    parameter values (``theta`` overrides input parameters); ModelError names the field.
    ``moving_optimum``: a state at the optimum that moves with the optimal subgradients
    (Douglas-Rachford) is accepted (the PEP takes it; the sublinear potentials, started
    at rest at x_0, do not, except for several operators: their state change is bounded
    from a free start)."""
    if spec.has_condition_number or spec.L is None:
        raise ModelError("m", "not a sublinear spec (m: 0, L given)")
    comp = _compiled(spec)
    nan = float("nan")
    params = parameter_values(spec, nan, theta)
    mats = _matrices(comp, [0.0, spec.L, nan] + [params[p] for p in comp.names])
    om = make_method(spec, mats, 0.0, spec.L, nan, params)
    basis = fixed_point_basis(om)
    several_operators = len(om.functions) > 1 and not any(fn[1].has_values
                                                         for fn in om.functions)
    moving_optimum = moving_optimum or several_operators  # measured by the state change
    if (not moving_optimum and basis is not None and basis.shape[1] > 1
            and np.abs(basis[:, 1:]).max() > 1e-12):
        raise ModelError("functions", "m: 0 (sublinear rates) needs a state at the optimum "
                         "that does not depend on the optimal subgradients (the potential "
                         "starts the method at rest at x_0); this method's does (e.g. "
                         "Douglas-Rachford): analyze it with a kappa instead")
    return om


def _matrices(comp: _Compiled, values: list[float]) -> dict[str, np.ndarray]:
    """The spec's matrices at ``values`` (m, L, kappa, then the parameters); a domain
    error becomes a ModelError naming the matrix."""
    mats = {}
    for k, fn in comp.matrix_fns.items():
        try:
            mats[k] = fn(values)
        except NumericError as exc:
            raise ModelError(f"matrices.{k}", str(exc)) from None
    return mats
