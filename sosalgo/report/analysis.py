"""What ``sosalgo analyze`` shows: rate-vs-kappa figures, result tables, attached checks.

The command runs the sweeps (:mod:`sosalgo.batch.sweeps`) and prints; the figures and
tables of its rows (the JSON form of the CSV rows) are assembled here.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.certificates import CertificateFamily, spec_family
from sosalgo.model import ModelError, bind
from sosalgo.report import format_table, plot_rates
from sosalgo.report.legend import (
    noise_legend,
    rate_legend,
    rate_meaning,
    reference_header,
    set_lines,
    sublinear_meaning,
)
from sosalgo.report.style import finish, new_figure
from sosalgo.schema import ANALYSIS_COLUMNS, FAMILY_COLUMNS, printed_columns
from sosalgo.spec import Spec
from sosalgo.spec.references import reference_curves

__all__ = ["ANALYSIS_COLUMNS", "FAMILY_COLUMNS", "analysis_figure", "analysis_lines",
           "analysis_table", "attach_checks", "families_figure", "noise_table",
           "sublinear_figure"]

Run = tuple[CertificateFamily, Path, list[dict[str, Any]]]  # family, its CSV, its JSON rows


def analysis_figure(spec: Spec, rows: list[dict[str, Any]], stem: Path) -> list[Path]:
    """Certified rate vs kappa with the spec's references (Theorem 1, the default); no
    figure for fewer than two kappas (one point is no curve)."""
    kappas = [r["kappa"] for r in rows]
    if len(kappas) < 2:
        return []
    return plot_rates(
        f"{spec.name}: certified rate (Theorem 1)",
        kappas,
        {"certified rate": [r["rho"] for r in rows]} | bracket_series(rows),
        {name: [r["references"][name] for r in rows] for name in spec.references},
        stem,
        uncertified=[r["kappa"] for r in rows if not r["certified"]],
        reference_curves=reference_curves(spec, kappas),
    )


def bracket_series(rows: list[dict[str, Any]]) -> dict[str, list[float | None]]:
    """The witnessed lower bound rho_lower as a series (the bracket's lower end: 1 where
    a cycle was found); none when no row has one."""
    lows = [r.get("rho_lower") for r in rows]
    return {"witnessed lower bound": lows} if any(v is not None for v in lows) else {}


def verdict_lines(rows: list[dict[str, Any]]) -> list[str]:
    """One line per row: "kappa K: worst-case rate in [lower, certified]", "does not
    converge: cycle of length K", ... (:func:`sosalgo.witnesses.rows.verdict`)."""
    from sosalgo.witnesses.rows import verdict

    return [f"kappa {r['kappa']:g}: {verdict(r)}" for r in rows if r.get("rate_type") !=
            "sublinear"]


def families_figure(spec: Spec, runs: Sequence[Run], stem: Path) -> list[Path]:
    """Every family's certified rate vs kappa, with the spec's references,
    1 - 1/sqrt(kappa) and the rate on quadratics (unless a reference already draws them),
    all drawn as smooth curves on a fine kappa grid; no figure for fewer than two kappas,
    as for one family."""
    kap = [r["kappa"] for r in runs[0][2]]
    if len(kap) < 2:
        return []
    series = {f"certified rate ({f.label})": [r["rho"] for r in rows] for f, _, rows in runs}
    series |= bracket_series([{"rho_lower": max((r.get("rho_lower") for r in row if
                                                  r.get("rho_lower") is not None), default=None)}
                              for row in zip(*(rows for _, _, rows in runs), strict=True)])
    refs = {name: [r["references"][name] for r in runs[0][2]] for name in spec.references}
    fine = reference_curves(spec, kap)
    grid, curves = fine if fine is not None else (kap, dict(refs))
    for label, fn in _EXTRA_CURVES.items():  # unless the spec already draws the same curve
        vals = [fn(spec, k) for k in kap]
        if not any(all(v is not None and abs(v - w) < 1e-6 for v, w in
                       zip(ref, vals, strict=True)) for ref in refs.values()):
            refs[label] = vals
            curves[label] = [fn(spec, k) for k in grid]
    none = [k for i, k in enumerate(kap) if all(rows[i]["rho"] is None for _, _, rows in runs)]
    title = " vs ".join(f.label for f, _, _ in runs)
    return plot_rates(f"{spec.name}: certified rate ({title})", kap, series, refs, stem,
                      uncertified=none, reference_curves=(grid, curves))


def _quadratic_bound(spec: Spec, kappa: float) -> float | None:
    from sosalgo.analysis import quadratic_rate

    try:
        return quadratic_rate(bind(spec, kappa))
    except (ModelError, ValueError, ArithmeticError):
        return None


_EXTRA_CURVES = {  # drawn beside the spec's references when comparing families
    "1 - 1/sqrt(kappa)": lambda spec, k: 1 - k ** -0.5,
    "quadratic bound max_q rho(A + qBC)": _quadratic_bound,
}


def attach_checks(spec: Spec, rows: list[dict[str, Any]], out_dir: Path,
                  family: CertificateFamily | None = None) -> None:
    """Verify every row (exact proof and simulation, :mod:`sosalgo.proofs.results`) and
    store the check in ``verification`` and its verdict in ``verified``."""
    from sosalgo.proofs.results import verify_document_rows

    checks = verify_document_rows(spec, rows, out_dir, family=family)
    for r, v in zip(rows, checks, strict=True):
        r["verification"] = v
        r["verified"] = None if v is None else v["verified"]


def attach_constant_checks(spec: Spec, rows: list[dict[str, Any]], out_dir: Path) -> None:
    """Verify every row of a sublinear spec (the exact proof of
    :mod:`sosalgo.certificates.exact_sublinear`; the simulation is the row's own) and store
    the check in ``verification`` and its verdict in ``verified``."""
    from sosalgo.proofs.results import verify_sublinear_rows

    checks = verify_sublinear_rows(spec, rows, out_dir, simulate=False,
                                   family=spec_family(spec))
    for r, v in zip(rows, checks, strict=True):
        if v is not None:
            v["simulation"] = r["simulation"]
        r["verification"] = v
        r["verified"] = None if v is None else v["verified"]


def analysis_table(spec: Spec, rows: list[dict[str, Any]], columns: list[str],
                   details: bool = True) -> str:
    """The printed table of analysis rows: ``columns`` and the spec's references, headed
    "reference: NAME" (a sublinear spec's rows: L, rate_type, constant, ...); without
    ``details`` the solver's internals are left out (:func:`sosalgo.schema.printed_columns`)."""
    own = spec_family(spec)  # a family with its own printed columns (m: 0: a constant)
    if own is not None:
        columns = own.printed_columns(columns)
    columns = printed_columns(columns, details)
    pep_only = set(spec.pep.get("references", ()))  # empty here (pep's question's values)
    refs = [n for n in spec.references if n not in pep_only]
    return format_table([{**r, **r["references"]} for r in rows], columns + refs,
                        columns + [reference_header(n) for n in refs])


def noise_table(rows: list[dict[str, Any]], details: bool) -> str:
    """The printed table of ``analyze --noise``: one row per kappa and family."""
    columns = ["kappa"] + (["family"] if len({r.get("family") for r in rows}) > 1 else []) + [
        "noise", "noise_quadratic", "noise_limsup", "noise_lag", "noise_check",
        "noise_limsup_rho"]
    return format_table(rows, printed_columns(columns, details))


UNITS_NOTE = "f/L in F(m/L, 1): the rate is scale-invariant; the certificate file says so"


def analysis_lines(doc: dict[str, Any], details: bool = False, verified: bool = False,
                   noise: bool = False) -> list[str]:
    """What ``sosalgo analyze`` prints (without ``--json``): per family its name, table
    and verdicts; what rho (or c) bounds, the legend, the noise table; the files."""
    from sosalgo.certificates import FAMILIES
    from sosalgo.spec import spec_from_text

    spec = spec_from_text(doc["spec_text"], doc["source"])
    rows = doc["rows"]
    out = [f"{spec.name}: {spec.description}".rstrip(": ")]
    out += set_lines(doc)
    columns = ["verified"] if verified else []
    groups = ([(name, [r for r in rows if r["family"] == name]) for name in doc["csvs"]]
              if "csvs" in doc else [(rows[0].get("family", "") if rows else "", rows)])
    for name, mine in groups:
        fam = FAMILIES.get(name)
        if fam is not None:
            out.append(f"certificate family: {fam.description}")
        base = ANALYSIS_COLUMNS if "csvs" not in doc else FAMILY_COLUMNS
        out.append(analysis_table(spec, mine, base + columns, details))
        out += verdict_lines(mine)
        out += [f"kappa {r['kappa']:g}: proven in units where L = 1 ({UNITS_NOTE})"
                for r in mine if (r.get("verification") or {}).get("units")]
    if spec_family(spec) is not None:  # what c bounds (no rate, no kappa)
        out.append(sublinear_meaning(spec))
    else:
        for name, mine in groups:
            out += rate_meaning(spec, name or None, [r.get("lag") for r in mine],
                                named=len(groups) > 1)
        out += rate_legend(rows, list(spec.references))
    if noise and rows:
        out += [noise_table(rows, details), *noise_legend(details)]
    csvs = list(doc.get("csvs", {"": doc["csv"]}).values())
    out.append("wrote " + ", ".join(csvs + doc["figures"]))
    return out


def sublinear_figure(spec: Spec, row: dict[str, Any], stem: Path, steps: int = 50) -> list[Path]:
    """The certified bound c/k on measure(x_k) / |x_0 - x*|^2 against k (log-log), with
    each reference constant r drawn as r/k; none without a certified constant."""
    from sosalgo.report import pyplot, save_figure

    if row.get("constant") is None:
        return []
    plt = pyplot()
    k = np.arange(1, steps + 1)
    fig, ax = new_figure()
    ax.loglog(k, row["constant"] / k, "o-", ms=3, label=f"certified c/k, c = {row['constant']:.6g}")
    for name, val in row.get("references", {}).items():
        if val is not None:
            ax.loglog(k, val / k, "--", label=f"{name}: {val:.6g}/k")
    ax.set_xlabel("k")
    ax.set_ylabel("bound on measure(x_k) / |x_0 - x*|^2")
    ax.set_title(f"{spec.name}: sublinear bound (L = {spec.L:g})")
    finish(ax)
    try:
        return save_figure(fig, stem)
    finally:
        plt.close(fig)
