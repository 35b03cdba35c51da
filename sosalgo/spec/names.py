"""Spec names: where no such file exists, the name of a shipped example (``nesterov`` or
``nesterov.yaml``, see ``sosalgo examples``) stands for it, and a missing file's error
names the closest shipped example (:func:`sosalgo.spec.loading.read_spec_text`)."""

from __future__ import annotations

import difflib
import os
from importlib.abc import Traversable
from pathlib import Path

__all__ = ["closest_example", "shipped_example"]


def shipped_example(name: str | Path) -> Traversable | None:
    """The shipped example a bare name (no folder; ``.yaml`` optional) stands for, else
    None. Only asked where no such file exists: a file always wins."""
    from sosalgo.kernel.resources import example_specs

    text = str(name)
    if not text or os.sep in text or (os.altsep and os.altsep in text):
        return None
    stem = text[: -len(".yaml")] if text.endswith(".yaml") else text
    return example_specs().get(stem)


def closest_example(name: str | Path) -> str | None:
    """The shipped example whose name is closest to ``name``'s file stem (difflib)."""
    from sosalgo.kernel.resources import example_specs

    names = list(example_specs())
    stem = Path(str(name)).name
    for ext in (".yaml", ".yml"):
        stem = stem[: -len(ext)] if stem.endswith(ext) else stem
    close = difflib.get_close_matches(stem, names, n=1, cutoff=0.0)
    return close[0] if close else None
