"""Continuous-time questions (``flow:``): the derivative of a Lyapunov function along an ODE
at one point, as a PEP question on an equivalent one-call method.

A flow spec gives the functions, the parameters and

    flow:
      time: t                       # the parameter that is the time (optional)
      velocity: -g                  # first order: x' = c g
      # or, second order (x' = v):  acceleration: -3/t*v - g   (v' = a v + b g)
      lyapunov: t*f + 1/2*x**2      # V(t, x, v)
      question: decrease            # or rate

in the names ``f`` (f(x) - f*), ``x`` (x - x*), ``v`` (x'), ``g`` (a subgradient of f at x)
with coefficients in the parameters, m and L. A product of two of x, v, g is their inner
product (``x**2`` = |x - x*|^2, ``(x + t/2*v)**2`` = |x - x* + t/2 v|^2). V must be linear
in f and a quadratic form in (x, v); the ODE linear in g (and v). The derivative is taken
symbolically (sympy, exact): dV/dt = dV/dt|_explicit + (dV/df) <g, x'> + <dV/dx, x'> +
<dV/dv, v'>, a quadratic form in (x, v, g) plus a multiple of f.

``question: decrease`` asks for the worst case of dV/dt over every point and function of
the class (no normalization: 0 when dV/dt <= 0 everywhere, else unbounded; the pep
question ``initial: none``); ``question: rate`` the worst case of dV/dt / V (the least
tau with dV/dt <= tau V: initial condition V).

The equivalent method has the state (x) or (x, w) with w = x + v (a point, so that v =
w - x is a difference of points), a free start, a call of f at x (its subgradient g and
value) and a step that only moves w to the output (x_1 = w, where f is called again: an
extra point of f changes no worst case); the measure and initial
condition are written in the pep terms at y_0 (= x) and x_1 (= w), so that ``sosalgo pep
SPEC --steps 1`` solves it, proves it exactly and ``sosalgo verify`` checks it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import sympy as sp

from sosalgo.spec.types import FLOW_KEY

__all__ = ["flow_spec"]

_FIELDS = {"time", "velocity", "acceleration", "lyapunov", "question"}
_VECTORS = ("x", "v", "g")
_QUESTIONS = ("decrease", "rate")


def flow_spec(data: dict[str, Any], fail: Callable[[str, str], Exception]) -> dict[str, Any]:
    """The method spec (a mapping, without ``flow``) that asks the flow's question;
    ``fail(field, message)`` builds the error of a bad field."""
    raw = data[FLOW_KEY]
    if not isinstance(raw, dict) or set(raw) - _FIELDS or "lyapunov" not in raw:
        raise fail(FLOW_KEY, "expected a mapping with lyapunov, velocity (first order) or "
                             "acceleration (second order), optional time and question")
    for key in ("matrices", "pep", "oracles", "output", "initial_state", "sequences"):
        if key in data:
            raise fail(key, "a flow spec has no " + key + " (the flow defines the question)")
    if ("velocity" in raw) == ("acceleration" in raw):
        raise fail(FLOW_KEY, "give exactly one of velocity (x' = c g) and acceleration "
                             "(x' = v, v' = a v + b g)")
    question = raw.get("question", "decrease")
    if question not in _QUESTIONS:
        raise fail(f"{FLOW_KEY}.question", "expected decrease or rate")
    params = data.get("parameters") or {}
    if not isinstance(params, dict):
        raise fail("parameters", "expected a mapping")
    time = raw.get("time")
    if time is not None and time not in params:
        raise fail(f"{FLOW_KEY}.time", f"{time!r} is not a parameter")
    second = "acceleration" in raw
    names = {n: sp.Symbol(n, real=True) for n in params}
    V, xdot, vdot = _parsed(raw, names, second, fail)
    t = names.get(time) if time is not None else sp.Symbol("_no_time")
    F, X, Vv, G = (sp.Symbol(n, real=True) for n in ("f", "x", "v", "g"))
    dV = (sp.diff(V, t) + sp.diff(V, F) * G * xdot + sp.diff(V, X) * xdot
          + (sp.diff(V, Vv) * vdot if second else 0))
    out = {k: v for k, v in data.items() if k != FLOW_KEY}
    if isinstance(out.get("functions"), dict):
        out["functions"] = _class_constants(out["functions"], params)
    out.update(_method(second))
    out.setdefault("m", 0)
    out.setdefault("L", 1)
    out["pep"] = {"measure": _terms(sp.expand(dV), second),
                  "initial": "none" if question == "decrease" else
                  "free + " + _terms(sp.expand(V), second)}
    return out


def _class_constants(functions: dict[str, Any], params: Mapping[str, Any]
                     ) -> dict[str, Any]:
    """The functions with a class parameter that names a constant parameter of the flow
    (``m: mu``, ``mu: {value: 0.1}`` or ``--set mu=0.2``) written as its value, so that
    ``--set`` changes the class as PEPit's arguments do."""
    import re

    consts = {}
    for name, p in params.items():
        v = p.get("value") if isinstance(p, dict) else p
        if isinstance(v, (int, float, str)) and not isinstance(v, bool) \
                and not re.search(r"[A-Za-z_]", str(v).replace("sqrt", "")):
            consts[name] = f"({v})"
    out = {}
    for fname, decl in functions.items():
        if not isinstance(decl, dict):
            out[fname] = decl
            continue
        out[fname] = {k: (re.sub(r"\b(" + "|".join(map(re.escape, consts)) + r")\b",
                                 lambda m: consts[m.group(1)], v)
                          if k != "class" and isinstance(v, str) and consts else v)
                      for k, v in decl.items()}
    return out


def _parsed(raw: Mapping[str, Any], names: dict[str, sp.Symbol], second: bool,
            fail: Callable[[str, str], Exception]) -> tuple[sp.Expr, sp.Expr, sp.Expr]:
    """(V, x', v') as sympy expressions in f, x, v, g, checked (see the module)."""
    from sosalgo.kernel.expr.parse import parse_expression, sympy_symbol
    from sosalgo.kernel.expr.tree import ExprError

    symbols = {**names, **{n: sympy_symbol(n) for n in ("m", "L")},
               **{n: sp.Symbol(n, real=True) for n in ("f", *_VECTORS)}}
    F, X, Vv, G = (symbols[n] for n in ("f", "x", "v", "g"))

    def parse(key: str, allowed: tuple[sp.Symbol, ...]) -> sp.Expr:
        try:
            e = sp.expand(parse_expression(raw[key], symbols))
        except ExprError as exc:
            raise fail(f"{FLOW_KEY}.{key}", str(exc)) from None
        extra = e.free_symbols & {F, X, Vv, G} - set(allowed)
        if extra:
            raise fail(f"{FLOW_KEY}.{key}", f"{sorted(map(str, extra))[0]} is not allowed here")
        return e

    V = parse("lyapunov", (F, X, Vv) if second else (F, X))
    for mono in sp.Poly(V, F, X, Vv).monoms():
        a, b, c = mono
        if not ((a == 1 and b + c == 0) or (a == 0 and b + c == 2)):
            raise fail(f"{FLOW_KEY}.lyapunov", "not c*f plus a quadratic form in x" +
                       (", v" if second else "") + " (e.g. t*f + 1/2*x**2)")
    if second:
        xdot, vdot = Vv, parse("acceleration", (Vv, G))
        _linear(vdot, (Vv, G), "acceleration", fail)
    else:
        xdot, vdot = parse("velocity", (G,)), sp.Integer(0)
        _linear(xdot, (G,), "velocity", fail)
    return V, xdot, vdot


def _linear(e: sp.Expr, variables: tuple[sp.Symbol, ...], key: str,
            fail: Callable[[str, str], Exception]) -> None:
    if any(sum(m) != 1 for m in sp.Poly(e, *variables).monoms()):
        raise fail(f"{FLOW_KEY}.{key}", "must be linear in " +
                   " and ".join(str(s) for s in variables) + " (no constant term)")


def _method(second: bool) -> dict[str, Any]:
    """The one-call method: state (x) or (x, w = x + v); call f at x; x_1 = w."""
    if second:  # xi_1 = (w, w): the output x_1 (the call at step 1) is w
        return {"matrices": {"A": [[0, 1], [0, 1]], "B": [[0], [0]], "C": [[1, 0]]},
                "output": "y1"}
    return {"matrices": {"A": [[1]], "B": [[0]], "C": [[1]]}, "output": "y1"}


def _terms(e: sp.Expr, second: bool) -> str:
    """The pep terms of a form c f + sum c_ab a b (a, b in x, v, g): f(y_0) and inner
    products of the points y_0 (x), x_1 (w = x + v) and the subgradient g(y_0)."""
    F, X, Vv, G = (sp.Symbol(n, real=True) for n in ("f", "x", "v", "g"))
    vec = {X: {"y_0": 1}, G: {"g(y_0)": 1}, Vv: {"x_1": 1, "y_0": -1}}
    out: dict[tuple[str, ...], sp.Expr] = {}
    poly = sp.Poly(e, F, X, Vv, G)
    for mono, coef in poly.terms():
        if mono[0] == 1:
            out[("f(y_0)",)] = out.get(("f(y_0)",), 0) + coef
            continue
        pair = [s for s, k in zip((X, Vv, G), mono[1:], strict=True) for _ in range(k)]
        for p, cp in vec[pair[0]].items():
            for q, cq in vec[pair[1]].items():
                key = tuple(sorted((p, q)))
                out[key] = out.get(key, 0) + coef * cp * cq
    parts = []
    for key, coef in out.items():
        coef = sp.simplify(coef)
        if coef == 0:
            continue
        term = key[0] if len(key) == 1 else f"inner({key[0]}, {key[1]})"
        parts.append(f"({_text(coef)})*{term}")
    return " + ".join(parts) or "0*f(y_0)"


def _text(coef: sp.Expr) -> str:
    """A coefficient in the expression language (``**`` powers, ``sqrt``)."""
    return sp.sstr(coef)
