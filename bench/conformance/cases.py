"""The conformance cases: one YAML file per PEPit example under ``cases/``.

A case names the example (``example``: its path under ``PEPit/examples`` without
``.py``; ``function``: its ``wc_`` function), lists PEPit keyword argument sets
(``arguments``: the example's own defaults first, then two others) and says either
``status: expressed`` with the sosalgo command that asks the same question, or
``status: not expressible`` with ``needs`` (short tags) and ``reason``.

An expressed case's ``command`` is what a user types after ``sosalgo``; ``{expr}`` in it
is an expression of the argument set's numbers (parsed by sosalgo's expression parser,
never eval'ed), e.g. ``--kappa {L/mu}``; ``commands`` may give one command per argument
set (``null``: ``command``). ``scale`` (an expression of the arguments, default ``1``) is
what sosalgo's tau is multiplied by to be PEPit's: sosalgo's classes have m = 1 (or L = 1
for ``m: 0`` specs), and the measures are homogeneous in f (``scale_reason`` says how).
``theoretical_tight`` (one value, or one per argument set) says where the example's
theoretical value is the exact worst case, so that a proven bound must be above it; that
value is then also a reference of the verdicts beside PEPit's float (``pepit_accuracy``
says where PEPit's float is above it by its solver's accuracy).
"""

from __future__ import annotations

import json
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
CASES = HERE / "cases"
# the PEPit 0.5.1 examples, one a line: "path function parameters" (comma-separated, the
# optional ones marked "?"; wrapper, solver and verbose left out)
EXAMPLES = HERE / "examples.txt"
EXPRESSED, NOT_EXPRESSIBLE = "expressed", "not expressible"
_FIELDS = {"example", "function", "question", "arguments", "status", "command", "commands",
           "scale", "scale_reason", "theoretical_tight", "pepit_accuracy", "fast", "needs",
           "reason", "zero"}
_PLACEHOLDER = re.compile(r"\{([^{}]+)\}")


class CaseError(ValueError):
    """A case file that is not well-formed: the message names the file and the field."""


@dataclass(frozen=True)
class Case:
    example: str
    function: str
    question: str
    arguments: tuple[dict, ...]
    status: str
    commands: tuple[str, ...] = ()  # one per argument set (expressed cases)
    scale: str = "1"
    scale_reason: str = ""
    tight: tuple[bool, ...] = ()
    fast: bool = False
    needs: tuple[str, ...] = ()
    reason: str = ""
    zero: bool = False  # the worst case is exactly 0 (a question with no initial condition)

    @property
    def expressed(self) -> bool:
        return self.status == EXPRESSED

    def command(self, index: int) -> list[str]:
        """The sosalgo command line of argument set ``index`` (without ``sosalgo``)."""
        return shlex.split(fill(self.commands[index], self.arguments[index]))

    def scale_at(self, index: int) -> float:
        return evaluate(self.scale, self.arguments[index])


def listed_examples() -> list[tuple[str, str]]:
    """The committed list of PEPit's examples: (path, function)."""
    rows = [line.split() for line in EXAMPLES.read_text().splitlines() if line.strip()]
    return [(r[0], r[1]) for r in rows]


def listed_parameters() -> dict[str, tuple[set[str], set[str]]]:
    """Each example's (required, optional) keyword parameters, from the committed list."""
    out = {}
    for line in EXAMPLES.read_text().splitlines():
        if line.strip():
            path, _, names = line.split()
            names = names.split(",")
            out[path] = ({n for n in names if not n.endswith("?")},
                         {n[:-1] for n in names if n.endswith("?")})
    return out


def case_files() -> list[Path]:
    return sorted(CASES.rglob("*.yaml"))


def load_all() -> list[Case]:
    return [load(p) for p in case_files()]


def load(path: Path, root: Path = CASES) -> Case:
    """The case in ``path``, a file under ``root`` (its example is its path there)."""
    path, root = Path(path).resolve(), Path(root).resolve()
    where = str(path.relative_to(HERE.parents[1])) if path.is_relative_to(HERE.parents[1]) \
        else str(path)
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict):
        raise CaseError(f"{where}: not a mapping")
    unknown = set(data) - _FIELDS
    if unknown:
        raise CaseError(f"{where}: {sorted(unknown)[0]}: unknown field")
    for key in ("example", "function", "question", "arguments", "status"):
        if key not in data:
            raise CaseError(f"{where}: {key}: missing")
    example = str(path.relative_to(root).with_suffix(""))
    if data["example"] != example:
        raise CaseError(f"{where}: example: {data['example']!r} is not the file's path {example!r}")
    args = data["arguments"]
    if not (isinstance(args, list) and len(args) >= 3 and all(isinstance(a, dict) for a in args)):
        raise CaseError(f"{where}: arguments: at least three mappings (the defaults, two others)")
    common = dict(example=example, function=str(data["function"]),
                  question=str(data["question"]), arguments=tuple(args))
    if data["status"] == NOT_EXPRESSIBLE:
        return _not_expressible(where, data, common)
    if data["status"] != EXPRESSED:
        raise CaseError(f"{where}: status: {EXPRESSED!r} or {NOT_EXPRESSIBLE!r}")
    return _expressed(where, data, common)


def _not_expressible(where: str, data: dict, common: dict) -> Case:
    needs, reason = data.get("needs"), data.get("reason")
    if not (isinstance(needs, list) and needs and isinstance(reason, str) and reason.strip()):
        raise CaseError(f"{where}: needs, reason: a not expressible case says what it needs")
    if "command" in data:
        raise CaseError(f"{where}: command: only for expressed cases")
    return Case(status=NOT_EXPRESSIBLE, needs=tuple(map(str, needs)), reason=reason, **common)


def _expressed(where: str, data: dict, common: dict) -> Case:
    n = len(common["arguments"])
    command = data.get("command")
    if not isinstance(command, str) or not command.startswith("pep "):
        raise CaseError(f"{where}: command: a sosalgo command, e.g. "
                        "'pep specs/ogm.yaml --steps {n}'")
    per_set = data.get("commands") or [None] * n
    if len(per_set) != n:
        raise CaseError(f"{where}: commands: one per argument set")
    tight = data.get("theoretical_tight", False)
    tight = tuple(tight) if isinstance(tight, list) else (bool(tight),) * n
    if len(tight) != n:
        raise CaseError(f"{where}: theoretical_tight: one value, or one per argument set")
    case = Case(status=EXPRESSED, commands=tuple(c or command for c in per_set),
                scale=str(data.get("scale", "1")), scale_reason=str(data.get("scale_reason", "")),
                tight=tight, fast=bool(data.get("fast", False)),
                zero=bool(data.get("zero", False)), **common)
    for i in range(n):
        try:
            case.command(i)
            case.scale_at(i)
        except (ValueError, KeyError) as exc:
            raise CaseError(f"{where}: command or scale at arguments[{i}]: {exc}") from None
    return case


def evaluate(text: str, args: dict) -> float:
    """The value of an expression of the argument set's numbers (parsed, never eval'ed)."""
    from sosalgo.kernel.expr import compile_expression, parse_tree

    names = [k for k, v in args.items() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    return compile_expression(parse_tree(text, names), names)([float(args[k]) for k in names])


def number(value: float) -> str:
    """The shortest text of a float; integers without a point."""
    return str(int(value)) if float(value).is_integer() else repr(float(value))


def fill(template: str, args: dict) -> str:
    return _PLACEHOLDER.sub(lambda m: number(evaluate(m.group(1), args)), template)


def arguments_text(args: dict) -> str:
    return json.dumps(args, separators=(", ", "="))[1:-1].replace('"', "")
