"""Figure 4 of ``sosalgo fig4`` (its runs: :mod:`sosalgo.runs.fig4`).

Figure 4: the three-parameter family (h, β, γ) designed with the interpolation family over
κ, beside the Theorem 1 design, Nesterov's tuning certified by both families and the floor
1 - 1/√κ; a second panel shows the designed parameters beside the triple momentum
method's formulas (ρ = 1 - 1/√κ, h = (1+ρ)/L, β = ρ²/(2-ρ), γ = ρ²/((1+ρ)(2-ρ))).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.pareto import tmm_parameters

__all__ = ["fig4_figure", "fig4_rows"]


def fig4_rows(data: dict[str, list]) -> list[dict[str, Any]]:
    """The printed table of Figure 4: one row per kappa, the four curves and the floor."""
    return [{"kappa": k, "designed (interpolation)": a, "designed (Theorem 1)": b,
             "Nesterov (interpolation)": c, "Nesterov (Theorem 1)": d,
             "1 - 1/sqrt(kappa)": 1 - 1 / math.sqrt(k)}
            for k, a, b, c, d in zip(data["kappa"], data["designed (interpolation)"],
                                     data["designed (Theorem 1)"],
                                     data["Nesterov's tuning (interpolation)"],
                                     data["Nesterov's tuning (Theorem 1)"], strict=True)]


def fig4_figure(stem: Path, data: dict[str, list]) -> list[Path]:
    """Both panels, written as ``stem.png`` and ``stem.pdf``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sosalgo.report import save_figure

    k = np.asarray(data["kappa"], dtype=float)
    fine = np.geomspace(k.min(), k.max(), 400)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.6))
    _draw_rates(ax, k, fine, data)
    _draw_parameters(bx, k, fine, data)
    fig.tight_layout()
    return save_figure(fig, stem)


def _draw_rates(ax: Any, k: np.ndarray, fine: np.ndarray, data: dict[str, list]) -> None:
    """Left panel: the four rate curves (a curve without values gets only its "missing"
    marks on the bottom edge), the floor and the quadratic rate."""
    from sosalgo.report import log_ticks

    styles = {"designed (interpolation)": dict(marker="o", lw=2.2, zorder=5),
              "designed (Theorem 1)": dict(marker="s", lw=1.4),
              "Nesterov's tuning (interpolation)": dict(marker="^", lw=1.2),
              "Nesterov's tuning (Theorem 1)": dict(marker="v", lw=1.2)}
    for i, (label, st) in enumerate(styles.items()):
        y = np.array([np.nan if v is None else v for v in data[label]], dtype=float)
        if np.isfinite(y).any():
            ax.plot(k, y, ms=4, label=label, color=f"C{i}", **st)
        if (~np.isfinite(y)).any():
            ax.plot(k[~np.isfinite(y)], np.zeros((~np.isfinite(y)).sum()), ls="none",
                    marker="v", ms=7, color=f"C{i}", label=f"{label}: missing",
                    transform=ax.get_xaxis_transform(), clip_on=False, zorder=6)
    ax.plot(fine, 1 - 1 / np.sqrt(fine), "k--", lw=1.2, label=r"$1 - 1/\sqrt{\kappa}$ (floor)")
    ax.plot(fine, (np.sqrt(fine) - 1) / (np.sqrt(fine) + 1), ls=":", color="grey", lw=1.2,
            label=r"$(\sqrt{\kappa}-1)/(\sqrt{\kappa}+1)$ (quadratics)")
    ax.set_xscale("log")
    log_ticks(ax.xaxis, float(k.min()), float(k.max()))
    ax.set_xlabel(r"condition number $\kappa = L/m$")
    ax.set_ylabel(r"rate $\rho$")
    ax.set_title("three-parameter family: designed rate")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="best")


def _draw_parameters(bx: Any, k: np.ndarray, fine: np.ndarray, data: dict[str, list]) -> None:
    """Right panel: designed h L, beta, gamma (m = 1 in the shipped spec, so L = kappa)
    beside the triple momentum method's formulas."""
    from sosalgo.report import log_ticks

    tmm = [tmm_parameters(x, x) for x in fine]
    colors = {"h": "C0", "beta": "C1", "gamma": "C2"}
    names = {"h": r"$hL$", "beta": r"$\beta$", "gamma": r"$\gamma$"}
    for p, c in colors.items():
        scale = k if p == "h" else np.ones_like(k)
        fscale = fine if p == "h" else np.ones_like(fine)
        y = np.array([np.nan if (t is None or t.get(p) is None) else t[p]
                      for t in data["theta"]], dtype=float) * scale
        if np.isfinite(y).any():
            bx.plot(k, y, "o", color=c, ms=5, label=f"designed {names[p]}")
        bx.plot(fine, np.array([t[p] for t in tmm]) * fscale, "-", color=c, lw=1.0,
                label=f"triple momentum {names[p]}")
    bx.set_xscale("log")
    log_ticks(bx.xaxis, float(k.min()), float(k.max()))
    bx.set_xlabel(r"condition number $\kappa = L/m$")
    bx.set_title("designed parameters vs the triple momentum method")
    bx.grid(True, which="both", alpha=0.3)
    bx.legend(fontsize=8, ncol=2)
