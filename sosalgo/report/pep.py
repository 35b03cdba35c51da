"""The figures of ``sosalgo pep``: tau_k against k (with C rho^(2k) when a rate is
certified at that kappa), and a one-dimensional worst case beside its functions."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sosalgo.spec import Spec

__all__ = ["pep_figure", "rate_curve"]


def pep_figure(spec: Spec, docs: Sequence[dict[str, Any]], out: Path,
               rates: Mapping[float | None, float | None]) -> list[str]:
    """``<name>-pep[-k<kappa>]`` (.png, .pdf) per kappa with two steps or more; a 1-D
    witness of the last step as ``<name>-pep-N<N>-witness`` beside it. ``rates``: the
    rate certified at each kappa (None: none), drawn as C rho^(2k)."""
    from sosalgo.report import pyplot, save_figure

    plt = pyplot()
    files: list[str] = []
    for kappa in sorted({d["kappa"] for d in docs}, key=lambda k: k or 0.0):
        rows = sorted((d for d in docs if d["kappa"] == kappa), key=lambda d: d["steps"])
        tag = "" if kappa is None else f"-k{kappa:g}"
        if len(rows) >= 2:
            fig, ax = plt.subplots(figsize=(5.5, 3.8))
            ks = [d["steps"] for d in rows]
            taus = [d["tau"] for d in rows]
            ax.semilogy(ks, taus, "o-", label=r"$\tau_k$ (PEP)")
            rho = rates.get(kappa)
            if rho is not None and 0 < rho < 1:
                C, curve = rate_curve(list(zip(ks, taus, strict=True)), rho)
                ax.semilogy(ks, curve, "--", label=rf"$C\rho^{{2k}}$, $\rho$ = {rho:.4g} "
                                                   f"(certified), C = {C:.3g}")
            ax.set_xlabel("steps k")
            ax.set_ylabel(f"{rows[0]['measure']} / {rows[0]['initial']}")
            ax.set_title(f"{spec.name}: worst case" + ("" if kappa is None
                                                       else f", kappa = {kappa:g}"))
            ax.legend()
            files += [str(p) for p in save_figure(fig, out / f"{spec.name}-pep{tag}")]
        w = rows[-1].get("witness")
        if w and w.get("interpolant"):
            files += [str(p) for p in _witness_figure(plt, save_figure, w, out /
                      f"{spec.name}-pep{tag}-N{rows[-1]['steps']}-witness")]
    return files


def _witness_figure(plt: Any, save: Any, w: dict[str, Any], stem: Path) -> list[Path]:
    """Each function (tilted, minimal at x* = 0) with the trajectory's points on it."""
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for name, f in w["interpolant"].items():
        ax.plot(f["x"], f["h"], label=f"{name} (tilted, interpolating)")
        xs = [p[0] for p in f["points"]]
        ax.plot(xs, [p[1] for p in f["points"]], "o", ms=4)
    its = [x[0] for x in w["iterates"]]
    ax.plot(its, [0.0] * len(its), "k|", ms=12, label="iterates $x_k$")
    for k, x in enumerate(its):
        ax.annotate(str(k), (x, 0.0), textcoords="offset points", xytext=(0, 8), fontsize=7)
    ax.set_xlabel("x")
    ax.set_title(f"worst case after N = {w['steps']} steps (1-D witness)")
    ax.legend(fontsize=8)
    return save(fig, stem)


def rate_curve(taus: list[tuple[int, float]], rho: float) -> tuple[float, list[float]]:
    """C rho^(2k) with C the smallest constant that puts the curve above every tau_k."""
    finite = [(k, t) for k, t in taus if t is not None and math.isfinite(t)]
    C = max((t / rho ** (2 * k) for k, t in finite), default=0.0)
    return C, [C * rho ** (2 * k) for k, _ in taus]
