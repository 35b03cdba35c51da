"""``sosalgo analyze`` on a sublinear spec (``m: 0``, L given, no kappa): one row.

Writes ``<name>-analysis.csv`` (columns :func:`sosalgo.schema.sublinear_columns`) and the
bound figure ``<name>-rate`` (.png, .pdf), and returns the ``--json`` document, whose row
says ``rate_type: sublinear`` and ``constant: c``.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from sosalgo.spec import Spec

__all__ = ["attach_verification", "design_lines", "sublinear_design_run",
           "sublinear_grid_run", "sublinear_row", "sublinear_run", "sublinear_simulation"]

DESIGN_COLUMNS = ["L", "rate_type", "free", "constant", "certified", "lower_bound",
                  "bound_status", "evaluations", "seconds", "time_limit", "timed_out",
                  "check_kind", "simulation_ok", "simulation_worst_ratio"]


def sublinear_simulation(spec: Spec, constant: float | None,
                         theta: dict[str, float] | None = None) -> dict[str, Any] | None:
    """The simulation check of a certified constant (evidence, not proof:
    :mod:`sosalgo.verify.simulate_sublinear`), or None when nothing is certified."""
    from sosalgo.model import bind_sublinear
    from sosalgo.verify.simulate_sublinear import simulate_sublinear

    if constant is None:
        return None
    return simulate_sublinear(bind_sublinear(spec, theta), constant).to_dict()


def sublinear_row(spec: Spec) -> dict[str, Any]:
    """The analysis of a sublinear spec as a JSON row (with the references' values and the
    simulation check of the constant)."""
    from sosalgo.analysis import analyze_sublinear
    from sosalgo.batch.sweeps import reference_values

    row = analyze_sublinear(spec).to_dict()
    row["references"] = reference_values(spec, float("nan"))
    row["simulation"] = sublinear_simulation(spec, row["constant"])
    return row


def sublinear_design_run(spec: Spec, text: str, out_dir: str | Path, free: Any = None,
                         time_limit: float = 120.0, verify: bool = False) -> dict[str, Any]:
    """``sosalgo design`` on a sublinear spec: minimize the certified constant over the box
    (:func:`sosalgo.sublinear_design.sublinear_design`), simulate the design, write
    ``<name>-design.csv``; returns the document (one row)."""
    from sosalgo import inputs
    from sosalgo.sublinear_design import sublinear_design

    names = inputs.free_names(spec, free)
    inputs.check_time_limit(time_limit, "--time-limit")
    out = inputs.out_dir(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    row = sublinear_design(spec, names, time_limit)
    row |= {"spec": spec.name, "source": spec.source, "spec_text": text}  # self-contained
    row["simulation"] = sublinear_simulation(spec, row["constant"], row["theta"])
    if verify:
        attach_verification(spec, row, out)
    path = out / f"{spec.name}-design.csv"
    columns = DESIGN_COLUMNS + [f"param_{p}" for p in spec.parameters] + ["certificate"]
    cells = {k: row.get(k) for k in DESIGN_COLUMNS} | {
        "free": ",".join(names), "certificate": json.dumps(row["certificate"]),
        "simulation_ok": None if row["simulation"] is None else row["simulation"]["ok"],
        "simulation_worst_ratio": None if row["simulation"] is None
        else row["simulation"]["worst_ratio"]}
    cells |= {f"param_{p}": v for p, v in row["params"].items()}
    _write_csv(path, columns, cells)
    return {"spec": spec.name, "source": spec.source, "spec_text": text, "csv": str(path),
            "figures": [], "rows": [row]}


def sublinear_grid_run(spec: Spec, text: str, out_dir: str | Path, points: int = 60,
                       free: Any = None) -> dict[str, Any]:
    """``sosalgo grid`` on a sublinear spec: the certified constant at every point of a
    grid over the free parameters' box, written row by row to ``<name>-grid.csv``."""
    import itertools

    import numpy as np

    from sosalgo import inputs
    from sosalgo.analysis import analyze_sublinear
    from sosalgo.model import ModelError, parameter_box

    names = inputs.free_names(spec, free)
    inputs.check_grid_points(points, len(names))
    box = parameter_box(spec, float("nan"), names)
    out = inputs.out_dir(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{spec.name}-grid.csv"
    columns = names + ["constant", "certified", "solves", "seconds"]
    best = None
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, columns)
        writer.writeheader()
        for pt in itertools.product(*[np.linspace(lo, hi, points) for lo, hi in box]):
            theta = dict(zip(names, map(float, pt), strict=True))
            try:
                res = analyze_sublinear(spec, theta)
                cells = {"constant": res.constant, "certified": res.certified,
                         "solves": res.solves, "seconds": res.seconds}
            except ModelError:
                cells = {"certified": False}
            if cells.get("constant") is not None and (best is None or cells["constant"] < best):
                best = cells["constant"]
            writer.writerow({c: "" if v is None else v for c, v in (theta | cells).items()})
            fh.flush()
    tmp.replace(path)
    return {"spec": spec.name, "rate_type": "sublinear", "free": names, "csv": str(path),
            "best": best, "grids": []}


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


def _write_csv(path: Path, columns: list[str], cells: dict[str, Any]) -> None:
    """One row, written to a temporary file and moved into place (never half-written)."""
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, columns)
        writer.writeheader()
        writer.writerow({c: "" if cells.get(c) is None else cells[c] for c in columns})
    tmp.replace(path)


def _csv_cells(spec: Spec, row: dict[str, Any]) -> dict[str, Any]:
    cells = {k: row.get(k) for k in ("L", "rate_type", "constant", "certified",
                                      "constant_estimate", "measure", "solves", "seconds",
                                      "solver", "check_kind")}
    cells["check"] = None if row["check"] is None else json.dumps(row["check"])
    cells["certificate"] = (None if row["certificate"] is None
                            else json.dumps(row["certificate"], separators=(",", ":")))
    cells.update({f"param_{p}": v for p, v in row["params"].items()})
    cells.update(row["references"])
    return cells


def attach_verification(spec: Spec, row: dict[str, Any], out: Path) -> None:
    """``verification`` (the exact proof of :mod:`sosalgo.verify.exact_sublinear` and the
    row's simulation; proof document in ``out/certificates``) and ``verified`` on a row."""
    from sosalgo.verify.results import verify_sublinear_rows

    check = verify_sublinear_rows(spec, [row], out / "certificates", simulate=False)[0]
    if check is not None:
        check["simulation"] = row["simulation"]
    row["verification"] = check
    row["verified"] = None if check is None else check["verified"]


def sublinear_run(spec: Spec, text: str, out_dir: str | Path, plot: bool = True,
                  kappa: Any = None, verify: bool = False) -> dict:
    """Analyze, write the CSV (and the figure with ``plot``), return the document (a kappa
    is refused first). With ``verify`` the row gets ``verification`` (the exact proof of
    :mod:`sosalgo.verify.exact_sublinear` and the row's simulation; proof document in
    ``out_dir/certificates``) and ``verified``."""
    from sosalgo import inputs
    from sosalgo.errors import InputError
    from sosalgo.report.analysis import sublinear_figure
    from sosalgo.schema import analysis_csv, rate_stem, sublinear_columns

    if kappa is not None and kappa != () and kappa != []:
        raise InputError(f"{spec.source}: --kappa: undefined for a sublinear spec (m: 0)")
    out = inputs.out_dir(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    row = sublinear_row(spec)
    if verify:
        attach_verification(spec, row, out)
    path = analysis_csv(out, spec.name, None)
    columns = sublinear_columns(spec)
    _write_csv(path, columns, _csv_cells(spec, row))
    figs = sublinear_figure(spec, row, rate_stem(out, spec.name)) if plot else []
    return {"spec": spec.name, "source": spec.source, "spec_text": text, "csv": str(path),
            "figures": [str(p) for p in figs], "rows": [row]}
