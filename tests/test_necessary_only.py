"""Classes given by necessary conditions only (no interpolation theorem): a witness meeting
those conditions bounds the PEP from below, not the class's worst case, and the output says
so; classes that interpolate get no such note."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from sosalgo.cli import cli

ROOT = Path(__file__).resolve().parents[1]


def _pep(spec: str, tmp_path: Path, *extra: str) -> tuple[dict, str]:
    out = CliRunner().invoke(cli, ["pep", str(ROOT / "specs" / spec), "--steps", "1",
                                   "--out", str(tmp_path), "--no-plot", *extra],
                             catch_exceptions=False)
    assert out.exit_code == 0, out.output
    name = spec.removesuffix(".yaml")
    doc = json.loads((tmp_path / f"{name}-pep-N1-witness.json").read_text())
    return doc, out.output


def test_a_necessary_only_class_marks_its_witness(tmp_path):
    doc, printed = _pep("gradient-pl.yaml", tmp_path)
    assert doc["interpolating"] is False
    assert doc["necessary_only"] == ["smooth_lojasiewicz"]
    assert "necessary conditions only" in printed
    assert "not the class's worst case" in printed


def test_an_interpolating_class_has_no_such_note(tmp_path):
    doc, printed = _pep("gradient-convex.yaml", tmp_path)
    assert "necessary_only" not in doc and "interpolating" not in doc
    assert "necessary conditions only" not in printed


def test_classes_described_as_necessary_say_so():
    """A class whose description calls its conditions necessary (not known to interpolate)
    is flagged ``interpolating = False``, which the witness note reads."""
    from sosalgo.classes import CLASSES

    for name, cls in CLASSES.items():
        text = (cls.description + " " + " ".join((cls.tilted_text or ("",))[:1])).lower()
        if "necessary" in text or "not known to interpolate" in text:
            assert not cls.interpolating, name
