"""One float method, asked rather than switched on (the seam of the problem layer): no module
above the problem layer chooses code by the type of a method (``spec.composite``,
``spec.sublinear``, ``hasattr(alg, "oracles")``, ``isinstance(alg, Algorithm)``); it asks
the spec or the bound method a question with a name (``has_seed_form``,
``has_condition_number``) or a family's ``applies_to``. The seed's ``Algorithm`` is the
one float method (:class:`~sosalgo.oracles.OracleMethod`) in the seed's form."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import sosalgo
from sosalgo.analysis import analyze_algorithm, quadratic_rate
from sosalgo.classes import SEED_CLASS
from sosalgo.model import Algorithm, bind, fixed_point
from sosalgo.oracles import OracleMethod, seed_functions
from sosalgo.spec import load_spec

from .conftest import SPECS
from .test_imports import LAYERS

PACKAGE = Path(__file__).resolve().parents[1] / "sosalgo"
PROBLEM_LAYER = dict(LAYERS)["problem"]

# attributes whose only use is telling kinds of methods apart (``time_varying``: the
# problem layer answers the step-k method, :func:`sosalgo.steps.step_methods`)
SWITCH_ATTRIBUTES = {"composite", "sublinear", "time_varying"}
# fields a kind of method has and another lacks (asked by hasattr/getattr, a type switch)
METHOD_FIELDS = {"oracles", "functions", "D", "output", "p", "measure", "has_seed_form",
                 "time_varying"}
# every method type left, (module, class): the one Method over any number type
# (sosalgo.oracles.Method), its float form checked on creation (OracleMethod) and the
# seed's form built from A, B, C, E, m, L (Algorithm)
METHOD_TYPES = {("sosalgo.oracles", "Method"), ("sosalgo.oracles", "OracleMethod"),
                ("sosalgo.model", "Algorithm")}
# the data kept around the one Method, (module, class): a ``method: Method`` field and
# their own data beside it, not a method type. The PEP's frame (fixed-point basis,
# deadbeat gain, tilted inequalities, term coefficients) and its arb view
METHOD_FRAMES = {("sosalgo.worstcase.structure", "PEPFrame"),
                 ("sosalgo.worstcase.check", "ArbView")}
# names no module above the problem layer may test ``isinstance`` against: the problem
# layer's method types and the names its bindings keep for the Method over balls and
# polynomials (the PEP's arb view is a number type inside the PEP's own package)
SWITCH_TYPES = {"Method", "OracleMethod", "Algorithm", "ExactAlgorithm", "ExactOracleMethod",
                "ExactMethod"}


def _switches(text: str, where: str) -> list[str]:
    """The method-type switches in the Python source ``text``: the attributes
    :data:`SWITCH_ATTRIBUTES`, ``hasattr``/``getattr`` of a :data:`METHOD_FIELDS` name, and
    ``isinstance`` with a :data:`SWITCH_TYPES` class."""
    found = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Attribute) and node.attr in SWITCH_ATTRIBUTES:
            found.append((node.lineno, node.col_offset, f".{node.attr}"))
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
            continue
        args = node.args
        if (node.func.id in ("hasattr", "getattr") and len(args) >= 2
                and isinstance(args[1], ast.Constant) and args[1].value in METHOD_FIELDS):
            found.append((node.lineno, node.col_offset,
                          f"{node.func.id}(..., {args[1].value!r})"))
        if node.func.id == "isinstance" and len(args) == 2:
            names = {n.id if isinstance(n, ast.Name) else getattr(n, "attr", None)
                     for n in ast.walk(args[1])}
            found += [(node.lineno, node.col_offset, f"isinstance(..., {t})")
                      for t in sorted(names & SWITCH_TYPES)]
    return [f"{where}:{line}: {what}" for line, _, what in sorted(found)]


def test_no_method_type_switch_above_the_problem_layer():
    found = [hit for path in sorted(PACKAGE.rglob("*.py"))
             if path.relative_to(PACKAGE).with_suffix("").parts[0] not in PROBLEM_LAYER
             for hit in _switches(path.read_text(encoding="utf-8"),
                                  str(path.relative_to(PACKAGE.parent)))]
    assert not found, ("method-type switches outside the problem layer (ask the spec or "
                       "the method, e.g. has_seed_form):\n" + "\n".join(found))


def test_the_scan_sees_each_kind_of_switch():
    """The scan above would see each switch in code, and not the question asked instead."""
    text = ("from sosalgo.certificates.sublinear import SUBLINEAR\n"
            "if spec.composite or spec.sublinear: pass\n"
            "if hasattr(alg, 'oracles') or getattr(alg, 'p', 1) == 1: pass\n"
            "if isinstance(alg, model.Algorithm): pass\n"
            "if spec.has_seed_form and alg.has_seed_form: pass\n"
            "if spec.time_varying or getattr(spec, 'time_varying', False): pass\n"
            "from sosalgo.spec.time_varying import uses_step\n"
            "if changes_with_k(spec): pass\n")
    assert _switches(text, "probe.py") == [
        "probe.py:2: .composite", "probe.py:2: .sublinear",
        "probe.py:3: hasattr(..., 'oracles')", "probe.py:3: getattr(..., 'p')",
        "probe.py:4: isinstance(..., Algorithm)", "probe.py:6: .time_varying",
        "probe.py:6: getattr(..., 'time_varying')"]


def test_the_problem_layer_units_exist():
    """The units exempted above are modules or packages of sosalgo (a renamed one would
    silently widen the scan's blind spot otherwise)."""
    for unit in PROBLEM_LAYER:
        assert (PACKAGE / f"{unit}.py").exists() or (PACKAGE / unit).is_dir(), unit


# --------------------------------------------------------------------------- one Method


def test_the_public_algorithm_is_the_method_in_the_seed_form():
    """``sosalgo.Algorithm(A=..., ...)`` builds the one float method with one gradient call
    on f in F(m, L): D = 0, x = E xi, measure function."""
    alg = sosalgo.Algorithm(A=[[1.0]], B=[[-0.25]], C=[[1.0]], E=[[1.0]], m=1.0, L=4.0)
    assert isinstance(alg, OracleMethod) and alg.has_seed_form
    assert (alg.n, alg.p, alg.oracles, alg.output, alg.measure) == (1, 1, (0,), None,
                                                                     "function")
    (f,) = alg.functions
    assert f.cls is SEED_CLASS and f.params == {"m": 1.0, "L": 4.0}
    assert np.array_equal(alg.D, [[0.0]]) and alg.kappa == 4.0 and alg.params == {}


@pytest.mark.parametrize("name, seed", [("nesterov", True), ("gradient", True),
                                        ("proximal-gradient", False)])
def test_bind_gives_one_type_and_says_its_form(name, seed):
    spec = load_spec(SPECS / f"{name}.yaml")
    alg = bind(spec, 10.0)
    assert isinstance(alg, OracleMethod)
    assert alg.has_seed_form is seed is spec.has_seed_form
    assert isinstance(alg, Algorithm) is seed
    assert spec.has_condition_number


def test_an_m0_spec_has_no_condition_number():
    spec = load_spec(SPECS / "gradient-convex.yaml")
    assert not spec.has_condition_number and not spec.has_seed_form


def _general_form(alg: Algorithm) -> OracleMethod:
    """The same numbers written as a method of the oracle model (not the seed's form)."""
    return OracleMethod(alg.A, alg.B, alg.C, np.zeros((1, 1)), alg.E, alg.m, alg.L,
                        seed_functions(alg.m, alg.L), (0,))


def test_heavy_ball_fixed_point_and_quadratic_rate_in_both_forms():
    """Heavy ball x+ = x - h g + b (x - x-), state (x, x-): the fixed point is (1, 1); its
    rate on quadratics with Polyak's h = 4/(sqrt L + sqrt m)^2, b = ((sqrt k - 1)/(sqrt k
    + 1))^2 is sqrt(b) = (sqrt k - 1)/(sqrt k + 1) (a closed form); the seed's form and
    the oracle-model form of the same numbers give both (two codes)."""
    m, L = 1.0, 16.0
    h, b = 4 / (np.sqrt(L) + np.sqrt(m)) ** 2, ((4 - 1) / (4 + 1)) ** 2
    alg = Algorithm([[1 + b, -b], [1, 0]], [[-h], [0]], [[1, 0]], [[1, 0]], m, L)
    general = _general_form(alg)
    assert not general.has_seed_form
    for form in (alg, general):
        assert np.allclose(fixed_point(form), [1.0, 1.0], atol=1e-12)
    closed = (4 - 1) / (4 + 1)
    assert quadratic_rate(alg) == pytest.approx(closed, abs=1e-6)
    assert quadratic_rate(general) == pytest.approx(closed, abs=1e-6)


def test_gradient_descent_rate_in_both_forms():
    """Gradient descent with h = 2/(m + L) on F(m, L) has the rate (kappa - 1)/(kappa + 1)
    (a closed form, attained on a quadratic); the interpolation family certifies it on the
    seed's form (its windows on A, B, C, E) and on the oracle-model form (the generic
    construction), two codes."""
    m, L = 1.0, 10.0
    alg = Algorithm([[1.0]], [[-2 / (m + L)]], [[1.0]], [[1.0]], m, L)
    closed = (L - m) / (L + m)
    for form in (alg, _general_form(alg)):
        res = analyze_algorithm(form, family="interpolation")
        assert res.certified and closed - 1e-9 <= res.rho <= closed + 1e-4


def test_theorem1_refuses_the_oracle_model_form():
    from sosalgo.certificates import get_family
    from sosalgo.errors import InputError

    alg = Algorithm([[1.0]], [[-0.1]], [[1.0]], [[1.0]], 1.0, 10.0)
    get_family("theorem1").problem(alg)  # the seed's form: built
    with pytest.raises(InputError, match="theorem1"):
        get_family("theorem1").problem(_general_form(alg))


# --------------------------------------------------------------------------- number types


def _method_types(root: Path) -> set[tuple[str, str]]:
    """(module, class) of every class under ``root`` (a package directory) that holds a
    method's numbers: it declares the oracle model's matrices A, B, C and D, or which
    function each call queries (``oracles`` with ``functions``), or exact matrices with m
    and L; and every class derived from one of those by name. The spec package (a
    method's text, not its numbers) is left out."""
    found, bases = set(), {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent).with_suffix("")
        if rel.parts[1] == "spec":
            continue
        module = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ClassDef):
                continue
            fields = {s.target.id for s in node.body if isinstance(s, ast.AnnAssign)
                      and isinstance(s.target, ast.Name)}
            if ({"A", "B", "C", "D"} <= fields or {"oracles", "functions"} <= fields
                    or {"matrices", "m", "L"} <= fields):
                found.add((module, node.name))
            bases[(module, node.name)] = {getattr(b, "id", getattr(b, "attr", None))
                                          for b in node.bases}
    grew = True
    while grew:
        names = {name for _, name in found}
        more = {key for key, b in bases.items() if b & names} - found
        found |= more
        grew = bool(more)
    return found


def _method_frames(root: Path) -> set[tuple[str, str]]:
    """(module, class) of every class under ``root`` that holds the one Method in a field
    ``method: Method`` (data kept around a method, not a method type)."""
    found = set()
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent).with_suffix("")
        module = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef) and any(
                    isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)
                    and s.target.id == "method" and ast.unparse(s.annotation) == "Method"
                    for s in node.body):
                found.add((module, node.name))
    return found


def test_the_method_types_left():
    """Three method types are left: the one ``Method`` over any number type, its float
    form ``OracleMethod`` (checked on creation) and the seed's form ``Algorithm``. The
    exact twins (``ExactAlgorithm``, ``ExactOracleMethod``), the arb one (``ArbMethod``),
    the polynomial one (``polymodel.ExactMethod``) and the noisy model (``NoisyModel``)
    are the Method over balls, arb, polynomials and floats; the names kept are the Method
    itself. The PEP's frame and its arb view hold the Method (``method``) beside the
    PEP's own data: they declare none of a method's fields."""
    from sosalgo.design_search.polymodel import ExactMethod
    from sosalgo.exact_method import ExactAlgorithm, ExactOracleMethod
    from sosalgo.oracles import Method

    assert _method_types(PACKAGE) == METHOD_TYPES
    assert len(METHOD_TYPES) == 3
    assert ExactAlgorithm is ExactOracleMethod is ExactMethod is Method
    assert _method_frames(PACKAGE) == METHOD_FRAMES


def test_the_scan_of_method_types_sees_each_form(tmp_path):
    """The scan above finds a class by any of the three signs, and its subclasses; the
    scan of frames a class holding a ``method: Method`` field."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "m.py").write_text(
        "class Full:\n    A: int\n    B: int\n    C: int\n    D: int\n"
        "class Calls:\n    oracles: tuple\n    functions: tuple\n"
        "class Exact:\n    matrices: dict\n    m: int\n    L: int\n"
        "class Seed(Full):\n    pass\n"
        "class System:\n    A: int\n    B: int\n    C: int\n    E: int\n"
        "class Frame:\n    method: Method\n    X0: int\n"
        "class Named:\n    method: str\n")
    assert _method_types(pkg) == {("pkg.m", "Full"), ("pkg.m", "Calls"), ("pkg.m", "Exact"),
                                  ("pkg.m", "Seed")}
    assert _method_frames(pkg) == {("pkg.m", "Frame")}


def test_the_pep_frames_hold_the_one_method():
    """The PEP's float frame holds the bound float method itself; its exact frame and that
    frame's arb view hold the Method over balls and over arb, whose entries enclose
    Nesterov's method at kappa 10 (a closed form, not the spec's expressions), as the
    frames' own A, B, C, E read them."""
    from sosalgo.kernel.arb import arb_fraction
    from sosalgo.method import bind as bind_numbers
    from sosalgo.oracles import Method
    from sosalgo.worstcase.check import arb_view
    from sosalgo.worstcase.core import float_method
    from sosalgo.worstcase.exact import exact_or_none

    spec = load_spec(SPECS / "nesterov.yaml")
    om = bind_numbers(spec, 10.0)
    frame = float_method(om, 10.0)
    assert frame.method is om and frame.A is om.A and (frame.n, frame.p) == (2, 1)
    ex = exact_or_none(spec, 10.0, 3)
    av = arb_view(ex)
    assert isinstance(ex.method, Method) and isinstance(av.method, Method)
    assert (ex.method.numbers, av.method.numbers) == ("ball", "arb")
    assert ex.oracles == av.method.oracles == (0,) and ex.E is ex.method.E
    for k, rows in _nesterov_at_10().items():
        for i, row in enumerate(rows):
            for j, want in enumerate(row):
                b, a = getattr(ex, k)[i, j], getattr(av, k)[i, j]
                assert _as_mpf(b.lo) <= want <= _as_mpf(b.hi)
                assert (_as_mpf(arb_fraction(a.lower())) <= want
                        <= _as_mpf(arb_fraction(a.upper())))
    (f,) = av.method.functions
    assert f.params["L"].contains(10) and av.method.L.contains(10)


def _nesterov_at_10() -> dict[str, list[list[object]]]:
    """Nesterov's method at kappa = 10 (m = 1, L = 10, h = 1/10, gamma = beta =
    (sqrt 10 - 1)/(sqrt 10 + 1) = (11 - 2 sqrt 10)/9), its entries as mpmath numbers at
    80 digits (a closed form, not the spec's expressions)."""
    import mpmath

    mpmath.mp.dps = 80
    beta = (11 - 2 * mpmath.sqrt(10)) / 9
    return {"A": [[0, 1], [-beta, 1 + beta]], "B": [[0], [-mpmath.mpf(1) / 10]],
            "C": [[-beta, 1 + beta]], "E": [[0, 1]]}


def _as_mpf(q):
    import mpmath

    return mpmath.mpf(q.numerator) / q.denominator


def test_bind_over_each_number_type_encloses_the_closed_form():
    """``sosalgo.method.bind(..., numbers=...)``: the float method is within 1e-15 of the
    closed form, the ball and arb methods enclose it (every entry, m and L, and the
    class parameters), the ball method keeps the exact entries."""
    import sympy as sp

    from sosalgo.kernel.arb import arb_fraction
    from sosalgo.method import bind as bind_numbers

    spec = load_spec(SPECS / "nesterov.yaml")
    closed = _nesterov_at_10()
    fl = bind_numbers(spec, 10.0)
    ball = bind_numbers(spec, 10.0, numbers="ball")
    am = bind_numbers(spec, 10.0, numbers="arb")
    assert (fl.numbers, ball.numbers, am.numbers) == ("float", "ball", "arb")
    for k, rows in closed.items():
        for i, row in enumerate(rows):
            for j, want in enumerate(row):
                assert abs(getattr(fl, k)[i, j] - float(want)) <= 1e-15
                b = getattr(ball, k)[i, j]
                assert _as_mpf(b.lo) <= want <= _as_mpf(b.hi) and b.hi - b.lo < 1e-40
                a = getattr(am, k)[i, j]
                assert (_as_mpf(arb_fraction(a.lower())) <= want
                        <= _as_mpf(arb_fraction(a.upper())))
                exact = ball.matrices[k][i, j]
                assert abs(sp.N(exact, 60) - sp.Float(str(want), 60)) < sp.Float(1e-55)
    assert (ball.m, ball.L, ball.kappa) == (1, 10, 10)
    (f,) = ball.functions
    assert f.params["L"].lo == f.params["L"].hi == 10 and f.params["m"].c == 1
    assert am.p == ball.p == fl.p == 1 and am.n == ball.n == fl.n == 2


def test_bind_over_polynomials_is_the_method_on_its_box():
    """``numbers="poly"``: beta free over its range [0, 1] is 1/2 + z/2 (box coordinate z
    in [-1, 1]); at z = -1/3 (beta = 1/3) A, C are the method at beta = 1/3, h = 1/10."""
    import sympy as sp

    from sosalgo.method import bind as bind_numbers

    spec = load_spec(SPECS / "nesterov.yaml")
    pm = bind_numbers(spec, 10.0, numbers="poly", free=["beta"])
    (z,) = pm.box.zs
    at = {z: sp.Rational(-1, 3)}
    third = sp.Rational(1, 3)
    assert pm.A.xreplace(at) == sp.Matrix([[0, 1], [-third, 1 + third]])
    assert pm.C.xreplace(at) == sp.Matrix([[-third, 1 + third]])
    assert pm.B == sp.Matrix([[0], [sp.Rational(-1, 10)]])
    assert pm.box.theta([-1 / 3]) == pytest.approx({"beta": 1 / 3}, abs=1e-15)
    for other in ("complex", "field"):  # field: the PEP's exact proof builds it, not bind
        with pytest.raises(ValueError, match="numbers"):
            bind_numbers(spec, 10.0, numbers=other)


def test_bind_of_an_m0_spec_takes_no_kappa():
    """A spec without a condition number (``m: 0``) is bound at its own L: m = 0, and
    kappa is infinite (no condition number)."""
    from sosalgo.method import bind as bind_numbers

    spec = load_spec(SPECS / "gradient-convex.yaml")
    om = bind_numbers(spec)
    assert isinstance(om, OracleMethod) and om.m == 0 and om.L == spec.L
    assert om.kappa == float("inf")


def test_bind_with_a_moving_optimum():
    """Douglas-Rachford (m: 0, L = 1, alpha = 1/L) keeps (x, v) with v = alpha grad f(x): at
    the optimum (x*, alpha s_f*), which moves with the optimal subgradient s_f*. The
    sublinear potentials refuse it; ``moving_optimum=True`` (the PEP's binding) takes it,
    with the fixed points [[1, 0], [0, alpha]] on (x*, s_f*) (a closed form)."""
    from sosalgo.method import bind as bind_numbers
    from sosalgo.model import ModelError
    from sosalgo.oracles import fixed_point_basis
    from sosalgo.worstcase.bind import bound_method

    spec = load_spec(SPECS / "douglas-rachford-convex.yaml")
    with pytest.raises(ModelError, match="optimal subgradients"):
        bind_numbers(spec)
    om = bind_numbers(spec, moving_optimum=True)
    assert np.allclose(fixed_point_basis(om), [[1.0, 0.0], [0.0, 1.0]], atol=1e-12)
    pep_om, kappa = bound_method(spec, None)
    assert np.array_equal(pep_om.A, om.A) and np.isnan(kappa)


def test_the_method_in_other_units_scales_its_class_too():
    """f/s is in F(m/s, L/s) and B s on its gradients gives the same iterates: at kappa
    10 (m = 1, L = 10, h = 1/10) and s = 10, m = 1/10, L = 1, f's class parameters are
    the same, B = [[0], [-1]]; a class other than F(m, L) is refused."""
    from fractions import Fraction

    from sosalgo.exact_method import exact_algorithm, scaled_method

    ex = scaled_method(exact_algorithm(load_spec(SPECS / "nesterov.yaml"), 10), Fraction(10))
    (f,) = ex.functions
    assert (ex.m, ex.L) == (Fraction(1, 10), 1)
    assert (f.params["m"].lo, f.params["m"].hi, f.params["L"].lo) == (Fraction(1, 10),) * 2 + (1,)
    assert [[b.c for b in row] for row in ex.balls["B"]] == [[0], [-1]]
    composite = exact_algorithm(load_spec(SPECS / "proximal-gradient.yaml"), 10)
    with pytest.raises(ValueError, match="seed's form"):
        scaled_method(composite, Fraction(10))
