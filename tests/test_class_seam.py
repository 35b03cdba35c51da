"""A function class owns everything about itself (the seam of ``sosalgo.classes``):
nothing outside the classes package names a shipped class, and a class written in one
module (tests/smooth_convex_class.py) plugs in by one registry line and runs through
analyze, pep and verify with the rates its closed forms give."""

from __future__ import annotations

import ast
import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
import yaml
from click.testing import CliRunner

from sosalgo import api
from sosalgo.certificates.exact_composite import exact_class_inequalities
from sosalgo.classes import CLASSES, register_class, unregister_class
from sosalgo.cli import cli
from sosalgo.kernel.exact import Ball

from .smooth_convex_class import CLASS as SMOOTH_CONVEX

PACKAGE = Path(__file__).resolve().parents[1] / "sosalgo"


def _shipped_names() -> set[str]:
    """Names of the classes the classes package itself registers."""
    return {c.name for c in CLASSES.values() if type(c).__module__.startswith("sosalgo.classes.")}


def _docstrings(tree: ast.AST) -> set[int]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            first = node.body[0] if node.body else None
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                out.add(id(first.value))
    return out


def _class_mentions(text: str, where: str, names: set[str]) -> list[str]:
    """String literals equal to a class name (docstrings and comments excluded), and
    imports of a class's module, in the Python source ``text``."""
    tree = ast.parse(text)
    docs = _docstrings(tree)
    found = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                and node.value in names and id(node) not in docs):
            found.append(f"{where}:{node.lineno}: {node.value!r}")
        elif isinstance(node, ast.ImportFrom) and node.module:
            mods = {node.module} | {f"{node.module}.{a.name}" for a in node.names}
            hit = sorted(m for m in mods if m.split(".")[-1] in names and ".classes" in m)
            found += [f"{where}:{node.lineno}: import {m}" for m in hit]
    return found


def test_no_module_outside_the_classes_package_names_a_class():
    names = _shipped_names()
    assert {"smooth_strongly_convex", "convex", "strongly_convex", "indicator",
            "smooth"} <= names
    found = [hit for path in sorted(PACKAGE.rglob("*.py"))
             if path.relative_to(PACKAGE).parts[0] != "classes"
             for hit in _class_mentions(path.read_text(encoding="utf-8"),
                                        str(path.relative_to(PACKAGE.parent)), names)]
    assert not found, "class names outside sosalgo/classes/ (ask the class):\n" + "\n".join(
        found)


def test_the_scan_sees_a_literal_and_an_import():
    """The scan above would see a class named in code (not in a docstring or comment)."""
    text = ('"""smooth_strongly_convex in a docstring is fine."""\n'
            'from sosalgo.classes import convex\n'
            'X = cls.name == "indicator"  # "strongly_convex" in a comment is fine\n')
    hits = _class_mentions(text, "probe.py", _shipped_names())
    assert hits == ["probe.py:2: import sosalgo.classes.convex", "probe.py:3: 'indicator'"]


@pytest.mark.parametrize("name,params", [
    ("smooth_strongly_convex", {"m": Fraction(1, 3), "L": Fraction(7, 2)}),
    ("convex", {}), ("strongly_convex", {"m": Fraction(2, 5)}), ("indicator", {}),
    ("test_smooth_convex", {"L": Fraction(9, 4)}),
    ("smooth", {"m": Fraction(-2, 3), "L": Fraction(3, 2)})])
def test_exact_twins_are_the_float_inequalities(name, params):
    """Each class's exact tilted inequalities (balls, exact here) equal its float ones at
    rational parameters (two codes: the float formulas and the exact ones)."""
    cls = CLASSES[name] if name in CLASSES else SMOOTH_CONVEX
    ineqs, source = exact_class_inequalities(cls, {k: Ball(v) for k, v in params.items()})
    assert source == "exact"
    floats = cls.tilted({k: float(v) for k, v in params.items()})
    assert len(ineqs) == len(floats)
    for (alpha, Q), f in zip(ineqs, floats, strict=True):
        assert alpha.r == 0 and float(alpha.c) == pytest.approx(f.alpha, rel=1e-15)
        assert all(b.r == 0 for b in Q.flat)
        got = np.array([[float(b.c) for b in row] for row in Q])
        assert np.allclose(got, f.Q, rtol=1e-15, atol=0)


def test_the_test_class_inequality_holds_on_its_test_functions():
    """Its inequality holds on its test functions and fails on a function outside it."""
    L = 3.0
    (ineq,) = SMOOTH_CONVEX.inequalities({"L": L})
    rng = np.random.default_rng(2)
    xs = rng.standard_normal(2)
    pts = xs + 2 * rng.standard_normal((25, 2))
    for f in SMOOTH_CONVEX.test_functions({"L": L}, xs, rng):
        vals, grads = f.value(pts), f.grad(pts)
        worst = np.inf
        for a in range(25):
            for b in range(25):
                X = np.array([pts[a], pts[b], grads[a], grads[b]])  # 4 x d
                q = np.einsum("id,ij,jd->", X, ineq.Q, X)
                worst = min(worst, ineq.alpha * (vals[a] - vals[b]) + q)
        assert worst >= -1e-9, f.name
    x = np.array([-1.0, 0.5, 2.0])  # (2L)/2 x^2: 2L-smooth, outside the class
    X = np.array([x[0], x[2], 2 * L * x[0], 2 * L * x[2]])
    assert ineq.alpha * (L * x[0] ** 2 - L * x[2] ** 2) + X @ ineq.Q @ X < 0


# --------------------------------------------------------------------------- plug-in


@pytest.fixture()
def registered():
    register_class(SMOOTH_CONVEX)  # the one registry line
    yield SMOOTH_CONVEX
    unregister_class(SMOOTH_CONVEX.name)
    assert SMOOTH_CONVEX.name not in CLASSES


def _prox_grad(f_class: dict) -> dict:
    """Proximal gradient with h = 1/L on f + g, g m-strongly convex."""
    return {"name": "pg-plugin", "functions": {"f": f_class, "g": {"class": "strongly_convex"}},
            "parameters": {"h": {"value": "1/L"}},
            "matrices": {"A": [[1]], "B": [["-h", "-h"]], "C": [[1], [1]],
                         "D": [[0, 0], ["-h", "-h"]], "E": [[1]]},
            "oracles": ["f", "g"], "measure": "distance", "kappa": [10]}


def _write(tmp_path: Path, f_class: dict) -> Path:
    path = tmp_path / "pg-plugin.yaml"
    path.write_text(yaml.safe_dump(_prox_grad(f_class)), encoding="utf-8")
    return path


def _closed_form(kappa: float) -> float:
    """x - h grad f(x) is nonexpansive for f L-smooth convex and h <= 2/L, and the prox
    of h g is 1/(1 + hm)-Lipschitz for g m-strongly convex: rho <= 1/(1 + hm), with
    equality at f = 0, g = (m/2)|x|^2. With h = 1/L, m/L = 1/kappa: kappa/(kappa + 1)."""
    return kappa / (kappa + 1)


@pytest.mark.parametrize("kappa", [2.0, 10.0])
def test_a_new_class_analyze_rate_and_quadratic_bracket(registered, tmp_path, kappa):
    path = _write(tmp_path, {"class": registered.name})
    res = api.analyze(path, kappa, brackets="quadratic")
    rho = _closed_form(kappa)
    assert res.certified and rho - 1e-9 <= res.rho <= rho + 2e-6
    # the slowest quadratic mode: f = 0 (curvature 0 from exact_curvatures), g = m/2 x^2
    assert res.rho_lower_kind == "quadratic"
    assert rho - 1e-6 <= res.rho_lower <= rho
    peer = api.analyze(_write(tmp_path, {"class": "smooth_strongly_convex", "m": 0}), kappa)
    assert res.rho == pytest.approx(peer.rho, abs=2e-6)  # F(0, L): the same class
    check = api.verify(path, res, out_dir=tmp_path / "v")
    assert check["verified"] == "exact" and check["rho_proven_float"] >= res.rho
    assert check["simulation"]["ok"]


def test_a_new_class_through_analyze_and_verify_commands(registered, tmp_path):
    path = _write(tmp_path, {"class": registered.name})
    out = tmp_path / "o"
    res = CliRunner().invoke(cli, ["analyze", str(path), "--kappa", "10", "--json", "--quiet",
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    (row,) = doc["rows"]
    assert row["certified"] and abs(row["rho"] - _closed_form(10.0)) <= 2e-6
    result = tmp_path / "result.json"
    result.write_text(res.stdout, encoding="utf-8")
    ver = CliRunner().invoke(cli, ["verify", str(result), "--json", "--out", str(tmp_path / "v")])
    assert ver.exit_code == 0, ver.output
    (check,) = json.loads(ver.stdout)["results"]
    assert check["verified"] == "exact" and check["simulation"]["ok"]


def test_a_new_class_through_pep_and_verify(registered, tmp_path):
    """Worst case after N steps: (kappa/(kappa + 1))^(2N) |x_0 - x*|^2 (the per-step bound
    of :func:`_closed_form`, attained at every step by f = 0, g = (m/2)|x|^2)."""
    path = _write(tmp_path, {"class": registered.name})
    steps, kappa = 2, 10.0
    out = tmp_path / "p"
    res = CliRunner().invoke(cli, ["pep", str(path), "--kappa", "10", "--steps", str(steps),
                                   "--json", "--out", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    tau = _closed_form(kappa) ** (2 * steps)
    assert doc["status"] == "solved" and doc["tau"] == pytest.approx(tau, rel=1e-6)
    assert doc["certificate"]["proof"]["proven"]
    assert float(Fraction(doc["certificate"]["tau_proven"])) >= tau * (1 - 1e-12)
    direct = api.pep(path, kappa, steps)
    assert direct.tau == pytest.approx(tau, rel=1e-6)
    result = tmp_path / "pep.json"
    result.write_text(res.stdout, encoding="utf-8")
    ver = CliRunner().invoke(cli, ["verify", str(result), "--json"])
    assert ver.exit_code == 0, ver.output
    checked = json.loads(ver.stdout)
    (check,) = checked["results"]  # verify dispatched on the document's kind, pep
    assert (doc["kind"], checked["kind"], check["verified"]) == ("pep", "verification",
                                                                 "exact")


def test_unregister_keeps_the_shipped_classes():
    with pytest.raises(ValueError, match="shipped"):
        unregister_class("convex")
    assert "convex" in CLASSES


def test_a_new_class_in_the_listing(registered, tmp_path):
    """``sosalgo lmi`` lists the class by its own text, or by its description and data
    (alpha, Q) when it gives none."""
    path = _write(tmp_path, {"class": registered.name})
    text = api.lmi(path)
    assert (f"f: {registered.name} (L = L); calls y1 (gradient); for every ordered pair "
            f"(a, b) of its points: {registered.tilted_text[0]}") in text
    assert registered.tilted_text[1] in api.lmi(path, latex=True)
    plain = type(registered)()
    plain.tilted_text = None
    head = "L-smooth convex (test class): alpha (h_a - h_b) + X'QX >= 0, alpha = 2, Q = "
    listed = plain.listing_text({"L": 2.0}, latex=False)
    assert listed.startswith(head)
    Q = np.array(sp.sympify(listed[len(head):]).tolist(), dtype=float)
    assert np.array_equal(Q, [[0, 0, 0, -1], [0, 0, 0, 1], [0, 0, -0.5, 0.5], [-1, 1, 0.5, -0.5]])
