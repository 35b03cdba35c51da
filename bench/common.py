"""Helpers shared by the benchmark suites: timing with repeats, pinning to one core."""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager


def timed(fn: Callable[[], object], repeats: int) -> tuple[float, object, float]:
    """(median seconds, last result, minimum seconds) of ``repeats`` calls."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out, min(times)


@contextmanager
def one_core() -> Iterator[str]:
    """Pin the process to one core for the block; yields a label for the table."""
    try:
        saved = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {sorted(saved)[0]})
        label = "one core (pinned)"
    except (AttributeError, OSError):
        saved, label = None, "unpinned"
    try:
        yield label
    finally:
        if saved is not None:
            os.sched_setaffinity(0, saved)


def bisect_rate(feasible: Callable[[float], bool], tol: float) -> float | None:
    """The baselines' plain bisection on rho in [0, 1] (None if rho = 1 is infeasible)."""
    if not feasible(1.0):
        return None
    lo, hi = 0.0, 1.0
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if feasible(mid):
            hi = mid
        else:
            lo = mid
    return hi
