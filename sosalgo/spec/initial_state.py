"""The spec field ``initial_state:``: where ``sosalgo pep`` starts the method.

By default xi_0 = u x_0 (every state block at x_0, u the fixed-point direction). The
field lists one expression per state, linear in the symbols ``x0`` and ``g0`` (g0 = the
gradient of the spec's smooth function at x0), the coefficients expressions of the
parameters and m, L, kappa; e.g. ``initial_state: [x0, x0 - h*g0]`` for a method whose
second state starts one gradient step ahead. The x0-coefficients must be u (so that the
start is the fixed point when x_0 = x* and g0 = 0), checked at every kappa of the spec
(:func:`sosalgo.spec_values.check_initial_state`, where the method is bound).
Expressions are parsed (:mod:`sosalgo.kernel.expr`), never evaluated as code.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from typing import Any

import numpy as np

from sosalgo.errors import InputError
from sosalgo.kernel.expr.tree import Expr, ExprError, evaluate, parse_tree

__all__ = ["initial_state_values", "linear_parts", "parse_initial_state"]

FIELD = "initial_state"
ZERO = Expr("num", (0,))


def linear_parts(e: Expr, consts: Collection[str], option: str,
                 what: str = "c*f, c*dist, c*grad") -> dict[str, Expr]:
    """{variable: coefficient} of an expression linear in its names outside ``consts``
    ("1": the constant part); InputError naming ``option`` for a nonlinear use."""
    one = Expr("num", (1,))
    if not e.names() - set(consts):
        return {"1": e}
    if e.op == "name":
        return {e.args[0]: one}
    if e.op in ("+", "-"):
        out = dict(linear_parts(e.args[0], consts, option, what))
        for k, c in linear_parts(e.args[1], consts, option, what).items():
            c2 = c if e.op == "+" else Expr("neg", (c,))
            out[k] = Expr("+", (out[k], c2)) if k in out else c2
        return out
    if e.op == "neg":
        return {k: Expr("neg", (c,)) for k, c in
                linear_parts(e.args[0], consts, option, what).items()}
    a, b = (e.args + (None,))[:2] if e.op in ("*", "/") else (None, None)
    if e.op == "*" and a.names() <= set(consts):
        return {k: Expr("*", (a, c)) for k, c in linear_parts(b, consts, option, what).items()}
    if e.op in ("*", "/") and b.names() <= set(consts):
        return {k: Expr(e.op, (c, b)) for k, c in linear_parts(a, consts, option, what).items()}
    raise InputError(f"{option}: not a sum of terms {what} ({e}); unknown terms and "
                     "products of terms are refused")


def parse_initial_state(raw: object, names: Collection[str], n: int,
                        functions: Mapping[str, Any], fail: Callable[[str, str], Exception]
                        ) -> tuple[tuple[Expr, Expr], ...] | None:
    """(x0-coefficient, g0-coefficient) per state, or None when the field is absent;
    ``functions``: the spec's declarations (g0 needs exactly one with a gradient)."""
    from sosalgo.classes import get_class

    if raw is None:
        return None
    smooth = sum("gradient" in get_class(d.cls).oracles for d in functions.values())
    if not isinstance(raw, list) or len(raw) != n:
        raise fail(FIELD, f"must be a list of {n} expressions in x0 and g0 (one per state)")
    clash = {"x0", "g0"} & set(names)
    if clash:
        raise fail(FIELD, f"{sorted(clash)[0]} is also a parameter name")
    out = []
    for i, item in enumerate(raw):
        where = f"{FIELD}[{i}]"
        if isinstance(item, bool) or not isinstance(item, str | int | float):
            raise fail(where, "must be an expression in x0 and g0")
        try:
            tree = parse_tree(str(item), {*names, "x0", "g0"})
            parts = linear_parts(tree, names, where, "c*x0, c*g0")
        except ExprError as exc:
            raise fail(where, str(exc)) from None
        except InputError as exc:
            raise fail(where, str(exc).split(": ", 1)[-1]) from None
        if "1" in parts:
            raise fail(where, "a constant term; every term multiplies x0 or g0")
        if "g0" in parts and smooth != 1:
            raise fail(where, f"g0 needs exactly one smooth function (a class with a "
                       f"gradient oracle); the spec has {smooth}")
        out.append((parts.get("x0", ZERO), parts.get("g0", ZERO)))
    return tuple(out)


def initial_state_values(pairs: tuple[tuple[Expr, Expr], ...], env: Mapping[str, float]
                         ) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) in floating point: xi_0 = a x0 + b g0 (``env``: m, L, kappa, parameters)."""
    a = np.array([evaluate(x, env) for x, _ in pairs])
    b = np.array([evaluate(g, env) for _, g in pairs])
    return a, b
