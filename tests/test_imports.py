"""The package's import structure: imports go down the layers (:data:`LAYERS`), no cycles
between sosalgo's modules (deferred imports inside functions included; imports only for
type annotations excluded), no private names imported across modules, and one error base
for everything raised on purpose."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "sosalgo"


def _modules() -> dict[str, Path]:
    out = {}
    for f in PKG.rglob("*.py"):
        parts = f.relative_to(PKG.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = f
    return out


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of import nodes under ``if TYPE_CHECKING:`` (annotation-only dependencies)."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for sub in node.body:
                for inner in ast.walk(sub):
                    skip.add(id(inner))
    return skip


def _imports(mods: dict[str, Path]) -> tuple[dict[str, set[str]], list[tuple[str, str, str]]]:
    edges: dict[str, set[str]] = {m: set() for m in mods}
    private = []
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _type_checking_nodes(tree)
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(tree):
            if id(node) in skip or not isinstance(node, ast.Import | ast.ImportFrom):
                continue
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                if node.level:
                    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    base = base[: len(base) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                subs = [f"{target}.{a.name}" for a in node.names]
                # ``from sosalgo import inputs`` needs the submodule, not the package's code
                lazy_root = target == "sosalgo" and all(t in mods for t in subs)
                targets = subs if lazy_root else [target, *subs]
                if target.startswith("sosalgo"):
                    private += [(mod, target, a.name) for a in node.names
                                if a.name.startswith("_") and not a.name.startswith("__")]
            for t in targets:
                while t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in mods and t != mod and t.startswith("sosalgo"):
                    edges[mod].add(t)
    return edges, private


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    edges, _ = _imports(_modules())
    assert _cycles(edges) == []


def test_the_check_finds_a_cycle():
    """The checker itself: a two-module cycle is reported."""
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": set()}) == [["a", "b"]]


# The layers of sosalgo, bottom first: each a group of top-level units (a package or a
# module directly under sosalgo/), listed in their allowed order. A module may import any
# unit of a lower layer and, within its own layer, the units listed before its own. A new
# top-level unit gets its place here (test_every_unit_has_a_layer). docs/architecture.md
# describes the layers.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("kernel", ("errors", "kinds", "kernel", "polyopt")),
    ("problem", ("classes", "spec", "oracles", "model", "exact_method", "method", "steps",
                 "spec_values")),
    ("families", ("certificates",)),
    ("questions", ("symbolic", "analysis", "inputs", "sensitivity", "witnesses", "design_search",
                   "sublinear_design", "worstcase", "pareto")),
    ("results", ("schema", "store", "proofs", "documents")),
    ("report", ("report",)),
    ("runs", ("batch", "runs")),
    ("faces", ("api", "__init__", "cli_errors", "cli")),
)

# The imports that still go against the layers, each with the reason it is there. The list
# only shrinks: an entry whose import is gone (or now follows the layers) fails
# test_allowlisted_imports_still_exist, so delete it.
ALLOWED_UPWARD: dict[tuple[str, str], str] = {}


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _rank() -> dict[str, tuple[int, int]]:
    return {unit: (i, j) for i, (_, units) in enumerate(LAYERS) for j, unit in enumerate(units)}


def _against_layers(edges: dict[str, set[str]]) -> set[tuple[str, str]]:
    """Imports (module, imported module) from a unit to a later one in the table (a unit
    missing from the table fails test_every_unit_has_a_layer instead)."""
    rank = _rank()
    return {(a, b) for a, targets in edges.items() for b in targets
            if _unit(a) in rank and _unit(b) in rank and rank[_unit(b)] > rank[_unit(a)]}


def test_every_unit_has_a_layer():
    units = {_unit(m) for m in _modules()}
    assert sorted(units - set(_rank())) == []


def test_imports_go_down_the_layers():
    edges, _ = _imports(_modules())
    new = sorted(_against_layers(edges) - set(ALLOWED_UPWARD))
    assert new == [], "imports against the layers (move the code, or list it with a reason)"


def test_allowlisted_imports_still_exist():
    edges, _ = _imports(_modules())
    gone = sorted(set(ALLOWED_UPWARD) - _against_layers(edges))
    assert gone == [], "these imports now follow the layers: remove them from ALLOWED_UPWARD"


def _unit_edges(edges: dict[str, set[str]]) -> dict[str, set[str]]:
    """The import graph between top-level units (packages and modules under sosalgo/)."""
    units: dict[str, set[str]] = {_unit(m): set() for m in edges}
    for a, targets in edges.items():
        units[_unit(a)] |= {_unit(b) for b in targets} - {_unit(a)}
    return units


def test_no_import_cycles_between_packages():
    """No cycle between top-level units either, deferred imports counted (a package whose
    modules import another package that imports it back, through different modules)."""
    edges, _ = _imports(_modules())
    assert _cycles(_unit_edges(edges)) == []


def test_the_package_check_finds_a_cycle_through_different_modules():
    edges = {"sosalgo.a.x": {"sosalgo.b.y"}, "sosalgo.b.z": {"sosalgo.a.w"},
             "sosalgo.a.w": set(), "sosalgo.b.y": set()}
    assert _cycles(edges) == []
    assert _cycles(_unit_edges(edges)) == [["a", "b"]]


def test_the_layer_check_finds_an_upward_import():
    """The checker itself: a report module importing a run is flagged, the reverse is not."""
    edges = {"sosalgo.report.x": {"sosalgo.batch.y"}, "sosalgo.batch.y": {"sosalgo.report.x"}}
    assert _against_layers(edges) == {("sosalgo.report.x", "sosalgo.batch.y")}


def test_no_private_names_across_modules():
    _, private = _imports(_modules())
    assert private == []


@pytest.mark.parametrize("name", [
    "sosalgo.spec.SpecError", "sosalgo.model.ModelError", "sosalgo.kernel.expr.ExprError",
    "sosalgo.kernel.expr.NumericError", "sosalgo.store.OutputError",
    "sosalgo.batch.executor.BatchError",
    "sosalgo.proofs.results.ResultError",
])
def test_input_errors_share_one_base(name):
    import importlib

    from sosalgo.errors import InputError, SosalgoError

    mod, cls = name.rsplit(".", 1)
    err = getattr(importlib.import_module(mod), cls)
    assert issubclass(err, InputError) and issubclass(err, SosalgoError)
    assert issubclass(err, ValueError)  # callers that caught ValueError still do


@pytest.mark.parametrize("name, values", [
    ("sosalgo.kernel.solvers.Feasibility", {"feasible", "infeasible", "failed"}),
    ("sosalgo.design_search.dualbound.BoundStatus", {"proved", "partial", "unsupported"}),
    ("sosalgo.kernel.exact.Verdict", {"exact", "failed"}),
    ("sosalgo.polyopt.RelaxationStatus",
     {"optimal", "inaccurate", "infeasible", "failed", "skipped", "inconsistent"}),
])
def test_status_enums_write_their_strings(name, values):
    """One status enum per concept, each member written to CSV/JSON as its plain string."""
    import importlib
    import json

    from sosalgo.store import format_value

    mod, cls = name.rsplit(".", 1)
    enum = getattr(importlib.import_module(mod), cls)
    assert {m.value for m in enum} == values
    for m in enum:
        assert m == m.value and format_value(m) == m.value and f"{m}" == m.value
        assert json.loads(json.dumps({"status": m})) == {"status": m.value}


def _absolute_imports(path: Path) -> list[str]:
    """Every module a file imports, relative imports resolved, ``from a import b`` giving
    both ``a`` and ``a.b`` (b may be a submodule; only ``sosalgo.b`` from the top package,
    whose ``__init__`` imports nothing), deferred imports included."""
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    package = parts[:-1]  # the package a relative import starts from
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            out += ([module] if module != "sosalgo" else [])
            out += [f"{module}.{a.name}" for a in node.names]
    return out


def test_kernel_imports_nothing_above():
    """The numeric kernel (layer 0: expressions, exact arithmetic, conic data, the solver
    door, the process pool) imports nothing of sosalgo but sosalgo.errors and itself."""
    files = sorted((PKG / "kernel").rglob("*.py"))
    assert {"solvers.py", "exact.py", "conic.py", "parallel.py"} <= {f.name for f in files}
    above = []
    for f in files:
        for target in _absolute_imports(f):
            inside = (target.split(".")[:2] in (["sosalgo", "kernel"], ["sosalgo", "errors"])
                      or not target.startswith("sosalgo"))
            if not inside:
                above.append((str(f.relative_to(PKG.parent)), target))
    assert above == []


def test_conic_solvers_are_imported_behind_one_door():
    """Clarabel and SCS are imported in at most two modules of sosalgo (the solver door),
    so every conic solve shares its settings, interruption handling and trusted statuses."""
    users: dict[str, set[str]] = {"clarabel": set(), "scs": set()}
    for f in PKG.rglob("*.py"):
        for target in _absolute_imports(f):
            top = target.split(".")[0]
            if top in users:
                users[top].add(str(f.relative_to(PKG.parent)))
    assert "sosalgo/kernel/solvers.py" in users["clarabel"]
    assert all(len(mods) <= 2 for mods in users.values()), users


def test_linear_programs_go_through_the_solver_door():
    """scipy's linprog (HiGHS) is called in the solver door only (linear_program)."""
    callers = sorted(str(f.relative_to(PKG.parent)) for f in PKG.rglob("*.py")
                     if "linprog" in f.read_text(encoding="utf-8"))
    assert callers == ["sosalgo/kernel/solvers.py"], callers
