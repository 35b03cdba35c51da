"""The docs table of the conformance suite, from the case files and ``results.csv`` (never
from a run: the docs build does not run PEPit)."""

from __future__ import annotations

from bench.conformance import ROOT, read_results
from bench.conformance.cases import Case, load_all

DOCS = ROOT / "docs" / "conformance.md"
START, END = "<!-- conformance table: start -->", "<!-- conformance table: end -->"


def agreeing(case: Case, results: dict) -> bool:
    """Every argument set run, agreeing with PEPit and proven not below it (and not below a
    tight theoretical value)."""
    rows = [results.get((case.example, i)) for i in range(len(case.arguments))]
    return case.expressed and all(
        r and r["agree"] == "yes" and r["not_below"] == "yes"
        and r["above_theoretical"] in ("yes", "") for r in rows)


def _num(value: float | None) -> str:
    return f"{value:.7g}" if value is not None else "—"


def _cell(text: str) -> str:
    """Text in a Markdown table cell (a bar would end the cell)."""
    return text.replace("|", "\\|")


def _text(text: str) -> str:
    """Prose in a Markdown table cell: bars and asterisks (x*, f*) escaped."""
    return _cell(text).replace("*", "\\*")


def _scaled(r: dict, key: str) -> float | None:
    return float(r[key]) * float(r["scale"]) if r[key] else None


def case_lines(case: Case, results: dict) -> list[str]:
    name = f"`{case.example}`"
    if not case.expressed:
        r = results.get((case.example, 0))
        pepit = _num(float(r["pepit_tau"])) if r and r["pepit_tau"] else ""
        return [f"| {name} | not expressible: {_text(case.reason)} | {pepit} | | | | | |"]
    lines = []
    for i in range(len(case.arguments)):
        r = results.get((case.example, i))
        label = name if i == 0 else "″"
        if r is None:
            lines.append(f"| {label} | `{' '.join(case.command(i))}` | not run | | | | | |")
            continue
        ratio = f"{float(r['time_ratio']):.1f}" if r["time_ratio"] else "—"
        if r["time_ratio"] and r["pepit_process_seconds"]:
            whole = float(r["sosalgo_seconds"]) / float(r["pepit_process_seconds"])
            ratio += f" ({whole:.1f})"
        command = _cell(r["command"].removeprefix("sosalgo "))
        lines.append(f"| {label} | `{command}` ({r['arguments']}) | "
                     f"{_num(float(r['pepit_tau']) if r['pepit_tau'] else None)} | "
                     f"{_num(_scaled(r, 'tau'))} | {_num(_scaled(r, 'tau_proven'))} | "
                     f"{r['witness_verified'] or '—'} | {ratio} | {verdict(r)} |")
    return lines


def verdict(r: dict) -> str:
    """The row's verdict in words; an agreeing proof further than 1e-6 above PEPit says so."""
    if r["pepit_error"] or r["sosalgo_error"]:
        return f"error: {_text(r['pepit_error'] or r['sosalgo_error'])}"
    if not r["tau_proven"]:
        return "agrees, not proven" if r["agree"] == "yes" else "differs, not proven"
    if r["above_theoretical"] == "no":
        return "proven below the tight theoretical value"
    if r["agree"] != "yes" or r["not_below"] != "yes":
        return "differs"
    if float(r["pepit_tau"]) == 0:  # a worst case of 0 (no initial condition)
        return "agrees" if _scaled(r, "tau_proven") == 0 else "agrees (proof above 0)"
    gap = _scaled(r, "tau_proven") / float(r["pepit_tau"]) - 1
    return "agrees" if gap <= 1e-6 else f"agrees (proof {gap:.1e} above)"


def table() -> str:
    cases, results = load_all(), read_results()
    good = sum(agreeing(c, results) for c in cases)
    head = [f"**{good} of {len(cases)} expressed and agreeing** "
            f"({sum(c.expressed for c in cases)} expressed).", "",
            "| example | sosalgo command (PEPit's arguments), or why not | PEPit τ | ours τ | "
            "ours proven | witness verified | time ratio | verdict |",
            "|---|---|---:|---:|---:|---|---:|---|"]
    body = [line for case in cases for line in case_lines(case, results)]
    return "\n".join(head + body + [""] + needs_tally(cases))


def needs_tally(cases: list[Case]) -> list[str]:
    """What the examples not expressed need: each tag with its examples' count."""
    count: dict[str, int] = {}
    for case in cases:
        for need in case.needs:
            count[need] = count.get(need, 0) + 1
    lines = ["| what is missing | examples that need it |", "|---|---:|"]
    return lines + [f"| {need} | {n} |" for need, n in sorted(count.items(), key=lambda x: -x[1])]


def write_docs() -> None:
    text = DOCS.read_text()
    before, rest = text.split(START, 1)
    after = rest.split(END, 1)[1]
    DOCS.write_text(f"{before}{START}\n{table()}\n{END}{after}")
