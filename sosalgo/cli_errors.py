"""How the command line fails: one line on stderr, an exit code, never a traceback.

Exit codes: 0 success, 2 bad input or usage (our :class:`~sosalgo.errors.InputError` and
click's usage errors alike) or an environment that refuses the output (a full disk, a
quota, a read-only file system), 3 a certificate failed its check, 1 internal error (set
SOSALGO_DEBUG=1 for the traceback), 130/143 interrupted, 141 broken pipe.
"""

from __future__ import annotations

import errno
import functools
import os
import sys
from collections.abc import Callable
from typing import Any

import click

from sosalgo.errors import InputError, VerificationError

__all__ = ["INTERRUPTED", "OneLineErrors", "Terminated", "disk_error", "handle_errors",
           "on_sigint", "on_sigterm"]

INTERRUPTED = (130, 143)  # the exit codes of Ctrl-C and SIGTERM

# errors of the place the output goes, not of sosalgo: reported in one line, exit 2
DISK_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})


def _fail(msg: str, code: int) -> None:
    click.echo(f"error: {msg}", err=True)
    sys.exit(code)


def _one_line(msg: str) -> str:
    return " ".join(msg.split())[:500]


class Terminated(BaseException):
    """SIGTERM received: unwinds like KeyboardInterrupt, so worker pools are shut down."""


def on_sigterm(signum: int, frame: Any) -> None:
    """SIGTERM: Terminated, at once or when the native solve under way has stopped."""
    from sosalgo.kernel.interrupts import request

    request(Terminated())


def on_sigint(signum: int, frame: Any) -> None:
    """Ctrl-C: KeyboardInterrupt, at once or when the native solve under way has stopped."""
    from sosalgo.kernel.interrupts import request

    request(KeyboardInterrupt())


def handle_errors(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Map our exceptions to one-line messages and exit codes."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except InputError as exc:  # spec, model, options, files, cluster: exit 2
            src = kwargs.get("spec_path", "")
            names_file = getattr(exc, "names_file", True)
            _fail(_one_line(str(exc) if names_file or not src else f"{src}: {exc}"), 2)
        except VerificationError as exc:  # results are written; a check failed: exit 3
            _fail(_one_line(str(exc)), 3)
        except BrokenPipeError:  # stdout closed early (`sosalgo ... | head`): quiet exit
            _broken_pipe()
        except OSError as exc:  # a full disk, a quota, a read-only file system: exit 2
            if exc.errno not in DISK_ERRNOS:
                _internal(exc)
            _fail(_one_line(disk_error(exc, kwargs.get("out"))), 2)
        except KeyboardInterrupt:
            click.echo("interrupted: finished rows are saved; rerun to resume", err=True)
            sys.exit(130)
        except Terminated:
            click.echo("terminated: finished rows are saved; rerun to resume", err=True)
            sys.exit(143)
        except click.exceptions.Exit:
            raise
        except Exception as exc:  # noqa: BLE001 - last line of defence
            _internal(exc)

    return wrapper


def disk_error(exc: OSError, out: object = None) -> str:
    """One line for a write the file system refused (see :data:`DISK_ERRNOS`)."""
    where = exc.filename or (f"--out {out}" if out else "output")
    return (f"{where}: {exc.strerror or os.strerror(exc.errno or 0)}: the rows finished before "
            "are saved; make room and rerun to resume")


def _internal(exc: BaseException) -> None:
    if os.environ.get("SOSALGO_DEBUG"):
        raise exc
    _fail(_one_line(f"internal error: {type(exc).__name__}: {exc}"), 1)


def _broken_pipe() -> None:
    """stdout closed early (``sosalgo ... | head``): a quiet exit."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())  # no second error at interpreter exit
    sys.exit(141)  # 128 + SIGPIPE, as a shell reports a broken pipe


class OneLineErrors(click.Group):
    """A group whose usage errors (a bad option value, a missing argument) are one line on
    stderr, exit code 2, like every other input error."""

    def main(self, *args: Any, standalone_mode: bool = True, **kwargs: Any) -> Any:
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            code = super().main(*args, standalone_mode=False, **kwargs)
        except click.exceptions.Abort:
            _fail("aborted", 1)
        except click.ClickException as exc:
            ctx = getattr(exc, "ctx", None)
            where = f" (see {ctx.command_path} --help)" if ctx is not None else ""
            _fail(_one_line(exc.format_message()) + where, exc.exit_code)
        sys.exit(code if isinstance(code, int) else 0)
