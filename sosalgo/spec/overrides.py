"""Parameter overrides: ``--set NAME=EXPR`` fixes a parameter. The spec's text is
rewritten with ``NAME: EXPR`` (a tie, so the parameter is neither analysed at its
``value`` nor free in a design), parsed by the same expression parser as the spec.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from sosalgo.errors import InputError

__all__ = ["apply_overrides", "parse_set_options", "same_overrides_applied"]

MAX_OVERRIDES = 64


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
