"""Render math to MathML at build time (latex2mathml): pages need no script and no internet.

Registered as the HTML math renderer ``mathml``; a formula latex2mathml cannot convert fails
the build with the formula named (Sphinx runs with warnings as errors).
"""

from docutils import nodes
from latex2mathml.converter import convert
from sphinx.application import Sphinx
from sphinx.util import logging

logger = logging.getLogger(__name__)


def _mathml(self, node: nodes.Element, latex: str, display: bool) -> str:
    try:
        mathml = convert(latex, display="block" if display else "inline")
    except Exception as exc:  # latex2mathml raises several unrelated types
        logger.warning("math not converted to MathML (%s): %s", exc, latex, location=node)
        return self.encode(latex)
    if "<mi>&</mi>" in mathml:  # an alignment latex2mathml does not know: invalid markup
        logger.warning("math environment not supported by latex2mathml: %s", latex,
                       location=node)
        return self.encode(latex)
    return mathml


def visit_math(self, node: nodes.Element) -> None:
    self.body.append('<span class="math">' + _mathml(self, node, node.astext(), False) + "</span>")
    raise nodes.SkipNode


def visit_displaymath(self, node: nodes.Element) -> None:
    latex = node.astext()
    if "\\\\" in latex and "\\begin" not in latex:  # several lines: align them at &
        latex = "\\begin{split}" + latex + "\\end{split}"
    self.body.append(self.starttag(node, "div", CLASS="math"))
    if node.get("number"):
        self.body.append(f'<span class="eqno">({node["number"]})</span>')
    self.body.append(_mathml(self, node, latex, True) + "</div>\n")
    raise nodes.SkipNode


def setup(app: Sphinx) -> dict:
    app.add_html_math_renderer("mathml", (visit_math, None), (visit_displaymath, None))
    return {"parallel_read_safe": True, "parallel_write_safe": True}
