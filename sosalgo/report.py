"""Tables and figures: console tables, rate-vs-kappa plots with the closed-form references.

Figures are written with the non-interactive Agg backend, as PNG and PDF, through a
temporary file and an atomic rename (never a half-written figure).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["format_table", "plot_rates", "save_figure"]


def _fmt(v: Any, digits: int = 7) -> str:
    if v is None or v == "":
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
            return f"{v:.3e}"
        return f"{v:.{digits}f}".rstrip("0").rstrip(".") if "." in f"{v:.{digits}f}" else str(v)
    return str(v)


def format_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str],
                 headers: Sequence[str] | None = None) -> str:
    """A plain aligned text table."""
    headers = list(headers or columns)
    cells = [[_fmt(r.get(c)) for c in columns] for r in rows]
    widths = [max([len(h)] + [len(row[i]) for row in cells]) for i, h in enumerate(headers)]
    line = "  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join(out)


def save_figure(fig: plt.Figure, stem: Path) -> list[Path]:
    """Write ``stem.png`` and ``stem.pdf`` atomically; returns the paths."""
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    for ext in ("png", "pdf"):
        final = stem.with_name(f"{stem.name}.{ext}")
        tmp = stem.with_name(f".{stem.name}.{ext}.tmp")
        fig.savefig(tmp, format=ext, dpi=150, bbox_inches="tight")
        os.replace(tmp, final)
        paths.append(final)
    plt.close(fig)
    return paths


def plot_rates(
    title: str,
    kappa: Sequence[float],
    series: Mapping[str, Sequence[float | None]],
    references: Mapping[str, Sequence[float | None]],
    stem: Path,
    uncertified: Sequence[float] = (),
    ylabel: str = r"rate $\rho$",
) -> list[Path]:
    """Rate vs kappa on a log-kappa axis: solid series, dashed references.

    ``uncertified`` kappas (no certificate) are marked along the top, never drawn as
    rho = 1.
    """
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    k = np.asarray(kappa, dtype=float)
    markers = "os^Dv<>"
    for i, (label, vals) in enumerate(series.items()):
        y = np.array([np.nan if v is None else v for v in vals], dtype=float)
        ax.plot(k, y, marker=markers[i % len(markers)], ms=4, lw=1.6, label=label)
    for label, vals in references.items():
        y = np.array([np.nan if v is None else v for v in vals], dtype=float)
        ax.plot(k, y, ls="--", lw=1.2, label=label)
    if len(uncertified):
        ax.plot(uncertified, np.ones(len(uncertified)), ls="none", marker="x", color="red",
                ms=7, label="no certificate", clip_on=False)
    ax.set_xscale("log")
    ax.set_xlabel(r"condition number $\kappa = L/m$")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    return save_figure(fig, stem)
