"""Sphinx configuration: MyST Markdown pages, furo theme, math rendered to MathML at build time."""

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
EXT = DOCS / "_ext"
sys.path.insert(0, str(EXT))
sys.path.insert(0, str(ROOT))

import sosalgo  # noqa: E402

project = "sosalgo"
author = "the sosalgo authors"
copyright = "the sosalgo authors"
version = release = sosalgo.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx_click",
    "sosalgo_clickdocs",
    "sosalgo_mathml",
]
# the example gallery builds its pages from the shipped specs when its extension is present
if (EXT / "sosalgo_gallery.py").exists():
    extensions.append("sosalgo_gallery")

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
myst_dmath_double_inline = True

html_theme = "furo"
html_title = f"sosalgo {release}"
html_static_path = ["_static"]
html_css_files = ["sosalgo.css"]
html_math_renderer = "mathml"
# no web fonts, no CDN: the site works without internet access
html_theme_options = {"navigation_with_keys": True}

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False}
napoleon_google_docstring = True
napoleon_numpy_docstring = False

nitpicky = False
# "--kappa" stays two hyphens (options, not dashes), quotes stay straight as in a terminal
smartquotes = False
# pages written before the site start at "##"; their heading levels are kept as they are
suppress_warnings = ["myst.header"]
os.environ.setdefault("SOSALGO_DOCS_BUILD", "1")
