"""The types of a spec: constants and limits, :class:`SpecError`, :class:`Parameter`,
:class:`Spec`, and the dependency graph of parameters (tied order, value order).

A leaf module: the numeric model (:mod:`sosalgo.model`) and the loader
(:mod:`sosalgo.spec.loading`) build on it, so neither needs the other at import time.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sosalgo.classes import SEED_CLASS
from sosalgo.errors import InputError
from sosalgo.kernel.expr.tree import Expr

if TYPE_CHECKING:
    import sympy as sp

__all__ = [
    "BASE_NAMES", "INDEX_NAMES", "MATRIX_NAMES", "MEASURES", "NEXT_SUFFIX", "VARIES", "ExprMatrix",
    "FunctionDecl", "Parameter", "SequenceDecl", "Spec", "SpecError", "deps", "tied_order",
    "value_order",
]

BASE_NAMES = ("m", "L", "kappa")
INDEX_NAMES = ("k", "N")  # the iteration index (0-based) and the horizon of a varying spec
NEXT_SUFFIX = "_next"  # ``theta_next``: a sequence's next value theta[k+1]
# what a command that takes no method changing with k says (after the file's name)
VARIES = "varies with k: use `sosalgo pep {source} --steps N`"
MATRIX_NAMES = ("A", "B", "C", "E")
ORACLE_MATRIX_NAMES = ("A", "B", "C", "D", "E")  # D optional; E absent with ``output``
MEASURES = ("function", "distance")
FLOW_KEY = "flow"  # a continuous-time question (:mod:`sosalgo.spec.flow`)
TOP_KEYS = {
    "name", "description", "parameters", "matrices", "references", "kappa", "m", "certificate",
    "functions", "oracles", "measure", "output", "L", "initial_state", "sequences", "pep",
    "line_search", "mirror", "finite_sum", "span_search", "optimality",
}
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,79}$")
PARAM_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")
RESERVED = set(BASE_NAMES) | {"sqrt", "exp", "log", "abs", "min", "max", "pi", "rho", "lambda"}
RESERVED_COLUMNS = {
    "kappa", "rho", "certified", "lambda", "max_eig_M", "min_eig_P", "solves", "seconds",
    "solver", "rho_infeasible", "error", "spec", "lower_bound", "rho_certified", "gap",
}
# Size limits keep loading well under a second or two whatever the input: PyYAML's pure-Python
# parser needs about 15 us per token, and every parameter is compiled against all the others.
MAX_FILE_BYTES = 64_000
MAX_WAIT_SECONDS = 60.0  # for the whole text of a spec read from a pipe or FIFO
MAX_STATE = 12
MAX_ORACLES = 8  # oracle calls per iteration
MAX_FUNCTIONS = 8
MAX_PARAMETERS = 100
MAX_REFERENCES = 100
MAX_KAPPA_POINTS = 10_000
MAX_SEQUENCES = 8
MAX_SCHEDULE = 1000  # values of a per-step list (the horizon of a listed schedule)
MAX_MESSAGE = 300  # characters of a SpecError's field or message (the rest is cut)


ExprMatrix = tuple[tuple[Expr, ...], ...]  # rows of expression trees


def __getattr__(name: str) -> Any:
    """``BASE_SYMBOLS`` (sympy symbols of m, L, kappa) is built on first use, so that numeric
    work never imports sympy."""
    if name == "BASE_SYMBOLS":
        from sosalgo.kernel.expr.parse import sympy_symbol

        return {k: sympy_symbol(k) for k in BASE_NAMES}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
    """A tunable parameter (``value`` and optional ``range``) or a tied one (``tied``).

    A parameter of a method that changes with k (docs/spec.md, "Methods that change with
    k") may be a ``schedule`` (one value per step; ``value`` is then its first entry) and
    is ``per_step`` when it can take a different value at each step (a schedule, a value
    that uses k, N or a sequence, or ``per_step: true``): free per step in a design when
    it has a range; ``fixed`` when the spec wrote it as a bare list (a tie per step)."""

    name: str
    value: Expr | None = None
    range: tuple[Expr, Expr] | None = None
    tied: Expr | None = None
    schedule: tuple[Expr, ...] | None = None
    per_step: bool = False
    fixed: bool = False

    @property
    def is_tied(self) -> bool:
        return self.tied is not None


@dataclass(frozen=True)
class SequenceDecl:
    """A named sequence s_0, ..., s_N of a method that changes with k: ``first`` (s_0),
    ``next`` (s_{k+1} from s_k, written with the name for s_k) and the optional ``last``
    (s_N from s_{N-1}, replacing ``next`` at the last step: OGM's theta_N)."""

    name: str
    first: Expr
    next: Expr
    last: Expr | None = None


@dataclass(frozen=True)
class FunctionDecl:
    """One entry of ``functions:``: its class and the class's parameters (expressions in m,
    L, kappa; the class's defaults where not given)."""

    name: str
    cls: str
    params: dict[str, Expr]
    given: frozenset[str] = frozenset()  # the parameters the spec gave explicitly


@dataclass(frozen=True, eq=False)
class Spec:
    """A validated spec. Expressions are :class:`~sosalgo.kernel.expr.tree.Expr` trees over the
    parameters and m, L, kappa; :meth:`sympy_matrices`, :meth:`templates` and
    :meth:`tied_closure` give their sympy form (built on first use)."""

    name: str
    description: str
    source: str
    parameters: dict[str, Parameter]
    matrices: dict[str, ExprMatrix]
    references: dict[str, Expr]
    kappa: tuple[float, ...]
    m: float = 1.0
    certificate: str = "theorem1"
    certificate_options: dict[str, Any] = field(default_factory=dict)
    # whether the spec names its family (``certificate:``); when not, each command takes
    # its own default (:func:`sosalgo.certificates.default_family_name`)
    certificate_given: bool = False
    # the oracle model (docs/function-classes.md); the defaults are the
    # seed's setting: one smooth strongly convex f queried by its gradient
    functions: dict[str, FunctionDecl] = field(default_factory=dict)
    oracles: tuple[str, ...] = ("f",)
    # inexact gradient calls (``oracles: [{function: f, relative_error: eps}]``): call index
    # (0-based) -> eps, the call answering some d with |d - grad f(y)| <= eps |grad f(y)|
    inexact: dict[int, Expr] = field(default_factory=dict)
    # epsilon-subgradient calls (``oracles: [{function: f, epsilon: eps}]``): call index
    # (0-based) -> eps, the call answering some g with f(z) >= f(y) + <g, z - y> - eps for
    # every z (:mod:`sosalgo.worstcase.epsilon`)
    epsilon: dict[int, Expr] = field(default_factory=dict)
    # linear minimization calls (``oracles: [f, {function: h, lmo: 1}]``): call index
    # (0-based) -> the index of the gradient call whose answer g is the direction; the call
    # answers u = s - y with s in argmin over the set of <g, s> (:mod:`sosalgo.worstcase.lmo`)
    lmo: dict[int, int] = field(default_factory=dict)
    # an inexact proximal call's reference vector (``relative_to``: rational coefficients
    # on the step's answers) and the calls whose answer is an inexact call's true
    # subgradient (``gradient_of``), 0-based (:mod:`sosalgo.worstcase.inexact`)
    error_refs: dict[int, tuple[Any, ...]] = field(default_factory=dict)
    twins: dict[int, int] = field(default_factory=dict)
    # ``line_search: gamma``: the step parameter of x+ = x - gamma u chosen at every step by
    # exact line search (``sosalgo pep`` only; :mod:`sosalgo.worstcase.linesearch`); None: none
    line_search: str | None = None
    # ``span_search: true`` (with ``line_search``): x_{k+1} minimizes f over x_0 + the span
    # of the past gradients, not only along u_k (conjugate gradient; the same module)
    span_search: bool = False
    # ``mirror: {kernel: {class: ...}, set: true}``: the state and the call points are
    # mirror variables grad h(x) (+ a normal vector of the set): Bregman steps, ``sosalgo
    # pep`` only (:mod:`sosalgo.worstcase.mirror`); {"kernel": FunctionDecl, "set": bool}
    mirror: dict[str, Any] | None = None
    output: int | None = None  # 0-based oracle index of ``output: y<i>``; None: x = E xi
    measure: str = "function"
    # sublinear specs (``m: 0``, ``L`` given, no kappa): L's value; None otherwise
    L: float | None = None
    # ``initial_state:`` the start xi_0 = a x0 + b g0 of ``pep``: (a_i, b_i) per state
    # (expressions of the parameters, m, L, kappa); None: xi_0 = u x0
    initial_state: tuple[tuple[Expr, Expr], ...] | None = None
    # ``m`` and ``L`` as written (constant expressions: ``1/10`` stays 1/10 in exact proofs);
    # None: the floats above are all there is
    m_expr: Expr | None = None
    L_expr: Expr | None = None
    # a method that changes with k: named sequences (in their order) and whether anything
    # varies with k (sequences, schedules, per-step parameters, k or N in an expression);
    # sosalgo.steps binds such a spec step by step
    sequences: dict[str, SequenceDecl] = field(default_factory=dict)
    time_varying: bool = False
    # ``pep: {measure, initial}``: the PEP's default terms (sosalgo.worstcase.terms), when the
    # command line gives none; ``constraints``: a list of relations on the instance
    # (sosalgo.worstcase.constraints)
    pep: dict[str, Any] = field(default_factory=dict)
    # ``finite_sum:`` a method on a finite sum, one function drawn per step
    # (:class:`sosalgo.spec.finite_sum.FiniteSum`; ``sosalgo pep`` only); None: none
    finite_sum: Any = None
    # transpose calls, functions composed with a linear operator and the optimality
    # condition that pairs them (:class:`sosalgo.spec.adjoint.Adjoint`); None: none
    adjoint: Any = None
    _sympy: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def sublinear(self) -> bool:
        """True for ``m: 0`` (L given, no kappa): analysis certifies a constant c in
        measure(x_k) <= c |x_0 - x*|^2 / k (:mod:`sosalgo.certificates.sublinear`)."""
        return self.m == 0

    @property
    def composite(self) -> bool:
        """False in the seed's setting (one smooth_strongly_convex f with the spec's m and
        L, one gradient call, no D, x = E xi, ``measure: function``): the only setting of
        Theorem 1; True for every other spec."""
        if self.oracles != ("f",) or self.output is not None or self.measure != "function":
            return True
        if (self.inexact or self.epsilon or self.line_search or self.lmo
                or self.mirror):  # not Theorem 1
            return True
        if self.sublinear:  # no kappa: outside Theorem 1's setting
            return True
        if "D" in self.matrices:
            return True
        decl = self.functions.get("f")
        return len(self.functions) > 1 or (
            decl is not None and (decl.cls != SEED_CLASS.name or bool(decl.given)))

    @property
    def has_seed_form(self) -> bool:
        """Whether the method is the seed's: one smooth_strongly_convex f with the spec's m
        and L queried by its gradient, no D, x = E xi, ``measure: function`` (the opposite
        of :attr:`composite`). Its certificates and proofs are built on (A, B, C, E) alone:
        the only setting of Theorem 1, of the exact polynomial forms of design and of the
        symbolic listing of eq. (15)."""
        return not self.composite

    @property
    def has_condition_number(self) -> bool:
        """Whether the method is bound at a condition number kappa = L/m (m > 0: linear
        rates); False for ``m: 0`` (L given, no kappa), whose rates are sublinear."""
        return not self.sublinear

    @property
    def p(self) -> int:
        """Number of oracle calls per iteration (columns of B)."""
        return len(self.oracles)

    @property
    def n(self) -> int:
        """State dimension (rows of A)."""
        return len(self.matrices["A"])

    @property
    def symbols(self) -> dict[str, sp.Symbol]:
        """The sympy symbol of each parameter."""
        from sosalgo.kernel.expr.parse import sympy_symbol

        return {p: sympy_symbol(p) for p in self.parameters}

    def sympy_matrices(self) -> dict[str, sp.Matrix]:
        """A, B, C, E as sympy matrices over the parameters and m, L, kappa."""
        if "matrices" not in self._sympy:
            import sympy as sp

            from sosalgo.kernel.expr.parse import to_sympy

            self._sympy["matrices"] = {
                k: sp.Matrix([[to_sympy(e) for e in row] for row in rows])
                for k, rows in self.matrices.items()
            }
        return self._sympy["matrices"]

    @property
    def inputs(self) -> list[str]:
        """Parameters that are not tied (they have a value, maybe a range)."""
        return [p for p, par in self.parameters.items() if not par.is_tied]

    @property
    def ranged(self) -> list[str]:
        """Parameters with a range: the default free set of design and grids."""
        return [p for p, par in self.parameters.items() if par.range is not None]

    def mL(self, kappa: float) -> tuple[float, float]:
        """(m, L) for a condition number: L = kappa * m; (0, L) for a sublinear spec (its
        kappa is undefined and ignored)."""
        if self.L is not None:
            return 0.0, self.L
        return self.m, kappa * self.m

    def tied_closure(self) -> dict[str, sp.Expr]:
        """Every tied parameter written (in sympy) in terms of input parameters and m, L,
        kappa."""
        from sosalgo.kernel.expr.parse import to_sympy

        order = tied_order(self.parameters, self.source)
        symbols = self.symbols
        out: dict[str, sp.Expr] = {}
        for name in order:
            expr = self.parameters[name].tied
            assert expr is not None
            out[name] = to_sympy(expr).xreplace({symbols[k]: v for k, v in out.items()})
        return out

    def templates(self, free: Sequence[str] | None = None) -> dict[str, sp.Matrix]:
        """Symbolic A, B, C, E with tied parameters substituted.

        Parameters in ``free`` stay symbols; other input parameters are replaced by their
        ``value`` expressions when ``free`` is given (``free=None`` keeps every input
        parameter symbolic).
        """
        from sosalgo.kernel.expr.parse import to_sympy

        if self.time_varying:  # one method per step: sosalgo.steps binds it
            raise SpecError(self.source, "", VARIES.format(source=self.source))
        symbols = self.symbols
        sub: dict[sp.Symbol, sp.Expr] = {}
        tied = self.tied_closure()
        for name, expr in tied.items():
            sub[symbols[name]] = expr
        out = {k: mat.xreplace(sub) for k, mat in self.sympy_matrices().items()}
        if free is not None:
            fixed = {
                symbols[p]: to_sympy(self.parameters[p].value)
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



def deps(expr: Expr | None, params: Mapping[str, Parameter]) -> set[str]:
    """The parameters an expression refers to."""
    if expr is None:
        return set()
    return {name for name in expr.names() if name in params}


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
