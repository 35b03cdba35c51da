"""The method of a spec at one kappa in rigorous ball arithmetic (python-flint ``arb``), for
the rate brackets: the spec's expression trees are evaluated with outward rounding (no
sympy, so the default ``analyze`` path stays light), m and kappa are the exact binary
values of their floats, L = kappa m.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from flint import arb, arb_mat

from sosalgo.kernel.arb import arb_fraction, arb_of, precision
from sosalgo.spec.types import Spec, value_order

__all__ = ["ArbMethod", "arb_method"]


def _apply(op: str, v: list[arb]) -> arb:
    if op in ("+", "-", "*", "/"):
        a, b = v
        return a + b if op == "+" else a - b if op == "-" else a * b if op == "*" else a / b
    if op == "**":
        a, b = v
        if b.is_exact() and b.is_integer():
            return a ** int(arb_fraction(b))
        return a ** b
    one = {"neg": lambda a: -a, "sqrt": arb.sqrt, "exp": arb.exp, "log": arb.log,
           "abs": abs}
    if op in one:
        return one[op](v[0])
    if op in ("min", "max"):
        out = v[0]
        for x in v[1:]:
            out = out.min(x) if op == "min" else out.max(x)
        return out
    raise ValueError(f"unknown operation {op}")


def _eval(expr: Any, env: Mapping[str, arb]) -> arb:
    if expr.op == "num":
        return arb_of(expr.args[0])
    if expr.op == "name":
        return env[expr.args[0]]
    if expr.op == "pi":
        return arb.pi()
    return _apply(expr.op, [_eval(a, env) for a in expr.args])


@dataclass
class ArbMethod:
    """A, B, C, D (arb_mat), the output rows erow (on xi) and drow (on u), every
    function's class name and parameters (arb), the oracles and the measure."""

    mats: dict[str, arb_mat]
    functions: list[tuple[str, str, dict[str, arb]]]
    oracles: tuple[int, ...]
    measure: str


def arb_method(spec: Spec, kappa: float, theta: Mapping[str, float] | None = None
               ) -> ArbMethod:
    """The method of ``spec`` at ``kappa`` (and ``theta``) as enclosures."""
    with precision():
        m = arb_of(spec.m)
        env: dict[str, arb] = {"m": m, "kappa": arb_of(kappa), "L": arb_of(kappa) * m}
        for p in value_order(spec.parameters, spec.source):
            par = spec.parameters[p]
            if theta and p in theta:
                env[p] = arb_of(theta[p])
            else:
                env[p] = _eval(par.tied if par.is_tied else par.value, env)
        mats = {k: arb_mat([[_eval(e, env) for e in row] for row in rows])
                for k, rows in spec.matrices.items()}
        p = len(spec.oracles)
        if "D" not in mats:
            mats["D"] = arb_mat(p, p)
        if spec.output is None:
            mats["erow"], mats["drow"] = mats["E"], arb_mat(1, p)
        else:
            o = spec.output
            mats["erow"] = arb_mat([[mats["C"][o, j] for j in range(mats["C"].ncols())]])
            mats["drow"] = arb_mat([[mats["D"][o, j] for j in range(p)]])
        funcs = [(name, d.cls, {k: _eval(e, env) for k, e in d.params.items()})
                 for name, d in spec.functions.items()]
        names = list(spec.functions)
        return ArbMethod(mats, funcs, tuple(names.index(f) for f in spec.oracles),
                         spec.measure)
