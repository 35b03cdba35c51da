"""Expressions of specs: parsed safely into small trees (:mod:`~sosalgo.kernel.expr.tree`, never
``eval``), compiled for fast numeric evaluation (:mod:`~sosalgo.kernel.expr.compile`) and turned
into sympy only for symbolic work (:mod:`~sosalgo.kernel.expr.parse`, imported on first use so
numeric analysis never loads sympy)."""

from typing import Any

from sosalgo.kernel.expr.compile import NumericError, compile_expression, compile_matrix
from sosalgo.kernel.expr.tree import Expr, ExprError, constant_value, parse_tree

__all__ = ["Expr", "ExprError", "NumericError", "compile_expression", "compile_matrix",
           "constant_value", "parse_expression", "parse_tree", "to_sympy"]


def __getattr__(name: str) -> Any:
    if name in ("parse_expression", "to_sympy"):
        from sosalgo.kernel.expr import parse

        return getattr(parse, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
