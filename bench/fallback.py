"""Theorem 1 on 16-state methods: the search with SCS in its fallback chain
and without it (Clarabel alone, as the interpolation family), interleaved in the same run;
the time spent in SCS, and what SCS answered.

The points the margin search cannot check go to the fallback chain; there SCS (at 1e-9)
ran into its iteration limit or repeated an infeasible verdict. Rates must agree (a
point is certified only by a checked certificate either way)."""

from __future__ import annotations

import collections
import time

import numpy as np

from sosalgo.analysis import analyze_algorithm
from sosalgo.certificates.theorem1 import Theorem1
from sosalgo.kernel import solvers
from sosalgo.model import Algorithm, bind
from sosalgo.spec import load_spec

from .common import one_core, timed

N = 16


class _WithSCS(Theorem1):
    """Theorem 1 with the whole default chain (Clarabel, then SCS) as its fallback."""

    fallback_solvers = None


def padded_nesterov(kappa: float, coupled: bool) -> Algorithm:
    """Nesterov's method (h = 1/L, beta = (sqrt(kappa) - 1)/(sqrt(kappa) + 1)) with 14
    more states: a stable shift register fed by the gradient (``coupled``) or not."""
    beta = (np.sqrt(kappa) - 1) / (np.sqrt(kappa) + 1)
    A = np.zeros((N, N))
    A[:2, :2] = [[0, 1], [-beta, 1 + beta]]
    A[2:, 2:] = 0.5 * np.eye(N - 2, k=-1)
    B = np.zeros((N, 1))
    B[1, 0] = -1 / kappa
    if coupled:
        B[2, 0] = 1.0
    C = np.zeros((1, N))
    C[0, :2] = [-beta, 1 + beta]
    E = np.zeros((1, N))
    E[0, 1] = 1
    return Algorithm(A, B, C, E, 1.0, kappa)


def averaged_gradient(kappa: float) -> Algorithm:
    """Gradient descent (h = 1/L) followed by a chain of 15 averaging states."""
    A = np.zeros((N, N))
    A[0, 0] = 1
    for i in range(1, N):
        A[i, i - 1] = A[i, i] = 0.5
    B = np.zeros((N, 1))
    B[0, 0] = -1 / kappa
    C = np.zeros((1, N))
    C[0, 0] = 1
    return Algorithm(A, B, C, C.copy(), 1.0, kappa)


def momentum_history(kappa: float, seed: int) -> Algorithm:
    """x+ = x + b (x - x_{-1}) - h grad f(y), y a random average of the last 16 iterates."""
    rng = np.random.default_rng(seed)
    A = np.zeros((N, N))
    A[1:, :-1] = np.eye(N - 1)
    b = rng.uniform(0, 0.5)
    A[0, 0], A[0, 1] = 1 + b, -b
    w = rng.dirichlet(np.ones(N)) * 0.3
    w[0] += 1 - w.sum()
    B = np.zeros((N, 1))
    B[0, 0] = -rng.uniform(0.3, 1.0) / kappa
    E = np.zeros((1, N))
    E[0, 0] = 1
    return Algorithm(A, B, w[None, :], E, 1.0, kappa)


class _SCSClock:
    """Time and answers of the SCS calls while installed."""

    def __init__(self) -> None:
        self.seconds, self.answers = 0.0, collections.Counter()
        self._orig = solvers.SOLVERS["scs"]

    def __enter__(self) -> _SCSClock:
        def timed_scs(*args, **kwargs):
            t0 = time.perf_counter()
            out = self._orig(*args, **kwargs)
            self.seconds += time.perf_counter() - t0
            self.answers[out[0]] += 1
            return out
        solvers.SOLVERS["scs"] = timed_scs
        return self

    def __exit__(self, *exc: object) -> None:
        solvers.SOLVERS["scs"] = self._orig


def _cases() -> list[tuple[str, Algorithm]]:
    out = []
    for k in (10.0, 100.0):
        out += [(f"padded Nesterov, k={k:g}", padded_nesterov(k, False)),
                (f"padded Nesterov, gradient-fed, k={k:g}", padded_nesterov(k, True)),
                (f"averaged gradient, k={k:g}", averaged_gradient(k))]
    out += [(f"momentum on 16 iterates #{s}, k=10", momentum_history(10.0, s)) for s in range(3)]
    nest = load_spec(__import__("pathlib").Path(__file__).resolve().parents[1]
                     / "specs" / "nesterov.yaml")
    out.append(("nesterov (2 states), k=10", bind(nest, 10.0)))
    return out


def run(quick: bool = False) -> None:
    repeats = 1 if quick else 3
    with one_core() as core:
        print(f"Theorem 1 with / without SCS in the fallback chain ({core}, median of "
              f"{repeats})")
        print("| method | rho (SCS) | rho (no SCS) | s with SCS | of which SCS | SCS answers "
              "| s without | speed-up |")
        print("|---|---|---|---|---|---|---|---|")
        tot_old = tot_new = 0.0
        for name, alg in _cases():
            with _SCSClock() as clock:
                t_old, old, _ = timed(lambda a=alg: analyze_algorithm(a, family=_WithSCS()),
                                      repeats)
            t_new, new, _ = timed(lambda a=alg: analyze_algorithm(a, family="theorem1"),
                                  repeats)
            tot_old, tot_new = tot_old + t_old, tot_new + t_new
            answers = ", ".join(f"{k} {v}" for k, v in sorted(clock.answers.items())) or "-"
            print(f"| {name} | {_r(old)} | {_r(new)} | {t_old:.2f} | "
                  f"{clock.seconds / repeats:.2f} | {answers} | {t_new:.2f} | "
                  f"{t_old / t_new:.2f}x |", flush=True)
        print(f"| total | | | {tot_old:.2f} | | | {tot_new:.2f} | {tot_old / tot_new:.2f}x |")


def _r(res: object) -> str:
    rho = getattr(res, "rho", None)
    return "-" if rho is None else f"{rho:.7f}"
