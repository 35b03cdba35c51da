"""Safe expression parsing: grammar, whitelist, refusal of code."""

from __future__ import annotations

import pytest
import sympy as sp

from sosalgo.kernel.expr import ExprError, constant_value, parse_expression, parse_tree, to_sympy
from sosalgo.kernel.expr.compile import NumericError, compile_expression

K, H = sp.symbols("kappa h")
NAMES = {"kappa": K, "h": H}


@pytest.mark.parametrize(
    "text, expected",
    [
        ("(sqrt(kappa) - 1)/(sqrt(kappa) + 1)", (sp.sqrt(K) - 1) / (sp.sqrt(K) + 1)),
        ("2*h**2 - h/3", 2 * H**2 - H / 3),
        ("-h", -H),
        ("max(h, 1) + min(kappa, 2, 3)", sp.Max(H, 1) + sp.Min(K, 2)),
        ("exp(log(kappa)) + abs(-2) + pi", K + 2 + sp.pi),
        ("0.5", sp.Rational(1, 2)),
        (3, sp.Integer(3)),
    ],
)
def test_parses_whitelisted_grammar(text, expected):
    assert sp.simplify(parse_expression(text, NAMES) - expected) == 0


@pytest.mark.parametrize(
    "text",
    [
        "__import__('os').system('touch x')",
        "h.__class__",
        "[h for h in ()]",
        "lambda: 1",
        "open('x')",
        "eval('1')",
        "h[0]",
        "'abc'",
        "h if kappa else 1",
        "h == 1",
        "sqrt(h, kappa)",
        "sqrt",
        "unknown + 1",
        "h ^ 2",
        "1/0",
        "10**10**10",
        "(" * 1000 + "1" + ")" * 1000,
        "-" * 500 + "1",
        "x" * 5000,
        "",
        "sqrt(h=1)",
    ],
)
def test_refuses_everything_else(text):
    with pytest.raises(ExprError):
        parse_expression(text, NAMES)


def test_injected_code_never_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ExprError):
        parse_expression("__import__('os').system('touch pwned')", NAMES)
    assert not (tmp_path / "pwned").exists()


def test_numeric_evaluation_matches_sympy():
    text = "(sqrt(kappa) - 1)/(sqrt(kappa) + 1) + max(h, 0.1)**2 - exp(-h)*log(kappa)/abs(-3)"
    fn = compile_expression(parse_tree(text, NAMES), ["kappa", "h"])
    expr = parse_expression(text, NAMES)
    for k, h in [(10.0, 0.3), (2.0, 0.05), (1e4, 1.0)]:
        assert fn([k, h]) == pytest.approx(float(expr.subs({K: k, H: h})), rel=1e-13)


def test_numeric_domain_errors():
    fn = compile_expression(parse_tree("sqrt(h - 2)", NAMES), ["kappa", "h"])
    with pytest.raises(NumericError):
        fn([10.0, 1.0])
    fn = compile_expression(parse_tree("1/(h - 1)", NAMES), ["kappa", "h"])
    with pytest.raises(NumericError):
        fn([10.0, 1.0])
    fn = compile_expression(parse_tree("(h - 1)**(-2)", NAMES), ["kappa", "h"])
    with pytest.raises(NumericError):
        fn([10.0, 1.0])


@pytest.mark.parametrize("text", [
    "(sqrt(kappa) - 1)/(sqrt(kappa) + 1)", "-h**2", "(-h)**2", "2**-h", "h - (kappa - 1)",
    "h/(kappa*h)", "h/kappa/2", "-(h + 1)", "max(h, -1) - min(kappa, 2, 3)", "2**3**h",
])
def test_tree_prints_an_expression_with_the_same_value(text):
    """str() of a tree parses back to the same function (parentheses where they matter)."""
    tree = parse_tree(text, NAMES)
    again = parse_tree(str(tree), NAMES)
    f, g = (compile_expression(t, ["kappa", "h"]) for t in (tree, again))
    for k, h in [(10.0, 0.3), (2.0, 0.5)]:
        assert f([k, h]) == pytest.approx(g([k, h]), rel=1e-15)
        assert f([k, h]) == pytest.approx(float(parse_expression(text, NAMES).subs(
            {K: k, H: h})), rel=1e-13)


def test_tree_names_and_constants():
    assert parse_tree("h*kappa + sqrt(2)", NAMES).names() == {"h", "kappa"}
    assert constant_value(parse_tree("sqrt(16) + 10**2", {})) == pytest.approx(104.0)
    with pytest.raises(ExprError, match="expected a number"):
        constant_value(parse_tree("h + 1", NAMES))


@pytest.mark.parametrize("text, match", [
    ("sqrt(-1)", "not real"), ("log(0)", "log"), ("(-8)**(1/3)", "not real"),
    ("1/(2 - 2)", "division by zero"), ("0**(-1)", "division by zero"),
    ("exp(1000)", "too large"), ("1e200 * 1e200", "too large"), ("h**100", "exponent"),
])
def test_constants_are_checked_while_parsing(text, match):
    with pytest.raises(ExprError, match=match):
        parse_tree(text, NAMES)


def test_symbolic_form_is_exact():
    """0.1 is the rational 1/10 in the symbolic form (exact verification relies on it)."""
    expr = to_sympy(parse_tree("0.1*h + kappa", NAMES))
    h, kappa = sp.Symbol("h", real=True), sp.Symbol("kappa", positive=True)
    assert sp.simplify(expr - (sp.Rational(1, 10) * h + kappa)) == 0
    with pytest.raises(ExprError, match="division by zero"):
        to_sympy(parse_tree("1/(kappa - kappa)", NAMES))


def test_analysis_never_imports_sympy():
    """Numeric analysis (load, bind, analyze) runs without sympy: start-up time."""
    import subprocess
    import sys
    from pathlib import Path

    spec = Path(__file__).resolve().parents[1] / "specs" / "nesterov.yaml"
    code = ("import sys; from sosalgo.spec import load_spec; from sosalgo.analysis import "
            f"analyze_spec; r = analyze_spec(load_spec({str(spec)!r}), 10.0); "
            "assert r.certified; print('sympy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
