"""``sosalgo design|grid`` on a sublinear spec (``m: 0``, L given, no kappa).

``design`` writes one row to ``<name>-design.csv``; ``grid`` one row per point to
``<name>-grid.csv``. Each returns the ``--json`` document (rows say ``rate_type:
sublinear`` and ``constant: c``). Every file is written under the run model of
:mod:`sosalgo.store` (resume, keep other settings' results aside, one output lock):
a rerun with the same settings reads the finished rows back instead of computing them.
``analyze`` goes through the analysis sweep (:mod:`sosalgo.batch.sweeps`) with the
sublinear family (:class:`sosalgo.certificates.sublinear.SublinearFamily`)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sosalgo.batch.sweeps import sublinear_simulation
from sosalgo.schema import DESIGN_KIND, GRID_KIND
from sosalgo.spec import Spec

__all__ = ["design_lines", "sublinear_design_run", "sublinear_grid_chunk",
           "sublinear_grid_run"]

DESIGN_COLUMNS = ["L", "rate_type", "free", "constant", "certified", "lower_bound",
                  "bound_status", "evaluations", "seconds", "time_limit", "timed_out",
                  "check_kind", "simulation_ok", "simulation_worst_ratio"]
GRID_RESULT_COLUMNS = ["constant", "certified", "solves", "seconds"]


# --------------------------------------------------------------------------- CSV cells
def _cell(v: Any) -> Any:
    """A CSV cell as these files have always written it (``True``/``False`` for flags)."""
    return str(v) if isinstance(v, bool) else v


def _num(v: str | None) -> float | None:
    return None if v in (None, "") else float(v)


def _flag(v: str | None) -> bool:
    return v in ("True", "true")


def _json_cell(v: str | None) -> Any:
    return None if v in (None, "") else json.loads(v)


def _store(path: Path, columns: Sequence[str], key: Sequence[str], settings: dict[str, Any],
           restart: bool, companions: Sequence[Path] = ()) -> Any:
    """The resumable output of a sublinear run (the run model of the other commands)."""
    from sosalgo.store import ResumableCSV

    return ResumableCSV(path, columns, key, settings, restart=restart, companions=companions)


def _figures(stem: Path) -> list[Path]:
    return [stem.with_name(f"{stem.name}.{ext}") for ext in ("png", "pdf")]


# --------------------------------------------------------------------------- design
def sublinear_design_run(spec: Spec, text: str, out_dir: str | Path, free: Any = None,
                         time_limit: float = 120.0, verify: bool = False,
                         restart: bool = False, progress: bool = True) -> dict[str, Any]:
    """``sosalgo design`` on a sublinear spec: minimize the certified constant over the box
    (:func:`sosalgo.sublinear_design.sublinear_design`), simulate the design, write
    ``<name>-design.csv``; returns the document (one row). A rerun with the same settings
    reads the design back from the CSV."""
    from sosalgo import inputs
    from sosalgo.batch.executor import Progress
    from sosalgo.report.analysis import attach_constant_checks

    names = inputs.free_names(spec, free)
    inputs.check_time_limit(time_limit, "--time-limit")
    out = inputs.out_dir(out_dir)
    path = out / f"{spec.name}-design.csv"
    columns = DESIGN_COLUMNS + [f"param_{p}" for p in spec.parameters] + ["certificate"]
    settings = {"job": "design", "spec": text, "free": names, "time_limit": float(time_limit)}
    with _store(path, columns, ["L"], settings, restart) as store:
        if store.rows():
            Progress(1, f"design {spec.name}", progress, done=1, resumed_from=path).close()
            row = _design_from_csv(spec, names, store.rows()[0])
        else:
            row = _design_row(spec, names, time_limit, progress)
            store.write(_design_cells(names, row))
    row |= {"kind": DESIGN_KIND, "spec": spec.name, "source": spec.source,
            "spec_text": text}  # self-contained
    if verify:
        attach_constant_checks(spec, [row], out / "certificates")
    return {"kind": DESIGN_KIND, "spec": spec.name, "source": spec.source, "spec_text": text,
            "csv": str(path), "figures": [], "rows": [row]}


def _design_row(spec: Spec, names: list[str], time_limit: float,
                progress: bool) -> dict[str, Any]:
    """The design (with its simulation), the progress bar saying so while it runs."""
    from sosalgo.batch.executor import Progress
    from sosalgo.sublinear_design import sublinear_design

    bar = Progress(1, f"design {spec.name}", progress)
    try:
        bar.phase("search", f"time limit {time_limit:g} s")
        row = sublinear_design(spec, names, time_limit)
        row["simulation"] = sublinear_simulation(spec, row["constant"], row["theta"])
        bar.update()
    finally:
        bar.close()
    return row


def _design_cells(names: list[str], row: dict[str, Any]) -> dict[str, Any]:
    sim = row["simulation"]
    cells = {k: row.get(k) for k in DESIGN_COLUMNS} | {
        "free": ",".join(names), "certificate": json.dumps(row["certificate"]),
        "simulation_ok": None if sim is None else sim["ok"],
        "simulation_worst_ratio": None if sim is None else sim["worst_ratio"]}
    cells |= {f"param_{p}": v for p, v in row["params"].items()}
    return {k: _cell(v) for k, v in cells.items()}


def _design_from_csv(spec: Spec, names: list[str], cells: dict[str, str]) -> dict[str, Any]:
    """The design row read back from its CSV row (the simulation is run again: it is
    evidence about the constant, cheap next to the design)."""
    from sosalgo.model import parameter_box

    params = {p: float(cells[f"param_{p}"]) for p in spec.parameters
              if cells.get(f"param_{p}", "") != ""}
    constant = _num(cells["constant"])
    theta = None if constant is None else {p: params[p] for p in names}
    row = {"rate_type": cells["rate_type"], "L": float(cells["L"]), "free": names,
           "box": [list(b) for b in parameter_box(spec, float("nan"), names)], "constant": constant,
           "certified": _flag(cells["certified"]), "theta": theta, "params": params,
           "lower_bound": _num(cells["lower_bound"]), "bound_status": cells["bound_status"],
           "evaluations": int(cells["evaluations"]), "seconds": float(cells["seconds"]),
           "time_limit": float(cells["time_limit"]), "timed_out": _flag(cells["timed_out"]),
           "check_kind": cells["check_kind"] or None,
           "certificate": _json_cell(cells["certificate"]), "family": "sublinear"}
    row["simulation"] = sublinear_simulation(spec, constant, theta)
    return row


# --------------------------------------------------------------------------- grid
def sublinear_grid_chunk(spec_text: str, source: str, options: dict[str, Any],
                         chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: the certified constant at each task's point (its free parameters' values)."""
    from sosalgo.analysis import analyze_sublinear
    from sosalgo.batch.sweeps import cached_spec
    from sosalgo.model import ModelError

    spec = cached_spec(spec_text, source)
    rows = []
    for task in chunk:
        theta = {p: float(task[p]) for p in options["free"]}
        try:
            res = analyze_sublinear(spec, theta)
            cells = {"constant": res.constant, "certified": res.certified,
                     "solves": res.solves, "seconds": res.seconds}
        except ModelError:  # no fixed point or a domain error there
            cells = {"certified": False}
        rows.append({k: _cell(v) for k, v in (theta | cells).items()})
    return rows


sublinear_grid_chunk.max_chunk = 1  # type: ignore[attr-defined]  # a point takes ~0.5 s


def sublinear_grid_run(spec: Spec, text: str, out_dir: str | Path, points: int = 60,
                       free: Any = None, workers: int | None = None,
                       scheduler: str | None = None, restart: bool = False,
                       progress: bool = True) -> dict[str, Any]:
    """``sosalgo grid`` on a sublinear spec: the certified constant at every point of a
    grid over the free parameters' box, written row by row to ``<name>-grid.csv``
    (resumable, on ``workers`` processes or a Dask ``scheduler`` like every grid)."""
    from sosalgo import inputs
    from sosalgo.batch.executor import check_scheduler
    from sosalgo.batch.sweeps import grid_points, run_store, seed_spec
    from sosalgo.model import parameter_box

    names = inputs.free_names(spec, free)
    inputs.check_grid_points(points, len(names))
    box = parameter_box(spec, float("nan"), names)
    out = inputs.out_dir(out_dir)
    if scheduler is not None:
        check_scheduler(scheduler)
    path = out / f"{spec.name}-grid.csv"
    settings = {"job": "grid", "spec": text, "free": names, "points": points,
                "box": [list(b) for b in box]}
    store = _store(path, names + GRID_RESULT_COLUMNS, names, settings, restart)
    tasks = [dict(zip(names, pt, strict=True)) for pt in grid_points(box, points)]
    seed_spec(spec, text)
    run_store(store, tasks, f"grid {spec.name}", progress, sublinear_grid_chunk, text,
               spec.source, {"free": names}, None, workers, scheduler)
    order = {store.row_key(t): i for i, t in enumerate(tasks)}
    rows = sorted((r for r in store.rows() if store.row_key(r) in order),
                  key=lambda r: order[store.row_key(r)])
    constants = [float(r["constant"]) for r in rows if r["constant"] != ""]
    return {"kind": GRID_KIND, "spec": spec.name, "rate_type": "sublinear", "free": names,
            "csv": str(path), "best": min(constants, default=None), "grids": []}

def design_lines(doc: dict[str, Any]) -> list[str]:
    """What ``sosalgo design`` prints for a sublinear design document."""
    row = doc["rows"][0]
    sim = row.get("simulation") or {}
    theta = ", ".join(f"{k} = {v:.7g}" for k, v in (row["theta"] or {}).items())
    head = (f"{doc['spec']}: design of {', '.join(row['free'])} minimizing the certified "
            "constant c in measure(x_k) <= c |x_0 - x*|^2 / k (no lower bound over the box)")
    best = ("no constant certified anywhere in the box" if row["constant"] is None else
            f"c = {row['constant']:.7g} at {theta} ({row['check_kind']}; simulation: "
            f"{'ok' if sim.get('ok') else 'VIOLATED'}, worst ratio "
            f"{sim.get('worst_ratio', float('nan')):.3g})")
    lines = [head, f"  {best}", f"  {row['evaluations']} evaluations, "
             f"{row['seconds']:.1f} s" + (" (time limit reached)" if row["timed_out"] else "")]
    ver = row.get("verification")
    if ver is not None:
        lines.append(f"  exact verification: {ver.get('verified')}"
                     + (f" (c <= {ver['constant_proven_float']:.7g})"
                        if ver.get("constant_proven_float") is not None else ""))
    return lines + [f"wrote {doc['csv']}"]
