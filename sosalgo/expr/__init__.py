"""Expressions of specs: parsed safely into sympy (:mod:`~sosalgo.expr.parse`, never
``eval``) and compiled for fast numeric evaluation (:mod:`~sosalgo.expr.compile`)."""

from sosalgo.expr.compile import NumericError, compile_expression, compile_matrix
from sosalgo.expr.parse import ExprError, parse_expression

__all__ = ["ExprError", "NumericError", "compile_expression", "compile_matrix",
           "parse_expression"]
