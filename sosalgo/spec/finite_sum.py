"""``finite_sum:`` of a spec: a method on a finite sum of n functions of one class, one of
them drawn uniformly at every step (SGD, SAGA, point SAGA), written as a short vector
program (parsed by :mod:`ast`, node by node, never evaluated as code).

.. code-block:: yaml

    functions:
      f: {class: smooth_strongly_convex, count: n}   # F = (f_1 + ... + f_n)/n (+ the others)
    finite_sum:
      state: [x]                        # "phi[j]": one vector per function (memory)
      step: ["x = x - gamma*grad(f[i], x)"]   # i: the index drawn at this step
      constraints: ["mean(grad(f[j], xs)**2) <= v**2"]
    pep: {measure: "E[(x - xs)**2]", initial: "(x - xs)**2 <= R**2"}

The PEP itself is :mod:`sosalgo.worstcase.finite_sum`; this module checks the text only."""

from __future__ import annotations

import ast
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

__all__ = ["FiniteSum", "VECTOR_CALLS", "check_program_text", "parse_finite_sum"]

VECTOR_CALLS = ("grad", "prox", "mean", "sqrt", "block", "argmin", "lmo", "sum")
# the calls the program and terms may use
MAX_STATEMENTS = 20
MAX_TEXT = 2000
_ALLOWED = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Add, ast.Sub, ast.Mult, ast.Div,
            ast.Pow, ast.USub, ast.UAdd, ast.Name, ast.Load, ast.Constant, ast.Call,
            ast.Subscript, ast.Compare, ast.LtE, ast.GtE, ast.Slice)
REFERENCES = ("minimizer", "free")  # xs: a minimizer of the sum, or a free common point


@dataclass(frozen=True)
class FiniteSum:
    """The drawn function (declared with ``count``), its count (an expression of the
    parameters), the state (name, one per function?), the step as (target, indexed by
    the draw i, expression text) in order, and the constraints (texts ``a <= b``)."""

    function: str | None
    count: Any
    state: tuple[tuple[str, bool], ...]
    step: tuple[tuple[str, bool, str], ...]
    constraints: tuple[str, ...] = ()
    # ``blocks: d`` instead of a function with count: the space is cut in d orthogonal
    # blocks, ``block(v, i)`` is v's i-th, and the step draws a block (count is d)
    blocks: bool = False
    # ``per_step: true`` on the function instead of ``count``: step k calls f_k, a new
    # member of the class (online learning; count = the number of steps, no draw)
    per_step: bool = False
    # assignments run once before the first step (``x = prox(h, 1, x)``: x_0 projected)
    start: tuple[tuple[str, bool, str], ...] = ()
    # xs: "minimizer" (of the sum: the gradients at xs sum to 0) or "free" (a point of
    # every function's domain, nothing else: a regret's reference point)
    reference: str = "minimizer"

    def memory(self) -> frozenset[str]:
        return frozenset(name for name, per in self.state if per)


def check_program_text(text: object, where: str, fail: Callable[[str, str], Exception],
                       compare: bool | None = False) -> ast.Expression:
    """The syntax tree of one expression of the program or of a term (``compare``: True,
    must be ``a <= b``; None, may be; False, must not), only the nodes the program
    language has; ``fail(where, message)`` otherwise."""
    if not isinstance(text, str) or not text.strip():
        raise fail(where, "expected an expression (a non-empty string)")
    if len(text) > MAX_TEXT:
        raise fail(where, f"longer than {MAX_TEXT} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        raise fail(where, f"not an expression: {text.strip()[:60]!r}") from None
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED):
            raise fail(where, f"{type(node).__name__} is not allowed (numbers, names, "
                              "+ - * / **, grad(), prox(), mean(), f[i](point), E[...])")
        if isinstance(node, ast.Constant) and (isinstance(node.value, bool)
                                               or not isinstance(node.value, int | float)):
            raise fail(where, f"{node.value!r}: only numbers")
        if isinstance(node, ast.Compare) and (len(node.ops) != 1 or node is not tree.body):
            raise fail(where, "one comparison a <= b, at the top")
        if isinstance(node, ast.Call) and not isinstance(node.func, ast.Name | ast.Subscript):
            raise fail(where, "only grad(), prox(), mean(), sqrt() and f[j](point) calls")
    top = isinstance(tree.body, ast.Compare)
    if compare is True and not top:
        raise fail(where, "expected a comparison a <= b")
    if compare is False and top:
        raise fail(where, "a comparison is not allowed here")
    return tree


def parse_finite_sum(raw: object, counts: dict[str, Any], names: Collection[str],
                     fail: Callable[[str, str], Exception],
                     blocks: Callable[[object], Any] | None = None) -> FiniteSum:
    """``finite_sum:`` checked against the functions' counts (exactly one function with
    ``count``) and the spec's names (parameters, m, L, kappa)."""
    if not isinstance(raw, dict) or set(raw) - {"state", "step", "constraints", "blocks",
                                                 "start", "reference"}:
        raise fail("finite_sum", "expected a mapping with state, step (and constraints, "
                                 "blocks, start, reference)")
    if len(counts) + ("blocks" in raw) != 1:
        raise fail("finite_sum", "exactly one function must have count: n (the drawn one), "
                                 "or blocks: d (a block of coordinates drawn) be given")
    function, count = next(iter(counts.items())) if counts else (None, None)
    per_step = function is not None and count is None
    if "blocks" in raw:
        count = blocks(raw["blocks"])
    state = _state(raw.get("state"), names, fail)
    step = _step(raw.get("step"), {s for s, _ in state}, dict(state), fail)
    start = _step(raw["start"], {s for s, _ in state}, dict(state), fail,
                  "finite_sum.start") if "start" in raw else []
    if any(indexed for _, indexed, _ in start):
        raise fail("finite_sum.start", "no draw before the first step: assign whole "
                                       "vectors (x = ...)")
    reference = raw.get("reference", "minimizer")
    if reference == "free" and not per_step:
        raise fail("finite_sum.reference", "free: only with a per-step function "
                                           "(functions.f.per_step: true)")
    if reference not in REFERENCES:
        raise fail("finite_sum.reference", f"must be one of {', '.join(REFERENCES)}, got "
                                           f"{str(reference)[:40]!r}")
    cons = raw.get("constraints", [])
    if not isinstance(cons, list) or len(cons) > MAX_STATEMENTS:
        raise fail("finite_sum.constraints", f"a list of at most {MAX_STATEMENTS} "
                                             "comparisons a <= b")
    for k, c in enumerate(cons):
        check_program_text(c, f"finite_sum.constraints[{k}]", fail, compare=True)
    return FiniteSum(function, count, tuple(state), tuple(step), tuple(str(c) for c in cons),
                     "blocks" in raw, per_step, tuple(start), str(reference))


def _state(raw: object, names: Collection[str], fail: Callable[[str, str], Exception]
           ) -> list[tuple[str, bool]]:
    if not isinstance(raw, list) or not raw or len(raw) > MAX_STATEMENTS:
        raise fail("finite_sum.state", "a list of state names: x, or phi[j] (one vector "
                                       "per function)")
    out: list[tuple[str, bool]] = []
    for k, item in enumerate(raw):
        text = str(item).replace(" ", "")
        name, per = (text[:-3], True) if text.endswith("[j]") else (text, False)
        if not name.isidentifier() or name in names or name in _RESERVED \
                or name in {s for s, _ in out}:
            raise fail(f"finite_sum.state[{k}]", f"{item!r}: not a new name (x, or phi[j])")
        out.append((name, per))
    return out


_RESERVED = {"E", "xs", "i", "j", "n", *VECTOR_CALLS}


def _step(raw: object, state: set[str], per: dict[str, bool],
          fail: Callable[[str, str], Exception], field: str = "finite_sum.step"
          ) -> list[tuple[str, bool, str]]:
    if not isinstance(raw, list) or not raw or len(raw) > MAX_STATEMENTS:
        raise fail(field, f"a list of at most {MAX_STATEMENTS} assignments "
                          "'x = ...' (phi[i] = ... for the drawn index)")
    out = []
    for k, item in enumerate(raw):
        where = f"{field}[{k}]"
        text = str(item)
        target, sep, expr = text.partition("=")
        tname = target.replace(" ", "")
        indexed = tname.endswith("[i]")
        tname = tname[:-3] if indexed else tname
        if not sep or not tname.isidentifier() or tname in _RESERVED or \
                indexed != per.get(tname, False):
            raise fail(where, f"expected 'name = expression' (phi[i] = ... for a memory "
                              f"phi[j]), got {text[:60]!r}")
        check_program_text(expr, where, fail)
        out.append((tname, indexed, expr.strip()))
    return out
