"""Shared fixtures: paths to the shipped specs."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"


@pytest.fixture(scope="session")
def specs_dir() -> Path:
    return SPECS


def spec_path(name: str) -> Path:
    return SPECS / f"{name}.yaml"
