"""``sosalgo pep`` as a Python function: :func:`pep_run` (CSV, witness JSON, figure,
resumable sweeps over kappa and N through the batch layer). The PEP itself is
:func:`sosalgo.worstcase.pep`; the figure is :func:`sosalgo.report.pep.pep_figure`."""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Mapping, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

from sosalgo.kernel.phases import begin_task
from sosalgo.kinds import PEP_KIND
from sosalgo.spec import Spec

__all__ = ["FILE_FIELDS", "document_file", "pep_chunk", "pep_heading", "pep_row", "pep_run",
           "term_words"]

# a PEP estimated (sosalgo.kernel.budget) longer than this runs in a worker process that a signal
# can end at once; a shorter one runs here, where a signal waits at most for its solve
ISOLATE_SECONDS = 0.5


def pep_row(res: Any, cls: dict[str, Any] | None = None) -> dict[str, Any]:
    """The row of a result (columns :data:`sosalgo.schema.PEP_COLUMNS`) as a worker hands
    it over, ``document`` the whole document's JSON text; the run stores that text in its
    own file and the cell names the file (:func:`document_file`). ``cls``: the class its
    proofs are about (:func:`sosalgo.worstcase.exact.class_description`), added to the document
    as ``class``."""
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


def task_kappa(task: dict[str, Any]) -> float | None:
    """The kappa of a (kappa, steps) task (None: an m: 0 spec), announced as the task the
    progress bar shows."""
    from sosalgo.runs import kappa_value

    kappa = None if task["kappa"] in ("", None) else kappa_value(task["kappa"])
    begin_task(f"N {task['steps']}" + ("" if kappa is None else f", kappa {kappa:g}"))
    return kappa


def pep_chunk(spec_text: str, source: str, options: dict[str, Any],
              chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: the PEP at each task's (kappa, steps)."""
    from sosalgo.spec import spec_from_text
    from sosalgo.worstcase.core import pep
    from sosalgo.worstcase.exact import class_description

    spec = spec_from_text(spec_text, source)
    rows = []
    for task in chunk:
        kappa = task_kappa(task)
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
    the run's estimate against the memory budget (:mod:`sosalgo.kernel.budget`): (estimate,
    workers allowed, whether each PEP runs in a worker process: one that may take longer
    than :data:`ISOLATE_SECONDS`, so that SIGTERM or Ctrl-C need not wait for its solve)."""
    from sosalgo.kernel import budget
    from sosalgo.worstcase.core import run_sizes

    sizes, per_step = run_sizes(spec, kappas, steps, measure, initial)
    if not per_step:  # a tree of outcomes: no per-step estimate, no witness
        est, w = budget.pep_estimate(f"pep {spec.name}", f"--steps {max(steps)}", sizes,
                                     workers, False)
        return budget.check(est), w, False
    top = max(steps)
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
            spec_text: str | None = None, max_memory: int | str | None = None,
            overrides: Mapping[str, str] | None = None) -> dict[str, Any]:
    """``sosalgo pep``: one document per (kappa, N) — ``{"spec", "kappa", "steps", "tau",
    "measure", "initial", "certificate", "witness", ...}`` — alone, or as ``rows`` for a
    range of steps or several kappas; the CSV, the witness JSON files and the figure
    (tau_k against k) go to ``out_dir`` (None: nothing written). ``overrides``
    (``--set``) fix parameters; the document and the witness files record them in
    ``set``."""
    from sosalgo import inputs
    from sosalgo.batch.executor import Progress, check_scheduler, run_batch
    from sosalgo.batch.sweeps import kappa_settings
    from sosalgo.runs import kappa_value, set_field, spec_with_text
    from sosalgo.schema import PEP_COLUMNS, pep_csv
    from sosalgo.store import ResumableCSV
    from sosalgo.worstcase.core import parse_steps

    spec, text = spec_with_text(spec, spec_text, overrides, varying=True)
    recorded = set_field(overrides)
    ks: list[float | None] = ([None] if kappa is None else
                              [kappa_value(kappa)] if isinstance(kappa, int | float | str)
                              else [kappa_value(k) for k in kappa])
    ns = parse_steps(steps)
    from sosalgo.kernel.budget import set_max_memory

    set_max_memory(max_memory)  # None: the machine's default
    est, workers, isolate = _check(spec, ks, ns, measure, initial, workers, witness)
    check_scheduler(scheduler)
    out = None if out_dir is None else inputs.out_dir(out_dir)
    options = {"measure": measure, "initial": initial, "exact": exact, "witness": witness}
    tasks = [{"kappa": "" if k is None else k, "steps": n} for k in ks for n in ns]
    if out is None:
        got: list[dict[str, Any]] = []
        run_batch(pep_chunk, text, spec.source, options, tasks, got.append, workers,
                  scheduler, isolate=isolate)
        return _pep_document(spec, measure, initial, _docs(got), [], est) | recorded
    path = pep_csv(out, spec.name)
    settings = {"job": "pep", "spec": text, **options} | kappa_settings(
        [k for k in ks if k is not None])  # 10/3 is not resumed from 3.3333333333333335
    store = ResumableCSV(path, PEP_COLUMNS, ["kappa", "steps"], settings, restart=restart,
                         companions=_companions(spec, ks, ns, out))
    with store:  # the lock is held until the last witness and figure are written
        todo = [t for t in tasks if not store.is_done(t)]
        bar = Progress(len(tasks), f"pep {spec.name}", progress,
                       done=len(tasks) - len(todo), resumed_from=path)

        def persist(row: dict[str, Any]) -> None:  # the document's file, then its row
            store.write(_persist_document(spec, text, row, out, recorded))

        try:
            run_batch(pep_chunk, text, spec.source, options, todo, persist,
                      workers, scheduler, bar, isolate=isolate)
        finally:
            bar.close()
        keys = {store.row_key(t) for t in tasks}
        docs = _docs([r for r in store.rows() if store.row_key(r) in keys], out, spec)
        files = _write_files(spec, text, docs, out, plot, recorded)
    return _pep_document(spec, measure, initial, docs, files, est) | recorded


def _docs(rows: list[dict[str, Any]], out: Path | None = None,
          spec: Spec | None = None) -> list[dict[str, Any]]:
    """The documents of the rows (a worker's, or the CSV's read back with their files in
    ``out``), in (kappa, steps) order."""
    docs = [_row_document(r, out, spec) for r in rows]
    return sorted(docs, key=lambda d: (d["kappa"] or 0.0, d["steps"]))


# what a document file adds to the document of its row (and reading it back drops)
FILE_FIELDS = ("kind", "source", "spec_text", "set")


def document_file(spec: Spec, kappa: float | None, steps: int) -> str:
    """``<name>-pep[-k<kappa>]-N<steps>.json``: one (kappa, N) document (kappa exact:
    :func:`sosalgo.schema.kappa_label`), beside the CSV; the CSV's ``document`` cell
    names it."""
    from sosalgo.schema import kappa_label

    tag = "" if kappa is None else f"-k{kappa_label(kappa)}"
    return f"{spec.name}-pep{tag}-N{steps}.json"


def _persist_document(spec: Spec, text: str, row: dict[str, Any], out: Path,
                      recorded: Mapping[str, Any]) -> dict[str, Any]:
    """Write the row's document (a ``pep`` document of its own, with the spec's text, so
    ``sosalgo verify`` needs nothing else) atomically to its file and return the row with
    the file's name in its ``document`` cell. Called under the CSV's lock, before the row
    is written: a row on disk always has its file."""
    from sosalgo.store import write_atomic

    doc = json.loads(row["document"])
    name = document_file(spec, doc["kappa"], doc["steps"])
    whole = {"kind": PEP_KIND} | doc | {"source": spec.source, "spec_text": text} | dict(
        recorded)
    write_atomic(out / name, json.dumps(whole, indent=1, default=float))
    return row | {"document": name}


def _row_document(row: Mapping[str, Any], out: Path | None,
                  spec: Spec | None) -> dict[str, Any]:
    """A row's document: the JSON text a worker handed over (or that a CSV written before
    documents had their own files holds), else the file the cell names, without what the
    file adds (:data:`FILE_FIELDS`). A file that is gone leaves the row's plain columns,
    with a note (no certificate, no witness: ``--restart`` computes them again)."""
    cell = str(row["document"])
    if cell.lstrip().startswith("{"):
        return json.loads(cell)
    assert out is not None and spec is not None  # a worker's rows hold the JSON text
    try:
        doc = json.loads((out / cell).read_text(encoding="utf-8"))
        return {k: v for k, v in doc.items() if k not in FILE_FIELDS}
    except (OSError, ValueError, AttributeError) as exc:
        sys.stderr.write(f"note: {out / cell}: unreadable ({type(exc).__name__}): the row "
                         "read from the CSV's columns, without its certificate and witness "
                         "(--restart computes them again)\n")
        return _plain_document(spec, row)


def _plain_document(spec: Spec, row: Mapping[str, Any]) -> dict[str, Any]:
    """The document of a CSV row from its plain columns alone."""
    def num(key: str) -> float | None:
        return None if row.get(key) in ("", None) else float(row[key])

    return {"spec": spec.name, "kappa": num("kappa"), "steps": int(row["steps"]),
            "tau": num("tau"), "measure": row.get("measure"), "initial": row.get("initial"),
            "status": row.get("status"), "gap": num("gap"), "certificate": None,
            "witness": None, "seconds": num("seconds")}


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
        files += [out / document_file(spec, k, n) for n in ns]
        for stem in (f"{spec.name}-pep{_tag(k)}", f"{spec.name}-pep{_tag(k)}-N{ns[-1]}-witness"):
            files += [out / f"{stem}.{ext}" for ext in ("png", "pdf")]
    return files


def _write_files(spec: Spec, text: str, docs: list[dict[str, Any]], out: Path,
                 plot: bool, recorded: Mapping[str, Any]) -> list[str]:
    """Witness JSON files (with the spec's text as the run read it and ``recorded``, the
    ``set`` overrides, so ``sosalgo verify`` needs nothing else), each written atomically,
    and the figure of tau_k against k for each kappa with two steps or more."""
    from sosalgo.store import write_atomic

    files = []
    for d in docs:
        if d.get("witness"):
            path = _witness_path(spec, out, d["kappa"], d["steps"])
            write_atomic(path, json.dumps(d["witness"] | {"spec_text": text} | dict(recorded),
                                          indent=1))
            files.append(str(path))
    if plot:
        from sosalgo.report.pep import pep_figure

        kappas = [d["kappa"] for d in docs]
        rates = {k: _certified_rate(spec, k) for k in set(kappas) if kappas.count(k) >= 2}
        files += pep_figure(spec, docs, out, rates)
    return files


def _certified_rate(spec: Spec, kappa: float | None) -> float | None:
    """The best rate ``sosalgo analyze`` certifies at kappa, as :func:`sosalgo.analyze`
    computes it (None: none, or m: 0)."""
    if kappa is None:
        return None
    from sosalgo.analysis import analyze_spec
    from sosalgo.inputs import check_kappa_points, select_families

    try:
        fam = select_families(spec, None, None, single=True, command="analyze")[0]
        check_kappa_points(spec, [kappa], None)
        res = analyze_spec(spec, kappa, None, tol=1e-6, family=fam)
    except (ValueError, ArithmeticError):
        return None
    return float(res.rho) if res.certified and res.rho is not None else None


def pep_summary(doc: dict[str, Any], details: bool = True) -> str:
    """The printed table of ``sosalgo pep``: what tau is (the class and its parameters, the
    measure, the initial condition and the steps, in words), the table (the witness's
    dimension and the seconds only with ``details``) and its legend."""
    from sosalgo.report import format_table
    from sosalgo.report.legend import set_lines
    from sosalgo.schema import printed_columns

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
    files = doc.get("files") or []
    return "\n".join([*pep_heading(rows), *set_lines(doc),
                      format_table(table, printed_columns(cols, details)),
                      *PEP_LEGEND, *witness_notes(rows)] + [f"wrote {f}" for f in files])


def witness_notes(rows: list[dict[str, Any]]) -> list[str]:
    """One plain line per row whose witness does not pin tau from below: not verified
    (no lower bound at all), or the quadratic of the search's last resort (a lower bound
    far below tau)."""
    out = []
    for d in rows:
        w = d.get("witness") or {}
        chk, where = w.get("check") or {}, f"kappa {d.get('kappa')}, N = {d.get('steps')}"
        if w and not chk.get("verified"):
            out.append(f"{where}: no witness verified ({chk.get('detail', 'not checked')}): "
                       "tau has no proven lower bound here (the witness file's search says "
                       "what was tried)")
        elif w.get("necessary_only"):
            out.append(f"{where}: {', '.join(w['necessary_only'])}: necessary conditions "
                       "only (no interpolation theorem); witness_lower bounds this PEP "
                       "from below, not the class's worst case, and tau_proven is an "
                       "upper bound of that worst case")
        elif (w.get("search") or {}).get("quadratic"):
            low, tau = chk.get("tau_lower_float"), d.get("tau")
            ratio = f", {low / tau:.2g} of tau" if low and tau else ""
            out.append(f"{where}: the SDP's worst case could not be made exact; the "
                       f"witness is a quadratic, proving only tau_N >= {low:.6g}{ratio}")
    return out


PEP_LEGEND = ("tau: the SDP's worst case (floating point); tau_proven: proven upper bound "
              "(exact dual certificate)",
              "witness_lower: witnessed lower bound (reached by an explicit function and start)")
_TERM = re.compile(r"\b(f|dist|grad|sdist|mingrad|minf|contraction)\b"
                   r"(\s*\(\s*([A-Za-z0-9_]+)\s*\))?")
_DIFF = re.compile(r"\(f\(([A-Za-z0-9_]+)\) - f\*\) - \(f\(([A-Za-z0-9_]+)\) - f\*\)")
_PAIR = re.compile(r"\bdist\s*\(\s*([A-Za-z0-9_]+(?:\s*-\s*\d+)?)\s*,"
                   r"\s*([A-Za-z0-9_]+(?:\s*-\s*\d+)?)\s*\)")


def term_words(text: str, initial: bool, several: bool) -> str:
    """A measure or initial condition (``f``, ``2*dist``, ``f + L/2*grad(y_N)``,
    ``dist(x_N, x_N-1)``) in words: f(x_N) - f*, |x_0 - x*|^2, |grad f(y_N)|^2,
    |xi_N - xi*|^2, |x_N - x_N-1|^2 (``several``: a sum over the functions)."""
    def words(mt: re.Match[str]) -> str:
        kind, point = mt.group(1), mt.group(3) or ("x_0" if initial else "x_N")
        state = "xi_0" if initial else "xi_N"
        return {"f": (f"(sum_j f_j({point}) - f_j*)" if several else f"(f({point}) - f*)"),
                "dist": f"|{point} - x*|^2", "grad": f"|grad f({point})|^2",
                "sdist": f"|{state} - xi*|^2",
                "mingrad": "min_{k <= N} |grad f(x_k)|^2",
                "minf": "min_{k <= N} f(x_k) - f*",
                "contraction": f"|{state} - {state}'|^2 (two runs)"}[kind]

    out = _DIFF.sub(r"f(\1) - f(\2)", _TERM.sub(words, _PAIR.sub(r"|\1 - \2|^2",
                                                                  str(text))))
    return out[1:-1] if out.startswith("(") and out.endswith(")") and out.count("(") == 2 \
        else out


def pep_heading(rows: list[dict[str, Any]]) -> list[str]:
    """What tau is, in words: the measure over the initial condition, each function's
    class with its parameters (m, L; L = kappa m over several kappas), the steps."""
    from sosalgo.classes import CLASSES

    d = rows[0]
    cls = d.get("class") or {}
    funcs = cls.get("functions") or {"f": {"class": "F(m, L)", "params": {
        "m": cls.get("m"), "L": cls.get("L")}}}  # a row written before rows named classes
    several = len(funcs) > 1
    many = len({r["kappa"] for r in rows}) > 1
    free = re.search(r"\bsdist\b(?!\s*\()", str(d["initial"]))  # sdist(x_0): not free
    start = ("any xi_0 (the whole state is free)" if free
             else "any two xi_0, xi_0' (two runs on the same functions)"
             if "contraction" in str(d["initial"])
             else "x_0 (the method at rest there, or as its initial_state says)")
    drawn = d.get("outcomes") is not None  # a finite sum: one function drawn per step
    bound = "" if drawn and "<=" in str(d["initial"]) else " <= 1"
    lines = [f"{d['spec']}: tau = worst case of {term_words(d['measure'], False, several)} "
             f"when {term_words(d['initial'], True, several)}{bound}, over"]
    if d.get("per_step"):  # a per-step program: its terms as written
        when = ("no initial condition (the classes' constants bound it)"
                if d["initial"] == "none" else f"{d['initial']}")
        lines = [f"{d['spec']}: tau = worst case of {d['measure']} ({when}), over"]
    for name, fn in funcs.items():
        what = getattr(CLASSES.get(fn.get("class")), "description", "") or fn.get("class")
        params = {k: ("kappa m" if many and k == "L" else v)
                  for k, v in (fn.get("params") or {}).items()}
        shown = ", ".join(f"{k} = {v}" for k, v in params.items())
        lines.append(f"  {name}: {fn.get('class')} ({what})" + (f" with {shown}" if shown
                                                                 else ""))
    prox = set(cls.get("inexact_proximal") or ())
    refs = cls.get("relative_to") or {}
    for call, eps in (cls.get("relative_errors") or {}).items():
        if call in refs:
            ref = " + ".join(f"{c}*u{i + 1}" for i, c in enumerate(refs[call]) if c != "0")
            lines.append(f"  {call}: an inexact {'proximal step' if call in prox else 'call'}"
                         f" answering d, |d - g| <= {eps} |{ref}| (g the true subgradient, "
                         "u the step's answers)")
            continue
        lines.append(f"  {call}: an inexact proximal step y = v - t d, d within {eps} |d| "
                     "of a subgradient at y (|y - prox| <= "
                     f"{eps} |y - v|)" if call in prox else
                     f"  {call}: an inexact gradient d, |d - grad f| <= {eps} |grad f|")
    for call, src in (cls.get("gradient_of") or {}).items():
        lines.append(f"  {call}: the true subgradient at {src}'s point")
    if cls.get("span_search"):
        lines.append("  x_k+1: minimizes f over x_0 + the span of the gradients so far "
                     "(exact span search)")
    elif cls.get("line_search"):
        lines.append(f"  {cls['line_search']}: chosen at every step by exact line search")
    if d.get("per_step"):
        f = d["per_step"]
        return lines + ["  start: every vector of finite_sum.state free, then "
                        "finite_sum.start (xs: the reference point)",
                        f"  N steps: step k = 0..N-1 calls {f}[i] = {f}_k, a new function "
                        "of its class; sum(...): the sum over the steps"]
    if drawn:
        return lines + ["  start: every vector of finite_sum.state free",
                        "  N steps: N runs of finite_sum.step, each drawing its index i "
                        f"uniformly ({d['outcomes']} outcomes); E[...]: their average"]
    return lines + [f"  start: {start}",
                    "  N steps: N iterations xi+ = A xi + B u (each with its oracle calls); "
                    "x_N: the output after them"]
