"""Hostile input: property-based fuzzing of the spec loader.

Whatever the text, ``spec_from_text`` returns a Spec or raises SpecError with a one-line
message; it never raises anything else, never hangs (HANG_GUARD: a guard far above normal
times, scaled by this machine's speed in this run; speed itself is for bench/) and never
executes code from the spec (canary payloads would create a file or set an attribute). An
accepted spec binds at each of its kappas or raises a one-line ModelError.

The number of generated cases is SOSALGO_FUZZ_EXAMPLES (total over the property tests,
default 600); ``make fuzz`` runs 20000. Generation is derandomized and database-less, so a
run is reproducible.
"""

from __future__ import annotations

import atexit
import builtins
import copy
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from sosalgo.model import Algorithm, ModelError, bind
from sosalgo.spec import (
    Spec,
    SpecError,
    load_spec,
    spec_from_dict,
    spec_from_text,
)
from sosalgo.spec.types import MAX_FILE_BYTES, MAX_PARAMETERS

from .conftest import SPECS

SOURCE = "fuzz.yaml"
NESTEROV_TEXT = (SPECS / "nesterov.yaml").read_text()
NESTEROV = yaml.safe_load(NESTEROV_TEXT)
SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*")
OUTCOME_FIELDS = {"YAML or file", "name", "description", "parameters", "matrices", "references",
                  "kappa", "m", "certificate"}

TOTAL_EXAMPLES = max(4, int(os.environ.get("SOSALGO_FUZZ_EXAMPLES", "600")))


def _baseline() -> float:
    """Seconds to load and bind the Nesterov spec here and now (best of five)."""
    best = math.inf
    for _ in range(5):
        start = time.perf_counter()
        spec = spec_from_text(NESTEROV_TEXT, SOURCE)
        for k in spec.kappa:
            bind(spec, k)
        best = min(best, time.perf_counter() - start)
    return best


# A hang guard, not a speed limit: the slowest accepted input takes ~600x the baseline
# (~2 s idle); the bugs it caught took 30-47 s. It scales with a busy machine.
HANG_GUARD = max(10.0, 3000 * _baseline())


def _examples(share: float) -> int:
    return max(1, math.ceil(TOTAL_EXAMPLES * share))


def fuzz_settings(share: float) -> settings:
    return settings(
        max_examples=_examples(share),
        deadline=None,
        derandomize=True,
        database=None,
        print_blob=True,
        suppress_health_check=[
            HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much
        ],
    )


# --------------------------------------------------------------------------- canary
# Payloads that would leave a trace if anything in them ever ran: a file in CANARY_DIR or
# an attribute on builtins. Absolute paths, so the working directory does not matter.

CANARY_DIR = Path(tempfile.mkdtemp(prefix="sosalgo-fuzz-canary-"))
atexit.register(shutil.rmtree, CANARY_DIR, ignore_errors=True)
CANARY = CANARY_DIR / "pwned"
CANARY_ATTR = "sosalgo_fuzz_pwned"


CODE_PAYLOADS = [
    f"__import__('os').system('touch {CANARY}')",
    f"__import__('pathlib').Path('{CANARY}').touch()",
    f"open('{CANARY}', 'w')",
    f"setattr(__import__('builtins'), '{CANARY_ATTR}', 1)",
    f"exec(\"open('{CANARY}', 'w')\")",
    f"eval(\"open('{CANARY}', 'w')\")",
    f"compile('open(1)', '{CANARY}', 'eval')",
    f"(lambda: open('{CANARY}', 'w'))()",
    f"[open('{CANARY}', 'w') for _ in (1,)]",
    f"{{open('{CANARY}', 'w'): 1 for _ in (1,)}}",
    f"(_w := open('{CANARY}', 'w'))",
    f"f\"{{open('{CANARY}', 'w')}}\"",
    "().__class__.__bases__[0].__subclasses__()",
    "kappa.__class__.__init__.__globals__",
    f"getattr(__builtins__, 'open')('{CANARY}', 'w')",
    f"sympify(\"open('{CANARY}', 'w')\")",
    f"S(\"__import__('os').system('touch {CANARY}')\")",
    f"Symbol('x').__class__.__call__(open('{CANARY}', 'w'))",
    "__builtins__",
    f"breakpoint() or open('{CANARY}', 'w')",
]

YAML_TAG_PAYLOADS = [
    f"!!python/object/apply:os.system ['touch {CANARY}']",
    f"!!python/object/apply:os.system\n  args: ['touch {CANARY}']",
    f"!!python/object/apply:pathlib.Path.touch [!!python/object/apply:pathlib.Path ['{CANARY}']]",
    f"!!python/object/new:os.system ['touch {CANARY}']",
    f"!!python/object/apply:builtins.setattr [!!python/module:builtins, {CANARY_ATTR}, 1]",
    f"!!python/object/apply:builtins.exec [\"open('{CANARY}', 'w')\"]",
    f"!<tag:yaml.org,2002:python/object/apply:os.system> ['touch {CANARY}']",
    f"!python/object/apply:os.system ['touch {CANARY}']",
    "!!python/name:os.system",
    "!!python/name:builtins.eval",
    "!!python/module:os",
    "!!python/object:builtins.object {}",
    "!!python/tuple [1, 2]",
    "!!python/bytes aGVsbG8=",
    "!!binary aGVsbG8=",
    "!!binary not-base64!",
    "!!set {a, b}",
    "!!omap [a: 1, b: 2]",
    "!!pairs [a: 1, a: 2]",
    "!!timestamp 2001-12-14t21:59:43.10-05:00",
    "!!timestamp 2001-13-45",
    "!!float .nan",
    "!!float 'abc'",
    "!!int 'abc'",
    "!!int 0x",
    "!!int _",
    "!!int ''",
    "!!float ''",
    "!!bool abc",
    "!!bool ''",
    "!!timestamp abc",
    "!!timestamp ''",
    "!!str 1/L",
    "!!null ''",
    "!!bool yes",
    "!!merge <<",
    "!custom 1",
    "!<!> 1",
]


def assert_nothing_ran() -> None:
    assert not CANARY.exists(), "code from the spec was executed (canary file)"
    assert not any(CANARY_DIR.iterdir()), "code from the spec was executed (canary dir)"
    assert not hasattr(builtins, CANARY_ATTR), "code from the spec was executed (attribute)"


# --------------------------------------------------------------------------- checks


def assert_one_line(message: str) -> None:
    assert message, "empty error message"
    assert "\n" not in message and "\r" not in message, repr(message)
    assert len(message.splitlines()) == 1, repr(message)


def check_accepted(spec: Spec) -> None:
    """What an accepted spec promises: a file-name-safe name and bindable kappas."""
    start = time.perf_counter()
    assert SAFE_NAME.fullmatch(spec.name), repr(spec.name)
    assert ".." not in spec.name and "/" not in spec.name and "\\" not in spec.name
    assert Path(spec.name).name == spec.name
    spec.description.encode("utf-8")  # writable wherever the description is shown
    for ref in spec.references:
        assert ref.isprintable(), repr(ref)
    assert spec.kappa and all(math.isfinite(k) and k > 1 for k in spec.kappa)
    assert math.isfinite(spec.m) and spec.m > 0
    assert all(math.isfinite(spec.mL(k)[1]) for k in spec.kappa)
    for k in spec.kappa:
        try:
            alg = bind(spec, k)
        except ModelError as exc:
            assert_one_line(str(exc))
        else:
            assert isinstance(alg, Algorithm)
    elapsed = time.perf_counter() - start
    assert elapsed < HANG_GUARD, f"{elapsed:.2f} s to bind {spec.name} at {len(spec.kappa)} kappas"


def check_text(text: str, record: bool = False) -> Spec | None:
    """Load ``text``; every property of the contract. Returns the spec if accepted.

    ``record`` labels the outcome for ``--hypothesis-show-statistics`` (inside @given only).
    """
    start = time.perf_counter()
    try:
        spec = spec_from_text(text, SOURCE)
    except SpecError as exc:
        spec = None
        message = str(exc)
        top = exc.field.split(".")[0].split("[")[0]
        if top.startswith("line ") or not top:
            top = "YAML or file"
        outcome = f"rejected: {top if top in OUTCOME_FIELDS else 'other field'}"
    else:
        outcome = "accepted"
    elapsed = time.perf_counter() - start
    assert elapsed < HANG_GUARD, f"{elapsed:.2f} s for {text[:200]!r}"
    assert_nothing_ran()
    if record:
        event(outcome)
    if spec is None:
        assert_one_line(message)
        assert message.startswith(f"{SOURCE}:"), message
    else:
        check_accepted(spec)
    return spec


def check_data(data: object, record: bool = False) -> None:
    """Check a parsed tree both as YAML text and through spec_from_dict."""
    text = dump(data)
    if text is not None:
        check_text(text, record=record)
    start = time.perf_counter()
    try:
        spec = spec_from_dict(data, SOURCE)
    except SpecError as exc:
        assert_one_line(str(exc))
    else:
        check_accepted(spec)
    assert time.perf_counter() - start < HANG_GUARD
    assert_nothing_ran()


def dump(data: object) -> str | None:
    try:
        return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=10**6)
    except (yaml.YAMLError, UnicodeError, RecursionError):
        return None


# --------------------------------------------------------------------------- strategies

VALID_NAMES = ["h", "beta", "gamma", "m", "L", "kappa", "pi"]
INVALID_NAMES = [
    "eta", "x", "rho", "lambda_", "__import__", "open", "eval", "exec", "os", "sys",
    "__builtins__", "__class__", "self", "print", "getattr", "sympify", "S", "E", "I", "oo",
    "nan", "inf", "zoo", "None", "True", "Symbol", "Integer", "ℎ", "β", "ｈ", "kappa\u200b",
    "\u202ekappa", "𝐿", "ĸappa", "Kappa", "_", "h_",
]
FUNCTION_NAMES = [
    "sqrt", "exp", "log", "abs", "min", "max", "__import__", "open", "eval", "exec",
    "compile", "getattr", "setattr", "globals", "locals", "vars", "print", "input", "sympify",
    "S", "Symbol", "type", "object", "sin", "cos", "pow", "round", "int", "float", "lambda_",
]
NUMBER_TEXTS = [
    "0", "1", "-1", "2", "0.5", ".5", "5.", "1e308", "1.7976931348623157e308", "1e-320",
    "5e-324", "1e999", "-1e999", "1e-999", "10**400", "10**64", "2**64", "10**-400",
    "1" + "0" * 400, "0." + "0" * 400 + "1", "1_000", "0x1F", "0o17", "0b101", "1j", "2e",
    "1e+", "nan", "inf", "-inf", "NaN", "Infinity", "00", "007", "1.0e-5", "9" * 30,
    "3.14159265358979323846264338327950288", "0.1e1000000",
]
STRING_LITERALS = ["'abc'", '"x"', "b'x'", "''", "r'\\n'", "u'h'", "'''x'''", "..."]
BINOPS = ["+", "-", "*", "/", "**", "//", "%", "@", "^", "&", "|", "<<", ">>", "==", "<",
          ">=", "!=", "and", "or", "is", "in", "not in"]
UNARY = ["-", "+", "~", "not "]
ATTRIBUTES = ["__class__", "__dict__", "real", "args", "func", "evalf", "subs", "__globals__"]

atoms = st.one_of(
    st.sampled_from(NUMBER_TEXTS),
    st.integers(-(10**6), 10**6).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(VALID_NAMES),
    st.sampled_from(INVALID_NAMES),
    st.sampled_from(STRING_LITERALS),
    st.sampled_from(CODE_PAYLOADS),
)


def _extend(e: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    return st.one_of(
        st.tuples(e, st.sampled_from(BINOPS), e).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(e, st.sampled_from(BINOPS[:5]), e).map(lambda t: f"{t[0]} {t[1]} {t[2]}"),
        st.tuples(st.sampled_from(UNARY), e).map(lambda t: f"{t[0]}{t[1]}"),
        st.tuples(st.sampled_from(FUNCTION_NAMES), st.lists(e, max_size=4)).map(
            lambda t: f"{t[0]}({', '.join(t[1])})"
        ),
        st.tuples(st.sampled_from(FUNCTION_NAMES), e).map(lambda t: f"{t[0]}(x={t[1]})"),
        st.tuples(st.sampled_from(FUNCTION_NAMES), e).map(lambda t: f"{t[0]}(*{t[1]})"),
        st.tuples(e, st.sampled_from(ATTRIBUTES)).map(lambda t: f"{t[0]}.{t[1]}"),
        st.tuples(e, e).map(lambda t: f"{t[0]}[{t[1]}]"),
        st.tuples(e, e).map(lambda t: f"{t[0]}[{t[1]}:]"),
        e.map(lambda x: f"(lambda: {x})()"),
        e.map(lambda x: f"lambda _y: {x}"),
        e.map(lambda x: f"[{x} for _ in (1, 2)]"),
        e.map(lambda x: f"{{{x} for _ in ()}}"),
        e.map(lambda x: f"({x} for _ in ())"),
        e.map(lambda x: f"f'{{{x}}}'"),
        e.map(lambda x: f"(_w := {x})"),
        e.map(lambda x: f"({x}, {x})"),
        e.map(lambda x: f"[{x}]"),
        e.map(lambda x: f"{{{x}: 1}}"),
        e.map(lambda x: f"await {x}"),
        e.map(lambda x: f"(yield {x})"),
        st.tuples(e, e, e).map(lambda t: f"({t[0]} if {t[1]} else {t[2]})"),
    )


expressions = st.recursive(atoms, _extend, max_leaves=10)

# Expressions inside the grammar, so that many specs are accepted and reach the numeric checks.
valid_atoms = st.one_of(
    st.sampled_from(["m", "L", "kappa", "pi", "h", "beta", "gamma"]),
    st.integers(-20, 20).map(str),
    st.floats(-1e3, 1e3, allow_nan=False).map(repr),
    st.sampled_from(NUMBER_TEXTS[:12]),
)


def _valid_extend(e: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    return st.one_of(
        st.tuples(e, st.sampled_from(BINOPS[:5]), e).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        e.map(lambda x: f"-{x}"),
        st.tuples(st.sampled_from(["sqrt", "exp", "log", "abs"]), e).map(
            lambda t: f"{t[0]}({t[1]})"
        ),
        st.tuples(st.sampled_from(["min", "max"]), st.lists(e, min_size=2, max_size=3)).map(
            lambda t: f"{t[0]}({', '.join(t[1])})"
        ),
    )


valid_expressions = st.recursive(valid_atoms, _valid_extend, max_leaves=8)

WRAPPERS = ["(", "-", "+", "sqrt(", "exp(", "log(", "abs(", "max(1, ", "min(kappa, ", "-(", "~"]


@st.composite
def deep_expressions(draw: st.DrawFn) -> str:
    """An expression nested up to ~600 levels (the parser and converter must refuse it)."""
    inner = draw(st.one_of(st.sampled_from(VALID_NAMES + NUMBER_TEXTS[:8]), expressions))
    depth = draw(st.one_of(st.integers(0, 70), st.integers(0, 600)))
    wrapper = draw(st.sampled_from(WRAPPERS))
    closing = ")" if wrapper.endswith("(") or wrapper.endswith(", ") else ""
    return wrapper * depth + inner + closing * depth


HOSTILE_STRINGS = [
    "", " ", "\t", "\n", "\x00", "a\x00b", "\ufeff", "\u202e", "\u2028", "\x85", "\ud800",
    "\udcff", "\U0001f600", "שלום", "مرحبا", "../../x", "..", ".", "/etc/passwd", "a/b",
    "a\\b", "C:\\x", "nesterov\n", "~", "null", "*a", "&a", "!a",
    "%x", "{{", "}}", "<<", "- x", "? x", ": x", "#", "'", '"', "`", "\x1b[31m",
]
# Long strings are built on demand (sampling them directly makes hypothesis' reprs huge).
LONG_STRINGS = [("x", 100_000), ("é", 1000), ("(", 600), ("1", 5000), ("\u202e", 300)]
long_strings = st.sampled_from(range(len(LONG_STRINGS))).map(
    lambda i: LONG_STRINGS[i][0] * LONG_STRINGS[i][1]
)

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.integers(-(10**400), 10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e308, -1e308, 1e-320, 5e-324, math.inf, -math.inf, math.nan]),
    st.text(max_size=20),
    st.sampled_from(HOSTILE_STRINGS),
    long_strings,
    expressions,
)
KEY_CHOICES = sorted(
    {"name", "description", "parameters", "matrices", "references", "kappa", "m", "certificate",
     "value", "range", "from", "to", "points", "scale", "A", "B", "C", "E", "h", "beta",
     "gamma"}
)
keys = st.one_of(st.sampled_from(KEY_CHOICES), st.text(max_size=8), st.integers(), st.booleans(),
                 st.none(), st.floats(allow_nan=False))
trees = st.recursive(
    scalars,
    lambda c: st.lists(c, max_size=4) | st.dictionaries(keys, c, max_size=4),
    max_leaves=16,
)
top_levels = st.one_of(
    trees,
    st.fixed_dictionaries(
        {"name": st.one_of(st.just("fuzz"), trees)},  # a valid name gets past the first check
        optional={k: st.one_of(trees, valid_expressions)
                  for k in ("description", "parameters", "matrices", "references", "kappa",
                            "m", "certificate")},
    ),
)


def _nodes(tree: Any, out: list[tuple[Any, Any]]) -> list[tuple[Any, Any]]:
    """(container, key) of every node below ``tree``."""
    if isinstance(tree, dict):
        for key, val in tree.items():
            out.append((tree, key))
            _nodes(val, out)
    elif isinstance(tree, list):
        for i, val in enumerate(tree):
            out.append((tree, i))
            _nodes(val, out)
    return out


def _containers(tree: Any, out: list[Any]) -> list[Any]:
    if isinstance(tree, dict | list):
        out.append(tree)
        for val in tree.values() if isinstance(tree, dict) else tree:
            _containers(val, out)
    return out


replacements = st.one_of(scalars, trees, valid_expressions, deep_expressions(),
                         st.sampled_from(CODE_PAYLOADS))


@st.composite
def mutated_nesterov(draw: st.DrawFn) -> dict:
    """The shipped nesterov spec with 1-4 random replacements, deletions and additions."""
    data = copy.deepcopy(NESTEROV)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["replace", "replace", "delete", "add"]))
        if op == "add":
            container = draw(st.sampled_from(_containers(data, [])))
            if isinstance(container, dict):
                container[draw(keys)] = draw(replacements)
            else:
                container.insert(draw(st.integers(0, len(container))), draw(replacements))
            continue
        nodes = _nodes(data, [])
        if not nodes:
            break
        container, key = draw(st.sampled_from(nodes))
        if op == "replace":
            container[key] = draw(replacements)
        elif isinstance(container, dict):
            del container[key]
        else:
            container.pop(key)
    return data


EXPRESSION_SLOTS: list[tuple[Any, ...]] = [
    ("parameters", "h", "value"), ("parameters", "h", "range", 0),
    ("parameters", "h", "range", 1), ("parameters", "beta", "value"),
    ("parameters", "beta", "range", 1), ("parameters", "gamma"),
    ("matrices", "A", 0, 0), ("matrices", "A", 1, 0), ("matrices", "A", 1, 1),
    ("matrices", "B", 1, 0), ("matrices", "C", 0, 0), ("matrices", "E", 0, 1),
    ("references", "Nesterov's bound"), ("kappa",), ("kappa", 0), ("m",),
]


@st.composite
def nesterov_with_expression(draw: st.DrawFn) -> dict:
    """The nesterov spec with a generated expression (or two) in expression slots."""
    data = copy.deepcopy(NESTEROV)
    for _ in range(draw(st.integers(1, 2))):
        slot = draw(st.sampled_from(EXPRESSION_SLOTS))
        expr = draw(st.one_of(valid_expressions, expressions, deep_expressions(),
                              st.sampled_from(CODE_PAYLOADS)))
        target: Any = data
        for part in slot[:-1]:
            target = target[part]
        if isinstance(target, list | dict):  # ("kappa", 0) after ("kappa",) was replaced
            target[slot[-1]] = expr
    return data


TEXT_SNIPPETS = [
    *YAML_TAG_PAYLOADS,
    "&a [1, 2]", "*a", "&a 1/L", "&x", "*undefined", "<<: {name: x}", "<<: *a", "? [a, b]",
    "? {a: 1}", "[", "]", "{", "}", "'", '"', "\"\\ud800\"", "\"\\0\"", "\"\\x00\"", "\"\\N\"",
    "\"\\u2028\"", "\"\\U0001F600\"", "\"a\\nb\"", "|\n  multi\n  line", ">\n  folded", "\t",
    "\x00", "\ufeff", "\ud800", "%YAML 1.1", "%TAG ! tag:yaml.org,2002:python/", "---", "...",
    "- - -", ": :", "name: dup", "kappa: [2]", "parameters: {}", "matrices: {}", "1e999",
    ".nan", ".inf", "-.inf", ".NaN", "0x1F", "0o17", "1:30:00", "2001-12-14", "~", "null",
    "yes", "on", "=",
]
LONG_SNIPPETS = [
    ("1", 5000, ""), ("x", 100_000, ""), ("[", 1000, "]"), ("{a: ", 300, "}"), ("- ", 500, ""),
    ("&a [", 200, "]"),
]
long_snippets = st.sampled_from(range(len(LONG_SNIPPETS))).map(
    lambda i: LONG_SNIPPETS[i][0] * LONG_SNIPPETS[i][1] + LONG_SNIPPETS[i][2] * LONG_SNIPPETS[i][1]
)
snippets = st.one_of(st.sampled_from(TEXT_SNIPPETS), long_snippets)


@st.composite
def mutated_text(draw: st.DrawFn) -> str:
    """The nesterov text with snippets inserted, values replaced, or raw random text."""
    kind = draw(st.sampled_from(["insert", "value", "random", "splice"]))
    lines = NESTEROV_TEXT.splitlines()
    if kind == "random":
        return draw(st.text(max_size=300))
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(lines) - 1))
        if kind == "insert":
            snippet = draw(snippets)
            indent = draw(st.sampled_from(["", "  ", "    "]))
            key = draw(st.sampled_from(["", "name: ", "x: ", "h: ", "A: ", "kappa: ", "m: "]))
            lines.insert(i, f"{indent}{key}{snippet}")
        elif kind == "value":
            head, sep, _ = lines[i].partition(": ")
            snippet = draw(st.one_of(snippets, expressions))
            lines[i] = f"{head}{sep or ': '}{snippet}"
        else:
            pos = draw(st.integers(0, len(lines[i])))
            lines[i] = lines[i][:pos] + draw(st.text(max_size=10)) + lines[i][pos:]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- properties


@fuzz_settings(0.2)
@given(top_levels)
def test_random_trees(data):
    check_data(data, record=True)


@fuzz_settings(0.3)
@given(mutated_nesterov())
def test_mutated_nesterov(data):
    check_data(data, record=True)


@fuzz_settings(0.3)
@given(nesterov_with_expression())
def test_random_expressions_in_nesterov(data):
    check_data(data, record=True)


@fuzz_settings(0.2)
@given(mutated_text())
def test_mutated_yaml_text(text):
    check_text(text, record=True)


def test_unmodified_nesterov_is_accepted():
    """The mutations start from a valid spec (otherwise the fuzzing would be shallow)."""
    assert check_text(NESTEROV_TEXT) is not None
    check_data(copy.deepcopy(NESTEROV))


# --------------------------------------------------------------------------- explicit cases


def _set(path: tuple[Any, ...], value: Any) -> str:
    data = copy.deepcopy(NESTEROV)
    target: Any = data
    for part in path[:-1]:
        target = target[part]
    target[path[-1]] = value
    text = dump(data)
    assert text is not None
    return text


def _replace(old: str, new: str) -> str:
    assert old in NESTEROV_TEXT
    return NESTEROV_TEXT.replace(old, new, 1)


H_VALUE = ("parameters", "h", "value")
BILLION_LAUGHS = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
    for p, c in zip("abcdefgh", "bcdefghi", strict=True)
)
DENSE_LIST = "[" + ",".join(["1"] * ((MAX_FILE_BYTES - 200) // 2)) + "]"

HOSTILE = {
    # numbers
    "huge-float": _set(H_VALUE, 1e308),
    "tiny-float": _set(H_VALUE, 1e-320),
    "huge-int-text": _set(H_VALUE, "10**400"),
    "huge-int-digits": _replace("1/L, range", "1" + "0" * 400 + ", range"),
    "5000-digit-int": _replace("1/L, range", "1" * 5000 + ", range"),
    "1e999-yaml": _replace("1/L, range", "1e999, range"),
    "1e999-string": _set(H_VALUE, "1e999"),
    "nan-yaml": _replace("1/L, range", ".nan, range"),
    "inf-yaml": _replace("1/L, range", ".inf, range"),
    "nan-string": _set(H_VALUE, "nan"),
    "inf-string": _set(H_VALUE, "inf"),
    "m-nan": NESTEROV_TEXT + "m: .nan\n",
    "m-inf": NESTEROV_TEXT + "m: -.inf\n",
    "m-tiny": NESTEROV_TEXT + "m: 1e-320\n",
    "kappa-inf": _replace("kappa: [2, 5, 10, 20, 50, 100]", "kappa: [2, .inf]"),
    "kappa-nan-range": _replace("kappa: [2, 5, 10, 20, 50, 100]",
                                "kappa: {from: .nan, to: 10, points: 3}"),
    "kappa-huge-points": _replace("kappa: [2, 5, 10, 20, 50, 100]",
                                  "kappa: {from: 2, to: 10, points: 1000000000000}"),
    "kappa-10000-points": _replace("kappa: [2, 5, 10, 20, 50, 100]",
                                   "kappa: {from: 1.5, to: 1e300, points: 10000}"),
    "power-tower": _set(H_VALUE, "10**10**10**10"),
    "exp-tower": _set(H_VALUE, "exp(exp(exp(exp(100))))"),
    # nesting
    "list-1000-deep": NESTEROV_TEXT + "x: " + "[" * 1000 + "]" * 1000 + "\n",
    "list-1000-deep-matrix": _replace("E: [[0, 1]]", "E: " + "[" * 1000 + "]" * 1000),
    "dict-1000-deep": "a: " + "{a: " * 1000 + "1" + "}" * 1000 + "\n",
    "block-500-deep": "".join("  " * i + "a:\n" for i in range(500)) + "  " * 500 + "1\n",
    "expr-500-parens": _set(H_VALUE, "(" * 500 + "1/L" + ")" * 500),
    "expr-500-sqrt": _set(H_VALUE, "sqrt(" * 500 + "L" + ")" * 500),
    "expr-500-minus": _set(H_VALUE, "-" * 500 + "L"),
    "expr-500-power": _set(H_VALUE, "**".join(["L"] * 500)),
    "tie-chain-1000": _replace(
        "  gamma: beta",
        "  gamma: beta\n" + "".join(f"  p{i}: p{i + 1}\n" for i in range(1000)) + "  p1000: 1",
    ),
    # sizes
    "long-description": _set(("description",), "x" * 60_000),
    "long-string-100k": _set(("description",), "x" * 100_000),
    "long-expression": _set(H_VALUE, "+".join(["L"] * 50_000)),
    "long-name": _set(("name",), "a" * 100_000),
    "long-key": NESTEROV_TEXT + "k" * 100_000 + ": 1\n",
    "dense-list-at-limit": NESTEROV_TEXT + "x: " + DENSE_LIST[: MAX_FILE_BYTES - 1000] + "1]\n",
    "many-parameters": _replace(
        "  gamma: beta", "  gamma: beta\n" + "".join(f"  p{i}: {i}\n" for i in range(200))
    ),
    # unicode
    "unicode-name": _set(("name",), "nesterov-β"),
    "rtl-name": _set(("name",), "\u202enesterov"),
    "nul-name": _set(("name",), "nes\x00terov"),
    "nul-raw": NESTEROV_TEXT + "\x00",
    "surrogate-raw": NESTEROV_TEXT + "\ud800",
    "surrogate-escape": NESTEROV_TEXT.replace("name: nesterov", 'name: "\\ud800"'),
    "surrogate-description": _replace("description: Nesterov", 'description: "\\udcff Nesterov'
                                      "\"\n#"),
    "unicode-parameter": _replace("gamma: beta", "γ: beta"),
    "nfkc-parameter": _set(H_VALUE, "ｈ"),
    "bom": "\ufeff" + NESTEROV_TEXT,
    "crlf": NESTEROV_TEXT.replace("\n", "\r\n"),
    "tabs": NESTEROV_TEXT.replace("  ", "\t"),
    # YAML features
    "duplicate-top-key": NESTEROV_TEXT + "name: other\n",
    "duplicate-param": _replace("  gamma: beta", "  gamma: beta\n  gamma: 0"),
    "duplicate-equal-keys": "1: a\n1.0: b\n",
    "billion-laughs": BILLION_LAUGHS,
    "anchor-alias": _replace("range: [0, 1]", "range: &r [0, 1]") + "x: *r\n",
    "merge-key": NESTEROV_TEXT + "<<: {colour: red}\n",
    "complex-key": "? [a, b]\n: 1\n",
    "set-key": "? !!set {a}\n: 1\n",
    "multi-document": NESTEROV_TEXT + "---\n" + NESTEROV_TEXT,
    "directive": "%YAML 1.1\n---\n" + NESTEROV_TEXT,
    "tag-directive": "%TAG !p! tag:yaml.org,2002:python/\n---\nname: !p!object/apply:os.system "
                     f"['touch {CANARY}']\n",
    # names and paths
    "path-escape": _set(("name",), "../../x"),
    "path-escape-dots": _set(("name",), "a..b"),
    "absolute-name": _set(("name",), "/etc/passwd"),
    "slash-name": _set(("name",), "a/b"),
    "backslash-name": _set(("name",), "a\\b"),
    "dot-name": _set(("name",), "."),
    "newline-name": _set(("name",), "nesterov\n"),
    "empty-name": _set(("name",), ""),
    "numeric-name": _set(("name",), 123),
    "list-name": _set(("name",), ["a"]),
    # misc structure
    "empty": "",
    "only-comment": "# nothing\n",
    "scalar": "42\n",
    "null-document": "~\n",
    "list-document": "- 1\n",
    "no-matrices": _set(("matrices",), None),
    "matrix-13x13": _set(("matrices", "A"), [[0] * 13 for _ in range(13)]),
    "ragged-matrix": _set(("matrices", "A"), [[0, 1], [1]]),
    "certificate-list": NESTEROV_TEXT + "certificate: [theorem1]\n",
    "certificate-dict": NESTEROV_TEXT + "certificate: {a: 1}\n",
    "certificate-int": NESTEROV_TEXT + "certificate: 1\n",
}
HOSTILE.update({f"code-{i}": _set(H_VALUE, p) for i, p in enumerate(CODE_PAYLOADS)})
HOSTILE.update({
    f"tag-{i}": _replace("1/L, range", f"{p}, range") if "\n" not in p
    else NESTEROV_TEXT + f"x: {p}\n"
    for i, p in enumerate(YAML_TAG_PAYLOADS)
})
HOSTILE.update({
    f"tag-name-{i}": f"name: {p}\n" for i, p in enumerate(YAML_TAG_PAYLOADS)
})

MUST_REJECT = {
    "path-escape", "path-escape-dots", "absolute-name", "slash-name", "backslash-name",
    "newline-name", "nul-name", "rtl-name", "empty-name", "numeric-name", "list-name",
    "billion-laughs", "duplicate-top-key", "duplicate-param", "anchor-alias", "5000-digit-int",
    "power-tower", "exp-tower", "many-parameters", "long-string-100k", "surrogate-escape",
    "surrogate-description", "certificate-list", "certificate-dict", "certificate-int",
    "1e999-yaml", "nan-yaml", "inf-yaml", "kappa-inf", "kappa-nan-range", "kappa-huge-points",
    "huge-int-digits", "matrix-13x13", "dict-1000-deep", "list-1000-deep-matrix",
    *(k for k in HOSTILE if k.startswith(("code-", "tag-name-"))),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_inputs(case):
    spec = check_text(HOSTILE[case])
    if case in MUST_REJECT:
        assert spec is None, f"{case} was accepted"


# --------------------------------------------------------------------------- regressions
# Bugs found by this fuzzer, each with the field the error must name.

REGRESSIONS = {
    # SpecError messages spanning several lines (YAML keys and strings were echoed verbatim)
    "newline-in-key": (NESTEROV_TEXT + '"a\\nb": 1\n', "a\\nb: unknown field"),
    "line-separator-in-key": (NESTEROV_TEXT + '"a\\u2028b": 1\n', "a\\u2028b: unknown field"),
    "newline-in-range": (_set(("parameters", "beta", "range"), ["(1\n)", 0]),
                         "parameters.beta.range"),
    "surrogate-in-key": (NESTEROV_TEXT + '"\\ud800": 1\n', "\\ud800: unknown field"),
    # NAME_RE.match accepted a trailing newline ('$' matches before it)
    "name-trailing-newline": (_set(("name",), "nesterov\n"), "name:"),
    "parameter-trailing-newline": (_replace("  gamma: beta", '  "gamma\\n": beta'),
                                   "not a valid parameter name"),
    # unhashable certificate: TypeError
    "certificate-unhashable-list": (NESTEROV_TEXT + "certificate: [1]\n", "certificate"),
    "certificate-unhashable-dict": (NESTEROV_TEXT + "certificate: {a: 1}\n", "certificate"),
    # names/text that cannot be written out (CSV column, console): accepted before
    "reference-name-surrogate": (_replace('"quadratic lower bound"', '"\\ud800 lower bound"'),
                                 "references."),
    "reference-name-nul": (_replace('"quadratic lower bound"', '"\\0 lower bound"'),
                           "references."),
    "reference-name-line-separator": (_replace('"quadratic lower bound"', '"a\\u2028b"'),
                                      "references."),
    "description-surrogate": (_replace("description: Nesterov's", 'description: "\\ud800"\n#'),
                              "description"),
    # hangs: sympy's arbitrary-precision evalf of exp towers never finished
    "exp-tower-value": (_set(H_VALUE, "exp(exp(exp(exp(100))))"), "parameters.h.value"),
    "exp-tower-m": (NESTEROV_TEXT + "m: exp(exp(exp(exp(100))))\n", "m:"),
    "exp-tower-kappa": (_replace("kappa: [2, 5, 10, 20, 50, 100]",
                                 "kappa: exp(exp(exp(exp(100))))"), "kappa"),
    "exp-tower-reference": (_set(("references", "Nesterov's bound"), "exp(exp(exp(100)))"),
                            "references.Nesterov's bound"),
    "exp-tower-in-division": (_set(H_VALUE, "1/(exp(exp(exp(exp(100)))) - 1)"),
                              "parameters.h.value"),
    "exp-tower-in-max": (_set(H_VALUE, "max(exp(exp(exp(exp(100)))), 1)"),
                         "parameters.h.value"),
    # huge constant printed in full (1200 digits) in the message
    "huge-constant-message": (_set(H_VALUE, "*".join(["10**60"] * 20)), "parameters.h.value"),
    # too many parameters: quadratic compile time (seconds)
    "too-many-parameters": (_replace("  gamma: beta", "  gamma: beta\n" + "".join(
        f"  p{i}: {i}\n" for i in range(MAX_PARAMETERS))), "parameters: more than"),
    # PyYAML constructors raised AttributeError, KeyError, IndexError on tagged scalars
    "tagged-timestamp": (NESTEROV_TEXT + "x: !!timestamp abc\n", "invalid !!timestamp value"),
    "tagged-bool": (NESTEROV_TEXT + "x: !!bool abc\n", "invalid !!bool value"),
    "tagged-empty-bool": (NESTEROV_TEXT + "x: !!bool\n", "invalid !!bool value"),
    "tagged-int": (_replace("1/L, range", "!!int _, range"), "invalid !!int value"),
    "tagged-empty-float": (NESTEROV_TEXT + "m: !!float ''\n", "invalid !!float value"),
    "tagged-in-list": (_replace("kappa: [2,", "kappa: [!!bool x,"), "invalid !!bool value"),
    # L = kappa * m overflowed to inf and the spec was accepted
    "infinite-L": (_replace("kappa: [2, 5, 10, 20, 50, 100]", "kappa: [1e10]") + "m: 1e300\n",
                   "kappa: L = kappa * m overflows"),
    # more than 64 kB of YAML: PyYAML's pure-Python parser took > 10 s on 600 kB
    "oversized-text": (NESTEROV_TEXT + "x: " + DENSE_LIST + "\n", "longer than"),
}

# Inputs that take far more than HANG_GUARD seconds without their guard; each must be fast.
SLOW_UNGUARDED = {
    # sympy Max/Min evaluation compares all pairs (47 s for 200 arguments)
    "max-200-arguments": _set(("references", "Nesterov's bound"), "max(" + ", ".join(
        f"kappa**{i % 5 + 1}/{i + 1}" for i in range(200)) + ")"),
    "max-in-matrix": _set(("matrices", "B"), [[0], ["-h + 0*max(" + ", ".join(
        f"(kappa - {i})**{i % 3 + 1}" for i in range(40)) + ")"]]),
    # sp.simplify of the range difference (30 s)
    "range-simplify": _set(("parameters", "h", "range", 1), "+".join(
        f"(sqrt(kappa)+{i})**{i % 7 + 2}/(L+{i})**3" for i in range(20))),
    # every reference and range was recompiled at every kappa (5 s for 10000 kappas)
    "kappa-10000-points": _replace("kappa: [2, 5, 10, 20, 50, 100]",
                                   "kappa: {from: 1.5, to: 1000, points: 10000}"),
    "parameters-at-limit": _replace("  gamma: beta", "  gamma: beta\n" + "".join(
        f"  p{i}: kappa*p{i + 1}\n" for i in range(MAX_PARAMETERS - 4)) +
        f"  p{MAX_PARAMETERS - 4}: 1"),
}


@pytest.mark.parametrize("case", sorted(REGRESSIONS))
def test_fuzzer_findings_are_refused_naming_their_field(case):
    text, expected = REGRESSIONS[case]
    assert check_text(text) is None, f"{case} was accepted"
    with pytest.raises(SpecError) as err:
        spec_from_text(text, SOURCE)
    assert expected in str(err.value), str(err.value)
    assert len(str(err.value)) < 1000


@pytest.mark.parametrize("case", sorted(SLOW_UNGUARDED))
def test_unguarded_slow_inputs_are_fast(case):
    check_text(SLOW_UNGUARDED[case])


def test_many_kappas_cost_linear_time():
    """Loading and binding 10 000 kappas costs about 20x 500 kappas (linear), not more
    (every reference and range was once recompiled at every kappa): a complexity check in
    one run, with a factor 4 of margin for a busy machine (quadratic cost would be 400x)."""
    def best(points: int) -> float:
        text = _replace("kappa: [2, 5, 10, 20, 50, 100]",
                        f"kappa: {{from: 1.5, to: 1000, points: {points}}}")
        times = []
        for _ in range(3):
            start = time.perf_counter()
            check_text(text)
            times.append(time.perf_counter() - start)
        return min(times)

    assert best(10_000) <= 80 * best(500)


def test_min_max_still_evaluate_numerically():
    text = _set(H_VALUE, "min(1/L, max(0.5/L, 2/L))")
    spec = check_text(text)
    assert spec is not None
    assert bind(spec, 10.0).B[1, 0] == pytest.approx(-0.1)


def test_load_spec_reads_a_bounded_amount():
    """/dev/zero has no size on disk: reading it whole never ended (regression)."""
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero")
    start = time.perf_counter()
    with pytest.raises(SpecError, match="larger than"):
        load_spec("/dev/zero")
    assert time.perf_counter() - start < HANG_GUARD


def test_load_spec_on_hostile_files(tmp_path):
    cases = {
        "latin1.yaml": "name: caf\xe9\n".encode("latin-1"),
        "big.yaml": b"# " + b"x" * (MAX_FILE_BYTES + 10) + b"\n",
        "nul.yaml": b"name: a\x00\n",
        "bom.yaml": b"\xef\xbb\xbf" + NESTEROV_TEXT.encode(),
    }
    for name, content in cases.items():
        (tmp_path / name).write_bytes(content)
    (tmp_path / "dir.yaml").mkdir()
    for name in [*cases, "dir.yaml", "missing.yaml"]:
        path = tmp_path / name
        try:
            load_spec(path)
        except SpecError as exc:
            assert_one_line(str(exc))
            assert str(exc).startswith(str(path)), str(exc)
    assert_nothing_ran()


# --------------------------------------------------------------------------- CLI

CLI_CASES = {
    "python-tag": f"name: !!python/object/apply:os.system ['touch {CANARY}']\n",
    "code-in-expression": _set(H_VALUE, CODE_PAYLOADS[1]),
    "newline-key": NESTEROV_TEXT + '"a\\nb\\rc": 1\n',
    "exp-tower": _set(H_VALUE, "exp(exp(exp(exp(100))))"),
    "surrogate-reference": _replace('"quadratic lower bound"', '"\\ud800"'),
    "billion-laughs": BILLION_LAUGHS,
}


def test_cli_refuses_hostile_files(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    env.pop("SOSALGO_DEBUG", None)
    for case, text in CLI_CASES.items():
        spec = tmp_path / f"{case}.yaml"
        spec.write_text(text, encoding="utf-8")
        out = tmp_path / f"out-{case}"
        proc = subprocess.run(
            [sys.executable, "-m", "sosalgo.cli", "analyze", str(spec), "--out", str(out)],
            capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120,
        )
        assert proc.returncode == 2, (case, proc.stderr)
        lines = proc.stderr.splitlines()
        assert len(lines) == 1, (case, proc.stderr)
        assert lines[0].startswith("error: ") and str(spec) in lines[0], (case, lines[0])
        assert "Traceback" not in proc.stderr
        assert proc.stdout == ""
        assert not out.exists(), case
        assert_nothing_ran()
