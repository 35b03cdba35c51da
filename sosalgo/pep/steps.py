"""Methods that change with k in the PEP: one method per step.

A method whose coefficients change with the iteration (a step-size schedule, FISTA's t_k,
OGM's theta_k with its last step) is, for the PEP of N steps, the list of its per-step
methods: step k's (A_k, B_k, C_k, D_k) make call k (y_k = C_k xi_k + D_k u_k) and the
move xi_{k+1} = A_k xi_k + B_k u_k. :class:`StepMethods` holds them twice:

* ``floats``: one :class:`sosalgo.oracles.OracleMethod` per step (the same functions,
  oracles, output or E, n and p at every step) for the float SDP;
* ``exact``: per step the matrices ``A``, ``B``, ``C``, ``D`` (and ``E``) as exact numbers:
  sympy matrices (rationals, small closed forms: enclosed here in rational balls) or
  object arrays of :class:`~sosalgo.kernel.exact.Ball` / Fraction (a sequence evaluated
  in outward-rounded ball arithmetic: OGM's nested radicals at N = 50);
* ``fixed_point``: the exact [u, X_s] (:func:`sosalgo.oracles.fixed_point_basis`) that
  every step keeps fixed, when its provider has proven it (ball matrices cannot prove
  it: a ball residual only contains 0); None: solved exactly from step 0's sympy
  matrices and checked exactly (sympy) on every step.

N steps make N calls: an output call and the ``y`` terms after N steps are the calls of
step N - 1 (:func:`sosalgo.pep.structure.last_calls`: the N-th prox point is x_N, as
PEPit counts FISTA).

The PEP is the one of :mod:`sosalgo.pep.structure` with the plain basis (K = 0: the
oracle answers themselves are the basis vectors, as PEPit's): a deadbeat gain is a
property of one (A, B), and a sublinear (m: 0) method's iterates do not shrink, so the
late rows are not differences of large numbers. The exact check rebuilds the same
structure on the exact per-step matrices, so the proof is about the per-step methods as
given; the provider answers for them being the spec's (:mod:`sosalgo.steps`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np
import sympy as sp

from sosalgo.errors import InputError
from sosalgo.pep.structure import Method

__all__ = ["StepMethods", "exact_step_method", "float_step_method"]

FIXED_TOL = 1e-9  # relative residual of the common fixed point in floating point


@dataclass
class StepMethods:
    """A method that changes with k (see the module): ``floats`` (k = 0, 1, ...),
    ``exact`` (per step {"A", "B", "C", "D", "E"?}), ``fixed_point`` (exact [u, X_s] or
    None), ``schedule`` (the per-step parameter values as written, recorded in the
    document so that ``sosalgo verify`` rebuilds the same method)."""

    floats: Sequence[Any]
    exact: Sequence[Mapping[str, Any]] | None = None
    fixed_point: Any = None
    schedule: dict[str, list[str]] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.floats)


def _same_shape(oms: Sequence[Any]) -> None:
    first = oms[0]
    for k, om in enumerate(oms[1:], 1):
        same = (om.oracles == first.oracles and om.output == first.output
                and om.A.shape == first.A.shape
                and [(f.name, f.cls.name, f.params) for f in om.functions]
                == [(f.name, f.cls.name, f.params) for f in first.functions]
                and (om.E is None) == (first.E is None)
                and (om.E is None or np.array_equal(om.E, first.E)))
        if not same:
            raise InputError(f"step {k}: the method's functions, oracles, output and shapes "
                             "must be those of step 0")


def _fixed_residual(om: Any, X: np.ndarray) -> float:
    """The largest relative residual of X = [u, X_s] as the fixed points of ``om``."""
    n, p = om.n, om.p
    S = om.optimal_map()
    erow, drow = om.output_row()
    lhs = np.vstack([np.eye(n) - om.A, om.C, erow[None, :]])
    rhs = np.zeros((n + p + 1, X.shape[1]))
    rhs[n:, 0] = 1.0
    if S.shape[1]:
        rhs[:n, 1:] = om.B @ S
        rhs[n: n + p, 1:] = -om.D @ S
        rhs[n + p, 1:] = -(drow @ S)
    scale = np.abs(lhs).sum(axis=1, keepdims=True) * (1.0 + np.abs(X).max()) + np.abs(rhs)
    return float((np.abs(lhs @ X - rhs) / np.maximum(scale, 1e-300)).max(initial=0.0))


def float_step_method(sm: StepMethods, kappa: float, count: int) -> Method:
    """The float :class:`Method` of the first ``count`` steps: step 0's method with the
    per-step matrices, the plain basis (K = 0) and the common fixed point (InputError
    when a step moves it or changes shape)."""
    from sosalgo.oracles import fixed_point_basis
    from sosalgo.pep.core import float_method

    if len(sm.floats) < count:
        raise InputError(f"--steps: {count} steps' methods needed, {len(sm.floats)} given")
    oms = list(sm.floats[:count])
    _same_shape(oms)
    X = fixed_point_basis(oms[0])
    assert X is not None  # the OracleMethod checked it
    for k, om in enumerate(oms[1:], 1):
        if _fixed_residual(om, X) > FIXED_TOL:
            raise InputError(f"step {k}: the method does not keep step 0's fixed point "
                             "(x* and the optimal subgradients): every step must")
    mt = float_method(oms[0], kappa)
    mt.K = np.zeros_like(mt.K)
    mt.per_step = [(om.A, om.B, om.C, om.D) for om in oms]
    if mt.out_call is not None:  # E = C_i, D_i = 0 at every step, or no output call
        i = mt.out_call
        if not all(mt.same(om.E[0], om.C[i]) and mt.same(om.D[i], 0 * om.D[i])
                   for om in oms):
            mt.out_call = None
    return mt


def _exact_array(M: Any, digits: int) -> np.ndarray:
    """An exact matrix as an object array of Fractions and rational balls: a sympy
    matrix enclosed at ``digits`` decimals, an array of Balls/rationals as given."""
    from sosalgo.kernel.exact import Ball
    from sosalgo.pep.exact import _balls

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


def _zero(v: Any) -> bool:
    """``v == 0`` proven: a sympy number simplified to 0, an exact 0 (a ball of radius 0)."""
    from sosalgo.pep.exact import _proven_zero

    if isinstance(v, sp.Basic):
        return _proven_zero(v)
    return bool(getattr(v, "c", v) == 0 and getattr(v, "r", 0) == 0)


def _sympy_steps(steps: Sequence[Mapping[str, Any]], p: int) -> list[dict[str, sp.Matrix]] | None:
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
    from sosalgo.pep.exact import _fixed_points

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
    from sosalgo.pep.exact import _proven_zero

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
    return all(all(_zero(x - y) for x, y in zip(a, b, strict=True))
               for a, b in zip(rows_a, rows_b, strict=True))


def exact_step_method(spec: Any, kappa: float | None, sm: StepMethods, count: int,
                      digits: int = 60) -> Method:
    """The exact :class:`Method` of the first ``count`` per-step methods of ``sm``: the
    class, units and terms of ``spec`` as written (:func:`sosalgo.pep.exact.exact_base`),
    the per-step matrices exact (sympy ones enclosed at ``digits`` decimals), K = 0.
    ValueError when they are missing or their fixed point is not proven."""
    from sosalgo.certificates.exact_composite import exact_class_inequalities
    from sosalgo.kernel.exact import Ball, enclose
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.pep.exact import _balls, _scale, _sym, exact_base
    from sosalgo.pep.structure import enclosure_bits

    if sm.exact is None or len(sm.exact) < count:
        raise ValueError(f"{count} steps' exact matrices needed")
    om = sm.floats[0]
    X, _ = _exact_fixed_point(sm, om, count)
    Xb = _balls(X, digits)
    steps = [{k: _exact_array(M, digits) for k, M in mats.items()}
             for mats in list(sm.exact)[:count]]
    p = om.p
    zero = np.full((p, p), Fraction(0), dtype=object)
    per = [(s["A"], s["B"], s["C"], s.get("D", zero)) for s in steps]
    base = exact_base(spec, kappa)
    funcs, ineqs = [], []
    for fn in om.functions:
        decl = spec.functions[fn.name]
        params = {k: enclose(to_sympy(e).xreplace(base), digits) for k, e in decl.params.items()}
        funcs.append((fn.name, fn.cls, params))
        ineqs.append(exact_class_inequalities(fn.cls, params)[0])

    def coef(t: Any) -> Any:
        return enclose(to_sympy(t.coef).xreplace(base), digits)

    def same(a: np.ndarray, b: np.ndarray) -> bool:
        return all(Ball.of(v).c == 0 and Ball.of(v).r == 0 for v in a - b)

    A0, B0, C0, D0 = per[0]
    E = steps[0].get("E")
    mt = Method(A0, B0, C0, D0, E, om.output, funcs, tuple(om.oracles), Xb[:, 0], Xb[:, 1:],
                _scale(base[_sym("L")]), ineqs, coef, same,
                np.full((p, om.n), Fraction(0), dtype=object), exact=True,
                bits=enclosure_bits(digits), per_step=per)
    mt.x0_call = _start_call(mt, per[0])
    mt.out_call = _output_call(mt, per)
    return mt


def _start_call(mt: Method, step0: tuple[np.ndarray, ...]) -> int | None:
    """The first call of step 0 at x_0 for every start xi_0 = X0 x_0 - Xs s~ (D_i = 0,
    C_i X0 = 1, C_i Xs = 0), proven exactly."""
    _, _, C, D = step0
    for i in range(C.shape[0]):
        if (_zero(C[i].dot(mt.X0) - 1) and all(_zero(v) for v in C[i].dot(mt.Xs))
                and all(_zero(v) for v in D[i])):
            return i
    return None


def _output_call(mt: Method, per: list[tuple[np.ndarray, ...]]) -> int | None:
    """The first call i with E = C_i and D_i = 0 at every step, proven exactly."""
    if mt.output is not None or mt.E is None:
        return None
    for i in range(mt.p):
        if all(_call_at([mt.E[0], D[i]], [C[i], 0 * D[i]]) for _, _, C, D in per):
            return i
    return None
