"""What ``sosalgo design`` shows: the verdict of each design, its table and its figure.

The command runs the design sweep (:mod:`sosalgo.batch.sweeps`) and prints; the documents
(the ``design --json`` form) are turned into tables, notes and figures here.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sosalgo.certificates import CertificateFamily
from sosalgo.report import format_table, plot_rates
from sosalgo.schema import printed_columns
from sosalgo.spec import Spec
from sosalgo.spec.references import reference_curves

__all__ = ["LEGEND", "design_figure", "design_legend", "design_table", "proven_bound",
           "sublinear_design_lines", "verdict", "verification_notes"]

LEGEND = "\n".join([
    "rho_certified: certified rate at the designed theta (with its certificate)",
    "lower_bound: proven lower bound, no theta in the box is certified below it",
    "rho_at_values: certified rate at the spec's own values",
    "floor: 1 - 1/sqrt(kappa), no first-order method is faster on F(m, L) (composite specs: "
    "only where",
    "  that is a theorem, see docs/commands/design.md; empty otherwise)"])


def design_legend(method: str) -> str:
    """The legend under the design table; the moment relaxation's bound is a floating-point
    SDP's value, not a proven lower bound."""
    if method != "moment":
        return LEGEND
    return LEGEND.replace(
        "lower_bound: proven lower bound, no theta in the box is certified below it",
        "lower_bound: the moment relaxation's value (floating point, not proven exactly)")


def tighter_family_note(spec: Spec, family: str, certificate: str | None) -> str | None:
    """One line when ``design`` took Theorem 1 by default (it alone proves a lower bound
    over the whole box) although the tighter interpolation family applies; None otherwise
    (a family asked for, named by the spec, or no tighter one)."""
    from sosalgo.certificates import default_family_name

    tight = default_family_name(spec, "analyze")
    if certificate is not None or spec.certificate_given or family == tight:
        return None
    return (f"note: the tighter {tight} family certifies a design at least as fast "
            f"(--certificate {tight}: every rate {family} certifies, often faster ones) but "
            "proves no box-wide lower bound, only the floor where that is a theorem")


def verdict(doc: dict[str, Any], gap: float) -> str:
    """What the numbers prove: optimal within the gap only when the gap proves it."""
    if doc.get("rho_certified") is None:
        return "no certified design"
    if proven_bound(doc) is None or doc.get("gap") is None:  # None, or 0: nothing proven
        return "no bound" + (" (time limit)" if doc.get("time_limited") else "")
    if doc.get("gap_met"):
        return f"optimal (gap <= {gap:g})"
    return f"gap {doc['gap']:.1e}" + (" (time limit)" if doc.get("time_limited") else "")


def design_table(docs: Sequence[dict[str, Any]], names: Sequence[str], gap: float,
                 method: str, details: bool = True) -> str:
    """One row per kappa: designed parameters, lower bound, certified rate, gap, verdict
    (and the relaxation's order and flatness for the moment method); the seconds only
    with ``details``."""
    table = []
    for d in docs:
        row = {"kappa": d["kappa"], "lower_bound": proven_bound(d) or "none proven",
               "rho_certified": d["rho_certified"], "gap": d["gap"],
               "verdict": verdict(d, gap), "rho_at_values": d["rho_at_values"],
               "floor": d.get("floor"), "seconds": d["seconds"]}
        if method == "moment":
            row.update(order=d["relaxation"].get("order"), flat=d["relaxation"].get("flat"))
        row.update({p: d["theta"].get(p) for p in names})
        table.append(row)
    cols = ["kappa", *names, "lower_bound", "rho_certified", "gap", "verdict",
            "rho_at_values", "floor"] + (["order", "flat"] if method == "moment" else []) + [
            "seconds"]
    return format_table(table, printed_columns(cols, details))


def verification_notes(docs: Sequence[dict[str, Any]]) -> list[str]:
    """One line per verified document: verdict, proven rate, simulation outcome."""
    lines = []
    for d in docs:
        v = d.get("verification")
        if v is not None:
            sim = v.get("simulation")
            note = "" if sim is None else (
                ", simulation skipped" if "skipped" in sim else
                ", simulation ok" if sim["ok"] else ", SIMULATION VIOLATION")
            proven = v.get("rho_proven_float")
            what = (f"rho proven {proven:.10g}" if proven is not None
                    else f"not proven: {v.get('reason')}")
            lines.append(f"  kappa {d['kappa']:g}: verified {v['verified']} ({what}{note})")
    return lines


def design_figure(spec: Spec, names: Sequence[str], rows: Sequence[dict[str, str]],
                  docs: Sequence[dict[str, Any]], stem: Path, fam: CertificateFamily,
                  how: str) -> list[Path]:
    """Designed rate, lower bound and spec-value rate vs kappa (figure of ``design``).

    A bound of 0 proves nothing and is drawn as missing; without any bound the figure
    has no bound curve and its title says "no lower bound" (``how`` names the method
    otherwise)."""
    refs = {name: [None if x[name] in ("", None) else float(x[name]) for x in rows]
            for name in spec.references}  # the CSV's reference columns
    bounds = [proven_bound(d) for d in docs]
    series = {"designed (certified)": [d["rho_certified"] for d in docs]}
    if any(b is not None for b in bounds):
        series["lower bound (proven)"] = bounds
    series["spec values (certified)"] = [d["rho_at_values"] for d in docs]
    bound = f"bound: {how}" if "lower bound (proven)" in series else "no lower bound"
    return plot_rates(
        f"{spec.name}: designed {', '.join(names)} ({fam.name}; {bound})",
        [d["kappa"] for d in docs], series, refs, stem,
        uncertified=[d["kappa"] for d in docs if d["rho_certified"] is None],
        reference_curves=reference_curves(spec, [d["kappa"] for d in docs]),
    )


def proven_bound(doc: dict[str, Any]) -> float | None:
    """The document's lower bound when it proves something (> 0), else None."""
    lb = doc.get("lower_bound")
    return lb if lb is not None and lb > 0 else None


def sublinear_design_lines(doc: dict[str, Any]) -> list[str]:
    """What ``sosalgo design`` prints for a sublinear design document."""
    row = doc["rows"][0]
    sim = row.get("simulation") or {}
    theta = ", ".join(f"{k} = {v:.7g}" for k, v in (row["theta"] or {}).items())
    head = (f"{doc['spec']}: design of {', '.join(row['free'])} minimizing the certified "
            "constant c in measure(x_k) <= c |x_0 - x*|^2 / k (no lower bound over the box)")
    best = ("no constant certified anywhere in the box" if row["constant"] is None else
            f"c = {row['constant']:.7g} at {theta} ({row['check_kind']}; simulation: "
            f"{'ok' if sim.get('ok') else 'VIOLATED'}, worst ratio "
            f"{sim.get('worst_ratio', float('nan')):.3g})")
    lines = [head, f"  {best}", f"  {row['evaluations']} evaluations, "
             f"{row['seconds']:.1f} s" + (" (time limit reached)" if row["timed_out"] else "")]
    ver = row.get("verification")
    if ver is not None:
        lines.append(f"  exact verification: {ver.get('verified')}"
                     + (f" (c <= {ver['constant_proven_float']:.7g})"
                        if ver.get("constant_proven_float") is not None else ""))
    return lines + [f"wrote {doc['csv']}"]
