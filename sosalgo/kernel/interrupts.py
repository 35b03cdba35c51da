"""Ctrl-C and SIGTERM during a native solve.

A Python signal handler runs only between bytecodes: during a long Clarabel solve it
would wait until the solve returns. Inside :func:`native_solve` the handler of the
command line (:mod:`sosalgo.cli_errors`) only records the interruption; the solver's
termination callback (:func:`stop_requested`, run between its iterations, where the
handler gets its turn) then stops the solve, and the interruption is raised when the
solve returns. Outside a solve it is raised at once. Only the main thread, the one that
receives signals, defers.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["native_solve", "request", "stop_requested", "watch"]

_depth = 0  # nesting of native_solve in the main thread
_pending: BaseException | None = None


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def request(exc: BaseException) -> None:
    """From a signal handler: raise ``exc`` now, or, inside a native solve of the main
    thread, once the solve has stopped (at its next iteration)."""
    global _pending
    if _depth and _main_thread():
        if _pending is None:
            _pending = exc
        return
    raise exc


def stop_requested(_info: Any = None) -> bool:
    """The solver's termination callback: whether an interruption is waiting."""
    return _pending is not None


@contextlib.contextmanager
def native_solve() -> Iterator[None]:
    """Around a native solve: an interruption meanwhile is raised when it returns."""
    global _depth, _pending
    if not _main_thread():
        yield
        return
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        if not _depth and _pending is not None:
            exc, _pending = _pending, None
            raise exc


def watch(solver: Any) -> Any:
    """Give a Clarabel solver the termination callback (where the installed Clarabel has
    one); returns the solver."""
    setter = getattr(solver, "set_termination_callback", None)
    if setter is not None and _main_thread():
        setter(stop_requested)
    return solver
