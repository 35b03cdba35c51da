"""One execution layer for every batch job (kappa sweeps, grids): serial, local processes
or an existing Dask distributed cluster, with chunking and a progress bar.

A task is a plain dict (e.g. ``{"kappa": 10.0, "h": 0.1}``); ``fn(spec_text, source,
options, chunk)`` is a module-level function that returns one row dict per task. Workers
re-load the spec from its YAML text (cached per process), so nothing unpicklable travels.
Results are handed to ``on_row`` in the parent as each chunk finishes, so the caller can
append them to a resumable CSV at once.

Local pools (:func:`worker_pool`, also used by ``design``) never fork the calling process:
a process that has run a solve holds Clarabel's solver threads, and a forked copy of it
deadlocks in the solver. Workers come from a fork server (started fresh, with sosalgo's
modules preloaded) or are spawned, and die with their parent.
"""

from __future__ import annotations

import gc
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

from sosalgo.errors import InputError

if TYPE_CHECKING:  # pragma: no cover - imported where a pool is started
    from concurrent.futures import Future, ProcessPoolExecutor

__all__ = ["BatchError", "Progress", "check_scheduler", "default_workers", "kill_pool",
           "map_until", "note", "pool_context", "quietly", "run_batch", "show_phase",
           "start_pool_server", "worker_pool"]

Row = dict[str, Any]
ChunkFn = Callable[[str, str, dict[str, Any], list[dict[str, Any]]], list[Row]]
SERIAL_BELOW = 8  # fewer tasks than this run in-process: pool start-up would dominate
CONNECT_TIMEOUT = float(os.environ.get("SOSALGO_CONNECT_TIMEOUT", "20"))  # seconds
NO_WORKER_TIMEOUT = float(os.environ.get("SOSALGO_NO_WORKER_TIMEOUT", "120"))
# imported once by the fork server, so that a worker starts in milliseconds
PRELOAD = ("sosalgo.batch.sweeps", "clarabel")


class BatchError(InputError):
    """The execution environment cannot run the batch (Dask missing, scheduler unreachable,
    no workers left): one line, exit code 2."""


def default_workers() -> int:
    """All cores this process may use."""
    from sosalgo.budget import cores

    return cores()


class Progress:
    """A one-line progress bar on stderr: count, rate, ETA and what the running task is
    doing (:func:`show_phase`); silent when disabled. ``done`` rows were read back from
    ``resumed_from`` (a saved file): said once, on its own line."""

    def __init__(self, total: int, label: str, enabled: bool = True, done: int = 0,
                 resumed_from: str | os.PathLike | None = None):
        global _ACTIVE
        self.total, self.label, self.enabled = total, label, enabled
        self.count = done
        self.start_count = done
        self.t0 = time.perf_counter()
        self.last = 0.0
        self.tty = sys.stderr.isatty()
        self.phase_name: str | None = None
        self.phase_detail = ""
        self.width = 0  # length of the line on screen (a tty line is overwritten)
        if enabled:
            _ACTIVE = self
            if done:
                where = f" from {resumed_from}" if resumed_from is not None else ""
                sys.stderr.write(f"resumed: {done} of {total} rows read{where}\n")
        self._draw(force=True)

    def update(self, n: int = 1) -> None:
        self.count += n
        self._draw()

    def phase(self, name: str | None, detail: str = "") -> None:
        """Show what is running now (``name``, e.g. "grid") and how far it is (``detail``):
        a new name is drawn at once, a new detail at the bar's usual pace."""
        changed = name != self.phase_name
        self.phase_name, self.phase_detail = name, detail
        self._draw(force=changed)

    def _line(self) -> str:
        elapsed = time.perf_counter() - self.t0
        rate = (self.count - self.start_count) / elapsed if elapsed > 0 else 0.0
        left = self.total - self.count
        eta = 0.0 if left <= 0 else left / rate if rate > 0 else math.inf
        frac = self.count / self.total if self.total else 1.0
        width = 24
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        eta_s = "?" if not math.isfinite(eta) else _fmt_time(eta)
        line = f"{self.label} [{bar}] {self.count}/{self.total} {rate:.1f}/s ETA {eta_s}"
        if self.phase_name and self.count < self.total:
            detail = f" {self.phase_detail}" if self.phase_detail else ""
            line += f" | {self.phase_name}{detail} ({_fmt_time(elapsed)} elapsed)"
        return line

    def _draw(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if not force and now - self.last < (0.2 if self.tty else 5.0) and self.count < self.total:
            return
        self.last = now
        line = self._line()
        end = "\r" if self.tty and self.count < self.total else "\n"
        pad = " " * max(0, self.width - len(line)) if self.tty else ""
        self.width = len(line) if end == "\r" else 0
        sys.stderr.write(line + pad + end)
        sys.stderr.flush()

    def close(self) -> None:
        global _ACTIVE
        if _ACTIVE is self:
            _ACTIVE = None
        if self.enabled and self.tty and self.count < self.total:
            sys.stderr.write("\n")


_ACTIVE: Progress | None = None  # this process's bar, which :func:`show_phase` reaches


def note(msg: str) -> None:
    """Print ``msg`` on its own line of stderr; on a terminal, this process's progress bar
    is cleared first and drawn again below it (a message never runs into the bar)."""
    bar = _ACTIVE
    clear = bar is not None and bar.enabled and bar.tty and bar.width
    sys.stderr.write(("\r" + " " * bar.width + "\r" if clear else "") + msg + "\n")
    sys.stderr.flush()
    if clear:
        bar.width = 0
        bar._draw(force=True)


def show_phase(name: str | None, detail: str = "") -> None:
    """Tell this process's progress bar what the running task is doing (a no-op without
    a bar, e.g. in a pool's worker: only a task run in the bar's process shows phases)."""
    if _ACTIVE is not None:
        _ACTIVE.phase(name, detail)


def _fmt_time(sec: float) -> str:
    sec = int(round(sec))
    h, rem = divmod(sec, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def _chunks(tasks: Sequence[dict[str, Any]], size: int) -> Iterator[list[dict[str, Any]]]:
    for i in range(0, len(tasks), size):
        yield list(tasks[i : i + size])


def chunk_size(n_tasks: int, workers: int, largest: int = 64) -> int:
    """Chunks of a few dozen rates keep per-task overhead small, yet balance the load;
    at least eight chunks per worker (one worker too), so that rows reach the file as
    chunks finish and a lost worker loses one chunk. ``largest``: the job's own cap
    (``fn.max_chunk``: 1 for jobs whose tasks take seconds or more)."""
    return max(1, min(largest, math.ceil(n_tasks / (max(1, workers) * 8))))


def _largest_chunk(fn: ChunkFn) -> int:
    return int(getattr(fn, "max_chunk", 64))


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
    isolate: bool = False,
) -> None:
    """Run ``fn`` over ``tasks`` and hand each resulting row to ``on_row`` as it finishes.
    ``isolate``: every task runs in a worker process, one task per chunk, even a single
    one (a long native solve then never delays SIGTERM or Ctrl-C in this process: the
    worker is killed, the finished rows are kept)."""
    if not tasks:
        return
    from sosalgo.budget import usable_workers

    workers = usable_workers(workers)

    def deliver(rows: list[Row]) -> None:
        for row in rows:
            on_row(row)
        if progress is not None:
            progress.update(len(rows))

    if scheduler:
        _run_dask(fn, spec_text, source, options, tasks, deliver, scheduler)
        return
    if not isolate and (workers == 1 or len(tasks) < SERIAL_BELOW):
        for task in tasks:
            deliver(quietly(fn, spec_text, source, options, [task]))
        return
    from concurrent.futures import FIRST_COMPLETED, wait

    workers = min(workers, len(tasks)) if isolate else workers
    size = 1 if isolate else chunk_size(len(tasks), workers, _largest_chunk(fn))
    if progress is not None:
        progress.phase(f"starting {workers} workers")
    pool = worker_pool(workers)
    try:
        pending: set[Future] = set()
        chunks = _chunks(tasks, size)
        for chunk in chunks:
            pending.add(pool.submit(quietly, fn, spec_text, source, options, chunk))
            if len(pending) >= workers * 2:
                break
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            if progress is not None and progress.phase_name:
                progress.phase(None)  # the workers run: the count says it from now on
            for fut in finished:
                deliver(fut.result())
            for chunk in chunks:
                pending.add(pool.submit(quietly, fn, spec_text, source, options, chunk))
                if len(pending) >= workers * 2:
                    break
    except BaseException:
        kill_pool(pool)  # interrupted or failed: do not wait for (or leave) running workers
        raise
    pool.shutdown(wait=True)


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


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """A process pool of ``workers`` safely started workers that die with their parent
    (never more than the cores and the memory budget allow: :mod:`sosalgo.budget`).
    Stop it with ``shutdown`` when its work is done, else with :func:`kill_pool`."""
    from concurrent.futures import ProcessPoolExecutor

    from sosalgo.budget import usable_workers

    ctx = pool_context()
    start_pool_server()  # started quietly (no-op when it runs already)
    return ProcessPoolExecutor(max_workers=usable_workers(workers), mp_context=ctx,
                               initializer=_die_with_parent)


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
              deadline: float, grace: float = 1.0) -> tuple[list[Any], list[BaseException]]:
    """``fn(item)`` for every item on a pool of ``workers`` processes, waited for until the
    wall-clock time ``deadline`` (``time.time()``) plus ``grace`` seconds. Returns the
    results (None for an item not finished or failed) and the exceptions raised; a pool
    with tasks still running is killed, never waited for."""
    from concurrent.futures import wait

    out: list[Any] = [None] * len(items)
    errors: list[BaseException] = []
    pool = worker_pool(workers)
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


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise BatchError("--scheduler needs Dask distributed, which is not installed: "
                         "pip install 'sosalgo[dist]'") from None
    return distributed


def _connect(address: str):
    """A Dask client for ``address``, or a one-line BatchError."""
    distributed = _import_distributed()
    if not isinstance(address, str) or "://" not in address and ":" not in address:
        raise BatchError(f"--scheduler {address}: not a scheduler address "
                         "(e.g. tcp://host:8786)")
    _probe_scheduler(address)
    try:
        return distributed.Client(address, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError, TypeError, MemoryError) as exc:
        msg = " ".join(str(exc).split())[:200] or type(exc).__name__
    # The half-built Client closes itself when it is garbage collected. Collect it now: left
    # to chance, that can happen while another Dask event loop is starting in this thread,
    # and distributed then deadlocks on its own loop lock.
    gc.collect()
    raise BatchError(f"--scheduler {address}: cannot connect ({msg})")


HANDSHAKE_TIMEOUT = min(CONNECT_TIMEOUT, 5.0)  # seconds for the scheduler's first bytes
MAX_HANDSHAKE_BYTES = 1 << 20  # a scheduler's handshake is a few hundred bytes


def _probe_scheduler(address: str) -> None:
    """For a TCP address: BatchError unless the server there greets like a Dask scheduler.

    A Dask listener writes its handshake as soon as a connection is accepted, prefixed by
    its length (8 bytes). Another server (HTTP, SSH, ...) sends nothing or text, which Dask
    would read as a length in the exabytes and try to allocate; so the first 8 bytes are
    read here, with a timeout, and must announce a small message."""
    import socket
    import struct

    scheme, _, rest = address.rpartition("://")
    if scheme not in ("", "tcp"):
        return  # tls://, ws://, ...: left to Dask
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise BatchError(f"--scheduler {address}: not a scheduler address "
                         "(e.g. tcp://host:8786)")
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT) as sock:
            sock.settimeout(HANDSHAKE_TIMEOUT)
            head = b""
            while len(head) < 8:
                chunk = sock.recv(8 - len(head))
                if not chunk:
                    break
                head += chunk
    except TimeoutError:
        raise BatchError(f"--scheduler {address}: no Dask handshake within "
                         f"{HANDSHAKE_TIMEOUT:g} s (is this a Dask scheduler's address?)") from None
    except (OSError, UnicodeError, ValueError) as exc:
        msg = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise BatchError(f"--scheduler {address}: cannot connect ({msg})") from None
    size = struct.unpack("Q", head)[0] if len(head) == 8 else 0
    if not 0 < size <= MAX_HANDSHAKE_BYTES:
        raise BatchError(f"--scheduler {address}: the server there does not speak the Dask "
                         f"protocol (its first bytes: {head[:8]!r})")


def check_scheduler(address: str | None) -> None:
    """Connect once (then disconnect): Dask installed, address well formed and reachable
    (None: no scheduler, nothing to check), before anything is written."""
    if address:
        client = _connect(address)
        client.close()


def _run_dask(fn, spec_text, source, options, tasks, deliver, address: str) -> None:
    """Run the chunks on a Dask cluster. Fails with a BatchError (finished rows are kept)
    when the scheduler goes away or no worker has been connected for NO_WORKER_TIMEOUT s."""
    import asyncio
    import concurrent.futures
    import logging

    distributed = _import_distributed()
    # the client logs reconnection tracebacks itself; our one-line error says it all
    for name in ["distributed", *logging.root.manager.loggerDict]:
        if name.startswith("distributed"):
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
    client = _connect(address)
    lost = (OSError, TimeoutError, distributed.comm.CommClosedError,
            concurrent.futures.CancelledError, asyncio.CancelledError)

    def failed(exc: BaseException) -> BatchError:
        msg = ("the scheduler connection was cancelled"
               if isinstance(exc, concurrent.futures.CancelledError | asyncio.CancelledError)
               else " ".join(str(exc).split())[:160] or type(exc).__name__)
        return BatchError(f"--scheduler {address}: connection lost ({msg}); finished rows "
                          "are saved, rerun to resume")

    try:
        nworkers = max(1, len(client.scheduler_info().get("workers", {})))
        size = chunk_size(len(tasks), nworkers, _largest_chunk(fn))
        pending = {
            client.submit(quietly, fn, spec_text, source, options, chunk, pure=False)
            for chunk in _chunks(tasks, size)
        }
        idle_since: float | None = None
        while pending:
            try:
                done, pending = distributed.wait(pending, timeout=2.0,
                                                 return_when="FIRST_COMPLETED")
            except TimeoutError:
                done = set()
            except lost as exc:
                raise failed(exc) from None
            for fut in done:
                if fut.status == "error":  # the task itself raised: a bug, not the cluster
                    fut.result()
                try:
                    rows = fut.result()
                except lost as exc:
                    raise failed(exc) from None
                deliver(rows)
            if not pending:
                break
            try:
                idle_since = _watch_workers(client, address, idle_since)
            except lost as exc:
                raise failed(exc) from None
    finally:
        try:
            client.close(timeout=5)
        except lost:
            pass


def _watch_workers(client: Any, address: str, idle_since: float | None) -> float | None:
    """Track how long the cluster has had no worker; fail after NO_WORKER_TIMEOUT s."""
    if client.status not in ("running", "connecting"):
        raise BatchError(f"--scheduler {address}: the scheduler went away; finished rows "
                         "are saved, rerun to resume")
    if client.scheduler_info().get("workers"):
        return None
    now = time.monotonic()
    if idle_since is None:
        sys.stderr.write(f"note: the cluster at {address} has no workers; waiting up to "
                         f"{NO_WORKER_TIMEOUT:g} s for one to join\n")
        return now
    if now - idle_since > NO_WORKER_TIMEOUT:
        raise BatchError(f"--scheduler {address}: no workers for {NO_WORKER_TIMEOUT:g} s; "
                         "finished rows are saved, rerun to resume")
    return idle_since
