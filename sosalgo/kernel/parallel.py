"""Local process pools that never fork the caller, and maps over them until a deadline.

A process that has run a solve holds Clarabel's solver threads, and a forked copy of it
deadlocks in the solver: workers come from a fork server (started fresh, with the modules
of ``preload`` imported) or are spawned, and die with their parent. :func:`map_until` runs
a function over items on such a pool and never waits for a task past its deadline;
a pool's workers send the phases of their tasks (:mod:`sosalgo.kernel.phases`) on a relay
queue to the process that runs the pool.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from sosalgo.kernel.phases import set_sink

if TYPE_CHECKING:  # pragma: no cover - imported where a pool is started
    from concurrent.futures import ProcessPoolExecutor

__all__ = ["PRELOAD", "default_workers", "kill_pool", "map_until", "pool_context", "quietly",
           "set_chunk", "start_pool_server", "worker_pool"]

# imported once by a fork server that no caller gave its own list, so that a worker
# starts in milliseconds
PRELOAD = ("clarabel",)
_RELAY: Any = None  # in a pool's worker: the queue to the bar of the process that runs it
_CHUNK: int | None = None  # in a pool's worker: the number of the chunk it runs


def default_workers() -> int:
    """All cores this process may use."""
    from sosalgo.kernel.budget import cores

    return cores()


def set_chunk(number: int | None) -> None:
    """In a pool's worker: the chunk it runs now (its phases are sent labelled with it)."""
    global _CHUNK
    _CHUNK = number


def quietly(fn: Callable[..., Any], *args: Any) -> Any:
    """``fn(*args)`` with numpy's floating-point warnings off: an overflow or a NaN shows in
    the results (a point with non-finite data is not certified, the solvers are never given
    such data), not as stray lines on stderr."""
    import warnings

    import numpy as np

    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return fn(*args)


def pool_context(preload: Sequence[str] = PRELOAD):
    """The multiprocessing context of every local pool: a fork server (a fresh process with
    ``preload`` imported, forked for each worker) where available, else spawn. Never a
    fork of the caller, whose solver threads (Clarabel's thread pool, started by the first
    solve) a forked worker would inherit without the threads: it deadlocks in the solver."""
    import multiprocessing as mp

    _start_tracker_quietly()
    if "forkserver" in mp.get_all_start_methods():
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(list(preload))  # read when the server starts (once)
        return ctx
    return mp.get_context("spawn")  # pragma: no cover - platforms without a fork server


def _start_tracker_quietly() -> None:
    """Start multiprocessing's resource tracker (it unlinks a pool's named semaphores when
    the run is killed) with its stderr on /dev/null: its note about them is no error."""
    from multiprocessing import resource_tracker

    if getattr(resource_tracker._resource_tracker, "_fd", None) is not None:
        return  # already running
    _without_stderr(resource_tracker.ensure_running)


def _without_stderr(start: Callable[[], Any]) -> None:
    """Run ``start`` (which starts a helper process) with file descriptor 2 on /dev/null,
    so that the helper and what it forks inherit a silent stderr."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 2)
        os.close(null)
        start()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def start_pool_server(preload: Sequence[str] = PRELOAD) -> None:
    """Start the fork server now (once per process): it imports ``preload`` while the
    caller goes on, so that a pool started later has its workers at once."""
    import multiprocessing.forkserver as fs

    if pool_context(preload).get_start_method() == "forkserver":
        # silent stderr: a worker being forked while a killed run exits fails to open the
        # pool's unlinked semaphore and would print that (task errors travel by futures,
        # and workers' warnings are silenced anyway)
        _without_stderr(fs.ensure_running)


def worker_pool(workers: int, preload: Sequence[str] = PRELOAD, relay: Any = None
                ) -> ProcessPoolExecutor:
    """A process pool of ``workers`` safely started workers that die with their parent
    (never more than the cores and the memory budget allow: :mod:`sosalgo.kernel.budget`);
    its fork server, when it starts now, imports ``preload``. Stop it with ``shutdown``
    when its work is done, else with :func:`kill_pool`. ``relay``: a queue of the pool's
    context on which the workers' phases are sent."""
    from concurrent.futures import ProcessPoolExecutor

    from sosalgo.kernel.budget import usable_workers

    ctx = pool_context(preload)
    start_pool_server(preload)  # started quietly (no-op when it runs already)
    return ProcessPoolExecutor(max_workers=usable_workers(workers), mp_context=ctx,
                               initializer=_start_worker, initargs=(relay,))


def _start_worker(relay: Any) -> None:
    """Pool initializer: die with the parent; send the phases of the tasks it runs on
    ``relay`` (never waited for at exit: a message the parent no longer reads is dropped)."""
    global _RELAY
    _die_with_parent()
    if relay is not None:
        relay.cancel_join_thread()
        _RELAY = relay
        set_sink(_to_relay)


def _to_relay(task: str | None, name: str | None, detail: str) -> None:
    """A worker's sink of :mod:`sosalgo.kernel.phases`: the phase of a named task, with the
    number of its chunk, to the process that runs the pool."""
    if task is None or _RELAY is None:
        return
    try:
        _RELAY.put_nowait((_CHUNK, task, name, detail))
    except (OSError, ValueError):  # the run is ending: the bar is gone
        pass


def _die_with_parent() -> None:
    """Pool initializer: the worker ends when the process that started the pool is gone,
    even by SIGKILL, busy or idle (a thread waits on its multiprocessing sentinel; a fork
    server's worker is not that process's child, so a parent-death signal alone would wait
    for the server); Ctrl-C is left to that process."""
    import multiprocessing
    import signal
    import threading

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # ends the worker (kill_pool)
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # pragma: no cover - not Linux/glibc
        pass
    parent = multiprocessing.parent_process()
    if parent is not None and parent.sentinel is not None:
        threading.Thread(target=_exit_when_gone, args=(parent.sentinel,), daemon=True).start()
    if os.getppid() == 1:  # the parent died before prctl took effect
        os._exit(1)


def _exit_when_gone(sentinel: int) -> None:
    """End this worker at once when ``sentinel`` (the pool owner's) shows it has exited."""
    from multiprocessing.connection import wait

    wait([sentinel])
    os._exit(1)


def map_until(fn: Callable[[Any], Any], items: Sequence[Any], workers: int,
              deadline: float, grace: float = 1.0, preload: Sequence[str] = PRELOAD
              ) -> tuple[list[Any], list[BaseException]]:
    """``fn(item)`` for every item on a pool of ``workers`` processes, waited for until the
    wall-clock time ``deadline`` (``time.time()``) plus ``grace`` seconds. Returns the
    results (None for an item not finished or failed) and the exceptions raised; a pool
    with tasks still running is killed, never waited for."""
    from concurrent.futures import wait

    out: list[Any] = [None] * len(items)
    errors: list[BaseException] = []
    pool = worker_pool(workers, preload)
    finished = False
    try:
        futs = [pool.submit(fn, item) for item in items]
        done, rest = wait(futs, timeout=max(0.0, deadline - time.time()) + grace)
        for i, f in enumerate(futs):
            if f in done and f.exception() is None:
                out[i] = f.result()
            elif f in done:
                errors.append(f.exception())
        finished = not rest
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:
            kill_pool(pool)  # interrupted, or tasks running past the deadline
    return out, errors


def kill_pool(pool: ProcessPoolExecutor) -> None:
    """Terminate the pool's worker processes and drop queued work (running tasks are
    lost): for an interrupted run or a time limit, never waiting for a busy worker."""
    procs = list(getattr(pool, "_processes", {}).values())
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        proc.join(timeout=5)
