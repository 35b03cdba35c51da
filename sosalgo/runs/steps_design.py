"""``sosalgo design SPEC --steps N`` as a Python function: :func:`steps_design_run` (one CSV
row per (kappa, N), resumable, through the batch layer; figures of the schedule and of
the worst case against N). The design itself is :func:`sosalgo.design_search.steps.design_steps`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sosalgo.errors import InputError
from sosalgo.kinds import DESIGN_STEPS_KIND
from sosalgo.spec import Spec

__all__ = ["steps_design_chunk", "steps_design_run"]


def steps_design_chunk(spec_text: str, source: str, options: dict[str, Any],
                       chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: the design at each task's (kappa, steps)."""
    from sosalgo.design_search.steps import design_steps, steps_problem
    from sosalgo.runs.pep import task_kappa
    from sosalgo.spec import spec_from_text
    from sosalgo.worstcase.evaluate import steps_evaluator

    spec = spec_from_text(spec_text, source)
    rows = []
    for task in chunk:
        kappa = task_kappa(task)
        steps = int(task["steps"])
        prob = steps_problem(spec, kappa, steps, options["free"])
        res = design_steps(spec, spec_text, kappa, steps, prob.layout, prob.box,
                           steps_evaluator(spec, spec_text, kappa, steps, prob),
                           options["time_limit"], options["gap"], prob.seeds, prob.model,
                           prob.reason, box_workers=options.get("box_workers", 1))
        doc = res.to_dict()
        rows.append({"kappa": "" if kappa is None else kappa, "steps": res.steps,
                     "schedule": json.dumps(doc["schedule"]),
                     **{k: doc[k] for k in ("tau_certified", "lower_bound", "gap",
                                            "gap_relative", "floor", "time_limited",
                                            "seconds")},
                     "document": json.dumps(doc)})
    return rows


steps_design_chunk.max_chunk = 1  # type: ignore[attr-defined]  # a design takes minutes


def _box_workers(workers: int | None, scheduler: str | None,
                 todo: Sequence[Any]) -> int:
    """The processes each design's bound proves boxes on: the local workers that the
    designs leave free, shared among them (``--workers 2`` and one N: both cores prove
    boxes); one on a Dask scheduler."""
    if scheduler is not None or not todo:
        return 1
    from sosalgo.kernel.budget import usable_workers

    return max(1, usable_workers(workers) // len(todo))


def _kappas(spec: Spec, kappa: float | Sequence[float] | None) -> list[float | None]:
    from sosalgo.runs import kappa_value

    if not spec.has_condition_number:
        if kappa not in (None, [], ()):
            raise InputError(f"{spec.source}: --kappa: undefined for a sublinear spec (m: 0)")
        return [None]
    if kappa in (None, [], ()):
        return list(spec.kappa)
    if isinstance(kappa, int | float | str):
        return [kappa_value(kappa)]
    return [kappa_value(k) for k in kappa]  # type: ignore[union-attr]


def steps_design_run(spec: Spec | str | Path, kappa: float | Sequence[float] | None = None,
                     steps: int | str = 1, out_dir: str | Path = "outputs",
                     free: str | Sequence[str] | None = None, gap: float = 1e-3,
                     time_limit: float = 120.0, workers: int | None = None,
                     scheduler: str | None = None, restart: bool = False,
                     progress: bool = True, verify: bool = False, plot: bool = True,
                     spec_text: str | None = None,
                     overrides: Mapping[str, str] | None = None) -> dict[str, Any]:
    """``sosalgo design --steps``: one design document per (kappa, N) — ``schedule``,
    ``tau_certified``, ``lower_bound``, ``gap``, ``floor`` — in ``rows`` (the CSV
    ``<name>-design-steps.csv`` and the figures in ``out_dir``); with ``verify`` each row
    gets ``verification`` (its worst case and lower bound proven again)."""
    from sosalgo import inputs
    from sosalgo.batch.executor import Progress, check_scheduler, run_batch
    from sosalgo.batch.sweeps import kappa_settings
    from sosalgo.design_search.steps import steps_problem
    from sosalgo.runs import set_field, spec_with_text
    from sosalgo.schema import STEPS_DESIGN_COLUMNS, steps_design_csv
    from sosalgo.store import ResumableCSV
    from sosalgo.worstcase.core import parse_steps
    from sosalgo.worstcase.evaluate import steps_evaluator

    spec, text = spec_with_text(spec, spec_text, overrides, varying=True)
    ks = _kappas(spec, kappa)
    ns = parse_steps(steps)
    names = inputs.free_names(spec, free)
    inputs.check_gap(gap, "--gap")
    inputs.check_time_limit(time_limit, "--time-limit")
    for k in ks:  # every input error before anything is written
        for n in ns:
            prob = steps_problem(spec, k, n, names)
            steps_evaluator(spec, text, k, n, prob)
    check_scheduler(scheduler)
    out = inputs.out_dir(out_dir)
    options = {"free": names, "gap": gap, "time_limit": time_limit}
    tasks = [{"kappa": "" if k is None else k, "steps": n} for k in ks for n in ns]
    path = steps_design_csv(out, spec.name)
    settings = {"job": "design-steps", "spec": text, **options} | kappa_settings(
        [k for k in ks if k is not None])
    store = ResumableCSV(path, STEPS_DESIGN_COLUMNS, ["kappa", "steps"], settings,
                         restart=restart,
                         companions=_figure_files(spec, out) + [
                             out / document_file(spec, k, n) for k in ks for n in ns])
    with store:
        todo = [t for t in tasks if not store.is_done(t)]
        bar = Progress(len(tasks), f"design {spec.name} --steps", progress,
                       done=len(tasks) - len(todo), resumed_from=path)
        try:
            def persist(row: dict[str, Any]) -> None:  # the document's file, then its row
                store.write(_persist(spec, text, row, out, set_field(overrides)))

            run_batch(steps_design_chunk, text, spec.source,
                      {**options, "box_workers": _box_workers(workers, scheduler, todo)},
                      todo, persist, workers, scheduler, bar, isolate=True)
        finally:
            bar.close()
        keys = {store.row_key(t) for t in tasks}
        docs = sorted((_row_document(r, out) for r in store.rows()
                       if store.row_key(r) in keys),
                      key=lambda d: (d["kappa"] or 0.0, d["steps"]))
        for d in docs:
            d.update({"kind": DESIGN_STEPS_KIND, "source": spec.source, "spec_text": text}
                     | set_field(overrides))
        figs = _figures(spec, docs, out) if plot else []
    if verify:
        from sosalgo.proofs.steps_design import verify_steps_row

        for d in docs:
            d["verification"] = verify_steps_row(d, spec)
    return {"kind": DESIGN_STEPS_KIND, "spec": spec.name, "source": spec.source,
            "spec_text": text, "csv": str(path), "figures": figs, "rows": docs} \
        | set_field(overrides)


def document_file(spec: Spec, kappa: float | None, steps: int) -> str:
    """``<name>-design-steps[-k<kappa>]-N<steps>.json``: one (kappa, N) document beside
    the CSV (its leaves are too large for a CSV cell); the ``document`` cell names it."""
    from sosalgo.schema import kappa_label

    tag = "" if kappa is None else f"-k{kappa_label(kappa)}"
    return f"{spec.name}-design-steps{tag}-N{steps}.json"


def _persist(spec: Spec, text: str, row: dict[str, Any], out: Path,
             recorded: Mapping[str, Any]) -> dict[str, Any]:
    """Write the row's document (a ``design-steps`` document of its own, with the spec's
    text: ``sosalgo verify`` needs nothing else) atomically, then return the row with the
    file's name in its ``document`` cell (called under the CSV's lock)."""
    from sosalgo.store import write_atomic

    doc = json.loads(row["document"])
    name = document_file(spec, doc["kappa"], doc["steps"])
    whole = {"kind": DESIGN_STEPS_KIND} | doc | {"source": spec.source,
                                                 "spec_text": text} | dict(recorded)
    write_atomic(out / name, json.dumps(whole, indent=1))
    return row | {"document": name}


def _row_document(row: Mapping[str, Any], out: Path) -> dict[str, Any]:
    """A row's document: the file its cell names (InputError when it is gone)."""
    cell = str(row["document"])
    if cell.lstrip().startswith("{"):
        return json.loads(cell)
    try:
        return json.loads((out / cell).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"{out / cell}: unreadable ({type(exc).__name__}): run again "
                         "with --restart") from None


def _figure_files(spec: Spec, out: Path) -> list[Path]:
    return [out / f"{spec.name}-design-steps-{what}.{ext}"
            for what in ("schedule", "worst-case") for ext in ("png", "pdf")]


def _figures(spec: Spec, docs: list[dict[str, Any]], out: Path) -> list[str]:
    from sosalgo.report.steps_design import steps_design_figures

    return [str(p) for p in steps_design_figures(spec.name, docs, out)]
