"""The claim ledger of a whole result document (analyze, design, objective design,
sublinear, pareto): each row's entries (:mod:`sosalgo.proofs.ledger`) and the
document's own fields (a pareto front, its floor, the tunings bound to their names)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sosalgo.certificates import spec_family
from sosalgo.kernel.phases import show_phase
from sosalgo.proofs.claims import HANDLERS, SUBLINEAR
from sosalgo.proofs.design_claims import DESIGN_HANDLERS
from sosalgo.proofs.ledger import (
    BACKED,
    CONTEXT,
    CONTRADICTED,
    UNSUPPORTED,
    RowLedger,
    entry,
    row_ledger,
)
from sosalgo.spec import Spec

__all__ = ["document_ledger"]


def _not_here(L: RowLedger, field: str) -> None:
    if L.row.get(field):
        L.add(field, CONTRADICTED, "reference rows exist only in pareto documents (the "
                                   "known tunings); this row is checked against the "
                                   "document's spec")
    else:
        L.add(field, CONTEXT, "not a reference row")


def _rows_field(L: RowLedger, field: str) -> None:
    L.add(field, CONTEXT, "the rows (each field in its own entries)")


def _handlers(spec: Spec, design: bool) -> dict[str, Any]:
    own = spec_family(spec)  # the sublinear family's rows claim a constant
    out = {**HANDLERS, **(SUBLINEAR if own is not None else {}), "reference": _not_here}
    return out | DESIGN_HANDLERS if design else out


def document_ledger(spec: Spec, doc: Mapping[str, Any], rows: Sequence[Mapping[str, Any]],
                    checks: Sequence[Mapping[str, Any] | None]) -> list[dict[str, Any]]:
    """Every entry of the document (module docstring); a document without rows gets an
    ``unsupported`` entry: there is nothing to vouch for."""
    from sosalgo.pareto import is_pareto_document

    if is_pareto_document(doc):
        return _pareto(spec, doc, checks)
    out: list[dict[str, Any]] = []
    lone = not isinstance(doc.get("rows"), list)
    if not lone:
        out += row_ledger(spec, None, {k: v for k, v in doc.items()}, None,
                          {"rows": _rows_field})
    if not rows:
        out.append(entry(None, "rows", [], UNSUPPORTED, "no rows: nothing to vouch for"))
    for i, (row, chk) in enumerate(zip(rows, checks, strict=True)):
        show_phase("claims", f"row {i + 1} of {len(rows)}")
        design = "rho_certified" in row or "lower_bound" in row
        out += row_ledger(spec, None if lone else i, row, chk, _handlers(spec, design))
    return out


# --------------------------------------------------------------------------- pareto
def _front(points: Sequence[Mapping[str, Any]]) -> Any:
    def handler(L: RowLedger, field: str) -> None:
        from sosalgo.pareto import pareto_filter

        front = L.row.get(field)
        ok = isinstance(front, list) and front == pareto_filter(points)
        L.add(field, BACKED if ok else CONTRADICTED,
              "exactly the points (each checked in its entries) that no other dominates"
              if ok else "not the non-dominated points of the document's own points")
    return handler


def _tuning_theta(known: Mapping[str, Mapping[str, float]]) -> Any:
    def handler(L: RowLedger, field: str) -> None:
        name, th = L.row.get("name"), L.row.get(field)
        ok = name in known and isinstance(th, Mapping) and dict(th) == dict(known[name])
        L.add(field, BACKED if ok else CONTRADICTED,
              f"the parameters of {name!r} in the form of eq. (9), recomputed" if ok else
              f"not the parameters of the known tuning {name!r}: a certificate vouches "
              "only for the method it was computed for")
    return handler


def _tuning_name(known: Mapping[str, Any]) -> Any:
    def handler(L: RowLedger, field: str) -> None:
        ok = L.row.get(field) in known
        L.add(field, CONTEXT if ok else CONTRADICTED,
              "a known tuning (its theta is checked against it)" if ok
              else "not a known tuning")
    return handler


def _known(kappa: Any) -> dict[str, dict[str, float]]:
    from sosalgo.model import bind
    from sosalgo.pareto import known_tunings, reference_spec

    try:
        ref = bind(reference_spec(), float(kappa))
        return {name: th for _, name, th in known_tunings(float(kappa), ref.m, ref.L)}
    except (TypeError, ValueError):
        return {}


def _pareto(spec: Spec, doc: Mapping[str, Any], checks: Sequence[Any]) -> list[dict]:
    from sosalgo.pareto import reference_spec

    fronts = doc.get("fronts", [doc])
    out: list[dict[str, Any]] = []
    if "fronts" in doc:
        out += row_ledger(spec, None, {k: v for k, v in doc.items() if k != "fronts"}, None)
    it = iter(checks)
    total = 0
    for f in fronts:
        kappa = f.get("kappa")
        points, tunings = f.get("points") or [], f.get("tunings") or []
        top = {k: v for k, v in f.items() if k not in ("points", "tunings")}
        out += row_ledger(spec, None, top, None, {"front": _front(points), **HANDLERS})
        known = _known(kappa)
        for key, pts in (("points", points), ("tunings", tunings)):
            extra = _handlers(spec, True) | (
                {"theta": _tuning_theta(known), "name": _tuning_name(known)}
                if key == "tunings" else {})
            s = reference_spec() if key == "tunings" else spec
            for p in pts:
                show_phase("claims", f"{key} row {total + 1} of {len(checks)}")
                view = {"kappa": kappa, "family": f.get("family"), **p} | {
                    k: f[k] for k in ("kappa_exact",) if k in f}
                out += row_ledger(s, total, view, next(it), extra)
                total += 1
    if total == 0:
        out.append(entry(None, "points", [], UNSUPPORTED, "no points: nothing to vouch for"))
    return out
