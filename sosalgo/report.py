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

import numpy as np


def _pyplot() -> Any:
    """matplotlib.pyplot with the Agg backend, imported on first use (tables need none)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt

__all__ = ["format_table", "plot_rates", "save_figure", "plot_grid"]


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


def save_figure(fig: Any, stem: Path) -> list[Path]:
    """Write ``stem.png`` and ``stem.pdf`` atomically; returns the paths."""
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    for ext in ("png", "pdf"):
        final = stem.with_name(f"{stem.name}.{ext}")
        tmp = stem.with_name(f".{stem.name}.{ext}.tmp")
        fig.savefig(tmp, format=ext, dpi=150, bbox_inches="tight")
        os.replace(tmp, final)
        paths.append(final)
    _pyplot().close(fig)
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
    fig, ax = _pyplot().subplots(figsize=(6.4, 4.4))
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


def plot_grid(
    title: str,
    names: Sequence[str],
    axes: Sequence[np.ndarray],
    rho: np.ndarray,
    stem: Path,
    value_point: Sequence[float] | None = None,
) -> list[Path]:
    """Certified rate over a 1-D or 2-D grid. ``rho`` holds NaN where no certificate was
    found; those points are drawn as a hatched grey region (2-D) or marked (1-D), never as
    rho = 1. The grid minimum and the spec's own value point are marked."""
    fig, ax = _pyplot().subplots(figsize=(6.4, 4.8))
    finite = np.isfinite(rho)
    if len(names) == 1:
        x = axes[0]
        ax.plot(x, np.where(finite, rho, np.nan), lw=1.6, label="certified rate")
        if (~finite).any():
            ax.plot(x[~finite], np.ones((~finite).sum()), "x", color="grey",
                    label="no certificate", clip_on=False)
        if finite.any():
            i = int(np.nanargmin(np.where(finite, rho, np.nan)))
            ax.plot(x[i], rho[i], "*", ms=12, color="red",
                    label=f"grid minimum {rho[i]:.4f}")
        if value_point is not None:
            ax.axvline(value_point[0], ls=":", color="k", label="spec value")
        ax.set_xlabel(names[0])
        ax.set_ylabel(r"certified rate $\rho$")
    else:
        X, Y = np.meshgrid(axes[0], axes[1], indexing="ij")
        Z = np.where(finite, rho, np.nan)
        if (~finite).any():
            ax.contourf(X, Y, (~finite).astype(float), levels=[0.5, 1.5], colors=["0.85"],
                        hatches=["//"])
            ax.plot([], [], "s", color="0.85", label="no certificate")
        if finite.sum() >= 4:
            lo, hi = float(np.nanmin(Z)), float(np.nanmax(Z))
            levels = np.unique(np.round(np.linspace(lo, hi, 12), 4))
            if len(levels) >= 2:
                cf = ax.contourf(X, Y, Z, levels=levels, cmap="viridis", alpha=0.85)
                cs = ax.contour(X, Y, Z, levels=levels, colors="k", linewidths=0.6)
                ax.clabel(cs, fmt="%.3f", fontsize=7)
                fig.colorbar(cf, ax=ax, label=r"certified rate $\rho$")
            i = np.unravel_index(int(np.nanargmin(Z)), Z.shape)
            ax.plot(X[i], Y[i], "*", ms=14, color="red",
                    label=f"grid minimum {Z[i]:.4f}")
        if value_point is not None:
            ax.plot(*value_point, "o", ms=8, mfc="white", mec="k", label="spec value")
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
    ax.set_title(title)
    ax.legend(fontsize=8, loc="best")
    return save_figure(fig, stem)
