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

from sosalgo.report.style import color, finish, log_ticks, new_figure, pyplot

__all__ = ["format_table", "grid_figure", "log_ticks", "plot_grid", "plot_rates", "pyplot",
           "rate_figure", "save_figure"]


def fmt(v: Any, digits: int = 7) -> str:
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
    cells = [[fmt(r.get(c)) for c in columns] for r in rows]
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
        tmp = stem.with_name(f".{stem.name}.{ext}.{os.getpid()}.tmp")  # one per process
        try:
            fig.savefig(tmp, format=ext, dpi=150, bbox_inches="tight")
            os.replace(tmp, final)
        finally:
            tmp.unlink(missing_ok=True)
        paths.append(final)
    pyplot().close(fig)
    return paths


def plot_rates(
    title: str,
    kappa: Sequence[float],
    series: Mapping[str, Sequence[float | None]],
    references: Mapping[str, Sequence[float | None]],
    stem: Path,
    uncertified: Sequence[float] = (),
    ylabel: str = r"rate $\rho$",
    reference_curves: tuple[Sequence[float], Mapping[str, Sequence[float | None]]] | None = None,
) -> list[Path]:
    """Rate vs kappa, written as ``stem.png`` and ``stem.pdf`` (see :func:`rate_figure`)."""
    return save_figure(rate_figure(title, kappa, series, references, uncertified, ylabel,
                                   reference_curves), stem)


def rate_figure(
    title: str,
    kappa: Sequence[float],
    series: Mapping[str, Sequence[float | None]],
    references: Mapping[str, Sequence[float | None]],
    uncertified: Sequence[float] = (),
    ylabel: str = r"rate $\rho$",
    reference_curves: tuple[Sequence[float], Mapping[str, Sequence[float | None]]] | None = None,
) -> Any:
    """Rate vs kappa: series with markers (later series drawn under earlier ones, so the
    first, e.g. the designed rate, stays visible where it meets a bound), references
    dashed (smooth ``reference_curves`` = (fine kappa grid, values) when given, else at
    the data kappas). Kappas where a series has no value are marked along the bottom
    ("<series>: missing"; a series without any value gets only those marks, no legend
    line); ``uncertified`` kappas along the top, never as rho = 1 data. The legend lists
    exactly what is drawn."""
    fig, ax = new_figure()
    k = np.asarray(kappa, dtype=float)
    unc = np.isin(k, np.asarray(uncertified, dtype=float))
    for i, (label, vals) in enumerate(series.items()):
        _series(ax, k, _floats(vals), label, i, len(series), unc)
    ref_k, ref_vals = (k, references) if reference_curves is None else reference_curves
    for j, (label, vals) in enumerate(ref_vals.items(), start=len(series)):
        y = _floats(vals)
        if np.isfinite(y).any():
            ax.plot(np.asarray(ref_k, dtype=float), y, ls="--", lw=1.2, label=label, zorder=2,
                    color=color(j))
    if len(uncertified):
        ax.plot(uncertified, np.ones(len(uncertified)), ls="none", marker="x", color="red",
                ms=7, label="no certificate", clip_on=False)
    _kappa_axis(ax, k)
    ax.set_xlabel(r"condition number $\kappa = L/m$")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    finish(ax)  # legend "best": it also keeps clear of the bottom marks
    return fig


_MARKERS = "os^Dv<>"
_STYLES = [dict(ms=5, lw=1.8), dict(ms=7, lw=1.2, mfc="none"), dict(ms=4, lw=1.0)]


def _floats(vals: Sequence[float | None]) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in vals], dtype=float)


def _series(ax: Any, k: np.ndarray, y: np.ndarray, label: str, i: int, n: int,
            uncertified: np.ndarray) -> None:
    """One series (the i-th of n) and, in its colour, triangles on the bottom edge where
    it has no value (except where "no certificate" already marks the kappa)."""
    color_i = color(i)
    if np.isfinite(y).any():
        ax.plot(k, y, marker=_MARKERS[i % len(_MARKERS)], label=label, zorder=3 + n - i,
                color=color_i, **_STYLES[min(i, len(_STYLES) - 1)])
    missing = ~np.isfinite(y) & ~uncertified
    if missing.any():
        ax.plot(k[missing], np.zeros(missing.sum()), ls="none", marker="v", ms=7,
                color=color_i, label=f"{label}: missing", transform=ax.get_xaxis_transform(),
                clip_on=False, zorder=6)


def _kappa_axis(ax: Any, k: np.ndarray) -> None:
    """Log kappa axis over a decade or more (:func:`log_ticks`); over shorter spans a
    linear axis with a few plain ticks (a log axis would label its minor ticks and the
    labels overlap)."""
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    finite = k[np.isfinite(k) & (k > 0)]
    lo, hi = (finite.min(), finite.max()) if finite.size else (1.0, 10.0)
    if hi >= 10 * lo:
        ax.set_xscale("log")
        log_ticks(ax.xaxis, lo, hi)
        return
    ax.set_xscale("linear")
    ax.xaxis.set_major_locator(MaxNLocator(nbins=5, min_n_ticks=2))
    fmt = ScalarFormatter(useOffset=True, useMathText=True)
    fmt.set_powerlimits((-3, 4))
    ax.xaxis.set_major_formatter(fmt)


def plot_grid(
    title: str,
    names: Sequence[str],
    axes: Sequence[np.ndarray],
    rho: np.ndarray,
    stem: Path,
    value_point: Sequence[float] | None = None,
) -> list[Path]:
    """Certified rate over a 1-D or 2-D grid, as ``stem.png``/``.pdf`` (see
    :func:`grid_figure`)."""
    return save_figure(grid_figure(title, names, axes, rho, value_point), stem)


def grid_figure(
    title: str,
    names: Sequence[str],
    axes: Sequence[np.ndarray],
    rho: np.ndarray,
    value_point: Sequence[float] | None = None,
) -> Any:
    """Certified rate over a 1-D or 2-D grid. ``rho`` holds NaN where no certificate was
    found; those parameters are drawn as a hatched grey region (2-D: everything the
    certified contours do not cover, so no white band between the two; 1-D: shaded
    intervals), never as rho = 1. The grid minimum and the spec's own value are marked."""
    fig, ax = new_figure()
    finite = np.isfinite(rho)
    if len(names) == 1:
        _grid_1d(ax, axes[0], rho, finite, value_point)
        ax.set_xlabel(names[0])
        ax.set_ylabel(r"certified rate $\rho$")
    else:
        _grid_2d(fig, ax, axes, rho, finite, value_point)
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
    ax.set_title(title)
    finish(ax)
    if len(names) > 1:
        ax.grid(False)  # the contours carry the grid's information
    return fig


def _grid_1d(ax: Any, x: np.ndarray, rho: np.ndarray, finite: np.ndarray,
             value_point: Sequence[float] | None) -> None:
    ax.plot(x, np.where(finite, rho, np.nan), lw=1.6, marker=".", ms=3,
            label="certified rate")
    if (~finite).any():
        half = np.diff(x).min() / 2 if len(x) > 1 else 0.5
        first = True
        for xi in x[~finite]:  # shaded cells, never points at rho = 1
            ax.axvspan(xi - half, xi + half, color="0.85", hatch="//", lw=0,
                       label="no certificate" if first else None)
            first = False
        ax.set_xlim(x.min(), x.max())
    if finite.any():
        i = int(np.nanargmin(np.where(finite, rho, np.nan)))
        ax.plot(x[i], rho[i], "*", ms=12, color="red", label=f"grid minimum {rho[i]:.4f}")
    if value_point is not None:
        ax.axvline(value_point[0], ls=":", color="k", label="spec value")


def _grid_2d(fig: Any, ax: Any, axes: Sequence[np.ndarray], rho: np.ndarray,
             finite: np.ndarray, value_point: Sequence[float] | None) -> None:
    from matplotlib.patches import Rectangle

    X, Y = np.meshgrid(axes[0], axes[1], indexing="ij")
    Z = np.where(finite, rho, np.nan)
    x0, x1, y0, y1 = axes[0].min(), axes[0].max(), axes[1].min(), axes[1].max()
    if (~finite).any():  # the background is the uncertified region
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor="0.85", hatch="//",
                               edgecolor="0.6", lw=0, zorder=0, label="no certificate"))
    if finite.sum() >= 4:
        lo, hi = float(np.nanmin(Z)), float(np.nanmax(Z))
        levels = np.unique(np.round(np.linspace(lo, hi, 12), 4))
        if len(levels) >= 2:
            levels[0], levels[-1] = min(levels[0], lo), max(levels[-1], hi)
            cf = ax.contourf(X, Y, Z, levels=levels, cmap="viridis", zorder=1)
            cs = ax.contour(X, Y, Z, levels=levels, colors="k", linewidths=0.6, zorder=2)
            _label_contours(ax, cs, (x0, x1, y0, y1))
            fig.colorbar(cf, ax=ax, label=r"certified rate $\rho$")
        i = np.unravel_index(int(np.nanargmin(Z)), Z.shape)
        ax.plot(X[i], Y[i], "*", ms=14, color="red", label=f"grid minimum {Z[i]:.4f}",
                zorder=4)
    if value_point is not None:
        ax.plot(*value_point, "o", ms=8, mfc="white", mec="k", label="spec value", zorder=4)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)


def _label_contours(ax: Any, cs: Any, extent: tuple[float, float, float, float],
                    most: int = 6) -> None:
    """Label at most ``most`` contour levels (every other one, or sparser), each where it
    lies farthest from the labels placed so far and from the frame, so the labels spread
    over the plot instead of crowding where the contours bunch up."""
    x0, x1, y0, y1 = extent
    span = np.array([max(x1 - x0, 1e-300), max(y1 - y0, 1e-300)])
    lows = np.array([x0, y0])
    n = len(cs.levels)
    step = max(2, math.ceil(n / most))
    placed: list[np.ndarray] = []  # in units of the axes (0..1)
    levels, manual = [], []
    for i in range(step // 2, n, step):
        segs = [sg for sg in cs.allsegs[i] if len(sg)]
        if not segs:
            continue
        u = (np.vstack(segs) - lows) / span
        inside = np.all((u > 0.06) & (u < 0.94), axis=1)
        if not inside.any():
            continue
        u = u[inside]
        room = np.min(np.stack([u[:, 0], 1 - u[:, 0], u[:, 1], 1 - u[:, 1]]), axis=0)
        for q in placed:
            room = np.minimum(room, np.hypot(*(u - q).T))
        best = u[int(np.argmax(room))]
        placed.append(best)
        levels.append(cs.levels[i])
        manual.append(tuple(lows + best * span))
    if levels:
        ax.clabel(cs, levels=levels, manual=manual, fmt="%.3f", fontsize=7, inline=True)
