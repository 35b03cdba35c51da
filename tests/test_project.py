"""A stand-alone project: own docs, shipped example specs, version, make help,
range checks, and the Python API."""

from __future__ import annotations

import doctest
import importlib.metadata
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.model import Algorithm, ModelError
from sosalgo.spec import SpecError, spec_from_text

from .conftest import SPECS

ROOT = Path(__file__).resolve().parents[1]


def project_files() -> list[Path]:
    out = [ROOT / "README.md", ROOT / "Makefile", ROOT / "pyproject.toml"]
    for folder in ("docs", "specs", "sosalgo", "bench", "tests"):
        out += [p for p in (ROOT / folder).rglob("*") if p.suffix in (".md", ".yaml", ".py")]
    return out


def test_no_file_points_outside_the_project():
    pattern = re.compile(r"\.\./shared|NOTES\.md|NOTES item")
    offenders = [str(p.relative_to(ROOT)) for p in project_files()
                 if p.name != "test_project.py" and pattern.search(p.read_text("utf-8"))]
    assert offenders == []
    notes = (ROOT / "docs" / "paper-notes.md").read_text("utf-8")
    for fact in ("exchanged", "M22", "Q_f", "n(n+1)/2", "ρ² V_k",
                 "P ⪰ 0", "1 − 1/√κ", "lower bound", "limits"):
        assert fact in notes, fact


def test_version_agrees_everywhere():
    res = CliRunner().invoke(cli, ["--version"])
    assert res.exit_code == 0 and sosalgo.__version__ in res.output
    assert importlib.metadata.version("sosalgo") == sosalgo.__version__


def test_make_help_lists_every_target():
    text = (ROOT / "Makefile").read_text()
    phony = re.search(r"^\.PHONY:(.*)$", text, re.M).group(1).split()
    targets = set(re.findall(r"^([a-z][a-z0-9_-]*):", text, re.M))
    res = subprocess.run(["make", "-s", "help"], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0
    listed = set(re.findall(r"^make ([a-z0-9_-]+)", res.stdout, re.M))
    assert (set(phony) | targets) - {"help"} <= listed, (set(phony) | targets) - listed


def test_value_outside_its_range_is_refused(tmp_path):
    text = (SPECS / "nesterov.yaml").read_text()
    bad = re.sub(r"beta:\s*\{value:[^,]*,", "beta: {value: 1.3,", text, count=1)
    assert bad != text
    with pytest.raises(SpecError, match=r"parameters\.beta\.value: 1\.3 is outside"):
        spec_from_text(bad)
    path = tmp_path / "bad.yaml"
    path.write_text(bad)
    res = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(tmp_path)])
    assert res.exit_code == 2 and res.stderr.count("\n") == 1


def test_packages_list_every_subpackage():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(conf["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "sosalgo").rglob(
        "__init__.py")}
    assert found <= listed
    assert conf["tool"]["setuptools"]["package-dir"]["sosalgo.examples"] == "specs"


@pytest.mark.slow
def test_installed_copy_runs_table1_and_examples_outside_the_repo(tmp_path):
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps",
                    "--target", str(target), str(ROOT)],
                   check=True, capture_output=True, timeout=600)
    assert (target / "sosalgo" / "examples" / "nesterov.yaml").exists()
    env = {**os.environ, "PYTHONPATH": str(target)}
    work = tmp_path / "elsewhere"
    work.mkdir()
    res = subprocess.run([sys.executable, "-m", "sosalgo.cli", "examples", "nesterov",
                          "--copy", "mine"], cwd=work, env=env, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert (work / "mine" / "nesterov.yaml").read_text() == (SPECS / "nesterov.yaml").read_text()
    res = subprocess.run([sys.executable, "-m", "sosalgo.cli", "table1", "--kappa", "2",
                          "--out", "o"], cwd=work, env=env, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr
    assert "nesterov" in res.stdout and (work / "o" / "table1.csv").exists()


def test_examples_lists_the_shipped_specs():
    res = CliRunner().invoke(cli, ["examples"])
    assert res.exit_code == 0
    for p in SPECS.glob("*.yaml"):
        assert p.stem in res.stdout
    assert CliRunner().invoke(cli, ["examples", "nope"]).exit_code == 2


# --------------------------------------------------------------------------- Python API
def test_api_names():
    for name in ("__version__", "load_spec", "analyze", "design", "verify", "AnalysisResult",
                 "DesignResult", "ExactResult", "Spec", "Algorithm"):
        assert hasattr(sosalgo, name), name


def test_api_functions_are_functions_after_their_packages_load():
    import types

    import sosalgo.design_search
    import sosalgo.proofs
    import sosalgo.worstcase  # noqa: F401  (the packages behind the functions)

    for name in ("analyze", "design", "pep", "verify"):
        assert isinstance(getattr(sosalgo, name), types.FunctionType), name


def test_api_analyze_a_list_and_verify():
    spec = sosalgo.load_spec(SPECS / "gradient-optimal.yaml")
    results = sosalgo.analyze(spec, kappa=[2, 10])
    assert isinstance(results, list) and len(results) == 2
    for res, k in zip(results, (2, 10), strict=True):
        assert isinstance(res, sosalgo.AnalysisResult)
        assert res.rho == pytest.approx((k - 1) / (k + 1), abs=1e-5)
    one = sosalgo.analyze(SPECS / "gradient-optimal.yaml", kappa=10)
    assert one.rho == pytest.approx(9 / 11, abs=1e-5)
    from sosalgo.proofs.exact import verify_exact  # the submodule stays importable

    assert callable(verify_exact)
    check = sosalgo.verify(spec, one, simulate=False)
    assert check["verified"] == "exact"
    assert callable(sosalgo.design)


def test_algorithm_accepts_lists_and_refuses_no_fixed_point():
    alg = Algorithm([[1.0]], [[-0.1]], [[1.0]], [[1.0]], 1.0, 10.0)
    assert isinstance(alg.A, np.ndarray) and alg.A.shape == (1, 1)
    res = sosalgo.analyze_algorithm(alg)
    assert res.rho == pytest.approx(0.9, abs=1e-5)  # h = 1/L: 1 - 1/kappa
    with pytest.raises(ModelError, match="fixed point"):
        Algorithm([[0.5]], [[-0.1]], [[1.0]], [[1.0]], 1.0, 10.0)
    with pytest.raises(ModelError, match="matrices.B"):
        Algorithm([[1.0]], [[-0.1, 0.0]], [[1.0]], [[1.0]], 1.0, 10.0)


def _loaded_after(args: list[str], modules: tuple[str, ...], tmp_path) -> list[str]:
    """Which of ``modules`` a CLI run (in a fresh process, writing into tmp_path) imported."""
    code = ("import sys\nfrom sosalgo.cli import cli\n"
            "try:\n    cli(sys.argv[2:] + ['--out', sys.argv[1], '--quiet'])\n"
            "except SystemExit as e:\n    assert not e.code, e.code\n"
            f"print('MODULES:' + ' '.join(m for m in {modules!r} if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path), *args],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    return res.stdout.strip().splitlines()[-1].removeprefix("MODULES:").split()


def test_one_kappa_analyze_imports_no_plotting_cvxpy_dask_or_sympy(tmp_path):
    modules = ("matplotlib", "cvxpy", "dask", "distributed", "sympy", "sosalgo.proofs",
               "sosalgo.design_search", "sosalgo.polyopt")
    args = ["analyze", str(SPECS / "nesterov.yaml"), "--kappa", "10"]
    assert _loaded_after(args, modules, tmp_path) == []


def test_default_design_does_not_import_cvxpy(tmp_path):
    """cvxpy (about 2 s of imports) is for the paper's relaxation (--method moment) only."""
    args = ["design", str(SPECS / "nesterov.yaml"), "--kappa", "10", "--free", "beta"]
    assert _loaded_after(args, ("cvxpy",), tmp_path) == []


def test_kappa_numbers_are_parsed_as_numbers(monkeypatch):
    import sosalgo.spec.loading as spec_mod

    def boom(*a, **k):
        raise AssertionError("expression parsing of a plain number")

    monkeypatch.setattr(spec_mod, "parse_tree", boom)
    values = [f"{1.5 + 0.25 * i:g}" for i in range(241)]
    out = spec_mod.parse_kappa(values + [7, 2.5, "1e6"], "x", "kappa")
    assert out[:241] == tuple(float(v) for v in values) and out[-1] == 1e6


def test_api_page_session_runs_as_shown(monkeypatch, tmp_path):
    """The Python API page's notebook session, run by doctest from a folder that is not the
    checkout (shipped examples by name)."""
    text = (ROOT / "docs" / "api.md").read_text()
    block = text[text.index("# Python API"):].split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    parser = doctest.DocTestParser()
    test = parser.get_doctest(block, {}, "docs/api.md", str(ROOT / "docs" / "api.md"), 0)
    assert sum(1 for ex in test.examples if ex.want) >= 4
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    assert runner.summarize(verbose=False).failed == 0
