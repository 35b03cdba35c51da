"""Design time, lower bound and gap (kappa = 10): the gradient method and Nesterov-beta with
default settings, then 'pmi' beside 'minors' at equal relaxation order."""

from __future__ import annotations

import time
from pathlib import Path

from sosalgo.design import design
from sosalgo.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"


def _row(label: str, spec_name: str, free: list[str], **kw) -> None:
    spec = load_spec(SPECS / f"{spec_name}.yaml")
    t0 = time.perf_counter()
    res = design(spec, 10.0, free=free, **kw)
    dt = time.perf_counter() - t0
    lb = "-" if res.lower_bound is None else f"{res.lower_bound:.8f}"
    gap = "-" if res.gap is None else f"{res.gap:.1e}"
    rel = res.relaxation
    print(f"| {label} | {rel.get('scalarize')} | {rel.get('order')} | {rel.get('status')} | "
          f"{lb} | {res.rho_certified:.8f} | {gap} | {dt:.2f} |", flush=True)


def run(quick: bool = False) -> None:
    print("design at kappa = 10 (wall time includes relaxation, extraction, certification)")
    print("| problem | scalarize | order | relaxation status | lower bound | certified | gap "
          "| seconds |")
    print("|---|---|---|---|---|---|---|---|")
    _row("gradient, h free (default settings)", "gradient", ["h"])
    _row("Nesterov, beta free, h = 1/L (default settings)", "nesterov", ["beta"])
    _row("gradient, h free", "gradient", ["h"], scalarize="pmi", order=4)
    if not quick:
        _row("gradient, h free", "gradient", ["h"], scalarize="minors", order=4, time_limit=30)
    print("Nesterov-beta with 'minors': its 3x3 determinant has degree 12, so the smallest "
          "order is 6 (moment matrix of side C(12,6) = 924 in 6 variables): not run.")
