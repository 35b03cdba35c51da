"""Algorithm specs: YAML in, validated symbolic templates out.

A spec describes a first-order method in the state-space form of eq. (10) of the paper,

    xi_{k+1} = A xi_k + B grad f(y_k),   y_k = C xi_k,   x_k = E xi_k,

through the reduced templates A (n x n), B (n x 1), C and E (1 x n) of Remark 1 (the
Kronecker factor ``⊗ I_d`` is implied). Entries are safe expressions (see
:mod:`sosalgo.kernel.expr`) of the parameters and of ``m``, ``L``, ``kappa``. Loading checks
shapes, names, ranges, cycles among tied parameters and the fixed-point conditions of eq. (11).

Every problem is reported as a :class:`SpecError` naming the file and the field.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import select
import stat
import time
from collections.abc import Collection, Mapping
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sosalgo.kernel.expr import Expr, ExprError, constant_value, parse_tree
from sosalgo.kernel.expr.tree import Measure, check_measure, measure
from sosalgo.spec.checks import run_checks
from sosalgo.spec.types import (
    BASE_NAMES,
    FLOW_KEY,
    MAX_FILE_BYTES,
    MAX_FUNCTIONS,
    MAX_KAPPA_POINTS,
    MAX_ORACLES,
    MAX_PARAMETERS,
    MAX_REFERENCES,
    MAX_STATE,
    MAX_WAIT_SECONDS,
    MEASURES,
    NAME_RE,
    PARAM_RE,
    RESERVED,
    RESERVED_COLUMNS,
    TOP_KEYS,
    ExprMatrix,
    FunctionDecl,
    Parameter,
    Spec,
    SpecError,
    tied_order,
    value_order,
)

__all__ = [
    "SpecError", "Parameter", "Spec", "load_spec", "read_spec_text", "spec_from_dict",
    "spec_from_text",
]

# --------------------------------------------------------------------------- loading



def constant_parameters(params: dict[str, Any]) -> frozenset[str]:
    """The parameters whose value is one number for the whole run: not per step, and
    (through ties) in m, L, kappa and such parameters only; a class parameter may name
    them (the class is the same at every step; ``--set`` reaches it)."""
    done: set[str] = set()
    grew = True
    while grew:
        grew = False
        for name, par in params.items():
            if name in done or par.per_step or par.schedule is not None:
                continue
            names = set().union(*(e.names() for e in (par.value, par.tied) if e is not None))
            if names <= set(BASE_NAMES) | done:
                done.add(name)
                grew = True
    return frozenset(done)

class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys and aliases (no billion-laughs tricks)."""


def _construct_mapping(loader: _StrictLoader, node: yaml.MappingNode, deep: bool = False):
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        try:
            hash(key)
        except TypeError:
            raise yaml.constructor.ConstructorError(
                None, None, "mapping keys must be plain scalars", key_node.start_mark
            ) from None
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark
            )
        seen.add(key)
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_StrictLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping
)


def _compose_node(self: _StrictLoader, parent, index):
    if self.check_event(yaml.AliasEvent):
        event = self.peek_event()
        raise yaml.composer.ComposerError(
            None, None, "YAML aliases are not supported", event.start_mark
        )
    return yaml.SafeLoader.compose_node(self, parent, index)


_StrictLoader.compose_node = _compose_node  # type: ignore[method-assign]


def _construct_object(self: _StrictLoader, node: yaml.Node, deep: bool = False) -> Any:
    """PyYAML's constructors fail with KeyError, IndexError, ... on explicitly tagged values
    such as ``!!bool abc`` or ``!!timestamp x``: report them as YAML errors at the node."""
    try:
        return yaml.SafeLoader.construct_object(self, node, deep=deep)
    except (ArithmeticError, AttributeError, LookupError, TypeError, ValueError):
        tag = str(node.tag).replace("tag:yaml.org,2002:", "!!")
        raise yaml.constructor.ConstructorError(
            None, None, f"invalid {tag} value", node.start_mark
        ) from None


_StrictLoader.construct_object = _construct_object  # type: ignore[method-assign]


def read_spec_text(path: str | Path) -> str:
    """The text of a spec file, read once and bounded in size (:data:`MAX_FILE_BYTES`).

    A regular file or a terminal is read as it is. A pipe (``/dev/stdin`` fed by a pipe,
    ``<(...)``, a named FIFO) is read as it arrives, but the whole text must have arrived
    within :data:`MAX_WAIT_SECONDS`: a FIFO nobody writes to is refused, not waited on
    forever. A directory, a block device or a socket is refused. Where no such file
    exists, a shipped example's name (``nesterov``) reads that example."""
    source = str(path)
    try:
        mode = os.stat(path).st_mode
        if stat.S_ISDIR(mode):
            raise SpecError(source, "", "is a directory, not a spec file")
        if stat.S_ISFIFO(mode):
            raw = _read_pipe(source)
        elif stat.S_ISREG(mode) or stat.S_ISCHR(mode):
            with open(path, "rb") as fh:  # bounded: /dev/zero or a growing file never ends
                raw = fh.read(MAX_FILE_BYTES + 1)
        else:
            raise SpecError(source, "", "not a regular file, a pipe or a terminal")
        if len(raw) > MAX_FILE_BYTES:
            raise SpecError(source, "", f"file larger than {MAX_FILE_BYTES} bytes")
        return raw.decode("utf-8")
    except SpecError:
        raise
    except FileNotFoundError:
        return _shipped_or_missing(source)
    except IsADirectoryError:
        raise SpecError(source, "", "is a directory, not a spec file") from None
    except UnicodeDecodeError:
        raise SpecError(source, "", "not UTF-8 text") from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the path
        reason = getattr(exc, "strerror", None) or str(exc)
        raise SpecError(source, "", f"cannot read ({reason})") from None


def _shipped_or_missing(source: str) -> str:
    """The text of the shipped example a bare name stands for (``nesterov``: no such file
    here); else the one-line error naming the closest shipped example."""
    from sosalgo.spec.names import closest_example, shipped_example

    example = shipped_example(source)
    if example is not None:
        return example.read_bytes()[: MAX_FILE_BYTES + 1].decode("utf-8")
    close = closest_example(source)
    hint = (f" (closest shipped example: {close}; `sosalgo examples` lists them)"
            if close else "")
    raise SpecError(source, "", f"no such file{hint}")


def spec_text_and_path(name: str) -> tuple[str, str]:
    """Text and location of a shipped example spec."""
    try:
        from sosalgo.kernel.resources import example_specs

        p: Any = example_specs()[name]
    except ImportError:  # a checkout without packaged examples: the repository's specs/
        p = Path(__file__).resolve().parent.parent / "specs" / f"{name}.yaml"
    return p.read_text(encoding="utf-8"), str(p)


def _read_pipe(source: str) -> bytes:
    """A pipe's bytes up to its end (or one more than MAX_FILE_BYTES), all within
    MAX_WAIT_SECONDS; opened without blocking, so a FIFO without a writer times out."""
    deadline = time.monotonic() + MAX_WAIT_SECONDS
    fd = os.open(source, os.O_RDONLY | os.O_NONBLOCK)
    try:
        poller = select.poll()
        poller.register(fd, select.POLLIN | select.POLLHUP)
        chunks: list[bytes] = []
        size = 0
        while size <= MAX_FILE_BYTES:
            left = deadline - time.monotonic()
            events = poller.poll(max(0, int(left * 1000))) if left > 0 else []
            if not events:
                what = "incomplete" if size else "nothing to read"
                raise SpecError(source, "", f"{what} after {MAX_WAIT_SECONDS:g} s (a pipe or "
                                "FIFO whose writer never finishes?)")
            try:
                data = os.read(fd, MAX_FILE_BYTES + 1 - size)
            except BlockingIOError:
                continue
            if not data:
                if any(ev & select.POLLHUP for _, ev in events):
                    break  # the writer closed its end: the text is complete
                time.sleep(0.05)  # no writer yet (Linux reports no event for that)
                continue
            chunks.append(data)
            size += len(data)
        return b"".join(chunks)
    finally:
        os.close(fd)


def operator_functions(spec: Spec) -> list[str]:
    """``name (class)`` of each function of ``spec`` whose class is an operator class (no
    function values, :mod:`sosalgo.classes.operator`)."""
    from sosalgo.classes import CLASSES

    return [f"{name} ({decl.cls})" for name, decl in spec.functions.items()
            if not CLASSES[decl.cls].has_values]


def set_functions(spec: Spec) -> list[str]:
    """``name (class)`` of each function of ``spec`` when every one is an indicator of a
    set (zero values: a feasibility problem, no function value to measure), else []."""
    from sosalgo.classes import CLASSES

    found = [f"{name} ({decl.cls})" for name, decl in spec.functions.items()
             if CLASSES[decl.cls].zero_values]
    return found if len(found) == len(spec.functions) else []


def load_spec(path: str | Path) -> Spec:
    """Read and validate a YAML spec file."""
    return spec_from_text(read_spec_text(path), source=str(path))


def spec_from_text(text: str, source: str = "<spec>") -> Spec:
    """Parse YAML text into a validated spec."""
    if len(text) > MAX_FILE_BYTES:
        raise SpecError(source, "", f"text longer than {MAX_FILE_BYTES} characters")
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - strict *safe* loader
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"line {mark.line + 1}" if mark is not None else "YAML"
        problem = (exc.problem or exc.context or "invalid YAML").strip()
        raise SpecError(source, where, f"invalid YAML: {problem}") from None
    except (yaml.YAMLError, RecursionError, MemoryError, ValueError, LookupError) as exc:
        raise SpecError(source, "", f"invalid YAML: {type(exc).__name__}") from None
    return spec_from_dict(data, source=source)


def spec_from_dict(data: object, source: str = "<spec>") -> Spec:
    """Validate an already-parsed spec mapping."""
    try:
        return _Builder(source).build(data)
    except RecursionError:
        raise SpecError(source, "", "structure nested too deeply") from None


class _Builder:
    def __init__(self, source: str):
        self.source = source
        self.sequence_keys: list[str] = []  # sequences: s[k], s[k+1] are rewritten
        self.step_names: tuple[str, ...] = ()  # k, N and the sequences' names
        self.in_references = False  # references may use s[N], a sequence's last value

    def fail(self, field_: str, message: str) -> SpecError:
        return SpecError(self.source, field_, message)

    def pep_terms(self, raw: object, references: Mapping[str, Any] | None = None
                  ) -> dict[str, Any]:
        """``pep: {measure: TERMS, initial: TERMS, constraints: [RELATION, ...],
        references: [NAME, ...]}`` (the terms are parsed by ``sosalgo pep``,
        :mod:`sosalgo.worstcase.terms`, which names pep.measure, pep.initial or
        pep.constraints[i]; constraints are kept as a list; ``references`` names the spec's
        references that are values of pep's question, not of analyze's:
        :func:`sosalgo.spec.references.reference_values` leaves them empty)."""
        if raw is None:
            return {}
        cons = raw.get("constraints") if isinstance(raw, dict) else None
        if cons is not None and (not isinstance(cons, list) or not cons or len(cons) > 100
                                 or not all(isinstance(c, str) and c.strip() for c in cons)):
            raise self.fail("pep.constraints", "expected a list of relations such as "
                            "'gamma*grad(x_0) == 2*f(x_0)' (==, <= or >=)")
        refs = self.pep_references(raw, references or {})
        text = {k: v for k, v in raw.items() if k not in ("constraints", "references")
                } if isinstance(raw, dict) else raw
        if (not isinstance(text, dict) or not raw
                or set(text) - {"measure", "initial"}
                or not all(isinstance(v, str) and v.strip() for v in text.values())):
            raise self.fail("pep", "expected a mapping with measure, initial, constraints "
                                   "and/or references, the first two terms such as "
                                   "'mingrad', 'f(x_0) - f(x_N)'")
        out: dict[str, Any] = {str(k): str(v) for k, v in text.items()}
        if cons is not None:
            out["constraints"] = [str(c) for c in cons]
        if refs is not None:
            out["references"] = refs
        return out

    def pep_references(self, raw: object, references: Mapping[str, Any]) -> list[str] | None:
        """``pep.references``: names of the spec's references (None when absent)."""
        names = raw.get("references") if isinstance(raw, dict) else None
        if names is None:
            return None
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise self.fail("pep.references", "expected a list of the names of references")
        for n in names:
            if n not in references:
                raise self.fail("pep.references", f"{n[:60]!r} is not one of references:")
        return list(names)

    # -- top level -------------------------------------------------------------------
    def build(self, data: object) -> Spec:
        if not isinstance(data, dict):
            raise self.fail("", "a spec must be a YAML mapping (name, parameters, matrices, ...)")
        if FLOW_KEY in data:  # a continuous-time question: its equivalent method
            from sosalgo.spec.flow import flow_spec  # sympy: only for flow specs

            data = flow_spec(data, self.fail)
        for key in data:
            if not isinstance(key, str) or key not in TOP_KEYS:
                known = ", ".join(sorted(TOP_KEYS))
                raise self.fail(str(key)[:40], f"unknown field (known: {known})")
        name = self.name(data.get("name"))
        description = data.get("description", "")
        if not isinstance(description, str):
            raise self.fail("description", "must be a string")
        if not _is_unicode(description):
            raise self.fail("description", "contains an invalid (surrogate) character")
        m = self.m_value(data.get("m", 1), "kappa" in data)
        L = self.l_value(data, m)

        raw_params = data.get("parameters", {})
        if raw_params is None:
            raw_params = {}
        if not isinstance(raw_params, dict):
            raise self.fail("parameters", "must be a mapping of parameter names")
        if len(raw_params) > MAX_PARAMETERS:
            raise self.fail("parameters", f"more than {MAX_PARAMETERS} parameters")
        symbols: list[str] = []
        for pname in raw_params:
            if not isinstance(pname, str) or not PARAM_RE.fullmatch(pname):
                raise self.fail(f"parameters.{str(pname)[:40]}", "not a valid parameter name")
            if pname in RESERVED:
                raise self.fail(f"parameters.{pname}", "name is reserved")
            symbols.append(pname)
        sequences = self.sequences(data.get("sequences"), symbols)
        names = frozenset(BASE_NAMES) | frozenset(symbols) | frozenset(self.step_names)
        params = {p: self.parameter(p, raw, names) for p, raw in raw_params.items()}
        tied_order(params, self.source)  # detects cycles
        value_order(params, self.source)

        self.counts: dict[str, Any] = {}
        self.images: dict[str, str] = {}
        functions = self.functions(data.get("functions"), constant_parameters(params))
        if "finite_sum" in data or self.counts:
            return self.finite_sum_spec(data, name, description, m, L, params, functions,
                                        names)
        raw_oracles = data.get("oracles", ["f"])
        from sosalgo.spec.adjoint import parse_adjoint

        adjoint = parse_adjoint(data, raw_oracles, self.images, functions, self.fail)
        inexact = self.oracle_errors(raw_oracles, names)
        error_refs, twins = self.oracle_links(raw_oracles)
        lmo = self.oracle_lmo(raw_oracles)
        oracles = self.oracles(_oracle_names(raw_oracles), functions)
        epsilon = self.oracle_epsilon(raw_oracles, names, functions)
        measure = data.get("measure", "function")
        if measure not in MEASURES:
            raise self.fail("measure", f"must be one of {', '.join(MEASURES)}")
        raw_matrices = data.get("matrices")
        output = self.output(data, raw_matrices, len(oracles))
        matrices = self.matrices(raw_matrices, names, len(oracles), output is not None)
        named = self.check_sizes(params, matrices)
        varies = self.varies(sequences, params, matrices)
        from sosalgo.spec.time_varying import LAST_SUFFIX

        self.in_references = True
        ends = (*(("N",) if "N" in self.step_names else ()),
                *(s + LAST_SUFFIX for s in sequences))
        references = self.references(data.get("references", {}), ends)
        self.in_references = False
        varies = varies or any(e.names() & set(ends) for e in references.values())
        kappa = () if m == 0 else self.kappa(data.get("kappa", [10]))
        if varies and data.get("initial_state") is not None:
            raise self.fail("initial_state", "not supported for a method that changes with k "
                            "(it starts at xi_0 = u x0)")
        from sosalgo.spec.initial_state import parse_initial_state

        initial_state = parse_initial_state(data.get("initial_state"), {*BASE_NAMES, *symbols},
                                            len(matrices["A"]), functions, self.fail)
        for i, pair in enumerate(initial_state or ()):
            for e in pair:
                self.check_size(e, named, f"initial_state[{i}]")
        spec = Spec(
            name=name, description=description, source=self.source, parameters=params,
            matrices=matrices, references=references, kappa=kappa, m=m,
            functions=functions, oracles=oracles, inexact=inexact, lmo=lmo, output=output,
            epsilon=epsilon,
            error_refs=error_refs, twins=twins,
            measure=measure, L=L,
            initial_state=initial_state, m_expr=parse_tree(data.get("m", 1), ()),
            L_expr=parse_tree(data["L"], ()) if L is not None else None,
            sequences=sequences, time_varying=varies,
            pep=self.pep_terms(data.get("pep"), references),
            line_search=self.line_search(data.get("line_search"), params, matrices, output),
            span_search=self.span_search(data, functions, oracles),
            mirror=self.mirror(data, functions, matrices, output, inexact or lmo or epsilon),
            adjoint=adjoint,
        )
        if spec.sublinear:
            self.check_sublinear(spec)
        if adjoint is not None:
            self.check_adjoint(spec, data)
        return run_checks(spec, data, self.fail)

    def check_adjoint(self, spec: Spec, data: dict) -> None:
        """Transpose calls with no other special step (:mod:`sosalgo.spec.adjoint`)."""
        others = {"line_search": spec.line_search, "mirror": spec.mirror,
                  "initial_state": spec.initial_state,
                  "pep.constraints": spec.pep.get("constraints"),
                  "oracles": spec.inexact or spec.lmo or spec.twins}
        if spec.time_varying:
            raise self.fail("optimality", "transpose calls: not for a method that changes "
                            "with k")
        for where, value in others.items():
            if value:
                raise self.fail(where, "not with transpose calls (optimality:)")

    def finite_sum_spec(self, data: dict, name: str, description: str, m: float,
                        L: float | None, params: dict[str, Parameter],
                        functions: dict[str, FunctionDecl], names: frozenset[str]) -> Spec:
        """A spec whose method is a ``finite_sum:`` program (no matrices; ``sosalgo pep``
        only, :mod:`sosalgo.spec.finite_sum`)."""
        from sosalgo.spec.finite_sum import parse_finite_sum

        for key in ("matrices", "oracles", "output", "initial_state", "sequences",
                    "line_search", "certificate", "measure"):
            if key in data:
                raise self.fail(key, "not with finite_sum: (the step is its program)")
        if "finite_sum" not in data:
            raise self.fail("finite_sum", "missing: a function with count: (or per_step:) "
                                          "is called by the step of finite_sum:")
        fs = parse_finite_sum(data["finite_sum"], self.counts, names, self.fail,
                              lambda raw: self.expr(raw, names, "finite_sum.blocks"))
        self.in_references = True  # one function per step: references may use N
        references = self.references(data.get("references", {}),
                                     ("N",) if fs.per_step and "N" in self.step_names else ())
        self.in_references = False
        kappa = () if m == 0 else self.kappa(data.get("kappa", [10]))
        return Spec(
            name=name, description=description, source=self.source, parameters=params,
            matrices={}, references=references, kappa=kappa, m=m, functions=functions,
            oracles=(), measure="function", L=L, m_expr=parse_tree(data.get("m", 1), ()),
            L_expr=parse_tree(data["L"], ()) if L is not None else None,
            pep=self.pep_terms(data.get("pep"), references), finite_sum=fs)

    def name(self, raw: object) -> str:
        if raw is None:
            raise self.fail("name", "missing (a short file-name-safe identifier)")
        if not isinstance(raw, str) or not NAME_RE.fullmatch(raw) or ".." in raw:
            raise self.fail(
                "name", "must be letters, digits, '_', '-', '.' (no path separators, no '..')"
            )
        return raw

    def m_value(self, raw: object, has_kappa: bool) -> float:
        try:
            val = constant_value(parse_tree(raw, ()))
        except ExprError as exc:
            raise self.fail("m", str(exc)) from None
        if val == 0 and has_kappa:
            raise self.fail("m", "m: 0 with kappa (kappa = L/m is undefined): for sublinear "
                            "rates give L and no kappa")
        if val == 0:
            return 0.0
        if not (math.isfinite(val) and val > 0):
            raise self.fail("m", "must be a positive finite number")
        return val

    def l_value(self, data: dict, m: float) -> float | None:
        """``L``: given exactly when ``m: 0`` (a positive constant expression)."""
        if "L" not in data:
            if m == 0:
                raise self.fail("L", "missing: m: 0 (sublinear rates) needs L, a positive "
                                "number")
            return None
        if m != 0:
            raise self.fail("L", "only with m: 0 (otherwise L = kappa * m)")
        try:
            val = constant_value(parse_tree(data["L"], ()))
        except ExprError as exc:
            raise self.fail("L", str(exc)) from None
        if not (math.isfinite(val) and val > 0):
            raise self.fail("L", "must be a positive finite number")
        return val

    def check_sublinear(self, spec: Spec) -> None:
        """A sublinear spec: no expression uses kappa (undefined when m = 0), and the
        measure is a function value (the distance to a minimizer need not decrease; an
        operator spec has no function value: ``measure: distance``)."""
        if spec.measure != "function" and not (operator_functions(spec)
                                               or set_functions(spec)):
            raise self.fail("measure", "distance has no rate when m: 0 (the minimizer need "
                            "not be unique): use measure: function")
        found = [(f"parameters.{p}", e) for p, par in spec.parameters.items()
                 for e in (par.value, par.tied, *(par.range or ()))]
        found += [(f"matrices.{k}", e) for k, rows in spec.matrices.items()
                  for row in rows for e in row]
        found += [(f"references.{k}", e) for k, e in spec.references.items()]
        found += [(f"functions.{f}.{k}", e) for f, d in spec.functions.items()
                  for k, e in d.params.items()]
        found += [(f"sequences.{s}.{k}", getattr(d, k)) for s, d in spec.sequences.items()
                  for k in ("first", "next", "last")]
        found += [(f"parameters.{p}[{i}]", e) for p, par in spec.parameters.items()
                  for i, e in enumerate(par.schedule or ())]
        for where, expr in found:
            if expr is not None and "kappa" in expr.names():
                raise self.fail(where, "uses kappa, undefined when m: 0 (use L)")

    # -- the oracle model ------------------------------------------------------------
    def functions(self, raw: object, spec_names: frozenset[str] = frozenset(),
                  field: str = "functions") -> dict[str, FunctionDecl]:
        """``functions:`` name -> {class: NAME, <parameter>: expr}; default: one f in
        F(m, L). A class parameter may name the spec's constant parameters ``spec_names``
        too (B's beta as the spec's parameter beta, set by ``--set beta=VALUE``; a free
        one is refused by :func:`sosalgo.inputs.refuse_free_class_parameters`)."""
        from sosalgo.classes import CLASSES, SEED_CLASS

        if raw is None:
            raw = {"f": {"class": SEED_CLASS.name}}
        if not isinstance(raw, dict) or not raw:
            raise self.fail("functions", "must be a non-empty mapping name: {class: ...}")
        if len(raw) > MAX_FUNCTIONS:
            raise self.fail("functions", f"more than {MAX_FUNCTIONS} functions")
        out = {}
        for fname, body in raw.items():
            where = f"{field}.{str(fname)[:40]}"
            if not isinstance(fname, str) or not PARAM_RE.fullmatch(fname):
                raise self.fail(where, "not a valid function name")
            if not isinstance(body, dict) or "class" not in body:
                raise self.fail(where, "must be a mapping {class: NAME, ...}")
            cname = body["class"]
            if not isinstance(cname, str) or cname not in CLASSES:
                raise self.fail(f"{where}.class", f"unknown class {str(cname)[:40]!r} (known: "
                                f"{', '.join(CLASSES)})")
            cls = CLASSES[cname]
            params = {}
            for key, val in body.items():
                if key == "class":
                    continue
                if key == "at":  # composed with a linear operator (sosalgo.spec.adjoint)
                    self.images[fname] = val if isinstance(val, str) else repr(val)[:40]
                    continue
                if key == "count":  # one of n functions drawn per step (finite_sum:)
                    self.counts[fname] = self.expr(val, spec_names | set(BASE_NAMES),
                                                   f"{where}.count")
                    continue
                if key == "per_step":  # a new member of the class at every step
                    if val is not True or "count" in body:
                        raise self.fail(f"{where}.per_step", "true (step k calls f_k, a "
                                        "new function of the class; not with count:)")
                    self.counts[fname] = None
                    continue
                if key not in cls.parameters:
                    raise self.fail(f"{where}.{str(key)[:40]}", f"not a parameter of {cname} "
                                    f"(its parameters: {', '.join(cls.parameters) or 'none'})")
                params[key] = self.expr(val, frozenset(BASE_NAMES) | spec_names,
                                        f"{where}.{key}")
            given = frozenset(params)
            for key in cls.parameters:
                if key not in params:
                    params[key] = self.expr(cls.defaults[key], BASE_NAMES, f"{where}.{key}")
            out[fname] = FunctionDecl(fname, cname, params, given)
        return out

    def oracles(self, raw: object, functions: dict[str, FunctionDecl]) -> tuple[str, ...]:
        """``oracles:`` the function each call queries (one per column of B)."""
        if not isinstance(raw, list) or not raw:
            raise self.fail("oracles", "must be a non-empty list of function names")
        if len(raw) > MAX_ORACLES:
            raise self.fail("oracles", f"more than {MAX_ORACLES} oracle calls")
        for i, name in enumerate(raw):
            if not isinstance(name, str) or name not in functions:
                raise self.fail(f"oracles[{i}]", f"{str(name)[:40]!r} names no function "
                                f"(functions: {', '.join(functions)})")
        for fname in functions:
            if fname not in raw:
                raise self.fail(f"functions.{fname}", "no oracle queries it (list it in "
                                "oracles)")
        return tuple(raw)

    def oracle_errors(self, raw: object, names: frozenset[str]) -> dict[int, Expr]:
        """The inexact calls of ``oracles:``: an entry ``{function: f, relative_error:
        eps}`` is a gradient call answering some d with |d - grad f(y)| <= eps |grad f(y)|
        (eps an expression of m, L, kappa and the parameters; its value, in [0, 1), is
        checked where the method is bound)."""
        out: dict[int, Expr] = {}
        for i, entry in enumerate(raw if isinstance(raw, list) else ()):
            if not isinstance(entry, dict):
                continue
            extra = [str(k)[:40] for k in entry
                     if k not in ("function", "relative_error", "lmo", "relative_to",
                                  "gradient_of", "epsilon", "transpose")]
            if extra:
                raise self.fail(f"oracles[{i}].{extra[0]}", "unknown key (an oracle entry is "
                                "a function name, {function: NAME, relative_error: EPS} or "
                                "{function: NAME, lmo: CALL})")
            if "function" not in entry:
                raise self.fail(f"oracles[{i}]", "missing function: (the function queried)")
            if "relative_error" in entry:
                out[i] = self.expr(entry["relative_error"], names,
                                   f"oracles[{i}].relative_error")
        return out

    def oracle_epsilon(self, raw: object, names: frozenset[str],
                       functions: dict[str, FunctionDecl]) -> dict[int, Expr]:
        """The epsilon-subgradient calls of ``oracles:``: an entry ``{function: f, epsilon:
        eps}`` answers some g with f(z) >= f(y) + <g, z - y> - eps for every z (eps an
        expression of m, L, kappa and the parameters, >= 0; :mod:`sosalgo.worstcase.epsilon`),
        on a convex class with values and a (sub)gradient oracle."""
        from sosalgo.classes import CLASSES

        out: dict[int, Expr] = {}
        for i, entry in enumerate(raw if isinstance(raw, list) else ()):
            if not isinstance(entry, dict) or "epsilon" not in entry:
                continue
            where = f"oracles[{i}].epsilon"
            if set(entry) - {"function", "epsilon"}:
                raise self.fail(where, "an epsilon-subgradient call has no other key "
                                "(relative_error, lmo, relative_to, gradient_of)")
            cls = CLASSES[functions[entry["function"]].cls]
            if (not cls.convex or not cls.has_values
                    or not {"gradient", "subgradient"} & set(cls.oracles)):
                raise self.fail(where, f"{cls.name} has no subgradients with function "
                                "values: an epsilon-subgradient is for a convex class with "
                                "a (sub)gradient oracle")
            out[i] = self.expr(entry["epsilon"], names, where)
        return out

    def oracle_links(self, raw: object) -> tuple[dict[int, tuple[Fraction, ...]],
                                                 dict[int, int]]:
        """(``relative_to``, ``gradient_of``) of ``oracles:``: an inexact proximal call's
        reference vector as rational coefficients on the step's answers (one per call;
        default: the call's own answer), and a call ``{function: f, gradient_of: j}``
        whose answer is the true subgradient of call j's point (an earlier inexact
        proximal call of f in the step): no point of its own (:mod:`sosalgo.worstcase.inexact`).
        Both are 0-based here."""
        refs: dict[int, tuple[Fraction, ...]] = {}
        twins: dict[int, int] = {}
        entries = raw if isinstance(raw, list) else []
        for i, entry in enumerate(entries):
            if not isinstance(entry, dict):
                continue
            if "relative_to" in entry:
                refs[i] = self._reference(entry, i, len(entries))
            if "gradient_of" in entry:
                j, where = entry["gradient_of"], f"oracles[{i}].gradient_of"
                if set(entry) - {"function", "gradient_of"}:
                    raise self.fail(where, "a gradient_of call has no other key")
                if isinstance(j, bool) or not isinstance(j, int) or not 1 <= j <= i:
                    raise self.fail(where, f"{str(j)[:40]!r}: the number (1..{i}) of an "
                                    "earlier call of the step")
                src = entries[j - 1]
                if (not isinstance(src, dict) or "relative_error" not in src
                        or src.get("function") != entry.get("function")):
                    raise self.fail(where, f"call {j} must be an inexact call "
                                    "(relative_error) of the same function")
                twins[i] = j - 1
        return refs, twins

    def _reference(self, entry: dict[str, Any], i: int, p: int) -> tuple[Fraction, ...]:
        where = f"oracles[{i}].relative_to"
        ref = entry["relative_to"]
        if "relative_error" not in entry:
            raise self.fail(where, "a reference vector is for an inexact call "
                            "(relative_error)")
        if not isinstance(ref, list) or len(ref) != p:
            raise self.fail(where, f"a list of {p} rational coefficients, one per call of "
                            "the step (the answers the error is relative to)")
        try:
            out = tuple(Fraction(str(v)) for v in ref if not isinstance(v, bool))
        except (ValueError, ZeroDivisionError):
            out = ()
        if len(out) != p or not any(out):
            raise self.fail(where, f"a list of {p} rational coefficients, not all 0")
        return out

    def oracle_lmo(self, raw: object) -> dict[int, int]:
        """The linear minimization calls of ``oracles:``: an entry ``{function: h, lmo:
        j}`` answers u = s - y, s a minimizer of <g, .> over the set h indicates, g the
        answer of call j (1-based, as ``y<j>``: an earlier gradient call of the same step).
        Returns call index -> direction call index (0-based)."""
        out: dict[int, int] = {}
        for i, entry in enumerate(raw if isinstance(raw, list) else ()):
            if not isinstance(entry, dict) or "lmo" not in entry:
                continue
            j = entry["lmo"]
            where = f"oracles[{i}].lmo"
            if "relative_error" in entry:
                raise self.fail(where, "a linear minimization call has no relative error")
            if isinstance(j, bool) or not isinstance(j, int) or not 1 <= j <= i:
                raise self.fail(where, f"{str(j)[:40]!r}: the number (1..{i}) of an earlier "
                                "call of the step whose answer is the direction")
            if isinstance(raw[j - 1], dict) and "lmo" in raw[j - 1]:
                raise self.fail(where, f"call {j} is a linear minimization call: the "
                                "direction is a gradient call's answer")
            out[i] = j - 1
        return out

    def mirror(self, data: dict[str, Any], functions: dict[str, FunctionDecl],
               matrices: dict[str, ExprMatrix], output: int | None,
               special: object) -> dict[str, Any] | None:
        """``mirror: {kernel: {class: NAME, ...}, set: BOOL}``: Bregman steps with the
        kernel h (:mod:`sosalgo.worstcase.mirror`): one function, one call, one state (the
        mirror variable). A class relative to a kernel is refused without it."""
        from sosalgo.classes import CLASSES

        raw = data.get("mirror")
        relative = [f for f, d in functions.items() if getattr(CLASSES[d.cls], "relative", 0)]
        if raw is None:
            if relative:
                decl = functions[relative[0]]
                raise self.fail(f"functions.{relative[0]}.class", f"{decl.cls} is relative "
                                "to a kernel h: give mirror: {kernel: {class: ...}}")
            return None
        if not isinstance(raw, dict) or "kernel" not in raw or set(raw) - {"kernel", "set"}:
            raise self.fail("mirror", "expected {kernel: {class: NAME, ...}, set: true|false}")
        kernel = self.functions({"kernel": raw["kernel"]}, frozenset(), "mirror")["kernel"]
        kcls = CLASSES[kernel.cls]
        if (getattr(kcls, "relative", False) or not kcls.convex or not kcls.has_values
                or kcls.zero_values or not kcls.tilt_invariant or not kcls.homogeneous):
            raise self.fail("mirror.kernel.class", f"{kernel.cls}: the kernel must be a convex "
                            "function class with values (convex, strongly_convex, ...)")
        if not isinstance(raw.get("set", False), bool):
            raise self.fail("mirror.set", "must be true or false")
        if len(functions) != 1 or len(matrices["A"]) != 1 or len(matrices["B"][0]) != 1:
            raise self.fail("mirror", "a Bregman step is one function, one call, one state "
                            "(the mirror variable z = grad h(x))")
        if output is not None or special or data.get("line_search") is not None \
                or data.get("initial_state") is not None or data.get("sequences"):
            raise self.fail("mirror", "not with output, inexact or linear minimization "
                            "calls, line_search, initial_state or sequences")
        return {"kernel": kernel, "set": bool(raw.get("set", False))}

    def line_search(self, raw: object, params: dict[str, Parameter],
                    matrices: dict[str, ExprMatrix], output: int | None) -> str | None:
        """``line_search: NAME``: the parameter gamma of a gradient method x+ = x - gamma u
        (A = C = E = [[1]], B = [[b]] with b an expression of gamma, no D) chosen at every
        step by exact line search (the next gradient orthogonal to u)."""
        if raw is None:
            return None
        if not isinstance(raw, str) or raw not in params:
            raise self.fail("line_search", f"{str(raw)[:40]!r} names no parameter (the step "
                            "chosen by exact line search)")
        ones = [("A", matrices["A"]), ("C", matrices["C"])]
        ones += [] if output is not None else [("E", matrices.get("E"))]
        shape = all(M is not None and len(M) == 1 and len(M[0]) == 1 and M[0][0].is_constant
                    and constant_value(M[0][0]) == 1 for _, M in ones)
        B = matrices["B"]
        if not (shape and len(B) == 1 and len(B[0]) == 1 and raw in B[0][0].names()
                and "D" not in matrices):
            raise self.fail("line_search", "exact line search is for x+ = x - gamma u: one "
                            "state and one call, A = C = E = [[1]], B = [[-gamma]], no D")
        return raw

    def span_search(self, data: dict, functions: dict[str, FunctionDecl],
                    oracles: tuple[str, ...]) -> bool:
        """``span_search: true``: the line search's step minimizes f over x_0 + the span of
        every gradient so far (conjugate gradient); with ``line_search`` on a gradient call
        of a class with a (sub)gradient oracle and values."""
        from sosalgo.classes import CLASSES

        raw = data.get("span_search", False)
        if not isinstance(raw, bool):
            raise self.fail("span_search", "expected true or false")
        if not raw:
            return False
        if data.get("line_search") is None:
            raise self.fail("span_search", "a span search is an exact line search over the "
                            "span of the past gradients: give line_search: NAME (the step "
                            "parameter of x+ = x - gamma u) too")
        cls = CLASSES[functions[oracles[0]].cls]
        if not {"gradient", "subgradient"} & set(cls.oracles) or not cls.has_values:
            raise self.fail("span_search", f"{oracles[0]} ({cls.name}) has no gradient "
                            "call: a span search needs the gradients of a function with "
                            "values")
        return True

    def output(self, data: dict, raw_matrices: object, p: int) -> int | None:
        """``output: y<i>`` (top level or under matrices): the output is the point of oracle
        call i (1-based); None when absent (x = E xi)."""
        inner = raw_matrices.get("output") if isinstance(raw_matrices, dict) else None
        if inner is not None and "output" in data:
            raise self.fail("output", "given twice (top level and under matrices)")
        raw = data.get("output", inner)
        where = "output" if "output" in data else "matrices.output"
        if raw is None:
            return None
        text = str(raw)
        if not (isinstance(raw, str) and re.fullmatch(r"y[1-9][0-9]?", text)
                and int(text[1:]) <= p):
            raise self.fail(where, f"must be y1..y{p} (the point of an oracle call)")
        return int(text[1:]) - 1

    # -- parameters ------------------------------------------------------------------
    def parameter(self, pname: str, raw: object, names: frozenset[str]) -> Parameter:
        from sosalgo.spec.time_varying import parse_schedule, per_step_flag, uses_step

        where = f"parameters.{pname}"
        if isinstance(raw, dict):
            for key in raw:
                if key not in ("value", "range", "per_step"):
                    raise self.fail(f"{where}.{str(key)[:40]}",
                                    "unknown field (use value, range, per_step)")
            if "value" not in raw:
                raise self.fail(f"{where}.value", "missing (analysis needs a value)")
            rng = None
            if "range" in raw:
                rng = self.range(raw["range"], f"{where}.range")
            flag = per_step_flag(raw.get("per_step", False), f"{where}.per_step", self.fail)
            if isinstance(raw["value"], list):
                return parse_schedule(pname, raw["value"], rng, False, self.fail, self.expr)
            value = self.expr(raw["value"], names, f"{where}.value")
            if pname in value.names():
                raise self.fail(f"{where}.value", "refers to itself")
            per_step = flag or uses_step(value, self.step_names)
            return Parameter(pname, value=value, range=rng, per_step=per_step)
        if raw is None:
            raise self.fail(where, "missing value: give {value: ..., range: [lo, hi]} or a tie")
        if isinstance(raw, list):
            return parse_schedule(pname, raw, None, True, self.fail, self.expr)
        tied = self.expr(raw, names, where)
        return Parameter(pname, tied=tied)

    # -- methods that change with k ---------------------------------------------------
    def sequences(self, raw: object, symbols: list[str]) -> dict[str, Any]:
        """``sequences:`` (:mod:`sosalgo.spec.time_varying`); sets the names k, N and the
        sequences' that the parameters and matrices may use."""
        from sosalgo.spec.time_varying import (
            index_names,
            parse_sequences,
            sequence_keys,
            sequence_names,
        )

        keys = sequence_keys(raw, self.fail)
        for name in sequence_names(keys):
            if name in symbols:
                raise self.fail(f"parameters.{name}", "a sequence has this name")
        index = index_names(symbols)
        self.sequence_keys = keys
        self.step_names = (*index, *sequence_names(keys))
        return parse_sequences(raw, keys, index, self.fail, self.expr) if keys else {}

    def varies(self, sequences: dict[str, Any], params: dict[str, Parameter],
               matrices: dict[str, ExprMatrix]) -> bool:
        """Whether the method changes with k; the listed schedules must agree in length
        (they fix the horizon N)."""
        from sosalgo.spec.time_varying import schedule_lengths, uses_step

        lengths = schedule_lengths(params)
        if len(set(lengths.values())) > 1:
            (p0, n0), *rest = lengths.items()
            p1, n1 = next((p, n) for p, n in rest if n != n0)
            raise self.fail(f"parameters.{p1}", f"{n1} values, but parameters.{p0} has {n0} "
                            "(one value per step: the lists fix the horizon N)")
        exprs = [e for par in params.values() for e in (par.value, par.tied)]
        exprs += [e for rows in matrices.values() for row in rows for e in row]
        return (bool(sequences) or any(par.per_step for par in params.values())
                or any(uses_step(e, self.step_names) for e in exprs))

    def range(self, raw: object, where: str) -> tuple[Expr, Expr]:
        if not isinstance(raw, list) or len(raw) != 2:
            raise self.fail(where, "must be a list [lo, hi]")
        lo = self.expr(raw[0], BASE_NAMES, f"{where}[0]")
        hi = self.expr(raw[1], BASE_NAMES, f"{where}[1]")
        # ranges may depend on m, L, kappa: constant ones are compared here, the others by
        # check_values at every kappa of the spec.
        if lo.is_constant and hi.is_constant and constant_value(lo) > constant_value(hi):
            raise self.fail(where, f"lower bound {raw[0]} exceeds upper bound {raw[1]}")
        return lo, hi

    def check_sizes(self, params: dict[str, Parameter], matrices: dict[str, ExprMatrix]
                    ) -> dict[str, Measure]:
        """Bound every parameter and matrix entry with tied parameters written out (see
        :func:`sosalgo.kernel.expr.tree.measure`); the measure of each parameter is returned. A
        parameter kept symbolic (an input) has degree at least 1."""
        named: dict[str, Measure] = {}
        for pname in value_order(params, self.source):
            par = params[pname]
            expr = par.tied if par.is_tied else par.value
            where = f"parameters.{pname}" + ("" if par.is_tied else ".value")
            size = self.check_size(expr, named, where)
            if not par.is_tied:
                size = dataclasses.replace(size, degree=max(1.0, size.degree))
            named[pname] = size
        for key, rows in matrices.items():
            for i, row in enumerate(rows):
                for j, e in enumerate(row):
                    self.check_size(e, named, f"matrices.{key}[{i}][{j}]")
        return named

    def check_size(self, expr: Expr, named: dict[str, Measure], where: str) -> Measure:
        try:
            size = measure(expr, named)
            check_measure(size)
        except ExprError as exc:
            raise self.fail(where, str(exc)) from None
        return size

    def expr(self, raw: object, names: Collection[str], where: str) -> Expr:
        try:
            if self.sequence_keys:
                from sosalgo.spec.time_varying import rewrite_indices

                raw = rewrite_indices(raw, self.sequence_keys, self.in_references)
            return parse_tree(raw, names)
        except ExprError as exc:
            raise self.fail(where, str(exc)) from None

    # -- matrices --------------------------------------------------------------------
    def matrices(self, raw: object, names: frozenset[str], p: int = 1,
                 has_output: bool = False) -> dict[str, ExprMatrix]:
        """A (n x n), B (n x p), C (p x n), optional D (p x p) and E (1 x n; absent with
        ``output``), p the number of oracle calls."""
        if raw is None:
            raise self.fail("matrices", "missing (A, B, C, E)")
        if not isinstance(raw, dict):
            raise self.fail("matrices", "must be a mapping with A, B, C, E")
        for key in raw:
            if key not in ("A", "B", "C", "D", "E", "output"):
                raise self.fail(f"matrices.{str(key)[:40]}",
                                "unknown matrix (use A, B, C, D, E)")
        if has_output and "E" in raw:
            raise self.fail("matrices.E", "give E or output, not both")
        needed = ["A", "B", "C"] + ([] if has_output else ["E"])
        out: dict[str, ExprMatrix] = {}
        for key in needed + (["D"] if "D" in raw else []):
            if key not in raw:
                raise self.fail(f"matrices.{key}", "missing")
            out[key] = self.matrix(raw[key], names, f"matrices.{key}")
        n = len(out["A"])
        if _dims(out["A"]) != (n, n):
            raise self.fail("matrices.A", f"must be square, got {_shape(out['A'])}")
        if n > MAX_STATE:
            raise self.fail("matrices.A", f"state dimension {n} exceeds {MAX_STATE}")
        calls = "" if p == 1 else f" (one column per oracle call, {p} calls)"
        shapes = {"B": (n, p), "C": (p, n), "D": (p, p), "E": (1, n)}
        for key, shape in shapes.items():
            if key in out and _dims(out[key]) != shape:
                what = "x".join(map(str, shape))
                raise self.fail(f"matrices.{key}", f"must be {what}{calls if key != 'E' else ''}"
                                f", got {_shape(out[key])}")
        return out

    def matrix(self, raw: object, names: frozenset[str], where: str) -> ExprMatrix:
        if not isinstance(raw, list) or not raw:
            raise self.fail(where, "must be a non-empty list of rows, e.g. [[0, 1], [1, 0]]")
        rows = []
        for i, row in enumerate(raw):
            if not isinstance(row, list) or not row:
                raise self.fail(f"{where}[{i}]", "each row must be a non-empty list")
            rows.append(tuple(self.expr(v, names, f"{where}[{i}][{j}]")
                              for j, v in enumerate(row)))
        widths = {len(r) for r in rows}
        if len(widths) != 1:
            raise self.fail(where, "rows have different lengths")
        return tuple(rows)

    # -- references and kappa --------------------------------------------------------
    def references(self, raw: object, extra: tuple[str, ...] = ()) -> dict[str, Expr]:
        if raw is None:
            return {}
        if not isinstance(raw, dict):
            raise self.fail("references", "must be a mapping name: expression")
        if len(raw) > MAX_REFERENCES:
            raise self.fail("references", f"more than {MAX_REFERENCES} references")
        out = {}
        for key, val in raw.items():
            if not isinstance(key, str) or not key.strip() or len(key) > 80:
                raise self.fail("references", "names must be non-empty strings (<= 80 chars)")
            if not key.isprintable():
                raise self.fail(f"references.{key[:40]}", "name has non-printable characters")
            if key in RESERVED_COLUMNS or re.fullmatch(r"P\d+", key):
                raise self.fail(f"references.{key}", "name clashes with an output column")
            out[key] = self.expr(val, (*BASE_NAMES, *extra), f"references.{key}")
        return out

    def kappa(self, raw: object) -> tuple[float, ...]:
        return parse_kappa(raw, self.source, "kappa")


_PLAIN_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def parse_kappa(raw: object, source: str, where: str) -> tuple[float, ...]:
    """A kappa list ``[2, 10]`` or a range ``{from, to, points, scale: log|linear}``; each
    a :class:`~sosalgo.kernel.kappa.Kappa`, its float with its exact value as written
    (``10/3``; a YAML number or a range point: the shortest decimal of its float)."""
    from sosalgo.kernel.kappa import kappa_written

    def fail(msg: str, sub: str = "") -> SpecError:
        return SpecError(source, where + sub, msg)

    def number(v: object, sub: str) -> float:
        try:
            if isinstance(v, int | float) and not isinstance(v, bool):
                val = float(v)  # a number is a number: no symbolic parsing
            elif isinstance(v, str) and _PLAIN_NUMBER.fullmatch(v.strip()):
                val = float(v)
            else:
                val = constant_value(parse_tree(v, ()))
        except (ExprError, OverflowError) as exc:
            raise fail(str(exc), sub) from None
        if not math.isfinite(val):
            raise fail("must be finite", sub)
        if val <= 1:
            raise fail(f"condition number must be > 1, got {val:g}", sub)
        return kappa_written(val, v)  # its exact value as written (sosalgo.kernel.kappa)

    if isinstance(raw, bool):
        raise fail("must be a number, a list or {from, to, points, scale}")
    if isinstance(raw, int | float | str):
        return (number(raw, ""),)
    if isinstance(raw, list):
        if not raw:
            raise fail("empty list")
        if len(raw) > MAX_KAPPA_POINTS:
            raise fail(f"more than {MAX_KAPPA_POINTS} values")
        return tuple(number(v, f"[{i}]") for i, v in enumerate(raw))
    if isinstance(raw, dict):
        allowed = {"from", "to", "points", "scale"}
        for key in raw:
            if key not in allowed:
                raise fail("unknown field (use from, to, points, scale)", f".{str(key)[:40]}")
        for key in ("from", "to", "points"):
            if key not in raw:
                raise fail("missing", f".{key}")
        lo = number(raw["from"], ".from")
        hi = number(raw["to"], ".to")
        if lo > hi:
            raise fail(f"from ({lo:g}) exceeds to ({hi:g})")
        pts = raw["points"]
        if isinstance(pts, bool) or not isinstance(pts, int) or not 1 <= pts <= MAX_KAPPA_POINTS:
            raise fail(f"must be an integer in 1..{MAX_KAPPA_POINTS}", ".points")
        scale = raw.get("scale", "log")
        if scale not in ("log", "linear"):
            raise fail("must be 'log' or 'linear'", ".scale")
        if pts == 1:
            return (lo,)
        vals = np.geomspace(lo, hi, pts) if scale == "log" else np.linspace(lo, hi, pts)
        return (lo, *(kappa_written(float(v)) for v in vals[1:-1]), hi)
    raise fail("must be a number, a list or {from, to, points, scale}")


def _is_unicode(text: str) -> bool:
    """False when ``text`` holds a lone surrogate (it could not be written as UTF-8)."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _dims(mat: ExprMatrix) -> tuple[int, int]:
    return len(mat), len(mat[0])


def _shape(mat: ExprMatrix) -> str:
    return "{}x{}".format(*_dims(mat))


def _oracle_names(raw: object) -> object:
    """``oracles:`` with each ``{function: NAME, ...}`` entry replaced by its NAME."""
    if not isinstance(raw, list):
        return raw
    return [e.get("function") if isinstance(e, dict) else e for e in raw]
