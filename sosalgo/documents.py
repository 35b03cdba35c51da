"""Result documents (``analyze --json``, ``design --json``, ``pareto --json``): reading
them, choosing the spec they are checked against, verifying every certificate they hold and
every claim they make (:func:`verify_document`, the Python twin of ``sosalgo verify``)."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sosalgo.errors import InputError
from sosalgo.kernel.phases import show_phase
from sosalgo.spec import Spec

__all__ = ["MAX_RESULT_BYTES", "read_result", "result_rows", "result_spec", "verify_document"]

MAX_RESULT_BYTES = 200_000_000
MAX_INTEGER = 2**1023  # larger integers have no float value


def read_result(path: str | Path) -> dict[str, Any]:
    """A result JSON document (bounded in size), or a one-line InputError naming ``path``."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_RESULT_BYTES + 1)
        if len(raw) > MAX_RESULT_BYTES:
            raise InputError(f"{path}: larger than {MAX_RESULT_BYTES} bytes")
        doc = json.loads(raw.decode("utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InputError(f"{path}: not a JSON result ({type(exc).__name__})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: not a sosalgo result document")
    return doc


def result_rows(doc: Mapping[str, Any], where: str = "result") -> list[dict[str, Any]]:
    """The rows of a document: its ``rows``, or the document itself (one design). Rows of
    a sublinear spec (``rate_type: sublinear``, m: 0) have no kappa: they come back as
    copies with ``kappa: None`` (the tables of ``sosalgo verify`` have that column)."""
    from sosalgo.pareto import is_pareto_document, pareto_rows

    if is_pareto_document(doc):  # ``sosalgo pareto --json``: every point and tuning
        return pareto_rows(doc, where)
    lone = "rho_certified" in doc or doc.get("rate_type") == "sublinear"  # one design
    rows = doc.get("rows", [doc] if lone else None)
    if isinstance(rows, list) and rows and all(
            isinstance(r, dict) and r.get("rate_type") == "sublinear" for r in rows):
        return [{"kappa": None, **r} for r in rows]
    if not isinstance(rows, list) or not all(isinstance(r, dict) and "kappa" in r for r in rows):
        raise InputError(f"{where}: rows: expected analyze or design results")
    return rows


def result_spec(doc: Mapping[str, Any], where: str = "result",
                spec: Spec | str | Path | None = None) -> tuple[Spec, str | None, str | None]:
    """(spec, its source, a note): ``spec`` when given, else the spec text embedded in the
    result (``spec_text``), else its ``source`` path. The note says when a given spec differs
    from the embedded one (a failed check may then be the edit, not the certificate).
    The document's ``set`` overrides (``--set``) are applied to the spec file; the embedded
    text already holds them, and a ``set`` it does not hold is refused (VerificationError)."""
    from sosalgo.spec import read_spec_text, spec_from_text
    from sosalgo.spec.overrides import apply_overrides

    rows = doc.get("rows")
    first = rows[0] if isinstance(rows, list) and rows and isinstance(rows[0], dict) else {}
    embedded = doc.get("spec_text") or first.get("spec_text")
    if embedded is not None and not isinstance(embedded, str):
        raise InputError(f"{where}: spec_text: expected the spec's YAML text")
    overrides = _overrides(doc, first, where)
    note = None
    if spec is not None:
        if isinstance(spec, Spec):
            chosen, src, text = spec, spec.source, None
        else:
            text = apply_overrides(read_spec_text(spec), overrides, str(spec))
            chosen, src = spec_from_text(text, source=str(spec)), str(spec)
        if embedded is not None and text is not None and text != embedded:
            note = _difference_note(src, where, embedded, text)
    elif embedded is not None:
        src = doc.get("source") or first.get("source")
        _check_overrides_held(embedded, overrides, where)
        chosen = spec_from_text(embedded, source=f"{where}: spec_text")
    else:
        src = doc.get("source") or first.get("source")
        if not src or not isinstance(src, str):
            raise InputError(f"{where}: source: unknown spec file; pass --spec")
        chosen = spec_from_text(apply_overrides(read_spec_text(src), overrides, src), src)
    if doc.get("spec") not in (None, chosen.name):
        raise InputError(f"{where}: spec: result is for '{doc.get('spec')}', "
                         f"{src} is '{chosen.name}'")
    return chosen, src if isinstance(src, str) else None, note


def _overrides(doc: Mapping[str, Any], first: Mapping[str, Any], where: str) -> dict[str, str]:
    """The document's ``set`` field (``--set NAME=EXPR`` overrides), checked."""
    from sosalgo.spec.overrides import parse_set_options

    raw = doc.get("set", first.get("set"))
    if raw is None:
        return {}
    if not isinstance(raw, dict) or not all(isinstance(v, str) for v in raw.values()):
        raise InputError(f"{where}: set: expected a mapping of parameter names to expressions")
    return parse_set_options(raw)


def _check_overrides_held(embedded: str, overrides: Mapping[str, str], where: str) -> None:
    """Refuse a ``set`` the embedded spec does not hold: the document would claim a
    computation with other parameters than the one its certificates were made for."""
    from sosalgo.errors import VerificationError
    from sosalgo.spec.overrides import same_overrides_applied

    if overrides and not same_overrides_applied(embedded, overrides, f"{where}: spec_text"):
        raise VerificationError(f"{where}: set: the overrides are not those of the embedded "
                                "spec the result was computed with (edited after the run?)")


def check_numbers(doc: Any, where: str) -> None:
    """InputError naming the first field that holds NaN, an infinity or an integer beyond
    the float range (sosalgo never writes one; every check works on floats or their exact
    values)."""
    stack: list[tuple[str, Any]] = [("", doc)]
    while stack:
        path, v = stack.pop()
        if isinstance(v, dict):
            stack += [(f"{path}.{k}" if path else str(k), x) for k, x in v.items()]
        elif isinstance(v, list):
            stack += [(f"{path}[{i}]", x) for i, x in enumerate(v)]
        elif isinstance(v, float) and not math.isfinite(v) or (
                isinstance(v, int) and not isinstance(v, bool) and abs(v) > MAX_INTEGER):
            shown = repr(v) if isinstance(v, float) else f"an integer of {len(str(v))} digits"
            raise InputError(f"{where}: {path}: {shown} is not a finite number")


def _difference_note(src: str, where: str, embedded: str, text: str) -> str:
    from sosalgo.store import describe_difference

    what = describe_difference({"spec": embedded}, {"spec": text})
    return (f"{src} differs from the spec embedded in {where} ({what}); the certificates "
            f"are checked against {src}")


def _verify_rows(spec: Spec, rows: list[dict[str, Any]], out_dir: Path | None,
                 simulate: bool, fam: Any, pareto: bool = False) -> list[dict[str, Any] | None]:
    """The rows' checks; the known tunings of a pareto document (``reference``) against
    the spec they are written in (:func:`sosalgo.pareto.reference_spec`). Only a pareto
    document has such rows: elsewhere ``reference`` is ignored (the row is checked
    against the document's spec, and the ledger refuses the field)."""
    from sosalgo.verify.results import verify_document_rows

    if not pareto or not any(r.get("reference") for r in rows):
        return verify_document_rows(spec, rows, out_dir, simulate, family=fam)
    from sosalgo.pareto import reference_spec

    out: list[dict[str, Any] | None] = [None] * len(rows)
    mine = [i for i, r in enumerate(rows) if not r.get("reference")]
    for i, chk in zip(mine, verify_document_rows(spec, [rows[i] for i in mine], out_dir,
                                                 simulate, family=fam), strict=True):
        out[i] = chk
    for i, row in enumerate(rows):  # a tuning's certificate file: the document's name, its own
        if row.get("reference"):
            show_phase("checking", f"tuning {row.get('name')}")
            stem = f"{spec.name}-tuning-{_slug(row.get('name'))}"
            out[i] = verify_document_rows(reference_spec(), [row], out_dir, simulate,
                                          family=fam, file_stem=stem)[0]
    return out


def _slug(name: Any) -> str:
    """A tuning's name as part of a file name ("robust momentum rho=0.7" ->
    "robust-momentum-rho-0.7")."""
    text = re.sub(r"[^A-Za-z0-9.]+", "-", str(name or "unnamed")).strip("-.").lower()
    return text[:60] or "unnamed"


def verify_document(result: str | Path | Mapping[str, Any], spec: Spec | str | Path | None = None,
                    out_dir: str | Path | None = None, simulate: bool = True,
                    certificate: str | None = None, options: Mapping[str, Any] | None = None,
                    name: str | None = None) -> dict[str, Any]:
    """Verify every certificate of a result document (a path or the parsed dict).

    Returns ``{"spec", "source", "results"}`` (one check per row, None for a row that claims
    no certificate), ``notes`` (e.g. that ``spec`` differs from the embedded one), and the
    claim ledger: ``ledger`` (every field of every row: backed, recomputed, contradicted,
    unsupported or context, :mod:`sosalgo.verify.ledger`), ``claims`` (the count per
    status) and ``vouched`` (True only when every claim is backed; ``sosalgo verify``
    exits 3 otherwise).
    Rational certificates go to ``out_dir`` when given (nothing is written otherwise).
    A malformed document raises InputError naming it (its path, or ``name``); failed
    checks are results, not errors (:func:`sosalgo.verify.results.check_failed`)."""
    from sosalgo.inputs import select_families
    from sosalgo.verify.results import ResultError

    where = name or (str(result) if isinstance(result, str | Path) else "result")
    doc = read_result(result) if isinstance(result, str | Path) else dict(result)
    from sosalgo.pep.claims import is_pep_document

    if doc.get("kind") == "pep-witness" or is_pep_document(doc):  # ``sosalgo pep``
        from sosalgo.pep.claims import verify_pep_document, verify_witness_file

        chosen, src, note = result_spec(doc, where, spec)
        checks = ([verify_witness_file(doc, chosen, where)] if doc.get("kind") ==
                  "pep-witness" else verify_pep_document(doc, chosen, where))
        return {"spec": chosen.name, "source": src, "results": checks,
                "notes": [] if note is None else [note]}
    from sosalgo.pareto import is_pareto_document
    from sosalgo.verify.document_ledger import document_ledger
    from sosalgo.verify.ledger import ledger_counts, vouched

    check_numbers(doc, where)
    rows = result_rows(doc, where)
    chosen, src, note = result_spec(doc, where, spec)
    fam = None
    if certificate is not None or any(v is not None for v in (options or {}).values()):
        fam = select_families(chosen, certificate, options, single=True)[0]
    try:
        checks = _verify_rows(chosen, rows, None if out_dir is None else Path(out_dir),
                              simulate, fam, is_pareto_document(doc))
    except ResultError as exc:
        raise InputError(f"{where}: {exc}") from None
    ledger = document_ledger(chosen, doc, rows, checks)
    return {"spec": chosen.name, "source": src, "results": checks,
            "notes": [] if note is None else [note], "ledger": ledger,
            "claims": ledger_counts(ledger), "vouched": vouched(ledger)}

