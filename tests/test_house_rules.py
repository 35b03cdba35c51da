"""House rules of the source tree that no other test keeps: the package ``sosalgo`` is a
plain module (its Python API functions are attributes, not a callable module), files are
named for what they hold or test, no issue numbers or dates in the code, its docstrings,
the tests and the pages users read, and the removed scalar-SOS branch stays removed."""

from __future__ import annotations

import ast
import re
import types
from pathlib import Path

import sosalgo

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted(p for p in [*(ROOT / "sosalgo").rglob("*.py"), *(ROOT / "tests").rglob("*.py"),
                             *(ROOT / "bench").rglob("*.py")]
                 if p != Path(__file__).resolve())  # this file spells what it looks for
# the pages a user reads (history goes in CHANGELOG.md, which docs/changelog.md includes)
PAGES = sorted([ROOT / "README.md", *(p for p in (ROOT / "docs").rglob("*.md")
                                     if not {"_build", "_generated"} & set(p.parts)
                                     and p.name != "changelog.md")])
# a stem that says when or in which round a file was written, not what it tests
UNNAMED = re.compile(r"(^|_)(new|old|tmp|v\d+)$")
# an issue number or a date of the project's history (a fuzz input's 2001 date is data)
HISTORY = re.compile(r"\bissues?\s*#?\d+\b|(?<![\w#&])#\d{2,4}\b(?!-)"
                     r"|\b20[2-9]\d-[01]\d-[0-3]\d\b", re.IGNORECASE)


def test_the_package_is_a_plain_module():
    """``sosalgo`` is an ordinary module: its class is not replaced (no callable-module
    trick); ``sosalgo.analyze`` and the others are the plain functions of ``sosalgo.api``."""
    from sosalgo import api

    assert type(sosalgo) is types.ModuleType and not callable(sosalgo)
    for name in ("analyze", "design", "pep", "verify"):
        assert getattr(sosalgo, name) is getattr(api, name)
    tree = ast.parse((ROOT / "sosalgo" / "__init__.py").read_text(encoding="utf-8"))
    assigned = {ast.unparse(t) for node in ast.walk(tree) if isinstance(node, ast.Assign)
                for t in node.targets}
    assert not any("__class__" in t for t in assigned), assigned


def test_files_are_named_for_their_subject():
    stems = [p for p in SOURCES if p.suffix == ".py" and UNNAMED.search(p.stem)]
    assert stems == [], "name these files for what they hold or test"


def test_no_issue_numbers_or_dates():
    found = [f"{p.relative_to(ROOT)}:{i}: {m.group(0)}" for p in [*SOURCES, *PAGES]
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             for m in HISTORY.finditer(line)]
    assert found == [], "\n".join(found)


def test_the_checks_see_what_they_look_for():
    """The patterns above find a file named for its round and each kind of history, and
    not a colour, a year, a reference or a dotted version."""
    assert [s for s in ("soundness_new", "independent_new", "pep_v2", "old", "pep_tmp")
            if UNNAMED.search(s)] == ["soundness_new", "independent_new", "pep_v2", "old",
                                      "pep_tmp"]
    assert not any(UNNAMED.search(s) for s in ("test_newton", "test_renewal", "gold"))
    hits = ["see issue 28", "Issues #12 and", "fixed in #123", "on 2026-11-28"]
    assert all(HISTORY.search(s) for s in hits)
    misses = ["color '#1f77b4'", "Taylor et al. (2017)", "eq. (15)", "version 1.2.3",
              "&#123;", "tissue 3"]
    assert not any(HISTORY.search(s) for s in misses)


def test_the_scalar_sos_branch_is_gone():
    name = "SCALAR" + "_SOS"
    assert not [p for p in (ROOT / "sosalgo").rglob("*.py")
                if name in p.read_text(encoding="utf-8")]
