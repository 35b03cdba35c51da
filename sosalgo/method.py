"""Bind a spec to the one :class:`~sosalgo.oracles.Method` over a number type.

:func:`bind` is the one entry point: ``numbers`` chooses the number type of the method's
matrices and class parameters (:data:`~sosalgo.oracles.BOUND_NUMBER_TYPES`):

- ``"float"``: :func:`sosalgo.model.bind` (the :class:`~sosalgo.oracles.OracleMethod`, checked
  on creation; a spec without a condition number, ``m: 0``, is bound at its own L,
  :func:`sosalgo.model.bind_sublinear`, which refuses a state at the optimum that moves with
  the optimal subgradients unless ``moving_optimum``: the PEP takes such a method, the
  sublinear potentials do not);
- ``"ball"``: :func:`sosalgo.exact_method.exact_algorithm` (rational kappa and theta, exact
  sympy entries and their rational ball enclosures);
- ``"arb"``: :func:`arb_method` (python-flint balls, the spec's expression trees evaluated
  with outward rounding: no sympy, so the default ``analyze`` path stays light; m and
  kappa are the exact binary values of their floats, L = kappa m);
- ``"poly"``: :func:`sosalgo.exact_method.polynomial_method` (the ``free`` parameters as
  polynomials in the coordinates of their box, exact coefficients).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from flint import arb, arb_mat

from sosalgo.classes import CLASSES
from sosalgo.kernel.arb import arb_fraction, arb_of, precision
from sosalgo.model import bind_sublinear, evaluate_algorithm
from sosalgo.oracles import BOUND_NUMBER_TYPES, BoundFunction, Method
from sosalgo.spec.types import Spec, value_order

__all__ = ["arb_method", "arb_output_row", "bind"]


def bind(spec: Spec, kappa: Any = None, theta: Mapping[str, float] | None = None, *,
         numbers: str = "float", digits: int | None = None,
         free: Sequence[str] = (), moving_optimum: bool = False) -> Method:
    """The spec's method at condition number ``kappa`` (None for a spec without one) and
    input parameter values ``theta``, over the number type ``numbers`` (module doc).
    ``digits``: the decimals of the ball enclosures (``ball``); ``free``: the parameters
    left as polynomials over their ranges (``poly``, at ``kappa``); ``moving_optimum``: an
    ``m: 0`` spec's state at the optimum may move with the optimal subgradients (``float``)."""
    if numbers not in BOUND_NUMBER_TYPES:
        raise ValueError(f"numbers: one of {', '.join(BOUND_NUMBER_TYPES)}, got {numbers!r}")
    if numbers == "float":
        if not spec.has_condition_number:
            return bind_sublinear(spec, theta, moving_optimum=moving_optimum)
        return evaluate_algorithm(spec, float(kappa), theta)
    if numbers == "arb":
        return arb_method(spec, kappa, theta)
    # sympy: loaded by the exact bindings only
    from sosalgo.exact_method import exact_algorithm, polynomial_method

    if numbers == "ball":
        return exact_algorithm(spec, kappa, theta, *(() if digits is None else (digits,)))
    return polynomial_method(spec, kappa, free)


# --------------------------------------------------------------------------- arb balls
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


def arb_method(spec: Spec, kappa: float, theta: Mapping[str, float] | None = None
               ) -> Method:
    """The method of ``spec`` at ``kappa`` (and ``theta``) over arb balls
    (``numbers="arb"``): A, B, C, D (zero when the spec has none), E (None with
    ``output: y<i>``) as ``arb_mat``, m, L, the parameters and every function's class
    parameters as ``arb``."""
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
        funcs = tuple(BoundFunction(name, CLASSES[d.cls],
                                    {k: _eval(e, env) for k, e in d.params.items()})
                      for name, d in spec.functions.items())
        names = list(spec.functions)
        return Method(mats["A"], mats["B"], mats["C"], mats.get("D", arb_mat(p, p)),
                      mats.get("E"), env["m"], env["L"], funcs,
                      tuple(names.index(f) for f in spec.oracles), spec.output, spec.measure,
                      {q: env[q] for q in spec.parameters}, numbers="arb")


def arb_output_row(am: Method) -> tuple[arb_mat, arb_mat]:
    """(row on xi, row on u) of the output point of a method over arb balls: x = E xi, or
    y_i = C_i xi + D_i u (``output: y<i>``)."""
    if am.output is None:
        return am.E, arb_mat(1, am.p)
    o = am.output
    return (arb_mat([[am.C[o, j] for j in range(am.C.ncols())]]),
            arb_mat([[am.D[o, j] for j in range(am.p)]]))
