"""The claims of a design document that no single certificate backs: the lower bound
(re-proven from ``bound_certificate``, :mod:`sosalgo.design_search.boundcheck`), the
relaxation's status, gaps, θ inside Θ, the rate at the spec's values
(``values_certificate``) and ``bound_status``."""

from __future__ import annotations

import math
from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from sosalgo.kernel.phases import show_phase
from sosalgo.proofs.ledger import (
    BACKED,
    CONTEXT,
    CONTRADICTED,
    UNSUPPORTED,
    RowLedger,
    frac,
)

__all__ = ["DESIGN_HANDLERS", "ROUNDING"]

ROUNDING = Fraction(1, 2**52)  # the relative rounding of a reported float target


def _bound(L: RowLedger) -> Any:
    """The re-proof of the row's bound certificate (cached on the ledger), or a reason."""
    if "bound" not in L.cache:
        L.cache["bound"] = _reprove(L)
    return L.cache["bound"]


def _reprove(L: RowLedger) -> Any:
    from sosalgo.certificates import get_family
    from sosalgo.design_search import bound_model
    from sosalgo.design_search.boundcheck import check_bound_certificate
    from sosalgo.design_search.witness import (
        WITNESS_CERTIFICATE_KIND,
        check_witness_certificate,
    )
    from sosalgo.proofs.results import row_kappa

    row = L.row
    cert = row.get("bound_certificate")
    if (row.get("relaxation") or {}).get("method") == "moment" or row.get("method") == "moment":
        return "the moment relaxation's bound comes from a floating-point SDP: not re-provable"
    if not isinstance(cert, Mapping):
        return "no bound_certificate in the document (e.g. a design read back from its CSV)"
    show_phase("re-proving the bound certificate", f"kappa {row.get('kappa')}")
    if cert.get("kind") == WITNESS_CERTIFICATE_KIND:
        try:
            return check_witness_certificate(L.spec, row_kappa(row, "row"), list(row["free"]),
                                             cert)
        except (KeyError, TypeError, ValueError) as exc:
            return f"the bound certificate cannot be re-proven: {exc}"
    try:
        fam = get_family(str(row.get("family") or L.spec.certificate),
                         {"lag": row.get("lag")} if row.get("lag") is not None else None)
        model = bound_model(L.spec, row_kappa(row, "row"), list(row["free"]), fam)
        if model is None:
            return f"the {fam.name} family has no box-wide dual bound"
        return check_bound_certificate(model, cert)
    except (KeyError, TypeError, ValueError) as exc:
        return f"the bound certificate cannot be re-proven: {exc}"


def lower_bound(L: RowLedger, field: str) -> None:
    v = L.row.get(field)
    c = frac(v)
    if v is None:
        L.add(field, CONTEXT, "claims no lower bound")
    elif c is None:
        L.add(field, CONTRADICTED, "not a number")
    elif c <= 0:
        L.add(field, BACKED, "a rate is never below 0", 0.0)
    else:
        b = _bound(L)
        if isinstance(b, str):
            L.add(field, UNSUPPORTED, b)
        elif c * c <= Fraction(b.r):
            L.add(field, BACKED, f"re-proven: {b.reason}", b.rho)
        else:
            L.add(field, CONTRADICTED, f"above what the certificate proves ({b.reason})",
                  b.rho)


def relaxation(L: RowLedger, field: str) -> None:
    rel = L.row.get(field)
    if not isinstance(rel, Mapping):
        L.add(field, CONTRADICTED if rel is not None else CONTEXT, "not an object")
        return
    status = rel.get("status")
    if status != "proved":
        L.add(field, CONTEXT, f"status {status!r}: claims no complete proof")
        return
    b = _bound(L)
    # the target proven (a design read back from its CSV has none: then its lower bound)
    t = frac(rel.get("target", L.row.get("lower_bound")))
    if isinstance(b, str):
        L.add(field, UNSUPPORTED, f"status proved: {b}")
    elif t is None:
        L.add(field, CONTRADICTED, "status proved without a target or a lower bound")
    elif t * t <= Fraction(b.r) * (1 + ROUNDING):
        L.add(field, BACKED, f"status proved: the boxes cover Θ up to the target "
                             f"({b.reason})", b.rho)
    else:
        L.add(field, CONTRADICTED, f"status proved, but {b.reason}: below the target", b.rho)


def gap(of: str) -> Any:
    def handler(L: RowLedger, field: str) -> None:
        v, a, b = L.row.get(field), L.row.get("rho_certified"), L.row.get(of)
        if v is None:
            L.add(field, CONTEXT, "none")
        elif isinstance(a, float) and isinstance(b, float) and v == a - b:
            L.add(field, BACKED, f"rho_certified - {of} (each checked in its own entry)")
        else:
            L.add(field, CONTRADICTED, f"not rho_certified - {of}")
    return handler


def theta(L: RowLedger, field: str) -> None:
    """Designed parameters: each inside its range Θ at this kappa (exactly)."""
    from sosalgo.model import parameter_box

    th = L.row.get(field)
    if not th:
        L.add(field, CONTEXT, "none")
        return
    try:
        names = list(th)
        kappa = L.row.get("kappa")
        box = parameter_box(L.spec, float("nan") if kappa is None else float(kappa), names)
        inside = all(frac(lo) <= frac(th[p]) <= frac(hi)
                     for p, (lo, hi) in zip(names, box, strict=True))
    except Exception as exc:  # noqa: BLE001 - a θ that cannot be placed in Θ
        L.add(field, CONTRADICTED, f"not parameters of the spec ({type(exc).__name__})")
        return
    L.add(field, BACKED if inside else CONTRADICTED,
          "inside Θ (the certificates are proven at it)" if inside else "outside Θ")


def rho_at_values(L: RowLedger, field: str) -> None:
    from sosalgo.proofs.results import verify_document_rows

    v = L.row.get(field)
    cert = L.row.get("values_certificate")
    if v is None:
        L.add(field, CONTEXT, "claims no rate at the spec's values")
        return
    if not isinstance(cert, Mapping):
        L.add(field, UNSUPPORTED, "no values_certificate in the document")
        return
    fam = {k: L.row[k] for k in ("family", "lag") if L.row.get(k) is not None}
    row = {"kappa": L.row.get("kappa"), "rho": v, "certified": True, **fam,
           **({"P": cert.get("P"), "lambda": cert.get("lambda")} if fam.get(
               "family", "theorem1") == "theorem1" else {"certificate": dict(cert)})}
    try:
        chk = verify_document_rows(L.spec, [row], None, simulate=False)[0]
    except ValueError as exc:
        L.add(field, CONTRADICTED, f"malformed values_certificate: {exc}")
        return
    ok = chk is not None and chk.get("verified") == "exact"
    L.add(field, BACKED if ok else CONTRADICTED,
          "proven exactly at the spec's values" if ok else
          f"the exact check failed: {None if chk is None else chk.get('reason')}",
          None if chk is None else chk.get("rho_proven"))


def bound_status(L: RowLedger, field: str) -> None:
    v = L.row.get(field)
    if v in (None, "unsupported", "none"):
        L.add(field, CONTEXT, "claims no bound")
    elif L.row.get("lower_bound") is None:
        L.add(field, CONTRADICTED, f"{v!r} without a lower bound")
    else:
        b = _bound(L)
        ok = not isinstance(b, str) and v == "proved" and math.isfinite(b.r)
        L.add(field, BACKED if ok else UNSUPPORTED,
              "backed by the re-proven bound" if ok else "not backed by a re-proof")


DESIGN_HANDLERS: dict[str, Any] = {
    "lower_bound": lower_bound, "relaxation": relaxation, "gap": gap("lower_bound"),
    "gap_to_floor": gap("floor"), "theta": theta, "rho_at_values": rho_at_values,
    "bound_status": bound_status,
}
