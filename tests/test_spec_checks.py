"""The checks a spec load runs beyond its structure (sosalgo.spec.checks): they live in the
layers that own them, and ``sosalgo.spec.load_spec`` runs all of them in a fresh
interpreter, whatever was imported before (nothing but the spec package, here)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

GRADIENT = """\
name: {name}
parameters:
  h: 1/L
matrices:
  A: [[{a}]]
  B: [[-h]]
  C: [[1]]
  E: [[1]]
kappa: [10]
"""
# (I - A) u = 0 with A = 1/2 forces u = 0, so C u = 1 fails: no fixed point (eq. (11))
NO_FIXED_POINT = GRADIENT.format(name="nofix", a="0.5")
# lag is an integer in 0..8 (the interpolation family's option)
BAD_OPTION = (GRADIENT.format(name="badlag", a="1")
              + "certificate: {family: interpolation, lag: -1}\n")
UNKNOWN_FAMILY = GRADIENT.format(name="nofam", a="1") + "certificate: sos\n"


def _fresh(code: str) -> subprocess.CompletedProcess:
    """``code`` run by a new interpreter with this checkout first on the path."""
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


def _load_in_fresh_interpreter(path: Path) -> str:
    out = _fresh(f"""
        import sys
        from sosalgo.spec import SpecError, load_spec
        assert "sosalgo.certificates" not in sys.modules and "sosalgo.model" not in sys.modules
        try:
            load_spec({str(path)!r})
        except SpecError as exc:
            print(exc)
        else:
            print("loaded")
        """)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


@pytest.mark.parametrize("text, message", [
    (NO_FIXED_POINT, "matrices: at kappa=10: no fixed point: eq. (11) needs u with "
                     "(I - A) u = 0, C u = 1, E u = 1"),
    (BAD_OPTION, "certificate.lag: must be an integer in 0..8"),
    (UNKNOWN_FAMILY, "certificate: unknown family (known: theorem1, interpolation"),
], ids=["no-fixed-point", "bad-option", "unknown-family"])
def test_a_fresh_load_runs_every_check(tmp_path, text, message):
    path = tmp_path / "s.yaml"
    path.write_text(text, encoding="utf-8")
    line = _load_in_fresh_interpreter(path)
    assert line.startswith(f"{path}: {message}") and "\n" not in line


def test_a_sound_spec_loads_in_a_fresh_interpreter(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(GRADIENT.format(name="gradient", a="1"), encoding="utf-8")
    assert _load_in_fresh_interpreter(path) == "loaded"


def test_a_load_with_a_check_missing_is_refused():
    """A provider that leaves out a stage makes every load fail, never pass unchecked."""
    out = _fresh("""
        from sosalgo.spec import spec_from_text
        from sosalgo.spec.checks import provide_checks
        from sosalgo.spec_values import check_values
        provide_checks(lambda: {"values": check_values})
        try:
            spec_from_text(open("specs/gradient.yaml").read(), "g.yaml")
        except RuntimeError as exc:
            print(exc)
        """)
    assert out.stdout.strip() == "spec checks missing: oracles, certificate", out.stderr


def test_the_cli_refuses_a_bad_option_in_one_line(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(BAD_OPTION, encoding="utf-8")
    out = subprocess.run([sys.executable, "-m", "sosalgo.cli", "analyze", str(path), "--out",
                          str(tmp_path / "out")], cwd=ROOT, capture_output=True, text=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}, timeout=120)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "certificate.lag: must be an integer in 0..8" in out.stderr
    assert not (tmp_path / "out").exists()
