"""The claim ledger of ``sosalgo verify``: every field of every row of a result document,
with what backs it.

Each entry is ``{"row", "field", "claimed", "status", "proven", "reason"}``; ``row`` is
the row's index (None for a field of the document itself). Statuses:

* ``backed``: proven, in exact or outward-rounded arithmetic, at least as good as
  claimed in the safe direction (a rate or an upper bound: proven <= claimed; a lower
  bound: re-proven >= claimed);
* ``recomputed``: a value computed in floating point from the spec alone (a closed-form
  reference, a sampled value on quadratics) that verify computed again and found equal;
  not a proof, and never called one;
* ``contradicted``: the check disproves the claim, or it does not hold;
* ``unsupported``: nothing in the document lets verify check it (with the reason);
* ``context``: not a claim about the method: the inputs the claims are made under
  (kappa, theta's names, the family), how the run went (seconds, solver, steps) or a
  certificate that backs another entry.

:func:`vouched` is True only when no entry is contradicted or unsupported and at least
one is backed (a document that claims nothing is not vouched for).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from fractions import Fraction
from typing import Any

from sosalgo.spec import Spec

__all__ = ["BAD", "RowLedger", "entry", "frac", "ledger_counts", "rate_ok", "row_ledger",
           "vouched", "why_not"]

BACKED, RECOMPUTED, CONTRADICTED = "backed", "recomputed", "contradicted"
UNSUPPORTED, CONTEXT = "unsupported", "context"
BAD = (CONTRADICTED, UNSUPPORTED)

# not claims about the method: how the run went, where it is written, or what a run's
# own --verify found (claims, vouched, unbacked: verify derives them again)
RUN_FIELDS = frozenset({
    "seconds", "solves", "solver", "steps", "tol", "error", "warning", "max_eig_M",
    "min_eig_P", "rho_infeasible", "csv", "csvs", "figures", "source", "spec_text",
    "spec", "time_limited", "time_limit", "timed_out", "evaluations", "check_kind",
    "check", "simulation", "constant_estimate", "verification", "index", "kind",
    "method", "rate_type", "gap_met", "objective", "objective_status", "description",
    "free", "box", "name", "note", "notes", "estimate", "claims", "vouched", "unbacked"})
CONDITION_FIELDS = frozenset({"kappa", "family", "lag", "reference", "set"})


def entry(row: int | None, field: str, claimed: Any, status: str, reason: str,
          proven: Any = None) -> dict[str, Any]:
    return {"row": row, "field": field, "claimed": _short(claimed), "status": status,
            "proven": proven, "reason": reason}


def _short(v: Any) -> Any:
    """Scalars as they are; objects and lists summarized (the ledger stays readable)."""
    if isinstance(v, Mapping):
        return f"<object with {len(v)} fields>"
    if isinstance(v, list):
        return f"<list of {len(v)}>"
    if isinstance(v, str) and len(v) > 80:
        return v[:77] + "..."
    return v


def vouched(ledger: Sequence[Mapping[str, Any]]) -> bool:
    return (not any(e["status"] in BAD for e in ledger)
            and any(e["status"] == BACKED for e in ledger))


def ledger_counts(ledger: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    out = {s: 0 for s in (BACKED, RECOMPUTED, CONTRADICTED, UNSUPPORTED, CONTEXT)}
    for e in ledger:
        out[e["status"]] += 1
    return out


def frac(x: Any) -> Fraction | None:
    """The exact value of a float, int or "p/q" string; None when it has none."""
    if x is None or isinstance(x, bool):
        return None
    try:
        if isinstance(x, str):
            return Fraction(x)
        if isinstance(x, float) and not math.isfinite(x):
            return None
        return Fraction(x)
    except (ValueError, ZeroDivisionError, TypeError, OverflowError):
        return None


def rate_ok(check: Mapping[str, Any] | None) -> bool:
    """The rate (or constant) check proved its certificate exactly and no simulation
    found a violation."""
    if not check or check.get("noise_only"):
        return False
    sim = check.get("simulation")
    bad_sim = isinstance(sim, Mapping) and "skipped" not in sim and sim.get("ok") is False
    return check.get("verified") == "exact" and not bad_sim


def why_not(check: Mapping[str, Any] | None, what: str = "rate") -> str:
    if not check or check.get("noise_only"):
        return f"no {what} certificate was checked"
    sim = check.get("simulation")
    if check.get("verified") == "exact" and isinstance(sim, Mapping):
        return f"the simulation found {sim.get('violations', 'a')} violation(s)"
    return f"the exact check failed: {check.get('reason') or check.get('verified')}"


# --------------------------------------------------------------------------- one row
class RowLedger:
    """The entries of one row: a handler per field, the rest unknown (unsupported)."""

    def __init__(self, spec: Spec, i: int | None, row: Mapping[str, Any],
                 check: Mapping[str, Any] | None,
                 handlers: Mapping[str, Callable] | None = None):
        self.spec, self.i, self.row, self.check = spec, i, row, check
        self.out: list[dict[str, Any]] = []
        self.handlers = dict(handlers or {})
        self.cache: dict[str, Any] = {}  # proofs shared by several fields of the row

    def add(self, field: str, status: str, reason: str, proven: Any = None) -> None:
        self.out.append(entry(self.i, field, self.row.get(field), status, reason, proven))

    def rate_ok(self) -> bool:
        return rate_ok(self.check)

    def run(self) -> list[dict[str, Any]]:
        for field in self.row:
            if field in self.handlers:
                self.handlers[field](self, field)
            elif field in RUN_FIELDS:
                self.add(field, CONTEXT, "how the result was computed, not a claim")
            elif field in CONDITION_FIELDS:
                self.add(field, CONTEXT, "a condition the claims are proven under")
            else:
                self.add(field, UNSUPPORTED, "not a field sosalgo writes here: nothing in "
                                             "the document lets verify check it")
        return self.out


def row_ledger(spec: Spec, i: int | None, row: Mapping[str, Any],
               check: Mapping[str, Any] | None,
               handlers: Mapping[str, Callable] | None = None) -> list[dict[str, Any]]:
    """The entries of one row: ``handlers`` (field -> function(ledger, field)) for the
    claims, the rest context (known run fields) or unsupported (unknown fields)."""
    return RowLedger(spec, i, row, check, handlers).run()
