"""Fast, safe numeric evaluation of the expression trees of :mod:`sosalgo.kernel.expr.tree`.

An expression is compiled once into nested Python closures (no code generation, no
``eval``, no computer algebra) and then evaluated at many points (kappa values, grid
points). Constant subexpressions are folded once.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from sosalgo.errors import InputError
from sosalgo.kernel.expr.tree import Expr, apply, evaluate, power

__all__ = ["NumericError", "compile_expression", "compile_matrix"]

Fn = Callable[[Sequence[float]], float]


class NumericError(InputError):
    """An expression cannot be evaluated to a finite real number at the given point."""


def compile_expression(expr: Expr, names: Sequence[str]) -> Fn:
    """Return ``f(values) -> float`` evaluating ``expr`` with ``names[i] = values[i]``."""
    index = {s: i for i, s in enumerate(names)}
    inner = _compile(expr, index)

    def evaluate_at(values: Sequence[float]) -> float:
        try:
            out = inner(values)
        except (ValueError, ZeroDivisionError, OverflowError, TypeError) as exc:
            raise NumericError(_reason(exc)) from None
        if isinstance(out, complex) or not math.isfinite(out):
            raise NumericError("value is not a finite real number")
        return float(out)

    return evaluate_at


def compile_matrix(
    rows: Sequence[Sequence[Expr]], names: Sequence[str]
) -> Callable[[Sequence[float]], np.ndarray]:
    """Compile every entry of a matrix given as rows of trees; ``f(values) -> ndarray``."""
    shape = (len(rows), len(rows[0]))
    fns = [compile_expression(e, names) for row in rows for e in row]

    def evaluate_at(values: Sequence[float]) -> np.ndarray:
        return np.array([f(values) for f in fns], dtype=float).reshape(shape)

    return evaluate_at


def _reason(exc: Exception) -> str:
    if isinstance(exc, ZeroDivisionError):
        return "division by zero"
    if isinstance(exc, OverflowError):
        return "numeric overflow"
    return "outside the domain of a function (sqrt/log of a negative number?)"


def _short(expr: Expr, n: int = 60) -> str:
    text = str(expr)
    return text if len(text) <= n else text[: n - 3] + "..."


def _compile(expr: Expr, index: dict[str, int]) -> Fn:
    if expr.op == "name":
        name = expr.args[0]
        if name not in index:
            raise NumericError(f"unbound symbol '{name}'")
        i = index[name]
        return lambda v: float(v[i])
    if expr.is_constant:
        try:
            value = evaluate(expr, {})
        except (ValueError, ZeroDivisionError, OverflowError):
            value = math.nan
        if not math.isfinite(value):
            raise NumericError(f"constant {_short(expr)} is not a finite real number")
        return lambda v: value
    args = [_compile(a, index) for a in expr.args]
    op = expr.op
    if op == "+":
        a, b = args
        return lambda v: a(v) + b(v)
    if op == "-":
        a, b = args
        return lambda v: a(v) - b(v)
    if op == "*":
        a, b = args
        return lambda v: a(v) * b(v)
    if op == "/":
        a, b = args
        return lambda v: a(v) / b(v)
    if op == "**":
        a, b = args
        return lambda v: power(a(v), b(v))
    if op == "neg":
        (a,) = args
        return lambda v: -a(v)
    return lambda v: apply(op, [f(v) for f in args])  # functions: sqrt, exp, ..., max
