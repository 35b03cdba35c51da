"""Result documents: their kinds, reading them, choosing the spec they are checked
against, verifying every certificate they hold and every claim they make
(:func:`verify_document`, the Python twin of ``sosalgo verify``).

Every JSON document sosalgo writes names its kind in a top-level ``kind`` field (the
names: ``sosalgo.schema``, ``*_KIND``); the kinds are registered once, in :data:`KINDS`
(what each holds, the command and files that write it, its fields and CSV columns, how
its rows are persisted, and how it is verified).
``sosalgo verify`` dispatches on ``kind`` (:func:`document_kind`); a document written
before documents named their kind is recognised by its fields instead, as it was then.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sosalgo.errors import InputError, VerificationError
from sosalgo.kernel.phases import show_phase
from sosalgo.kinds import (
    ALLK_KIND,
    ANALYSIS_KIND,
    CERTIFICATE_KIND,
    DESIGN_CERTIFICATES_KIND,
    DESIGN_KIND,
    DESIGN_STEPS_KIND,
    FIG4_KIND,
    GRID_KIND,
    PARETO_KIND,
    PEP_KIND,
    TABLE1_KIND,
    VERIFICATION_KIND,
    WITNESS_KIND,
)
from sosalgo.spec import Spec

__all__ = ["KINDS", "MAX_RESULT_BYTES", "ResultKind", "claim_ledger", "document_kind",
           "read_result", "result_rows", "result_spec", "sniff_kind", "verify_document",
           "vouch_run"]

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
    from sosalgo.proofs.results import verify_document_rows

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

    Returns ``{"kind": "verification", "spec", "source", "results"}`` (one check per row,
    None for a row that claims no certificate), ``notes`` (e.g. that ``spec`` differs from
    the embedded one), and for analyze, design and pareto documents the claim ledger:
    ``ledger`` (every field of every row: backed, recomputed, contradicted, unsupported or
    context, :mod:`sosalgo.proofs.ledger`), ``claims`` (the count per status) and
    ``vouched`` (True only when every claim is backed; ``sosalgo verify`` exits 3
    otherwise). The document's ``kind`` chooses the check (:func:`document_kind`: a kind
    its content contradicts raises VerificationError, exit code 3).
    Rational certificates go to ``out_dir`` when given (nothing is written otherwise).
    A malformed document raises InputError naming it (its path, or ``name``); failed
    checks are results, not errors (:func:`sosalgo.proofs.results.check_failed`)."""
    where = name or (str(result) if isinstance(result, str | Path) else "result")
    doc = read_result(result) if isinstance(result, str | Path) else dict(result)
    kind = document_kind(doc, where)
    if kind.verify is None:
        raise InputError(f"{where}: kind: a {kind.name} document ({kind.summary}) claims "
                         f"nothing sosalgo verify checks; it checks {_verifiable_names()} "
                         "documents")
    return {"kind": VERIFICATION_KIND} | kind.verify(doc, where, spec, out_dir, simulate,
                                                certificate, options)


def _verify_pep(doc: dict[str, Any], where: str, spec: Spec | str | Path | None,
                *_: Any) -> dict[str, Any]:
    """The claims of a ``pep --json`` document (:mod:`sosalgo.worstcase.claims`)."""
    from sosalgo.worstcase.claims import verify_pep_document

    chosen, src, note = result_spec(doc, where, spec)
    return {"spec": chosen.name, "source": src,
            "results": verify_pep_document(doc, chosen, where),
            "notes": [] if note is None else [note]}


def _verify_steps(doc: dict[str, Any], where: str, spec: Spec | str | Path | None,
                  *_: Any) -> dict[str, Any]:
    """The claims of a ``design --steps`` document (:mod:`sosalgo.proofs.steps_design`)."""
    from sosalgo.proofs.steps_design import verify_steps_document

    chosen, src, note = result_spec(doc, where, spec)
    return {"spec": chosen.name, "source": src,
            "results": verify_steps_document(doc, chosen, where),
            "notes": [] if note is None else [note]}


def _verify_allk(doc: dict[str, Any], where: str, spec: Spec | str | Path | None,
                 *_: Any) -> dict[str, Any]:
    """The bound of an ``all-k`` document, re-proven from its certificate
    (:func:`sosalgo.certificates.exact_allk.verify_allk_document`)."""
    from sosalgo.certificates.exact_allk import verify_allk_document

    chosen, src, note = result_spec(doc, where, spec)
    return {"spec": chosen.name, "source": src,
            "results": verify_allk_document(doc, chosen, where),
            "notes": [] if note is None else [note]}


def _verify_witness(doc: dict[str, Any], where: str, spec: Spec | str | Path | None,
                    *_: Any) -> dict[str, Any]:
    """The claims of a pep witness file (:func:`sosalgo.worstcase.claims.verify_witness_file`)."""
    from sosalgo.worstcase.claims import verify_witness_file

    chosen, src, note = result_spec(doc, where, spec)
    return {"spec": chosen.name, "source": src,
            "results": [verify_witness_file(doc, chosen, where)],
            "notes": [] if note is None else [note]}


def _verify_ledger(doc: dict[str, Any], where: str, spec: Spec | str | Path | None,
                   out_dir: str | Path | None, simulate: bool, certificate: str | None,
                   options: Mapping[str, Any] | None) -> dict[str, Any]:
    """Every certificate and every claim of an analyze, design or pareto document: the
    rows' checks and the claim ledger."""
    from sosalgo.inputs import select_families
    from sosalgo.pareto import is_pareto_document
    from sosalgo.proofs.results import ResultError

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
    return {"spec": chosen.name, "source": src, "results": checks,
            "notes": [] if note is None else [note]} | claim_ledger(chosen, doc, rows, checks)


def claim_ledger(spec: Spec, doc: Mapping[str, Any], rows: list[dict[str, Any]],
                 checks: list[dict[str, Any] | None]) -> dict[str, Any]:
    """The claim ledger of a document whose rows have their ``checks``
    (:mod:`sosalgo.proofs.document_ledger`): ``ledger`` (every entry), ``claims`` (the
    count per status) and ``vouched`` (True only when every claim is backed)."""
    from sosalgo.proofs.document_ledger import document_ledger
    from sosalgo.proofs.ledger import ledger_counts, vouched

    ledger = document_ledger(spec, doc, rows, checks)
    return {"ledger": ledger, "claims": ledger_counts(ledger), "vouched": vouched(ledger)}


def vouch_run(spec: Spec, doc: Mapping[str, Any]) -> dict[str, Any]:
    """The fields a run with ``--verify`` adds to the document it writes, after its rows
    got their checks (``verification``): the claim ledger that ``sosalgo verify`` runs
    on that document (:func:`claim_ledger`), as ``claims`` (the count per status),
    ``vouched`` and ``unbacked`` (the entries contradicted or unsupported)."""
    from sosalgo.proofs.ledger import BAD

    rows = result_rows(doc, doc.get("spec") or "result")
    res = claim_ledger(spec, doc, rows, [r.get("verification") for r in rows])
    return {"claims": res["claims"], "vouched": res["vouched"],
            "unbacked": [e for e in res["ledger"] if e["status"] in BAD]}


# ---------------------------------------------------------------------------- result kinds
@dataclass(frozen=True)
class ResultKind:
    """One kind of result document: what it holds (``summary``), the command that writes
    it, its files, its top-level ``fields`` and the CSV ``columns`` of its rows (a
    function of :mod:`sosalgo.schema`), how a row goes to its file and back
    (``persisted``), the test of its content (``looks_like``: how a document without a
    ``kind`` is recognised, and how a ``kind`` is checked against the content) and its
    check (``verify``: None when ``sosalgo verify`` checks no claim of it; ``checks``
    says how the command reports it: ``ledger`` or ``claims``)."""

    name: str
    summary: str
    command: str
    files: str
    fields: tuple[str, ...]
    columns: str
    persisted: str
    looks_like: Callable[[Mapping[str, Any]], bool]
    verify: Callable[..., dict[str, Any]] | None = None
    checks: str | None = None


def _design_row(r: Any) -> bool:
    return isinstance(r, Mapping) and ("rho_certified" in r or "lower_bound" in r)


def _analysis_row(r: Any) -> bool:
    return isinstance(r, Mapping) and not _design_row(r) and (
        {"kappa", "rho"} <= set(r) or (r.get("rate_type") == "sublinear" and "constant" in r))


def _rows_all(doc: Mapping[str, Any], test: Callable[[Any], bool]) -> bool:
    rows = doc.get("rows")
    return isinstance(rows, list) and bool(rows) and all(test(r) for r in rows)


def _looks_design(doc: Mapping[str, Any]) -> bool:
    """One design (the document is its row), or rows that are all designs."""
    if "rows" not in doc:
        return _design_row(doc) and "columns" not in doc
    return _rows_all(doc, _design_row) and "columns" not in doc


def _steps_row(r: Any) -> bool:
    return isinstance(r, Mapping) and "tau_certified" in r and "schedule" in r


def _looks_steps(doc: Mapping[str, Any]) -> bool:
    """One ``design --steps`` row (the document is its row), or rows that all are."""
    return _steps_row(doc) if "rows" not in doc else _rows_all(doc, _steps_row)


def _looks_pep(doc: Mapping[str, Any]) -> bool:
    from sosalgo.worstcase.claims import is_pep_document

    return is_pep_document(doc)


def _has(*names: str) -> Callable[[Mapping[str, Any]], bool]:
    return lambda doc: set(names) <= set(doc)


def _verifiable_names() -> str:
    return ", ".join(k.name for k in KINDS.values() if k.verify is not None)


KINDS: dict[str, ResultKind] = {k.name: k for k in [
    ResultKind(
        ANALYSIS_KIND, "the certified rate at each kappa, or the sublinear constant of an m: 0 "
        "spec", "sosalgo analyze --json (sosalgo.analyze_run)",
        "<name>-analysis[-<family>...].csv, one row per kappa",
        ("kind", "spec", "source", "spec_text", "tol", "csv", "csvs", "figures", "rows",
         "estimate", "claims", "vouched", "unbacked"),
        "sosalgo.schema.analysis_columns (sublinear_columns for an m: 0 spec)",
        "typed result -> CSV cells (sosalgo.batch.sweeps) -> JSON row (csv_row_to_json)",
        lambda doc: _rows_all(doc, _analysis_row), _verify_ledger, "ledger"),
    ResultKind(
        DESIGN_KIND, "designed parameters with their certified rate and proven lower bound, "
        "one design per kappa (the document itself for one kappa)",
        "sosalgo design --json (sosalgo.design_run)",
        "<name>-design[-<family>...][-min-noise|-min-rate].csv, one row per kappa",
        ("kind", "spec", "kappa", "free", "theta", "rho_certified", "lower_bound", "gap",
         "certificate", "source", "spec_text", "rows", "estimate", "claims", "vouched",
         "unbacked"),
        "sosalgo.schema.design_columns",
        "typed result -> CSV cells (sosalgo.batch.sweeps) -> JSON (design_csv_to_json); the "
        "certificates too large for a cell in a design-certificates file",
        _looks_design, _verify_ledger, "ledger"),
    ResultKind(
        DESIGN_STEPS_KIND, "a schedule minimizing the worst case after N steps, its worst "
        "case proven, a lower bound proven over the whole box, one per (kappa, N)",
        "sosalgo design --steps N --json (sosalgo.steps_design_run)",
        "<name>-design-steps.csv, one row per (kappa, N)",
        ("kind", "spec", "kappa", "steps", "free", "schedule", "tau_certified",
         "lower_bound", "gap", "floor", "bound", "source", "spec_text", "rows"),
        "sosalgo.schema.STEPS_DESIGN_COLUMNS",
        "the document in the CSV's document column", _looks_steps, _verify_steps, "claims"),
    ResultKind(
        PARETO_KIND, "the front of (certified rate, certified noise sensitivity) at each kappa",
        "sosalgo pareto --json (sosalgo.pareto_run)", "<name>-pareto-k<kappa>.csv",
        ("kind", "spec", "kappa", "front", "points", "tunings", "family", "floor", "fronts",
         "source", "spec_text", "csv", "figures", "estimate"),
        "sosalgo.schema.PARETO_COLUMNS", "point -> CSV cells -> JSON point (sosalgo.pareto)",
        lambda doc: "fronts" in doc or {"front", "points"} <= set(doc),
        _verify_ledger, "ledger"),
    ResultKind(
        PEP_KIND, "the worst case after N steps, its proven dual bound and checked witness",
        "sosalgo pep --json (sosalgo.pep_run)",
        "<name>-pep.csv, one row per (kappa, N); <name>-pep[-k<kappa>]-N<steps>.json, its "
        "document",
        ("kind", "spec", "kappa", "steps", "tau", "measure", "initial", "certificate",
         "witness", "source", "files", "rows", "estimate"),
        "sosalgo.schema.PEP_COLUMNS", "result -> plain CSV cells (sosalgo.store) and the "
        "document in its own file, named in the row's document cell (sosalgo.runs.pep)",
        _looks_pep, _verify_pep, "claims"),
    ResultKind(
        WITNESS_KIND, "a worst-case function set and trajectory for N steps",
        "sosalgo pep (beside its CSV)", "<name>-pep[-k<kappa>]-N<steps>-witness.json",
        ("kind", "spec", "kappa", "steps", "iterates", "tau_float", "check", "class",
         "upper", "spec_text"), "", "written whole (sosalgo.worstcase.witness.make_witness)",
        _has("calls_per_step", "iterates", "tau_float"), _verify_witness, "claims"),
    ResultKind(
        ALLK_KIND, "a bound for every N of a spec whose matrices are closed forms in k, "
        "its potential and its exact proof",
        "sosalgo analyze --json of such a spec (sosalgo.runs.allk.allk_run)",
        "<name>-allk.json",
        ("kind", "spec", "source", "spec_text", "rate_type", "degree", "bound", "constant",
         "constant_proven", "a", "offset", "weights", "certificate", "verified"), "",
        "written whole (sosalgo.runs.allk)", lambda doc: doc.get("rate_type") == "all-k",
        _verify_allk, "claims"),
    ResultKind(
        GRID_KIND, "the certified rate (or constant) on a grid of the free parameters",
        "sosalgo grid --json (sosalgo.grid_run)", "<name>-grid-k<kappa>[-<family>...].csv",
        ("kind", "spec", "free", "fixed", "grids", "rate_type", "best", "csv", "estimate"),
        "sosalgo.schema.grid_columns", "typed result -> CSV cells -> JSON (report.grid)",
        _has("grids")),
    ResultKind(
        TABLE1_KIND, "each spec's certified rate beside its closed form",
        "sosalgo.table1_run (sosalgo table1 prints its table)", "table1.csv",
        ("kind", "rows", "columns", "csv"), "sosalgo.schema.TABLE1_COLUMNS",
        "row -> CSV cells (written whole)", _has("rows", "columns", "csv")),
    ResultKind(
        FIG4_KIND, "Figure 4: the designed three-parameter family against kappa",
        "sosalgo fig4 --json", "fig4-tight-design.png/.pdf and its sweeps' CSV files",
        ("kind", "figures", "kappa"), "", "the sweeps' CSV files (analysis, design)",
        _has("designed (interpolation)", "designed (Theorem 1)")),
    ResultKind(
        CERTIFICATE_KIND, "a rational certificate and its exact check, re-checkable without "
                     "sosalgo", "sosalgo verify (and --verify)",
        "DIR/certificates/<name>-k<kappa>[-<family>][-<digest>]-certificate.json",
        ("kind", "spec", "verified", "rho_proven", "inputs_hash"), "",
        "written whole (sosalgo.proofs.exact.write_certificate)",
        _has("inputs_hash", "verified")),
    ResultKind(
        DESIGN_CERTIFICATES_KIND, "the certificates of a design row too large for a CSV cell",
        "sosalgo design (beside its CSV)", "<design csv stem>-k<kappa>-certificates.json",
        ("kind", "for", "bound_certificate", "values_certificate"), "",
        "written whole; attached again to a row read back from the CSV", _has("for")),
    ResultKind(
        VERIFICATION_KIND, "the checks and claim ledger of a result document",
        "sosalgo verify --json (sosalgo.verify_document)", "stdout only",
        ("kind", "spec", "source", "results", "notes", "ledger", "claims", "vouched"), "",
        "not persisted", _has("results", "notes")),
]}

# the order content is recognised in (the most specific first)
_SNIFF_ORDER = (ALLK_KIND, WITNESS_KIND, PEP_KIND, PARETO_KIND, GRID_KIND, TABLE1_KIND, FIG4_KIND,
                CERTIFICATE_KIND, DESIGN_CERTIFICATES_KIND, VERIFICATION_KIND,
                DESIGN_STEPS_KIND, DESIGN_KIND, ANALYSIS_KIND)


def sniff_kind(doc: Mapping[str, Any]) -> str | None:
    """The kind a document's content shows, whatever its ``kind`` field says (None when
    it shows none)."""
    return next((n for n in _SNIFF_ORDER if KINDS[n].looks_like(doc)), None)


def document_kind(doc: Mapping[str, Any], where: str = "result") -> ResultKind:
    """The kind of a document: its ``kind`` field, checked against its content (a kind
    the content contradicts raises VerificationError naming the field; an unknown kind an
    InputError). A document without ``kind`` (written before documents named it) is
    recognised by its content among the kinds verify checks, as it was then (else it is
    taken for an analysis, whose checks name what is missing)."""
    declared = doc.get("kind")
    shown = sniff_kind(doc)
    if declared is None:
        return KINDS[shown if shown is not None and KINDS[shown].verify else ANALYSIS_KIND]
    if not isinstance(declared, str) or declared not in KINDS:
        raise InputError(f"{where}: kind: {declared!r} is not a sosalgo result kind "
                         f"(known: {', '.join(KINDS)})")
    if shown is not None and shown != declared:
        raise VerificationError(f"{where}: kind: the document says {declared!r}, but it "
                                f"holds {KINDS[shown].summary} ({shown!r}): refused")
    return KINDS[declared]
