"""A method that changes with k, bound step by step over a horizon of N steps.

A spec whose coefficients vary with the iteration (``k``, ``N``, ``sequences:``, per-step
parameters; docs/spec.md, "Methods that change with k") is one linear system per step,

    xi_{k+1} = A_k xi_k + B_k u_k,   y_k = C_k xi_k + D_k u_k,   k = 0, ..., N - 1,

with the same functions, oracles, output and sizes at every step. This module gives those
per-step systems for the PEP and for schedule design:

- :func:`float_steps`: one :class:`~sosalgo.oracles.OracleMethod` per step (floats);
- :func:`exact_steps`: per-step sympy matrices (exact numbers), when the closed forms stay
  small; None when they grow (OGM's nested radicals at large N);
- :func:`ball_steps`: per-step matrices of outward-rounded rational balls
  (:class:`~sosalgo.kernel.exact.Ball`), the recurrences evaluated in ball arithmetic
  (python-flint ``arb``) at high precision: always available, the route for long horizons;
- :func:`sequence_values`, :func:`step_values`: the sequences and the parameters per step.

Every step must keep the optimum fixed with one common fixed-point basis (the state xi* at
the optimum cannot depend on k); otherwise, and at any point where an expression cannot be
evaluated (a sequence dividing by zero at some k), a one-line :class:`SpecError` names the
file, the field and the step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from sosalgo.errors import ModelError
from sosalgo.kernel.expr import Expr
from sosalgo.kernel.expr.compile import NumericError, compile_expression, compile_matrix
from sosalgo.oracles import OracleMethod, fixed_point_basis, fixed_point_system, make_method
from sosalgo.spec.types import NEXT_SUFFIX, Spec, SpecError, value_order

if TYPE_CHECKING:
    import sympy as sp
    from flint import arb

__all__ = ["MAX_EXACT_OPS", "MAX_STEPS", "SAMPLE_HORIZON", "ball_steps", "changes_with_k",
           "check_steps", "exact_steps", "float_steps", "horizon", "one_method",
           "reference_values", "sequence_values", "step_methods", "step_values"]

MAX_STEPS = 10_000
SAMPLE_HORIZON = 4  # the horizon a spec is checked at when it is loaded (lists: their own)
MAX_EXACT_OPS = 32  # sympy operations of one exact value before exact_steps gives up (sympy
# slows steeply past it: OGM's theta_9 alone takes minutes)
BALL_BITS = 320  # working precision of ball_steps
FIXED_POINT_TOL = 1e-9

Theta = Mapping[str, float | Sequence[float]]


def changes_with_k(spec: Spec) -> bool:
    """Whether the spec's method changes with k (``k``, ``N``, sequences, per-step
    parameters): then step k's method is :func:`float_steps`'s k-th; otherwise one
    method serves every step (:mod:`sosalgo.model` binds it once)."""
    return bool(spec.time_varying)


def one_method(spec: Spec) -> Spec:
    """``spec``, for a command that takes one method for every step; SpecError (one line
    naming ``sosalgo pep --steps``) when its method changes with k."""
    if changes_with_k(spec):
        from sosalgo.spec.types import VARIES

        raise SpecError(spec.source, "", VARIES.format(source=spec.source))
    return spec


def step_methods(spec: Spec, kappa: float | None, steps: int, theta: Theta | None = None
                 ) -> list[OracleMethod] | None:
    """The method of each step k = 0..N-1: one float method per step
    (:func:`float_steps`) when the spec's method changes with k; None when it is one
    method for every step (N equal steps, which its caller binds once)."""
    return float_steps(spec, kappa, steps, theta) if changes_with_k(spec) else None


def horizon(spec: Spec, steps: int | None) -> int:
    """The number of steps N: ``steps``, which must equal the length of the spec's listed
    schedules when it has some (they are the default when ``steps`` is None)."""
    lengths = {p: len(par.schedule) for p, par in spec.parameters.items()
               if par.schedule is not None}
    if steps is None:
        if not lengths:
            raise SpecError(spec.source, "--steps", "required: the horizon N of a method "
                            "that changes with k")
        return next(iter(lengths.values()))
    if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= MAX_STEPS:
        raise SpecError(spec.source, "--steps", f"must be an integer in 1..{MAX_STEPS}")
    for p, n in lengths.items():
        if n != steps:
            raise SpecError(spec.source, f"parameters.{p}", f"a schedule of {n} values, but "
                            f"the horizon is N = {steps} steps (give --steps {n}, or one "
                            f"value per step with --set {p}=[...])")
    return steps


def _base(spec: Spec, kappa: float | None) -> dict[str, float]:
    if spec.sublinear:
        return {"m": 0.0, "L": float(spec.L or 0.0), "kappa": math.nan}
    if kappa is None:
        raise SpecError(spec.source, "--kappa", "required (the condition number L/m)")
    m, L = spec.mL(float(kappa))
    return {"m": m, "L": L, "kappa": float(kappa)}


# --------------------------------------------------------------------------- floats


def _float(expr: Expr, env: Mapping[str, float], spec: Spec, where: str, k: int | None
           ) -> float:
    names = list(env)
    try:
        return compile_expression(expr, names)([env[n] for n in names])
    except NumericError as exc:
        at = "" if k is None else f" at k={k}"
        raise SpecError(spec.source, where, f"{exc}{at}") from None


def sequence_values(spec: Spec, kappa: float | None, steps: int) -> dict[str, list[float]]:
    """Each sequence's values s_0, ..., s_N (floats) over ``steps`` = N steps."""
    N = horizon(spec, steps)
    env0 = {**_base(spec, kappa), "N": float(N)}
    vals: dict[str, list[float]] = {}
    for s, decl in spec.sequences.items():
        vals[s] = [_float(decl.first, {**env0, **{e: v[0] for e, v in vals.items()}}, spec,
                          f"sequences.{s}.first", None)]
    for k in range(N):
        env = {**env0, "k": float(k), **{s: v[k] for s, v in vals.items()}}
        for s, decl in spec.sequences.items():
            rule, key = ((decl.last, "last") if k == N - 1 and decl.last is not None
                         else (decl.next, "next"))
            value = _float(rule, env, spec, f"sequences.{s}.{key}", k)
            vals[s].append(value)
            env[s + NEXT_SUFFIX] = value
    return vals


def _theta_at(spec: Spec, theta: Theta | None, N: int) -> dict[str, list]:
    """``theta`` (a value, or one value per step, per input parameter) as per-step lists."""
    out: dict[str, list] = {}
    for p, v in (theta or {}).items():
        if p not in spec.parameters:
            raise SpecError(spec.source, f"parameters.{p}", "unknown parameter")
        if spec.parameters[p].is_tied:
            raise SpecError(spec.source, f"parameters.{p}", "is tied to other parameters; "
                            "it cannot be set")
        vals = list(v) if isinstance(v, Sequence | np.ndarray) else [v] * N
        if len(vals) != N:
            raise SpecError(spec.source, f"parameters.{p}", f"{len(vals)} values given for "
                            f"a horizon of N = {N} steps")
        out[p] = vals
    return out


def step_values(spec: Spec, kappa: float | None, steps: int, theta: Theta | None = None
                ) -> list[dict[str, float]]:
    """Per step k = 0..N-1: every name the matrices may use (m, L, kappa, k, N, each
    sequence s at k and s_next at k+1, every parameter), as floats. ``theta`` sets input
    parameters: one value for every step, or a list of N values."""
    N = horizon(spec, steps)
    seqs = sequence_values(spec, kappa, N)
    given = _theta_at(spec, theta, N)
    base = _base(spec, kappa)
    order = value_order(spec.parameters, spec.source)
    out = []
    for k in range(N):
        env = {**base, "k": float(k), "N": float(N)}
        for s, v in seqs.items():
            env[s], env[s + NEXT_SUFFIX] = v[k], v[k + 1]
        for p in order:
            par = spec.parameters[p]
            if p in given:
                env[p] = float(given[p][k])
            elif par.schedule is not None:
                env[p] = _float(par.schedule[k], base, spec, f"parameters.{p}[{k}]", None)
            else:
                expr, where = ((par.tied, f"parameters.{p}") if par.is_tied
                               else (par.value, f"parameters.{p}.value"))
                env[p] = _float(expr, env, spec, where, k)  # type: ignore[arg-type]
        out.append(env)
    return out


def float_steps(spec: Spec, kappa: float | None, steps: int, theta: Theta | None = None
                ) -> list[OracleMethod]:
    """One :class:`~sosalgo.oracles.OracleMethod` per step k = 0..N-1 (N = ``steps``): the
    same functions, oracles, output and sizes at every step, each keeping the optimum
    fixed with the same fixed-point basis as step 0 (SpecError otherwise). ``kappa``:
    None for an ``m: 0`` spec; ``theta`` as in :func:`step_values`."""
    envs = step_values(spec, kappa, steps, theta)
    names = list(envs[0])
    fns = {}
    for key, rows in spec.matrices.items():
        try:
            fns[key] = compile_matrix(rows, names)
        except NumericError as exc:
            raise SpecError(spec.source, f"matrices.{key}", str(exc)) from None
    methods: list[OracleMethod] = []
    for k, env in enumerate(envs):
        values = [env[n] for n in names]
        try:
            mats = {key: fn(values) for key, fn in fns.items()}
            params = {p: env[p] for p in spec.parameters}
            om = make_method(spec, mats, env["m"], env["L"], env["kappa"], params)
        except (NumericError, ModelError) as exc:
            field_ = getattr(exc, "field", "matrices")
            message = getattr(exc, "message", str(exc))
            raise SpecError(spec.source, field_, f"{message} at k={k}") from None
        methods.append(om)
    _check_common_fixed_point(spec, methods)
    return methods


def _check_common_fixed_point(spec: Spec, methods: list[OracleMethod]) -> None:
    """Every step keeps x* fixed with step 0's fixed-point basis."""
    X = fixed_point_basis(methods[0])
    if X is None:  # make_method refuses this already; kept for hand-built specs
        raise SpecError(spec.source, "matrices", "the optimum is not a fixed point at k=0")
    for k, om in enumerate(methods[1:], start=1):
        lhs, rhs = fixed_point_system(om)
        err = np.abs(lhs @ X - rhs)
        scale = np.abs(lhs) @ np.abs(X) + np.abs(rhs) + 1e-300
        # X's round-off (least squares: 1e-16 where 0 is exact) is no change of the state
        floor = 1e3 * np.finfo(float).eps * np.abs(lhs).sum() * np.abs(X).max(initial=0.0)
        if np.any(err > FIXED_POINT_TOL * scale + floor):
            raise SpecError(spec.source, "matrices", f"the state at the optimum changes at "
                            f"k={k}: every step must keep x* fixed with one common state "
                            "xi* (that of k=0)")


def check_steps(spec: Spec, fail: Any) -> None:
    """The load-time check of a method that changes with k: it binds at every kappa of the
    spec over the horizon of its lists (else :data:`SAMPLE_HORIZON` steps), its per-step
    values lie in their ranges and its references are numbers (``fail(field, message)``
    raises the loader's one-line error)."""
    N = horizon(spec, None) if any(p.schedule for p in spec.parameters.values()) \
        else SAMPLE_HORIZON
    kappas: Sequence[float | None] = [None] if spec.sublinear else spec.kappa
    try:
        for kappa in kappas:
            for k, om in enumerate(float_steps(spec, kappa, N)):
                _check_ranges(spec, om.params, kappa, k, fail)
            reference_values(spec, kappa, N)
    except SpecError as exc:
        at = "" if spec.sublinear or kappa is None else f" (kappa={kappa:g})"
        raise fail(exc.field, f"{exc.message}{at}") from None


def reference_values(spec: Spec, kappa: float | None, steps: int) -> dict[str, float]:
    """The spec's references at horizon N = ``steps`` (they may use N and a sequence's last
    value ``s[N]``), as floats."""
    from sosalgo.spec.time_varying import LAST_SUFFIX

    N = horizon(spec, steps)
    env = {**_base(spec, kappa), "N": float(N)}
    env.update({s + LAST_SUFFIX: v[-1] for s, v in sequence_values(spec, kappa, N).items()})
    return {ref: _float(expr, env, spec, f"references.{ref}", None)
            for ref, expr in spec.references.items()}


def _check_ranges(spec: Spec, values: Mapping[str, float], kappa: float | None, k: int,
                  fail: Any) -> None:
    base = _base(spec, kappa)
    for p, par in spec.parameters.items():
        if par.range is None:
            continue
        lo, hi = (_float(e, base, spec, f"parameters.{p}.range", None) for e in par.range)
        if lo > hi:
            raise fail(f"parameters.{p}.range", f"lower bound {lo:g} exceeds upper bound "
                       f"{hi:g}")
        v = values[p]
        slack = 1e-12 * max(1.0, abs(lo), abs(hi))
        if not lo - slack <= v <= hi + slack:
            raise fail(f"parameters.{p}.value", f"{v:.6g} is outside its range "
                       f"[{lo:.6g}, {hi:.6g}] at k={k}")


# --------------------------------------------------------------------------- exact numbers


def _exact_base(spec: Spec, kappa: Any) -> dict[str, sp.Expr]:
    """m, L, kappa of the class as written, exactly (the spec's own expressions; kappa as
    written, :func:`sosalgo.kernel.kappa.exact_kappa`)."""
    import sympy as sp

    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.kernel.kappa import exact_kappa

    def written(expr: Expr | None, value: float) -> sp.Expr:
        if expr is not None:
            return sp.sympify(to_sympy(expr))
        q = Fraction(repr(float(value)))
        return sp.Rational(q.numerator, q.denominator)

    if spec.sublinear:
        return {"m": sp.Integer(0), "L": written(spec.L_expr, float(spec.L or 0.0)),
                "kappa": sp.nan}
    if kappa is None:
        raise SpecError(spec.source, "--kappa", "required (the condition number L/m)")
    kq, mq = exact_kappa(kappa), written(spec.m_expr, spec.m)
    return {"m": mq, "L": kq * mq, "kappa": kq}


class _TooLarge(Exception):
    """An exact value grew past :data:`MAX_EXACT_OPS` operations."""


def _sympy_value(expr: Expr, env: Mapping[str, Any], spec: Spec, where: str, k: int | None,
                 limit: bool = False) -> sp.Expr:
    """The exact value of ``expr`` at ``env``; with ``limit`` (a sequence's values, which
    feed the next ones), :class:`_TooLarge` past :data:`MAX_EXACT_OPS` operations."""
    import sympy as sp

    from sosalgo.kernel.expr import ExprError
    from sosalgo.kernel.expr.parse import sympy_symbol, to_sympy

    try:
        value = to_sympy(expr).xreplace({sympy_symbol(n): v for n, v in env.items()})
    except ExprError as exc:
        at = "" if k is None else f" at k={k}"
        raise SpecError(spec.source, where, f"{exc}{at}") from None
    value = sp.nsimplify(value) if value.is_Float else value
    if value.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
        at = "" if k is None else f" at k={k}"
        raise SpecError(spec.source, where, f"division by zero{at}")
    if limit and sp.count_ops(value) > MAX_EXACT_OPS:
        raise _TooLarge
    return value


def _exact_env(spec: Spec, kappa: Any, N: int, theta: Theta | None) -> list[dict[str, Any]]:
    """Per step: m, L, kappa, k, N, the sequences and the parameters, exact (sympy)."""
    import sympy as sp

    base = _exact_base(spec, kappa)
    given = _theta_at(spec, theta, N)
    env0 = {**base, "N": sp.Integer(N)}
    seqs: dict[str, list] = {}
    used = _used_sequences(spec, given)
    for s, decl in spec.sequences.items():
        if s not in used:
            continue
        seqs[s] = [_sympy_value(decl.first, {**env0, **{e: v[0] for e, v in seqs.items()}},
                                spec, f"sequences.{s}.first", None, True)]
    for k in range(N):
        env = {**env0, "k": sp.Integer(k), **{s: v[k] for s, v in seqs.items()}}
        for s, decl in spec.sequences.items():
            if s not in used:
                continue
            rule, key = ((decl.last, "last") if k == N - 1 and decl.last is not None
                         else (decl.next, "next"))
            env[s + NEXT_SUFFIX] = _sympy_value(rule, env, spec, f"sequences.{s}.{key}", k,
                                                True)
            seqs[s].append(env[s + NEXT_SUFFIX])
    out = []
    for k in range(N):
        env = {**env0, "k": sp.Integer(k)}
        for s, v in seqs.items():
            env[s], env[s + NEXT_SUFFIX] = v[k], v[k + 1]
        for p in value_order(spec.parameters, spec.source):
            env[p] = _exact_parameter(spec, p, k, env, base, given)
        out.append(env)
    return out


def _used_sequences(spec: Spec, given: Mapping[str, list]) -> set[str]:
    """The sequences the matrices and parameters refer to (directly, through parameters
    or through other sequences); a parameter set by ``given`` refers to none. A sequence
    kept for the references only (OGM's theta beside a given schedule) is not computed,
    so its closed form cannot make the exact matrices give way to balls."""
    names: set[str] = set()
    for rows in spec.matrices.values():
        names.update(n for row in rows for e in row for n in e.names())
    for p, par in spec.parameters.items():
        if p in given:
            continue
        for e in (par.value, par.tied, *(par.schedule or ())):
            if e is not None:
                names.update(e.names())
    def sequence(n: str) -> str | None:  # s and s_next are both about sequence s
        base = n.removesuffix(NEXT_SUFFIX)
        return base if base in spec.sequences else None

    used: set[str] = set()
    todo = [s for s in map(sequence, names) if s is not None]
    while todo:
        s = todo.pop()
        if s in used:
            continue
        used.add(s)
        decl = spec.sequences[s]
        for e in (decl.first, decl.next, decl.last):
            if e is not None:
                todo.extend(t for t in map(sequence, e.names()) if t is not None)
    return used


def _exact_parameter(spec: Spec, p: str, k: int, env: dict[str, Any], base: dict[str, Any],
                     given: Mapping[str, list]) -> Any:
    import sympy as sp

    par = spec.parameters[p]
    if p in given:
        q = Fraction(given[p][k]) if not isinstance(given[p][k], sp.Basic) else given[p][k]
        return sp.Rational(q.numerator, q.denominator) if isinstance(q, Fraction) else q
    if par.schedule is not None:
        return _sympy_value(par.schedule[k], base, spec, f"parameters.{p}[{k}]", None)
    expr, where = ((par.tied, f"parameters.{p}") if par.is_tied
                   else (par.value, f"parameters.{p}.value"))
    return _sympy_value(expr, env, spec, where, k)  # type: ignore[arg-type]


def exact_steps(spec: Spec, kappa: Any, steps: int, theta: Theta | None = None
                ) -> list[dict[str, sp.Matrix]] | None:
    """Per step k = 0..N-1, the spec's matrices (A, B, C, E or the output's, D when given)
    as sympy matrices of exact numbers, about the class as written (m, L as the spec
    writes them, kappa as written; None for an ``m: 0`` spec). Values set by ``theta``
    are read exactly (a float is its binary value; a Fraction or sympy number itself).
    None when a value's closed form grows past :data:`MAX_EXACT_OPS` operations (OGM's
    nested radicals at large N): use :func:`ball_steps` then. Call :func:`float_steps`
    first for the structural checks (the common fixed point)."""
    N = horizon(spec, steps)
    try:
        envs = _exact_env(spec, kappa, N, theta)
    except _TooLarge:
        return None
    from sosalgo.kernel.expr.parse import sympy_symbol

    out = []
    for env in envs:
        sub = {sympy_symbol(n): v for n, v in env.items()}
        out.append({key: M.xreplace(sub) for key, M in spec.sympy_matrices().items()})
    return out


# --------------------------------------------------------------------------- balls


def _arb_value(expr: Expr, env: Mapping[str, arb]) -> arb:
    """An outward-rounded ball holding the value of ``expr`` at the balls ``env``
    (ValueError where it cannot be enclosed: a division by a ball holding 0, sqrt or log
    of a ball reaching below 0)."""
    from flint import arb

    from sosalgo.kernel.arb import arb_of

    op, args = expr.op, expr.args
    if op == "num":
        return arb_of(Fraction(repr(args[0])) if isinstance(args[0], float) else args[0])
    if op == "name":
        return env[args[0]]
    if op == "pi":
        return arb.pi()
    vals = [_arb_value(a, env) for a in args]
    out = _arb_apply(op, vals, args)
    if not out.is_finite():
        raise ValueError("not a finite number (division by zero, or sqrt/log of a number "
                         "that may be negative)")
    return out


def _arb_apply(op: str, vals: list[arb], args: tuple) -> arb:
    a = vals[0]
    if op == "+":
        return a + vals[1]
    if op == "-":
        return a - vals[1]
    if op == "*":
        return a * vals[1]
    if op == "/":
        if vals[1].contains(0):
            raise ValueError("division by zero")
        return a / vals[1]
    if op == "**":
        if args[1].op == "num" and float(args[1].args[0]).is_integer():
            return a ** int(args[1].args[0])
        return a ** vals[1]
    if op == "neg":
        return -a
    if op in ("sqrt", "log") and not a > 0 and not (op == "sqrt" and a == 0):
        raise ValueError(f"{op} of a number that may be negative")
    if op in ("sqrt", "exp", "log"):
        return getattr(a, op)()
    if op == "abs":
        return abs(a)
    out = a
    for b in vals[1:]:  # min(a, b) = (a + b - |a - b|)/2, max likewise: enclosed exactly
        out = (out + b - abs(out - b)) / 2 if op == "min" else (out + b + abs(out - b)) / 2
    return out


def _ball(x: arb) -> Any:
    """A rational :class:`~sosalgo.kernel.exact.Ball` holding the arb ball ``x``."""
    from sosalgo.kernel.exact import Ball

    def exact(v: arb) -> Fraction:
        man, exp = v.man_exp()
        return Fraction(int(man)) * Fraction(2) ** int(exp)

    return Ball(exact(x.mid()), exact(x.rad()))


def _ball_of_sympy(value: Any, bits: int) -> arb:
    from flint import arb

    from sosalgo.kernel.exact import enclose

    b = enclose(value, digits=int(bits / 3.3) + 10)
    return (arb(b.c.numerator) / b.c.denominator) + arb(0, float(b.r) * (1 + 1e-12))


def ball_steps(spec: Spec, kappa: Any, steps: int, theta: Theta | None = None,
               bits: int = BALL_BITS) -> list[dict[str, np.ndarray]]:
    """Per step k = 0..N-1, the spec's matrices as object arrays of rational balls
    (:class:`~sosalgo.kernel.exact.Ball`: centre and radius, exact rationals) that hold the
    exact entries: the class as written (as :func:`exact_steps`), the sequences' recurrences
    and every expression evaluated in outward-rounded ball arithmetic (python-flint ``arb``)
    at ``bits`` bits. Entries that are exact binary rationals have radius 0."""
    from sosalgo.kernel.arb import arb_of, precision

    N = horizon(spec, steps)
    with precision(bits):
        base = {n: _ball_of_sympy(v, bits) for n, v in _exact_base(spec, kappa).items()
                if not (spec.sublinear and n == "kappa")}
        given = _theta_at(spec, theta, N)
        env0 = {**base, "N": arb_of(N)}
        seqs = _ball_sequences(spec, env0, N)
        out = []
        for k in range(N):
            env = {**env0, "k": arb_of(k)}
            for s, v in seqs.items():
                env[s], env[s + NEXT_SUFFIX] = v[k], v[k + 1]
            for p in value_order(spec.parameters, spec.source):
                env[p] = _ball_parameter(spec, p, k, env, base, given)
            out.append({key: _ball_matrix(spec, key, rows, env, k)
                        for key, rows in spec.matrices.items()})
    return out


def _ball_sequences(spec: Spec, env0: dict[str, arb], N: int) -> dict[str, list[arb]]:
    seqs: dict[str, list] = {}
    for s, decl in spec.sequences.items():
        seqs[s] = [_ball_or_fail(decl.first, {**env0, **{e: v[0] for e, v in seqs.items()}},
                                 spec, f"sequences.{s}.first", None)]
    from sosalgo.kernel.arb import arb_of

    for k in range(N):
        env = {**env0, "k": arb_of(k), **{s: v[k] for s, v in seqs.items()}}
        for s, decl in spec.sequences.items():
            rule, key = ((decl.last, "last") if k == N - 1 and decl.last is not None
                         else (decl.next, "next"))
            env[s + NEXT_SUFFIX] = _ball_or_fail(rule, env, spec, f"sequences.{s}.{key}", k)
            seqs[s].append(env[s + NEXT_SUFFIX])
    return seqs


def _ball_parameter(spec: Spec, p: str, k: int, env: dict[str, arb], base: dict[str, arb],
                    given: Mapping[str, list]) -> arb:
    from sosalgo.kernel.arb import arb_of

    par = spec.parameters[p]
    if p in given:
        return arb_of(Fraction(given[p][k]))
    if par.schedule is not None:
        return _ball_or_fail(par.schedule[k], base, spec, f"parameters.{p}[{k}]", None)
    expr, where = ((par.tied, f"parameters.{p}") if par.is_tied
                   else (par.value, f"parameters.{p}.value"))
    return _ball_or_fail(expr, env, spec, where, k)  # type: ignore[arg-type]


def _ball_or_fail(expr: Expr, env: Mapping[str, arb], spec: Spec, where: str, k: int | None
                  ) -> arb:
    try:
        return _arb_value(expr, env)
    except (ValueError, ZeroDivisionError) as exc:
        at = "" if k is None else f" at k={k}"
        raise SpecError(spec.source, where, f"{exc}{at}") from None


def _ball_matrix(spec: Spec, key: str, rows: Any, env: Mapping[str, arb], k: int
                 ) -> np.ndarray:
    out = np.empty((len(rows), len(rows[0])), dtype=object)
    for i, row in enumerate(rows):
        for j, e in enumerate(row):
            out[i, j] = _ball(_ball_or_fail(e, env, spec, f"matrices.{key}[{i}][{j}]", k))
    return out
