"""docs/architecture.md stays true: every path and dotted name it gives exists, and its
table of layers is the one tests/test_imports.py enforces."""

from __future__ import annotations

import glob
import importlib
import re
from pathlib import Path

import pytest

from tests.test_imports import LAYERS

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "architecture.md"
CODE = re.findall(r"`([^`\n]+)`", PAGE.read_text(encoding="utf-8"))
PATHS = sorted({c for c in CODE if "/" in c and " " not in c and "<" not in c})
DOTTED = sorted({c for c in CODE if re.fullmatch(r"sosalgo(\.\w+)+", c)})


def _resolve(dotted: str) -> object:
    """The module or attribute ``dotted`` names (ImportError/AttributeError if none)."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for name in parts[i:]:
            obj = getattr(obj, name)
        return obj
    raise ImportError(dotted)


def test_the_page_names_paths_and_names():
    assert len(PATHS) > 10 and len(DOTTED) > 10  # the patterns below find what it names


@pytest.mark.parametrize("path", PATHS)
def test_every_path_exists(path):
    base = ROOT if path.split("/")[0] in ("sosalgo", "tests", "docs") else ROOT / "sosalgo"
    assert glob.glob(str(base / path)), f"docs/architecture.md names {path}: no such file"


@pytest.mark.parametrize("dotted", DOTTED)
def test_every_dotted_name_exists(dotted):
    _resolve(dotted)


def test_the_layer_table_is_the_tested_one():
    rows = re.findall(r"^\| (\w+) \| ((?:`\w+`(?:, )?)+) \|", PAGE.read_text(encoding="utf-8"),
                      re.M)
    page = [(name, tuple(re.findall(r"`(\w+)`", units))) for name, units in rows]
    assert page == [(name, units) for name, units in LAYERS]
