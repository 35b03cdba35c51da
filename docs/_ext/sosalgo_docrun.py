"""``{sosalgo-run}``: run a sosalgo command while the docs build and show what it prints.

    ```{sosalgo-run} sosalgo analyze heavy-ball.yaml --kappa 10
    :figures: outputs/heavy-ball-rate*.png
    ```

The commands of one page run in order in one folder, empty when the page's first command
starts (``_build/.sosalgo-runs/<page>``), so a page reads as a session in a fresh folder.
Only ``sosalgo ...`` commands run (no shell); a final ``> FILE`` sends stdout to FILE in that
folder. The page shows the command and its stdout, progress lines removed; ``:figures:``
(glob patterns in the folder) are shown below it. ``:expect:`` is a regular expression that
stdout must match (the page's prose relies on it). A command that exits with another code
than ``:returncode:`` (default 0), stdout that misses ``:expect:``, or a figure pattern
that matches nothing stops the build with the command and the end of its stderr.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.application import Sphinx
from sphinx.errors import ExtensionError
from sphinx.util.docutils import SphinxDirective

PROGRESS = re.compile(r"(\[[#\-= ]*\]\s+\d+/\d+)|(\bETA\b)|(\d+/\d+ .*elapsed)")
RUNNER = "import sys; from sosalgo.cli import main; sys.argv[0] = 'sosalgo'; sys.exit(main())"


def strip_progress(text: str) -> str:
    """stdout without progress lines (what a terminal overwrites in place)."""
    lines = [line.rsplit("\r", 1)[-1].rstrip() for line in text.splitlines()]
    return "\n".join(line for line in lines if not PROGRESS.search(line)).strip("\n")


def split_command(command: str) -> tuple[list[str], str | None]:
    """(arguments after ``sosalgo``, the file of a final ``> FILE`` or None)."""
    words = shlex.split(command)
    target = None
    if len(words) >= 2 and words[-2] == ">":
        words, target = words[:-2], words[-1]
    if not words or words[0] != "sosalgo" or any(w in {">", "|", "&&", ";"} for w in words):
        raise ExtensionError(f"sosalgo-run: not a plain `sosalgo ...` command: {command}")
    return words[1:], target


def run_command(command: str, folder: Path, timeout: float) -> subprocess.CompletedProcess:
    """Run one sosalgo command in ``folder`` with the sosalgo this build imports."""
    import sosalgo

    args, _ = split_command(command)
    root = str(Path(sosalgo.__file__).resolve().parent.parent)
    env = dict(os.environ, COLUMNS="100", NO_COLOR="1", TERM="dumb",
               PYTHONPATH=os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p))
    try:
        return subprocess.run([sys.executable, "-c", RUNNER, *args], cwd=folder, env=env,
                              capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        raise ExtensionError(f"sosalgo-run: `{command}` took more than {timeout:g} s") from None


class SosalgoRun(SphinxDirective):
    """Run a sosalgo command at build time; show it, its stdout and its figures."""

    required_arguments = 1
    final_argument_whitespace = True
    has_content = False
    option_spec = {"figures": directives.unchanged, "returncode": directives.nonnegative_int,
                   "timeout": directives.positive_int, "expect": directives.unchanged}

    def folder(self) -> Path:
        """This page's run folder, emptied before the page's first command."""
        folder = self.env.temp_data.get("sosalgo_run_folder")
        if folder is None:
            slug = self.env.docname.replace("/", "-")
            folder = Path(self.env.app.outdir).parent / ".sosalgo-runs" / slug
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir(parents=True)
            self.env.temp_data["sosalgo_run_folder"] = folder
        return folder

    def run(self) -> list[nodes.Node]:
        command = self.arguments[0].strip()
        folder = self.folder()
        done = run_command(command, folder, float(self.options.get("timeout", 600)))
        expected = self.options.get("returncode", 0)
        if done.returncode != expected:
            tail = "\n".join(done.stderr.strip().splitlines()[-8:])
            raise ExtensionError(f"sosalgo-run in {self.env.docname}: `{command}` exited with "
                                 f"{done.returncode} (expected {expected}):\n{tail}")
        expect = self.options.get("expect")
        if expect and not re.search(expect, done.stdout, flags=re.M):
            raise ExtensionError(f"sosalgo-run in {self.env.docname}: the output of `{command}` "
                                 f"no longer matches :expect: {expect} (the page's text relies "
                                 "on it):\n" + strip_progress(done.stdout)[-2000:])
        _, target = split_command(command)
        shown = f"$ {command}"
        if target is not None:
            (folder / target).write_text(done.stdout, encoding="utf-8")
        elif strip_progress(done.stdout):
            shown += "\n" + strip_progress(done.stdout)
        block = nodes.literal_block(shown, shown, language="console")
        return [block, *self.figures(folder, command)]

    def figures(self, folder: Path, command: str) -> list[nodes.Node]:
        """The files the ``:figures:`` patterns match, copied into the source tree."""
        out: list[nodes.Node] = []
        for pattern in self.options.get("figures", "").split():
            found = sorted(folder.glob(pattern))
            if not found:
                raise ExtensionError(f"sosalgo-run in {self.env.docname}: `{command}` wrote no "
                                     f"file matching {pattern}")
            for path in found:
                out += self.figure(path, path.relative_to(folder).as_posix())
        return out

    def figure(self, path: Path, shown_name: str) -> list[nodes.Node]:
        slug = self.env.docname.replace("/", "-")
        copy = Path(self.env.srcdir) / "_generated" / "run" / slug / path.name
        copy.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, copy)
        text = [f"```{{figure}} /_generated/run/{slug}/{path.name}", f":alt: {shown_name}", "",
                f"`{shown_name}`, written by the command above.", "```"]
        container = nodes.container()
        self.state.nested_parse(StringList(text, source=self.env.docname), self.content_offset,
                                container)
        return list(container.children)


def setup(app: Sphinx) -> dict[str, Any]:
    app.add_directive("sosalgo-run", SosalgoRun)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
