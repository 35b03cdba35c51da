"""The example specs shipped with sosalgo (``sosalgo examples``).

Installed, they live in the package as ``sosalgo.examples`` (built from the repository's
``specs/`` folder, see pyproject.toml); in a source checkout they are read from ``specs/``.
"""

from __future__ import annotations

from importlib import resources
from importlib.abc import Traversable
from pathlib import Path

__all__ = ["example_specs", "examples_dir"]


def examples_dir() -> Traversable:
    """The folder of the shipped example specs."""
    try:
        files = resources.files("sosalgo.examples")
        if any(p.name.endswith(".yaml") for p in files.iterdir()):
            return files
    except (ModuleNotFoundError, FileNotFoundError, NotADirectoryError):
        pass
    return Path(__file__).resolve().parents[2] / "specs"


def example_specs() -> dict[str, Traversable]:
    """Example spec files by name (file stem), sorted."""
    folder = examples_dir()
    try:
        items = [p for p in folder.iterdir() if p.name.endswith(".yaml")]
    except (FileNotFoundError, NotADirectoryError):
        return {}
    return {p.name[: -len(".yaml")]: p for p in sorted(items, key=lambda p: p.name)}
