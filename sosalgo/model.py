"""Bind a spec to numbers: kappa (m, L) and parameter values -> numeric A, B, C, E.

Also checks the fixed-point conditions of eq. (11): there must be a u with
(I - A) u = 0, C u = 1 and E u = 1, so that xi* = u ⊗ x* is a fixed point with
y* = x* (Remark 1 reduction).
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sosalgo.errors import ModelError
from sosalgo.kernel.expr.compile import NumericError, compile_expression, compile_matrix
from sosalgo.oracles import check_magnitudes
from sosalgo.spec.types import BASE_NAMES, MATRIX_NAMES, Spec, SpecError, value_order

__all__ = ["Algorithm", "ModelError", "bind", "bind_sublinear", "design_box", "evaluate_algorithm",
           "fixed_point"]

FIXED_POINT_TOL = 1e-8
MAX_DESIGN_ENTRY = 1e50  # largest parameter value or matrix entry a design box may reach


@dataclass(frozen=True)
class Algorithm:
    """Numeric reduced templates (Remark 1) of one method on F(m, L).

    A, B, C, E may be given as nested lists or arrays; they are stored as float arrays of
    shapes n x n, n x 1, 1 x n, 1 x n. As in the spec loader, a method without the fixed
    point of eq. (11) is refused with a :class:`ModelError` (``require_fixed_point=False``
    skips that check, for algebraic tests only).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    E: np.ndarray
    m: float
    L: float
    params: dict[str, float] = field(default_factory=dict)
    require_fixed_point: bool = field(default=True, repr=False, compare=False)

    def __post_init__(self) -> None:
        mats = {}
        for k in MATRIX_NAMES:
            try:
                mats[k] = np.array(getattr(self, k), dtype=float, ndmin=2)
            except (TypeError, ValueError):
                raise ModelError(f"matrices.{k}", "must be a matrix of numbers") from None
            check_magnitudes(k, mats[k])
            object.__setattr__(self, k, mats[k])
        n = mats["A"].shape[0]
        shapes = {"A": (n, n), "B": (n, 1), "C": (1, n), "E": (1, n)}
        for k, shape in shapes.items():
            if mats[k].shape != shape:
                raise ModelError(f"matrices.{k}", f"must be {shape[0]}x{shape[1]}, "
                                 f"got {mats[k].shape[0]}x{mats[k].shape[1]}")
        m, L = float(self.m), float(self.L)
        if not (np.isfinite(m) and np.isfinite(L) and 0 < m < L):
            raise ModelError("m, L", f"need 0 < m < L (finite), got m={m:g}, L={L:g}")
        object.__setattr__(self, "m", m)
        object.__setattr__(self, "L", L)
        if self.require_fixed_point and fixed_point(self) is None:
            raise ModelError(
                "matrices",
                "no fixed point: eq. (11) needs u with (I - A) u = 0, C u = 1, E u = 1",
            )

    @property
    def kappa(self) -> float:
        return self.L / self.m

    @property
    def n(self) -> int:
        return int(self.A.shape[0])


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


def bind(spec: Spec, kappa: float, theta: Mapping[str, float] | None = None) -> Algorithm:
    """Numeric Algorithm at condition number ``kappa`` (m = spec.m, L = kappa m).

    ``theta`` sets input parameters (others keep their ``value``; tied ones follow).
    The fixed-point conditions of eq. (11) are checked (by :class:`Algorithm`). A spec
    outside the seed's setting (``spec.composite``) gives an
    :class:`~sosalgo.oracles.OracleMethod` (its own fixed-point check).
    """
    return evaluate_algorithm(spec, kappa, theta)


def evaluate_algorithm(
    spec: Spec, kappa: float, theta: Mapping[str, float] | None = None
) -> Algorithm:
    """The numeric templates at ``kappa`` and ``theta`` as an :class:`Algorithm` (which
    refuses a method without the fixed point of eq. (11), :class:`ModelError`)."""
    if not (np.isfinite(kappa) and kappa > 1):
        raise ModelError("kappa", f"condition number must be > 1, got {kappa:g}")
    comp = _compiled(spec)
    m, L = spec.mL(kappa)
    if not np.isfinite(L):
        raise ModelError("kappa", f"L = kappa * m overflows at kappa={kappa:g}")
    params = parameter_values(spec, kappa, theta)
    mats = _matrices(comp, [m, L, kappa] + [params[p] for p in comp.names])
    if spec.composite:
        from sosalgo.oracles import make_method

        return make_method(spec, mats, m, L, kappa, params)  # type: ignore[return-value]
    return Algorithm(mats["A"], mats["B"], mats["C"], mats["E"], m, L, params)


def fixed_point(alg: Algorithm, tol: float = FIXED_POINT_TOL) -> np.ndarray | None:
    """The u of eq. (11) (least-squares solution), or None if the conditions fail. For a
    method of the oracle model: its xi* for x* = 1 with zero optimal subgradients
    (:func:`sosalgo.oracles.fixed_point_basis`)."""
    if hasattr(alg, "oracles"):
        from sosalgo.oracles import fixed_point_basis

        basis = fixed_point_basis(alg, tol)  # type: ignore[arg-type]
        return None if basis is None else basis[:, 0]
    from sosalgo.oracles import consistent_solution

    n = alg.n
    lhs = np.vstack([np.eye(n) - alg.A, alg.C, alg.E])
    rhs = np.concatenate([np.zeros(n), [1.0, 1.0]])[:, None]
    u = consistent_solution(lhs, rhs, tol)
    return None if u is None else u[:, 0]


def bind_sublinear(spec: Spec, theta: Mapping[str, float] | None = None) -> Any:
    """The :class:`OracleMethod` of a sublinear spec (``m: 0``, L given, no kappa) at its
    parameter values (``theta`` overrides input parameters); ModelError names the field."""
    from sosalgo.oracles import fixed_point_basis, make_method

    if not spec.sublinear or spec.L is None:
        raise ModelError("m", "not a sublinear spec (m: 0, L given)")
    comp = _compiled(spec)
    nan = float("nan")
    params = parameter_values(spec, nan, theta)
    mats = _matrices(comp, [0.0, spec.L, nan] + [params[p] for p in comp.names])
    om = make_method(spec, mats, 0.0, spec.L, nan, params)
    basis = fixed_point_basis(om)
    if basis is not None and basis.shape[1] > 1 and np.abs(basis[:, 1:]).max() > 1e-12:
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
