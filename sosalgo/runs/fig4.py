"""The runs of ``sosalgo fig4`` (the figure itself: :mod:`sosalgo.report.fig4`).

Figure 4: the three-parameter family (h, β, γ) designed with the interpolation family over
κ, beside the Theorem 1 design, Nesterov's tuning certified by both families and the floor
1 - 1/√κ; a second panel shows the designed parameters beside the triple momentum
method's formulas (ρ = 1 - 1/√κ, h = (1+ρ)/L, β = ρ²/(2-ρ), γ = ρ²/((1+ρ)(2-ρ))).
Every run goes through the resumable batch layer, so an interrupted ``fig4`` resumes.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sosalgo.batch.sweeps import (
    csv_row_to_json,
    design_csv_to_json,
    family_options,
    run_analysis_sweep,
    run_design_sweep,
)
from sosalgo.certificates import get_family
from sosalgo.report.fig4 import fig4_figure
from sosalgo.spec import spec_from_text
from sosalgo.spec.loading import spec_text_and_path

__all__ = ["fig4"]


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
    from sosalgo.kernel.kappa import kappa_fields
    from sosalgo.runs import kappa_value

    out_dir.mkdir(parents=True, exist_ok=True)
    kappas = sorted((kappa_value(k) for k in kappas), key=float)  # as written
    tight = _design("three-parameter", "interpolation", kappas, out_dir, 1e-3, time_limit,
                    workers, scheduler, restart, progress)
    t1 = _design("three-parameter", "theorem1", kappas, out_dir, 1e-3, time_limit,
                 workers, scheduler, restart, progress)
    nest = {fam: _analysis("nesterov", fam, kappas, out_dir, workers, scheduler, restart,
                           progress) for fam in ("theorem1", "interpolation")}
    data = {
        "kappa": [float(k) for k in kappas],
        "kappa_exact": [kappa_fields(k)["kappa_exact"] for k in kappas],  # proven about
        "designed (interpolation)": [d["rho_certified"] for d in tight],
        "designed (Theorem 1)": [d["rho_certified"] for d in t1],
        "Nesterov's tuning (interpolation)": [r["rho"] for r in nest["interpolation"]],
        "Nesterov's tuning (Theorem 1)": [r["rho"] for r in nest["theorem1"]],
        "theta": [d["theta"] for d in tight],
    }
    return fig4_figure(out_dir / "fig4-tight-design", data), data
