"""Simulation check of a composite certificate: run the method with its proximal steps on
test functions (:mod:`sosalgo.proofs.prox_functions`) and watch the Lyapunov function.

The method xi+ = A xi + B u, y = C xi + D u is run in d dimensions in absolute
coordinates; D is lower triangular, so the calls are made in order: with
v_i = C_i xi + sum_{j<i} D_ij u_j, a call with D_ii = -t < 0 is the proximal step
y_i = prox_{t f}(v_i), u_i = (v_i - y_i)/t (so u_i is in ∂f(y_i)), and one with D_ii = 0
queries the (sub)gradient at y_i = v_i. With the fixed point xi* of the problem's x* and
optimal subgradients s* (from :func:`sosalgo.oracles.fixed_point_basis`) and the tilted
values h_j(y) = f_j(y) - f_j(x*) - <s_j*, y - x*>, the certificate's Lyapunov function

    V_k = z_k' (P ⊗ I_d) z_k + sum_{t, i} p_{t p + i} h_{j(i)}(y_{k-t, i})
          + c sum_{j not at the output} h_j(x_k),   z_k = (xi_k - xi*, u~_k, ..., u~_{k-l}),

must satisfy, from k = l on, V_{k+1} <= rho^2 V_k, measure(x_k) <= V_k and
measure(x_k) <= rho^(2(k-l)) V_l, with measure |x_k - x*|^2 or F(x_k) - F*. Each
comparison allows 1e-11 of the size of what V_k is computed from (the absolute values of
its terms and of the points they are differences of: rounding), and a trajectory is
followed while V_k is above 1e-5 of that size. Evidence, not proof; a
violation disproves the certificate for that problem.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from sosalgo.oracles import fixed_point_basis
from sosalgo.proofs.prox_functions import ProxProblem, composite_problems
from sosalgo.proofs.simulate import SimulationResult, Tally, Violation

__all__ = ["fixed_point_state", "run_method", "simulate_composite"]

TOL = 1e-11  # of the size of what V is computed from (rounding)
FOLLOW = 1e-5  # follow while V >= FOLLOW * that size


def fixed_point_state(om: Any, prob: ProxProblem) -> np.ndarray:
    """xi* (n, d) of the problem's x* and optimal subgradients."""
    X = fixed_point_basis(om)
    if X is None:
        raise ValueError("the method has no fixed point")
    xi = np.outer(X[:, 0], prob.x_star)
    for j in range(X.shape[1] - 1):
        xi = xi + np.outer(X[:, 1 + j], prob.s_star[j])
    return xi


def run_method(om: Any, prob: ProxProblem, xi0: np.ndarray,
               iters: int) -> dict[str, np.ndarray]:
    """Trajectories from xi0 (batch, n, d): xi (iters + 1, ...), y and u (iters, batch, p, d)."""
    xi = np.array(xi0, dtype=float)
    b, _, d = xi.shape
    xis, ys, us = [xi], [], []
    for _ in range(iters):
        y, u = np.zeros((b, om.p, d)), np.zeros((b, om.p, d))
        for i in range(om.p):
            v = np.einsum("j,bjd->bd", om.C[i], xi) + np.einsum("j,bjd->bd", om.D[i, :i],
                                                                u[:, :i])
            f, t = prob.functions[om.oracles[i]], -float(om.D[i, i])
            if t > 0:
                y[:, i] = f.prox(v, t)
                u[:, i] = (v - y[:, i]) / t
            else:
                y[:, i], u[:, i] = v, f.grad(v)
        xi = np.einsum("ij,bjd->bid", om.A, xi) + np.einsum("ij,bjd->bid", om.B, u)
        xis.append(xi)
        ys.append(y)
        us.append(u)
    return {"xi": np.array(xis), "y": np.array(ys), "u": np.array(us)}


def _tilted(prob: ProxProblem, j: int, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """h_j(y) for y (batch, d), and the size of what it is computed from (rounding)."""
    f, xs = prob.functions[j], prob.x_star
    fy, fs, lin = f.value(y), f.value(xs[None, :])[0], (y - xs) @ f.s
    return fy - fs - lin, np.abs(fy) + abs(fs) + np.abs(lin)


def _series(om: Any, prob: ProxProblem, tr: dict[str, np.ndarray], P: np.ndarray,
            lyap: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(V_k, |terms|_k, measure_k) for k = lag .. iters - 1, each (steps, batch)."""
    lag, p, J = int(lyap["lag"]), om.p, len(om.functions)
    weights, c = list(lyap["p"]), lyap.get("c")
    xi_s = fixed_point_state(om, prob)
    s_of_call = np.array([prob.s_star[j] for j in om.oracles])  # (p, d)
    out_f = None if om.output is None else om.oracles[om.output]
    V, S, M = [], [], []
    for k in range(lag, tr["y"].shape[0]):
        ut = [tr["u"][k - tau] - s_of_call[None] for tau in range(lag + 1)]
        z = np.concatenate([tr["xi"][k] - xi_s[None]] + ut, axis=1)  # (batch, nz, d)
        quad = np.einsum("bid,ij,bjd->b", z, P, z)
        big = np.abs(z) + np.abs(np.concatenate([tr["xi"][k]] + [tr["u"][k - tau] for tau
                                                               in range(lag + 1)], axis=1))
        scale = np.einsum("bid,ij,bjd->b", np.abs(z), np.abs(P), big)
        vk = quad
        for tau in range(lag + 1):
            for i in range(p):
                h, sz = _tilted(prob, om.oracles[i], tr["y"][k - tau][:, i])
                w = weights[tau * p + i]
                vk, scale = vk + w * h, scale + abs(w) * sz
        x = (tr["y"][k][:, om.output] if om.output is not None
             else np.einsum("j,bjd->bd", om.E[0], tr["xi"][k]))
        hx = [_tilted(prob, j, x) for j in range(J) if j != out_f]
        extra = sum((h for h, _ in hx), np.zeros(len(x)))
        if c is not None:
            vk = vk + c * extra
            scale = scale + abs(c) * sum((sz for _, sz in hx), np.zeros(len(x)))
        if om.measure == "distance":
            meas = ((x - prob.x_star) ** 2).sum(axis=1)
        else:
            meas = extra + (0.0 if out_f is None else _tilted(prob, out_f, x)[0])
        V.append(vk)
        S.append(scale)
        M.append(meas)
    return np.array(V), np.array(S), np.array(M)


def _starts(xi_s: np.ndarray, starts: int, rng: np.random.Generator) -> np.ndarray:
    """xi* plus random deviations of log-uniform size in [0.1, 30] (batch, n, d)."""
    n, d = xi_s.shape
    e = rng.standard_normal((starts, n, d))
    e *= 10 ** rng.uniform(-1, 1.5, (starts, 1, 1)) / np.linalg.norm(e, axis=(1, 2),
                                                                      keepdims=True)
    return xi_s[None] + e


def _check(t: Tally, key: str, name: str, d: int, lag: int, r2: float,
           V: np.ndarray, S: np.ndarray, M: np.ndarray) -> None:
    """Decrease, positivity and the bound along one batch of trajectories."""
    active = np.isfinite(V[0]) & (V[0] >= FOLLOW * S[0])
    t.traj += V.shape[1]
    for k in range(V.shape[0]):
        tol = TOL * S[k]
        for b in np.flatnonzero(active & ~(M[k] <= V[k] + tol)):
            t.violate(key, Violation(name, d, int(b), k + lag, "positivity",
                                     float(M[k][b] / V[k][b])))
        limit = r2 ** k * V[0]
        for b in np.flatnonzero(active & ~(M[k] <= limit + tol + r2 ** k * TOL * S[0])):
            t.violate(key, Violation(name, d, int(b), k + lag, "bound", float(M[k][b] / limit[b])))
        if k + 1 == V.shape[0]:
            break
        ok = V[k + 1] <= r2 * V[k] + TOL * (S[k + 1] + S[k])
        with np.errstate(all="ignore"):
            ratio = np.where(active, V[k + 1] / (r2 * V[k]), 0.0)
        t.steps += int(active.sum())
        ratio = np.where(np.isnan(ratio), np.inf, ratio)
        if active.any() and ratio.max() > t.worst_ratio:
            i = int(np.argmax(ratio))
            t.worst_ratio, t.worst = float(ratio[i]), {"function": name, "dim": d,
                                                       "start": i, "k": k + lag}
        for b in np.flatnonzero(active & ~ok):
            t.violate(key, Violation(name, d, int(b), k + lag, "decrease", float(ratio[b])))
        active = active & np.isfinite(V[k + 1]) & (V[k + 1] >= FOLLOW * S[k + 1])


def simulate_composite(om: Any, rho: float, P: Any, lyapunov: dict[str, Any],
                       dims: Sequence[int] = (1, 2, 5), starts: int = 12, iters: int = 50,
                       seed: int = 0, problems: Sequence[ProxProblem] | None = None,
                       **_: Any) -> SimulationResult:
    """Run an :class:`~sosalgo.oracles.OracleMethod` on test problems (default: every
    combination of its classes' test functions in each of ``dims``) and check the
    certificate's Lyapunov function along the trajectories (module docstring)."""
    start_t = time.perf_counter()
    rng = np.random.default_rng(seed)
    P = np.atleast_2d(np.asarray(P, float))
    lag = int(lyapunov["lag"])
    nz = om.n + om.p * (lag + 1)
    if P.shape != (nz, nz):
        raise ValueError(f"P has shape {P.shape}, expected {(nz, nz)}")
    probs = list(problems) if problems is not None else [
        pr for d in dims for pr in composite_problems(om, d, rng)]
    t = Tally()
    with np.errstate(all="ignore"):
        for prob in probs:
            key = f"{prob.name} (d={prob.d})"
            t.names.append(key)
            tr = run_method(om, prob, _starts(fixed_point_state(om, prob), starts, rng), iters)
            V, S, M = _series(om, prob, tr, P, lyapunov)
            _check(t, key, prob.name, prob.d, lag, float(rho) ** 2, V, S, M)
    return SimulationResult(
        rho=float(rho), ok=t.n_viol == 0 and t.traj > 0, trajectories=t.traj,
        steps_checked=t.steps, worst_ratio=t.worst_ratio, worst=t.worst,
        n_violations=t.n_viol, violations=t.violations, violations_by_function=t.per_fn,
        functions=t.names, dims=tuple(sorted({pr.d for pr in probs})),
        seconds=time.perf_counter() - start_t)
