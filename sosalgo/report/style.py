"""One style for every figure sosalgo draws: size, fonts, colours, grid, log-axis ticks.

A figure starts with :func:`new_figure` and ends with :func:`finish` (on each panel);
log axes are labelled by :func:`log_ticks`, as plain numbers (2, 5, 10, 0.2, 0.5),
never as mantissa-times-power labels. Nothing here changes matplotlib's global settings:
each figure gets the same sizes explicitly.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["FIGSIZE", "WIDE", "color", "finish", "log_ticks", "new_figure", "plain_tick",
           "pyplot"]

FIGSIZE = (6.4, 4.4)  # inches: one panel
WIDE = (12.0, 4.6)  # two panels side by side
TITLE_SIZE = 11
LABEL_SIZE = 10
TICK_SIZE = 9
LEGEND_SIZE = 8
GRID_ALPHA = 0.3


def color(i: int) -> str:
    """The i-th colour of the shared cycle (matplotlib's ten-colour palette)."""
    return f"C{i % 10}"


def pyplot() -> Any:
    """matplotlib.pyplot with the Agg backend, imported on first use (tables need none)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def new_figure(panels: int = 1) -> tuple[Any, Any]:
    """A figure of the shared size with ``panels`` axes side by side (one axes object for
    one panel, a tuple otherwise)."""
    return pyplot().subplots(1, panels, figsize=FIGSIZE if panels == 1 else WIDE)


def finish(ax: Any, legend: bool = True, **legend_options: Any) -> None:
    """The shared fonts and grid on ``ax``; its legend (``legend_options``: loc, ncol)."""
    ax.title.set_fontsize(TITLE_SIZE)
    ax.xaxis.label.set_fontsize(LABEL_SIZE)
    ax.yaxis.label.set_fontsize(LABEL_SIZE)
    ax.tick_params(axis="both", which="both", labelsize=TICK_SIZE)
    ax.grid(True, which="both", alpha=GRID_ALPHA)
    if legend and ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=LEGEND_SIZE, **({"loc": "best"} | legend_options))


def log_ticks(axis: Any, lo: float, hi: float) -> None:
    """Label a log axis (already log-scaled) as plain numbers: at 1, 2 and 5 times the
    powers of ten (2, 5, 10, 20, ...; 0.2, 0.5, 1), at every integer multiple over less
    than a decade (so that a short span still has labels), at the powers of ten only over
    more than four decades (the labels would crowd); other minor ticks stay unlabelled."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    decades = math.log10(hi / lo) if hi > 0 and lo > 0 else 1.0
    subs = (tuple(float(s) for s in range(1, 10)) if decades < 1
            else (1.0, 2.0, 5.0) if decades <= 4 else (1.0,))
    axis.set_major_locator(LogLocator(base=10.0, subs=subs, numticks=30))
    axis.set_major_formatter(FuncFormatter(plain_tick))
    axis.set_minor_locator(LogLocator(base=10.0, subs=np.arange(2, 10), numticks=30))
    axis.set_minor_formatter(NullFormatter())


def plain_tick(v: float, _pos: Any = None) -> str:
    """2, 50, 1000, 0.2 as plain numbers; very small or large values as powers of ten."""
    if v <= 0:
        return ""
    if 1e-3 <= v < 1e6:
        return f"{v:g}"
    exp = math.log10(v)
    return f"$10^{{{round(exp)}}}$" if abs(exp - round(exp)) < 1e-9 else f"{v:.0e}"
