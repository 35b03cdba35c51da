"""Shared fixtures and helpers: paths to the shipped specs, documents without timings."""

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


def timeless(value):
    """``value`` without its ``seconds`` (how long a step took) anywhere inside."""
    if isinstance(value, dict):
        return {k: timeless(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [timeless(v) for v in value]
    return value


def pep_json(spec: Path, out: Path, steps: int, *extra: str) -> dict:
    """``sosalgo pep SPEC --steps N ... --json`` through the CLI (exit code 0 asserted):
    the printed document."""
    import json

    from click.testing import CliRunner

    from sosalgo.cli import cli

    r = CliRunner().invoke(cli, ["pep", str(spec), "--steps", str(steps), *extra, "--json",
                                 "--out", str(out)])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)
