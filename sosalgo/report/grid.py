"""What ``sosalgo grid`` shows: the rate map over Θ, its minimum and a one-line summary."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.model import parameter_values
from sosalgo.report import plot_grid
from sosalgo.schema import kappa_label
from sosalgo.spec import Spec

__all__ = ["grid_document", "grid_lines", "grid_plot", "grid_rates"]


def grid_rates(rows: Sequence[dict[str, str]]) -> np.ndarray:
    """The certified rate of each grid row (NaN where none was certified)."""
    return np.array([float(r["rho"]) if r["rho"] else np.nan for r in rows])


def grid_plot(spec: Spec, kappa: float, names: Sequence[str],
              box: Sequence[tuple[float, float]], points: int, rho: np.ndarray,
              stem: Path) -> list[Path]:
    """The rate over a 1- or 2-parameter grid, with the spec's own values marked."""
    axes = [np.linspace(lo, hi, points) for lo, hi in box]
    vals = parameter_values(spec, kappa)
    return plot_grid(f"{spec.name}: certified rate, kappa = {kappa:.10g}", names, axes,
                     rho.reshape([points] * len(names)), stem,
                     value_point=[vals[p] for p in names])


def grid_document(kappa: float, csv_path: Path, figs: Sequence[Path],
                  rows: Sequence[dict[str, str]], rho: np.ndarray,
                  names: Sequence[str]) -> dict[str, Any]:
    """The ``grids`` entry of ``grid --json``: files, counts and the certified minimum."""
    finite = np.isfinite(rho)
    best = None
    if finite.any():
        i = int(np.nanargmin(np.where(finite, rho, np.nan)))
        best = {"rho": float(rho[i]), "theta": {p: float(rows[i][p]) for p in names}}
    return {"kappa": kappa, "csv": str(csv_path), "figures": [str(f) for f in figs],
            "points": len(rows), "certified": int(finite.sum()), "minimum": best}


def grid_lines(spec_name: str, doc: dict[str, Any]) -> list[str]:
    """Two printed lines of one grid: certified points and minimum; files written."""
    m = doc["minimum"]
    where = "none certified" if m is None else (
        f"minimum rho {m['rho']:.6f} at "
        + ", ".join(f"{p} = {v:.6g}" for p, v in m["theta"].items()))
    return [f"{spec_name} kappa={kappa_label(doc['kappa'])}: {doc['certified']}/"
            f"{doc['points']} points certified; {where}",
            f"wrote {doc['csv']}" + "".join(f", {p}" for p in doc["figures"])]
