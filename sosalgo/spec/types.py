"""The types of a spec: constants and limits, :class:`SpecError`, :class:`Parameter`,
:class:`Spec`, and the dependency graph of parameters (tied order, value order).

A leaf module: the numeric model (:mod:`sosalgo.model`) and the loader
(:mod:`sosalgo.spec.loading`) build on it, so neither needs the other at import time.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import sympy as sp

from sosalgo.errors import InputError

__all__ = [
    "BASE_SYMBOLS", "MATRIX_NAMES", "Parameter", "Spec", "SpecError", "deps", "tied_order",
    "value_order",
]

M_SYM, L_SYM, KAPPA_SYM = sp.symbols("m L kappa", positive=True)
BASE_SYMBOLS: dict[str, sp.Symbol] = {"m": M_SYM, "L": L_SYM, "kappa": KAPPA_SYM}
MATRIX_NAMES = ("A", "B", "C", "E")
TOP_KEYS = {
    "name", "description", "parameters", "matrices", "references", "kappa", "m", "certificate",
}
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,79}$")
PARAM_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")
RESERVED = set(BASE_SYMBOLS) | {"sqrt", "exp", "log", "abs", "min", "max", "pi", "rho", "lambda"}
RESERVED_COLUMNS = {
    "kappa", "rho", "certified", "lambda", "max_eig_M", "min_eig_P", "solves", "seconds",
    "solver", "rho_infeasible", "error", "spec", "lower_bound", "rho_certified", "gap",
}
# Size limits keep loading well under a second or two whatever the input: PyYAML's pure-Python
# parser needs about 15 us per token, and every parameter is compiled against all the others.
MAX_FILE_BYTES = 64_000
MAX_STATE = 12
MAX_PARAMETERS = 100
MAX_REFERENCES = 100
MAX_KAPPA_POINTS = 10_000
MAX_MESSAGE = 300  # characters of a SpecError's field or message (the rest is cut)


def _printable(text: str, limit: int | None = None) -> str:
    """``text`` on one printable line: line breaks, control and surrogate characters escaped."""
    if limit is not None and len(text) > limit:
        text = text[: limit - 3] + "..."
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)


class SpecError(InputError):
    """Invalid spec: carries the file and the field so the message is one precise line.

    Field and message are made printable (newlines, control characters and lone surrogates
    from the spec are escaped), so ``str(error)`` is always a single line.
    """

    def __init__(self, source: str, field_: str, message: str):
        self.source = _printable(source)
        self.field = _printable(field_, MAX_MESSAGE)
        self.message = _printable(message, MAX_MESSAGE)
        where = f"{self.source}: {self.field}" if self.field else self.source
        super().__init__(f"{where}: {self.message}")


@dataclass(frozen=True)
class Parameter:
    """A tunable parameter (``value`` and optional ``range``) or a tied one (``tied``)."""

    name: str
    value: sp.Expr | None = None
    range: tuple[sp.Expr, sp.Expr] | None = None
    tied: sp.Expr | None = None

    @property
    def is_tied(self) -> bool:
        return self.tied is not None


@dataclass(frozen=True, eq=False)
class Spec:
    """A validated spec. Expressions are sympy objects over parameters and m, L, kappa."""

    name: str
    description: str
    source: str
    parameters: dict[str, Parameter]
    matrices: dict[str, sp.Matrix]
    references: dict[str, sp.Expr]
    kappa: tuple[float, ...]
    m: float = 1.0
    certificate: str = "theorem1"
    symbols: dict[str, sp.Symbol] = field(default_factory=dict, repr=False)
    certificate_options: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """State dimension (rows of A)."""
        return int(self.matrices["A"].shape[0])

    @property
    def inputs(self) -> list[str]:
        """Parameters that are not tied (they have a value, maybe a range)."""
        return [p for p, par in self.parameters.items() if not par.is_tied]

    @property
    def ranged(self) -> list[str]:
        """Parameters with a range: the default free set of design and grids."""
        return [p for p, par in self.parameters.items() if par.range is not None]

    def mL(self, kappa: float) -> tuple[float, float]:
        """(m, L) for a condition number: L = kappa * m."""
        return self.m, kappa * self.m

    def tied_closure(self) -> dict[str, sp.Expr]:
        """Every tied parameter written in terms of input parameters and m, L, kappa."""
        order = tied_order(self.parameters, self.source)
        out: dict[str, sp.Expr] = {}
        for name in order:
            expr = self.parameters[name].tied
            assert expr is not None
            out[name] = expr.xreplace({self.symbols[k]: v for k, v in out.items()})
        return out

    def templates(self, free: Sequence[str] | None = None) -> dict[str, sp.Matrix]:
        """Symbolic A, B, C, E with tied parameters substituted.

        Parameters in ``free`` stay symbols; other input parameters are replaced by their
        ``value`` expressions when ``free`` is given (``free=None`` keeps every input
        parameter symbolic).
        """
        sub: dict[sp.Symbol, sp.Expr] = {}
        tied = self.tied_closure()
        for name, expr in tied.items():
            sub[self.symbols[name]] = expr
        out = {k: mat.xreplace(sub) for k, mat in self.matrices.items()}
        if free is not None:
            fixed = {
                self.symbols[p]: self.parameters[p].value
                for p in self.inputs
                if p not in free
            }
            out = {k: mat.xreplace(fixed) for k, mat in out.items()}
        return out

    def check_free(self, free: Sequence[str], need_range: bool = True) -> None:
        """Raise SpecError unless every name in ``free`` is an input parameter (with range)."""
        for p in free:
            if p not in self.parameters:
                raise SpecError(self.source, f"--free {p}", "unknown parameter")
            par = self.parameters[p]
            if par.is_tied:
                raise SpecError(self.source, f"parameters.{p}", "tied parameters cannot be free")
            if need_range and par.range is None:
                raise SpecError(
                    self.source, f"parameters.{p}.range", "a free parameter needs a range"
                )



def deps(expr: sp.Expr | None, params: Mapping[str, Parameter]) -> set[str]:
    if expr is None:
        return set()
    return {s.name for s in expr.free_symbols if s.name in params}


def topo(graph: dict[str, set[str]], source: str, what: str) -> list[str]:
    order: list[str] = []
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        if state.get(node) == 2:
            return
        if state.get(node) == 1:
            cycle = " -> ".join(path[path.index(node):] + [node])
            raise SpecError(source, f"parameters.{node}", f"cycle among {what}: {cycle}")
        state[node] = 1
        for dep in sorted(graph[node]):
            visit(dep, path + [node])
        state[node] = 2
        order.append(node)

    for node in graph:
        visit(node, [])
    return order


def tied_order(params: Mapping[str, Parameter], source: str) -> list[str]:
    """Tied parameters in dependency order; raises on a cycle."""
    graph = {
        p: {d for d in deps(par.tied, params) if params[d].is_tied}
        for p, par in params.items()
        if par.is_tied
    }
    return topo(graph, source, "tied parameters")


def value_order(params: Mapping[str, Parameter], source: str) -> list[str]:
    """All parameters in the order their values can be computed; raises on a cycle."""
    graph = {p: deps(par.tied if par.is_tied else par.value, params) for p, par in params.items()}
    return topo(graph, source, "parameter values")
