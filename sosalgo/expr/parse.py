"""Safe arithmetic expressions for spec templates.

An expression such as ``(sqrt(kappa) - 1)/(sqrt(kappa) + 1)`` is *parsed* with Python's
``ast`` module and converted node by node into a sympy expression. Only numbers, the
names the caller allows, ``+ - * / **``, unary signs, parentheses and the functions
``sqrt exp log abs min max`` (and the constant ``pi``) are accepted. Nothing is ever
``eval``-ed: an attribute access, a call of anything else, a subscript, a lambda, a
string literal ... is a parse error. (sympy's own ``parse_expr`` calls ``eval`` on the
transformed text, so it is deliberately not used here.)
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping

import sympy as sp

from sosalgo.errors import InputError

__all__ = ["ExprError", "parse_expression", "FUNCTIONS", "MAX_LENGTH"]

MAX_LENGTH = 2000  # characters; longer strings are refused before parsing
MAX_DEPTH = 60  # nesting depth of the syntax tree
MAX_MAGNITUDE_LOG10 = 300  # numeric constants must stay below 1e300 in magnitude
# exp() of a constant beyond this would leave the float range (and sympy's arbitrary-precision
# evalf of exp(exp(exp(100))) never finishes), so such constants are refused while parsing.
MAX_EXP_ARGUMENT = MAX_MAGNITUDE_LOG10 * math.log(10)

FUNCTIONS: dict[str, object] = {
    "sqrt": sp.sqrt,
    "exp": sp.exp,
    "log": sp.log,
    "abs": sp.Abs,
    "min": sp.Min,
    "max": sp.Max,
}
CONSTANTS: dict[str, sp.Expr] = {"pi": sp.pi}


class ExprError(InputError):
    """An expression string that is not a valid, safe arithmetic expression."""


def parse_expression(text: object, names: Mapping[str, sp.Symbol]) -> sp.Expr:
    """Parse ``text`` (a string or a number) into a sympy expression over ``names``.

    Raises :class:`ExprError` with a one-line message for anything outside the grammar.
    """
    if isinstance(text, bool):
        raise ExprError("expected a number or an expression, got a boolean")
    if isinstance(text, int):
        return _number(text)
    if isinstance(text, float):
        if not math.isfinite(text):
            raise ExprError(f"number {text} is not finite")
        return _number(text)
    if not isinstance(text, str):
        raise ExprError(f"expected a number or an expression, got {type(text).__name__}")
    src = text.strip()
    if not src:
        raise ExprError("empty expression")
    if len(src) > MAX_LENGTH:
        raise ExprError(f"expression longer than {MAX_LENGTH} characters")
    if "^" in src:
        raise ExprError("'^' is not a power operator here; write '**'")
    try:
        tree = ast.parse(src, mode="eval")
    except (SyntaxError, ValueError, MemoryError, RecursionError) as exc:
        msg = exc.msg if isinstance(exc, SyntaxError) else type(exc).__name__
        raise ExprError(f"cannot parse {_short(src)!r}: {msg}") from None
    try:
        return _Converter(names).convert(tree.body, 0)
    except RecursionError:
        raise ExprError("expression nested too deeply") from None


def _short(src: str, n: int = 60) -> str:
    return src if len(src) <= n else src[: n - 3] + "..."


def _number(value: int | float) -> sp.Expr:
    if value != 0 and math.log10(abs(value)) > MAX_MAGNITUDE_LOG10:
        raise ExprError("number too large")
    if isinstance(value, int):
        return sp.Integer(value)
    return sp.nsimplify(value, rational=True) if abs(value) >= 1e-300 or value == 0 else sp.Float(0)


class _Converter:
    """Walks a Python syntax tree, accepting only the whitelisted grammar."""

    def __init__(self, names: Mapping[str, sp.Symbol]):
        self.names = names

    def convert(self, node: ast.AST, depth: int) -> sp.Expr:
        if depth > MAX_DEPTH:
            raise ExprError("expression nested too deeply")
        d = depth + 1
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, int | float):
                raise ExprError(f"unsupported literal {node.value!r}")
            return _number(node.value)
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return self.names[node.id]
            if node.id in CONSTANTS:
                return CONSTANTS[node.id]
            if node.id in FUNCTIONS:
                raise ExprError(f"function '{node.id}' used without arguments")
            raise ExprError(f"unknown name '{node.id}'")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
            operand = self.convert(node.operand, d)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.BinOp):
            left = self.convert(node.left, d)
            right = self.convert(node.right, d)
            return self._binop(node.op, left, right)
        if isinstance(node, ast.Call):
            return self._call(node, d)
        raise ExprError(f"unsupported syntax ({type(node).__name__})")

    def _binop(self, op: ast.operator, left: sp.Expr, right: sp.Expr) -> sp.Expr:
        if isinstance(op, ast.Add):
            out = left + right
        elif isinstance(op, ast.Sub):
            out = left - right
        elif isinstance(op, ast.Mult):
            out = left * right
        elif isinstance(op, ast.Div):
            if right.is_zero:
                raise ExprError("division by zero")
            out = left / right
        elif isinstance(op, ast.Pow):
            _check_power(left, right)
            out = left**right
        else:
            raise ExprError(f"unsupported operator {type(op).__name__}")
        return _check_finite(out)

    def _call(self, node: ast.Call, depth: int) -> sp.Expr:
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            what = node.func.id if isinstance(node.func, ast.Name) else "this expression"
            raise ExprError(f"call of '{what}' is not allowed")
        if node.keywords:
            raise ExprError("keyword arguments are not allowed")
        name = node.func.id
        args = [self.convert(a, depth) for a in node.args]
        if name in ("min", "max"):
            if len(args) < 2:
                raise ExprError(f"{name}() needs at least two arguments")
        elif len(args) != 1:
            raise ExprError(f"{name}() takes exactly one argument")
        if name == "log" and args[0].is_zero:
            raise ExprError("log(0)")
        if name == "exp" and args[0].is_number and _magnitude(args[0]) > MAX_EXP_ARGUMENT:
            raise ExprError("argument of exp() too large in magnitude")
        if name in ("min", "max"):
            # Kept as written: sympy's evaluation of Min/Max compares every pair of arguments
            # through the assumptions system, which takes seconds for a few dozen arguments.
            return _check_finite(FUNCTIONS[name](*args, evaluate=False))  # type: ignore[operator]
        return _check_finite(FUNCTIONS[name](*args))  # type: ignore[operator]


def _check_power(base: sp.Expr, exponent: sp.Expr) -> None:
    """Refuse powers whose value could explode (e.g. 10**10**10)."""
    if exponent.is_number:
        e = _magnitude(exponent)
        if e > 64:
            raise ExprError("exponent larger than 64 in magnitude")
        e = _real(exponent)
        if base.is_number:
            b = _magnitude(base)
            if b == 0 and e < 0:
                raise ExprError("division by zero")
            if b > 0 and abs(e * math.log10(b)) > MAX_MAGNITUDE_LOG10:
                raise ExprError("number too large")


def _magnitude(value: sp.Expr) -> float:
    """|value| of a constant (inf when it leaves the float range or cannot be evaluated)."""
    try:
        return abs(complex(value.evalf(20)))
    except (OverflowError, TypeError, ValueError):
        return math.inf


def _real(value: sp.Expr) -> float:
    """Real part of a constant whose magnitude is known to be small."""
    return complex(value.evalf(20)).real


def _check_finite(expr: sp.Expr) -> sp.Expr:
    if expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ExprError("expression is not finite (division by zero?)")
    if expr.has(sp.I):
        raise ExprError("expression is not real (square root or log of a negative number?)")
    return expr
