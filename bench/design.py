"""Design: time, proven lower bound and gap for single-κ designs, the Figure 1 and 2 sweeps,
and the paper's moment relaxation beside the dual-certificate bound (same run)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from tempfile import TemporaryDirectory

from sosalgo.design_search import design
from sosalgo.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"
FIG_SWEEP = "{from: 1.5, to: 1000, points: 20, scale: log}"

# (label, spec, free, gap, target seconds from the issue)
SINGLE = [
    ("gradient, h free", "gradient", ["h"], 1e-4, 1.0),
    ("Nesterov, beta free, h = 1/L", "nesterov", ["beta"], 1e-4, 5.0),
    ("Nesterov, h and beta free", "nesterov", ["h", "beta"], 1e-4, 30.0),
    ("three parameters h, beta, gamma", "three-parameter", ["h", "beta", "gamma"], 1e-3, 60.0),
]


def _row(label: str, spec_name: str, free: list[str], kappa: float, gap: float,
         target: float | None, **kw) -> None:
    spec = load_spec(SPECS / f"{spec_name}.yaml")
    t0 = time.perf_counter()
    res = design(spec, kappa, free=free, gap=gap, **kw)
    dt = time.perf_counter() - t0
    lb = "-" if res.lower_bound is None else f"{res.lower_bound:.8f}"
    g = "-" if res.gap is None else f"{res.gap:.1e}"
    rel = res.relaxation
    status = rel.get("status")
    tgt = "-" if target is None else f"{target:g}"
    print(f"| {label} | {kappa:g} | {res.method} | {status} | {lb} | {res.rho_certified:.8f} "
          f"| {g} | {dt:.2f} | {tgt} |", flush=True)


def _sweep(target: str, spec: str, free: str, limit: float) -> None:
    """A Makefile figure target's command, timed as a user runs it (fresh process)."""
    with TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "sosalgo.cli", "design", str(SPECS / f"{spec}.yaml"),
               "--free", free, "--kappa", FIG_SWEEP, "--time-limit", "30", "--out", out,
               "--quiet", "--json"]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        dt = time.perf_counter() - t0
        if proc.returncode != 0:
            print(f"| {target} | failed: {proc.stderr.strip()[:80]} |")
            return
        import json

        rows = json.loads(proc.stdout)["rows"]
        gaps = [r["gap"] for r in rows]
        bounded = sum(g is not None for g in gaps)
        worst = max((g for g in gaps if g is not None), default=float("nan"))
        print(f"| {target} | {len(rows)} | {bounded} | {worst:.1e} | {dt:.1f} | {limit:g} |",
              flush=True)


def _tight_row(kappa: float, target_rho: float, target_s: float) -> None:
    """Three-parameter design with the interpolation family vs the triple momentum method."""
    import numpy as np

    from sosalgo.pareto import tmm_parameters

    spec = load_spec(SPECS / "three-parameter.yaml")
    t0 = time.perf_counter()
    res = design(spec, kappa, free=["h", "beta", "gamma"], family="interpolation",
                 time_limit=600)
    dt = time.perf_counter() - t0
    tmm = tmm_parameters(kappa, kappa)
    dev = max(abs(res.theta[p] - tmm[p]) * (kappa if p == "h" else 1.0) for p in tmm)
    ok = "yes" if (res.rho_certified <= target_rho and dt <= target_s) else "no"
    print(f"| {kappa:g} | {res.rho_certified:.7f} | {1 - 1 / np.sqrt(kappa):.7f} | "
          f"{res.rho_certified - res.floor:.1e} | {dev:.1e} | {dt:.1f} | "
          f"<= {target_rho:g} in {target_s:g} s: {ok} |", flush=True)


def run(quick: bool = False) -> None:
    print("single-κ designs (wall time: search, certification and bound)")
    print("| problem | κ | method | bound status | lower bound | certified | gap | seconds "
          "| target s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, spec, free, gap, target in SINGLE:
        for kappa in ((10.0,) if quick else (10.0, 100.0)):
            _row(label, spec, free, kappa, gap, target)
    print("\nbaseline in the same run: the paper's moment relaxation (pmi, order 3) as bound")
    print("| problem | κ | method | bound status | lower bound | certified | gap | seconds "
          "| target s |")
    print("|---|---|---|---|---|---|---|---|---|")
    _row("gradient, h free", "gradient", ["h"], 10.0, 1e-4, None, method="moment")
    _row("Nesterov, beta free, h = 1/L", "nesterov", ["beta"], 10.0, 1e-4, None,
         method="moment")
    if not quick:
        _row("Nesterov, h free, beta = Nesterov's", "nesterov", ["h"], 4.0, 1e-4, None,
             method="moment", time_limit=60)
        _row("Nesterov, h free, beta = Nesterov's", "nesterov", ["h"], 4.0, 1e-4, None)
    print("\ntight design (interpolation family, lag n-1) of (h, beta, gamma)")
    print("| κ | certified ρ | 1 - 1/√κ | gap to floor | max |θ - θ_TMM| (hL, β, γ) | "
          "seconds | target |")
    print("|---|---|---|---|---|---|---|")
    _tight_row(10.0, 0.683800, 60.0)
    if not quick:
        _tight_row(100.0, 0.900050, 120.0)
    if quick:
        return
    print("\nFigure sweeps (20 κ from 1.5 to 1000, as `make fig1` / `make fig2` run them)")
    print("| target | κ points | with a bound | worst gap | seconds | target s |")
    print("|---|---|---|---|---|---|")
    _sweep("make fig1 (gradient, h)", "gradient", "h", 120)
    _sweep("make fig2 (Nesterov, beta)", "nesterov", "beta", 240)
    with TemporaryDirectory() as out:  # make fig4 with 2 workers
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "sosalgo.cli", "fig4", "--kappa", FIG_SWEEP,
                               "--workers", "2", "--out", out, "--quiet"],
                              capture_output=True, text=True, check=False)
        dt = time.perf_counter() - t0
        status = "ok" if proc.returncode == 0 else f"failed: {proc.stderr.strip()[:60]}"
        print(f"| make fig4 --workers 2 (20 κ, 4 sweeps) | 20 | {status} | - | {dt:.1f} | 900 |")
