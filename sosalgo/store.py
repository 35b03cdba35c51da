"""Resumable CSV output and the run model of every batch command.

The run model
-------------
``DIR/<name>.csv`` holds the rows of one run; ``DIR/<name>.csv.settings.json`` the settings
that determine them (job, spec text, kappa list, tolerance, free parameters, ...).

- A rerun with **identical settings resumes**: keys already in the file are skipped.
- A rerun with **other settings recomputes**. The existing file (and its figures, the
  ``companions``) is *kept aside* under a name carrying a short hash of its settings,
  ``DIR/<name>-<hash8>.csv`` (``.settings.json``, figures likewise), and a one-line note
  says which setting differs and where the old results went. If a kept-aside file for the
  new settings exists it is moved back and resumed, so alternating between two settings
  never recomputes anything. ``restart=True`` (``--restart``) *replaces* the results of
  the current file instead (deleted, then recomputed), again with a note.
- One exclusive lock per output file (``fcntl.flock`` on ``DIR/.<name>.csv.lock``) is held
  from reading the done set to the last row, so two concurrent runs into one folder never
  write a row twice: the second waits (with a note) and then resumes or keeps aside. The
  lock file is removed when its run lets go (:func:`output_lock`); a killed run leaves
  an empty one, which the next run takes over.
- Nothing is written before the first row is ready (header and settings come with it).
- Each row is written with a single ``write`` of a complete line followed by a flush (a
  killed process loses nothing written); the file is fsync'ed at most every
  ``FSYNC_SECONDS`` and when the run ends, so an OS crash loses at most that much. On
  reading, a truncated last line (a killed writer) and malformed rows (wrong
  number of cells, unreadable key) are dropped with a warning and the file is rewritten
  atomically. A path that is not a regular file (a symlink to ``/dev/full``, a FIFO) is
  refused (:class:`OutputError`).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
import stat
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sosalgo.errors import InputError
from sosalgo.schema import kappa_label  # file names are the schema's; re-exported here

__all__ = [
    "OutputError",
    "ResumableCSV",
    "describe_difference",
    "format_value",
    "kappa_label",
    "output_lock",
    "settings_hash",
    "write_atomic",
    "write_table",
]

MAX_SETTINGS_BYTES = 4_000_000
FSYNC_SECONDS = 1.0  # a per-row fsync costs milliseconds on a busy disk: as much as a rate


class OutputError(InputError):
    """An output path cannot be used (not a regular file, not writable, ...): exit code 2."""


def format_value(v: Any) -> str:
    """CSV text of a value: repr-exact floats, empty for None."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def settings_hash(settings: Any) -> str:
    """Eight hex digits of SHA-256 of the canonical JSON of ``settings``."""
    text = json.dumps(settings, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:8]


def _summary(value: Any) -> str:
    """Short text of a setting's value for a one-line message."""
    if isinstance(value, list) and len(value) > 4 and all(
            isinstance(v, int | float) for v in value):
        return f"{len(value)} values in [{min(value):g}, {max(value):g}]"
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _text_difference(old: str, new: str) -> str:
    a, b = old.splitlines(), new.splitlines()
    for i, (x, y) in enumerate(zip(a, b, strict=False)):
        if x != y:
            return f"line {i + 1}: {_summary(x.strip())} -> {_summary(y.strip())}"
    return f"{len(a)} -> {len(b)} lines"


def describe_difference(old: Any, new: dict[str, Any]) -> str:
    """Which settings differ between two settings dicts, in a few words."""
    if not isinstance(old, dict):
        return "its settings file is missing or unreadable"
    parts = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if a == b:
            continue
        if key == "spec" and isinstance(a, str) and isinstance(b, str):
            parts.append(f"spec text ({_text_difference(a, b)})")
        else:
            parts.append(f"{key}: {_summary(a)} -> {_summary(b)}")
    return "; ".join(parts[:4]) + ("; ..." if len(parts) > 4 else "")


def _note(msg: str) -> None:
    sys.stderr.write(f"note: {msg}\n")
    sys.stderr.flush()


# --------------------------------------------------------------------------- locking
_HELD: dict[str, tuple[int, int]] = {}  # lock path -> (fd, depth): re-entrant per process


@contextmanager
def output_lock(path: Path, notify: Callable[[str], None] = _note) -> Iterator[None]:
    """Exclusive (re-entrant within a process) lock on output ``path`` across processes.

    The lock file ``DIR/.<name>.lock`` exists only while a run holds it: the holder
    removes it before letting go, and a run that was waiting on the removed file (its
    lock taken on a name no longer in the folder) opens the new one and waits again, so
    two runs never hold the lock of one output at once."""
    path = Path(path)
    lock = str(path.with_name(f".{path.name}.lock").absolute())
    if lock in _HELD:
        fd, depth = _HELD[lock]
        _HELD[lock] = (fd, depth + 1)
    else:
        _HELD[lock] = (_acquire(path, lock, notify), 1)
    try:
        yield
    finally:
        fd, depth = _HELD[lock]
        if depth > 1:
            _HELD[lock] = (fd, depth - 1)
        else:
            del _HELD[lock]
            _release(lock, fd)


def _acquire(path: Path, lock: str, notify: Callable[[str], None]) -> int:
    """A descriptor holding the flock on the file named ``lock`` (created if missing)."""
    import fcntl

    told = False
    while True:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OutputError(f"{path.parent}: cannot write ({exc.strerror})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if not told:
                notify(f"another sosalgo run is writing {path}; waiting for it to finish")
                told = True
            fcntl.flock(fd, fcntl.LOCK_EX)
        if _same_file(fd, lock):
            return fd
        os.close(fd)  # its holder removed it while we waited: lock the new one


def _same_file(fd: int, name: str) -> bool:
    """True when ``name`` still names the file open as ``fd``."""
    try:
        st = os.stat(name)
    except FileNotFoundError:
        return False
    own = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)


def _release(lock: str, fd: int) -> None:
    """Remove the lock file (while still holding it), then let go of it."""
    try:
        if _same_file(fd, lock):
            os.unlink(lock)
    except OSError:  # a read-only folder keeps its lock file; the lock is released anyway
        pass
    finally:
        os.close(fd)  # closing the descriptor releases the flock


# --------------------------------------------------------------------------- files
def _regular_or_missing(path: Path) -> bool:
    """True if ``path`` exists as a regular file; False if missing; OutputError otherwise."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            raise OutputError(f"{path}: a dangling symbolic link; remove it") from None
        return False
    except OSError as exc:
        raise OutputError(f"{path}: cannot read ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise OutputError(f"{path}: not a regular file; remove it or choose another --out")
    return True


def _read_settings(path: Path) -> Any:
    """The settings JSON beside a CSV, or None when missing or unreadable."""
    try:
        if not _regular_or_missing(path):
            return None
        with open(path, "rb") as fh:
            raw = fh.read(MAX_SETTINGS_BYTES + 1)
        if len(raw) > MAX_SETTINGS_BYTES:
            return None
        return json.loads(raw.decode("utf-8"))
    except (OSError, OutputError, UnicodeDecodeError, ValueError, RecursionError):
        return None


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all (a temporary file of this process,
    fsync'ed, then renamed over ``path``): a reader never sees half a file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


_atomic_write = write_atomic


def _content_hash(path: Path) -> str:
    """Eight hex digits naming a file whose settings are unknown (by its content)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:8]


def _old_digest(old_settings: Any, path: Path) -> str:
    """The kept-aside name's hash for an existing file: of its settings, else its content."""
    return settings_hash(old_settings) if isinstance(old_settings, dict) else _content_hash(path)


def _move_aside(files: Sequence[Path], digest: str, back: bool = False) -> None:
    """Rename ``files`` to their kept-aside names (``back``: the other way round)."""
    for p in files:
        aside = _aside_name(p, digest)
        src, dst = (aside, p) if back else (p, aside)
        if src.exists() or src.is_symlink():
            os.replace(src, dst)
        elif back:
            dst.unlink(missing_ok=True)


def _aside_name(path: Path, digest: str) -> Path:
    """``DIR/stem-<digest>.ext`` (``.csv.settings.json`` keeps its double suffix)."""
    name = path.name
    for suffix in (".csv.settings.json", ".csv", ".png", ".pdf", ".json"):
        if name.endswith(suffix):
            return path.with_name(f"{name[: -len(suffix)]}-{digest}{suffix}")
    return path.with_name(f"{name}-{digest}")


def write_table(path: Path, columns: Sequence[str], rows: Iterable[dict[str, Any]],
                settings: dict[str, Any], notify: Callable[[str], None] = _note) -> None:
    """Write a small table computed in one go (``table1``) under the run model: the whole
    file is replaced atomically under the output lock; a file written with other settings is
    kept aside first (``DIR/<name>-<hash8>.csv``), with a note saying what differs."""
    path = Path(path)
    settings = json.loads(json.dumps(settings, sort_keys=True))
    settings_path = path.with_name(path.name + ".settings.json")
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows([format_value(r.get(c)) for c in columns] for r in rows)
    with output_lock(path, notify):
        if _regular_or_missing(path):
            old = _read_settings(settings_path)
            if old != settings:
                digest = _old_digest(old, path)
                _move_aside([path, settings_path], digest)
                notify(f"{path} was written with other settings "
                       f"({describe_difference(old, settings)}); kept it aside as "
                       f"{_aside_name(path, digest).name}")
        _atomic_write(path, buf.getvalue())
        _atomic_write(settings_path, json.dumps(settings, indent=2, sort_keys=True) + "\n")


class ResumableCSV:
    """Append-only CSV keyed by a tuple of columns, resumable across runs (see module doc)."""

    def __init__(
        self,
        path: Path,
        columns: Sequence[str],
        key: Sequence[str],
        settings: dict[str, Any],
        restart: bool = False,
        companions: Sequence[Path] = (),
        notify: Callable[[str], None] = _note,
    ):
        self.path = Path(path)
        self.columns = list(columns)
        self.key = list(key)
        self.settings_path = self.path.with_name(self.path.name + ".settings.json")
        self.settings = json.loads(json.dumps(settings, sort_keys=True))
        self.digest = settings_hash(self.settings)
        self.companions = [Path(p) for p in companions]
        self.restart = restart
        self.notify = notify
        self.done: dict[tuple[str, ...], dict[str, str]] = {}
        self.dropped = 0
        self._fh: io.TextIOWrapper | None = None
        self._synced = 0.0
        self._lock: Any = None
        self._new = True
        self._reconciled = False
        if not restart and _regular_or_missing(self.path):  # a first look, without the lock
            old = _read_settings(self.settings_path)
            if old == self.settings:
                self._load(repair=False)

    # -- reconciling an existing file with this run's settings ---------------------------
    def _files(self) -> list[Path]:
        return [self.path, self.settings_path, *self.companions]

    def _reconcile(self) -> None:
        """Under the lock: resume, keep aside, replace or reuse a kept-aside file."""
        self.done = {}
        exists = _regular_or_missing(self.path)
        if exists and self.restart:
            for p in self._files():
                p.unlink(missing_ok=True)
            self.notify(f"--restart: replaced the earlier results in {self.path}")
            exists = False
        elif exists:
            old = _read_settings(self.settings_path)
            why = None
            if old != self.settings:
                digest = _old_digest(old, self.path)
                why = describe_difference(old, self.settings)
            elif not self._header_ok(self.path):
                digest = _content_hash(self.path)
                why = "its columns differ: written by another version of sosalgo"
            if why is not None:
                _move_aside(self._files(), digest)
                self.notify(f"{self.path} was written with other settings ({why}); "
                            f"kept it aside as {_aside_name(self.path, digest).name}; "
                            "computing anew")
                exists = False
        if not exists and not self.restart:
            aside = _aside_name(self.path, self.digest)
            if (_regular_or_missing(aside) and self._header_ok(aside) and _read_settings(
                    _aside_name(self.settings_path, self.digest)) == self.settings):
                _move_aside(self._files(), self.digest, back=True)
                self.notify(f"resuming the results of these settings kept in {aside.name}")
                exists = True
        if exists:
            self.dropped = 0
            self._load()
        self._new = not exists or self.path.stat().st_size == 0
        self._reconciled = True

    def _header_ok(self, path: Path) -> bool:
        """True when ``path`` is empty or starts with this run's header line."""
        with open(path, encoding="utf-8", errors="replace", newline="") as fh:
            first = fh.readline()
        if not first:
            return True
        return next(csv.reader([first]), None) == self.columns

    # -- reading -----------------------------------------------------------------------
    def _load(self, repair: bool = True) -> None:
        """Read the rows on disk; drop a truncated last line and malformed rows (and, with
        ``repair``, under the lock, say so and rewrite the file without them)."""
        with open(self.path, encoding="utf-8", errors="replace", newline="") as fh:
            text = fh.read()
        if text and not text.endswith("\n"):  # a killed writer left half a line
            text = text[: text.rfind("\n") + 1]
            self.dropped += 1
        records = list(csv.reader(io.StringIO(text)))
        if records and records[0] != self.columns:
            if not repair:
                return  # the locked reconcile keeps this file aside
            raise OutputError(f"{self.path}: has other columns than this run writes")
        done: dict[tuple[str, ...], dict[str, str]] = {}
        for cells in records[1:]:
            row = dict(zip(self.columns, cells, strict=False))
            if len(cells) != len(self.columns) or not self._key_ok(row):
                self.dropped += 1
                continue
            done.setdefault(self.row_key(row), row)
        self.done = done
        if self.dropped and repair:
            self.notify(f"{self.path}: dropped {self.dropped} incomplete or malformed row(s); "
                        "they will be recomputed")
            buf = io.StringIO()
            writer = csv.writer(buf, lineterminator="\n")
            writer.writerow(self.columns)
            writer.writerows([row[c] for c in self.columns] for row in done.values())
            _atomic_write(self.path, buf.getvalue())

    def _key_ok(self, row: dict[str, str]) -> bool:
        """Every key cell a finite number, or empty (``pep`` without a kappa)."""
        try:
            return all(row[k] == "" or math.isfinite(float(row[k])) for k in self.key)
        except (KeyError, TypeError, ValueError):
            return False

    def row_key(self, row: dict[str, Any]) -> tuple[str, ...]:
        return tuple(format_value(float(row[k])) if row[k] not in (None, "") else ""
                     for k in self.key)

    def is_done(self, key_values: dict[str, Any]) -> bool:
        return self.row_key(key_values) in self.done

    # -- writing -----------------------------------------------------------------------
    def open(self) -> ResumableCSV:
        """Take the lock and reconcile with what is on disk (nothing is written yet)."""
        self._lock = output_lock(self.path, self.notify)
        self._lock.__enter__()
        try:
            self._reconcile()
        except BaseException:
            self.close()
            raise
        return self

    def _start_file(self) -> None:
        _atomic_write(self.settings_path,
                      json.dumps(self.settings, indent=2, sort_keys=True) + "\n")
        self._fh = open(self.path, "a", encoding="utf-8", newline="")
        if self.path.stat().st_size == 0:
            self._write_line(self.columns)
        self._new = False

    def _write_line(self, values: Iterable[Any]) -> None:
        assert self._fh is not None
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([format_value(v) for v in values])
        self._fh.write(buf.getvalue())
        self._fh.flush()
        now = time.monotonic()
        if now - self._synced >= FSYNC_SECONDS:
            os.fsync(self._fh.fileno())
            self._synced = now

    def write(self, row: dict[str, Any]) -> None:
        """Append one complete row (skipped if its key is already present)."""
        key = self.row_key(row)
        if key in self.done:
            return
        if self._fh is None:
            if self._new:
                self._start_file()
            else:
                self._fh = open(self.path, "a", encoding="utf-8", newline="")
        self._write_line(row.get(c) for c in self.columns)
        self.done[key] = {c: format_value(row.get(c)) for c in self.columns}

    def close(self) -> None:
        if self._fh is not None:
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()
            self._fh = None
        if self._lock is not None:
            lock, self._lock = self._lock, None
            lock.__exit__(None, None, None)

    def __enter__(self) -> ResumableCSV:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def rows(self) -> list[dict[str, str]]:
        """All rows on disk (as strings), in file order."""
        return list(self.done.values())
