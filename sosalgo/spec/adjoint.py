"""Linear operators with their transposes in a spec: calls of M^T, functions composed with
M, and the optimality condition that pairs them (``sosalgo pep`` only).

Three fields, all optional, describe a problem such as min_x f(x) + g(Mx):

- an ``oracles:`` entry ``{function: M, transpose: true}`` calls M^T (M of a
  linear operator class: ``linear_operator``): its answer is M^T y at the call's point y;
- a function's ``at: M`` says its point at the solution is M x* (g is composed with M);
- ``optimality: [f, M.T(g)]`` lists the terms whose sum vanishes at the solution:
  s_f* + M^T s_g* = 0 with s_j* the (sub)gradient of f_j at its point at the solution
  (x*, or M x* for a function ``at: M``). Exactly one term is transposed; every function
  that is not a linear operator appears once.

A spec with a transpose call needs ``optimality:`` (and conversely). The model at the
solution (:meth:`sosalgo.oracles.OracleMethod.reference_tables`): each call of f_j is at
its reference point with answer s_j*, each call of M at x* (answer M x*), each call of M^T
at s_g* (answer M^T s_g* = minus the other terms).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Adjoint", "parse_adjoint"]


def _linear(decl: Any) -> bool:
    """Whether a function's class is a linear operator with a transpose call."""
    from sosalgo.classes import CLASSES

    return bool(getattr(CLASSES.get(decl.cls), "transposable", False))

_TRANSPOSED = re.compile(r"^\s*([A-Za-z][A-Za-z0-9_]*)\.T\(\s*([A-Za-z][A-Za-z0-9_]*)\s*\)\s*$")
_PLAIN = re.compile(r"^\s*([A-Za-z][A-Za-z0-9_]*)\s*$")


@dataclass(frozen=True)
class Adjoint:
    """The transpose calls (0-based call indices), the functions composed with an
    operator (function -> operator, ``at:``) and the optimality condition: ``plain``
    functions plus ``dual`` = (operator, function), the transposed term."""

    transposes: frozenset[int]
    images: dict[str, str] = field(default_factory=dict)
    plain: tuple[str, ...] = ()
    dual: tuple[str, str] = ("", "")

    @property
    def operators(self) -> frozenset[str]:
        """The linear operators of the model (they have no free optimal subgradient)."""
        return frozenset({self.dual[0], *self.images.values()})


def parse_adjoint(data: Mapping[str, Any], raw_oracles: object, images: dict[str, str],
                  functions: Mapping[str, Any], fail: Callable[[str, str], Exception]
                  ) -> Adjoint | None:
    """The spec's :class:`Adjoint` (None when it has no transpose call, no ``at:`` and no
    ``optimality:``); ``fail(field, message)`` for every error."""
    transposes = _transposes(raw_oracles, functions, fail)
    raw = data.get("optimality")
    if not transposes and raw is None and not images:
        return None
    if raw is None:
        where = "oracles" if transposes else f"functions.{next(iter(images))}.at"
        raise fail(where, "needs optimality: (the terms that vanish at the solution, e.g. "
                   "[f, M.T(g)])")
    if not isinstance(raw, list) or not raw:
        raise fail("optimality", "must be a non-empty list of terms (NAME or M.T(NAME))")
    for fname, op in images.items():
        if op not in functions or not _linear(functions[op]):
            raise fail(f"functions.{fname}.at", f"{str(op)[:40]!r} is not a function of "
                       "a linear operator class")
    plain, duals = _terms(raw, functions, images, fail)
    if len(duals) != 1:
        raise fail("optimality", "needs exactly one transposed term M.T(NAME), got "
                   f"{len(duals)}")
    op, g = duals[0]
    if images.get(g) != op:
        raise fail("optimality", f"{op}.T({g}): {g} must be composed with {op} "
                   f"(functions.{g}.at: {op})")
    for i in transposes:
        name = _oracle_name(raw_oracles, i)
        if name != op:
            raise fail(f"oracles[{i}].transpose", f"{name}.T: only {op}, the operator of "
                       "optimality:, is transposed")
    for fname, decl in functions.items():
        if _linear(decl):
            continue
        if fname not in (*plain, g):
            raise fail("optimality", f"{fname} is in no term (every function that is not "
                       "a linear operator appears once)")
    for fname, decl in functions.items():
        if _linear(decl) and fname != op:
            raise fail(f"functions.{fname}", f"a second linear operator beside {op} is "
                       "not supported with transpose calls")
    return Adjoint(frozenset(transposes), dict(images), tuple(plain), (op, g))


def _oracle_name(raw: object, i: int) -> str:
    entry = raw[i] if isinstance(raw, list) else None
    return str(entry.get("function") if isinstance(entry, dict) else entry)


def _transposes(raw: object, functions: Mapping[str, Any],
                fail: Callable[[str, str], Exception]) -> set[int]:
    out = set()
    for i, entry in enumerate(raw if isinstance(raw, list) else ()):
        if not isinstance(entry, dict) or "transpose" not in entry:
            continue
        where = f"oracles[{i}].transpose"
        if entry["transpose"] is not True and entry["transpose"] is not False:
            raise fail(where, "must be true or false")
        if set(entry) - {"function", "transpose"}:
            raise fail(where, "a transpose call has no other key")
        if not entry["transpose"]:
            continue
        name = entry.get("function")
        decl = functions.get(name) if isinstance(name, str) else None
        if decl is not None and not _linear(decl):
            raise fail(where, f"{name} ({decl.cls}) has no transpose call: only a "
                       "linear operator has one")
        out.add(i)
    return out


def _terms(raw: list, functions: Mapping[str, Any], images: dict[str, str],
           fail: Callable[[str, str], Exception]) -> tuple[list[str], list[tuple[str, str]]]:
    plain: list[str] = []
    duals: list[tuple[str, str]] = []
    for i, term in enumerate(raw):
        where = f"optimality[{i}]"
        text = term if isinstance(term, str) else ""
        dual, one = _TRANSPOSED.match(text), _PLAIN.match(text)
        if not (dual or one):
            raise fail(where, f"{str(term)[:40]!r}: a term is NAME or M.T(NAME)")
        names = dual.groups() if dual else (None, one.group(1))
        for name in names:
            if name is not None and name not in functions:
                raise fail(where, f"{name!r} names no function")
        fname = names[1]
        if _linear(functions[fname]):
            raise fail(where, f"{fname} is a linear operator, not a term")
        if fname in plain or any(fname == g for _, g in duals):
            raise fail(where, f"{fname} appears twice")
        if dual:
            if not _linear(functions[names[0]]):
                raise fail(where, f"{names[0]}.T: {names[0]} ({functions[names[0]].cls}) "
                           f"has no transpose: only a linear operator has one")
            duals.append((names[0], fname))
        else:
            if fname in images:
                raise fail(where, f"{fname} is composed with {images[fname]}: its term is "
                           f"{images[fname]}.T({fname})")
            plain.append(fname)
    return plain, duals
