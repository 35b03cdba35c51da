"""The README: at most 150 lines, and its quick start runs as written with the output it shows.

The quick start's commands run in an empty folder; their stdout is compared with the
README's output block. Solver-internal columns and timings (``seconds``, ``solves``,
``max_eig_M``, ``min_eig_P``) vary from machine to machine and are masked; every other
number must agree to 2e-6. After a change of the printed text, regenerate the block with
``python tests/test_readme.py --regenerate``.
"""

from __future__ import annotations

import math
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MARKER = "<!-- quick-start-output"
MASKED_COLUMNS = {"seconds", "solves", "max_eig_M", "min_eig_P"}
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
TOLERANCE = 2e-6


def quick_start() -> tuple[list[str], str]:
    """The quick start's commands and its output block, as the README shows them."""
    text = README.read_text("utf-8")
    section = text[text.index("## Quick start"):]
    commands = section.split("```\n", 2)[1].strip().splitlines()
    output = section[section.index(MARKER):].split("```\n", 2)[1]
    return commands, output


def run_quick_start(folder: Path) -> str:
    """Run the commands in ``folder`` with this checkout's sosalgo; their stdout."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "200"}
    out = []
    for line in quick_start()[0]:
        argv = shlex.split(line)
        assert argv[0] == "sosalgo", line
        done = subprocess.run(
            [sys.executable, "-c", "from sosalgo.cli import main; main()", *argv[1:]],
            cwd=folder, env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, (line, done.stderr)
        out.append(done.stdout)
    return "".join(out)


def masked_table_cells(lines: list[str]) -> dict[int, set[int]]:
    """Line index -> character positions of masked cells, for each table in ``lines``.

    A table is a header line followed by a line of dash groups; the groups give the
    columns' spans, the header their names."""
    masked: dict[int, set[int]] = {}
    for i, rule in enumerate(lines):
        if i == 0 or not re.fullmatch(r"-+( +-+)*", rule.strip() or "x"):
            continue
        spans = [m.span() for m in re.finditer(r"-+", rule)]
        names = [lines[i - 1][a:b].strip() for a, b in spans]
        hidden = {pos for (a, b), name in zip(spans, names, strict=True)
                  if name in MASKED_COLUMNS for pos in range(a, b)}
        j = i + 1
        while j < len(lines) and lines[j].strip() and len(lines[j]) >= spans[0][1] \
                and NUMBER.match(lines[j].strip()):
            masked[j] = hidden
            j += 1
    return masked


def skeleton(line: str, hidden: set[int]) -> tuple[str, list[float]]:
    """The line with its numbers replaced by '#' (masked cells dropped) and the numbers."""
    numbers: list[float] = []
    parts: list[str] = []
    last = 0
    for m in NUMBER.finditer(line):
        parts.append(line[last:m.start()])
        if not any(p in hidden for p in range(m.start(), m.end())):
            numbers.append(float(m.group()))
            parts.append("#")
        else:
            parts.append("*")
        last = m.end()
    parts.append(line[last:])
    return re.sub(r"\s+", " ", "".join(parts)).strip(), numbers


def compare(shown: str, printed: str) -> list[str]:
    """Differences between the README's block and the printed output, one per line."""
    a, b = shown.strip("\n").splitlines(), printed.strip("\n").splitlines()
    if len(a) != len(b):
        return [f"README shows {len(a)} lines, the commands print {len(b)}:\n{printed}"]
    masked_a, masked_b = masked_table_cells(a), masked_table_cells(b)
    problems = []
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        sx, nx = skeleton(x, masked_a.get(i, set()))
        sy, ny = skeleton(y, masked_b.get(i, set()))
        close = len(nx) == len(ny) and all(
            math.isclose(p, q, rel_tol=TOLERANCE, abs_tol=TOLERANCE)
            for p, q in zip(nx, ny, strict=True))
        if sx != sy or not close:
            problems.append(f"line {i + 1}:\n  README:  {x}\n  printed: {y}")
    return problems


def test_readme_has_at_most_150_lines():
    assert len(README.read_text("utf-8").splitlines()) <= 150


def test_readme_quick_start_prints_what_it_shows(tmp_path):
    commands, shown = quick_start()
    assert commands and all(c.startswith("sosalgo ") for c in commands)
    printed = run_quick_start(tmp_path)
    assert compare(shown, printed) == []


def test_compare_masks_only_the_varying_columns():
    """The comparison is not vacuous: a changed rate or reference fails, a changed time
    does not."""
    shown = ("kappa   rho  seconds  ref\n"
             "-----  ----  -------  ---\n"
             "   10  0.75      0.1  0.8\n"
             "kappa 10: worst-case rate in [0.68, 0.75]\n")
    assert compare(shown, shown.replace("0.1 ", "9.9 ")) == []
    assert compare(shown, shown.replace("0.75      0.1", "0.76      0.1")) != []
    assert compare(shown, shown.replace("0.68", "0.67")) != []
    assert compare(shown, shown.replace("worst-case", "best-case")) != []


def regenerate() -> None:
    """Rewrite the README's output block with what the quick start prints now."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        printed = run_quick_start(Path(folder))
    text = README.read_text("utf-8")
    start = text.index("```\n", text.index(MARKER)) + len("```\n")
    end = text.index("```\n", start)
    README.write_text(text[:start] + printed.rstrip("\n") + "\n" + text[end:], "utf-8")


if __name__ == "__main__":
    if sys.argv[1:] == ["--regenerate"]:
        regenerate()
    else:
        sys.exit("usage: python tests/test_readme.py --regenerate")
