"""Exact check of a PEP dual certificate: a rigorous upper bound tau_N^exact >= tau_N.

The method is rebuilt on exact numbers: kappa, m, L rational (the binary values of the
floats; an m: 0 spec's L), every parameter and matrix entry from the spec's expressions
with sympy, irrational entries enclosed in rational balls (:func:`sosalgo.verify.exact.
enclose`), the classes' tilted inequalities from exact formulas
(:func:`sosalgo.verify.exact_composite.exact_class_inequalities`), the fixed points
(u and the optimal-subgradient fixed points) solved exactly with sympy, and the PEP
structure (:func:`sosalgo.pep.structure.build_structure`) built again on those numbers,
with the same labels and the same basis as the float one (the gain K that defines the
basis is the float one, read as binary rationals: any K gives the same PEP). The
multipliers become rationals (their binary values; negative ones 0), tau a rational
slightly above the float one, and

    c_F = tau i_F - m_F - sum lambda_k a_k >= 0   (every entry, ball lower ends)
    S = tau I0 - M - sum lambda_k Q_k ⪰ delta I   (exact LDL^T of the centre, radius bound)

are proven; then measure <= tau for every function of the classes (weak duality,
:mod:`sosalgo.pep.sdp`). Long horizons: an entry whose denominators grow past a few
hundred bits is replaced by a ball around a short binary rational that holds it
(:func:`sosalgo.pep.structure.coarsen`, outward), in the rows and in S.
"""

from __future__ import annotations

import time
from fractions import Fraction
from typing import Any

import numpy as np
import sympy as sp

from sosalgo.pep.structure import Method, PEPStructure, build_structure, coarsen, deadbeat_gain
from sosalgo.pep.terms import Term
from sosalgo.spec import Spec

__all__ = ["exact_method", "prove_certificate"]

TAU_STEPS = (1e-12, 1e-9, 1e-7)


def _base(spec: Spec, kappa: float | None) -> dict[sp.Symbol, sp.Expr]:
    from sosalgo.spec.types import BASE_SYMBOLS
    from sosalgo.verify.exact import rational

    if spec.sublinear:
        Lq = rational(spec.L)
        vals = {"m": Fraction(0), "L": Lq}
    else:
        kq, mq = rational(kappa), rational(spec.m)
        vals = {"m": mq, "L": kq * mq, "kappa": kq}
    return {BASE_SYMBOLS[k]: sp.Rational(v.numerator, v.denominator) for k, v in vals.items()}


def _exact_matrices(spec: Spec, base: dict[sp.Symbol, sp.Expr]) -> dict[str, sp.Matrix]:
    """The spec's matrices at the parameter values (value expressions, tied ones
    followed), exactly."""
    from sosalgo.expr.parse import to_sympy
    from sosalgo.spec.types import value_order

    env = dict(base)
    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        env[spec.symbols[p]] = to_sympy(par.tied if par.is_tied else par.value).xreplace(env)
    return {k: m.xreplace(env) for k, m in spec.sympy_matrices().items()}


def _balls(M: sp.Matrix) -> np.ndarray:
    from sosalgo.verify.exact import enclose

    out = np.empty(M.shape, dtype=object)
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            out[i, j] = enclose(M[i, j])
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
    rhs = sp.zeros(n + p + 1, 1 + S.shape[1])
    for r in range(n, n + p + 1):
        rhs[r, 0] = 1
    if S.shape[1]:
        rhs[:, 1:] = sp.Matrix.vstack(mats["B"] * S, -D * S, -drow * S)
    sol, free = lhs.gauss_jordan_solve(rhs)
    return sol.xreplace({t: 0 for t in free})


def exact_method(spec: Spec, kappa: float | None, om: Any) -> Method:
    """The exact :class:`Method` of ``spec`` (``om``: its float OracleMethod, for shapes)."""
    from sosalgo.expr.parse import to_sympy
    from sosalgo.verify.exact import Ball, enclose
    from sosalgo.verify.exact_composite import exact_class_inequalities

    base = _base(spec, kappa)
    mats = _exact_matrices(spec, base)
    X = _balls(_fixed_points(mats, om))
    p = om.p
    funcs, ineqs = [], []
    for fn in om.functions:
        decl = spec.functions[fn.name]
        params = {k: enclose(to_sympy(e).xreplace(base)) for k, e in decl.params.items()}
        funcs.append((fn.name, fn.cls, params))
        ineqs.append(exact_class_inequalities(fn.cls, params)[0])
    L = Fraction(int(base[_sym("L")].p), int(base[_sym("L")].q))

    def coef(t: Term) -> Any:
        return enclose(to_sympy(t.coef).xreplace(base))

    def same(a: np.ndarray, b: np.ndarray) -> bool:
        return all(Ball.of(v).c == 0 and Ball.of(v).r == 0 for v in a - b)

    D = _balls(mats["D"]) if "D" in mats else np.full((p, p), Fraction(0), dtype=object)
    K = np.array([[Fraction(float(v)) for v in row]
                  for row in deadbeat_gain(om.A, om.B, float(om.L))], dtype=object)
    return Method(_balls(mats["A"]), _balls(mats["B"]), _balls(mats["C"]), D,
                  _balls(mats["E"]) if "E" in mats else None, om.output, funcs,
                  tuple(om.oracles), X[:, 0], X[:, 1:], L, ineqs, coef, same, K, exact=True)


def _sym(name: str) -> sp.Symbol:
    from sosalgo.spec.types import BASE_SYMBOLS

    return BASE_SYMBOLS[name]


def _residual_parts(mt: Method, st: PEPStructure, lam: list[Fraction]):
    """(sum lambda_k Q_k on G, sum lambda_k a_k on F), exactly: the pairs' weights are
    gathered on the points' rows first (W), then S_part = R' W R."""
    rows: list[np.ndarray] = []
    index: dict[int, int] = {}

    def ix(v: np.ndarray) -> int:
        if id(v) not in index:
            index[id(v)] = len(rows)
            rows.append(v)
        return index[id(v)]

    for fp in st.points:
        for pt in fp:
            ix(pt.x), ix(pt.g)
    nr = len(rows)
    W = np.full((nr, nr), Fraction(0), dtype=object)
    aF = np.full(st.nF, Fraction(0), dtype=object)
    for k, lk in enumerate(lam):
        if lk == 0:
            continue
        j, a, b, r = st.pairs[k]
        pa, pb = st.points[j][a], st.points[j][b]
        alpha, Q = mt.ineqs[j][r]
        idx = [index[id(pa.x)], index[id(pb.x)], index[id(pa.g)], index[id(pb.g)]]
        sc = [1, 1, mt.s, mt.s]
        for u in range(4):
            for v in range(4):
                W[idx[u], idx[v]] = W[idx[u], idx[v]] + Q[u, v] * (lk * sc[u] * sc[v])
        if pa.f is not None:
            aF[pa.f] = aF[pa.f] + alpha * (lk * mt.s)
        if pb.f is not None:
            aF[pb.f] = aF[pb.f] - alpha * (lk * mt.s)
    R = np.vstack(rows)
    return R.T @ (W @ R), aF


def prove_certificate(spec: Spec, kappa: float | None, st_float: PEPStructure,
                      mterms: list[Term], iterms: list[Term], tau: float,
                      lam: np.ndarray) -> dict[str, Any]:
    """Prove measure <= tau' for a rational tau' >= tau (see the module); a dict with
    ``proven``, ``tau_proven`` (p/q), ``tau_proven_float``, ``detail``, ``seconds``."""
    from sosalgo.pep.bind import bound_method
    from sosalgo.verify.exact import Ball, fraction_str, rational, rational_at_least
    from sosalgo.verify.exact_interpolation import prove_definite, symmetrize_balls

    t0 = time.perf_counter()
    out: dict[str, Any] = {"proven": False, "tau_proven": None, "tau_proven_float": None}
    try:
        om, _ = bound_method(spec, None if spec.sublinear else kappa)
        mt = exact_method(spec, kappa, om)
        st = build_structure(mt, st_float.steps, mterms, iterms)
    except (ValueError, ArithmeticError) as exc:
        return out | {"detail": f"exact method: {exc}", "seconds": time.perf_counter() - t0}
    if st.labels != st_float.labels or st.basis != st_float.basis:
        return out | {"detail": "the exact structure differs from the float one (a point "
                                "coincides in floating point only)",
                      "seconds": time.perf_counter() - t0}
    top = float(np.max(lam, initial=0.0))
    lq = [rational(v) if v > 1e-14 * top else Fraction(0) for v in lam]
    quad, lin = _residual_parts(mt, st, lq)
    detail = ""
    for step in TAU_STEPS:
        tq = rational_at_least(Fraction(tau) * (1 + Fraction(step)))
        cF = [Ball.of(tq * st.init_f[k]) - st.meas_f[k] - lin[k] for k in range(st.nF)]
        bad = [k for k, c in enumerate(cF) if Ball.of(c).lo < 0]
        if bad:
            detail = f"value residual {bad[0]} is not >= 0"
            continue
        S = np.vectorize(lambda v: coarsen(v, 100), otypes=[object])(
            tq * st.init_q - st.meas_q - quad)  # outward: balls around short rationals
        ok, delta, why = prove_definite(symmetrize_balls(S), +1)
        if ok:
            return out | {"proven": True, "tau_proven": fraction_str(tq),
                          "tau_proven_float": float(tq), "delta": fraction_str(delta),
                          "detail": f"S ⪰ {float(delta):.3g} I: {why}; c_F >= 0",
                          "multipliers_nonzero": sum(1 for v in lq if v),
                          "seconds": time.perf_counter() - t0}
        detail = why
    return out | {"detail": detail, "seconds": time.perf_counter() - t0}
