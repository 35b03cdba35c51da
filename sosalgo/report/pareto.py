"""The figure of ``sosalgo pareto``: certified rate against certified noise sensitivity.

The front (every point proven on both axes, dominated points dropped) as a line, the
other points the searches returned in grey, the known tunings as labelled markers, the
robust momentum family as a curve and the floor 1 - 1/sqrt(kappa) as a dashed line.
Only certified values are drawn; a tuning with no certified rate or sensitivity is named
in the legend as "not certified".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sosalgo.report import save_figure
from sosalgo.report.legend import set_lines
from sosalgo.report.style import color, finish, log_ticks, new_figure

__all__ = ["noise_check_lines", "objective_lines", "pareto_figure", "pareto_lines",
           "pareto_plot"]

NOISE_LEGEND = ("noise: certified upper bound on gamma, the root of the long-run average of "
                "E|x_k - x*|^2/d per sigma^2 (the limsup when E|x_k - x*|^2 converges, e.g. "
                "on quadratics; exact: proven in rational arithmetic)")
RHO_LEGEND = ("rho: certified rate (exact: a float >= the rate proven in rational arithmetic "
              "from its certificate; float: that proof failed, the certificate is only checked "
              "in floating point and the point is left off the front)")
_MARKERS = {"gradient h=2/(m+L)": "s", "gradient h=1/L": "D", "Nesterov": "^",
            "heavy ball (Polyak)": "v", "triple momentum": "*"}


def _certified(p: Mapping[str, Any]) -> bool:
    return p.get("rho") is not None and p.get("noise") is not None


def pareto_figure(doc: Mapping[str, Any], stem: Path) -> list[Path]:
    """Draw a ``sosalgo pareto`` document (one kappa) into ``stem``.png/.pdf."""
    return save_figure(pareto_plot(doc), stem)


def pareto_plot(doc: Mapping[str, Any]) -> Any:
    """The figure of a ``sosalgo pareto`` document (one kappa), not yet saved."""
    fig, ax = new_figure()
    front = doc["front"]
    on_front = {p["index"] for p in front}
    rest = [p for p in doc["points"] if _certified(p) and p["index"] not in on_front]
    if rest:
        ax.plot([p["rho"] for p in rest], [p["noise"] for p in rest], "x", color="0.6",
                label="dominated search results")
    if front:
        ax.plot([p["rho"] for p in front], [p["noise"] for p in front], "o-", color=color(0),
                lw=2, ms=4, label=f"front over Θ ({doc['family']}, proven)", zorder=3)
    rm = [p for p in doc["tunings"] if p["kind"] == "robust momentum" and _certified(p)]
    if rm:
        ax.plot([p["rho"] for p in rm], [p["noise"] for p in rm], ".--", color=color(1),
                label="robust momentum family (certified)")
    for i, p in enumerate(t for t in doc["tunings"] if t["kind"] == "tuning"):
        marker = _MARKERS.get(p["name"], "P")
        if _certified(p):
            ax.plot([p["rho"]], [p["noise"]], marker, color=color(i + 2), ms=9,
                    label=p["name"], zorder=4)
        else:
            ax.plot([], [], marker, color=color(i + 2), label=f"{p['name']}: not certified")
    ax.axvline(doc["floor"], color="k", ls=":", lw=1, label="1 - 1/√κ (no method is faster)")
    ax.set_yscale("log")
    noise = [p["noise"] for p in [*doc["points"], *doc["tunings"]] if _certified(p)]
    if noise:
        log_ticks(ax.yaxis, min(noise), max(noise))
    ax.set_xlabel("certified rate ρ")
    ax.set_ylabel("certified noise sensitivity γ (upper bound)")
    ax.set_title(f"{doc['spec']}: speed vs robustness at κ = {doc['kappa']:g}")
    finish(ax, loc="lower left")
    return fig


def objective_lines(doc: Mapping[str, Any], details: bool = True) -> list[str]:
    """What ``sosalgo design --objective noise|--max-noise`` prints: one row per kappa
    (the noise certificate's lag and check and the seconds only with ``details``)."""
    from sosalgo.report import format_table
    from sosalgo.schema import printed_columns

    docs = doc["rows"]
    names = docs[0]["free"]
    d0 = docs[0]
    what = (f"least sensitive with certified rate <= {d0['max_rate']:g}"
            if d0["objective"] == "noise" else
            f"fastest with certified noise sensitivity <= {d0['max_noise']:g}")
    rows = [{"kappa": d["kappa"], **{p: d["theta"].get(p) for p in names},
             "rho_certified": d["rho_certified"], "rho_check": d.get("rho_check"),
             "noise": d["noise"],
             "noise_quadratic": d["noise_quadratic"], "noise_lag": d["noise_lag"],
             "noise_check": d["noise_check"], "status": d["objective_status"],
             "seconds": d["seconds"]} for d in docs]
    lines = [f"{doc['spec']}: {what}, over {', '.join(names)} ({d0['family']}; a search, "
             "no lower bound for this objective)",
             format_table(rows, printed_columns(
                 ["kappa", *names, "rho_certified", "rho_check", "noise", "noise_quadratic",
                  "noise_lag", "noise_check", "status", "seconds"], details))]
    lines += [f"  - {s}" for s in (d0.get("steps") or [])] if len(docs) == 1 else []
    lines += [RHO_LEGEND.replace("rho:", "rho_certified:"), NOISE_LEGEND,
              "status 'none found': no theta found meeting the cap (not a proof that none "
              "exists)"]
    lines.append("wrote " + ", ".join([doc["csv"], *doc["figures"]]))
    return lines


def pareto_lines(doc: Mapping[str, Any], details: bool = True) -> list[str]:
    """What ``sosalgo pareto`` prints for one kappa: the front, then the known tunings
    (the noise certificates' lags and checks only with ``details``)."""
    from sosalgo.report import format_table
    from sosalgo.schema import printed_columns

    names = doc["free"]
    front = [{"rho": p["rho"], "rho_check": p.get("rho_check"), "noise": p["noise"],
              "noise_quadratic": p["noise_quadratic"], "noise_lag": p["noise_lag"],
              "noise_check": p["noise_check"],
              **{n: p["theta"].get(n) for n in names}} for p in doc["front"]]
    tun = [{"name": p["name"], "rho": p["rho"], "rho_check": p.get("rho_check"),
            "noise": p["noise"], "noise_quadratic": p["noise_quadratic"],
            "noise_check": p["noise_check"]} for p in doc["tunings"]]
    cols = ["rho", "rho_check", "noise", "noise_quadratic", "noise_lag", "noise_check", *names]
    lost = len(doc["points"]) - len(doc["front"])
    return [f"{doc['spec']}: front of certified rate vs certified noise sensitivity at "
            f"kappa {doc['kappa']:g} over {', '.join(names)} ({doc['family']}); "
            f"{len(doc['front'])} points ({lost} dominated or uncertified dropped)",
            *set_lines(doc),
            format_table(front, printed_columns(cols, details)),
            "known tunings, in the form x+ = x + beta (x - x-) - h grad f(x + gamma (x - x-)):",
            format_table(tun, printed_columns(["name", "rho", "rho_check", "noise",
                                               "noise_quadratic", "noise_check"], details)),
            RHO_LEGEND, NOISE_LEGEND,
            "wrote " + ", ".join([doc["csv"], *doc["figures"]])]


def noise_check_lines(rows: Sequence[Mapping[str, Any]],
                      checks: Sequence[Mapping[str, Any] | None]) -> list[str]:
    """What ``sosalgo verify`` adds for the rows with a noise certificate: one line each,
    the exact proof's verdict and the proven bound (or why it failed)."""
    out = []
    for i, (r, c) in enumerate(zip(rows, checks, strict=True)):
        for k in ("noise", "noise_limsup"):  # the average bound, the limsup bound
            if c is None or f"{k}_verified" not in c:
                continue
            what = f"row {i}" + (f" ({r['name']})" if r.get("name") else "") + \
                f", kappa {r['kappa']:g}"
            if c[f"{k}_verified"] == "exact":
                out.append(f"{k} {what}: verified exact, gamma <= {c[f'{k}_proven']:.10g} "
                           f"(claimed {c[k]})")
            else:
                out.append(f"{k} {what}: NOT verified: {c[f'{k}_reason']}")
    return out
