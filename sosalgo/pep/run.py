"""``sosalgo pep`` as a Python function: :func:`pep_run` (CSV, witness JSON, figure,
resumable sweeps over kappa and N through the batch layer)."""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

from sosalgo.errors import InputError
from sosalgo.schema import PEP_KIND
from sosalgo.spec import Spec

__all__ = ["parse_steps", "pep_chunk", "pep_row", "pep_run"]

# a PEP estimated (sosalgo.budget) longer than this runs in a worker process that a signal
# can end at once; a shorter one runs here, where a signal waits at most for its solve
ISOLATE_SECONDS = 0.5


def parse_steps(text: object) -> list[int]:
    """``N`` or ``1..N`` (any ``a..b``), 1 <= a <= b <= MAX_STEPS."""
    from sosalgo.pep.core import MAX_STEPS

    src = str(text).strip()
    hit = re.fullmatch(r"(\d+)(?:\s*\.\.\s*(\d+))?", src)
    if hit is None:
        raise InputError(f"--steps: expected N or a range a..b, got {src!r}")
    a = int(hit.group(1))
    b = int(hit.group(2)) if hit.group(2) else a
    if not 1 <= a <= b <= MAX_STEPS:
        raise InputError(f"--steps: need 1 <= N <= {MAX_STEPS} (and a <= b), got {src!r}")
    return list(range(a if hit.group(2) else a, b + 1))


def pep_row(res: Any, cls: dict[str, Any] | None = None) -> dict[str, Any]:
    """The CSV row of a result (columns :data:`sosalgo.schema.PEP_COLUMNS`); ``cls``: the
    class its proofs are about (:func:`sosalgo.pep.exact.class_description`), added to
    the document as ``class``."""
    cert = res.certificate or {}
    chk = (res.witness or {}).get("check") or {}
    return {"kappa": res.kappa if res.kappa is not None else "", "steps": res.steps,
            "tau": res.tau, "status": res.status, "gap": res.gap,
            "tau_proven": _proven_float(cert),
            "check_kind": cert.get("check_kind", ""),
            "witness_verified": chk.get("verified", ""),
            "tau_lower": chk.get("tau_lower_float"),
            "witness_dimension": (res.witness or {}).get("dimension"),
            "measure": res.measure, "initial": res.initial, "seconds": res.seconds,
            "document": json.dumps(res.to_dict() | ({"class": cls} if cls else {}),
                                   default=float)}


def _proven_float(cert: dict[str, Any]) -> float | None:
    """The float of the proven rational ``tau_proven`` (None without a proof)."""
    text = cert.get("tau_proven")
    return float(Fraction(text)) if isinstance(text, str) else None


def pep_chunk(spec_text: str, source: str, options: dict[str, Any],
              chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: the PEP at each task's (kappa, steps)."""
    from sosalgo.pep.core import pep
    from sosalgo.pep.exact import class_description
    from sosalgo.spec import spec_from_text

    spec = spec_from_text(spec_text, source)
    rows = []
    for task in chunk:
        kappa = None if task["kappa"] in ("", None) else float(task["kappa"])
        res = pep(spec, kappa, int(task["steps"]), options["measure"], options["initial"],
                  options["exact"], options["witness"])
        try:
            cls = class_description(spec, kappa)
        except (ValueError, ArithmeticError):  # the proofs say why they failed
            cls = None
        rows.append(pep_row(res, cls))
    return rows


pep_chunk.max_chunk = 1  # type: ignore[attr-defined]  # a PEP takes seconds to minutes


def _check(spec: Spec, kappas: list[float | None], steps: list[int], measure: str | None,
           initial: str | None, workers: int | None, witness: bool = True
           ) -> tuple[Any, int, bool]:
    """Every input error before anything is written (one small problem per kappa), then
    the run's estimate against the memory budget (:mod:`sosalgo.budget`): (estimate,
    workers allowed, whether each PEP runs in a worker process: one that may take longer
    than :data:`ISOLATE_SECONDS`, so that SIGTERM or Ctrl-C need not wait for its solve)."""
    from sosalgo import budget
    from sosalgo.pep.core import pep_problem

    for k in kappas:
        pep_problem(spec, k, 1, measure, initial)
    top = max(steps)
    _, st, *_ = pep_problem(spec, kappas[0], top, measure, initial)
    sizes = [(round(len(st.pairs) * ((n + 1) / (top + 1)) ** 2),
              max(1, round(st.d * (n + 1) / (top + 1)))) for n in steps] * len(kappas)
    span = f"N={steps[0]}" if len(steps) == 1 else f"N={steps[0]}..{top}"
    what = f"pep {spec.name} {span}" + (f" at {len(kappas)} kappas" if len(kappas) > 1 else "")
    est, w = budget.pep_estimate(what, f"--steps {top}", sizes, workers, witness)
    longest = budget.pep_task(*sizes[steps.index(top)], witness)[1]
    return budget.check(est), w, longest > ISOLATE_SECONDS


def pep_run(spec: Spec | str | Path, kappa: float | Sequence[float] | None = None,
            steps: int | str = 1, measure: str | None = None, initial: str | None = None,
            out_dir: str | Path | None = "outputs", workers: int | None = None,
            scheduler: str | None = None, restart: bool = False, progress: bool = True,
            plot: bool = True, exact: bool = True, witness: bool = True,
            spec_text: str | None = None, max_memory: int | str | None = None
            ) -> dict[str, Any]:
    """``sosalgo pep``: one document per (kappa, N) — ``{"spec", "kappa", "steps", "tau",
    "measure", "initial", "certificate", "witness", ...}`` — alone, or as ``rows`` for a
    range of steps or several kappas; the CSV, the witness JSON files and the figure
    (tau_k against k) go to ``out_dir`` (None: nothing written)."""
    from sosalgo import inputs
    from sosalgo.batch.executor import Progress, run_batch
    from sosalgo.batch.store import ResumableCSV
    from sosalgo.runs import spec_with_text
    from sosalgo.schema import PEP_COLUMNS, pep_csv

    spec, text = spec_with_text(spec, spec_text)
    ks: list[float | None] = ([None] if kappa is None else
                              [float(kappa)] if isinstance(kappa, int | float)
                              else [float(k) for k in kappa])
    ns = parse_steps(steps)
    from sosalgo.budget import set_max_memory

    set_max_memory(max_memory)  # None: the machine's default
    est, workers, isolate = _check(spec, ks, ns, measure, initial, workers, witness)
    inputs.check_scheduler(scheduler)
    out = None if out_dir is None else inputs.out_dir(out_dir)
    options = {"measure": measure, "initial": initial, "exact": exact, "witness": witness}
    tasks = [{"kappa": "" if k is None else k, "steps": n} for k in ks for n in ns]
    if out is None:
        got: list[dict[str, Any]] = []
        run_batch(pep_chunk, text, spec.source, options, tasks, got.append, workers,
                  scheduler, isolate=isolate)
        return _pep_document(spec, measure, initial, _docs(got), [], est)
    path = pep_csv(out, spec.name)
    settings = {"job": "pep", "spec": text, **options}
    store = ResumableCSV(path, PEP_COLUMNS, ["kappa", "steps"], settings, restart=restart,
                         companions=_companions(spec, ks, ns, out))
    with store:  # the lock is held until the last witness and figure are written
        todo = [t for t in tasks if not store.is_done(t)]
        bar = Progress(len(tasks), f"pep {spec.name}", progress,
                       done=len(tasks) - len(todo), resumed_from=path)
        try:
            run_batch(pep_chunk, text, spec.source, options, todo, store.write,
                      workers, scheduler, bar, isolate=isolate)
        finally:
            bar.close()
        keys = {store.row_key(t) for t in tasks}
        docs = _docs([r for r in store.rows() if store.row_key(r) in keys])
        files = _write_files(spec, text, docs, out, plot)
    return _pep_document(spec, measure, initial, docs, files, est)


def _docs(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The documents of the CSV rows, in (kappa, steps) order."""
    docs = [json.loads(r["document"]) for r in rows]
    return sorted(docs, key=lambda d: (d["kappa"] or 0.0, d["steps"]))


def _pep_document(spec: Spec, measure: str | None, initial: str | None,
                  docs: list[dict[str, Any]], files: list[str], est: Any) -> dict[str, Any]:
    if len(docs) == 1:
        return {"kind": PEP_KIND} | docs[0] | {"source": spec.source, "files": files,
                                          "estimate": est.to_dict()}
    return {"kind": PEP_KIND, "spec": spec.name, "source": spec.source, "measure": measure,
            "initial": initial, "rows": docs, "files": files, "estimate": est.to_dict()}


def _tag(kappa: float | None) -> str:
    return "" if kappa is None else f"-k{kappa:g}"


def _witness_path(spec: Spec, out: Path, kappa: float | None, steps: int) -> Path:
    return out / f"{spec.name}-pep{_tag(kappa)}-N{steps}-witness.json"


def _companions(spec: Spec, ks: list[float | None], ns: list[int], out: Path) -> list[Path]:
    """The files a run writes beside its CSV (witnesses, figures): kept aside with it when
    a run with other settings replaces it."""
    files = []
    for k in ks:
        files += [_witness_path(spec, out, k, n) for n in ns]
        for stem in (f"{spec.name}-pep{_tag(k)}", f"{spec.name}-pep{_tag(k)}-N{ns[-1]}-witness"):
            files += [out / f"{stem}.{ext}" for ext in ("png", "pdf")]
    return files


def _write_files(spec: Spec, text: str, docs: list[dict[str, Any]], out: Path,
                 plot: bool) -> list[str]:
    """Witness JSON files (with the spec's text as the run read it, so ``sosalgo verify``
    needs nothing else), each written atomically, and the figure of tau_k against k for
    each kappa with two steps or more."""
    from sosalgo.batch.store import write_atomic

    files = []
    for d in docs:
        if d.get("witness"):
            path = _witness_path(spec, out, d["kappa"], d["steps"])
            write_atomic(path, json.dumps(d["witness"] | {"spec_text": text}, indent=1))
            files.append(str(path))
    if plot:
        from sosalgo.pep.figure import pep_figure

        files += pep_figure(spec, docs, out)
    return files


def pep_summary(doc: dict[str, Any]) -> str:
    """The printed table of ``sosalgo pep``."""
    from sosalgo.report import format_table

    rows = doc.get("rows", [doc])
    table = []
    for d in rows:
        cert = d.get("certificate") or {}
        chk = (d.get("witness") or {}).get("check") or {}
        table.append({"kappa": d["kappa"], "N": d["steps"], "tau": d["tau"],
                      "tau_proven": cert.get("tau_proven") and float(
                          Fraction(cert["tau_proven"])),
                      "check": cert.get("check_kind", d.get("status")),
                      "witness_lower": chk.get("tau_lower_float"),
                      "witness_dim": (d.get("witness") or {}).get("dimension"),
                      "seconds": d.get("seconds")})
    cols = ["kappa", "N", "tau", "tau_proven", "check", "witness_lower", "witness_dim",
            "seconds"]
    head = f"{rows[0]['spec']}: worst case of {rows[0]['measure']} / {rows[0]['initial']}"
    cls = rows[0].get("class")
    if cls:  # the class the proofs are about, exactly
        many = len({d["kappa"] for d in rows}) > 1
        head += f" over the class m = {cls['m']}, L = " + ("kappa m" if many else cls["L"])
    files = doc.get("files") or []
    return "\n".join([head, format_table(table, cols)] + [f"wrote {f}" for f in files])
