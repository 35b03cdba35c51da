"""The parts of a spec that let a method change with k (docs/spec.md, "Methods that change
with k"): the names ``k`` (the iteration index, 0-based) and ``N`` (the horizon), named
``sequences:`` defined by recurrence, and per-step parameters (a list of values, or free per
step within a range).

A sequence's next value is written ``theta[k+1]`` (or ``theta_next``); ``theta[k]`` and the
bare name ``theta`` are its value at step k. The loader (:mod:`sosalgo.spec.loading`) calls
these helpers; the binding step by step is :mod:`sosalgo.steps`.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection, Mapping
from typing import Any

from sosalgo.kernel.expr import Expr, ExprError
from sosalgo.spec.types import (
    BASE_NAMES,
    INDEX_NAMES,
    MAX_SCHEDULE,
    MAX_SEQUENCES,
    NEXT_SUFFIX,
    PARAM_RE,
    RESERVED,
    Parameter,
    SequenceDecl,
)

__all__ = ["LAST_SUFFIX", "index_names", "parse_schedule", "parse_sequences",
           "rewrite_indices", "schedule_lengths", "sequence_keys", "sequence_names",
           "uses_step"]

SEQUENCE_KEYS = ("first", "next", "last")
_SUBSCRIPT = re.compile(r"\b([A-Za-z][A-Za-z0-9_]*)\s*\[([^\[\]]*)\]")
_INDEX = {"k": "", "k+1": NEXT_SUFFIX}
LAST_SUFFIX = "_last"  # ``theta[N]`` in references: the sequence's last value

Fail = Callable[[str, str], Exception]
ExprOf = Callable[[object, Collection[str], str], Expr]


def rewrite_indices(text: object, sequences: Collection[str], last: bool = False) -> object:
    """``text`` with ``s[k]`` written ``s`` and ``s[k+1]`` written ``s_next`` for each
    sequence s (other text unchanged); with ``last`` (references), only ``s[N]``, written
    ``s_last``. ExprError for another index or a subscript of anything that is not a
    sequence."""
    if not isinstance(text, str) or "[" not in text:
        return text

    def one(match: re.Match[str]) -> str:
        name, index = match.group(1), re.sub(r"\s+", "", match.group(2))
        if name not in sequences:
            raise ExprError(f"'{name}[...]': only a sequence can be indexed (sequences: "
                            f"{', '.join(sequences) or 'none'})")
        if last:
            if index != "N":
                raise ExprError(f"'{name}[{match.group(2)}]': a reference can use {name}[N] "
                                "(the last value)")
            return name + LAST_SUFFIX
        if index not in _INDEX:
            raise ExprError(f"'{name}[{match.group(2)}]': write {name}[k] or {name}[k+1]")
        return name + _INDEX[index]

    return _SUBSCRIPT.sub(one, text)


def index_names(parameters: Collection[str]) -> tuple[str, ...]:
    """``k`` and ``N``, except a name a parameter already holds (that spec's own)."""
    return tuple(n for n in INDEX_NAMES if n not in parameters)


def sequence_names(sequences: Collection[str]) -> tuple[str, ...]:
    """Each sequence's name and its next-value name (``theta``, ``theta_next``)."""
    return tuple(n for s in sequences for n in (s, s + NEXT_SUFFIX))


def uses_step(expr: Expr | None, step_names: Collection[str]) -> bool:
    """Whether an expression uses k, N or a sequence."""
    return expr is not None and bool(expr.names() & frozenset(step_names))


def sequence_keys(raw: object, fail: Fail) -> list[str]:
    """The names ``sequences:`` defines, checked (valid, not reserved)."""
    if raw is None:
        return []
    if not isinstance(raw, dict) or not raw:
        raise fail("sequences", "must be a mapping name: {first: ..., next: ..., last: ...}")
    if len(raw) > MAX_SEQUENCES:
        raise fail("sequences", f"more than {MAX_SEQUENCES} sequences")
    for name in raw:
        where = f"sequences.{str(name)[:40]}"
        if not isinstance(name, str) or not PARAM_RE.fullmatch(name):
            raise fail(where, "not a valid sequence name")
        if name in RESERVED or name in INDEX_NAMES or name.endswith(NEXT_SUFFIX):
            raise fail(where, f"name is reserved (k, N, m, L, kappa, functions, names "
                       f"ending in {NEXT_SUFFIX})")
    return list(raw)


def parse_sequences(raw: object, names: list[str], index: tuple[str, ...], fail: Fail,
                    expr: ExprOf) -> dict[str, SequenceDecl]:
    """``sequences:`` name -> {first, next, last}: ``first`` an expression of m, L, kappa,
    N and earlier sequences' first values; ``next`` and ``last`` of m, L, kappa, k, N, every
    sequence's value at k and earlier sequences' next values."""
    out: dict[str, SequenceDecl] = {}
    for i, name in enumerate(names):
        body = raw[name]  # type: ignore[index]
        where = f"sequences.{name}"
        if not isinstance(body, dict):
            raise fail(where, "must be a mapping {first: ..., next: ..., last: ...}")
        for key in body:
            if key not in SEQUENCE_KEYS:
                raise fail(f"{where}.{str(key)[:40]}", "unknown field (use first, next, last)")
        for key in ("first", "next"):
            if key not in body:
                raise fail(f"{where}.{key}", "missing")
        earlier = names[:i]
        at_first = (*BASE_NAMES, *(n for n in index if n == "N"), *earlier)
        at_next = (*BASE_NAMES, *index, *names, *(e + NEXT_SUFFIX for e in earlier))
        first = expr(body["first"], at_first, f"{where}.first")
        nxt = expr(body["next"], at_next, f"{where}.next")
        last = expr(body["last"], at_next, f"{where}.last") if "last" in body else None
        out[name] = SequenceDecl(name, first, nxt, last)
    return out


def parse_schedule(pname: str, raw: list, range_: tuple[Expr, Expr] | None, fixed: bool,
                   fail: Fail, expr: ExprOf) -> Parameter:
    """A per-step list of values (expressions of m, L, kappa): one value per step, so the
    horizon is its length. ``fixed``: written as a bare list (a tie per step)."""
    where = f"parameters.{pname}" + ("" if fixed else ".value")
    if not raw:
        raise fail(where, "empty list (one value per step)")
    if len(raw) > MAX_SCHEDULE:
        raise fail(where, f"more than {MAX_SCHEDULE} values")
    entries = tuple(expr(v, BASE_NAMES, f"{where}[{i}]") for i, v in enumerate(raw))
    return Parameter(pname, value=entries[0], range=range_, schedule=entries, per_step=True,
                     fixed=fixed)


def schedule_lengths(parameters: Mapping[str, Parameter]) -> dict[str, int]:
    """The length of each listed schedule (a spec's lists must agree: they fix N)."""
    return {p: len(par.schedule) for p, par in parameters.items() if par.schedule is not None}


def per_step_flag(raw: Any, where: str, fail: Fail) -> bool:
    """``per_step:`` true or false."""
    if not isinstance(raw, bool):
        raise fail(where, "must be true or false")
    return raw
