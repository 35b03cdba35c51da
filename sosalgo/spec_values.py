"""The checks of a parsed spec at its own values (the ``values`` check of
:mod:`sosalgo.spec.checks`, run by every spec load): at every kappa of the spec, its
references are numbers, its parameters lie in their ranges, the method binds
(:func:`sosalgo.model.bind`: the fixed-point conditions of eq. (11)) and
``initial_state:`` starts it at the fixed point.

Every problem is reported through ``fail(field, message)``, the loader's one-line
:class:`~sosalgo.spec.SpecError` naming the file and the field.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from typing import Any

import numpy as np

from sosalgo.kernel.expr import Expr
from sosalgo.kernel.expr.compile import NumericError, compile_expression
from sosalgo.model import ModelError, bind, bind_sublinear, parameter_box, parameter_values
from sosalgo.oracles import as_oracle_method, fixed_point_basis
from sosalgo.spec.initial_state import FIELD, initial_state_values
from sosalgo.spec.types import BASE_NAMES, Spec

__all__ = ["check_in_range", "check_initial_state", "check_sublinear_values", "check_values"]

Fail = Callable[[str, str], Exception]


def check_values(spec: Spec, data: Mapping[str, Any], fail: Fail) -> None:
    """The numeric checks at the spec's own values, at every kappa of the spec."""
    if spec.time_varying:
        from sosalgo.steps import check_steps

        check_steps(spec, fail)
        return
    if spec.sublinear:
        check_sublinear_values(spec, fail)
        return
    for k in spec.kappa:
        if not math.isfinite(spec.mL(k)[1]):
            raise fail("kappa", f"L = kappa * m overflows at kappa={k:g}, m={spec.m:g}")
    for ref, expr in spec.references.items():
        where = f"references.{ref}"
        fn = _compile_or_fail(expr, fail, where)
        for k in spec.kappa:
            _num(fn, spec, k, fail, where)
    for pname, par in spec.parameters.items():
        if par.range is None:
            continue
        where = f"parameters.{pname}.range"
        fns = [_compile_or_fail(e, fail, where) for e in par.range]
        for k in spec.kappa:
            lo, hi = (_num(fn, spec, k, fail, where) for fn in fns)
            if lo > hi:
                raise fail(
                    f"parameters.{pname}.range",
                    f"lower bound {lo:g} exceeds upper bound {hi:g} at kappa={k:g}",
                )
    for k in spec.kappa:
        try:
            bind(spec, k)
        except ModelError as exc:
            raise fail(exc.field, f"at kappa={k:g}: {exc.message}") from None
    check_in_range(spec, fail)
    check_initial_state(spec, spec.kappa, fail)


def check_sublinear_values(spec: Spec, fail: Fail) -> None:
    """:func:`check_values` for a sublinear spec: at (m, L) = (0, L), kappa undefined."""
    nan = math.nan
    for ref, expr in spec.references.items():
        _num(_compile_or_fail(expr, fail, f"references.{ref}"), spec, nan, fail,
             f"references.{ref}")
    try:
        values = parameter_values(spec, nan)
        ranged = spec.ranged
        for pname, (lo, hi) in zip(ranged, parameter_box(spec, nan, ranged), strict=True):
            slack = 1e-12 * max(1.0, abs(lo), abs(hi))
            if not lo - slack <= values[pname] <= hi + slack:
                raise fail(f"parameters.{pname}.value", f"{values[pname]:.6g} is "
                           f"outside its range [{lo:.6g}, {hi:.6g}]")
        bind_sublinear(spec, moving_optimum=True)  # analyze refuses it, pep takes it
    except ModelError as exc:
        raise fail(exc.field, exc.message) from None
    check_initial_state(spec, [nan], fail)


def check_in_range(spec: Spec, fail: Fail) -> None:
    """Each ranged parameter's value lies in its own range at every kappa of the spec."""
    ranged = spec.ranged
    if not ranged:
        return
    for k in spec.kappa:
        values = parameter_values(spec, k)
        for pname, (lo, hi) in zip(ranged, parameter_box(spec, k, ranged), strict=True):
            v = values[pname]
            slack = 1e-12 * max(1.0, abs(lo), abs(hi))
            if not lo - slack <= v <= hi + slack:
                raise fail(f"parameters.{pname}.value",
                           f"{v:.6g} is outside its range [{lo:.6g}, {hi:.6g}] "
                           f"at kappa={k:g}")


def check_initial_state(spec: Spec, kappas: Collection[float], fail: Fail) -> None:
    """``initial_state:`` at every kappa: the coefficients are finite and the
    x0-coefficients are the fixed-point direction u (relative 1e-9)."""
    if spec.initial_state is None:
        return
    for k in kappas:
        m, L = (0.0, spec.L) if spec.sublinear else spec.mL(k)
        env = {"m": m, "L": L, "kappa": k, **parameter_values(spec, k)}
        try:
            a, b = initial_state_values(spec.initial_state, env)
        except (ValueError, ZeroDivisionError, OverflowError, KeyError) as exc:
            raise fail(FIELD, f"not a number at kappa={k:g}: {exc}") from None
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise fail(FIELD, f"not a finite number at kappa={k:g}")
        om = as_oracle_method(bind_sublinear(spec, moving_optimum=True) if spec.sublinear
                          else bind(spec, k))
        X = fixed_point_basis(om)
        u = X[:, 0] if X is not None else None
        if u is not None and np.abs(a - u).max() > 1e-9 * (1 + np.abs(u).max()):
            at = "" if math.isnan(k) else f" at kappa={k:g}"
            raise fail(FIELD, f"the x0-coefficients {np.round(a, 9).tolist()} must be the "
                       f"fixed-point direction u = {np.round(u, 9).tolist()}{at}")


def _compile_or_fail(expr: Expr, fail: Fail, where: str) -> Callable[[Sequence[float]], float]:
    """``expr`` (over m, L, kappa) compiled once for evaluation at every kappa."""
    try:
        return compile_expression(expr, BASE_NAMES)
    except NumericError as exc:
        raise fail(where, str(exc)) from None


def _num(fn: Callable[[Sequence[float]], float], spec: Spec, kappa: float, fail: Fail,
         where: str) -> float:
    m, L = spec.mL(kappa)
    try:
        return fn([m, L, kappa])
    except NumericError as exc:
        at = "" if spec.sublinear else f"at kappa={kappa:g}: "
        raise fail(where, f"{at}{exc}") from None
