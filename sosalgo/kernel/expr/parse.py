"""Symbolic form of spec expressions: :class:`~sosalgo.kernel.expr.tree.Expr` trees to sympy.

Only symbolic work imports this module (design's polynomial model, the ``lmi`` display,
exact verification, polyopt's string input); numeric analysis works on the tree itself.
A float such as ``0.1`` becomes the rational ``1/10`` here, so exact checks see the number
the user wrote.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from fractions import Fraction

import sympy as sp

from sosalgo.kernel.expr.tree import Expr, ExprError, parse_tree

__all__ = ["parse_expression", "sympy_symbol", "to_sympy"]

BASE_NAMES = ("m", "L", "kappa")

_FUNCTIONS = {"sqrt": sp.sqrt, "exp": sp.exp, "log": sp.log, "abs": sp.Abs}


def sympy_symbol(name: str) -> sp.Symbol:
    """The symbol of a spec name: m, L, kappa are positive, parameters real."""
    return sp.Symbol(name, positive=True) if name in BASE_NAMES else sp.Symbol(name, real=True)


def parse_expression(text: object, names: Mapping[str, sp.Symbol]) -> sp.Expr:
    """Parse ``text`` (a string or a number) into a sympy expression over ``names``.

    Raises :class:`ExprError` with a one-line message for anything outside the grammar.
    """
    return to_sympy(parse_tree(text, names), names)


def to_sympy(expr: Expr, symbols: Mapping[str, sp.Symbol] | None = None) -> sp.Expr:
    """The sympy expression of a tree. Names map through ``symbols`` when given there, else
    to :func:`sympy_symbol`. Raises :class:`ExprError` when sympy's simplification shows an
    expression is not a finite real (``1/(kappa - kappa)``, ``sqrt(-kappa)``)."""
    return _convert(expr, symbols or {})


def _convert(e: Expr, symbols: Mapping[str, sp.Symbol]) -> sp.Expr:
    if e.op == "num":
        return _number(e.args[0])
    if e.op == "name":
        name = e.args[0]
        return symbols[name] if name in symbols else sympy_symbol(name)
    if e.op == "pi":
        return sp.pi
    args = [_convert(a, symbols) for a in e.args]
    if e.op == "+":
        out = args[0] + args[1]
    elif e.op == "-":
        out = args[0] - args[1]
    elif e.op == "*":
        out = args[0] * args[1]
    elif e.op == "/":
        if args[1].is_zero:
            raise ExprError("division by zero")
        out = args[0] / args[1]
    elif e.op == "**":
        out = args[0] ** args[1]
    elif e.op == "neg":
        out = -args[0]
    elif e.op in ("min", "max"):
        # Kept as written: sympy's evaluation of Min/Max compares every pair of arguments
        # through the assumptions system, which takes seconds for a few dozen arguments.
        fn = sp.Min if e.op == "min" else sp.Max
        out = fn(*args, evaluate=False)
    else:
        if e.op == "log" and args[0].is_zero:
            raise ExprError("log(0)")
        out = _FUNCTIONS[e.op](args[0])
    return _check_finite(out)


def _number(value: int | float) -> sp.Expr:
    """A literal exactly as written: a decimal is the shortest decimal that reads back as
    its float (``0.1`` is 1/10, ``0.5092387589007107`` keeps its 16 digits; a rounding
    to 15 digits would make the exact method another one)."""
    if isinstance(value, int):
        return sp.Integer(value)
    if not (abs(value) >= 1e-300 or value == 0):
        return sp.Float(0)
    if not math.isfinite(value):
        return sp.nsimplify(value, rational=True)
    q = Fraction(repr(value))
    return sp.Rational(q.numerator, q.denominator)


def _check_finite(expr: sp.Expr) -> sp.Expr:
    if expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ExprError("expression is not finite (division by zero?)")
    if expr.has(sp.I):
        raise ExprError("expression is not real (square root or log of a negative number?)")
    return expr
