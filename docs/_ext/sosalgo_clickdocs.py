"""Command pages from the click commands: their help texts are plain text, not reStructuredText.

sphinx-click hands each help text to the reST parser, where ``*``, ``|``, backquotes and
trailing underscores of ordinary prose (``|x_N - x*|``, ``rho_``) start markup and fail the
build. This extension escapes those characters, so a help text reads on the page exactly as
``sosalgo CMD --help`` prints it.
"""

import re

from sphinx.application import Sphinx

_MARKUP = re.compile(r"([\\*|`_\[\]])")


def _escape_text(text: str) -> str:
    """Escape one line of help text; a leading "| " (a click \\b block) stays a line block."""
    if text.startswith("| "):
        return "| " + _MARKUP.sub(r"\\\1", text[2:])
    return _MARKUP.sub(r"\\\1", text)


def _escape(lines: list[str]) -> None:
    for i, line in enumerate(lines):
        if line.lstrip().startswith(".."):  # sphinx-click's own directives
            continue
        lines[i] = _escape_text(line)


def _escape_description(app: Sphinx, ctx: object, lines: list[str]) -> None:
    _escape(lines)


def _escape_option_help(app: Sphinx, ctx: object, lines: list[str]) -> None:
    # option blocks are ".. option:: --name VALUE" followed by indented help text
    for i, line in enumerate(lines):
        if line.startswith("    ") and not line.lstrip().startswith(":"):
            lines[i] = "    " + _escape_text(line[4:])


def setup(app: Sphinx) -> dict:
    app.setup_extension("sphinx_click")
    app.connect("sphinx-click-process-description", _escape_description)
    app.connect("sphinx-click-process-epilog", _escape_description)
    app.connect("sphinx-click-process-options", _escape_option_help)
    app.connect("sphinx-click-process-arguments", _escape_option_help)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
