"""The documentation site, loaded in a real headless browser (the system's Chromium).

Builds the site (or reuses a build newer than its sources), then opens every page from
disk with every request outside the build refused (the site must work offline) and checks:
no console error, no failed request; math rendered as MathML with non-zero size and
superscripts raised above their base; every image decoded (naturalWidth > 0); every
internal link and anchor resolving to a page and an element of the build.

Chromium is Debian's ``chromium`` (playwright drives it; no browser is downloaded).
Without it the browser test is skipped locally and fails under CI (``CI=true``), whose
``.ci/run`` installs it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from urllib.parse import unquote, urldefrag, urlparse

import pytest

from sosalgo.cli import cli

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
HTML = DOCS / "_build" / "html"
SOURCES = ("docs", "sosalgo", "specs")

pytestmark = pytest.mark.xdist_group("docs_site")


def newest_source() -> float:
    """mtime of the newest file the site is built from (pages, extensions, docstrings,
    click commands, specs for the gallery, the changelog)."""
    files = [ROOT / "CHANGELOG.md"]
    for folder in SOURCES:
        files += [p for p in (ROOT / folder).rglob("*") if p.is_file()
                  and "_build" not in p.parts and "__pycache__" not in p.parts]
    return max(p.stat().st_mtime for p in files)


@pytest.fixture(scope="module")
def site() -> Path:
    index = HTML / "index.html"
    if not index.exists() or index.stat().st_mtime < newest_source():
        done = subprocess.run(
            [sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-q", "-b", "html",
             str(DOCS), str(HTML)], cwd=ROOT, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, done.stderr[-4000:]
    return HTML


def chromium() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("chromium is not installed (CI installs it: apt-get install chromium)")
        pytest.skip("chromium is not installed (apt-get install chromium)")
    return path


def test_every_command_has_its_page():
    for name in cli.commands:
        page = DOCS / "commands" / f"{name}.md"
        assert page.exists(), f"no page for the command {name}"
        assert f".. click:: sosalgo.cli:{name}" in page.read_text("utf-8")


PAGE_FACTS = """() => {
  const rect = (e) => { const r = e.getBoundingClientRect(); return [r.width, r.height]; };
  const maths = [...document.querySelectorAll('math')];
  const sups = [...document.querySelectorAll('math msup')].filter(s => s.children.length == 2)
    .map(s => [s.children[0].getBoundingClientRect().top,
               s.children[1].getBoundingClientRect().top]);
  const prose = document.body.cloneNode(true);
  prose.querySelectorAll('pre, code, script, style').forEach(e => e.remove());
  return {
    ids: [...document.querySelectorAll('[id]')].map(e => e.id)
          .concat([...document.querySelectorAll('a[name]')].map(e => e.name)),
    links: [...document.querySelectorAll('a[href]')].map(a => a.href),
    images: [...document.querySelectorAll('img')].map(i => [i.src, i.complete, i.naturalWidth]),
    math: maths.map(m => [getComputedStyle(m).display].concat(rect(m))),
    sups: sups,
    rawTex: /\\\\(frac|sqrt|begin)\\{|\\$\\$/.test(prose.textContent),
  };
}"""


def visit(page, url: str, problems: list[str]) -> dict:
    page.goto(url, wait_until="load")
    facts = page.evaluate(PAGE_FACTS)
    for src, complete, width in facts["images"]:
        if not complete or width == 0:
            problems.append(f"{url}: image not shown: {src}")
    for display, width, height in facts["math"]:
        if width <= 0 or height <= 0 or "math" not in display:
            problems.append(f"{url}: math not rendered (display {display}, {width}x{height})")
    for base_top, sup_top in facts["sups"]:
        if not sup_top < base_top:
            problems.append(f"{url}: a superscript is not raised above its base")
    if facts["rawTex"]:
        problems.append(f"{url}: TeX source shown as text")
    return facts


def check_links(site: Path, facts: dict[str, dict]) -> list[str]:
    problems = []
    for url, page_facts in facts.items():
        for link in page_facts["links"]:
            target, fragment = urldefrag(link)
            if urlparse(target).scheme != "file":
                continue
            path = Path(unquote(urlparse(target).path))
            if path.is_dir():
                path = path / "index.html"
            if not path.exists():
                problems.append(f"{url}: broken link {link}")
            elif fragment and path.suffix == ".html":
                ids = facts.get(path.as_uri(), {}).get("ids")
                if ids is not None and unquote(fragment) not in ids:
                    problems.append(f"{url}: no anchor #{fragment} in {path.name}")
    return problems


def test_site_in_headless_chromium(site):
    executable = chromium()
    from playwright.sync_api import sync_playwright

    pages = sorted(site.rglob("*.html"))
    assert len(pages) >= 30
    problems: list[str] = []
    facts: dict[str, dict] = {}
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=executable, headless=True,
                                     args=["--no-sandbox", "--disable-gpu"])
        page = browser.new_page()
        current = {"url": ""}

        def refuse_outside(route):
            if not route.request.url.startswith(site.as_uri()):
                problems.append(f"{current['url']}: request outside the site: "
                                f"{route.request.url}")
                return route.abort()
            return route.continue_()

        page.route("**/*", refuse_outside)
        page.on("console", lambda msg: msg.type == "error" and problems.append(
            f"{current['url']}: console error: {msg.text}"))
        page.on("pageerror", lambda exc: problems.append(f"{current['url']}: {exc}"))
        page.on("requestfailed", lambda req: problems.append(
            f"{current['url']}: failed to load {req.url}"))
        for path in pages:
            current["url"] = path.as_uri()
            facts[path.as_uri()] = visit(page, path.as_uri(), problems)
        browser.close()
    problems += check_links(site, facts)
    math_pages = [u for u, f in facts.items() if f["math"]]
    assert any(u.endswith("/theory.html") for u in math_pages)
    assert sum(len(f["sups"]) for f in facts.values()) > 0
    assert problems == []


def test_spec_reference_names_every_field_the_loader_knows():
    from sosalgo.spec.types import TOP_KEYS

    rows = [line for line in (DOCS / "spec.md").read_text("utf-8").splitlines()
            if line.startswith("| `")]
    documented = {row.split("`")[1] for row in rows}
    assert TOP_KEYS <= documented, sorted(TOP_KEYS - documented)
