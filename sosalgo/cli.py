"""Command-line interface: a thin layer over the Python API.

Each command parses its options, calls its twin in the API (:mod:`sosalgo.runs`,
:mod:`sosalgo.documents`, :mod:`sosalgo.api`; every check lives there) and prints.
Errors are one line on stderr naming the file and field (:mod:`sosalgo.cli_errors`).
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Callable
from typing import Any

import click

from sosalgo import __version__
from sosalgo.cli_errors import INTERRUPTED, OneLineErrors, handle_errors, on_sigint, on_sigterm
from sosalgo.errors import InputError, VerificationError

__all__ = ["main", "cli"]


def _kappas(values: tuple[str, ...]) -> list[float] | None:
    """The --kappa options (numbers, lists or ranges); None when none was given."""
    from sosalgo.inputs import kappa_option

    return [k for v in values for k in kappa_option(v)] or None


CERTIFICATE_DEFAULTS = {  # what each command uses without --certificate (and the spec's
    # certificate: field): sosalgo.certificates.default_family_name
    "tightest": "default: the tightest that applies, interpolation",
    "design": ("default: theorem1, the family with a box-wide lower bound; the tightest, "
               "interpolation, for composite specs and with --objective noise or --max-noise"),
    "declared": "default: the spec's certificate: field, else theorem1 (interpolation for "
                "composite specs)",
    "verify": "for rows that name none; default: theorem1, the family of rows written "
              "before rows named their family",
}


def certificate_options(fn: Callable[..., Any] | None = None, default: str = "declared",
                        several: bool = False) -> Any:
    """--certificate NAME[,NAME...] and --lag L (the interpolation family's lag);
    ``default`` names the command's default (:data:`CERTIFICATE_DEFAULTS`)."""
    def add(fn: Callable[..., Any]) -> Callable[..., Any]:
        fn = click.option("--lag", type=int, default=None,
                          help="Lag of the interpolation family, 0..8 (default: analyze "
                               "keeps the best of the lags it tries; else states - 1).")(fn)
        return click.option(
            "--certificate", "certificate", default=None, metavar="FAMILY",
            help=f"Certificate family: theorem1 or interpolation "
                 f"({CERTIFICATE_DEFAULTS[default]})"
                 + ("; comma-separated to compare several." if several else "."))(fn)
    return add if fn is None else add(fn)


def batch_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """The options every batch command shares: --json, --workers, --scheduler, --restart,
    --quiet, --max-memory."""
    options = [
        click.option("--json", "as_json", is_flag=True,
                     help="Print one JSON document on stdout."),
        click.option("--workers", type=click.IntRange(min=1), default=None,
                     help="Local worker processes (default: all cores; short runs stay "
                          "serial)."),
        click.option("--scheduler", default=None, metavar="ADDRESS",
                     help="Run on an existing Dask distributed scheduler, e.g. "
                          "tcp://host:8786."),
        click.option("--restart", is_flag=True,
                     help="Replace the results in the output file instead of resuming them "
                          "(results of other settings are kept aside anyway)."),
        click.option("--quiet", is_flag=True, help="No progress bar."),
        click.option("--max-memory", "max_memory", default=None, metavar="SIZE",
                     help="Memory budget of the run, e.g. 8G or 512M (default: half the "
                          "machine's memory). A run estimated above it is refused; workers "
                          "are capped to fit it."),
    ]
    for opt in reversed(options):
        fn = opt(fn)
    return fn


def set_option(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--set NAME=EXPR (repeatable): fix a parameter of the spec for this run."""
    return click.option(
        "--set", "overrides", multiple=True, metavar="NAME=EXPR",
        help="Fix a parameter of the spec, e.g. --set h=1/L (repeatable; an expression of "
             "m, L, kappa and the other parameters, parsed like the spec's); "
             "--set h.range=[0, 7/L] replaces the range a design searches instead. The "
             "result records it in 'set'; verify applies it again.")(fn)


def details_option(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--details: the solver's internals in the printed table (always in CSV/JSON)."""
    return click.option(
        "--details", is_flag=True,
        help="Also print the solver's internals (lambda, eigenvalue margins, solves, "
             "seconds, ...); the CSV and --json always hold them.")(fn)


def _overrides(values: tuple[str, ...]) -> dict[str, str]:
    from sosalgo.spec.overrides import parse_set_options

    return parse_set_options(values)


def _exit_if_unverified(checks: list[Any], what: str = "some certificate",
                        doc: dict[str, Any] | None = None) -> None:
    """Exit code 3 when some certificate failed its check, or (``doc`` of a run with
    ``--verify``) when the claim ledger found a claim contradicted or unsupported, named
    in the one line (as ``sosalgo verify`` does)."""
    if all(c is None for c in checks) and not (doc or {}).get("unbacked"):
        return  # nothing was verified (no --verify): nothing to import or report
    from sosalgo.proofs.results import check_failed

    if any(check_failed(c) for c in checks):
        raise VerificationError(f"{what} failed verification (exit code 3)")
    if doc is not None and doc.get("unbacked"):
        from sosalgo.report.checks import entry_text

        bad = doc["unbacked"]
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise VerificationError(f"claim {bad[0]['status']}: {entry_text(bad[0])}{more} "
                                "(exit code 3)")


def _claims_line(doc: dict[str, Any]) -> None:
    """With ``--verify``: the claim ledger's count per status (as ``sosalgo verify``)."""
    if "claims" in doc:
        click.echo("claims: " + ", ".join(f"{v} {k}" for k, v in doc["claims"].items()))


@click.group(cls=OneLineErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(version=__version__, prog_name="sosalgo")
def cli() -> None:
    """Certify and design first-order methods for L-smooth, m-strongly convex functions."""


# --------------------------------------------------------------------------- analyze
@cli.command()
@click.argument("spec_path", metavar="SPEC", type=click.Path(dir_okay=False))
@click.option("--kappa", "kappa", multiple=True, metavar="K",
              help="Condition number(s) L/m; repeat for several. Default: the spec's list.")
@click.option("--tol", default=1e-6, show_default=True, type=float,
              help="Bisection tolerance on rho.")
@click.option("--out", default="outputs", show_default=True, metavar="DIR",
              help="Directory for <name>-analysis.csv and <name>-rate.png/.pdf (two kappas "
                   "or more; -rate-<family> for a family other than the default).")
@batch_options
@click.option("--no-plot", is_flag=True, help="Skip the figure.")
@click.option("--verify", "verify_", is_flag=True,
              help="Prove each certificate in exact arithmetic and simulate it.")
@click.option("--noise", is_flag=True,
              help="Add the certified sensitivity to gradient noise (noise, noise_quadratic, "
                   "noise_lag; noise_limsup, noise_limsup_rho: the bound on the limsup).")
@click.option("--brackets", type=click.Choice(["quadratic", "self-similar", "none"]),
              default="quadratic", show_default=True,
              help="Witnessed lower bound rho_lower beside the certified rate: the slowest "
                   "quadratic mode, or also a self-similar trajectory (slower to search).")
@click.option("--cycle-seconds", type=click.FloatRange(0, 600), default=5.0,
              show_default=True,
              help="Time per uncertified kappa for the search of a cycle (0: no search).")
@certificate_options(default="tightest", several=True)
@set_option
@details_option
@handle_errors
def analyze(spec_path: str, kappa: tuple[str, ...], tol: float, out: str, as_json: bool,
            workers: int | None, scheduler: str | None, restart: bool, quiet: bool,
            max_memory: str | None, no_plot: bool, verify_: bool, noise: bool, brackets: str,
            cycle_seconds: float, certificate: str | None, lag: int | None,
            overrides: tuple[str, ...], details: bool) -> None:
    """Best rate certified at each kappa, with its certificate; by default by the
    tightest certificate family that applies (interpolation; --certificate theorem1 for
    the paper's Theorem 1). Python: sosalgo.analyze_run (files) or sosalgo.analyze."""
    from sosalgo.report import analysis as rep
    from sosalgo.runs import analyze_run, analyzed_for_every_n

    if analyzed_for_every_n(spec_path, _overrides(overrides)):  # one bound for every N
        if kappa or noise:
            from sosalgo.spec.types import VARIES

            raise InputError(f"{'--kappa' if kappa else '--noise'}: the bound for every N "
                             "is on smooth convex f (m: 0), without kappa or noise; "
                             f"{spec_path} " + VARIES.format(source=spec_path))
        _analyze_all_k(spec_path, out, as_json, _overrides(overrides), verify_)
        return
    doc = analyze_run(spec_path, _kappas(kappa), out, tol, certificate, {"lag": lag},
                      workers, scheduler, restart, not quiet, not no_plot, verify_,
                      noise=noise, brackets=brackets, cycle_seconds=cycle_seconds,
                      max_memory=max_memory, overrides=_overrides(overrides))
    rows = doc["rows"]
    if as_json:
        click.echo(json.dumps(doc, indent=2))
    else:
        click.echo("\n".join(rep.analysis_lines(doc, details, verify_, noise)))
        for r in rows:
            if r.get("warning"):
                click.echo(f"warning at kappa {r['kappa']:g}: {r['warning']}", err=True)
        _claims_line(doc)
    _exit_if_unverified([r.get("verification") for r in rows], doc=doc)


def _analyze_all_k(spec_path: str, out: str, as_json: bool,
                   overrides: dict[str, str] | None, verify_: bool) -> None:
    """``analyze`` of a spec whose matrices are closed forms in k (docs/all-k.md): the
    bound is proven exactly by the run itself; with ``--verify`` an unproven one exits 3."""
    from sosalgo.runs.allk import allk_lines, allk_run

    doc = allk_run(spec_path, out, overrides)
    click.echo(json.dumps(doc, indent=2) if as_json else "\n".join(allk_lines(doc)))
    if verify_ and not doc["certified"]:
        raise VerificationError(f"{spec_path}: no bound for every N proven (exit code 3)")


# --------------------------------------------------------------------------- design
@cli.command()
@click.argument("spec_path", metavar="SPEC", type=click.Path(dir_okay=False))
@click.option("--kappa", "kappa", multiple=True, metavar="K",
              help="Condition number(s); repeat or give a range. Default: the spec's list.")
@click.option("--free", default=None, metavar="NAMES",
              help="Comma-separated parameters to design (default: those with a range).")
@click.option("--scalarize", type=click.Choice(["pmi", "minors"]), default="pmi",
              show_default=True, help="Matrix inequality kept whole (pmi) or as minors.")
@click.option("--order", type=click.IntRange(min=1), default=None,
              help="Relaxation order (default: 3 for pmi, the minimum for minors).")
@click.option("--gap", default=None, type=float,
              help="Target gap between certified rate and lower bound  [default: 1e-4; "
                   "with --steps 1e-3, relative]")
@click.option("--time-limit", default=120.0, show_default=True, type=float,
              help="Wall-clock seconds per kappa (all phases); the best proven results "
                   "so far are returned when it runs out.")
@click.option("--steps", default=None, metavar="N|a..b",
              help="Minimize the worst case after N steps (or each N of a..b) over the "
                   "box: schedule, tau_certified, lower_bound, gap, floor (docs/design.md).")
@click.option("--method", type=click.Choice(["dual", "moment"]), default="dual",
              show_default=True,
              help="Lower bound by box-wide dual certificates (dual) or by the paper's "
                   "moment relaxation (moment; uses --scalarize and --order).")
@click.option("--out", default="outputs", show_default=True, metavar="DIR")
@batch_options
@click.option("--verify", "verify_", is_flag=True,
              help="Prove each certificate in exact arithmetic and simulate it.")
@click.option("--objective", type=click.Choice(["rate", "noise"]), default="rate",
              show_default=True,
              help="Minimize the certified rate, or the certified noise sensitivity "
                   "(needs --max-rate).")
@click.option("--max-rate", type=float, default=None, metavar="R",
              help="With --objective noise: the certified rate must be <= R.")
@click.option("--max-noise", type=float, default=None, metavar="G",
              help="With --objective rate: the certified noise sensitivity must be <= G.")
@certificate_options(default="design")
@set_option
@details_option
@handle_errors
def design(spec_path: str, kappa: tuple[str, ...], free: str | None, scalarize: str,
           order: int | None, gap: float | None, time_limit: float, steps: str | None,
           method: str, out: str,
           as_json: bool, workers: int | None, scheduler: str | None, restart: bool,
           quiet: bool, max_memory: str | None, verify_: bool, objective: str,
           max_rate: float | None,
           max_noise: float | None, certificate: str | None, lag: int | None,
           overrides: tuple[str, ...], details: bool) -> None:
    """Design parameters: certified design, proven lower bound, gap between them.
    Python: sosalgo.design_run (files) or sosalgo.design (results); with --steps
    sosalgo.steps_design_run."""
    from sosalgo.report import design as rep
    from sosalgo.runs import design_run

    if steps is not None:
        mixed = [o for o, on in (("--objective noise", objective != "rate"),
                                 ("--max-rate", max_rate is not None),
                                 ("--max-noise", max_noise is not None),
                                 ("--method moment", method != "dual"),
                                 ("--certificate", certificate is not None)) if on]
        if mixed:
            raise InputError(f"--steps: designs the N-step worst case; not with {mixed[0]}")
        _design_steps(spec_path, kappa, free, gap, time_limit, steps, out, as_json, workers,
                      scheduler, restart, quiet, verify_, overrides, details)
        return
    gap = 1e-4 if gap is None else gap
    doc = design_run(spec_path, _kappas(kappa), out, free, scalarize, order, gap, time_limit,
                     method, certificate, {"lag": lag}, workers, scheduler, restart,
                     not quiet, verify_, progress_steps=not quiet and not as_json,
                     objective=objective, max_rate=max_rate, max_noise=max_noise,
                     max_memory=max_memory, overrides=_overrides(overrides))
    docs = doc["rows"]
    if as_json:
        one = docs[0] | ({"estimate": doc["estimate"]} if "estimate" in doc else {})
        click.echo(json.dumps(one if len(docs) == 1 else doc, indent=2))
        _exit_if_unverified([d.get("verification") for d in docs], doc=doc)
        return
    if "objective" in docs[0]:  # a design with the noise sensitivity
        from sosalgo.report.pareto import objective_lines

        click.echo("\n".join(objective_lines(doc, details)))
        _claims_line(doc)
        _exit_if_unverified([d.get("verification") for d in docs], doc=doc)
        return
    if docs[0].get("rate_type") == "sublinear":
        from sosalgo.report.design import sublinear_design_lines

        click.echo("\n".join(sublinear_design_lines(doc)))
        _claims_line(doc)
        _exit_if_unverified([d.get("verification") for d in docs], doc=doc)
        return
    names = docs[0]["free"]
    unsupported = all((d.get("relaxation") or {}).get("status") == "unsupported" for d in docs)
    how = ("no lower bound for this family" if unsupported
           else "proven lower bound by box-wide dual certificates" if method == "dual"
           else f"lower bound by moment relaxation ({scalarize}; floating point)")
    click.echo(f"{doc['spec']}: design of {', '.join(names)} certified by "
               f"{docs[0]['family']}; {how}")
    from sosalgo.report.legend import set_lines

    for line in set_lines(doc):
        click.echo(line)
    from sosalgo.spec import spec_from_text

    note = rep.tighter_family_note(spec_from_text(doc["spec_text"], doc["source"]),
                                   docs[0]["family"], certificate)
    if note:
        click.echo(note)
    click.echo(rep.design_table(docs, names, gap, method, details))
    for step in docs[0]["steps"] if len(docs) == 1 else ():
        click.echo(f"  - {step}")
    for line in rep.verification_notes(docs):
        click.echo(line)
    click.echo(rep.design_legend(method))
    click.echo("wrote " + ", ".join([doc["csv"], *doc["figures"]]))
    for d in docs:
        if d.get("error"):
            click.echo(f"error at kappa {d['kappa']:g}: {d['error']}", err=True)
    _claims_line(doc)
    _exit_if_unverified([d.get("verification") for d in docs], doc=doc)


def _design_steps(spec_path: str, kappa: tuple[str, ...], free: str | None,
                  gap: float | None, time_limit: float, steps: str, out: str, as_json: bool,
                  workers: int | None, scheduler: str | None, restart: bool, quiet: bool,
                  verify_: bool, overrides: tuple[str, ...], details: bool) -> None:
    """``design --steps``: the N-step design (:func:`sosalgo.runs.steps_design`)."""
    from sosalgo.report.steps_design import steps_design_lines
    from sosalgo.runs.steps_design import steps_design_run

    doc = steps_design_run(spec_path, _kappas(kappa), steps, out, free,
                           1e-3 if gap is None else gap, time_limit, workers, scheduler,
                           restart, not quiet, verify_, overrides=_overrides(overrides))
    rows = doc["rows"]
    if as_json:
        click.echo(json.dumps(rows[0] if len(rows) == 1 else doc, indent=2))
    else:
        click.echo("\n".join(steps_design_lines(doc, details)))
        for r in rows:
            if "verification" in r:
                from sosalgo.worstcase.claims import pep_check_lines

                click.echo("\n".join(pep_check_lines("verify", [r["verification"]])))
    bad = [r for r in rows if (r.get("verification") or {}).get("verified") == "failed"]
    if bad:
        raise VerificationError(f"{len(bad)} design(s) not verified (exit code 3)")


# --------------------------------------------------------------------------- pareto
@cli.command()
@click.argument("spec_path", metavar="SPEC", type=click.Path(dir_okay=False))
@click.option("--kappa", "kappa", multiple=True, metavar="K",
              help="Condition number(s); one front (CSV and figure) per value.")
@click.option("--points", default=20, show_default=True, type=int,
              help="Rate caps from the fastest certified rate to the slow end (>= 2).")
@click.option("--time-limit", default=180.0, show_default=True, type=float,
              help="Wall-clock seconds per kappa (the rate design takes a quarter).")
@click.option("--free", default=None, metavar="NAMES",
              help="Comma-separated parameters to design (default: those with a range).")
@click.option("--out", default="outputs", show_default=True, metavar="DIR",
              help="Directory for <name>-pareto-k<kappa>.csv/.png/.pdf.")
@batch_options
@click.option("--no-plot", is_flag=True, help="Skip the figure.")
@certificate_options(default="tightest")
@set_option
@details_option
@handle_errors
def pareto(spec_path: str, kappa: tuple[str, ...], points: int, time_limit: float,
           free: str | None, out: str, as_json: bool, workers: int | None,
           scheduler: str | None, restart: bool, quiet: bool, max_memory: str | None,
           no_plot: bool, certificate: str | None, lag: int | None,
           overrides: tuple[str, ...], details: bool) -> None:
    """Front of certified rate vs certified noise sensitivity over the parameter box,
    beside the known tunings. Python: sosalgo.pareto_run."""
    from sosalgo.report.pareto import pareto_lines
    from sosalgo.runs.pareto import pareto_run

    doc = pareto_run(spec_path, _kappas(kappa), out, points, time_limit, free, certificate,
                     {"lag": lag}, workers, scheduler, restart, not quiet, not no_plot,
                     max_memory=max_memory, overrides=_overrides(overrides))
    fronts = doc["fronts"]
    if as_json:
        one = fronts[0] | ({"estimate": doc["estimate"]} if "estimate" in doc else {})
        click.echo(json.dumps(one if len(fronts) == 1 else doc, indent=2))
        return
    for d in fronts:
        click.echo("\n".join(pareto_lines(d, details)))


# --------------------------------------------------------------------------- fig4
@cli.command()
@click.option("--kappa", "kappa", multiple=True, metavar="K",
              help="Condition numbers (default: 20 from 1.5 to 1000, log scale).")
@click.option("--time-limit", default=120.0, show_default=True, type=float,
              help="Wall-clock seconds per kappa and design.")
@click.option("--out", default="outputs/fig4", show_default=True, metavar="DIR")
@batch_options
@handle_errors
def fig4(kappa: tuple[str, ...], time_limit: float, out: str, as_json: bool,
         workers: int | None, scheduler: str | None, restart: bool, quiet: bool,
         max_memory: str | None) -> None:
    """Figure 4: the three-parameter family designed with tight certificates vs kappa.
    Python: sosalgo.runs.fig4.fig4."""
    from sosalgo.inputs import check_time_limit, out_dir
    from sosalgo.report import format_table
    from sosalgo.report.fig4 import fig4_rows
    from sosalgo.runs.fig4 import fig4 as run_fig4

    kappas = sorted(set(_kappas(kappa or ("{from: 1.5, to: 1000, points: 20, scale: log}",))
                        or []))
    check_time_limit(time_limit, "--time-limit")
    from sosalgo.kernel import budget

    budget.set_max_memory(max_memory)
    workers = budget.announce_workers(workers)
    figs, data = run_fig4(out_dir(out), kappas, workers=workers, scheduler=scheduler,
                          restart=restart, progress=not quiet, time_limit=time_limit)
    if as_json:
        from sosalgo.kinds import FIG4_KIND

        click.echo(json.dumps({"kind": FIG4_KIND, "figures": [str(p) for p in figs], **data},
                              indent=2))
        return
    rows = fig4_rows(data)
    click.echo(format_table(rows, list(rows[0]) if rows else []))
    click.echo("wrote " + ", ".join(str(p) for p in figs))


# --------------------------------------------------------------------------- grid
@cli.command()
@click.argument("spec_path", metavar="SPEC", type=click.Path(dir_okay=False))
@click.option("--kappa", "kappa", multiple=True, metavar="K",
              help="Condition number(s); one grid (and one CSV/figure) per value.")
@click.option("--points", default=60, show_default=True, type=click.IntRange(2, 2000),
              help="Grid points per free parameter.")
@click.option("--free", default=None, metavar="NAMES",
              help="Comma-separated parameters to grid (default: those with a range).")
@click.option("--tol", default=1e-6, show_default=True, type=float)
@click.option("--out", default="outputs", show_default=True, metavar="DIR")
@batch_options
@certificate_options
@set_option
@handle_errors
def grid(spec_path: str, kappa: tuple[str, ...], points: int, free: str | None, tol: float,
         out: str, as_json: bool, workers: int | None, scheduler: str | None, restart: bool,
         quiet: bool, max_memory: str | None, certificate: str | None, lag: int | None,
         overrides: tuple[str, ...]) -> None:
    """Exhaustive search: certified rate on a grid over the free parameters (Figure 3).
    Python: sosalgo.grid_run."""
    from sosalgo.report import grid as rep
    from sosalgo.runs import grid_run

    doc = grid_run(spec_path, _kappas(kappa), out, points, free, tol, certificate,
                   {"lag": lag}, workers, scheduler, restart, not quiet,
                   max_memory=max_memory, overrides=_overrides(overrides))
    if as_json:
        click.echo(json.dumps(doc, indent=2))
        return
    if doc.get("rate_type") == "sublinear":
        click.echo(f"{doc['spec']}: certified constant c on a grid of {', '.join(doc['free'])}"
                   f"; best c = {doc['best']}; wrote {doc['csv']}")
        return
    from sosalgo.report.legend import set_lines

    for line in set_lines(doc):
        click.echo(line)
    for d in doc["grids"]:
        for line in rep.grid_lines(doc["spec"], d):
            click.echo(line)


# --------------------------------------------------------------------------- verify
@cli.command()
@click.argument("result_path", metavar="RESULT.json", type=click.Path(dir_okay=False))
@click.option("--spec", "spec_override", default=None, metavar="SPEC",
              help="The spec file (default: the spec embedded in the result, else its "
                   "'source').")
@click.option("--out", default="outputs", show_default=True, metavar="DIR",
              help="Rational certificates go to DIR/certificates/ (when DIR is writable; "
                   "otherwise the certificates are only checked).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document on stdout.")
@click.option("--no-simulate", is_flag=True, help="Skip the simulation check.")
@certificate_options(default="verify")
@handle_errors
def verify(result_path: str, spec_override: str | None, out: str, as_json: bool,
           no_simulate: bool, certificate: str | None, lag: int | None) -> None:
    """Verify every claim of an `analyze --json`, `design --json` or `pareto --json`
    result (rates, bounds, noise bounds, constants): a ledger of each claim, backed,
    contradicted or unsupported (docs/verify.md); and every claim of a `pep --json`
    document or a pep witness file (docs/pep.md). The document's `kind` field chooses
    the check (docs/results.md).

    Exit code 3 when some claim is not backed, nothing is claimed, or the document's
    kind contradicts its content. Python: sosalgo.verify_document.
    """
    from sosalgo.batch.executor import Progress
    from sosalgo.documents import document_kind, read_result, result_rows, verify_document
    from sosalgo.inputs import writable
    from sosalgo.proofs.results import check_failed

    doc = read_result(result_path)
    kind = document_kind(doc, result_path)  # a kind its content contradicts: exit code 3
    if kind.checks == "claims":  # from `sosalgo pep`
        from sosalgo.worstcase.claims import passed, pep_check_lines

        res = verify_document(doc, spec_override, name=result_path)
        for note in res["notes"]:
            click.echo(f"note: {note}", err=True)
        click.echo(json.dumps(res, indent=2) if as_json else
                   "\n".join(pep_check_lines(result_path, res["results"])))
        failed = [c for c in res["results"] if not passed(c)]
        if failed:
            raise VerificationError(f"{result_path}: {len(failed)} of "
                                    f"{len(res['results'])} not verified")
        return
    rows = result_rows(doc, result_path) if kind.verify else []  # else refused below
    folder = os.path.join(out, "certificates")
    can_write = writable(out)
    bar = Progress(len(rows), f"verify {result_path}", enabled=not as_json,  # rows, claims
                   lazy=True)
    try:
        res = verify_document(doc, spec_override, folder if can_write else None,
                              not no_simulate, certificate, {"lag": lag}, name=result_path)
        bar.update(len(rows))
    finally:
        bar.close()
    notes = res["notes"] + ([] if can_write else [
        f"--out {out} is not writable: certificates checked, no files written"])
    for note in notes:
        click.echo(f"note: {note}", err=True)
    failed = [c for c in res["results"] if check_failed(c)]
    if as_json:
        click.echo(json.dumps(res, indent=2))
    else:
        from sosalgo.report.checks import checks_table, ledger_lines
        from sosalgo.report.legend import VERIFY_LEGEND, set_lines
        from sosalgo.report.pareto import noise_check_lines

        for line in set_lines(doc):
            click.echo(line)
        click.echo(checks_table(rows, res["results"]))
        click.echo(VERIFY_LEGEND)
        for line in noise_check_lines(rows, res["results"]):
            click.echo(line)
        from sosalgo.report.analysis import UNITS_NOTE

        for r, c in zip(rows, res["results"], strict=True):
            if (c or {}).get("units"):
                click.echo(f"kappa {r['kappa']:g}: proven in units where L = 1 ({UNITS_NOTE})")
        click.echo(f"rational certificates in {folder}" if can_write
                   else "no certificate files written")
        for line in ledger_lines(res["ledger"], res["claims"]):
            click.echo(line)
    edited = " (with a --spec that differs from the result's own spec)" if res[
        "notes"] and spec_override else ""
    if failed:
        raise VerificationError(f"{len(failed)} certificate(s) failed verification{edited}")
    if not res["vouched"]:
        bad = res["claims"]["contradicted"] + res["claims"]["unsupported"]
        raise VerificationError(f"{bad} claim(s) not backed{edited}" if bad else
                                "nothing to vouch for: the document claims nothing verify "
                                "can back")


# --------------------------------------------------------------------------- pep
@cli.command()
@click.argument("spec_path", metavar="SPEC", type=click.Path(dir_okay=False))
@click.option("--kappa", "kappa", multiple=True, metavar="K",
              help="Condition number(s); none for an m: 0 spec (required otherwise).")
@click.option("--steps", default="1", show_default=True, metavar="N|a..b",
              help="Steps N, or a range such as 1..10 (one row per N).")
@click.option("--measure", default=None, metavar="TERMS",
              help="Sum of c*f, c*dist, c*grad (points x_N, y_N, y<i>_N), c*sdist "
                   "(|xi_N - xi*|^2), c*inner(P, Q); default: the spec's measure (f, or "
                   "dist for measure: distance).")
@click.option("--initial", default=None, metavar="TERMS",
              help="Sum of c*f, c*dist, c*grad at x_0, c*sdist (|xi_0 - xi*|^2: a free "
                   "start), or none (no initial condition: the worst case is 0 or "
                   "unbounded); default sdist when the fixed point moves with the optimal "
                   "subgradients (Douglas-Rachford), dist otherwise.")
@click.option("--out", default="outputs", show_default=True, metavar="DIR",
              help="Directory for <name>-pep.csv, its rows' documents, witness JSON files "
                   "and figures.")
@batch_options
@click.option("--no-plot", is_flag=True, help="Skip the figures.")
@click.option("--no-witness", is_flag=True, help="Skip the worst-case witness.")
@set_option
@details_option
@handle_errors
def pep(spec_path: str, kappa: tuple[str, ...], steps: str, measure: str | None,
        initial: str | None, out: str, as_json: bool, workers: int | None,
        scheduler: str | None, restart: bool, quiet: bool, max_memory: str | None,
        no_plot: bool, no_witness: bool, overrides: tuple[str, ...], details: bool) -> None:
    """Worst case after N steps (performance estimation), its dual certificate proven
    exactly and a checked worst-case witness. Python: sosalgo.pep_run or sosalgo.worstcase."""
    from sosalgo.runs.pep import pep_run, pep_summary

    ks = _kappas(kappa)
    doc = pep_run(spec_path, ks[0] if ks and len(ks) == 1 else ks, steps, measure, initial,
                  out, workers, scheduler, restart, not quiet, not no_plot,
                  witness=not no_witness, max_memory=max_memory,
                  overrides=_overrides(overrides))
    click.echo(json.dumps(doc, indent=2) if as_json else pep_summary(doc, details))


# --------------------------------------------------------------------------- lmi
@cli.command()
@click.argument("spec_path", metavar="SPEC", type=click.Path(dir_okay=False))
@click.option("--latex", is_flag=True,
              help="Print a LaTeX snippet (equation*/aligned/bmatrix; needs amsmath).")
@click.option("--free", default=None, metavar="NAMES",
              help="Comma-separated parameters kept symbolic (default: all untied ones).")
@certificate_options
@set_option
@handle_errors
def lmi(spec_path: str, latex: bool, free: str | None, certificate: str | None,
        lag: int | None, overrides: tuple[str, ...]) -> None:
    """Print the symbolic matrix M(theta, rho, lambda, P) of Theorem 1 (eq. 15), or the
    blocks of another certificate family. Python: sosalgo.lmi."""
    from sosalgo.api import lmi as symbolic

    click.echo(symbolic(spec_path, free, latex, certificate, {"lag": lag},
                        overrides=_overrides(overrides)))


# --------------------------------------------------------------------------- table1
@cli.command()
@click.option("--specs", "spec_paths", multiple=True, metavar="SPEC",
              help="Specs to tabulate (default: specs/*.yaml, else the shipped examples).")
@click.option("--kappa", "kappa", multiple=True, metavar="K", help="Default: 2, 10, 100.")
@click.option("--tol", default=1e-6, show_default=True, type=float)
@click.option("--out", default="outputs", show_default=True, metavar="DIR")
@certificate_options(several=True)
@handle_errors
def table1(spec_paths: tuple[str, ...], kappa: tuple[str, ...], tol: float, out: str,
           certificate: str | None, lag: int | None) -> None:
    """Table 1 of the paper: certified rate beside each spec's closed-form rate.

    The closed-form rate of a spec is the first entry of its ``references``. With several
    families (--certificate theorem1,interpolation) the first fills rho_certified and every
    further family adds rho_<family>, certified_<family> and difference_<family>.
    Python: sosalgo.table1_run.
    """
    from sosalgo.report import format_table
    from sosalgo.runs import table1_run

    doc = table1_run(spec_paths, _kappas(kappa) or (), tol, out, certificate, {"lag": lag})
    from sosalgo.report.legend import TABLE1_LEGEND

    click.echo(format_table(doc["rows"], doc["columns"]))
    click.echo(TABLE1_LEGEND)
    click.echo(f"wrote {doc['csv']}")


# --------------------------------------------------------------------------- examples
@cli.command()
@click.argument("names", nargs=-1, metavar="[NAME ...]")
@click.option("--copy", "copy_to", default=None, metavar="DIR",
              help="Copy the named example specs (default: all) into DIR.")
@handle_errors
def examples(names: tuple[str, ...], copy_to: str | None) -> None:
    """List the example specs shipped with sosalgo, or copy them to start from.
    Python: sosalgo.example(NAME), sosalgo.copy_examples."""
    from sosalgo.api import copy_examples, example
    from sosalgo.kernel.resources import example_specs
    from sosalgo.report import format_table

    found = example_specs()
    unknown = [n for n in names if n not in found]
    if unknown:
        from sosalgo.spec.names import closest_example

        raise InputError(f"{unknown[0]}: no such example (closest: "
                         f"{closest_example(unknown[0])}; known: {', '.join(found)})")
    if copy_to is None:
        rows = [{"name": n, "description": example(n).description} for n in names or found]
        click.echo(format_table(rows, ["name", "description"]))
        click.echo("copy one to edit it: sosalgo examples NAME --copy DIR")
        return
    for target, written in copy_examples(names, copy_to).items():
        click.echo(f"wrote {target}" if written else
                   f"kept {target} (exists and differs; not overwritten)", err=not written)


def main() -> None:
    """Console-script entry point (SIGTERM unwinds like Ctrl-C: pools are shut down, the
    finished rows saved). An interrupted run then ends at once: the interpreter's own
    teardown (collecting every object, stopping native thread pools) can take seconds on a
    loaded machine, and everything it would close is closed by the unwinding already. A
    finished run skips the collection of its objects at exit (files are closed already)."""
    import signal

    signal.signal(signal.SIGTERM, on_sigterm)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not ignored (nohup)
        signal.signal(signal.SIGINT, on_sigint)
    try:
        cli(prog_name="sosalgo")
    except SystemExit as exc:
        if exc.code not in INTERRUPTED:
            raise
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        os._exit(exc.code)
    finally:  # a finished run: no collection of its objects at exit (seconds when loaded)
        import gc

        gc.freeze()


if __name__ == "__main__":  # pragma: no cover
    main()
