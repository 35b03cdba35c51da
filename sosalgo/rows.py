"""Resumable CSV output: rows appended and flushed as they finish, settings recorded beside.

``DIR/<name>.csv`` holds the rows; ``DIR/<name>.csv.settings.json`` the settings of the run
that wrote them. A rerun with the same settings skips the keys already present; a rerun
with other settings is refused (:class:`SettingsMismatch`) unless ``restart=True``.
Each row is written with a single ``write`` of a complete line followed by flush and
fsync, and a truncated last line (a killed writer) is dropped when the file is reopened,
so a row is either entirely there or not at all.
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["ResumableCSV", "SettingsMismatch", "format_value"]


class SettingsMismatch(RuntimeError):
    """Existing output was produced with different settings."""


def format_value(v: Any) -> str:
    """CSV text of a value: repr-exact floats, empty for None."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


class ResumableCSV:
    """Append-only CSV keyed by a tuple of columns, resumable across runs."""

    def __init__(
        self,
        path: Path,
        columns: Sequence[str],
        key: Sequence[str],
        settings: dict[str, Any],
        restart: bool = False,
    ):
        self.path = Path(path)
        self.columns = list(columns)
        self.key = list(key)
        self.settings_path = self.path.with_name(self.path.name + ".settings.json")
        self.settings = json.loads(json.dumps(settings, sort_keys=True))
        self.done: dict[tuple[str, ...], dict[str, str]] = {}
        self._fh: io.TextIOWrapper | None = None
        if restart:
            for p in (self.path, self.settings_path):
                p.unlink(missing_ok=True)
        self._load()

    # -- reading -----------------------------------------------------------------------
    def _load(self) -> None:
        if not self.path.exists():
            return
        old = None
        if self.settings_path.exists():
            try:
                old = json.loads(self.settings_path.read_text())
            except (OSError, json.JSONDecodeError):
                old = None
        if old != self.settings:
            raise SettingsMismatch(
                f"{self.path} was written with different settings "
                f"(see {self.settings_path.name}); use --restart to start over"
            )
        text = self.path.read_text(encoding="utf-8")
        if text and not text.endswith("\n"):  # a killed writer left half a line
            text = text[: text.rfind("\n") + 1]
            self.path.write_text(text, encoding="utf-8")
        reader = csv.DictReader(io.StringIO(text))
        if reader.fieldnames is not None and list(reader.fieldnames) != self.columns:
            raise SettingsMismatch(f"{self.path} has other columns; use --restart to start over")
        for row in reader:
            self.done[self.row_key(row)] = row

    def row_key(self, row: dict[str, Any]) -> tuple[str, ...]:
        return tuple(format_value(row[k]) if not isinstance(row[k], str) else row[k]
                     for k in self.key)

    def is_done(self, key_values: dict[str, Any]) -> bool:
        return self.row_key(key_values) in self.done

    # -- writing -----------------------------------------------------------------------
    def open(self) -> ResumableCSV:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists() or self.path.stat().st_size == 0
        if new:
            tmp = self.settings_path.with_suffix(".tmp")
            tmp.write_text(json.dumps(self.settings, indent=2, sort_keys=True) + "\n")
            os.replace(tmp, self.settings_path)
        self._fh = open(self.path, "a", encoding="utf-8", newline="")
        if new:
            self._write_line(self.columns)
        return self

    def _write_line(self, values: Iterable[Any]) -> None:
        assert self._fh is not None
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([format_value(v) for v in values])
        self._fh.write(buf.getvalue())
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def write(self, row: dict[str, Any]) -> None:
        """Append one complete row (skipped if its key is already present)."""
        key = self.row_key(row)
        if key in self.done:
            return
        self._write_line(row.get(c) for c in self.columns)
        self.done[key] = {c: format_value(row.get(c)) for c in self.columns}

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> ResumableCSV:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def rows(self) -> list[dict[str, str]]:
        """All rows on disk (as strings), in file order."""
        return list(self.done.values())
