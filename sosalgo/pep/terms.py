"""Measures and initial conditions of the PEP: sums of terms ``c*f``, ``c*dist``, ``c*grad``.

``f`` = sum_j f_j(x) - f_j*, ``dist`` = |x - x*|^2, ``grad`` = |grad f(x)|^2 of the smooth
part (the functions of a class with a gradient oracle), ``sdist`` = |xi - xi*|^2 over
every state block (an initial ``sdist`` makes the start free); ``c`` is an expression in
m, L, kappa. A measure term may name its point: ``f(x_N)`` (the output, the default),
``dist(y_N)`` (the point of the single call), ``grad(y2_N)`` (the point of call 2); an
initial term is at x_0. The string is parsed by :mod:`sosalgo.kernel.expr` (never evaluated) and
split into its linear terms; anything nonlinear in f, dist, grad is refused.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from sosalgo.errors import InputError
from sosalgo.kernel.expr.tree import Expr, ExprError, evaluate, parse_tree
from sosalgo.spec.initial_state import linear_parts

__all__ = ["KINDS", "Term", "describe_terms", "parse_terms"]

KINDS = ("f", "dist", "grad", "sdist")
_AT = re.compile(r"\b(f|dist|grad)\s*\(\s*([A-Za-z0-9_]+)\s*\)")
_POINT = re.compile(r"^(x|y(\d*))_(N|0)$")


@dataclass(frozen=True)
class Term:
    """``coef * kind(point)``: point "x" (the output), "y<i>" (call i, 1-based) or "x0"."""

    kind: str
    point: str
    coef: Expr

    def value(self, m: float, L: float, kappa: float) -> float:
        """The coefficient in floating point (InputError when it is not finite)."""
        try:
            v = evaluate(self.coef, {"m": m, "L": L, "kappa": kappa})
        except (ValueError, ZeroDivisionError, OverflowError):
            v = math.nan
        return v


def _placeholder(kind: str, point: str) -> str:
    return f"{kind}__{point}"


def _rewrite(text: str, option: str, initial: bool, p: int) -> str:
    """Replace ``kind(point)`` by placeholder names; check the points."""

    def sub(mt: re.Match[str]) -> str:
        kind, pt = mt.group(1), mt.group(2)
        hit = _POINT.match(pt)
        if hit is None:
            raise InputError(f"{option}: unknown point {pt!r} (use x_N, y_N, y<i>_N"
                             + (", x_0)" if initial else ")"))
        if initial != (hit.group(3) == "0"):
            raise InputError(f"{option}: {pt}: " + ("the initial condition is at x_0" if initial
                                                     else "the measure is at step N (x_N, y_N)"))
        if hit.group(1) == "x":
            return _placeholder(kind, "x0" if initial else "x")
        i = int(hit.group(2) or (1 if p == 1 else 0))
        if not 1 <= i <= p:
            raise InputError(f"{option}: {pt}: the method has {p} oracle call(s) per step"
                             + ("; name one: y1_N .. y{p}_N" if i == 0 else ""))
        return _placeholder(kind, f"y{i}")

    return _AT.sub(sub, text)


def parse_terms(text: object, option: str, initial: bool, p: int) -> list[Term]:
    """The terms of ``text`` (an InputError naming ``option`` for anything else)."""
    if not isinstance(text, str) or not text.strip():
        raise InputError(f"{option}: expected terms such as 'f', '2*dist', 'L/2*grad'")
    src = _rewrite(text, option, initial, p)
    names = {"m", "L", "kappa", *KINDS}
    names |= {w for w in re.findall(r"\b\w+__\w+\b", src)}
    try:
        tree = parse_tree(src, names)
    except ExprError as exc:
        raise InputError(f"{option}: {exc}") from None
    parts = linear_parts(tree, frozenset({"m", "L", "kappa"}), option)
    if "1" in parts:
        raise InputError(f"{option}: a constant term; every term multiplies f, dist or grad")
    out = []
    for key, coef in parts.items():
        kind, _, point = key.partition("__")
        out.append(Term(kind, point or ("x0" if initial else "x"), coef))
    return out


def describe_terms(terms: list[Term]) -> str:
    """A readable form: ``1*f(x) + L/2*dist(x0)``."""
    return " + ".join(f"({t.coef})*{t.kind}({t.point})" for t in terms)
