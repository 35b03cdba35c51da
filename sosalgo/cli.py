"""Command-line interface: a thin layer over the Python API.

Exit codes: 0 success, 2 bad input or usage, 1 internal error. Errors are one line on
stderr naming the file and the field; no traceback (set SOSALGO_DEBUG=1 to see one).
"""

from __future__ import annotations

import functools
import json
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from sosalgo import __version__
from sosalgo.batch.store import kappa_label, output_lock
from sosalgo.errors import InputError, VerificationError

__all__ = ["main", "cli"]


def _fail(msg: str, code: int) -> None:
    click.echo(f"error: {msg}", err=True)
    sys.exit(code)


def handle_errors(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Map our exceptions to one-line messages and exit codes."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except InputError as exc:  # spec, model, options, files, cluster: exit 2
            src = kwargs.get("spec_path", "")
            names_file = getattr(exc, "names_file", True)
            _fail(_one_line(str(exc) if names_file or not src else f"{src}: {exc}"), 2)
        except VerificationError as exc:  # results are written; a check failed: exit 3
            _fail(_one_line(str(exc)), 3)
        except BrokenPipeError:  # stdout closed early (`sosalgo ... | head`): quiet exit
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())  # no second error at interpreter exit
            sys.exit(141)  # 128 + SIGPIPE, as a shell reports a broken pipe
        except KeyboardInterrupt:
            click.echo("interrupted: finished rows are saved; rerun to resume", err=True)
            sys.exit(130)
        except Terminated:
            click.echo("terminated: finished rows are saved; rerun to resume", err=True)
            sys.exit(143)
        except click.exceptions.Exit:
            raise
        except Exception as exc:  # noqa: BLE001 - last line of defence
            if os.environ.get("SOSALGO_DEBUG"):
                raise
            _fail(_one_line(f"internal error: {type(exc).__name__}: {exc}"), 1)

    return wrapper


class Terminated(BaseException):
    """SIGTERM received: unwinds like KeyboardInterrupt, so worker pools are shut down."""


def _on_sigterm(signum: int, frame: Any) -> None:
    raise Terminated()


def _one_line(msg: str) -> str:
    return " ".join(msg.split())[:500]


def _kappas(spec, values: tuple[str, ...]) -> tuple[float, ...]:
    if not values:
        return spec.kappa
    return tuple(k for v in values for k in _kappa_option(v))


def _kappa_option(value: str) -> tuple[float, ...]:
    """One --kappa value: a number, or a YAML list/range like '{from: 2, to: 100, points: 9}'."""
    import yaml

    raw: object = value
    if "," in value and value.strip()[:1] not in "[{":
        raise InputError(f"--kappa {value}: one value per --kappa; write --kappa "
                         + " --kappa ".join(v.strip() for v in value.split(","))
                         + f" or a list --kappa '[{value}]'")
    if value.strip()[:1] in "[{":
        try:
            raw = yaml.safe_load(value)
        except yaml.YAMLError:
            raise InputError(f"--kappa {value}: not a number, list or range") from None
    from sosalgo.spec import parse_kappa

    return parse_kappa(raw, "--kappa", "value")


def _out_dir(out: str) -> Path:
    """The --out directory, checked writable (nothing is created yet)."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory")
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"--out {out}: not writable ({probe} does not accept new files)")
    return path


def _load(spec_path: str):
    """The spec and its text, read once (so a pipe or /dev/stdin works)."""
    from sosalgo.spec import read_spec_text, spec_from_text

    text = read_spec_text(spec_path)
    return spec_from_text(text, source=str(spec_path)), text


def _check_scheduler(scheduler: str | None) -> None:
    """Fail early (exit 2, nothing written) on a missing Dask or an unusable scheduler."""
    if scheduler:
        from sosalgo.batch.executor import check_scheduler

        check_scheduler(scheduler)


def _check_points(spec, kappas, theta=None) -> None:
    """Evaluate the spec at every requested kappa before any output is written."""
    from sosalgo.model import ModelError, bind

    for k in kappas:
        try:
            bind(spec, k, theta)
        except ModelError as exc:
            raise InputError(f"{spec.source}: {exc.field}: at kappa={k:g}: {exc.message}") from None


def _free_names(spec, free: str | None) -> list[str]:
    """The --free list (default: parameters with a range), checked against the spec."""
    names = spec.ranged if free is None else [p.strip() for p in free.split(",") if p.strip()]
    if not names:
        raise InputError(f"{spec.source}: parameters: no parameter has a range (use --free)")
    spec.check_free(names)
    return names


def _boxes(spec, kappas, names) -> dict[float, list[tuple[float, float]]]:
    """The box Θ at every kappa, or a one-line input error."""
    from sosalgo.model import ModelError, parameter_box

    boxes = {}
    for k in kappas:
        try:
            boxes[k] = parameter_box(spec, k, names)
        except ModelError as exc:
            raise InputError(f"{spec.source}: {exc.field}: at kappa={k:g}: {exc.message}") from None
    return boxes


def _check_tol(tol: float) -> None:
    if not (0 < tol < 0.5):
        raise InputError(f"--tol {tol}: must be in (0, 0.5)")


def certificate_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """--certificate NAME[,NAME...] and --lag L (the interpolation family's lag)."""
    fn = click.option("--lag", type=click.IntRange(0, 8), default=None,
                      help="Lag of the interpolation family (default: states - 1).")(fn)
    return click.option("--certificate", "certificate", default=None, metavar="FAMILY",
                        help="Certificate family: theorem1 (default) or interpolation; "
                             "comma-separated to compare several.")(fn)


def _families(spec, value: str | None, lag: int | None, single: bool = False) -> list[Any]:
    """The certificate families asked for (default: the spec's own)."""
    from sosalgo.analysis import spec_family
    from sosalgo.certificates import FAMILIES, FAMILY_OPTIONS, get_family

    if value is None:
        fams = [spec_family(spec)]
        names = [fams[0].name]
    else:
        names = [v.strip() for v in value.split(",") if v.strip()]
        if not names or len(set(names)) != len(names):
            raise InputError(f"--certificate {value}: expected distinct family names")
        for nm in names:
            if nm not in FAMILIES:
                raise InputError(f"--certificate {nm}: unknown family "
                                 f"(known: {', '.join(FAMILIES)})")
        fams = [get_family(nm, spec.certificate_options if nm == spec.certificate else None)
                for nm in names]
    if single and len(fams) > 1:
        raise InputError(f"--certificate {value}: this command takes one family")
    if lag is not None:
        if not any("lag" in FAMILY_OPTIONS[nm] for nm in names):
            raise InputError("--lag: only the interpolation family has a lag")
        fams = [get_family(f.name, {"lag": lag}) if "lag" in FAMILY_OPTIONS[f.name] else f
                for f in fams]
    return fams


def _family_suffix(fam) -> str:
    """'' for the default family (Theorem 1), '-<family>' otherwise, '-<family>-lag<l>' for an
    explicit lag."""
    if fam.is_default:
        return ""
    lag = getattr(fam, "lag", None)
    return f"-{fam.name}" + ("" if lag is None else f"-lag{lag}")


def _analysis_csv(out_dir: Path, spec, fam) -> Path:
    """<name>-analysis.csv for Theorem 1, <name>-analysis-<family>[-lag<l>].csv otherwise."""
    return out_dir / f"{spec.name}-analysis{_family_suffix(fam)}.csv"


def batch_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """The options every batch command shares: --json, --workers, --scheduler, --restart,
    --quiet."""
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
    ]
    for opt in reversed(options):
        fn = opt(fn)
    return fn


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
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
                   "or more).")
@batch_options
@click.option("--no-plot", is_flag=True, help="Skip the figure.")
@click.option("--verify", "verify_", is_flag=True,
              help="Prove each certificate in exact arithmetic and simulate it.")
@certificate_options
@handle_errors
def analyze(spec_path: str, kappa: tuple[str, ...], tol: float, out: str, as_json: bool,
            workers: int | None, scheduler: str | None, restart: bool, quiet: bool,
            no_plot: bool, verify_: bool, certificate: str | None, lag: int | None) -> None:
    """Best rate certified at each kappa, with its certificate (Theorem 1: P, lambda)."""
    from sosalgo.batch.sweeps import csv_row_to_json, run_analysis_sweep
    from sosalgo.report import analysis as rep

    spec, spec_text = _load(spec_path)
    kappas = _kappas(spec, kappa)
    _check_tol(tol)
    fams = _families(spec, certificate, lag)
    _check_points(spec, kappas)
    out_dir = _out_dir(out)
    _check_scheduler(scheduler)
    if len(fams) > 1 or not fams[0].is_default:
        runs = []
        for fam in fams:
            path = _analysis_csv(out_dir, spec, fam)
            with output_lock(path):
                rows = run_analysis_sweep(spec, spec_text, kappas, path, tol, workers=workers,
                                          scheduler=scheduler, restart=restart,
                                          progress=not quiet, family=fam)
            runs.append((fam, path, [csv_row_to_json(spec, r, fam) for r in rows]))
        _analyze_families(spec, runs, out_dir, tol, as_json, no_plot, verify_, spec_text)
        return
    csv_path = out_dir / f"{spec.name}-analysis.csv"
    fig_stem = out_dir / f"{spec.name}-rate"
    with output_lock(csv_path):
        rows = run_analysis_sweep(spec, spec_text, kappas, csv_path, tol, workers=workers,
                                  scheduler=scheduler, restart=restart, progress=not quiet,
                                  companions=_figures(fig_stem))
        jrows = [csv_row_to_json(spec, r) for r in rows]
        # a rate-vs-kappa figure needs two kappas or more (one point is not a curve)
        figs = [] if no_plot or len(jrows) < 2 else rep.analysis_figure(spec, jrows, fig_stem)
    if verify_:
        rep.attach_checks(spec, jrows, out_dir / "certificates")
    if as_json:
        doc = {"spec": spec.name, "source": spec.source, "spec_text": spec_text, "tol": tol,
               "csv": str(csv_path), "figures": [str(p) for p in figs], "rows": jrows}
        click.echo(json.dumps(doc, indent=2))
    else:
        click.echo(f"{spec.name}: {spec.description}".rstrip(": "))
        click.echo(rep.analysis_table(spec, jrows, rep.ANALYSIS_COLUMNS
                                      + (["verified"] if verify_ else [])))
        for r in jrows:
            if r.get("warning"):
                click.echo(f"warning at kappa {r['kappa']:g}: {r['warning']}", err=True)
        click.echo(f"wrote {csv_path}" + "".join(f", {p}" for p in figs))
    _exit_if_unverified([r.get("verification") for r in jrows])


def _exit_if_unverified(checks: list[Any]) -> None:
    """Exit code 3 when some certificate failed its check (as ``sosalgo verify`` does)."""
    if all(c is None for c in checks):
        return  # nothing was verified (no --verify): nothing to import or report
    from sosalgo.verify.results import check_failed

    if any(check_failed(c) for c in checks):
        raise VerificationError("some certificate failed verification (exit code 3)")


def _figures(stem: Path) -> list[Path]:
    """The PNG and PDF written for a figure stem (they move with their CSV)."""
    return [stem.with_name(f"{stem.name}.{ext}") for ext in ("png", "pdf")]


def _analyze_families(spec, runs: list, out_dir: Path, tol: float, as_json: bool,
                      no_plot: bool, verify_: bool, spec_text: str) -> None:
    """Output of ``analyze`` for a family other than the default or several families: one
    CSV per family, one figure with every family (:func:`families_figure`)."""
    from sosalgo.report import analysis as rep

    figs = [] if no_plot else rep.families_figure(spec, runs, out_dir / f"{spec.name}-rate")
    for fam, _, rows in runs:
        for r in rows:
            r["family"] = fam.name
        if verify_:
            rep.attach_checks(spec, rows, out_dir / "certificates", family=fam)
    if as_json:
        doc = {"spec": spec.name, "source": spec.source, "spec_text": spec_text, "tol": tol,
               "csv": str(runs[0][1]), "csvs": {f.name: str(p) for f, p, _ in runs},
               "figures": [str(p) for p in figs], "rows": [r for _, _, rows in runs for r in rows]}
        click.echo(json.dumps(doc, indent=2))
    else:
        click.echo(f"{spec.name}: {spec.description}".rstrip(": "))
        cols = rep.FAMILY_COLUMNS + (["verified"] if verify_ else [])
        for fam, _, rows in runs:
            click.echo(f"certificate family: {fam.description}")
            click.echo(rep.analysis_table(spec, rows, cols))
        click.echo("wrote " + ", ".join([str(p) for _, p, _ in runs] + [str(p) for p in figs]))
    _exit_if_unverified([r.get("verification") for _, _, rows in runs for r in rows])


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
@click.option("--gap", default=1e-4, show_default=True, type=float,
              help="Target gap between certified rate and lower bound.")
@click.option("--time-limit", default=120.0, show_default=True, type=float,
              help="Wall-clock seconds per kappa (all phases); the best proven results "
                   "so far are returned when it runs out.")
@click.option("--method", type=click.Choice(["dual", "moment"]), default="dual",
              show_default=True,
              help="Lower bound by box-wide dual certificates (dual) or by the paper's "
                   "moment relaxation (moment; uses --scalarize and --order).")
@click.option("--out", default="outputs", show_default=True, metavar="DIR")
@batch_options
@click.option("--verify", "verify_", is_flag=True,
              help="Prove each certificate in exact arithmetic and simulate it.")
@certificate_options
@handle_errors
def design(spec_path: str, kappa: tuple[str, ...], free: str | None, scalarize: str,
           order: int | None, gap: float, time_limit: float, method: str, out: str,
           as_json: bool, workers: int | None, scheduler: str | None, restart: bool,
           quiet: bool, verify_: bool, certificate: str | None, lag: int | None) -> None:
    """Design parameters: certified design, proven lower bound, gap between them."""
    from sosalgo.batch.sweeps import design_csv_to_json, run_design_sweep
    from sosalgo.report import design as rep

    spec, spec_text = _load(spec_path)
    fam = _families(spec, certificate, lag, single=True)[0]
    if method == "moment" and not fam.supports_moment:
        raise InputError(f"--method moment: the moment relaxation is built on Theorem 1, "
                         f"not {fam.name} (use --method dual)")
    kappas = _kappas(spec, kappa)
    names = _free_names(spec, free)
    if not gap > 0:
        raise InputError(f"--gap {gap}: must be positive")
    if not time_limit > 0:
        raise InputError(f"--time-limit {time_limit}: must be positive")
    if not math.isfinite(time_limit):
        raise InputError(f"--time-limit {time_limit}: must be finite")
    _check_points(spec, kappas)
    _boxes(spec, kappas, names)
    from sosalgo.design.polymodel import check_polynomial

    check_polynomial(spec, names)  # before anything is written
    out_dir = _out_dir(out)
    _check_scheduler(scheduler)
    from sosalgo.batch.sweeps import family_options

    options = {"free": names, "scalarize": scalarize, "order": order, "gap": gap,
               "time_limit": time_limit, "method": method,
               "certificate": family_options(fam),
               "progress_steps": len(kappas) == 1 and not quiet and not as_json,
               # one kappa: its grid and local searches use the workers
               "inner_workers": (workers or os.cpu_count() or 1)
               if len(kappas) == 1 and scheduler is None else 1}
    csv_path = out_dir / f"{spec.name}-design{_family_suffix(fam)}.csv"
    fig_stem = out_dir / f"{spec.name}-design{_family_suffix(fam)}"
    with output_lock(csv_path):
        rows, fresh = run_design_sweep(spec, spec_text, kappas, csv_path, options,
                                       workers=workers, scheduler=scheduler, restart=restart,
                                       progress=not quiet, companions=_figures(fig_stem))
        docs = [fresh.get(float(r["kappa"])) or design_csv_to_json(spec, names, r, fam)
                for r in rows]
        for d in docs:
            d["source"] = spec.source
            d["spec_text"] = spec_text
        figs = []
        if len(docs) > 1:
            figs = rep.design_figure(spec, names, rows, docs, fig_stem, fam,
                                     "dual certificates" if method == "dual"
                                     else f"moment relaxation, {scalarize}")
    if verify_:
        from sosalgo.verify.results import verify_document_rows

        checks = verify_document_rows(spec, docs, out_dir / "certificates")
        for d, v in zip(docs, checks, strict=True):
            d["verification"] = v
    if as_json:
        if len(docs) == 1:
            click.echo(json.dumps(docs[0], indent=2))
        else:
            click.echo(json.dumps({"spec": spec.name, "source": spec.source,
                                   "spec_text": spec_text, "csv": str(csv_path),
                                   "figures": [str(p) for p in figs], "rows": docs}, indent=2))
        _exit_if_unverified([d.get("verification") for d in docs])
        return
    how = ("box-wide dual certificates" if method == "dual"
           else f"moment relaxation ({scalarize})")
    click.echo(f"{spec.name}: design of {', '.join(names)} certified by {fam.name}; "
               f"lower bound by {how}")
    click.echo(rep.design_table(docs, names, gap, method))
    if len(docs) == 1:
        for step in docs[0]["steps"]:
            click.echo(f"  - {step}")
    for line in rep.verification_notes(docs):
        click.echo(line)
    click.echo(rep.LEGEND)
    click.echo(f"wrote {csv_path}" + "".join(f", {p}" for p in figs))


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
         workers: int | None, scheduler: str | None, restart: bool, quiet: bool) -> None:
    """Figure 4: the three-parameter family designed with tight certificates vs kappa."""
    from sosalgo.report.fig4 import fig4 as run_fig4

    values = kappa or ("{from: 1.5, to: 1000, points: 20, scale: log}",)
    kappas = sorted({k for v in values for k in _kappa_option(v)})
    if not (time_limit > 0 and math.isfinite(time_limit)):
        raise InputError(f"--time-limit {time_limit}: must be positive and finite")
    figs, data = run_fig4(_out_dir(out), kappas, workers=workers, scheduler=scheduler,
                          restart=restart, progress=not quiet, time_limit=time_limit)
    if as_json:
        click.echo(json.dumps({"figures": [str(p) for p in figs], **data}, indent=2))
        return
    from sosalgo.report import format_table
    from sosalgo.report.fig4 import fig4_rows

    rows = fig4_rows(data)

    click.echo(format_table(rows, list(rows[0]) if rows else []))
    click.echo("wrote " + ", ".join(str(p) for p in figs))


# --------------------------------------------------------------------------- grid
GRID_COLUMNS = {"kappa", "rho", "certified", "lambda", "max_eig_M", "min_eig_P", "solves",
                "seconds", "solver", "error"}


@cli.command()
@click.argument("spec_path", metavar="SPEC", type=click.Path(dir_okay=False))
@click.option("--kappa", "kappa", multiple=True, metavar="K", required=True,
              help="Condition number(s); one grid (and one CSV/figure) per value.")
@click.option("--points", default=60, show_default=True, type=click.IntRange(2, 2000),
              help="Grid points per free parameter.")
@click.option("--free", default=None, metavar="NAMES",
              help="Comma-separated parameters to grid (default: those with a range).")
@click.option("--tol", default=1e-6, show_default=True, type=float)
@click.option("--out", default="outputs", show_default=True, metavar="DIR")
@batch_options
@certificate_options
@handle_errors
def grid(spec_path: str, kappa: tuple[str, ...], points: int, free: str | None, tol: float,
         out: str, as_json: bool, workers: int | None, scheduler: str | None, restart: bool,
         quiet: bool, certificate: str | None, lag: int | None) -> None:
    """Exhaustive search: certified rate on a grid over the free parameters (Figure 3)."""
    from sosalgo.batch.sweeps import run_grid
    from sosalgo.report import grid as rep

    spec, spec_text = _load(spec_path)
    kappas = _kappas(spec, kappa)
    names = _free_names(spec, free)
    for p in names:
        if p in GRID_COLUMNS:
            raise InputError(f"{spec.source}: parameters.{p}: name clashes with a grid column")
    _check_tol(tol)
    fam = _families(spec, certificate, lag, single=True)[0]
    boxes = _boxes(spec, kappas, names)
    out_dir = _out_dir(out)
    _check_scheduler(scheduler)
    docs = []
    for k in dict.fromkeys(kappas):
        stem = out_dir / f"{spec.name}-grid-k{kappa_label(k)}{_family_suffix(fam)}"
        csv_path = stem.with_name(stem.name + ".csv")
        with output_lock(csv_path):
            rows = run_grid(spec, spec_text, k, names, boxes[k], points, csv_path, tol,
                            workers=workers, scheduler=scheduler, restart=restart,
                            progress=not quiet, companions=_figures(stem), family=fam)
            rho = rep.grid_rates(rows)
            figs = [] if len(names) > 2 else rep.grid_plot(spec, k, names, boxes[k], points,
                                                           rho, stem)
        docs.append(rep.grid_document(k, csv_path, figs, rows, rho, names))
    if as_json:
        click.echo(json.dumps({"spec": spec.name, "free": names, "grids": docs}, indent=2))
        return
    for d in docs:
        for line in rep.grid_lines(spec.name, d):
            click.echo(line)


# --------------------------------------------------------------------------- verify
@cli.command()
@click.argument("result_path", metavar="RESULT.json", type=click.Path(dir_okay=False))
@click.option("--spec", "spec_override", default=None, metavar="SPEC",
              help="The spec file (default: the 'source' recorded in the result).")
@click.option("--out", default="outputs", show_default=True, metavar="DIR",
              help="Rational certificates go to DIR/certificates/.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document on stdout.")
@click.option("--no-simulate", is_flag=True, help="Skip the simulation check.")
@certificate_options
@handle_errors
def verify(result_path: str, spec_override: str | None, out: str, as_json: bool,
           no_simulate: bool, certificate: str | None, lag: int | None) -> None:
    """Verify every certificate of an `analyze --json` or `design --json` result.

    Exit code 3 when some certificate fails to verify.
    """
    from sosalgo.spec import load_spec, spec_from_text
    from sosalgo.verify.results import ResultError, check_failed, verify_document_rows

    doc = _read_result(result_path)
    rows = doc.get("rows", [doc] if "rho_certified" in doc else None)
    if not isinstance(rows, list) or not all(isinstance(r, dict) and "kappa" in r for r in rows):
        raise InputError(f"{result_path}: rows: expected analyze or design results")
    first = rows[0] if rows else {}
    src = spec_override or doc.get("source") or first.get("source")
    text = None if spec_override else (doc.get("spec_text") or first.get("spec_text"))
    if text is not None:  # the spec embedded in the result: moving or editing files is fine
        if not isinstance(text, str) or not isinstance(src or "", str):
            raise InputError(f"{result_path}: spec_text: expected the spec's YAML text")
        spec = spec_from_text(text, source=f"{result_path}: spec_text")
    elif not src or not isinstance(src, str):
        raise InputError(f"{result_path}: source: unknown spec file; pass --spec")
    else:
        spec = load_spec(src)
    if doc.get("spec") not in (None, spec.name):
        raise InputError(f"{result_path}: spec: result is for '{doc.get('spec')}', "
                         f"{src} is '{spec.name}'")
    out_dir = _out_dir(out)
    fam = None if certificate is None and lag is None else _families(spec, certificate, lag,
                                                                      single=True)[0]
    try:
        checks = verify_document_rows(spec, rows, out_dir / "certificates", not no_simulate,
                                      family=fam)
    except ResultError as exc:
        raise InputError(f"{result_path}: {exc}") from None
    failed = [c for c in checks if check_failed(c)]
    if as_json:
        click.echo(json.dumps({"spec": spec.name, "source": src, "results": checks}, indent=2))
    else:
        from sosalgo.report.checks import checks_table

        click.echo(checks_table(rows, checks))
        click.echo(f"rational certificates in {out_dir / 'certificates'}")
    if failed:
        raise VerificationError(f"{len(failed)} certificate(s) failed verification")


def _read_result(result_path: str) -> dict[str, Any]:
    """A result JSON document (bounded in size and depth), or a one-line InputError."""
    try:
        with open(result_path, "rb") as fh:
            raw = fh.read(MAX_RESULT_BYTES + 1)
        if len(raw) > MAX_RESULT_BYTES:
            raise InputError(f"{result_path}: larger than {MAX_RESULT_BYTES} bytes")
        doc = json.loads(raw.decode("utf-8"))
    except FileNotFoundError:
        raise InputError(f"{result_path}: no such file") from None
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InputError(f"{result_path}: not a JSON result ({type(exc).__name__})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{result_path}: not a sosalgo result document")
    return doc


MAX_RESULT_BYTES = 200_000_000


# --------------------------------------------------------------------------- lmi
@cli.command()
@click.argument("spec_path", metavar="SPEC", type=click.Path(dir_okay=False))
@click.option("--latex", is_flag=True, help="Print LaTeX instead of plain text.")
@click.option("--free", default=None, metavar="NAMES",
              help="Comma-separated parameters kept symbolic (default: all untied ones).")
@certificate_options
@handle_errors
def lmi(spec_path: str, latex: bool, free: str | None, certificate: str | None,
        lag: int | None) -> None:
    """Print the symbolic matrix M(theta, rho, lambda, P) of Theorem 1 (eq. 15), or the
    blocks of another certificate family."""
    from sosalgo.spec import load_spec
    from sosalgo.symbolic import symbolic_lmi

    spec = load_spec(spec_path)
    names = None if free is None else [p.strip() for p in free.split(",") if p.strip()]
    if names is not None:
        spec.check_free(names, need_range=False)
    fam = _families(spec, certificate, lag, single=True)[0]
    click.echo(symbolic_lmi(spec, free=names, latex=latex, family=fam))


# --------------------------------------------------------------------------- table1
@cli.command()
@click.option("--specs", "spec_paths", multiple=True, metavar="SPEC",
              help="Specs to tabulate (default: specs/*.yaml, else the shipped examples).")
@click.option("--kappa", "kappa", multiple=True, metavar="K", help="Default: 2, 10, 100.")
@click.option("--tol", default=1e-6, show_default=True, type=float)
@click.option("--out", default="outputs", show_default=True, metavar="DIR")
@certificate_options
@handle_errors
def table1(spec_paths: tuple[str, ...], kappa: tuple[str, ...], tol: float, out: str,
           certificate: str | None, lag: int | None) -> None:
    """Table 1 of the paper: certified rate beside each spec's closed-form rate.

    The closed-form rate of a spec is the first entry of its ``references``. With several
    families (--certificate theorem1,interpolation) the first fills rho_certified and every
    further family adds rho_<family>, certified_<family> and difference_<family>.
    """
    from sosalgo.report import format_table
    from sosalgo.report.table1 import table1_rows, write_table1
    from sosalgo.spec import read_spec_text, spec_from_text

    _check_tol(tol)
    paths = list(spec_paths) or sorted(str(p) for p in Path("specs").glob("*.yaml"))
    if paths:
        texts = {p: read_spec_text(p) for p in paths}
    else:  # outside a checkout: the example specs shipped with sosalgo
        from sosalgo.resources import example_specs

        texts = {f"examples/{name}.yaml": f.read_text(encoding="utf-8")
                 for name, f in example_specs().items()}
    specs = [spec_from_text(text, source=src) for src, text in texts.items()]
    if not specs:
        raise InputError("--specs: no spec files given and none in specs/")
    kappas = [k for v in kappa for k in _kappa_option(v)] or [2.0, 10.0, 100.0]
    fams = [_families(spec, certificate, lag) if certificate or lag is not None else [None]
            for spec in specs]
    rows, cols = table1_rows(specs, kappas, tol, fams)
    settings = {"job": "table1", "specs": texts, "kappa": kappas, "tol": tol,
                "certificate": certificate, "lag": lag}
    path = write_table1(_out_dir(out), rows, cols, settings)
    click.echo(format_table(rows, cols))
    click.echo(f"wrote {path}")


# --------------------------------------------------------------------------- examples
@cli.command()
@click.argument("names", nargs=-1, metavar="[NAME ...]")
@click.option("--copy", "copy_to", default=None, metavar="DIR",
              help="Copy the named example specs (default: all) into DIR.")
@handle_errors
def examples(names: tuple[str, ...], copy_to: str | None) -> None:
    """List the example specs shipped with sosalgo, or copy them to start from."""
    from sosalgo.report import format_table
    from sosalgo.resources import example_specs
    from sosalgo.spec import spec_from_text

    found = example_specs()
    unknown = [n for n in names if n not in found]
    if unknown:
        raise InputError(f"{unknown[0]}: no such example (known: {', '.join(found)})")
    chosen = {n: found[n] for n in (names or found)}
    if copy_to is None:
        rows = []
        for name, f in chosen.items():
            spec = spec_from_text(f.read_text(encoding="utf-8"), source=f"{name}.yaml")
            rows.append({"name": name, "description": spec.description})
        click.echo(format_table(rows, ["name", "description"]))
        click.echo("copy one to edit it: sosalgo examples NAME --copy DIR")
        return
    out_dir = _out_dir(copy_to)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, f in chosen.items():
        target = out_dir / f"{name}.yaml"
        text = f.read_text(encoding="utf-8")
        if target.exists() and target.read_text(encoding="utf-8") != text:
            click.echo(f"kept {target} (exists and differs; not overwritten)", err=True)
            continue
        target.write_text(text, encoding="utf-8")
        click.echo(f"wrote {target}")


def main() -> None:
    """Console-script entry point (SIGTERM unwinds like Ctrl-C: pools are shut down)."""
    import signal

    signal.signal(signal.SIGTERM, _on_sigterm)
    cli(prog_name="sosalgo")


if __name__ == "__main__":  # pragma: no cover
    main()
