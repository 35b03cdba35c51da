"""Composite figures that combine several runs (``sosalgo fig4``).

Figure 4: the three-parameter family (h, β, γ) designed with the interpolation family over
κ, beside the Theorem 1 design, Nesterov's tuning certified by both families and the floor
1 - 1/√κ; a second panel shows the designed parameters beside the triple momentum
method's formulas (ρ = 1 - 1/√κ, h = (1+ρ)/L, β = ρ²/(2-ρ), γ = ρ²/((1+ρ)(2-ρ))).
Every run goes through the resumable batch layer, so an interrupted ``fig4`` resumes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.batch.sweeps import (
    csv_row_to_json,
    design_csv_to_json,
    family_options,
    run_analysis_sweep,
    run_design_sweep,
)
from sosalgo.certificates import get_family
from sosalgo.report.style import color, finish, log_ticks, new_figure
from sosalgo.spec import spec_from_text

__all__ = ["fig4", "fig4_rows", "tmm_parameters"]


def spec_text_and_path(name: str) -> tuple[str, str]:
    """Text and location of a shipped example spec."""
    try:
        from sosalgo.resources import example_specs

        p: Any = example_specs()[name]
    except ImportError:  # a checkout without packaged examples: the repository's specs/
        p = Path(__file__).resolve().parent.parent / "specs" / f"{name}.yaml"
    return p.read_text(encoding="utf-8"), str(p)


def tmm_parameters(kappa: float, L: float) -> dict[str, float]:
    """The triple momentum method in the paper's family (h, β, γ) at condition κ."""
    r = 1 - 1 / np.sqrt(kappa)
    return {"h": (1 + r) / L, "beta": r**2 / (2 - r), "gamma": r**2 / ((1 + r) * (2 - r))}


def _design(name: str, family: str, kappas, out_dir: Path, gap: float, time_limit: float,
            workers, scheduler, restart: bool, progress: bool) -> list[dict[str, Any]]:
    text, path = spec_text_and_path(name)
    spec = spec_from_text(text, path)
    fam = get_family(family)
    suffix = "" if family == "theorem1" else f"-{family}"
    opts = {"free": list(spec.ranged), "scalarize": "pmi", "order": None, "gap": gap,
            "time_limit": time_limit, "method": "dual", "certificate": family_options(fam)}
    rows, fresh = run_design_sweep(spec, text, kappas, out_dir / f"{spec.name}-design{suffix}"
                                   ".csv", opts, workers=workers, scheduler=scheduler,
                                   restart=restart, progress=progress)
    return [fresh.get(float(r["kappa"])) or design_csv_to_json(spec, spec.ranged, r, fam)
            for r in rows]


def _analysis(name: str, family: str, kappas, out_dir: Path, workers, scheduler,
              restart: bool, progress: bool) -> list[dict[str, Any]]:
    text, path = spec_text_and_path(name)
    spec = spec_from_text(text, path)
    fam = get_family(family)
    suffix = "" if family == "theorem1" else f"-{family}"
    rows = run_analysis_sweep(spec, text, kappas, out_dir / f"{spec.name}-analysis{suffix}.csv",
                              1e-6, workers=workers, scheduler=scheduler, restart=restart,
                              progress=progress, family=fam)
    return [csv_row_to_json(spec, r, fam) for r in rows]


def fig4(out_dir: Path, kappas: Sequence[float], workers: int | None = None,
         scheduler: str | None = None, restart: bool = False, progress: bool = True,
         time_limit: float = 120.0) -> tuple[list[Path], dict[str, list]]:
    """Run (or resume) the four sweeps of Figure 4 and draw it. Returns (figures, data)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    kappas = sorted(float(k) for k in kappas)
    tight = _design("three-parameter", "interpolation", kappas, out_dir, 1e-3, time_limit,
                    workers, scheduler, restart, progress)
    t1 = _design("three-parameter", "theorem1", kappas, out_dir, 1e-3, time_limit,
                 workers, scheduler, restart, progress)
    nest = {fam: _analysis("nesterov", fam, kappas, out_dir, workers, scheduler, restart,
                           progress) for fam in ("theorem1", "interpolation")}
    data = {
        "kappa": kappas,
        "designed (interpolation)": [d["rho_certified"] for d in tight],
        "designed (Theorem 1)": [d["rho_certified"] for d in t1],
        "Nesterov's tuning (interpolation)": [r["rho"] for r in nest["interpolation"]],
        "Nesterov's tuning (Theorem 1)": [r["rho"] for r in nest["theorem1"]],
        "theta": [d["theta"] for d in tight],
    }
    return _draw(out_dir / "fig4-tight-design", data), data


def fig4_rows(data: dict[str, list]) -> list[dict[str, Any]]:
    """The printed table of Figure 4: one row per kappa, the four curves and the floor."""
    return [{"kappa": k, "designed (interpolation)": a, "designed (Theorem 1)": b,
             "Nesterov (interpolation)": c, "Nesterov (Theorem 1)": d,
             "1 - 1/sqrt(kappa)": 1 - 1 / math.sqrt(k)}
            for k, a, b, c, d in zip(data["kappa"], data["designed (interpolation)"],
                                     data["designed (Theorem 1)"],
                                     data["Nesterov's tuning (interpolation)"],
                                     data["Nesterov's tuning (Theorem 1)"], strict=True)]


def _draw(stem: Path, data: dict[str, list]) -> list[Path]:
    """Both panels, written as ``stem.png`` and ``stem.pdf``."""
    from sosalgo.report import save_figure

    k = np.asarray(data["kappa"], dtype=float)
    fine = np.geomspace(k.min(), k.max(), 400)
    fig, (ax, bx) = new_figure(panels=2)
    _draw_rates(ax, k, fine, data)
    _draw_parameters(bx, k, fine, data)
    fig.tight_layout()
    return save_figure(fig, stem)


def _draw_rates(ax: Any, k: np.ndarray, fine: np.ndarray, data: dict[str, list]) -> None:
    """Left panel: the four rate curves (a curve without values gets only its "missing"
    marks on the bottom edge), the floor and the quadratic rate."""
    styles = {"designed (interpolation)": dict(marker="o", lw=2.2, zorder=5),
              "designed (Theorem 1)": dict(marker="s", lw=1.4),
              "Nesterov's tuning (interpolation)": dict(marker="^", lw=1.2),
              "Nesterov's tuning (Theorem 1)": dict(marker="v", lw=1.2)}
    for i, (label, st) in enumerate(styles.items()):
        y = np.array([np.nan if v is None else v for v in data[label]], dtype=float)
        if np.isfinite(y).any():
            ax.plot(k, y, ms=4, label=label, color=color(i), **st)
        if (~np.isfinite(y)).any():
            ax.plot(k[~np.isfinite(y)], np.zeros((~np.isfinite(y)).sum()), ls="none",
                    marker="v", ms=7, color=color(i), label=f"{label}: missing",
                    transform=ax.get_xaxis_transform(), clip_on=False, zorder=6)
    ax.plot(fine, 1 - 1 / np.sqrt(fine), "k--", lw=1.2, label=r"$1 - 1/\sqrt{\kappa}$ (floor)")
    ax.plot(fine, (np.sqrt(fine) - 1) / (np.sqrt(fine) + 1), ls=":", color="grey", lw=1.2,
            label=r"$(\sqrt{\kappa}-1)/(\sqrt{\kappa}+1)$ (quadratics)")
    ax.set_xscale("log")
    log_ticks(ax.xaxis, float(k.min()), float(k.max()))
    ax.set_xlabel(r"condition number $\kappa = L/m$")
    ax.set_ylabel(r"rate $\rho$")
    ax.set_title("three-parameter family: designed rate")
    finish(ax)


def _draw_parameters(bx: Any, k: np.ndarray, fine: np.ndarray, data: dict[str, list]) -> None:
    """Right panel: designed h L, beta, gamma (m = 1 in the shipped spec, so L = kappa)
    beside the triple momentum method's formulas."""
    tmm = [tmm_parameters(x, x) for x in fine]
    colors = {"h": color(0), "beta": color(1), "gamma": color(2)}
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
    finish(bx, ncol=2)
