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
step N - 1 (:func:`sosalgo.worstcase.structure.last_calls`: the N-th prox point is x_N, as
PEPit counts FISTA).

The PEP is the one of :mod:`sosalgo.worstcase.structure` with the plain basis (K = 0: the
oracle answers themselves are the basis vectors, as PEPit's): a deadbeat gain is a
property of one (A, B), and a sublinear (m: 0) method's iterates do not shrink, so the
late rows are not differences of large numbers. The exact check rebuilds the same
structure on the exact per-step matrices, so the proof is about the per-step methods as
given; the provider answers for them being the spec's (:mod:`sosalgo.steps`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sosalgo.errors import InputError
from sosalgo.worstcase.structure import PEPFrame

__all__ = ["StepMethods", "float_step_method", "spec_steps"]

FIXED_TOL = 1e-9  # relative residual of the common fixed point in floating point


@dataclass
class StepMethods:
    """A method that changes with k (see the module): ``floats`` (k = 0, 1, ...),
    ``exact`` (per step {"A", "B", "C", "D", "E"?}), ``fixed_point`` (exact [u, X_s] or
    None), ``schedule`` (the per-step parameter values as written, recorded in the
    document so that ``sosalgo verify`` rebuilds the same method)."""

    floats: Sequence[Any]
    exact: Sequence[Mapping[str, Any]] | Callable[[], Sequence[Mapping[str, Any]]] | None = None
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


def float_step_method(sm: StepMethods, mt: PEPFrame, count: int) -> PEPFrame:
    """The float :class:`PEPFrame` of the first ``count`` steps: ``mt`` (step 0's method)
    with the per-step matrices, the plain basis (K = 0) and the common fixed point
    (InputError when a step moves it or changes shape)."""
    from sosalgo.oracles import fixed_point_basis

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
    mt.K = np.zeros_like(mt.K)
    mt.per_step = [(om.A, om.B, om.C, om.D) for om in oms]
    if mt.out_call is not None:  # E = C_i, D_i = 0 at every step, or no output call
        i = mt.out_call
        if not all(mt.same(om.E[0], om.C[i]) and mt.same(om.D[i], 0 * om.D[i])
                   for om in oms):
            mt.out_call = None
    return mt


def spec_steps(spec: Any, kappa: float | None, steps: int) -> StepMethods | None:
    """The per-step methods of the spec over N = ``steps`` steps, as the problem layer
    gives them (:func:`sosalgo.steps.step_methods`): floats now; the exact matrices when
    first needed (sympy ones while their closed forms stay small, else outward-rounded
    balls); the schedule (every parameter per step) for the document. None when one
    method serves every step (N equal steps: the PEP binds it once and keeps its
    time-invariant structure). SpecError (one line) for bad input."""
    from sosalgo.steps import ball_steps, exact_steps, step_methods, step_values

    floats = step_methods(spec, kappa, steps)
    if floats is None:
        return None
    values = step_values(spec, kappa, steps)
    schedule = {p: [repr(float(env[p])) for env in values] for p in spec.parameters}

    def exact() -> list[dict[str, Any]]:
        mats = exact_steps(spec, kappa, steps)
        return mats if mats is not None else ball_steps(spec, kappa, steps)

    return StepMethods(floats, exact, None, schedule)
