"""The example gallery and the ``{sosalgo-run}`` directive (docs/_ext): pages built from the
specs, numbers against closed forms computed here, build failures on failing commands.

The builds use a small site of their own (a conf.py with MyST and the gallery extension, a
specs folder with two specs), so the test does not depend on the full documentation site.
"""

from __future__ import annotations

import html
import os
import re
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import pytest

import sosalgo

ROOT = Path(__file__).resolve().parent.parent
EXT = ROOT / "docs" / "_ext"
sys.path.insert(0, str(EXT))

import sosalgo_docrun  # noqa: E402
import sosalgo_gallery  # noqa: E402
from sosalgo_gallery_render import oracle_lines, state_lines  # noqa: E402

CONF = """
import sys
sys.path.insert(0, {ext!r})
project = "gallery-test"
extensions = ["myst_parser", "sosalgo_gallery"]
source_suffix = {{".md": "markdown"}}
exclude_patterns = ["_build"]
myst_enable_extensions = ["dollarmath", "amsmath"]
sosalgo_gallery_specs = "../specs"
"""


def make_site(tmp: Path, specs: dict[str, str], pages: dict[str, str]) -> Path:
    """A site in tmp/docs (index + the given pages + the gallery index) and tmp/specs."""
    (tmp / "specs").mkdir(parents=True)
    for name, text in specs.items():
        (tmp / "specs" / f"{name}.yaml").write_text(text)
    docs = tmp / "docs"
    (docs / "gallery").mkdir(parents=True)
    (docs / "conf.py").write_text(CONF.format(ext=str(EXT)))
    (docs / "gallery" / "index.md").write_text(
        (ROOT / "docs" / "gallery" / "index.md").read_text())
    toc = "\n".join(["gallery/index", *pages])
    (docs / "index.md").write_text(f"# test\n\n```{{toctree}}\n{toc}\n```\n")
    for name, text in pages.items():
        (docs / f"{name}.md").write_text(text)
    return docs


def build(docs: Path, warnings_are_errors: bool = True) -> subprocess.CompletedProcess:
    """sphinx-build -b html in a child process (the sosalgo of this checkout)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p))
    flags = ["-W", "--keep-going"] if warnings_are_errors else []
    return subprocess.run([sys.executable, "-m", "sphinx", "-q", *flags, "-b", "html",
                           str(docs), str(docs / "_build" / "html")],
                          capture_output=True, text=True, env=env, timeout=600, check=False)


def table_rows(page: str) -> list[list[str]]:
    """The body rows of the rates table (the table after 'Certified') as cell texts."""
    section = page[page.index('id="certified'):]
    body = section[section.index("<tbody>"):section.index("</tbody>")]
    rows = re.findall(r"<tr.*?</tr>", body, flags=re.S)
    return [[html.unescape(re.sub(r"<[^>]+>", "", c)).strip()
             for c in re.findall(r"<td.*?</td>", r, flags=re.S)] for r in rows]


RUN_PAGE = r"""# run

```{sosalgo-run} sosalgo examples gradient --copy .
:expect: gradient\.yaml
```

```{sosalgo-run} sosalgo analyze gradient.yaml --kappa 2 --kappa 10
:figures: outputs/gradient-rate*.png
```
"""


def edited_gradient() -> str:
    """gradient.yaml with the step 2/(m + L) and kappas 3, 9: a spec no page was built from."""
    text = (ROOT / "specs" / "gradient.yaml").read_text()
    text = text.replace("name: gradient", "name: gradient-edited")
    text = re.sub(r"value: 1/L", "value: 2/(m + L)", text)
    return re.sub(r"kappa: \[.*\]", "kappa: [3, 9]", text)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One build: three shipped specs (one that changes with k), an edited one, a page
    running two commands."""
    specs = {n: (ROOT / "specs" / f"{n}.yaml").read_text()
             for n in ("gradient", "gradient-convex", "gradient-schedule")}
    specs["gradient-edited"] = edited_gradient()
    label = "(methods-that-change-with-k)=\n# Methods that change with k\n"  # spec.md's
    docs = make_site(tmp_path_factory.mktemp("gallery"), specs,
                     {"run": RUN_PAGE, "varying": label})
    done = build(docs)
    assert done.returncode == 0, done.stderr
    return docs


def test_every_spec_in_the_folder_gets_a_page_and_an_index_line(site: Path) -> None:
    out = site / "_build" / "html" / "gallery"
    index = (out / "index.html").read_text()
    for name in ("gradient", "gradient-convex", "gradient-edited"):
        page = (out / f"{name}.html").read_text()
        assert "Update rule" in page and "The spec" in page
        assert f'href="{name}.html"' in index
        assert (site / "_build" / "html" / "_images" / f"{name}-rate.png").stat().st_size > 0


def test_the_gallery_shows_every_shipped_example() -> None:
    """The default folder of the gallery is the folder `sosalgo examples` ships."""
    from sosalgo.kernel.resources import example_specs

    class Config:
        sosalgo_gallery_specs = None

    class App:
        confdir = str(ROOT / "docs")
        config = Config()

    found = sorted(p.stem for p in sosalgo_gallery.specs_dir(App()).glob("*.yaml"))
    assert found == sorted(example_specs()) and len(found) >= 13


def test_gradient_rates_are_the_closed_form(site: Path) -> None:
    """Gradient with h = 1/L on F(m, L): rate max(|1 - hm|, |1 - hL|) = 1 - 1/kappa (tight:
    the quadratic with curvature m attains it), so the certified rate shown, rounded up,
    lies in [1 - 1/kappa, 1 - 1/kappa + 2e-6]."""
    rows = table_rows((site / "_build" / "html" / "gallery" / "gradient.html").read_text())
    assert [float(r[0]) for r in rows] == [2, 5, 10, 20, 50, 100]
    for row in rows:
        kappa, shown = Fraction(row[0]), Fraction(row[1])
        closed = 1 - 1 / kappa
        assert closed <= shown <= closed + Fraction(2, 10**6), row


def test_gradient_convex_constant_is_the_tight_one(site: Path) -> None:
    """Drori and Teboulle: gradient with step 1/L on L-smooth convex f has worst case
    L |x_0 - x*|^2 / (4k + 2) after k steps, so any c with f(x_k) - f* <= c |x_0 - x*|^2 / k
    for all k is at least L/4 (L = 1 here), and the certificate is tight to 1e-4."""
    page = (site / "_build" / "html" / "gallery" / "gradient-convex.html").read_text()
    (row,) = table_rows(page)
    assert float(row[0]) == 1.0
    assert Fraction(1, 4) <= Fraction(row[1]) <= Fraction(1, 4) + Fraction(1, 10**4)
    assert "c\\,\\|x_0 - x_\\star\\|^2 / k" in (site / "gallery" / "gradient-convex.md").read_text()


def test_a_method_that_changes_with_k_shows_its_proven_worst_case(site: Path) -> None:
    """Drori and Teboulle: gradient with h_k = 1/L on L-smooth convex f has the tight
    worst case L |x_0 - x*|^2 / (4N + 2) after N steps; the page of the per-step spec
    shows its proven PEP value, rounded up, within 2e-6 above it for N = 1..5."""
    page = (site / "_build" / "html" / "gallery" / "gradient-schedule.html").read_text()
    rows = table_rows(page)
    assert [int(r[0]) for r in rows] == [1, 2, 3, 4, 5]
    for row in rows:
        closed = Fraction(1, 4 * int(row[0]) + 2)
        assert closed <= Fraction(row[1]) <= closed + Fraction(2, 10**6), row
    assert "gradient-schedule-rate.png" in page


def test_update_rule_is_rendered_from_the_matrices(site: Path) -> None:
    text = (site / "gallery" / "gradient.md").read_text()
    assert "x_{k+1} &= x_k - h u_k" in text
    assert "u_k &= \\nabla f(y_k)" in text
    assert "\\rho^{2k} V_0" in text  # what the rate bounds


def test_an_edited_spec_gets_its_own_numbers(site: Path) -> None:
    """Numbers come from the spec at build time: gradient with h = 2/(m + L) has the rate
    max(|1 - hm|, |1 - hL|) = (kappa - 1)/(kappa + 1), at the spec's own kappas."""
    page = (site / "_build" / "html" / "gallery" / "gradient-edited.html").read_text()
    rows = table_rows(page)
    assert [r[0] for r in rows] == ["3", "9"]
    for row in rows:
        kappa, shown = Fraction(row[0]), Fraction(row[1])
        closed = (kappa - 1) / (kappa + 1)
        assert closed <= shown <= closed + Fraction(2, 10**6), row


def test_run_directive_shows_output_and_figures(site: Path) -> None:
    page = (site / "_build" / "html" / "run.html").read_text()
    out = html.unescape(re.sub(r"<[^>]+>", "", page))
    assert "$ sosalgo examples gradient --copy ." in out
    assert "$ sosalgo analyze gradient.yaml --kappa 2 --kappa 10" in out
    assert re.search(r"^\s*10\s+0\.9000", out, flags=re.M)  # 1 - 1/kappa at kappa = 10
    assert "ETA" not in out
    images = re.findall(r'<img[^>]*src="([^"]+)"', page)
    assert len(images) == 1 and "gradient-rate" in images[0]
    assert (site / "_build" / "html" / images[0]).stat().st_size > 0


@pytest.mark.parametrize("page, message", [
    ("```{sosalgo-run} sosalgo analyze missing.yaml\n```\n", "exited with 2"),
    ("```{sosalgo-run} sosalgo examples gradient --copy .\n:figures: outputs/*.png\n```\n",
     "wrote no file matching outputs/*.png"),
    ("```{sosalgo-run} sosalgo examples gradient --copy .\n:expect: ^nothing$\n```\n",
     "no longer matches :expect: ^nothing$"),
])
def test_run_directive_fails_the_build(tmp_path: Path, page: str, message: str) -> None:
    """A failing command stops the build, warnings-as-errors or not."""
    docs = make_site(tmp_path, {}, {"run": f"# run\n\n{page}"})
    done = build(docs, warnings_are_errors=False)
    assert done.returncode != 0
    assert message in done.stderr
    assert not (docs / "_build" / "html" / "run.html").exists()


def test_run_helpers() -> None:
    assert sosalgo_docrun.split_command("sosalgo analyze a.yaml --json > a.json") == (
        ["analyze", "a.yaml", "--json"], "a.json")
    for bad in ("ls -l", "sosalgo analyze a.yaml | head", "sosalgo a && rm x"):
        with pytest.raises(Exception, match="not a plain"):
            sosalgo_docrun.split_command(bad)
    text = "analyze x [####----] 1/2 0.5/s ETA 0:01\nkappa  rho\n   10  0.9\n"
    assert sosalgo_docrun.strip_progress(text) == "kappa  rho\n   10  0.9"


def test_round_up_never_rounds_down() -> None:
    assert sosalgo_gallery.round_up(Fraction(1, 3)) == "0.333334"
    assert sosalgo_gallery.round_up(Fraction(1, 2)) == "0.500000"
    assert sosalgo_gallery.round_up(Fraction(999999, 10**6) + Fraction(1, 10**9)) == "1.000000"


def test_cache_key_follows_the_spec_text() -> None:
    text = (ROOT / "specs" / "gradient.yaml").read_text()
    assert sosalgo_gallery.cache_key(text) == sosalgo_gallery.cache_key(text)
    assert sosalgo_gallery.cache_key(text) != sosalgo_gallery.cache_key(text + "\n# edited\n")


UNPROVEN = " (not proven exactly)"  # a value shown without its exact proof says so


def _shown_value(cell: str) -> bool:
    """A table cell is "none certified", a positive proven value, or a positive value
    marked as not proven exactly."""
    return cell == "none certified" or float(cell.removesuffix(UNPROVEN)) > 0


@pytest.mark.deep
def test_whole_gallery_and_getting_started_build(tmp_path: Path) -> None:
    """Every shipped spec gets a page with a rate (or 'none certified') at each of its
    table kappas; every command of the getting-started page succeeds."""
    from sosalgo.kernel.resources import example_specs

    specs = {n: p.read_text() for n, p in example_specs().items()}
    page = (ROOT / "docs" / "getting-started.md").read_text()
    # the spec reference's section that time-varying pages link to, as a stub page
    stub = "# Spec\n\n(methods-that-change-with-k)=\n## Methods that change with k\n"
    docs = make_site(tmp_path, specs, {"getting-started": page, "spec": stub})
    done = build(docs)
    assert done.returncode == 0, done.stderr
    for name in specs:
        html_page = (docs / "_build" / "html" / "gallery" / f"{name}.html").read_text()
        rows = table_rows(html_page)
        assert rows and all(_shown_value(r[1]) for r in rows), (name, rows)
        assert '<img' in html_page


def test_cache_prunes_only_older_versions_of_the_same_spec(tmp_path: Path) -> None:
    old, new, other = "a" * 24, "b" * 24, "c" * 24
    for name in (f"gradient-{old}.json", f"gradient-{old}.png", f"gradient-{new}.json",
                 f"gradient-convex-{other}.json", "notes.txt"):
        (tmp_path / name).write_text("x")
    sosalgo_gallery.prune_cache(tmp_path, "gradient", new)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        f"gradient-{new}.json", f"gradient-convex-{other}.json", "notes.txt"]


def test_a_broken_spec_fails_the_build_naming_it(tmp_path: Path) -> None:
    docs = make_site(tmp_path, {"broken": "name: broken\nmatrices: {A: [[1]]}\n"}, {})
    done = build(docs, warnings_are_errors=False)
    assert done.returncode != 0
    assert "broken.yaml" in done.stderr and "sosalgo_gallery" in done.stderr


@pytest.mark.parametrize("name, lines", [
    ("nesterov", [r"y_k &= x_k + \gamma \left(x_k - x_{k-1}\right)",
                  r"x_{k+1} &= x_k + \beta \left(x_k - x_{k-1}\right) - h u_k"]),
    ("proximal-gradient", [r"y^{(2)}_k &= \operatorname{prox}_{h g}\left(x_k - h u^{(1)}_k\right)",
                           r"x_{k+1} &= x_k - h u^{(1)}_k - h u^{(2)}_k"]),
    ("triple-momentum", [r"x_k &= z_k + \delta \left(z_k - z_{k-1}\right)"]),
    ("projected-gradient", [r"y^{(2)}_k &= \Pi_K\left(x_k - h u^{(1)}_k\right)"]),
])
def test_update_rule_reads_as_the_textbook_method(name: str, lines: list[str]) -> None:
    """From the matrices back to each method's usual form (Nesterov's two momentum steps,
    proximal gradient's prox of a gradient step, triple momentum's output, the projection
    of projected gradient), written here from the methods' definitions."""
    spec = sosalgo.example(name)
    rendered = (oracle_lines(spec) or []) + state_lines(spec)
    for line in lines:
        assert line in rendered
