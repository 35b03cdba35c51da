"""One execution layer for every batch job (kappa sweeps, grids): serial, local processes
or an existing Dask distributed cluster, with chunking and a progress bar.

A task is a plain dict (e.g. ``{"kappa": 10.0, "h": 0.1}``); ``fn(spec_text, source,
options, chunk)`` is a module-level function that returns one row dict per task. Workers
re-load the spec from its YAML text (cached per process), so nothing unpicklable travels.
Results are handed to ``on_row`` in the parent as each chunk finishes, so the caller can
append them to a resumable CSV at once.

Local pools are the kernel's (:func:`sosalgo.kernel.parallel.worker_pool`, also used by
``design``): they never fork the calling process (a process that has run a solve holds
Clarabel's solver threads, and a forked copy of it deadlocks in the solver). Workers come
from a fork server (started fresh, with the sweeps' modules preloaded) or are spawned, and
die with their parent; they send their tasks' phases to the bar on a relay queue.
"""

from __future__ import annotations

import gc
import itertools
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

from sosalgo.errors import InputError
from sosalgo.kernel.parallel import kill_pool, pool_context, quietly, set_chunk, worker_pool
from sosalgo.kernel.phases import begin_task, set_sink

if TYPE_CHECKING:  # pragma: no cover - imported where a pool is started
    from concurrent.futures import Future, ProcessPoolExecutor

__all__ = ["BatchError", "Progress", "check_scheduler", "note", "run_batch"]

Row = dict[str, Any]
ChunkFn = Callable[[str, str, dict[str, Any], list[dict[str, Any]]], list[Row]]
SERIAL_BELOW = 8  # fewer tasks than this run in-process: pool start-up would dominate
CONNECT_TIMEOUT = float(os.environ.get("SOSALGO_CONNECT_TIMEOUT", "20"))  # seconds
NO_WORKER_TIMEOUT = float(os.environ.get("SOSALGO_NO_WORKER_TIMEOUT", "120"))
# imported once by the fork server of a sweep's pool, so that a worker starts in milliseconds
PRELOAD = ("sosalgo.batch.sweeps", "clarabel")


class BatchError(InputError):
    """The execution environment cannot run the batch (Dask missing, scheduler unreachable,
    no workers left): one line, exit code 2."""


class Progress:
    """Progress of a batch on stderr, drawn by :mod:`rich`; silent when disabled.

    On a terminal: one live line (label, bar, count, elapsed time, ETA, and what the
    running tasks are doing, :mod:`sosalgo.kernel.phases`, also in pool workers). Elsewhere (a
    log file, CI): plain lines, one per finished row (at most one every ``PLAIN_SECONDS``,
    and the last) and one per new phase, ``LABEL | PHASE DETAIL`` (a named task's phase
    once it has lasted ``PLAIN_SECONDS``). ``done`` rows were read back from
    ``resumed_from`` (a saved file): said once, on its own line. ``lazy``: nothing is shown
    before the first phase or row (a command that may still refuse its input then says
    one line, its error)."""

    def __init__(self, total: int, label: str, enabled: bool = True, done: int = 0,
                 resumed_from: str | os.PathLike | None = None, lazy: bool = False):
        global _ACTIVE
        self.total, self.label, self.enabled = total, label, enabled
        self.count = done
        self.t0 = time.perf_counter()
        self.phases: dict[Any, tuple[str, str, float]] = {}  # source -> (name, detail, since)
        self.said: dict[Any, tuple[str, float]] = {}  # plain mode: source -> (phase, when)
        self.row_said, self.row_shown = 0.0, done  # plain mode: the last count said
        self.early: dict[int, int] = {}  # chunk -> rows finished in a worker, not delivered
        self.console = _console()
        self.tty = self.console.is_terminal
        self.live: Any = None
        self.previous_sink: Any = None
        if not enabled:
            return
        _ACTIVE = self
        self.previous_sink = set_sink(self._from_task)
        if done:
            where = f" from {resumed_from}" if resumed_from is not None else ""
            self._say(f"resumed: {done} of {total} rows read{where}")
        self.started = done >= total  # nothing left to show: no bar
        if not lazy:
            self._start()

    def _start(self) -> None:
        """The live bar on a terminal, else the first plain line."""
        if self.started:
            return
        self.started = True
        if self.tty:
            self.live = _live_bar(self.console, self.label, self.total)
            self.task = self.live.add_task(self.label, total=self.total, completed=self.count,
                                           phase="")
            self.live.start()
        else:
            self._say(f"{self.label}: {self.count}/{self.total} rows")

    def _from_task(self, task: str | None, name: str | None, detail: str) -> None:
        """The sink of :mod:`sosalgo.kernel.phases` while this bar is shown."""
        self.phase(name, detail, source=task)

    def update(self, n: int = 1) -> None:
        """``n`` more rows were delivered."""
        self.count += n
        self._show_count()

    def finished_early(self, chunk: int) -> None:
        """A row of ``chunk`` finished in a worker (its rows arrive when the chunk ends)."""
        self.early[chunk] = self.early.get(chunk, 0) + 1
        self._show_count()

    def settle(self, chunks: set[int]) -> None:
        """These chunks are delivered: their rows count through :meth:`update` now."""
        for c in chunks & self.early.keys():
            del self.early[c]

    def _show_count(self) -> None:
        shown = min(self.total, self.count + sum(self.early.values()))
        if not self.enabled:
            return
        self._start()
        if self.live is not None:
            self.live.update(self.task, completed=shown)
            return
        now = time.perf_counter()
        if shown != self.row_shown and (shown >= self.total
                                        or now - self.row_said >= PLAIN_SECONDS):
            self.row_said, self.row_shown = now, shown
            self._say(f"{self.label}: {shown}/{self.total} rows "
                      f"({_fmt_time(now - self.t0)} elapsed)")

    def phase(self, name: str | None, detail: str = "", source: Any = None) -> None:
        """Show what a running task is doing now (``name``, e.g. "grid") and how far it is
        (``detail``); ``source``: which task (a worker's label; None: this process's);
        ``name=None``: it is done."""
        old = self.phases.get(source)
        if name is None:
            self.phases.pop(source, None)
            self.said.pop(source, None)
        else:
            since = old[2] if old and old[0] == name else time.perf_counter()
            self.phases[source] = (name, detail, since)
        if not self.enabled:
            return
        self._start()
        if self.live is not None:  # a new phase is drawn at once, a new detail in time
            self.live.update(self.task, phase=self._phase_text(),
                             refresh=name is not None and (old is None or old[0] != name))
        elif name is not None and source is None:
            self._say_phase(source, name, detail)
        else:
            self.tick()

    def tick(self) -> None:
        """Plain mode: say the workers' phases that have lasted ``PLAIN_SECONDS`` (a short
        one is not worth a line in a log); on a terminal, refresh their clocks."""
        if not self.enabled:
            return
        if self.live is not None:
            self.live.update(self.task, phase=self._phase_text())
            return
        now = time.perf_counter()
        for source, (name, detail, since) in list(self.phases.items()):
            if source is not None and now - since >= PLAIN_SECONDS:
                self._say_phase(source, name, detail)

    def _phase_text(self) -> str:
        now = time.perf_counter()
        parts = [f"{f'{src}: ' if src is not None else ''}{name} ({_fmt_time(now - since)})"
                 f"{f' {detail}' if detail else ''}"  # a narrow screen cuts the detail
                 for src, (name, detail, since) in self.phases.items()]
        more = f" (+{len(parts) - 2} more)" if len(parts) > 2 else ""
        return ("| " + " | ".join(parts[:2]) + more) if parts else ""

    def _say_phase(self, source: Any, name: str, detail: str) -> None:
        """Plain mode: a line for a new phase at once, for a new detail now and then."""
        last, when = self.said.get(source, (None, -math.inf))
        now = time.perf_counter()
        if name != last or now - when >= PLAIN_PHASE_SECONDS:
            self.said[source] = (name, now)
            self._say(f"{self.label} | {f'{source}: ' if source is not None else ''}{name}"
                      f"{f' {detail}' if detail else ''}")

    def _say(self, msg: str) -> None:
        if self.live is not None:
            self.live.console.print(msg, markup=False, highlight=False, soft_wrap=True)
        else:
            sys.stderr.write(msg + "\n")
            sys.stderr.flush()

    def close(self) -> None:
        global _ACTIVE
        if _ACTIVE is self:
            _ACTIVE = None
            set_sink(self.previous_sink)
        if self.live is not None:
            self.live.update(self.task, phase="")
            self.live.stop()
            self.live = None


PLAIN_SECONDS = 2.0  # plain mode: at most one "rows done" line this often (and the last)
PLAIN_PHASE_SECONDS = 10.0  # plain mode: a phase's new detail at most this often
_ACTIVE: Progress | None = None  # this process's bar (where notes go above it)


def _console() -> Any:
    """A rich console on stderr (a terminal or not: rich decides, e.g. from TTY_COMPATIBLE)."""
    from rich.console import Console

    return Console(stderr=True)


def _live_bar(console: Any, label: str, total: int) -> Any:
    """rich's live progress display with our columns (stdout untouched; other lines
    written to stderr while it runs appear above it). On a narrow terminal the phase
    text is cut, never the label, the count or the times."""
    from rich import progress as rp
    from rich.table import Column

    widths = [len(label), 16, 2 * len(str(total)) + 1, 7, 3, 7]
    fixed = [Column(no_wrap=True, min_width=w) for w in widths]
    room = max(10, console.width - sum(widths) - len(widths))  # what the phase may take
    return rp.Progress(rp.TextColumn("{task.description}", table_column=fixed[0]),
                       rp.BarColumn(bar_width=16, table_column=fixed[1]),
                       rp.MofNCompleteColumn(table_column=fixed[2]),
                       rp.TimeElapsedColumn(table_column=fixed[3]),
                       rp.TextColumn("ETA", table_column=fixed[4]),
                       rp.TimeRemainingColumn(table_column=fixed[5]),
                       rp.TextColumn("{task.fields[phase]}",
                                     table_column=Column(no_wrap=True, overflow="ellipsis",
                                                         max_width=room)),
                       console=console, redirect_stdout=False, redirect_stderr=True,
                       refresh_per_second=5)


def note(msg: str) -> None:
    """Print ``msg`` on its own line of stderr (above the live progress bar, if any)."""
    bar = _ACTIVE
    if bar is not None and bar.live is not None:
        bar._say(msg)
        return
    sys.stderr.write(msg + "\n")
    sys.stderr.flush()


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
    from sosalgo.kernel.budget import usable_workers

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
            try:
                rows = quietly(fn, spec_text, source, options, [task])
            finally:
                begin_task(None)  # what the task did ends with it
            deliver(rows)
        return
    workers = min(workers, len(tasks)) if isolate else workers
    size = 1 if isolate else chunk_size(len(tasks), workers, _largest_chunk(fn))
    if progress is not None:
        progress.phase(f"starting {workers} workers")
    relay = pool_context(PRELOAD).Queue()  # the workers' phases, for this process's bar
    pool = worker_pool(workers, PRELOAD, relay)
    try:
        _run_pool(pool, relay, (fn, spec_text, source, options), _chunks(tasks, size),
                  2 * workers, deliver, progress)
    except BaseException:
        kill_pool(pool)  # interrupted or failed: do not wait for (or leave) running workers
        raise
    finally:
        relay.close()
    pool.shutdown(wait=True)


def _run_pool(pool: ProcessPoolExecutor, relay: Any, job: tuple, chunks: Iterator[list],
              ahead: int, deliver: Callable[[list[Row]], None],
              progress: Progress | None) -> None:
    """Keep ``ahead`` chunks of ``job`` submitted; deliver each as it finishes; meanwhile
    show what the workers are doing (their phases arrive on ``relay``)."""
    from concurrent.futures import FIRST_COMPLETED, wait

    pending: dict[Future, int] = {}  # chunk -> its number (the workers' messages name it)
    done: set[int] = set()
    started = False
    numbers = itertools.count()
    while True:
        for chunk in chunks:
            number = next(numbers)
            pending[pool.submit(_run_chunk_relayed, *job, chunk, number)] = number
            if len(pending) >= ahead:
                break
        if not pending:
            return
        finished, _ = wait(pending, timeout=RELAY_SECONDS, return_when=FIRST_COMPLETED)
        messages = _drain(relay)
        if progress is not None:
            if not started and (finished or messages):
                started = True
                progress.phase(None)  # the workers run: they say what they do from now on
            _show_workers(progress, messages, done)
        for fut in finished:
            done.add(pending.pop(fut))
            if progress is not None:
                progress.settle(done)
            deliver(fut.result())


def _show_workers(progress: Progress, messages: list[tuple], done: set[int]) -> None:
    """The workers' phases on the bar; a task's end (its phase None) counts its row at once,
    before its chunk's rows arrive (unless that chunk was delivered already)."""
    for number, label, name, detail in messages:
        if name is None and number not in done:
            progress.finished_early(number)
        progress.phase(name, detail, source=label)
    progress.tick()


RELAY_SECONDS = 0.25  # how often the workers' phases are read while waiting for rows


def _drain(relay: Any) -> list[tuple[str, str | None, str]]:
    """The messages waiting on ``relay`` (none when it is closed)."""
    import queue

    out = []
    while True:
        try:
            out.append(relay.get_nowait())
        except (queue.Empty, OSError, ValueError, EOFError):
            return out


def _run_chunk_relayed(fn: ChunkFn, spec_text: str, source: str, options: dict[str, Any],
                       chunk: list[dict[str, Any]], number: int) -> list[Row]:
    """In a pool's worker: ``fn`` on ``chunk`` (the ``number``-th); what it shows by
    :func:`show_phase` goes to the bar of the process running the pool, labelled by the
    task (:func:`begin_task`), and the end of each task counts its row there at once."""
    set_chunk(number)
    try:
        return quietly(fn, spec_text, source, options, chunk)
    finally:
        begin_task(None)
        set_chunk(None)


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
