"""One execution layer for every batch job (kappa sweeps, grids): serial, local processes
or an existing Dask distributed cluster, with chunking and a progress bar.

A task is a plain dict (e.g. ``{"kappa": 10.0, "h": 0.1}``); ``fn(spec_text, source,
options, chunk)`` is a module-level function that returns one row dict per task. Workers
re-load the spec from its YAML text (cached per process), so nothing unpicklable travels.
Results are handed to ``on_row`` in the parent as each chunk finishes, so the caller can
append them to a resumable CSV at once.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any

__all__ = ["run_batch", "default_workers", "Progress"]

Row = dict[str, Any]
ChunkFn = Callable[[str, str, dict[str, Any], list[dict[str, Any]]], list[Row]]
SERIAL_BELOW = 8  # fewer tasks than this run in-process: pool start-up would dominate


def default_workers() -> int:
    """All cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


class Progress:
    """A one-line progress bar on stderr: count, rate and ETA (silent when disabled)."""

    def __init__(self, total: int, label: str, enabled: bool = True, done: int = 0):
        self.total, self.label, self.enabled = total, label, enabled
        self.count = done
        self.start_count = done
        self.t0 = time.perf_counter()
        self.last = 0.0
        self.tty = sys.stderr.isatty()
        self._draw(force=True)

    def update(self, n: int = 1) -> None:
        self.count += n
        self._draw()

    def _draw(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if not force and now - self.last < (0.2 if self.tty else 5.0) and self.count < self.total:
            return
        self.last = now
        elapsed = now - self.t0
        done_here = self.count - self.start_count
        rate = done_here / elapsed if elapsed > 0 else 0.0
        left = self.total - self.count
        eta = left / rate if rate > 0 else math.inf
        frac = self.count / self.total if self.total else 1.0
        width = 24
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        eta_s = "?" if not math.isfinite(eta) else _fmt_time(eta)
        line = (
            f"{self.label} [{bar}] {self.count}/{self.total} "
            f"{rate:.1f}/s ETA {eta_s}"
        )
        end = "\r" if self.tty and self.count < self.total else "\n"
        sys.stderr.write(line + end)
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.tty and self.count < self.total:
            sys.stderr.write("\n")


def _fmt_time(sec: float) -> str:
    sec = int(round(sec))
    h, rem = divmod(sec, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def _chunks(tasks: Sequence[dict[str, Any]], size: int) -> Iterator[list[dict[str, Any]]]:
    for i in range(0, len(tasks), size):
        yield list(tasks[i : i + size])


def chunk_size(n_tasks: int, workers: int) -> int:
    """Chunks of a few dozen rates keep per-task overhead small, yet balance the load."""
    if workers <= 1:
        return max(1, n_tasks)
    return max(1, min(64, math.ceil(n_tasks / (workers * 8))))


def run_batch(
    fn: ChunkFn,
    spec_text: str,
    source: str,
    options: dict[str, Any],
    tasks: Sequence[dict[str, Any]],
    on_row: Callable[[Row], None],
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Progress | None = None,
) -> None:
    """Run ``fn`` over ``tasks`` and hand each resulting row to ``on_row`` as it finishes."""
    if not tasks:
        return
    workers = default_workers() if workers is None else max(1, workers)

    def deliver(rows: list[Row]) -> None:
        for row in rows:
            on_row(row)
        if progress is not None:
            progress.update(len(rows))

    if scheduler:
        _run_dask(fn, spec_text, source, options, tasks, deliver, scheduler)
        return
    if workers == 1 or len(tasks) < SERIAL_BELOW:
        for task in tasks:
            deliver(fn(spec_text, source, options, [task]))
        return
    size = chunk_size(len(tasks), workers)
    with ProcessPoolExecutor(max_workers=workers) as pool:
        pending: set[Future] = set()
        chunks = _chunks(tasks, size)
        for chunk in chunks:
            pending.add(pool.submit(fn, spec_text, source, options, chunk))
            if len(pending) >= workers * 2:
                break
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                deliver(fut.result())
            for chunk in chunks:
                pending.add(pool.submit(fn, spec_text, source, options, chunk))
                if len(pending) >= workers * 2:
                    break


def _run_dask(fn, spec_text, source, options, tasks, deliver, address: str) -> None:
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise RuntimeError(
            "--scheduler needs dask.distributed: pip install 'sosalgo[dist]'"
        ) from exc
    with Client(address, timeout="20s") as client:
        nworkers = max(1, len(client.scheduler_info().get("workers", {})))
        size = chunk_size(len(tasks), nworkers)
        futures = [
            client.submit(fn, spec_text, source, options, chunk, pure=False)
            for chunk in _chunks(tasks, size)
        ]
        for fut in as_completed(futures):
            deliver(fut.result())
