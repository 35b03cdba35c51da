"""The printed table and the figures of ``sosalgo design --steps``: the designed schedule
(step k against its value) and the worst case against N (certified, lower bound, floor)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sosalgo.report.style import color, finish, new_figure, pyplot

__all__ = ["STEPS_LEGEND", "steps_design_figures", "steps_design_lines"]

STEPS_LEGEND = (
    "tau_certified: the worst case after N steps at the schedule, its dual certificate "
    "proven exactly; lower_bound: proven for every parameter value in the box (exact "
    "rational arithmetic); gap = tau_certified - lower_bound; floor: a theorem's bound for "
    "every method of the class (Drori 2017, m = 0), never mixed with the box bound")


def _values(schedule: dict[str, Any], steps: int) -> dict[str, list[float]]:
    """Each parameter's value per step (a constant repeated N times)."""
    return {k: (list(v) if isinstance(v, list) else [v] * steps)
            for k, v in schedule.items()}


def steps_design_lines(doc: dict[str, Any], details: bool = False) -> list[str]:
    """The printed result of ``design --steps``."""
    from sosalgo.report import format_table

    rows = doc["rows"]
    table = []
    for d in rows:
        sched = ", ".join(f"{k}={_show(v)}" for k, v in d["schedule"].items())
        table.append({"kappa": d["kappa"], "N": d["steps"], "schedule": sched,
                      "tau_certified": d["tau_certified"], "lower_bound": d["lower_bound"],
                      "gap_rel": d.get("gap_relative"), "floor": d["floor"],
                      "seconds": d["seconds"]})
    cols = ["kappa", "N", "schedule", "tau_certified", "lower_bound", "gap_rel", "floor"]
    if details:
        cols.append("seconds")
    if all(d["kappa"] is None for d in rows):
        cols.remove("kappa")
    lines = [f"{doc['spec']}: design of {', '.join(rows[0]['free'])} minimizing the worst "
             "case after N steps", format_table(table, cols), STEPS_LEGEND]
    for d in rows:
        if details or d.get("time_limited"):
            lines += [f"  N = {d['steps']}: {x}" for x in d.get("log", [])]
        elif d.get("lower_bound") is None:  # say why there is none
            lines += [f"  N = {d['steps']}: {x}" for x in d.get("log", [])
                      if x.startswith("no box-wide")]
        if d.get("time_limited"):
            lines.append(f"  N = {d['steps']}: stopped by --time-limit (the bounds are "
                         "proven as far as they got)")
    return lines + [f"wrote {f}" for f in [doc["csv"], *doc["figures"]]]


def _show(v: Any) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(f"{x:.6g}" for x in v) + "]"
    return f"{v:.8g}"


def steps_design_figures(name: str, docs: Sequence[dict[str, Any]], out: Path) -> list[Path]:
    """``<name>-design-steps-schedule`` (the schedule of each N, step k against its value)
    and, with two N or more, ``<name>-design-steps-worst-case`` (.png, .pdf)."""
    from sosalgo.report import save_figure

    files: list[Path] = []
    fig, ax = new_figure()
    for i, d in enumerate(docs):
        for j, (p, vals) in enumerate(_values(d["schedule"], d["steps"]).items()):
            label = f"N = {d['steps']}" + (f", {p}" if len(d["schedule"]) > 1 else "") + (
                "" if d["kappa"] is None else f", kappa = {d['kappa']:g}")
            ax.plot(range(len(vals)), vals, "o-", color=color(i), alpha=1 - 0.3 * j,
                    label=label)
    ax.set_xlabel("step k")
    ax.set_ylabel("value")
    ax.set_title(f"{name}: designed schedule")
    finish(ax)
    files += save_figure(fig, out / f"{name}-design-steps-schedule")
    pyplot().close(fig)
    files += _worst_case_figure(name, docs, out, save_figure)
    return files


def _worst_case_figure(name: str, docs: Sequence[dict[str, Any]], out: Path,
                       save: Any) -> list[Path]:
    kappas = sorted({d["kappa"] for d in docs}, key=lambda k: k or 0.0)
    if not any(sum(d["kappa"] == k for d in docs) >= 2 for k in kappas):
        return []
    fig, ax = new_figure()
    for i, k in enumerate(kappas):
        rows = sorted((d for d in docs if d["kappa"] == k), key=lambda d: d["steps"])
        tag = "" if k is None else f", kappa = {k:g}"
        ns = [d["steps"] for d in rows]
        for key, style, what in (("tau_certified", "o-", "certified"),
                                 ("lower_bound", "v--", "lower bound (box)"),
                                 ("floor", ":", "floor (Drori 2017)")):
            pts = [(n, d[key]) for n, d in zip(ns, rows, strict=True)
                   if d.get(key) is not None and d[key] > 0]
            if pts:
                ax.semilogy(*zip(*pts, strict=True), style,
                            color="k" if key == "floor" else color(i), label=what + tag)
    ax.set_xlabel("steps N")
    ax.set_ylabel("worst case f(x_N) - f* (|x_0 - x*| = 1)")
    ax.set_title(f"{name}: designed worst case against N")
    finish(ax)
    files = save(fig, out / f"{name}-design-steps-worst-case")
    pyplot().close(fig)
    return files
