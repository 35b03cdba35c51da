"""Parameter overrides: ``--set NAME=EXPR`` fixes a parameter. The spec's text is
rewritten with ``NAME: EXPR`` (a tie, so the parameter is neither analysed at its
``value`` nor free in a design), parsed by the same expression parser as the spec.
``--set NAME.range=[LO, HI]`` instead replaces the range a design searches (the
parameter keeps its value and stays free; a per-step parameter stays per step).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sosalgo.errors import InputError

__all__ = ["apply_overrides", "parse_set_options", "same_overrides_applied"]

MAX_OVERRIDES = 64
RANGE = ".range"  # --set NAME.range=[LO, HI]: the design range of NAME


def parse_set_options(values: Sequence[str] | Mapping[str, str] | None) -> dict[str, str]:
    """``--set NAME=EXPR`` options (or a mapping NAME -> EXPR) as a dict; one InputError
    naming ``--set`` for a malformed or repeated option."""
    if not values:
        return {}
    pairs = (list(values.items()) if isinstance(values, Mapping)
             else [_split(v) for v in values])
    if len(pairs) > MAX_OVERRIDES:
        raise InputError(f"--set: more than {MAX_OVERRIDES} overrides")
    out: dict[str, str] = {}
    for name, expr in pairs:
        if not isinstance(name, str) or not isinstance(expr, str):
            raise InputError("--set: expected NAME=EXPR (text)")
        if name in out:
            raise InputError(f"--set {name}: given twice")
        out[name] = expr
    return out


def _split(option: str) -> tuple[str, str]:
    name, eq, expr = str(option).partition("=")
    if not eq or not name.strip() or not expr.strip():
        raise InputError(f"--set {option}: expected NAME=EXPR, e.g. --set h=1/L")
    return name.strip(), expr.strip()


def apply_overrides(text: str, overrides: Mapping[str, str], source: str) -> str:
    """The spec text with each parameter of ``overrides`` fixed to its expression (YAML
    re-emitted; comments are not kept). Unknown parameters, expressions the parser refuses
    and overrides that make the spec invalid (a tie referring to itself, a cycle) are one
    InputError naming ``--set`` and the parameter."""
    import yaml

    from sosalgo.kernel.expr import ExprError, parse_tree
    from sosalgo.spec.loading import spec_from_text
    from sosalgo.spec.types import BASE_NAMES, SpecError

    if not overrides:
        return text
    from sosalgo.spec.time_varying import index_names, rewrite_indices, sequence_names

    base = spec_from_text(text, source)  # the spec's own errors are the spec's
    data = yaml.safe_load(text)
    params = data.get("parameters") or {}
    names = (frozenset(BASE_NAMES) | frozenset(base.parameters)
             | frozenset(index_names(base.parameters)) | frozenset(sequence_names(base.sequences)))
    for name, expr in overrides.items():
        if name.endswith(RANGE):
            _set_range(params, base, name, expr, names)
            continue
        if name not in base.parameters:
            known = ", ".join(base.parameters) or "none"
            raise InputError(f"--set {name}: unknown parameter of {source} (parameters: "
                             f"{known})")
        value: str | list[str] = _schedule(name, expr)
        try:
            for entry in [value] if isinstance(value, str) else value:
                parse_tree(rewrite_indices(entry, base.sequences),
                           BASE_NAMES if isinstance(value, list) else names)
        except ExprError as exc:
            raise InputError(f"--set {name}: {exc}") from None
        params[name] = value
    data["parameters"] = params
    new = yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=1000,
                         default_flow_style=None)
    try:
        spec_from_text(new, source)
    except SpecError as exc:
        which = ", ".join(overrides)
        raise InputError(f"--set {which}: {exc.field}: {exc.message}") from None
    return new


def _set_range(params: dict, base: Any, name: str, expr: str, names: frozenset) -> None:
    """``params`` with the range of ``NAME`` (``name`` is ``NAME.range``) set to the two
    expressions of ``expr`` (``[LO, HI]``); one InputError naming the option else."""
    from sosalgo.kernel.expr import ExprError, parse_tree

    pname = name[:-len(RANGE)]
    if pname not in base.parameters:
        known = ", ".join(base.parameters) or "none"
        raise InputError(f"--set {name}: unknown parameter {pname!r} of {base.source} "
                         f"(parameters: {known})")
    text = expr.strip()
    ends = [e.strip() for e in text[1:-1].split(",")] if text[:1] + text[-1:] == "[]" else []
    if len(ends) != 2 or not all(ends):
        raise InputError(f"--set {name}: expected [LO, HI], e.g. --set {pname}.range=[0, 7/L]")
    try:
        for e in ends:
            parse_tree(e, names)
    except ExprError as exc:
        raise InputError(f"--set {name}: {exc}") from None
    raw = params.get(pname)
    entry = dict(raw) if isinstance(raw, dict) else {"value": raw}
    if isinstance(raw, list) or entry.get("value") is None:
        raise InputError(f"--set {name}: {pname} has no value to keep (give it a value "
                         f"in the spec, or fix it with --set {pname}=EXPR)")
    entry["range"] = ends
    params[pname] = entry


def _schedule(name: str, expr: str) -> str | list[str]:
    """``[e1, e2, ...]``: one value per step (a list of expressions); else ``expr``."""
    text = expr.strip()
    if not (text.startswith("[") and text.endswith("]")):
        return expr
    inner = text[1:-1]
    if "[" in inner or "]" in inner:
        raise InputError(f"--set {name}: a list of values [e1, e2, ...] (expressions of m, "
                         "L, kappa), one per step")
    entries = [e.strip() for e in inner.split(",")]
    if not all(entries):
        raise InputError(f"--set {name}: empty entry in the list {text}")
    return entries


def same_overrides_applied(text: str, overrides: Mapping[str, str], source: str) -> bool:
    """Whether ``text`` already holds ``overrides`` (applying them changes nothing)."""
    import yaml

    return yaml.safe_load(apply_overrides(text, overrides, source)) == yaml.safe_load(text)
