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

__all__ = ["refuse_sublinear", "sublinear_row", "sublinear_run"]


def sublinear_row(spec: Spec) -> dict[str, Any]:
    """The analysis of a sublinear spec as a JSON row (with the references' values)."""
    from sosalgo.analysis import analyze_sublinear
    from sosalgo.batch.sweeps import reference_values

    row = analyze_sublinear(spec).to_dict()
    row["references"] = reference_values(spec, float("nan"))
    return row


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


def sublinear_run(spec: Spec, text: str, out_dir: str | Path, plot: bool = True,
                  kappa: Any = None, verify: bool = False) -> dict:
    """Analyze, write the CSV (and the figure with ``plot``), return the document; a
    kappa or ``verify`` (no exact check of these certificates yet) is refused first."""
    from sosalgo import inputs
    from sosalgo.errors import InputError
    from sosalgo.report.analysis import sublinear_figure
    from sosalgo.schema import analysis_csv, rate_stem, sublinear_columns

    if kappa is not None and kappa != () and kappa != []:
        raise InputError(f"{spec.source}: --kappa: undefined for a sublinear spec (m: 0)")
    if verify:
        raise InputError(f"{spec.source}: --verify: sublinear certificates have a "
                         "floating-point check only (no exact verification yet)")
    out = inputs.out_dir(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    row = sublinear_row(spec)
    path = analysis_csv(out, spec.name, None)
    columns = sublinear_columns(spec)
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, columns)
        writer.writeheader()
        cells = _csv_cells(spec, row)
        writer.writerow({c: "" if cells.get(c) is None else cells[c] for c in columns})
    tmp.replace(path)
    figs = sublinear_figure(spec, row, rate_stem(out, spec.name)) if plot else []
    return {"spec": spec.name, "source": spec.source, "spec_text": text, "csv": str(path),
            "figures": [str(p) for p in figs], "rows": [row]}


def refuse_sublinear(spec: Spec, command: str) -> None:
    """One line (InputError) for a command that has no sublinear mode yet (design, grid,
    verify, table1): a sublinear spec (m: 0) has no kappa and no linear rate."""
    from sosalgo.errors import InputError

    if spec.sublinear:
        raise InputError(f"{spec.source}: m: 0 (sublinear rates): {command} is not supported "
                         "yet; use analyze")
