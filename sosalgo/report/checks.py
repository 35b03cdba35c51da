"""What ``sosalgo verify`` shows: one line per result row and its check."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sosalgo.report import format_table
from sosalgo.schema import CHECK_COLUMNS

__all__ = ["CHECK_COLUMNS", "checks_table", "entry_text", "ledger_lines"]


def checks_table(rows: Sequence[Mapping[str, Any]],
                 checks: Sequence[Mapping[str, Any] | None]) -> str:
    """kappa, rho, verdict ("no certificate" for rows that claim none), proven rate,
    simulation outcome and the reason of a failure."""
    table = [{"kappa": r["kappa"], "rho": (c or {}).get("rho"),
              "verified": "no certificate" if c is None else c["verified"],
              "rho_proven": None if c is None else c["rho_proven_float"],
              "simulation": _simulation(c),
              "reason": None if c is None else c["reason"]}
             for r, c in zip(rows, checks, strict=True)]
    return format_table(table, CHECK_COLUMNS)


def _simulation(check: Mapping[str, Any] | None) -> str | None:
    """ok, VIOLATION or skipped (the test functions could not be built)."""
    sim = None if check is None else check.get("simulation")
    if sim is None:
        return None
    if "skipped" in sim:
        return "skipped"
    return "ok" if sim["ok"] else "VIOLATION"


def ledger_lines(ledger: Sequence[Mapping[str, Any]], counts: Mapping[str, int]
                 ) -> list[str]:
    """The claim ledger of ``sosalgo verify``: one line per claim that is backed,
    recomputed, contradicted or unsupported (the context fields are only counted)."""
    lines = ["claims:"]
    for e in ledger:
        if e["status"] != "context":
            lines.append(f"  {e['status']:<12} {entry_text(e)}")
    lines.append("  " + ", ".join(f"{v} {k}" for k, v in counts.items()))
    return lines


def entry_text(e: Mapping[str, Any]) -> str:
    """One ledger entry in words: where, the field, its claimed value and the reason."""
    where = "document" if e["row"] is None else f"row {e['row']}"
    claimed = e["claimed"]
    shown = f"{claimed:.10g}" if isinstance(claimed, float) else str(claimed)
    return f"{where}: {e['field']} = {shown[:40]} -- {e['reason']}"
