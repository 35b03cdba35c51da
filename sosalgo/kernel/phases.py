"""What a long computation is doing now, for whoever shows progress.

A computation (a design, a PEP, a verification, one row of a sweep) says its phases with
:func:`show_phase` ("bound", "12 boxes proven, budget 40 s") and a batch says which task
runs with :func:`begin_task` ("kappa 10"). Where they go is decided above, by the run
layer (:mod:`sosalgo.batch.executor`), which installs a sink: the progress bar of this
process, or, in a pool's worker, the queue to the bar of the process that runs the pool.
Without a sink a phase goes nowhere. This module imports nothing of sosalgo: every layer
may report its phases.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["Sink", "begin_task", "current_task", "set_sink", "show_phase"]

Sink = Callable[[str | None, str | None, str], None]  # (task, phase or None: ended, detail)

_SINK: Sink | None = None
_TASK: str | None = None  # the label of the task running in this process


def set_sink(sink: Sink | None) -> Sink | None:
    """Send this process's phases to ``sink`` (None: nowhere); returns the previous sink."""
    global _SINK
    previous, _SINK = _SINK, sink
    return previous


def show_phase(name: str | None, detail: str = "") -> None:
    """The running task is now doing ``name`` (``detail``: how far it is); None: the
    phase ended."""
    if _SINK is not None:
        _SINK(_TASK, name, detail)


def begin_task(label: str | None) -> None:
    """A task named ``label`` (e.g. "kappa 10") starts in this process; None: the last one
    ended. The previous task's phase ends with it (which also counts its row, for a task
    running in a pool's worker)."""
    global _TASK
    if _TASK is not None:
        show_phase(None)
    _TASK = label
    if label is not None:
        show_phase("running")


def current_task() -> str | None:
    """The label of the task running in this process (None: none was named)."""
    return _TASK
