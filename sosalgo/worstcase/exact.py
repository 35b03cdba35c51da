"""Exact check of a PEP dual certificate: a rigorous upper bound tau_N^exact >= tau_N.

The method is rebuilt on exact numbers about the class as written
(:func:`exact_base`): m (an m: 0 spec's L) from the spec's own expression (``1/10`` is
1/10), kappa as written (``10/3`` is 10/3, ``3.3`` is 33/10), L = kappa m; every
parameter and matrix entry from the spec's expressions with sympy, irrational entries
enclosed in rational balls (:func:`sosalgo.kernel.exact.enclose`), the classes' tilted
inequalities from exact formulas
(:func:`sosalgo.certificates.exact_composite.exact_class_inequalities`), the fixed points
(u and the optimal-subgradient fixed points) solved exactly with sympy, and the PEP
structure (:func:`sosalgo.worstcase.structure.build_structure`) built again on those numbers,
with the same labels and the same basis as the float one (the gain K that defines the
basis is the float one, read as binary rationals: any K gives the same PEP). The
multipliers become rationals (their binary values; negative ones 0), tau a decimal
slightly above the float one, and, in ball arithmetic (python-flint ``arb``, outward
rounded, :data:`PREC` bits),

    c_F = tau i_F - m_F - sum lambda_k a_k >= 0   (every entry; :func:`_repaired`)
    D S D ⪰ delta I, S = tau I0 - M - sum lambda_k Q_k   (:func:`prove_scaled_psd`)

are proven (D = diag(w) > 0, the solver's scale); then measure <= tau for every function
of the classes (weak duality, :mod:`sosalgo.worstcase.sdp`). Long horizons: an entry whose
denominators grow past a few hundred bits is replaced by a ball around a short binary
rational that holds it (:func:`sosalgo.worstcase.structure.coarsen`, outward).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Mapping, Sequence
from fractions import Fraction
from typing import Any

import numpy as np
import sympy as sp
from flint import arb, arb_mat, fmpq

from sosalgo.kernel.exact import enclose as enclose_ball
from sosalgo.oracles import BoundFunction, Method
from sosalgo.spec import Spec
from sosalgo.worstcase.bind import class_kappa, has_kappa, initial_gradient
from sosalgo.worstcase.steps import StepMethods, spec_steps
from sosalgo.worstcase.structure import (
    PEPFrame,
    PEPStructure,
    build_structure,
    deadbeat_gain,
    enclosure_bits,
    enclosure_digits,
    radius_growth,
)
from sosalgo.worstcase.terms import Term

__all__ = ["ball", "class_description", "exact_base", "exact_method", "exact_or_none",
           "exact_values",
           "exact_step_method", "exact_steps_or_none", "prove_at", "prove_certificate",
           "prove_scaled_psd", "reprove_certificate", "symbolic_fixed_point"]

TAU_STEPS = (1e-12, 1e-9, 1e-7)
PREC = 320  # bits of the ball arithmetic of the proof


def document_kappa(kappa: float | None, exact: object, where: str) -> float | None:
    """The kappa a PEP document or witness is about: its float ``kappa`` with its
    ``kappa_exact`` (:func:`sosalgo.kernel.kappa.kappa_from_fields`; InputError when that
    is not the float's number); a document without ``kappa_exact`` is about the shortest
    decimal of its float, as PEP proofs were before they recorded it."""
    from sosalgo.errors import InputError
    from sosalgo.kernel.kappa import kappa_from_fields, kappa_written

    if kappa is None:
        return None
    if exact is None:
        return kappa_written(float(kappa))
    try:
        return kappa_from_fields(float(kappa), exact, where)
    except ValueError as exc:
        raise InputError(str(exc)) from None


def _written(expr: Any, value: float) -> sp.Expr:
    """A constant of the spec as written (``1/10``, ``sqrt(2)``) exactly; its float's
    decimal when the spec object has no expression (built by hand)."""
    from sosalgo.kernel.expr.parse import to_sympy

    if expr is not None:
        return sp.sympify(to_sympy(expr))
    q = Fraction(repr(float(value)))
    return sp.Rational(q.numerator, q.denominator)


def exact_base(spec: Spec, kappa: float | None) -> dict[sp.Symbol, sp.Expr]:
    """m, L (and kappa) of the class as written, exactly: the spec's ``m`` (``L`` for an
    m: 0 spec) from its expression, kappa as written
    (:func:`sosalgo.kernel.kappa.exact_kappa`), L = kappa m."""
    from sosalgo.kernel.kappa import exact_kappa
    from sosalgo.spec.types import BASE_SYMBOLS

    if not has_kappa(spec):  # m: 0: the class has no kappa
        vals = {"m": sp.Integer(0), "L": _written(spec.L_expr, float(spec.L or 0.0))}
    else:
        kq_s = exact_kappa(kappa)  # as written (sosalgo.kernel.kappa)
        mq = _written(spec.m_expr, spec.m)
        vals = {"m": mq, "L": kq_s * mq, "kappa": kq_s}
    return {BASE_SYMBOLS[k]: v for k, v in vals.items()}


def class_description(spec: Spec, kappa: float | None) -> dict[str, Any]:
    """Which class a proof is about, as exact strings: ``m``, ``L`` (``kappa``) and each
    function's class and parameters (sympy's exact form: ``1/10``, ``sqrt(2)/10``); the
    relative error of each inexact oracle call and the line search parameter, if any."""
    from sosalgo.kernel.expr import constant_value
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.kernel.kappa import kappa_fields
    from sosalgo.worstcase.bind import class_kappa

    base = exact_base(spec, kappa)
    env = _class_env(spec, base)
    out: dict[str, Any] = {str(k): str(v) for k, v in base.items()}
    if "kappa_enclosure" in (fields := kappa_fields(class_kappa(spec, kappa))):
        out["kappa_enclosure"] = fields["kappa_enclosure"]  # an irrational kappa's ball
    out["functions"] = {name: {"class": decl.cls, "params": {
        k: str(to_sympy(e).xreplace(env)) for k, e in decl.params.items()}}
        for name, decl in spec.functions.items()}
    if getattr(spec, "inexact", None):  # the oracles' relative errors, as written
        env = _exact_env(spec, base)
        out["relative_errors"] = {f"oracles[{i}]": str(to_sympy(e).xreplace(env))
                                  for i, e in spec.inexact.items()}
        D = spec.matrices.get("D")
        prox = [f"oracles[{i}]" for i in spec.inexact if D is not None
                and not (D[i][i].is_constant and constant_value(D[i][i]) == 0)]
        if prox:  # relatively inexact proximal steps (:mod:`sosalgo.worstcase.inexact`)
            out["inexact_proximal"] = prox
        refs = getattr(spec, "error_refs", None) or {}
        if refs:  # relative to a combination of the step's answers
            out["relative_to"] = {f"oracles[{i}]": [str(c) for c in ref]
                                  for i, ref in refs.items()}
    if getattr(spec, "epsilon", None):  # the epsilon-subgradient calls' eps, as written
        env = _exact_env(spec, base)
        out["epsilon_subgradients"] = {f"oracles[{i}]": str(to_sympy(e).xreplace(env))
                                       for i, e in spec.epsilon.items()}
    twins = getattr(spec, "twins", None) or {}
    if twins:
        out["gradient_of"] = {f"oracles[{i}]": f"oracles[{j}]" for i, j in twins.items()}
    if getattr(spec, "line_search", None):
        out["line_search"] = spec.line_search
    if getattr(spec, "span_search", False):
        out["span_search"] = True
    if getattr(spec, "mirror", None):  # the kernel of the Bregman steps and the set
        k = spec.mirror["kernel"]
        out["mirror"] = {"kernel": {"class": k.cls, "params": {
            key: str(to_sympy(e).xreplace(env)) for key, e in k.params.items()}},
            "set": spec.mirror["set"]}
    return out


def _class_env(spec: Spec, base: dict[sp.Symbol, sp.Expr]) -> dict[sp.Symbol, sp.Expr]:
    """What the classes' parameters are evaluated at, exactly: m, L, kappa, and the
    spec's parameters when a class names them (a class only ``pep`` answers may)."""
    from sosalgo.kernel.expr.parse import to_sympy

    named = {s for d in spec.functions.values() for e in d.params.values()
             for s in to_sympy(e).free_symbols}
    return _exact_env(spec, base) if named - set(base) else base


def _scale(L: sp.Expr) -> Fraction:
    """The unit s of the exact structure: L when it is rational, else a binary rational
    near it (any s > 0 gives the same PEP in another basis)."""
    if L.is_Rational:
        return Fraction(int(L.p), int(L.q))
    return Fraction(float(L))


def _exact_env(spec: Spec, base: dict[sp.Symbol, sp.Expr]) -> dict[sp.Symbol, sp.Expr]:
    """m, L, kappa and every parameter's value (tied ones followed), exactly."""
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.spec.types import value_order

    env = dict(base)
    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        env[spec.symbols[p]] = to_sympy(par.tied if par.is_tied else par.value).xreplace(env)
    return env


def exact_values(spec: Spec, kappa: float | None = None
                 ) -> tuple[dict[sp.Symbol, sp.Expr], dict[str, sp.Matrix]]:
    """(every parameter's exact value, the spec's matrices at them) of the class as
    written (:func:`exact_base`)."""
    env = _exact_env(spec, exact_base(spec, kappa))
    return env, _exact_matrices(spec, env)


def _exact_matrices(spec: Spec, env: dict[sp.Symbol, sp.Expr]) -> dict[str, sp.Matrix]:
    """The spec's matrices at the parameter values ``env``, exactly."""
    return {k: m.xreplace(env) for k, m in spec.sympy_matrices().items()}


def _balls(M: sp.Matrix, digits: int) -> np.ndarray:
    from sosalgo.kernel.exact import enclose

    out = np.empty(M.shape, dtype=object)
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            out[i, j] = enclose(M[i, j], digits)
    return out


def _fixed_points(mats: dict[str, sp.Matrix], om: Any) -> sp.Matrix:
    """[u, X_s] solved exactly: (I - A) X = B S_j, C X + D S_j = 1 (u) or 0, output row
    likewise (see :func:`sosalgo.oracles.fixed_point_basis`)."""
    n, p = om.n, om.p
    D = mats.get("D", sp.zeros(p, p))
    S = sp.Matrix(om.optimal_map().astype(int).tolist()) if om.optimal_map().size \
        else sp.zeros(p, 0)
    erow, drow = ((mats["E"], sp.zeros(1, p)) if om.output is None
                  else (mats["C"][om.output, :], D[om.output, :]))
    lhs = sp.Matrix.vstack(sp.eye(n) - mats["A"], mats["C"], erow)
    if getattr(om, "adjoint", None) is not None:  # each call's own reference point
        P, U = (sp.Matrix(T.astype(int).tolist()) for T in om.reference_tables())
        e0 = sp.zeros(1, P.shape[1])
        e0[0, 0] = 1
        rhs = sp.Matrix.vstack(mats["B"] * U, P - D * U, e0 - drow * U)
        sol, free = lhs.gauss_jordan_solve(rhs)
        return sol.xreplace({t: 0 for t in free})
    rhs = sp.zeros(n + p + 1, 1 + S.shape[1])
    for r in range(n, n + p + 1):
        rhs[r, 0] = 1
    if S.shape[1]:
        rhs[:, 1:] = sp.Matrix.vstack(mats["B"] * S, -D * S, -drow * S)
    sol, free = lhs.gauss_jordan_solve(rhs)
    return sol.xreplace({t: 0 for t in free})


def exact_method(spec: Spec, kappa: float | None, om: Any, steps: int = 0,
                 field: int | None = None) -> PEPFrame:
    """The exact :class:`PEPFrame` of ``spec`` (``om``: its float OracleMethod, for shapes),
    its irrational entries enclosed precisely enough for a trajectory of ``steps`` steps
    (:func:`sosalgo.worstcase.structure.enclosure_digits`); ``field`` = d: every number
    an exact element of Q(sqrt d) instead (:mod:`sosalgo.kernel.qfield`; ValueError when
    one is not)."""
    from sosalgo.certificates.exact_composite import exact_class_inequalities
    from sosalgo.kernel.exact import Ball
    from sosalgo.kernel.exact import enclose as enclose_at
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.oracles import pinned_optimum
    from sosalgo.worstcase.constraints import spec_constraints

    K = np.array([[Fraction(float(v)) for v in row]
                  for row in deadbeat_gain(om.A, om.B, float(om.L))], dtype=object)
    digits = enclosure_digits(radius_growth(om.A, om.B, K.astype(float), float(om.L)), steps)

    def enclose(expr: Any) -> Any:
        if field is not None:
            from sosalgo.kernel.qfield import to_field

            return to_field(expr, field)
        return enclose_at(expr, digits)

    def entries(M: sp.Matrix) -> np.ndarray:  # balls, or the field's numbers
        out = np.empty(M.shape, dtype=object)
        for i in range(M.shape[0]):
            for j in range(M.shape[1]):
                out[i, j] = enclose(M[i, j])
        return out

    base = exact_base(spec, kappa)
    env = _exact_env(spec, base)
    mats = _exact_matrices(spec, env)
    Xq = _fixed_points(mats, om)
    X = entries(Xq)
    p = om.p
    funcs, ineqs = [], []
    cenv = _class_env(spec, base)
    for fn in om.functions:
        decl = spec.functions[fn.name]
        params = {k: enclose(to_sympy(e).xreplace(cenv)) for k, e in decl.params.items()}
        if field is not None:  # the class data as balls of radius 0: rational parameters
            params = {k: Ball(_field_rational(v)) for k, v in params.items()}
        funcs.append((fn.name, fn.cls, params))
        fi = exact_class_inequalities(fn.cls, params, pinned_optimum(om.functions))[0]
        ineqs.append(fi if field is None else [
            (_field_rational(a), np.vectorize(_field_rational, otypes=[object])(Q))
            for a, Q in fi])
    extras = [class_extras(cls, params, len(fi)) for (_, cls, params), fi in zip(
        funcs, ineqs, strict=True)]
    L = _scale(base[_sym("L")])

    def coef(t: Term) -> Any:  # in m, L, kappa and the spec's parameters
        return enclose(to_sympy(t.coef).xreplace(env))

    def same(a: np.ndarray, b: np.ndarray) -> bool:
        if field is not None:
            return all(v == 0 for v in a - b)
        return all(Ball.of(v).c == 0 and Ball.of(v).r == 0 for v in a - b)

    D = (entries(mats["D"]) if "D" in mats
         else np.full((p, p), Fraction(0), dtype=object))
    method = frame_method(om, (entries(mats["A"]), entries(mats["B"]), entries(mats["C"]), D,
                               entries(mats["E"]) if "E" in mats else None),
                          funcs, base, digits, "ball" if field is None else "field")
    mt = PEPFrame(method, X[:, 0], X[:, 1:], L, ineqs, coef, same, K, exact=True,
                  bits=enclosure_bits(digits))
    mt.out_call = _exact_output_call(mats, om)
    mt.x0_call = _exact_start_call(mats, Xq, om)
    mt.prev_call = _exact_previous_call(mats, om)
    mt.errors = _exact_errors(spec, env, enclose)
    mt.epsilons = _exact_errors(spec, env, enclose, "epsilon")
    if mt.epsilons:  # the plain basis, as the float method's (short denominators)
        mt.K = np.full(K.shape, Fraction(0), dtype=object)
    mt.line_search = bool(getattr(spec, "line_search", None))
    mt.span_search = bool(getattr(spec, "span_search", False))
    mt.constraints = spec_constraints(spec, p)
    _call_links(mt, spec)
    mt.lmo = dict(getattr(spec, "lmo", None) or {})
    mt.blocks = [list(cls.exact_blocks(params) or []) for _, cls, params in funcs]
    mt.lmis = [list(cls.exact_lmis(params) or []) for _, cls, params in funcs]
    if any(e is not None for e in extras):
        mt.constants = [e[0] if e else [Fraction(0)] * len(fi)
                        for e, fi in zip(extras, ineqs, strict=True)]
        mt.scopes = [e[1] if e else ["pairs"] * len(fi)
                     for e, fi in zip(extras, ineqs, strict=True)]
    if getattr(om, "adjoint", None) is not None:  # transpose calls
        from sosalgo.worstcase.adjoint import split_transposes

        split_transposes(mt, om)
    g0, mt.smooth = initial_gradient(spec, om, float("nan") if kappa is None else kappa)
    if g0 is not None:  # the same start as the float method, exactly
        mt.G0 = np.array([enclose(to_sympy(b).xreplace(env))
                          for _, b in spec.initial_state], dtype=object)
    return mt


def _field_rational(v: Any) -> Fraction:
    """An exact rational (a field element, a ball of radius 0) as a Fraction; ValueError
    for an irrational class parameter (the field proof takes rational class data)."""
    if hasattr(v, "r") and hasattr(v, "c") and v.r == 0:
        return Fraction(v.c)
    if hasattr(v, "b") and v.b == 0:
        return Fraction(v.a)
    if isinstance(v, int | Fraction):
        return Fraction(v)
    raise ValueError(f"class datum {v!r} is not rational")


def class_extras(cls: Any, params: Mapping[str, Any], count: int
                 ) -> tuple[list[Any], list[str]] | None:
    """(constants, scopes) of a class's ``count`` inequalities at exact parameters
    (:meth:`~sosalgo.classes.base.FunctionClass.exact_constants`; scopes from its float
    data), None for a homogeneous pairwise class; ValueError when the class has a
    constant but no exact one (the proof would be about another class)."""
    fl = cls.tilted({k: float(getattr(v, "c", v)) for k, v in params.items()})
    if not any(i.constant or i.scope != "pairs" for i in fl):
        return None
    consts = cls.exact_constants(params)
    if consts is None:
        if any(i.constant for i in fl):
            raise ValueError(f"class {cls.name}: no exact constants (exact_constants)")
        consts = [Fraction(0)] * count
    if len(consts) != count or len(fl) != count:
        raise ValueError(f"class {cls.name}: {len(consts)} exact constants for {count} "
                         "inequalities")
    return list(consts), [i.scope for i in fl]


def _exact_errors(spec: Spec, env: dict[sp.Symbol, sp.Expr], enclose: Any,
                  field: str = "inexact") -> dict[int, Any]:
    """The relative error of each inexact call (``field`` "epsilon": the eps of each
    epsilon-subgradient call) as written (enclosed), exactly."""
    from sosalgo.kernel.expr.parse import to_sympy

    return {i: enclose(to_sympy(e).xreplace(env)) for i, e in
            (getattr(spec, field, None) or {}).items()}


def _proven_zero(v: sp.Expr) -> bool:
    """``v == 0`` proven (:func:`sosalgo.kernel.exact.is_zero`); a number sympy already
    knows to be nonzero is answered without simplification."""
    from sosalgo.kernel.exact import is_zero

    return v.is_zero is not False and is_zero(v)


def _exact_output_call(mats: dict[str, sp.Matrix], om: Any) -> int | None:
    """:func:`sosalgo.worstcase.structure.output_call` decided symbolically: the first call i
    with E - C_i = 0 and D_i = 0 exactly (sympy), None otherwise (or with an output call)."""
    if om.output is not None or "E" not in mats:
        return None
    D = mats.get("D", sp.zeros(om.p, om.p))
    for i in range(om.p):
        diff = list(mats["E"][0, :] - mats["C"][i, :]) + list(D[i, :])
        if all(_proven_zero(sp.sympify(v)) for v in diff):
            return i
    return None


def _exact_previous_call(mats: dict[str, sp.Matrix], om: Any) -> int | None:
    """The first call i whose point at step k - 1 is the output x_k for every state and
    answer (E A = C_i and E B = D_i exactly, sympy: x_k = E (A xi + B u) = C_i xi + D_i u),
    None otherwise (or with an output call)."""
    if om.output is not None or "E" not in mats:
        return None
    D = mats.get("D", sp.zeros(om.p, om.p))
    EA, EB = mats["E"] * mats["A"], mats["E"] * mats["B"]
    for i in range(om.p):
        diff = list(EA[0, :] - mats["C"][i, :]) + list(EB[0, :] - D[i, :])
        if all(_proven_zero(sp.sympify(v)) for v in diff):
            return i
    return None


def _exact_start_call(mats: dict[str, sp.Matrix], X: sp.Matrix, om: Any) -> int | None:
    """The first call i whose point at step 0 is x_0 for every start xi_0 = X0 x_0 -
    Xs s~: D_i = 0 and C_i [X0 Xs] = [1 0], decided symbolically (sympy), as
    :func:`_exact_output_call` (with beta irrational, y_0 = x_0 holds only symbolically)."""
    D = mats.get("D", sp.zeros(om.p, om.p))
    target = [1] + [0] * (X.shape[1] - 1)
    for i in range(om.p):
        row = mats["C"][i, :] * X
        diff = [row[0, c] - target[c] for c in range(X.shape[1])] + list(D[i, :])
        if all(_proven_zero(sp.sympify(v)) for v in diff):
            return i
    return None


def ball(v: Any) -> arb:
    """The arb enclosure of an exact number (int, Fraction, str ``p/q``, or a rational
    :class:`~sosalgo.kernel.exact.Ball`: centre and radius, the radius rounded up; an
    arb as it is)."""
    if isinstance(v, arb):
        return v
    if hasattr(v, "c"):
        c = ball(v.c)
        if not v.r:
            return c
        r = math.nextafter(float(v.r), math.inf)  # >= v.r: outward
        return c + arb(0, r)
    q = Fraction(v)
    return arb(fmpq(q.numerator, q.denominator))


def exact_or_none(spec: Spec, kappa: float | None, steps: int = 0) -> PEPFrame | None:
    """The exact method (:func:`sosalgo.worstcase.exact.exact_method`) for ``steps`` steps, None
    when it cannot be built (the proofs then say why)."""
    from sosalgo.steps import changes_with_k
    from sosalgo.worstcase.bind import bound_method

    if changes_with_k(spec):
        return exact_steps_or_none(spec, kappa, steps)
    try:
        return exact_method(spec, kappa, bound_method(spec, class_kappa(spec, kappa))[0],
                            steps)
    except (ValueError, ArithmeticError):
        return None


def frame_method(om: Any, matrices: Sequence[Any], functions: Sequence[Any],
                 base: Mapping[sp.Symbol, sp.Expr], digits: int, numbers: str) -> Method:
    """The one :class:`sosalgo.oracles.Method` an exact :class:`PEPFrame` is built on: the
    exact ``matrices`` (A, B, C, D, E; E None with ``output: y<i>``) over ``numbers``
    (``ball``, or ``field``: elements of Q(sqrt d)), the call layout of the float method
    ``om``, the ``functions`` (name, class, exact class parameters), and m and L of the
    class as written (:func:`exact_base`) as balls at ``digits`` decimals."""
    A, B, C, D, E = matrices
    return Method(A, B, C, D, E, enclose_ball(base[_sym("m")], digits),
                  enclose_ball(base[_sym("L")], digits),
                  tuple(BoundFunction(*fn) for fn in functions), tuple(om.oracles),
                  om.output, om.measure, numbers=numbers)


def _sym(name: str) -> sp.Symbol:
    from sosalgo.spec.types import BASE_SYMBOLS

    return BASE_SYMBOLS[name]


def _residual_parts(mt: PEPFrame, st: PEPStructure, lam: list[Fraction]
                    ) -> tuple[arb_mat, list[arb]]:
    """(sum lambda_k Q_k on G, sum lambda_k a_k on F) in ball arithmetic: the pairs'
    weights are gathered on the points' rows first (W), then R' W R."""
    rows: list[np.ndarray] = []
    index: dict[int, int] = {}
    for fp in st.points:
        for pt in fp:
            for v in (pt.x, pt.g):
                if id(v) not in index:
                    index[id(v)] = len(rows)
                    rows.append(v)
    nr, s, one = len(rows), ball(mt.s), arb(1)
    W = [[arb(0)] * nr for _ in range(nr)]
    aF = [arb(0)] * st.nF
    forms = [[(ball(al), [[ball(v) for v in row] for row in Q]) for al, Q in fi]
             for fi in mt.ineqs]
    for k, lk in enumerate(lam[:len(st.pairs)]):
        if lk == 0:
            continue
        j, a, b, r = st.pairs[k]
        pa, pb = st.points[j][a], st.points[j][b]
        alpha, Q = forms[j][r]
        idx = [index[id(pa.x)], index[id(pb.x)], index[id(pa.g)], index[id(pb.g)]]
        lb = ball(lk)
        sc = [one, one, s, s]  # s on the subgradient rows
        for u in range(4):
            for v in range(4):
                if not Q[u][v].is_zero():
                    W[idx[u]][idx[v]] += Q[u][v] * lb * sc[u] * sc[v]
        if pa.f is not None:
            aF[pa.f] += alpha * lb * s
        if pb.f is not None:
            aF[pb.f] -= alpha * lb * s
    if rows:
        if "_row_balls" not in st.__dict__:  # the points' rows as balls, once per PEP
            st.__dict__["_row_balls"] = arb_mat([[ball(v) for v in row] for row in rows])
        R = st.__dict__["_row_balls"]
        quad = R.transpose() * arb_mat(W) * R
    else:  # no points (the contraction measure: extra constraints only)
        quad = arb_mat(st.d, st.d)
    balls = st.__dict__.setdefault("_extra_balls", {})  # each extra's X, Qc as balls, once
    for e, ((_, Xe, Qe), lk) in enumerate(zip(st.extras, lam[len(st.pairs):], strict=True)):
        if lk:  # an extra constraint (:mod:`sosalgo.worstcase.inexact`): + lambda X' Qc X
            if e not in balls:
                balls[e] = (arb_mat([[ball(v) for v in row] for row in Xe]),
                            arb_mat([[ball(v) for v in row] for row in Qe]))
            Xb, Qb = balls[e]
            quad += Xb.transpose() * (Qb * ball(lk)) * Xb
            for i, v in enumerate(st.extra_values.get(e, ())):  # a constraint's values
                if _nonzero_value(v):
                    aF[i] += ball(v) * ball(lk)
    return quad, aF


def _nonzero_value(v: Any) -> bool:
    return bool(v.c != 0 or v.r != 0) if hasattr(v, "c") else bool(v != 0)


def _repaired(mt: PEPFrame, st: PEPStructure, lam: list[Fraction], tb: arb
              ) -> tuple[list[Fraction], arb_mat, list[arb]]:
    """(multipliers, sum lambda_k Q_k, c_F) after repairing c_F: an entry c_F[i] not
    proven >= 0 (the float dual's round-off) is raised by increasing the multiplier of
    the pair (x*, point i), whose only value coefficient is -alpha s on F_i, by a binary
    rational at least the deficit / (alpha s) (S moves by that times the pair's form)."""
    from sosalgo.kernel.arb import arb_fraction

    def residual(lq: list[Fraction]) -> tuple[arb_mat, list[arb]]:
        quad, lin = _residual_parts(mt, st, lq)
        t = coefficient(st, lq, tb)
        return quad, [t * ball(st.init_f[k]) - ball(st.meas_f[k]) - lin[k]
                      for k in range(st.nF)]

    quad, cF = residual(lam)
    star = {}
    for k, (j, a, b, r) in enumerate(st.pairs):
        pb = st.points[j][b]
        if st.points[j][a].label == "x*" and pb.f is not None and r == 0:
            star[pb.f] = k
    new = list(lam)
    for i, c in enumerate(cF):
        k = star.get(i)
        if c >= 0 or k is None:
            continue
        alpha = ball(mt.ineqs[st.pairs[k][0]][0][0]) * ball(mt.s)
        if not alpha > 0:
            continue
        need = arb_fraction(((-c) / alpha).upper()) * Fraction(1025, 1024)
        new[k] = new[k] + rational_up(need)
    if new == list(lam):
        return new, quad, cF
    quad, cF = residual(new)
    return new, quad, cF


def coefficient(st: PEPStructure, lam: Sequence[Fraction], tb: arb) -> arb:
    """The coefficient t of the initial condition in a certificate of the bound ``tb``:
    tb itself for a homogeneous PEP; tb - sum_k lambda_k c_k with constants (then
    measure <= t initial + sum_k lambda_k c_k <= tb when initial <= 1 and t >= 0)."""
    if st.constants is None:
        return tb
    total = arb(0)
    for lk, ck in zip(lam, st.constants, strict=True):
        if lk:
            total += ball(lk) * ball(ck)
    return tb - total


def _exact_fraction(v: Any) -> Fraction | None:
    """An exact number (rational, or a ball of radius 0) as a Fraction; None else."""
    if hasattr(v, "c"):
        return Fraction(v.c) if v.r == 0 else None
    return Fraction(v)


def _balanced(mt: PEPFrame, st: PEPStructure, lam: list[Fraction], tq: Fraction,
              repair: bool) -> tuple[list[Fraction], str]:
    """(multipliers, why not) with c_F = tau i_F - m_F - sum lambda_k a_k exactly 0, in
    rationals: the PEP's values enter only as differences (no x*), so the F_i are free up
    to a common shift and the dual needs c_F = 0; the float dual's round-off is routed
    (``repair``) through the pairs (hub, i) and (i, hub) of each function, each raised by
    a rational >= 0 (a pair adds alpha s to c_F[b] and takes it from c_F[a]). The sum of
    c_F is exactly 0 when the f coefficients cancel, so the hub ends at 0 too."""
    s = _exact_fraction(mt.s)
    alphas = [[_exact_fraction(a) for a, _ in fi] for fi in mt.ineqs]
    vals = [_exact_fraction(v) for v in list(st.init_f) + list(st.meas_f)]
    if s is None or None in vals or any(a is None for fa in alphas for a in fa):
        return lam, "values: irrational data (c_F = 0 cannot be proven exactly)"
    nF = st.nF
    cF = [tq * vals[i] - vals[nF + i] for i in range(nF)]
    by_f: dict[tuple[int, int], int] = {}
    for k, (j, a, b, r) in enumerate(st.pairs):
        fa, fb = st.points[j][a].f, st.points[j][b].f
        w = alphas[j][r] * s  # type: ignore[operator]
        if lam[k]:
            if fa is not None:
                cF[fa] -= lam[k] * w
            if fb is not None:
                cF[fb] += lam[k] * w
        if fa is not None and fb is not None and r == 0 and w > 0:
            by_f.setdefault((fa, fb), k)
    if repair:
        lam = list(lam)
        for fp in st.points:
            fs = [pt.f for pt in fp if pt.f is not None]
            for i in fs[1:]:
                hub = fs[0]
                k = by_f.get((hub, i) if cF[i] < 0 else (i, hub))
                if k is None or cF[i] == 0:
                    continue
                j, _, _, r = st.pairs[k]
                d = abs(cF[i]) / (alphas[j][r] * s)  # type: ignore[operator]
                lam[k] += d
                cF[hub] += cF[i]
                cF[i] = Fraction(0)
    bad = next((i for i, c in enumerate(cF) if c != 0), None)
    return lam, "" if bad is None else f"value residual {bad} is not exactly 0"


def decimal_up(x: Fraction, digits: int = 12) -> Fraction:
    """A decimal >= x with ``digits`` significant digits (x itself when x <= 0 or it has
    fewer): relative rounding, so a tiny tau keeps its digits."""
    if x <= 0:
        return x
    e = digits - math.floor(math.log10(x))
    scale = Fraction(10) ** e
    return Fraction(math.ceil(x * scale)) / scale


def above(tau: Fraction, step: Fraction) -> Fraction:
    """A short decimal at least ``tau`` by about the relative ``step`` (a negative tau, a
    rate of decrease, moves towards 0)."""
    if tau >= 0:
        return decimal_up(tau * (1 + step))
    x = -tau * (1 - step)  # > 0: its decimal rounded down, so -x rounds up
    e = 12 - math.floor(math.log10(x))
    scale = Fraction(10) ** e
    return -Fraction(math.floor(x * scale)) / scale


def rational_up(x: Fraction, bits: int = 64) -> Fraction:
    """A binary rational >= x > 0 with about ``bits`` significant bits."""
    e = x.numerator.bit_length() - x.denominator.bit_length() - bits
    return Fraction(math.ceil(x / Fraction(2) ** e)) * Fraction(2) ** e


def prove_scaled_psd(S: arb_mat, w: np.ndarray) -> tuple[bool, Fraction, str]:
    """Prove D S D ⪰ delta I (D = diag(w), powers of two; so S ⪰ 0) for every matrix in
    the balls: a floating-point Cholesky factor L of mid(D S D) - t I, then
    D S D - t I - L L' = E in ball arithmetic and |E|_F < t, so D S D ⪰ (t - |E|_F) I.
    (A singular S is decided in exact rationals instead: :func:`prove_at`.)"""
    return _scaled_psd(S, w)[:3]


# a least eigenvalue estimate of the scaled S below -INDEFINITE times its largest entry,
# beyond what the balls' radii can move it: S is indefinite (the float estimate errs by
# about d 2^-52 of that entry; d <= 40 here), so no exact decision of S ⪰ 0 is tried
INDEFINITE = 1e-10


def _scaled_psd(S: arb_mat, w: np.ndarray) -> tuple[bool, Fraction, str, bool]:
    """:func:`prove_scaled_psd`, and whether the scaled S is clearly indefinite (its
    least eigenvalue estimate below -:data:`INDEFINITE` of its largest entry and below
    -d times the largest radius: an S that is exactly 0, its balls' midpoints rounding
    noise, is not)."""
    from sosalgo.kernel.arb import arb_fraction
    from sosalgo.kernel.exact import rational

    d = S.nrows()
    Dm = arb_mat(d, d)
    for i in range(d):
        Dm[i, i] = ball(rational(float(w[i])))
    T = Dm * S * Dm
    mid = np.array([[float(T[i, j].mid()) for j in range(d)] for i in range(d)])
    mid = 0.5 * (mid + mid.T)
    try:
        est = float(np.linalg.eigvalsh(mid)[0])
    except np.linalg.LinAlgError:
        return False, Fraction(0), "eigenvalues of the scaled S failed", False
    if not est > 0:
        top = float(np.abs(mid).max(initial=0.0))
        # each matrix in the balls is within d * (largest radius) of mid in norm
        spread = d * max((float(T[i, j].rad()) for i in range(d) for j in range(d)),
                         default=0.0)
        return (False, Fraction(0), f"not proven (min eig estimate {est:.3g}, scaled)",
                est < -INDEFINITE * top - spread)
    t = rational(est / 2)
    try:
        Lf = np.linalg.cholesky(mid - float(t) * np.eye(d))
    except np.linalg.LinAlgError:
        return False, Fraction(0), "Cholesky of the scaled S failed", False
    Lb = arb_mat([[arb(float(v)) for v in row] for row in Lf])
    E = T - Lb * Lb.transpose()
    for i in range(d):
        E[i, i] -= ball(t)
    frob = sum((E[i, j] * E[i, j] for i in range(d) for j in range(d)), arb(0)).sqrt()
    delta = ball(t) - frob
    if not delta > 0:
        return False, Fraction(0), (f"not proven: residual {float(frob.upper()):.3g} >= "
                                    f"{float(t):.3g}"), False
    return True, arb_fraction(delta.lower()), "Cholesky with ball residual (scaled)", False


def prove_certificate(spec: Spec, kappa: float | None, st_float: PEPStructure,
                      mterms: list[Term], iterms: list[Term], tau: float,
                      lam: np.ndarray, w: np.ndarray | None = None,
                      mt: PEPFrame | None = None,
                      null: np.ndarray | None = None,
                      units: list[int] | None = None,
                      null_tol: float | None = None,
                      prover: Any = None) -> dict[str, Any]:
    """Prove measure <= tau' for a rational tau' >= tau (see the module); a dict with
    ``proven``, ``tau_proven`` (p/q), ``tau_proven_float``, ``detail``, ``seconds``.
    ``w``: the scale of the basis (powers of two, default 1); ``mt``: the exact method
    (built here when not given); ``null``: the float S of a certificate whose rows near
    zero are made exactly zero (:func:`null_row_multipliers`), nothing repaired;
    ``units``: the basis directions whose rows of S are made exactly zero instead (the
    directions no form has a square of, :func:`sosalgo.worstcase.sdp.linear_only`);
    ``null_tol``: the eigenvalues of the scaled ``null`` that count as its null space
    (default :data:`NULL_ROW` of its largest entry; a margin certificate's: below its
    margin); ``prover``: (exact method, exact structure, tq) -> (proven, multipliers,
    delta, detail), the proof of the bound tq from ``lam`` instead (a centered
    certificate's, :mod:`sosalgo.worstcase.centered`)."""
    from sosalgo.kernel.exact import fraction_str, rational
    from sosalgo.worstcase.bind import bound_method

    t0 = time.perf_counter()
    out: dict[str, Any] = {"proven": False, "tau_proven": None, "tau_proven_float": None}
    try:
        if mt is None:
            om, _ = bound_method(spec, class_kappa(spec, kappa))
            mt = exact_method(spec, kappa, om, st_float.steps)
        st = build_structure(mt, st_float.steps, mterms, iterms)
        if st_float.cuts:  # the blocks' rank-one cuts, the same rationals
            from sosalgo.worstcase.blocks import with_cuts

            st = with_cuts(mt, st, st_float.cuts)
        if st_float.lmi_cuts:  # the class LMIs' cuts, the same rationals
            from sosalgo.worstcase.lmis import with_lmi_cuts

            st = with_lmi_cuts(mt, st, st_float.lmi_cuts)
    except (ValueError, ArithmeticError) as exc:
        return out | {"detail": f"exact method: {exc}", "seconds": time.perf_counter() - t0}
    if st.labels != st_float.labels or st.basis != st_float.basis:
        return out | {"detail": "the exact structure differs from the float one (a point "
                                "coincides in floating point only)",
                      "seconds": time.perf_counter() - t0}
    lq = [rational(v) if v > 0 else Fraction(0) for v in lam]  # every positive one: a long
    # horizon's multipliers span more than 14 orders of magnitude (gradient N = 200)
    w = np.ones(st.d) if w is None else w
    detail = ""
    for step in TAU_STEPS:
        tq = above(Fraction(tau), Fraction(step))
        if prover is not None:
            ok, lq2, delta, why = prover(mt, st, tq)
        elif units:
            ok, lq2, delta, why, tq = _prove_null_rows(mt, st, lam, tq, None, w, units)
        elif null is not None:
            ok, lq2, delta, why, tq = _prove_null_rows(mt, st, lam, tq, null, w,
                                                       coarse=True, null_tol=null_tol)
        else:
            ok, lq2, delta, why = prove_at(mt, st, lq, tq, w, repair=True)
        if ok:
            return out | {"proven": True, "tau_proven": fraction_str(tq),
                          "tau_proven_float": float(tq), "delta": fraction_str(delta),
                          "detail": why, "multipliers_nonzero": sum(1 for v in lq2 if v),
                          "repaired": sum(1 for a, b in zip(lq, lq2, strict=True) if a != b),
                          "multipliers_exact": {lab: fraction_str(v) for lab, v in
                                                zip(st.labels, lq2, strict=True) if v},
                          "scale": [fraction_str(rational(float(v))) for v in w],
                          "class": class_description(spec, kappa),
                          **_cuts_field(mt, st),
                          "seconds": time.perf_counter() - t0}
        detail = why
    return out | {"detail": detail, "seconds": time.perf_counter() - t0}


def _cuts_field(mt: PEPFrame, st: PEPStructure) -> dict[str, Any]:
    """``cuts``: the rank-one cuts of the blocks' multipliers (function, condition,
    vector over the block's points; :mod:`sosalgo.worstcase.blocks`), for ``verify``."""
    from sosalgo.kernel.exact import fraction_str

    out: dict[str, Any] = {}
    if st.cuts:
        out["cuts"] = [[j, r, [fraction_str(Fraction(v)) for v in vec]]
                       for j, r, vec in st.cuts]
    if st.lmi_cuts:  # the class LMIs' cuts (:mod:`sosalgo.worstcase.lmis`)
        out["lmi_cuts"] = [[j, r, list(idx), [fraction_str(Fraction(v)) for v in vec]]
                           for j, r, idx, vec in st.lmi_cuts]
    return out


NULL_ROW = 1e-7  # a row of the scaled S this small (relative) is one the dual must zero
RATIONAL_MAX_D = 40  # the rational fallbacks of a proof: on PEPs of at most this basis


SNAPS = ((100, 1e-6), (1000, 1e-7), (10 ** 4, 1e-8), None)  # (denominator, tolerance)


def null_row_multipliers(mt: PEPFrame, st: PEPStructure, lam: np.ndarray, tq: Fraction,
                         S: np.ndarray | None, w: np.ndarray,
                         snap: tuple[int, float] | None = None,
                         units: list[int] | None = None,
                         null_tol: float | None = None) -> list[Fraction] | None:
    """Exact multipliers, on the float ones' support, with S v = 0 exactly for a rational
    basis v of the float certificate's null space (:func:`rational_null_space`; a basis
    row when S vanishes on a whole row), the free coordinates at the float values
    (``snap`` (q, tol): at the fraction of denominator <= q nearest each, when it is
    within tol relative: an optimum with small denominators is then found exactly, with
    its value residuals exactly 0); the value residuals that tq cannot raise (no initial
    term on them) are set exactly to 0 too. None when the data are not exact rationals,
    S has no null space, no rational basis is found, or the solution has a negative
    entry. A PEP whose worst case leaves a direction free (x* far away under a condition
    on f alone) has no certificate with S ≻ 0; S ⪰ 0 is then proven in exact rationals
    (:func:`prove_at`)."""
    from sosalgo.kernel.exact import solve_affine

    top = float(np.max(lam, initial=0.0))
    support = [k for k, v in enumerate(lam) if v > NULL_ROW * top]
    if not support or st.d > RATIONAL_MAX_D:
        return None
    null = ([[Fraction(int(j == c)) for j in range(st.d)] for c in units] if units
            else rational_null_space(S, w, snap, null_tol))
    if not null:
        return None
    if st.constants is not None and any(  # I0's coefficient is tq - sum lambda_k c_k:
            _nonzero_fraction(v[j]) and _nonzero_fraction(st.init_q[i][j])  # off the null
            for v in null for i in range(st.d) for j in range(st.d)):  # space only
        return None
    rows = exact_pair_parts(mt, st, support)
    if rows is None:
        return None
    quads, lins = rows
    I0, M = fraction_matrix(st.init_q), fraction_matrix(st.meas_q)
    fi, fm = fraction_matrix([st.init_f]), fraction_matrix([st.meas_f])
    if I0 is None or M is None or fi is None or fm is None:
        return None
    eqs, rhs = null_equations(st, quads, null, tq, I0, M)
    if eqs is None:  # a row 0 = nonzero: no exact certificate on this support
        return None
    cf = None if not units else st_value_residual(st, lam, lins, support)
    # with ``units``, the c_F that count as not clearly positive (a margin solve's c_F > 0):
    # below NULL_ROW; for a span search (free points tied by equalities only, its margin
    # solves at tight tolerances: :func:`sosalgo.worstcase.core._ladder`) those <= 0 only,
    # since zeroing a margin's slack there moves S by more than its margin
    slack = 0.0 if cf is None or st.margin_seen else NULL_ROW * (1.0 + abs(cf).max())
    for i in range(st.nF):  # c_F[i] = -m_F[i] - sum lambda a_i: no tq to raise it (with
        # ``units``: where the float c_F is not clearly positive, a margin solve's c_F > 0);
        # no x* (``free_values``): every c_F[i] = tq i_F[i] - m_F[i] - sum lambda a_i is 0
        if st.free_values or (fi[0][i] == 0 and (cf is None or cf[i] <= slack)):
            eqs.append([a[i] for a in lins])
            rhs.append(tq * fi[0][i] - fm[0][i])
    values = solve_affine(eqs, rhs, len(support),
                          lambda i: _snapped(float(lam[support[i]]), snap))
    if values is None:  # inconsistent: no exact certificate on this support
        return None
    out = [Fraction(0)] * len(lam)
    for k, q in zip(support, values, strict=True):
        if q < 0:
            return None
        out[k] = q
    return out


def null_equations(st: PEPStructure, quads: list[Any], null: list[list[Fraction]],
                    tq: Fraction, I0: list[list[Fraction]], M: list[list[Fraction]]
                    ) -> tuple[list[Any] | None, list[Fraction]]:
    """The rows of (tq I0 - M - sum_k lambda_k C_k) v = 0 for each v of ``null``, linear in
    the multipliers (C_k: the sparse ``quads``, row -> column -> value; each row sparse,
    multiplier -> coefficient); the rows 0 = 0 left out, (None, []) when a row reads 0 =
    nonzero."""
    eqs, rhs = [], []
    for v in null:
        nz = [j for j in range(st.d) if v[j]]
        products = []  # C_k v, by row, sparse (only the columns where v is nonzero)
        for quad in quads:
            prod: dict[int, Fraction] = {}
            for i, row in quad.items():
                for j in nz:
                    value = dict.get(row, j)
                    if value is not None:
                        prod[i] = prod.get(i, Fraction(0)) + value * v[j]
            products.append(prod)
        used = set().union(*products)
        for i in range(st.d):
            right = sum(((tq * I0[i][j] - M[i][j]) * v[j] for j in nz), Fraction(0))
            if i not in used:  # the row is 0 = right
                if right:
                    return None, []
                continue
            eqs.append({k: prod[i] for k, prod in enumerate(products) if i in prod})
            rhs.append(right)
    return eqs, rhs


def st_value_residual(st: PEPStructure, lam: np.ndarray, lins: list[Any],
                      support: list[int]) -> np.ndarray:
    """The float value residuals -m_F - sum lambda_k a_k of the multipliers on
    ``support`` (``lins``: their exact rows on F)."""
    def flt(v: Any) -> float:  # a ball: its center
        return float(v.c) if hasattr(v, "c") else float(v)

    cf = -np.asarray([flt(v) for v in st.meas_f], dtype=float)
    for k, a in zip(support, lins, strict=True):
        cf -= float(lam[k]) * np.asarray([flt(v) for v in a], dtype=float)
    return cf


def _nonzero_fraction(v: Any) -> bool:
    return bool(Fraction(v) != 0) if not hasattr(v, "c") else bool(v.c != 0 or v.r != 0)


def _prove_null_rows(mt: PEPFrame, st: PEPStructure, lam: np.ndarray, tq: Fraction,
                     S: np.ndarray | None, w: np.ndarray, units: list[int] | None = None,
                     coarse: bool = False, null_tol: float | None = None,
                     lift: bool = True) -> tuple[bool, list[Fraction], Fraction, str, Fraction]:
    """:func:`prove_at` (nothing repaired) on the multipliers of
    :func:`null_row_multipliers`, for each snap of :data:`SNAPS` until one proves
    (``coarse``: also the coarser snaps of :data:`COARSE_SNAPS`, on the float multipliers
    with those below each of :data:`COARSE_CUTS` of the largest dropped), then on those
    multipliers lifted (:func:`_lifted`). The last entry is the bound proven: ``tq``, or
    a lifted one above it."""
    why = "no exact multipliers zero the certificate's null rows"
    tries = [(0.0, snap) for snap in SNAPS]
    if coarse:
        tries += [(cut, snap) for cut in COARSE_CUTS for snap in COARSE_SNAPS
                  if (cut, snap) not in tries]
    seen: set[tuple[Fraction, ...]] = set()  # multipliers already tried
    inputs: set[tuple[Fraction, ...]] = set()  # with ``units``: snapped values already tried
    for cut, snap in tries:
        kept = np.where(lam > cut * float(np.max(lam, initial=0.0)), lam, 0.0)
        if units:  # the null space does not depend on the snap: only the values do
            key = tuple(_snapped(float(v), snap) if v else 0 for v in kept)
            if key in inputs:
                continue
            inputs.add(key)
        exact_lam = null_row_multipliers(mt, st, kept, tq, S, w, snap, units, null_tol)
        if exact_lam is None or tuple(exact_lam) in seen:
            continue
        seen.add(tuple(exact_lam))
        ok, lq2, delta, why = prove_at(mt, st, exact_lam, tq, w, repair=False)
        if ok:
            return ok, lq2, delta, why, tq
        for lifted, tl in _lifted(st, exact_lam, tq) if lift else ():
            ok, lq2, delta, why2 = prove_at(mt, st, lifted, tl, w, repair=False)
            if ok:
                return ok, lq2, delta, why2, tl
    return False, [], Fraction(0), why, tq


LIFTS = (Fraction(1, 10**9), Fraction(1, 10**8), Fraction(1, 10**7))  # relative to tq


def _lifted(st: PEPStructure, lam: list[Fraction], tq: Fraction
            ) -> list[tuple[list[Fraction], Fraction]]:
    """Multipliers raised by delta on every extra row with a constant c > 0, no values
    and a negative semidefinite diagonal form (|v|^2 <= c: raising its multiplier adds
    delta |v|^2 to S), the bound raised by delta (sum c + 1) (the initial term's
    coefficient by delta too): a certificate whose exact null rows left S a little
    indefinite on the directions those rows bound. Empty when there are none."""
    if st.constants is None:
        return []
    rows = []
    for e, (_, _, Qc) in enumerate(st.extras):
        k = len(st.pairs) + e
        c = _exact_fraction(st.constants[k])
        Q = fraction_matrix(Qc)
        if (c is None or c <= 0 or Q is None
                or (e in st.extra_values
                    and any(_nonzero_fraction(v) for v in st.extra_values[e]))
                or any(Q[u][v] for u in range(len(Q)) for v in range(len(Q)) if u != v)
                or any(Q[u][u] > 0 for u in range(len(Q)))):
            continue
        rows.append((k, c))
    if not rows:
        return []
    out = []
    for rel in LIFTS:
        delta = rel * max(tq, Fraction(1))
        lifted = list(lam)
        for k, _ in rows:
            lifted[k] += delta
        out.append((lifted, tq + delta * (sum(c for _, c in rows) + 1)))
    return out


# a singular certificate's null space from an interior-point answer on a degenerate face:
# its float eigenvectors up to 1e-3 off, a few 1e-5 spread on pairs the exact certificate
# does not use; coarse snaps and cuts (prove_at decides, so any guess is safe)
COARSE_SNAPS = ((100, 1e-4), (1000, 1e-5), (100, 1e-3), (12, 1e-2), *SNAPS)
COARSE_CUTS = (0.0, 1e-4, 1e-3)


def rational_null_space(S: np.ndarray, w: np.ndarray, snap: tuple[int, float] | None,
                        null_tol: float | None = None) -> list[list[Fraction]] | None:
    """A rational basis of the null space of the float S (eigenvalues of diag(w) S
    diag(w) below NULL_ROW of its largest entry), in reduced row echelon form (the
    identity on pivot coordinates) with its other entries snapped to fractions of
    denominator <= q (``snap``; every basis row when None: a null space of whole rows
    only); None when an entry does not snap."""
    Sh = S * np.outer(w, w)
    scale = max(1.0, float(np.abs(Sh).max()))
    vals, vecs = np.linalg.eigh(0.5 * (Sh + Sh.T))
    tol = NULL_ROW * scale if null_tol is None else null_tol
    V = vecs[:, np.abs(vals) <= tol] * np.asarray(w)[:, None]  # S's null space
    if not V.shape[1]:
        return None
    R = V.T.copy()  # rows span the null space: reduce to echelon form
    pivots, r = [], 0
    for c in range(R.shape[1]):
        if r == R.shape[0]:
            break
        p = r + int(np.argmax(np.abs(R[r:, c])))
        if abs(R[p, c]) <= 1e-8 * np.abs(R).max():
            continue
        R[[r, p]] = R[[p, r]]
        R[r] /= R[r, c]
        for i in range(R.shape[0]):
            if i != r:
                R[i] -= R[i, c] * R[r]
        pivots.append(c)
        r += 1
    out = []
    for row in R[:r]:
        vec = []
        for x in row:
            if abs(x) <= 1e-9:
                vec.append(Fraction(0))
                continue
            if snap is None:
                return None
            q = Fraction(float(x)).limit_denominator(snap[0])
            if abs(q - Fraction(float(x))) > max(snap[1], 1e-9) * max(1.0, abs(x)):
                return None
            vec.append(q)
        out.append(vec)
    return out


@functools.lru_cache(maxsize=1 << 16)  # the same float multipliers meet every snap and bound
def _snapped(v: float, snap: tuple[int, float] | None) -> Fraction:
    """The fraction of denominator <= q nearest v when within tol (relative; ``snap`` =
    (q, tol)), else v's binary value."""
    from sosalgo.kernel.exact import rational

    if snap is None:
        return rational(v)
    short = Fraction(v).limit_denominator(snap[0])
    return short if abs(short - Fraction(v)) <= snap[1] * abs(v) else rational(v)


def fraction_matrix(M: Any) -> list[list[Fraction]] | None:
    """An exact matrix (rationals or radius-0 balls) as Fractions; None otherwise."""
    out = []
    for row in M:
        vals = [_exact_fraction(v) for v in row]
        if any(v is None for v in vals):
            return None
        out.append(vals)
    return out


def exact_pair_parts(mt: PEPFrame, st: PEPStructure, support: list[int]
                      ) -> tuple[list[Any], list[list[Fraction]]] | None:
    """(X_k' Q_k X_k on G, sparse, a_k on F) of the rows ``support`` (pairs, then the
    extra rows) in Fractions; None when some entry is not an exact rational. Each row's
    parts are kept on ``st`` (the null-row proofs ask for the same rows again)."""
    if _exact_fraction(mt.s) is None:
        return None
    cache = st.__dict__.setdefault("_exact_rows", {})
    quads, lins = [], []
    for k in support:
        if k not in cache:
            cache[k] = _exact_row_parts(mt, st, k)
        if cache[k] is None:
            return None
        quads.append(cache[k][0])
        lins.append(cache[k][1])
    return quads, lins


def _exact_row_parts(mt: PEPFrame, st: PEPStructure, k: int) -> tuple[Any, list[Fraction]] | None:
    """(X_k' Q_k X_k, sparse, a_k) of row k in Fractions (None: not exact rationals)."""
    if k < len(st.pairs):
        _, av, X = st.pair_rows(mt, k)
        j, _, _, r = st.pairs[k]
        Q = mt.ineqs[j][r][1]
    else:  # an extra row: its X, Qc and values (a constraint's)
        e = k - len(st.pairs)
        _, X, Q = st.extras[e]
        av = st.extra_values.get(e, [Fraction(0)] * st.nF)
    Xf, Qf = fraction_matrix(X), fraction_matrix(Q)
    af = fraction_matrix([av])
    if Xf is None or Qf is None or af is None:
        return None
    n = len(Xf)
    cols = [c for c in range(st.d) if any(Xf[u][c] for u in range(n))]
    XQ = {c: [sum(Qf[u][v] * Xf[v][c] for v in range(n)) for u in range(n)] for c in cols}
    quad = _SparseQuad()  # X' Q X on the columns X uses (the others 0)
    for a in cols:
        row = _SparseRow()
        for c in cols:
            v = sum(Xf[u][a] * XQ[c][u] for u in range(n))
            if v:
                row[c] = v
        if row:
            quad[a] = row
    return quad, af[0]


class _SparseRow(dict):
    """A row of a sparse exact matrix: a missing column is 0."""

    def __missing__(self, key: int) -> Fraction:
        return Fraction(0)


_EMPTY_ROW = _SparseRow()


class _SparseQuad(dict):
    """A sparse exact matrix, ``q[i][j]`` (a missing row or column is 0; read only)."""

    def __missing__(self, key: int) -> _SparseRow:
        return _EMPTY_ROW


def prove_at(mt: PEPFrame, st: PEPStructure, lam: list[Fraction], tq: Fraction,
             w: np.ndarray, repair: bool = True
             ) -> tuple[bool, list[Fraction], Fraction, str]:
    """(proven, multipliers, delta, detail) of measure <= tq with the multipliers ``lam``
    (by pair of ``st``): c_F >= 0 (after :func:`_repaired` when ``repair``) and
    diag(w) S diag(w) ⪰ delta I (:func:`prove_scaled_psd`), in ball arithmetic."""
    from sosalgo.kernel.arb import precision

    with precision(PREC):
        I0 = arb_mat([[ball(v) for v in row] for row in st.init_q])
        M = arb_mat([[ball(v) for v in row] for row in st.meas_q])
        tb = ball(tq)
        if st.free_values and st.constants is not None:
            return False, list(lam), Fraction(0), "constants in a PEP without x*"
        if st.free_values:  # c_F = 0 exactly, in rationals (sosalgo.worstcase.structure)
            lam2, why = _balanced(mt, st, list(lam), tq, repair)
            if why:
                return False, lam2, Fraction(0), why
            quad, _ = _residual_parts(mt, st, lam2)
            cF = []
        elif repair:
            lam2, quad, cF = _repaired(mt, st, lam, tb)
        else:
            lam2 = list(lam)
            quad, lin = _residual_parts(mt, st, lam2)
            t0 = coefficient(st, lam2, tb)
            cF = [t0 * ball(st.init_f[k]) - ball(st.meas_f[k]) - lin[k]
                  for k in range(st.nF)]
        bad = [k for k, c in enumerate(cF) if not c >= 0]
        small = st.d <= RATIONAL_MAX_D
        if bad and not repair and small and _rational_residuals_ok(mt, st, lam2, tq):
            bad = []  # proven in rationals (a residual exactly 0: balls cannot say >= 0)
        if bad:
            return False, lam2, Fraction(0), f"value residual {bad[0]} is not proven >= 0"
        t = coefficient(st, lam2, tb)
        if st.constants is not None and not t >= 0:
            return False, lam2, Fraction(0), ("tau - sum of multipliers x constants is not "
                                              "proven >= 0")
        ok, delta, why, indefinite = _scaled_psd(I0 * t - M - quad, w)
        if not ok and not repair and small and not indefinite:
            ok, why = _rational_psd(mt, st, lam2, tq) or (ok, why)
            delta = Fraction(0)
    if not ok:
        return False, lam2, Fraction(0), why
    return True, lam2, delta, (f"diag(w) S diag(w) ⪰ {float(delta):.3g} I: {why}; "
                               + ("c_F = 0 (exact)" if st.free_values else "c_F >= 0")
                               + ("" if st.constants is None else
                                  "; tau = t + sum lambda_k c_k, t >= 0 (constants)"))


def _rational_parts(mt: PEPFrame, st: PEPStructure, lam: Sequence[Fraction],
                    values_only: bool = False
                    ) -> tuple[list[list[Fraction]], list[Fraction]] | None:
    """(sum_k lambda_k X_k' Q_k X_k, sum_k lambda_k a_k) in Fractions, None when some
    datum is not an exact rational; ``values_only``: the first left empty."""
    support = [k for k, v in enumerate(lam) if v]
    parts = exact_pair_parts(mt, st, support)
    if parts is None:
        return None
    quads, lins = parts
    d = st.d
    quad: list[list[Fraction]] = []
    if not values_only:
        quad = [[Fraction(0)] * d for _ in range(d)]
        for k, q in zip(support, quads, strict=True):
            for i, row in q.items():
                for j, v in row.items():
                    quad[i][j] += lam[k] * v
    lin = [Fraction(0)] * st.nF
    for k, a in zip(support, lins, strict=True):
        for i, v in enumerate(a):
            if v:
                lin[i] += lam[k] * v
    return quad, lin


def _rational_residuals_ok(mt: PEPFrame, st: PEPStructure, lam: Sequence[Fraction],
                           tq: Fraction) -> bool:
    """c_F = t i_F - m_F - sum lambda_k a_k >= 0 in exact rationals (t: :func:`_rational_t`)."""
    fi, fm = fraction_matrix([st.init_f]), fraction_matrix([st.meas_f])
    parts = _rational_parts(mt, st, lam, values_only=True)
    t = _rational_t(st, lam, tq)
    if parts is None or fi is None or fm is None or t is None:
        return False
    return all(t * a - b - c >= 0 for a, b, c in zip(fi[0], fm[0], parts[1], strict=True))


def _rational_t(st: PEPStructure, lam: Sequence[Fraction], tq: Fraction) -> Fraction | None:
    """The initial term's coefficient t = tq - sum_k lambda_k c_k in exact rationals (tq
    for a homogeneous PEP); None when a constant is irrational or t < 0 (the bound tq =
    t initial + sum lambda_k c_k needs t >= 0 under initial <= 1)."""
    if st.constants is None:
        return tq
    c = fraction_matrix([list(st.constants)])
    if c is None:
        return None
    t = tq - sum((Fraction(v) * ck for v, ck in zip(lam, c[0], strict=True) if v),
                 Fraction(0))
    return t if t >= 0 else None


def _rational_psd(mt: PEPFrame, st: PEPStructure, lam: Sequence[Fraction],
                  tq: Fraction) -> tuple[bool, str] | None:
    """S = t I0 - M - sum lambda_k Q_k ⪰ 0 (t: :func:`_rational_t`) decided in exact rationals
    (:func:`sosalgo.kernel.exact.prove_psd`: semidefinite allowed), None when some datum
    is irrational or S is not proven."""
    from sosalgo.kernel.exact import prove_psd

    I0, M = fraction_matrix(st.init_q), fraction_matrix(st.meas_q)
    parts = _rational_parts(mt, st, lam)
    t = _rational_t(st, lam, tq)
    if parts is None or I0 is None or M is None or t is None:
        return None
    quad = parts[0]
    S = [[t * I0[i][j] - M[i][j] - quad[i][j] for j in range(st.d)] for i in range(st.d)]
    proof = prove_psd(S)
    if not proof.psd:
        return None
    return True, f"S ⪰ 0 in exact rationals ({proof.kind}, {proof.method}: {proof.detail})"


def _bounding_terms(mt: PEPFrame, steps: int, mterms: list[Term], bound: Any) -> list[Term]:
    """The terms the proof is about: ``mterms``, or for a mingrad measure the proof's
    ``measure_bound`` once it is shown to bound the measure from above in exact rationals
    (:func:`sosalgo.worstcase.terms.dominates`); ValueError otherwise."""
    from sosalgo.worstcase.terms import MIN_OF, dominates, parse_terms

    if not any(t.kind in MIN_OF for t in mterms):
        return mterms
    if not isinstance(bound, str):
        raise ValueError("a mingrad measure needs the proof's measure_bound")
    terms = parse_terms(bound, "measure_bound", False, mt.p)

    def value(t: Term) -> Fraction:
        v = _exact_fraction(mt.coef(t))
        if v is None:
            raise ValueError(f"measure_bound: {t.coef}: not an exact rational")
        return v

    why = dominates(mterms, terms, steps, value)
    if why:
        raise ValueError(f"measure_bound: {why}")
    return terms


def reprove_certificate(spec: Spec, kappa: float | None, steps: int, measure: str,
                        initial: str, proof: dict[str, Any]) -> tuple[bool, str]:
    """(proven, detail): the claim measure <= ``proof["tau_proven"]`` proven again from
    the proof's own exact multipliers (by pair label) and scale, on the exact PEP of
    ``spec`` at ``kappa`` rebuilt here; nothing is repaired or solved."""
    from sosalgo.worstcase.terms import parse_terms

    lab = proof.get("multipliers_exact")
    if not isinstance(lab, dict) or not isinstance(proof.get("tau_proven"), str):
        return False, "the proof carries no exact multipliers (multipliers_exact)"
    try:
        tq = Fraction(proof["tau_proven"])
        mt = exact_or_none(spec, kappa, int(steps))
        if mt is None:
            return False, "the exact method cannot be built"
        mterms = _bounding_terms(mt, int(steps), parse_terms(measure, "measure", False, mt.p,
                                                             spec.parameters),
                                 proof.get("measure_bound"))
        st = build_structure(mt, int(steps), mterms, parse_terms(initial, "initial", True,
                                                                   mt.p, spec.parameters))
        if proof.get("cuts"):  # the blocks' rank-one cuts, as the proof gives them
            from sosalgo.worstcase.blocks import with_cuts

            st = with_cuts(mt, st, [(int(j), int(r), [Fraction(v) for v in vec])
                                    for j, r, vec in proof["cuts"]])
        if proof.get("lmi_cuts"):  # the class LMIs' cuts, checked PSD again
            from sosalgo.worstcase.lmis import with_lmi_cuts

            st = with_lmi_cuts(mt, st, [(int(j), int(r), tuple(int(a) for a in idx),
                                         [Fraction(v) for v in vec])
                                        for j, r, idx, vec in proof["lmi_cuts"]])
        index = {name: k for k, name in enumerate(st.labels)}
        unknown = [k for k in lab if k not in index]
        if unknown:
            return False, f"multiplier {unknown[0]!r} is not a pair of this PEP"
        lam = [Fraction(0)] * len(st.labels)
        for name, v in lab.items():
            lam[index[name]] = Fraction(v)
        if any(v < 0 for v in lam):
            return False, "a negative multiplier"
        w = [Fraction(v) for v in proof.get("scale") or [1] * st.d]
        wf = np.array([float(v) for v in w])
        if len(w) != st.d or not all(math.isfinite(v) and v > 0 for v in wf):
            return False, f"scale: expected {st.d} positive numbers"
    except (ValueError, TypeError, ZeroDivisionError, ArithmeticError, KeyError) as exc:
        return False, f"malformed proof: {type(exc).__name__}: {exc}"
    ok, _, _, why = prove_at(mt, st, lam, tq, wf, repair=False)
    return ok, why

# --------------------------------------------------------------------------- changes with k
# The exact method of per-step methods (:mod:`sosalgo.worstcase.steps`): the same class, units
# and terms as :func:`exact_method`, the per-step matrices exact, the plain basis (K = 0).


def exact_steps_or_none(spec: Spec, kappa: float | None, steps: int) -> PEPFrame | None:
    """The exact method of a spec that changes with k over ``steps`` steps
    (:func:`sosalgo.worstcase.steps.spec_steps`), None when it cannot be built."""
    from sosalgo.errors import InputError

    try:
        sm = spec_steps(spec, kappa, steps)
        return None if sm is None else exact_step_method(spec, kappa, sm, steps)
    except (ValueError, ArithmeticError, InputError):
        return None


def _exact_array(M: Any, digits: int) -> np.ndarray:
    """An exact matrix as an object array of Fractions and rational balls: a sympy
    matrix enclosed at ``digits`` decimals, an array of Balls/rationals as given."""
    from sosalgo.kernel.exact import Ball

    if isinstance(M, sp.MatrixBase):
        return _balls(M, digits)
    arr = np.array(M, dtype=object)
    if arr.ndim != 2:
        raise ValueError("a per-step matrix must be two-dimensional")
    out = np.empty(arr.shape, dtype=object)
    for idx, v in np.ndenumerate(arr):
        if isinstance(v, Ball):
            out[idx] = v if v.r else v.c
        elif isinstance(v, int | Fraction) and not isinstance(v, bool):
            out[idx] = Fraction(v)
        elif isinstance(v, sp.Rational):
            out[idx] = Fraction(int(v.p), int(v.q))
        else:
            raise ValueError(f"per-step entry {v!r}: expected an exact number or a Ball")
    return out


def _exact_zero(v: Any) -> bool:
    """``v == 0`` proven: a sympy number simplified to 0, an exact 0 (a ball of radius 0)."""

    if isinstance(v, sp.Basic):
        return _proven_zero(v)
    return bool(getattr(v, "c", v) == 0 and getattr(v, "r", 0) == 0)


def _sympy_steps(steps: Sequence[Mapping[str, Any]], p: int
                 ) -> list[dict[str, sp.Matrix]] | None:
    """The per-step matrices as sympy matrices (D = 0 when absent), None when a step is
    given as balls."""
    out = []
    for mats in steps:
        if not all(isinstance(M, sp.MatrixBase) for M in mats.values()):
            return None
        out.append({k: sp.Matrix(M) for k, M in mats.items()}
                   | ({} if "D" in mats else {"D": sp.zeros(p, p)}))
    return out


def _exact_fixed_point(sm: StepMethods, om: Any, count: int) -> tuple[Any, list | None]:
    """(X = [u, X_s] exact, the sympy steps or None): the provider's proven one, or
    solved from step 0 and proven on every step (sympy); ValueError when not proven."""

    steps = list(sm.exact or [])[:count]
    sym = _sympy_steps(steps, om.p)
    if sm.fixed_point is not None:
        return sp.Matrix(sm.fixed_point), sym
    if sym is None:
        raise ValueError("the per-step matrices are balls: their common fixed point must "
                         "be given (proven by their provider)")
    X = _fixed_points(sym[0], om)
    for k, mats in enumerate(sym[1:], 1):
        if not _fixed_points_hold(mats, om, X):
            raise ValueError(f"step {k} does not keep step 0's fixed point exactly")
    return X, sym


def _fixed_points_hold(mats: Mapping[str, sp.Matrix], om: Any, X: sp.Matrix) -> bool:
    """X = [u, X_s] solves step ``mats``' fixed-point equations exactly (sympy)."""

    n, p = om.n, om.p
    D = mats.get("D", sp.zeros(p, p))
    S = (sp.Matrix(om.optimal_map().astype(int).tolist()) if om.optimal_map().size
         else sp.zeros(p, 0))
    erow, drow = ((mats["E"], sp.zeros(1, p)) if om.output is None
                  else (mats["C"][om.output, :], D[om.output, :]))
    lhs = sp.Matrix.vstack(sp.eye(n) - mats["A"], mats["C"], erow)
    rhs = sp.zeros(n + p + 1, X.shape[1])
    for r in range(n, n + p + 1):
        rhs[r, 0] = 1
    if S.shape[1]:
        rhs[:, 1:] = sp.Matrix.vstack(mats["B"] * S, -D * S, -drow * S)
    return all(_proven_zero(sp.sympify(v)) for v in lhs * X - rhs)


def _call_at(rows_a: list[np.ndarray], rows_b: list[np.ndarray]) -> bool:
    return all(all(_exact_zero(x - y) for x, y in zip(a, b, strict=True))
               for a, b in zip(rows_a, rows_b, strict=True))


def exact_step_method(spec: Any, kappa: float | None, sm: StepMethods, count: int,
                      digits: int = 60) -> PEPFrame:
    """The exact :class:`PEPFrame` of the first ``count`` per-step methods of ``sm``: the
    class, units and terms of ``spec`` as written (:func:`sosalgo.worstcase.exact.exact_base`),
    the per-step matrices exact (sympy ones enclosed at ``digits`` decimals), K = 0.
    ValueError when they are missing or their fixed point is not proven."""
    from sosalgo.certificates.exact_composite import exact_class_inequalities
    from sosalgo.kernel.exact import Ball, enclose
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.oracles import pinned_optimum
    from sosalgo.steps import changes_with_k
    from sosalgo.worstcase.structure import enclosure_bits

    if callable(sm.exact):  # built when first needed (:func:`spec_steps`)
        sm.exact = sm.exact()
    if sm.exact is None or len(sm.exact) < count:
        raise ValueError(f"{count} steps' exact matrices needed")
    om = sm.floats[0]
    if sm.fixed_point is None and changes_with_k(spec):
        sm.fixed_point = symbolic_fixed_point(spec, om)
    X, _ = _exact_fixed_point(sm, om, count)
    Xb = _balls(X, digits)
    steps = [{k: _exact_array(M, digits) for k, M in mats.items()}
             for mats in list(sm.exact)[:count]]
    p = om.p
    zero = np.full((p, p), Fraction(0), dtype=object)
    per = [(s["A"], s["B"], s["C"], s.get("D", zero)) for s in steps]
    base = exact_base(spec, kappa)
    funcs, ineqs = [], []
    cenv = _class_env(spec, base)
    for fn in om.functions:
        decl = spec.functions[fn.name]
        params = {k: enclose(to_sympy(e).xreplace(cenv), digits)
                  for k, e in decl.params.items()}
        funcs.append((fn.name, fn.cls, params))
        ineqs.append(exact_class_inequalities(fn.cls, params,
                                              pinned_optimum(om.functions))[0])

    def coef(t: Any) -> Any:
        return enclose(to_sympy(t.coef).xreplace(base), digits)

    def same(a: np.ndarray, b: np.ndarray) -> bool:
        return all(Ball.of(v).c == 0 and Ball.of(v).r == 0 for v in a - b)

    A0, B0, C0, D0 = per[0]
    E = steps[0].get("E")
    mt = PEPFrame(frame_method(om, (A0, B0, C0, D0, E), funcs, base, digits, "ball"),
                  Xb[:, 0], Xb[:, 1:], _scale(base[_sym("L")]), ineqs, coef, same,
                  np.full((p, om.n), Fraction(0), dtype=object), exact=True,
                  bits=enclosure_bits(digits), per_step=per)
    mt.x0_call = _step_start_call(mt, per[0])
    mt.out_call = _step_output_call(mt, per)
    mt.blocks = [list(cls.exact_blocks(params) or []) for _, cls, params in funcs]
    mt.lmis = [list(cls.exact_lmis(params) or []) for _, cls, params in funcs]
    extras = [class_extras(cls, params, len(fi)) for (_, cls, params), fi in zip(
        funcs, ineqs, strict=True)]
    if any(e is not None for e in extras):
        mt.constants = [e[0] if e else [Fraction(0)] * len(fi)
                        for e, fi in zip(extras, ineqs, strict=True)]
        mt.scopes = [e[1] if e else ["pairs"] * len(fi)
                     for e, fi in zip(extras, ineqs, strict=True)]
    mt.errors = _exact_errors(spec, _exact_env(spec, base),
                              lambda e: enclose(e, digits))
    mt.epsilons = _exact_errors(spec, _exact_env(spec, base),
                                lambda e: enclose(e, digits), "epsilon")
    mt.lmo = dict(getattr(spec, "lmo", None) or {})
    _call_links(mt, spec)
    return mt


def _call_links(mt: PEPFrame, spec: Spec) -> None:
    """The inexact calls' reference vectors and the ``gradient_of`` calls, exactly
    (:mod:`sosalgo.worstcase.inexact`)."""
    mt.error_refs = {i: tuple(Fraction(c) for c in ref)
                     for i, ref in (getattr(spec, "error_refs", None) or {}).items()}
    mt.twins = dict(getattr(spec, "twins", None) or {})


def _step_start_call(mt: PEPFrame, step0: tuple[np.ndarray, ...]) -> int | None:
    """The first call of step 0 at x_0 for every start xi_0 = X0 x_0 - Xs s~ (D_i = 0,
    C_i X0 = 1, C_i Xs = 0), proven exactly."""
    _, _, C, D = step0
    for i in range(C.shape[0]):
        if (_exact_zero(C[i].dot(mt.X0) - 1) and all(_exact_zero(v) for v in C[i].dot(mt.Xs))
                and all(_exact_zero(v) for v in D[i])):
            return i
    return None


def _step_output_call(mt: PEPFrame, per: list[tuple[np.ndarray, ...]]) -> int | None:
    """The first call i with E = C_i and D_i = 0 at every step, proven exactly."""
    if mt.output is not None or mt.E is None:
        return None
    for i in range(mt.p):
        if all(_call_at([mt.E[0], D[i]], [C[i], 0 * D[i]]) for _, _, C, D in per):
            return i
    return None


def symbolic_fixed_point(spec: Any, om: Any) -> sp.Matrix | None:
    """The fixed points [u, X_s] of the spec's matrices, proven for every value of the
    parameters, sequences, k and N (sympy, those names left as symbols): the solution
    when it is free of them and solves the equations identically, else None. Then every
    per-step method of the spec keeps it (its matrices are these at numbers)."""

    mats = dict(spec.sympy_matrices())
    mats.setdefault("D", sp.zeros(om.p, om.p))
    try:
        X = _fixed_points(mats, om)
    except (ValueError, ArithmeticError, TypeError):
        return None
    if X.free_symbols or not _fixed_points_hold(mats, om, X):
        return None
    return X


def prove_bare(spec: Spec, kappa: float | None, st_float: PEPStructure,
               mterms: list[Term], iterms: list[Term], lam: np.ndarray, S: np.ndarray,
               w: np.ndarray, mt: PEPFrame | None = None, plain: bool = False
               ) -> dict[str, Any]:
    """Prove measure <= 0 for every instance of a question with no initial condition
    (``--initial none``, homogeneous: its worst case is 0 or unbounded): c_F >= 0 and
    S = -M - sum lambda_k Q_k ⪰ 0 at tau = 0 exactly, from the multipliers ``lam`` as
    they are (a certificate with S ≻ 0), else with the rows of S on the float ``S``'s
    null space made exactly zero in rationals (:func:`null_row_multipliers`); ``plain``:
    in the basis of K = 0, as the float solve was. The same dict as
    :func:`prove_certificate` (the multipliers, by pair, hold in any basis)."""
    from sosalgo.kernel.exact import fraction_str, rational
    from sosalgo.worstcase.bind import bound_method

    t0 = time.perf_counter()
    out: dict[str, Any] = {"proven": False, "tau_proven": None, "tau_proven_float": None}
    try:
        if mt is None:
            om, _ = bound_method(spec, class_kappa(spec, kappa))
            mt = exact_method(spec, kappa, om, st_float.steps)
        if plain:  # the float solve's basis
            mt.K = np.full(mt.K.shape, Fraction(0), dtype=object)
            mt.structures.clear()
        st = build_structure(mt, st_float.steps, mterms, iterms)
    except (ValueError, ArithmeticError) as exc:
        return out | {"detail": f"exact method: {exc}", "seconds": time.perf_counter() - t0}
    if st.labels != st_float.labels or st.basis != st_float.basis:
        return out | {"detail": "the exact structure differs from the float one",
                      "seconds": time.perf_counter() - t0}
    zero = Fraction(0)
    lq = [rational(v) if v > 0 else zero for v in lam]
    ok, lq2, delta, why = prove_at(mt, st, lq, zero, w, repair=True)
    if not ok:  # the null rows made exactly zero
        ok, lq2, delta, why, _ = _prove_null_rows(mt, st, lam, zero, S, w, coarse=True,
                                                  lift=False)
    if not ok:
        return out | {"detail": why, "seconds": time.perf_counter() - t0}
    return out | {"proven": True, "tau_proven": "0", "tau_proven_float": 0.0,
                  "delta": fraction_str(delta), "detail": why,
                  "multipliers_nonzero": sum(1 for v in lq2 if v),
                  "multipliers_exact": {lab: fraction_str(v) for lab, v in
                                        zip(st.labels, lq2, strict=True) if v},
                  "scale": [fraction_str(rational(float(v))) for v in w],
                  "class": class_description(spec, kappa),
                  "seconds": time.perf_counter() - t0}
