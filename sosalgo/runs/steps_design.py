"""``sosalgo design SPEC --steps N`` as a Python function: :func:`steps_design_run` (one CSV
row per (kappa, N), resumable, through the batch layer; figures of the schedule and of
the worst case against N). The design itself is :func:`sosalgo.design.steps.design_steps`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sosalgo.errors import InputError
from sosalgo.kernel.phases import begin_task
from sosalgo.kinds import DESIGN_STEPS_KIND
from sosalgo.spec import Spec

__all__ = ["steps_design_chunk", "steps_design_run"]


def steps_design_chunk(spec_text: str, source: str, options: dict[str, Any],
                       chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: the design at each task's (kappa, steps)."""
    from sosalgo.design.steps import design_steps, steps_problem
    from sosalgo.pep.evaluate import steps_evaluator
    from sosalgo.runs import kappa_value
    from sosalgo.spec import spec_from_text

    spec = spec_from_text(spec_text, source)
    rows = []
    for task in chunk:
        kappa = None if task["kappa"] in ("", None) else kappa_value(task["kappa"])
        begin_task(f"N {task['steps']}" + ("" if kappa is None else f", kappa {kappa:g}"))
        steps = int(task["steps"])
        prob = steps_problem(spec, kappa, steps, options["free"])
        res = design_steps(spec, spec_text, kappa, steps, prob.layout, prob.box,
                           steps_evaluator(spec, spec_text, kappa, steps, prob),
                           options["time_limit"], options["gap"], prob.seeds, prob.model)
        if prob.reason:
            res.log.insert(0, f"no box-wide lower bound: {prob.reason}")
        doc = res.to_dict()
        rows.append({"kappa": "" if kappa is None else kappa, "steps": res.steps,
                     "schedule": json.dumps(doc["schedule"]),
                     **{k: doc[k] for k in ("tau_certified", "lower_bound", "gap",
                                            "gap_relative", "floor", "time_limited",
                                            "seconds")},
                     "document": json.dumps(doc)})
    return rows


steps_design_chunk.max_chunk = 1  # type: ignore[attr-defined]  # a design takes minutes


def _kappas(spec: Spec, kappa: float | Sequence[float] | None) -> list[float | None]:
    from sosalgo.runs import kappa_value

    if spec.sublinear:
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
    from sosalgo.design.steps import steps_problem
    from sosalgo.pep.core import parse_steps
    from sosalgo.pep.evaluate import steps_evaluator
    from sosalgo.runs import set_field, spec_with_text
    from sosalgo.schema import STEPS_DESIGN_COLUMNS, steps_design_csv
    from sosalgo.store import ResumableCSV

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
                         restart=restart, companions=_figure_files(spec, out))
    with store:
        todo = [t for t in tasks if not store.is_done(t)]
        bar = Progress(len(tasks), f"design {spec.name} --steps", progress,
                       done=len(tasks) - len(todo), resumed_from=path)
        try:
            run_batch(steps_design_chunk, text, spec.source, options, todo, store.write,
                      workers, scheduler, bar, isolate=True)
        finally:
            bar.close()
        keys = {store.row_key(t) for t in tasks}
        docs = sorted((json.loads(r["document"]) for r in store.rows()
                       if store.row_key(r) in keys),
                      key=lambda d: (d["kappa"] or 0.0, d["steps"]))
        for d in docs:
            d.update({"kind": DESIGN_STEPS_KIND, "source": spec.source, "spec_text": text}
                     | set_field(overrides))
        figs = _figures(spec, docs, out) if plot else []
    if verify:
        from sosalgo.verify.steps_design import verify_steps_row

        for d in docs:
            d["verification"] = verify_steps_row(d, spec)
    return {"kind": DESIGN_STEPS_KIND, "spec": spec.name, "source": spec.source,
            "spec_text": text, "csv": str(path), "figures": figs, "rows": docs} \
        | set_field(overrides)


def _figure_files(spec: Spec, out: Path) -> list[Path]:
    return [out / f"{spec.name}-design-steps-{what}.{ext}"
            for what in ("schedule", "worst-case") for ext in ("png", "pdf")]


def _figures(spec: Spec, docs: list[dict[str, Any]], out: Path) -> list[str]:
    from sosalgo.report.steps_design import steps_design_figures

    return [str(p) for p in steps_design_figures(spec.name, docs, out)]
