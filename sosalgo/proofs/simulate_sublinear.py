"""Simulation check of a sublinear constant: measure(x_k) <= c |x_0 - x*|^2 / k.

For operators only (``measure: residual``, :func:`sosalgo.certificates.composite.residual_measured`)
the measure is sum_i |u_i|^2 of the calls at time k; for several operators (``measure:
state_change``) it is |xi_{k+1} - xi_k|^2 against |xi_0 - xi*|^2 from random free starts.

The method (oracle model, proximal steps included: :func:`run_method`) is started at rest,
xi_0 = xi* + u (x_0 - x*) (u the fixed point of x* = 1), on the test problems of its
classes (:mod:`sosalgo.proofs.prox_functions`, with m = 0: quadratics with curvatures in
[0, L] (a zero curvature among them), Huber functions, l1, boxes, balls), from random
starts at several distances, and every k = 1..iters is compared with the bound, allowing
1e-11 of the size of the values involved (rounding). For gradient descent with h = 1/L
the Huber function is a worst case, which makes the check sharp. Evidence, not proof: a
violation disproves the constant for that problem.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from sosalgo.certificates.composite import STATE_CHANGE
from sosalgo.oracles import fixed_point_basis
from sosalgo.proofs.prox_functions import ProxProblem, composite_problems
from sosalgo.proofs.simulate import SimulationResult, Tally, Violation
from sosalgo.proofs.simulate_composite import fixed_point_state, run_method

__all__ = ["simulate_sublinear"]

TOL = 1e-11


def _measure(om: Any, prob: ProxProblem, tr: dict[str, np.ndarray]) -> tuple[np.ndarray, ...]:
    """(measure(x_k), size of what it is computed from), k = 1..iters, each (iters, batch)."""
    n = tr["y"].shape[0] - 1  # run for n + 1 steps: y_k exists for k = 1..n
    if om.measure == "residual":  # operators: sum_i |u_i|^2 of the calls at k (u* = 0)
        res = np.sum(tr["u"][1: n + 1] ** 2, axis=(2, 3))
        return res, res
    if om.measure == STATE_CHANGE:  # several operators: |xi_k+1 - xi_k|^2
        step = tr["xi"][2: n + 2] - tr["xi"][1: n + 1]
        size = np.sum(tr["xi"][1: n + 2] ** 2, axis=(2, 3))
        return np.sum(step ** 2, axis=(2, 3)), size[1:] + size[:-1]
    if om.output is None:
        x = np.einsum("j,kbjd->kbd", om.E[0], tr["xi"][1: n + 1])
    else:
        x = tr["y"][1: n + 1, :, om.output]
    k, b, d = x.shape
    flat = x.reshape(-1, d)
    if om.measure == "distance":
        dist = np.sum((flat - prob.x_star) ** 2, axis=1)
        return dist.reshape(k, b), dist.reshape(k, b)
    val, size = np.zeros(len(flat)), np.zeros(len(flat))
    for f in prob.functions:
        fx, fs = f.value(flat), f.value(prob.x_star[None, :])[0]
        val, size = val + fx - fs, size + np.abs(fx) + abs(fs)
    return val.reshape(k, b), size.reshape(k, b)


def _starts(om: Any, prob: ProxProblem, starts: int, rng: np.random.Generator) -> np.ndarray:
    """xi_0 = xi* + u (x_0 - x*), x_0 - x* at random directions and distances 1e-2..1e2;
    for :data:`STATE_CHANGE` a free start, xi_0 - xi* at random (its squared norm returned)."""
    u = fixed_point_basis(om)[:, 0]
    xi_s = fixed_point_state(om, prob)
    if om.measure == STATE_CHANGE:
        e = rng.standard_normal((starts,) + xi_s.shape)
        e *= np.logspace(-2, 2, starts)[:, None, None]
        return xi_s[None] + e, np.sum(e ** 2, axis=(1, 2))
    e = rng.standard_normal((starts, prob.d)) * np.logspace(-2, 2, starts)[:, None]
    return xi_s[None] + u[None, :, None] * e[:, None, :], np.sum(e ** 2, axis=1)


def simulate_sublinear(om: Any, constant: float, dims: Sequence[int] = (1, 2, 5),
                       starts: int = 12, iters: int = 200, seed: int = 0,
                       problems: Sequence[ProxProblem] | None = None) -> SimulationResult:
    """Check ``measure(x_k) <= constant |x_0 - x*|^2 / k`` along trajectories of ``om``
    (a sublinear method: m = 0) on test problems (module docstring). ``rho`` of the
    result holds the constant."""
    from sosalgo.certificates.composite import residual_measured

    om = residual_measured(om)
    start_t = time.perf_counter()
    rng = np.random.default_rng(seed)
    probs = list(problems) if problems is not None else [
        pr for d in dims for pr in composite_problems(om, d, rng)]
    t = Tally()
    ks = np.arange(1, iters + 1)[:, None]
    with np.errstate(all="ignore"):
        for prob in probs:
            key = f"{prob.name} (d={prob.d})"
            t.names.append(key)
            xi0, r0 = _starts(om, prob, starts, rng)
            tr = run_method(om, prob, xi0, iters + 1)
            M, size = _measure(om, prob, tr)
            bound = constant * r0[None, :] / ks
            ratio = M / bound
            bad = M > bound + TOL * (size + bound)
            t.traj += M.shape[1]
            t.steps += M.size
            k, b = np.unravel_index(np.nanargmax(ratio), ratio.shape)
            if ratio[k, b] > t.worst_ratio:
                t.worst_ratio = float(ratio[k, b])
                t.worst = {"function": key, "start": int(b), "k": int(k) + 1}
            for k, b in np.argwhere(bad | ~np.isfinite(M)):
                t.violate(prob.name, Violation(prob.name, prob.d, int(b), int(k) + 1,
                                               "bound", float(ratio[k, b])))
    return SimulationResult(
        rho=float(constant), ok=t.n_viol == 0 and t.traj > 0, trajectories=t.traj,
        steps_checked=t.steps, worst_ratio=t.worst_ratio, worst=t.worst,
        n_violations=t.n_viol, violations=t.violations, violations_by_function=t.per_fn,
        functions=t.names, dims=tuple(sorted({pr.d for pr in probs})),
        seconds=time.perf_counter() - start_t)
