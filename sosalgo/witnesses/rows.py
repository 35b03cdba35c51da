"""The witnesses of one analysis row: a cycle when no rate is certified, the rate bracket
otherwise (fields of :class:`sosalgo.analysis.AnalysisResult`, CSV cells, the verdict)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from sosalgo.errors import InputError, ModelError
from sosalgo.witnesses.brackets import BRACKET_KINDS, bracketed, rate_bracket

__all__ = ["BRACKET_CHOICES", "DEFAULT_BRACKETS", "EMPTY", "check_witness_options",
           "verdict", "with_witnesses", "witness_cells", "witness_fields", "witness_json"]

DEFAULT_BRACKETS = "quadratic"
BRACKET_CHOICES = (*BRACKET_KINDS, "none")
MAX_CYCLE_SECONDS = 600.0
CYCLE_SECONDS = 5.0  # default time of the cycle search per uncertified row
EMPTY: dict[str, Any] = {"rho_lower": None, "rho_lower_kind": None,
                         "rho_lower_witness": None, "cycle": None}


def witness_fields(spec: Any, kappa: float, theta: Mapping[str, float] | None,
                   certified: bool, rho: float | None, brackets: str = DEFAULT_BRACKETS,
                   cycle_seconds: float = CYCLE_SECONDS) -> dict[str, Any]:
    """``rho_lower``, ``rho_lower_kind``, ``rho_lower_witness`` and ``cycle`` of a row:
    a cycle searched (within ``cycle_seconds``) when not certified (then rho_lower = 1,
    kind "cycle"); else the bracket asked for (``brackets``: quadratic, self-similar,
    none; self-similar gets ``cycle_seconds`` too). Nothing (all None) when the method
    cannot be made exact."""
    search_cycle = not certified and cycle_seconds > 0
    if brackets == "none" and not search_cycle:
        return dict(EMPTY)
    try:
        if search_cycle:  # sympy and the exact verifier: only where nothing is certified
            from sosalgo.witnesses.cycles import find_cycle

            cyc = find_cycle(spec, kappa, theta, seconds=cycle_seconds)
            if cyc is not None:
                return {"rho_lower": 1.0, "rho_lower_kind": "cycle",
                        "rho_lower_witness": None, "cycle": cyc}
        if brackets == "none":
            return dict(EMPTY)
        lo, kind, wit = rate_bracket(bracketed(spec, kappa, theta), rho if certified else None,
                                     self_similar=brackets == "self-similar",
                                     seconds=max(cycle_seconds, 1.0))
    except (ValueError, ModelError, ArithmeticError, np.linalg.LinAlgError):
        return dict(EMPTY)
    return {"rho_lower": lo, "rho_lower_kind": kind, "rho_lower_witness": wit,
            "cycle": None}


def with_witnesses(spec: Any, kappa: float, theta: Mapping[str, float] | None, res: Any,
                   brackets: str = DEFAULT_BRACKETS,
                   cycle_seconds: float = CYCLE_SECONDS) -> Any:
    """An :class:`~sosalgo.analysis.AnalysisResult` with the fields of
    :func:`witness_fields` filled in (the Python API's ``analyze(..., brackets=...)``)."""
    import dataclasses

    return dataclasses.replace(res, **witness_fields(spec, kappa, theta, res.certified,
                                                     res.rho, brackets, cycle_seconds))


def check_witness_options(brackets: Any, cycle_seconds: Any) -> None:
    """InputError (one line naming the option) for a bad --brackets or --cycle-seconds."""
    if brackets not in BRACKET_CHOICES:
        raise InputError(f"--brackets {brackets}: must be one of {', '.join(BRACKET_CHOICES)}")
    if (isinstance(cycle_seconds, bool) or not isinstance(cycle_seconds, int | float)
            or not 0 <= cycle_seconds <= MAX_CYCLE_SECONDS):
        raise InputError(f"--cycle-seconds {cycle_seconds}: must be in [0, "
                         f"{MAX_CYCLE_SECONDS:g}]")


def witness_cells(fields: Mapping[str, Any]) -> dict[str, Any]:
    """CSV cells: rho_lower, rho_lower_kind, cycle_length, and the witnesses as JSON."""
    cyc, wit = fields.get("cycle"), fields.get("rho_lower_witness")
    return {"rho_lower": fields.get("rho_lower"), "rho_lower_kind": fields.get("rho_lower_kind"),
            "cycle_length": None if cyc is None else cyc["length"],
            "cycle": None if cyc is None else json.dumps(cyc, separators=(",", ":")),
            "rho_lower_witness": None if wit is None else json.dumps(wit,
                                                                     separators=(",", ":"))}


def witness_json(row: Mapping[str, str]) -> dict[str, Any]:
    """The JSON fields of a CSV row's witness cells (None where empty or absent)."""
    def load(key: str) -> Any:
        text = row.get(key) or ""
        return json.loads(text) if text else None

    lo = row.get("rho_lower") or ""
    return {"rho_lower": float(lo) if lo else None,
            "rho_lower_kind": row.get("rho_lower_kind") or None,
            "rho_lower_witness": load("rho_lower_witness"), "cycle": load("cycle")}


def verdict(row: Mapping[str, Any]) -> str:
    """One line per row: "does not converge: cycle of length K", "worst-case rate in
    [lower, certified]", or what is known when not certified."""
    cyc, lo, rho = row.get("cycle"), row.get("rho_lower"), row.get("rho")
    if cyc:
        return f"does not converge: cycle of length {cyc['length']}"
    if row.get("certified") and rho is not None:
        return (f"worst-case rate in [{lo:.6g}, {rho:.6g}]" if lo is not None
                else f"worst-case rate <= {rho:.6g}")
    if lo is not None:
        return f"not certified; worst-case rate >= {lo:.6g}"
    return "not certified"
