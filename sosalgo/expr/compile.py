"""Fast, safe numeric evaluation of the sympy expressions built by :mod:`sosalgo.expr`.

An expression is compiled once into nested Python closures (no code generation, no
``eval``) and then evaluated at many points (kappa values, grid points).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import sympy as sp

from sosalgo.errors import InputError

__all__ = ["NumericError", "compile_expression", "compile_matrix"]

Fn = Callable[[Sequence[float]], float]


class NumericError(InputError):
    """An expression cannot be evaluated to a finite real number at the given point."""


def compile_expression(expr: sp.Expr, symbols: Sequence[sp.Symbol]) -> Fn:
    """Return ``f(values) -> float`` evaluating ``expr`` with ``symbols[i] = values[i]``."""
    index = {s: i for i, s in enumerate(symbols)}
    inner = _compile(sp.sympify(expr), index)

    def evaluate(values: Sequence[float]) -> float:
        try:
            out = inner(values)
        except (ValueError, ZeroDivisionError, OverflowError, TypeError) as exc:
            raise NumericError(_reason(exc)) from None
        if isinstance(out, complex) or not math.isfinite(out):
            raise NumericError("value is not a finite real number")
        return float(out)

    return evaluate


def compile_matrix(
    mat: sp.Matrix, symbols: Sequence[sp.Symbol]
) -> Callable[[Sequence[float]], np.ndarray]:
    """Compile every entry of ``mat``; returns ``f(values) -> ndarray``."""
    rows, cols = mat.shape
    fns = [compile_expression(mat[i, j], symbols) for i in range(rows) for j in range(cols)]

    def evaluate(values: Sequence[float]) -> np.ndarray:
        return np.array([f(values) for f in fns], dtype=float).reshape(rows, cols)

    return evaluate


def _reason(exc: Exception) -> str:
    if isinstance(exc, ZeroDivisionError):
        return "division by zero"
    if isinstance(exc, OverflowError):
        return "numeric overflow"
    return "outside the domain of a function (sqrt/log of a negative number?)"


def _pow(a: float, b: float) -> float:
    if a == 0 and b < 0:
        raise ZeroDivisionError
    return math.pow(a, b)


def _short(expr: sp.Basic, n: int = 60) -> str:
    text = str(expr)
    return text if len(text) <= n else text[: n - 3] + "..."


def _compile(expr: sp.Basic, index: dict[sp.Symbol, int]) -> Callable[[Sequence[float]], float]:
    if isinstance(expr, sp.Symbol):
        if expr not in index:
            raise NumericError(f"unbound symbol '{expr}'")
        i = index[expr]
        return lambda v: float(v[i])
    if isinstance(expr, sp.Number | sp.NumberSymbol):
        try:
            value = float(expr)
        except (TypeError, ValueError, OverflowError):
            value = math.nan
        if not math.isfinite(value):
            raise NumericError(f"constant {_short(expr)} is not a finite real number")
        return lambda v: value
    if expr.is_number:
        # Other constants (sqrt(2), exp(3), ...) are folded in floating point through the
        # closures below: sympy's arbitrary-precision evalf can take unbounded time.
        fn = _compile_operation(expr, index)
        try:
            value = fn(())
        except (ValueError, ZeroDivisionError, OverflowError, TypeError):
            value = math.nan
        if isinstance(value, complex) or not math.isfinite(value):
            raise NumericError(f"constant {_short(expr)} is not a finite real number")
        return lambda v: value
    return _compile_operation(expr, index)


def _compile_operation(
    expr: sp.Basic, index: dict[sp.Symbol, int]
) -> Callable[[Sequence[float]], float]:
    args = [_compile(a, index) for a in expr.args]
    if isinstance(expr, sp.Add):
        return lambda v: math.fsum(f(v) for f in args)
    if isinstance(expr, sp.Mul):
        def mul(v: Sequence[float]) -> float:
            out = 1.0
            for f in args:
                out *= f(v)
            return out
        return mul
    if isinstance(expr, sp.Pow):
        base, ex = args
        return lambda v: _pow(base(v), ex(v))
    unary = {sp.exp: math.exp, sp.log: math.log, sp.Abs: abs}
    for cls, fn in unary.items():
        if isinstance(expr, cls):
            (a,) = args
            return lambda v, fn=fn: fn(a(v))
    if isinstance(expr, sp.Min):
        return lambda v: min(f(v) for f in args)
    if isinstance(expr, sp.Max):
        return lambda v: max(f(v) for f in args)
    raise NumericError(f"unsupported operation {type(expr).__name__}")
