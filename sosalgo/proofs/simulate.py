"""Simulation check of a certificate: run the method and watch the Lyapunov function.

The method of eq. (10) in dimension d is xi_{k+1} = (A ⊗ I_d) xi_k + (B ⊗ I_d) grad f(y_k),
y_k = (C ⊗ I_d) xi_k, x_k = (E ⊗ I_d) xi_k (Remark 1). The state is stored as an (n, d)
array X with xi = vec(X'), so (A ⊗ I_d) xi is A X. With the fixed point xi* = u ⊗ x* of
eq. (11), the error e_k = xi_k - xi* obeys exactly

    e_{k+1} = A e_k + B grad f(x* + C e_k),      x_k - x* = E e_k,

which is what is iterated (no cancellation against x*, so V can be followed to 1e-250);
a short run in absolute coordinates checks that both agree. Along every trajectory

    V_k = f(x_k) - f* + (xi_k - xi*)' (P ⊗ I_d)(xi_k - xi*)               (eq. 12)

must satisfy V_{k+1} <= rho^2 V_k (eq. 13) and f(x_k) - f* <= rho^(2k) V_0 (eq. 16), up to
a relative tolerance. Finding no violation is evidence, not proof; finding one disproves
the certificate (or the rate) for that function.

Certificates with function values and past gradients (the interpolation family) pass
``lyapunov={"lag": l, "p": [...], "c": c}``: then P acts on z_k = (e_k, u_k, ..., u_{k-l}) and

    V_k = z_k' (P ⊗ I_d) z_k + sum_j p_j (f(y_{k-j}) - f*) + c (f(x_k) - f*)

(c = None: no x term), checked from k = l on with the bound f(x_k) - f* <= rho^(2(k-l)) V_l.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sosalgo.model import Algorithm, fixed_point
from sosalgo.proofs.functions import Objective, function_suite

__all__ = ["SimulationResult", "Violation", "simulate_check"]

REL_TOL = 1e-9
ABS_FLOOR = 1e-300
UNDERFLOW = 1e-250
MAX_RECORDED = 50
CONSISTENCY_TOL = 1e-8  # error vs absolute coordinates (eq. 11 holds numerically)

Factory = Callable[[float, float, int, np.random.Generator], list[Objective]]
FunctionSource = Sequence[Objective] | Factory


@dataclass(frozen=True)
class Violation:
    """One failed inequality: ``kind`` is "decrease" (eq. 13) or "bound" (eq. 16)."""

    function: str
    dim: int
    start: int
    k: int
    kind: str
    ratio: float  # V_{k+1} / (rho^2 V_k), or (f(x_k) - f*) / (rho^(2k) V_0)

    def to_dict(self) -> dict[str, Any]:
        return {"function": self.function, "dim": self.dim, "start": self.start, "k": self.k,
                "kind": self.kind, "ratio": self.ratio}


@dataclass
class SimulationResult:
    """Outcome of :func:`simulate_check`."""

    rho: float
    ok: bool
    trajectories: int
    steps_checked: int
    worst_ratio: float  # max V_{k+1} / (rho^2 V_k) over checked steps
    worst: dict[str, Any] | None
    n_violations: int  # violating steps (a trajectory is followed after a violation)
    violations: list[Violation] = field(default_factory=list)  # first MAX_RECORDED
    violations_by_function: dict[str, int] = field(default_factory=dict)
    functions: list[str] = field(default_factory=list)
    dims: tuple[int, ...] = ()
    consistency: float = 0.0  # max relative gap between error and absolute coordinates
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "rho": self.rho,
            "ok": self.ok,
            "trajectories": self.trajectories,
            "steps_checked": self.steps_checked,
            "worst_ratio": self.worst_ratio,
            "worst": self.worst,
            "n_violations": self.n_violations,
            "violations": [v.to_dict() for v in self.violations],
            "violations_by_function": dict(self.violations_by_function),
            "functions": list(self.functions),
            "dims": list(self.dims),
            "consistency": self.consistency,
            "seconds": self.seconds,
        }


def _initial_errors(
    u: np.ndarray, n: int, d: int, starts: int, hints: Sequence[float], rng: np.random.Generator
) -> np.ndarray:
    """Random errors e_0 of shape (batch, n, d): half generic, half u ⊗ z (x_{-1} = x_0 ...).

    Scales are log-uniform in [0.1, 30] so piecewise functions are crossed at their kinks;
    ``hints`` add consistent starts x0 = x* + t 1.
    """
    k_gen = starts // 2
    k_con = starts - k_gen
    scale_g = 10 ** rng.uniform(-1, 1.5, (k_gen, 1, 1))
    gen = rng.standard_normal((k_gen, n, d))
    gen = gen / np.linalg.norm(gen, axis=(1, 2), keepdims=True) * scale_g
    scale_c = 10 ** rng.uniform(-1, 1.5, (k_con, 1))
    z = rng.standard_normal((k_con, d))
    z = z / np.linalg.norm(z, axis=1, keepdims=True) * scale_c
    con = u[None, :, None] * z[:, None, :]
    hint = np.array([u[:, None] * np.full((1, d), t) for t in hints]).reshape(-1, n, d)
    return np.concatenate([gen, con, hint], axis=0)


def _lyapunov(
    f: Objective, E: np.ndarray, P: np.ndarray, e: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(V, f(x) - f*) for errors e of shape (batch, n, d)."""
    gap = f.gap(np.einsum("j,bjd->bd", E, e))
    quad = np.einsum("bid,ij,bjd->b", e, P, e)
    return gap + quad, gap


def _lyapunov_hist(
    f: Objective, E: np.ndarray, P: np.ndarray, e: np.ndarray, grads: list[np.ndarray],
    gaps_y: list[np.ndarray], p: Sequence[float], c: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """(V, f(x) - f*) with z = (e, u_k, ..., u_{k-l}); ``grads``/``gaps_y`` newest first."""
    z = np.concatenate([e] + [g[:, None, :] for g in grads], axis=1)
    gap = f.gap(np.einsum("j,bjd->bd", E, e))
    V = np.einsum("bid,ij,bjd->b", z, P, z)
    for pj, gy in zip(p, gaps_y, strict=True):
        V = V + pj * gy
    if c is not None:
        V = V + c * gap
    return V, gap


def _push(f: Objective, C: np.ndarray, e: np.ndarray, hist: tuple[list, list],
          lag: int) -> tuple[list, list]:
    """Add u_k = grad f(y_k) and f(y_k) - f* at the new state e (newest first, l + 1 kept)."""
    y = np.einsum("j,bjd->bd", C, e)
    return ([f.grad_z(y)] + hist[0])[: lag + 1], ([f.gap(y)] + hist[1])[: lag + 1]


def _history_start(alg: Algorithm, f: Objective, e: np.ndarray,
                   lag: int) -> tuple[np.ndarray, tuple[list, list]]:
    """Run l steps from e_0 so that V_l (which needs u_0..u_l) is defined."""
    A, B, C = alg.A, alg.B[:, 0], alg.C[0]
    hist: tuple[list, list] = _push(f, C, e, ([], []), lag)
    for _ in range(lag):
        e = np.einsum("ij,bjd->bid", A, e) + B[None, :, None] * hist[0][0][:, None, :]
        hist = _push(f, C, e, hist, lag)
    return e, hist


def _consistency(
    alg: Algorithm, f: Objective, u: np.ndarray, e0: np.ndarray, steps: int = 5
) -> float:
    """Max relative difference between error-coordinate and absolute-coordinate runs."""
    A, B, C = alg.A, alg.B[:, 0], alg.C[0]
    xs = np.asarray(f.x_star, float)
    e = e0.copy()
    xi = u[None, :, None] * xs[None, None, :] + e0
    worst = 0.0
    for _ in range(steps):
        e = np.einsum("ij,bjd->bid", A, e) + B[None, :, None] * f.grad_z(
            np.einsum("j,bjd->bd", C, e))[:, None, :]
        xi = np.einsum("ij,bjd->bid", A, xi) + B[None, :, None] * f.grad(
            np.einsum("j,bjd->bd", C, xi))[:, None, :]
        diff = np.abs((xi - u[None, :, None] * xs[None, None, :]) - e).max()
        scale = 1.0 + np.abs(xi).max()
        if np.isfinite(diff) and np.isfinite(scale):
            worst = max(worst, float(diff / scale))
    return worst


def simulate_check(
    alg: Algorithm,
    rho: float,
    P: Any,
    lam: float | None = None,
    dims: Sequence[int] = (1, 2, 10),
    starts: int = 20,
    iters: int = 60,
    seed: int = 0,
    functions: FunctionSource | None = None,
    lyapunov: dict[str, Any] | None = None,
) -> SimulationResult:
    """Run the method on functions of F(m, L) and check eq. (13) and (16) along trajectories.

    ``functions``: None (the default :func:`~sosalgo.proofs.functions.function_suite`), a
    callable ``(m, L, d, rng) -> list[Objective]`` used for every d in ``dims``, or a list of
    Objective (their own dimensions are used and ``dims`` is ignored). ``lam`` does not enter
    V; it is accepted so a whole certificate can be passed. ``lyapunov`` (lag, p, c) selects
    the Lyapunov function with past gradients and function values (module docstring).
    """
    del lam
    start_t = time.perf_counter()
    rng = np.random.default_rng(seed)
    P = np.atleast_2d(np.asarray(P, float))
    n = alg.n
    lag = -1 if lyapunov is None else int(lyapunov["lag"])
    if P.shape != (n + lag + 1, n + lag + 1):
        raise ValueError(f"P has shape {P.shape}, expected {(n + lag + 1, n + lag + 1)}")
    u = fixed_point(alg)
    if u is None:
        raise ValueError("the method has no fixed point (eq. 11)")
    groups = _function_groups(alg, functions, dims, rng)
    run = _Run(alg, P, float(rho) ** 2, lyapunov)
    with np.errstate(all="ignore"):
        for d, fns in groups:
            for f in fns:
                run.follow(f, d, _initial_errors(u, n, d, starts, f.starts, rng), u, iters)
    t = run.tally
    return SimulationResult(
        rho=float(rho), ok=t.n_viol == 0 and t.consistency <= CONSISTENCY_TOL,
        trajectories=t.traj, steps_checked=t.steps,
        worst_ratio=t.worst_ratio, worst=t.worst, n_violations=t.n_viol,
        violations=t.violations, violations_by_function=t.per_fn,
        functions=t.names, dims=tuple(d for d, _ in groups), consistency=t.consistency,
        seconds=time.perf_counter() - start_t,
    )


def _function_groups(alg: Algorithm, functions: FunctionSource | None, dims: Sequence[int],
                     rng: np.random.Generator) -> list[tuple[int, list[Objective]]]:
    """(d, functions of dimension d) to run, each checked to lie in F(m, L)."""
    if functions is None or callable(functions):
        source = functions or function_suite
        groups = [(d, source(alg.m, alg.L, d, rng)) for d in dims]
    else:
        by_dim: dict[int, list[Objective]] = {}
        for f in functions:
            by_dim.setdefault(f.d, []).append(f)
        groups = sorted(by_dim.items())
    for _, fns in groups:
        for f in fns:
            if f.m < alg.m * (1 - 1e-12) or f.L > alg.L * (1 + 1e-12):
                raise ValueError(
                    f"{f.name} is in F({f.m:g}, {f.L:g}), not in F(m, L) = F({alg.m:g}, {alg.L:g})"
                )
    return groups


@dataclass
class Tally:
    """What the trajectories found so far (see :class:`SimulationResult`)."""

    violations: list[Violation] = field(default_factory=list)
    n_viol: int = 0
    worst_ratio: float = 0.0
    worst: dict[str, Any] | None = None
    steps: int = 0
    traj: int = 0
    consistency: float = 0.0
    names: list[str] = field(default_factory=list)
    per_fn: dict[str, int] = field(default_factory=dict)

    def violate(self, key: str, v: Violation) -> None:
        self.n_viol += 1
        self.per_fn[key] = self.per_fn.get(key, 0) + 1
        if len(self.violations) < MAX_RECORDED:
            self.violations.append(v)


class _Run:
    """Follows the Lyapunov function of one certificate along trajectories of the method."""

    def __init__(self, alg: Algorithm, P: np.ndarray, r2: float,
                 lyapunov: dict[str, Any] | None):
        self.alg, self.P, self.r2, self.lyap = alg, P, r2, lyapunov
        self.lag = -1 if lyapunov is None else int(lyapunov["lag"])
        self.tally = Tally()

    def _value(self, f: Objective, e: np.ndarray,
               hist: tuple[list, list] | None) -> tuple[np.ndarray, np.ndarray]:
        """(V, f(x) - f*) at the errors e (and the history, for the extended form)."""
        E = self.alg.E[0]
        if self.lyap is None:
            return _lyapunov(f, E, self.P, e)
        assert hist is not None
        return _lyapunov_hist(f, E, self.P, e, hist[0], hist[1], self.lyap["p"], self.lyap["c"])

    def follow(self, f: Objective, d: int, e: np.ndarray, u: np.ndarray, iters: int) -> None:
        """Check eq. (13) and (16) along the trajectories from the errors e (batch, n, d)."""
        alg, t, r2 = self.alg, self.tally, self.r2
        A, B, C = alg.A, alg.B[:, 0], alg.C[0]
        key = f"{f.name} (d={d})"
        t.names.append(key)
        t.consistency = max(t.consistency, _consistency(alg, f, u, e[: min(4, len(e))]))
        batch = e.shape[0]
        t.traj += batch
        hist = None
        if self.lyap is not None:
            e, hist = _history_start(alg, f, e, self.lag)
        V, gap = self._value(f, e, hist)
        V0 = V.copy()
        active = np.isfinite(V) & (V >= UNDERFLOW)
        bound_scale = np.ones(batch)
        for k in range(iters):
            # eq. (16) at step k: f(x_k) - f* <= rho^(2k) V_0
            limit = bound_scale * V0
            bad = active & ~(gap <= limit * (1 + REL_TOL) + ABS_FLOOR)
            for b in np.flatnonzero(bad):
                t.violate(key, Violation(f.name, d, int(b), k, "bound",
                                         float(gap[b] / limit[b])))
            g = hist[0][0] if hist is not None else f.grad_z(np.einsum("j,bjd->bd", C, e))
            e = np.einsum("ij,bjd->bid", A, e) + B[None, :, None] * g[:, None, :]
            if hist is not None:
                hist = _push(f, C, e, hist, self.lag)
            Vn, gapn = self._value(f, e, hist)
            self._decrease(f, d, key, k, active, V, Vn)
            # keep following violating trajectories (each step is its own claim)
            active = active & np.isfinite(Vn) & (Vn >= UNDERFLOW)
            V, gap = Vn, gapn
            bound_scale = bound_scale * r2
            if not active.any():
                break

    def _decrease(self, f: Objective, d: int, key: str, k: int, checked: np.ndarray,
                  V: np.ndarray, Vn: np.ndarray) -> None:
        """Eq. (13) at step k on the checked trajectories: V_{k+1} <= rho^2 V_k."""
        t, r2 = self.tally, self.r2
        ok = Vn <= r2 * V + REL_TOL * V + ABS_FLOOR
        t.steps += int(checked.sum())
        ratio = np.where(checked, Vn / (r2 * V), 0.0)
        ratio = np.where(np.isnan(ratio), np.inf, ratio)
        if checked.any():
            i = int(np.argmax(ratio))
            if ratio[i] > t.worst_ratio:
                t.worst_ratio = float(ratio[i])
                t.worst = {"function": f.name, "dim": d, "start": i, "k": k}
        for b in np.flatnonzero(checked & ~ok):
            t.violate(key, Violation(f.name, d, int(b), k, "decrease", float(ratio[b])))
