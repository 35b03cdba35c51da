"""Safe arithmetic expressions for spec templates, parsed into a small syntax tree.

An expression such as ``(sqrt(kappa) - 1)/(sqrt(kappa) + 1)`` is *parsed* with Python's
``ast`` module and converted node by node into an :class:`Expr` tree. Only numbers, the
names the caller allows, ``+ - * / **``, unary signs, parentheses and the functions
``sqrt exp log abs min max`` (and the constant ``pi``) are accepted. Nothing is ever
``eval``-ed: an attribute access, a call of anything else, a subscript, a lambda, a
string literal ... is a parse error. (sympy's own ``parse_expr`` calls ``eval`` on the
transformed text, so it is deliberately not used.)

The tree needs no computer algebra: numeric work (:mod:`~sosalgo.kernel.expr.compile`) reads it
directly, so analysing a spec never imports sympy. Symbolic work (design, ``lmi``, exact
verification) converts it with :func:`sosalgo.kernel.expr.parse.to_sympy`.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from functools import cached_property

from sosalgo.errors import InputError

__all__ = [
    "Expr", "ExprError", "Measure", "parse_tree", "check_measure", "constant_value", "evaluate",
    "measure", "FUNCTIONS", "MAX_LENGTH",
]

MAX_LENGTH = 2000  # characters; longer strings are refused before parsing
MAX_DEPTH = 60  # nesting depth of the syntax tree
MAX_MAGNITUDE_LOG10 = 300  # numeric constants must stay below 1e300 in magnitude
# exp() of a constant beyond this would leave the float range (and an arbitrary-precision
# evaluation of exp(exp(exp(100))) never finishes), so such constants are refused.
MAX_EXP_ARGUMENT = MAX_MAGNITUDE_LOG10 * math.log(10)
MAX_EXPONENT = 64  # of one power, and of the product of nested powers (2**8)**8 (see measure)
# Whole-expression bounds (see :func:`measure`), with tied parameters written out as their
# expressions, as symbolic work (``lmi``, ``design``, exact checks) sees them: the degree of
# a polynomial grows the cost of expanding it steeply, a tree written out through a chain of
# parameters can double with every link.
MAX_DEGREE = 32
MAX_NODES = 10_000
MAX_INLINED_DEPTH = 150

FUNCTIONS = ("sqrt", "exp", "log", "abs", "min", "max")
CONSTANTS = {"pi": math.pi}
_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}


class ExprError(InputError):
    """An expression string that is not a valid, safe arithmetic expression."""


@dataclass(frozen=True)
class Expr:
    """A node: ``op`` is ``num`` (args: the number), ``name`` (args: the name), ``pi``, a
    binary operator ``+ - * / **``, ``neg``, or a function of :data:`FUNCTIONS`."""

    op: str
    args: tuple

    def names(self) -> frozenset[str]:
        """The names (parameters, m, L, kappa) the expression refers to."""
        return self._names

    @cached_property
    def _names(self) -> frozenset[str]:
        if self.op == "name":
            return frozenset(self.args)
        if self.op in ("num", "pi"):
            return frozenset()
        return frozenset().union(*(a.names() for a in self.args))

    @property
    def is_constant(self) -> bool:
        return not self._names

    def __str__(self) -> str:
        return _show(self, 0)

    __repr__ = __str__


_PRECEDENCE = {"+": 1, "-": 1, "*": 2, "/": 2, "neg": 3, "**": 4}


def _show(e: Expr, outer: int) -> str:
    if e.op == "num":
        return repr(e.args[0])
    if e.op == "name":
        return e.args[0]
    if e.op == "pi":
        return "pi"
    if e.op in FUNCTIONS:
        return f"{e.op}({', '.join(_show(a, 0) for a in e.args)})"
    prec = _PRECEDENCE[e.op]
    if e.op == "neg":
        text = "-" + _show(e.args[0], prec)
    else:
        left, right = e.args
        # ** is right-associative, the others left-associative
        lp, rp = (prec + 1, prec) if e.op == "**" else (prec, prec + 1)
        text = f"{_show(left, lp)} {e.op} {_show(right, rp)}"
    return f"({text})" if prec < outer or (e.op == "neg" and outer == 4) else text


def parse_tree(text: object, names: Collection[str]) -> Expr:
    """Parse ``text`` (a string or a number) into an :class:`Expr` over ``names``.

    Raises :class:`ExprError` with a one-line message for anything outside the grammar and
    for constants that are not finite reals (``1/0``, ``sqrt(-1)``, ``10**400``).
    """
    if isinstance(text, bool):
        raise ExprError("expected a number or an expression, got a boolean")
    if isinstance(text, int | float):
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
        expr = _Converter(names).convert(tree.body, 0)
    except RecursionError:
        raise ExprError("expression nested too deeply") from None
    check_measure(measure(expr))
    return expr


def constant_value(expr: Expr) -> float:
    """The value of an expression without names (raises :class:`ExprError` otherwise)."""
    if not expr.is_constant:
        names = ", ".join(sorted(expr.names()))
        raise ExprError(f"expected a number, got an expression of {names}")
    return _constant(expr)


def evaluate(expr: Expr, env: Mapping[str, float]) -> float:
    """Evaluate in floating point (``env`` maps names to values); errors propagate as
    ``ValueError`` (domain), ``ZeroDivisionError``, ``OverflowError``."""
    op, args = expr.op, expr.args
    if op == "num":
        return float(args[0])
    if op == "name":
        return float(env[args[0]])
    if op == "pi":
        return math.pi
    vals = [evaluate(a, env) for a in args]
    return apply(op, vals)


def apply(op: str, vals: list[float]) -> float:
    """One operation on floats (shared by :func:`evaluate` and the compiled closures)."""
    if op == "+":
        return vals[0] + vals[1]
    if op == "-":
        return vals[0] - vals[1]
    if op == "*":
        return vals[0] * vals[1]
    if op == "/":
        return vals[0] / vals[1]
    if op == "**":
        return power(vals[0], vals[1])
    if op == "neg":
        return -vals[0]
    if op == "sqrt":
        return math.sqrt(vals[0])
    if op == "exp":
        return math.exp(vals[0])
    if op == "log":
        return math.log(vals[0])
    if op == "abs":
        return abs(vals[0])
    if op == "min":
        return min(vals)
    if op == "max":
        return max(vals)
    raise ValueError(f"unknown operation {op}")


def power(a: float, b: float) -> float:
    """``a ** b`` in floats: 0 to a negative power divides by zero, a complex result is a
    domain error."""
    if a == 0 and b < 0:
        raise ZeroDivisionError
    return math.pow(a, b)


@dataclass(frozen=True)
class Measure:
    """How big an expression is for symbolic work: ``degree`` (its total degree as a
    polynomial, every name counting 1 and a power ``x**c`` multiplying by ``|c|``),
    ``exponent`` (the product of the constant exponents of nested powers, 1 without one),
    ``nodes`` (tree size) and ``depth`` (tree height), names written out as their
    expressions when the caller gives those measures."""

    degree: float = 0.0
    exponent: float = 1.0
    nodes: int = 1
    depth: int = 1


NAME = Measure(degree=1.0)


def measure(expr: Expr, named: Mapping[str, Measure] | None = None) -> Measure:
    """The :class:`Measure` of ``expr``; a name has ``named[name]`` (default: degree 1,
    a leaf). Sums, min and max take the largest degree of their terms, products and
    quotients the sum, functions keep their argument's (sqrt, exp, log, abs)."""
    named = named or {}
    op, args = expr.op, expr.args
    if op == "name":
        return named.get(args[0], NAME)
    if op in ("num", "pi"):
        return Measure()
    parts = [measure(a, named) for a in args]
    nodes = 1 + sum(p.nodes for p in parts)
    depth = 1 + max(p.depth for p in parts)
    exponent = max(p.exponent for p in parts)
    if op in ("*", "/"):
        degree = parts[0].degree + parts[1].degree
    elif op == "**" and args[1].is_constant:
        k = max(1.0, abs(evaluate(args[1], {})))
        degree, exponent = parts[0].degree * k, parts[0].exponent * k
    elif op == "**":  # x**y, y not constant: kept as a power by symbolic work
        degree = parts[0].degree + parts[1].degree
    else:
        degree = max(p.degree for p in parts)
    return Measure(degree, exponent, nodes, depth)


def check_measure(size: Measure) -> None:
    """Raise :class:`ExprError` when ``size`` exceeds a bound (:data:`MAX_DEGREE`,
    :data:`MAX_EXPONENT` for nested powers, :data:`MAX_NODES`, :data:`MAX_INLINED_DEPTH`)."""
    if size.exponent > MAX_EXPONENT:
        raise ExprError(f"nested powers raise to the power {size.exponent:.4g}, more than "
                        f"{MAX_EXPONENT} (the product of the exponents counts)")
    if size.degree > MAX_DEGREE:
        raise ExprError(f"degree {size.degree:.4g} exceeds {MAX_DEGREE} (every name counts "
                        "1, a power multiplies, tied parameters count as written out)")
    if size.nodes > MAX_NODES:
        raise ExprError(f"{size.nodes} operations exceed {MAX_NODES} with tied parameters "
                        "written out")
    if size.depth > MAX_INLINED_DEPTH:
        raise ExprError(f"nesting depth {size.depth} exceeds {MAX_INLINED_DEPTH} with tied "
                        "parameters written out")


def _short(src: str, n: int = 60) -> str:
    return src if len(src) <= n else src[: n - 3] + "..."


def _number(value: int | float) -> Expr:
    if isinstance(value, float) and not math.isfinite(value):
        raise ExprError(f"number {value} is not finite")
    if value != 0 and math.log10(abs(value)) > MAX_MAGNITUDE_LOG10:
        raise ExprError("number too large")
    return Expr("num", (value,))


def _constant(expr: Expr) -> float:
    """Float value of a constant subtree; ExprError when it is not a finite real."""
    try:
        value = evaluate(expr, {})
    except ZeroDivisionError:
        raise ExprError("division by zero") from None
    except OverflowError:
        raise ExprError("number too large") from None
    except ValueError:
        raise ExprError("expression is not real (square root or log of a negative number?)"
                        ) from None
    if math.isnan(value):
        raise ExprError("expression is not finite (division by zero?)")
    if math.isinf(value) or (value != 0 and math.log10(abs(value)) > MAX_MAGNITUDE_LOG10):
        raise ExprError("number too large")
    return value


class _Converter:
    """Walks a Python syntax tree, accepting only the whitelisted grammar."""

    def __init__(self, names: Collection[str]):
        self.names = names

    def convert(self, node: ast.AST, depth: int) -> Expr:
        if depth > MAX_DEPTH:
            raise ExprError("expression nested too deeply")
        d = depth + 1
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, int | float):
                raise ExprError(f"unsupported literal {node.value!r}")
            return _number(node.value)
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return Expr("name", (node.id,))
            if node.id in CONSTANTS:
                return Expr("pi", ())
            if node.id in FUNCTIONS:
                raise ExprError(f"function '{node.id}' used without arguments")
            raise ExprError(f"unknown name '{node.id}'")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
            operand = self.convert(node.operand, d)
            return Expr("neg", (operand,)) if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.BinOp):
            left = self.convert(node.left, d)
            right = self.convert(node.right, d)
            return self._binop(node.op, left, right)
        if isinstance(node, ast.Call):
            return self._call(node, d)
        raise ExprError(f"unsupported syntax ({type(node).__name__})")

    def _binop(self, op: ast.operator, left: Expr, right: Expr) -> Expr:
        symbol = _BINARY.get(type(op))
        if symbol is None:
            raise ExprError(f"unsupported operator {type(op).__name__}")
        if symbol == "/" and right.is_constant and _constant(right) == 0:
            raise ExprError("division by zero")
        if symbol == "**":
            _check_power(left, right)
        return _checked(Expr(symbol, (left, right)))

    def _call(self, node: ast.Call, depth: int) -> Expr:
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
        if name == "log" and args[0].is_constant and _constant(args[0]) == 0:
            raise ExprError("log(0)")
        if name == "exp" and args[0].is_constant and abs(_constant(args[0])) > MAX_EXP_ARGUMENT:
            raise ExprError("argument of exp() too large in magnitude")
        return _checked(Expr(name, tuple(args)))


def _check_power(base: Expr, exponent: Expr) -> None:
    """Refuse powers whose value could explode (e.g. 10**10**10)."""
    if not exponent.is_constant:
        return
    e = _constant(exponent)
    if abs(e) > MAX_EXPONENT:
        raise ExprError(f"exponent larger than {MAX_EXPONENT} in magnitude")
    if base.is_constant:
        b = abs(_constant(base))
        if b == 0 and e < 0:
            raise ExprError("division by zero")
        if b > 0 and abs(e * math.log10(b)) > MAX_MAGNITUDE_LOG10:
            raise ExprError("number too large")


def _checked(expr: Expr) -> Expr:
    """A constant node must evaluate to a finite real (non-constant ones are checked where
    they are evaluated, at every kappa of the spec)."""
    if expr.is_constant:
        _constant(expr)
    return expr
