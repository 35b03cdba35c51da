"""Batch runs that write files (the Python twins of ``sosalgo analyze|design|grid|table1``).

Each function checks its input (:mod:`sosalgo.inputs`: InputError, a ValueError, before
anything is written), runs the resumable sweep into ``out_dir`` under the run model
(:mod:`sosalgo.store`), draws the figures and returns the document that the
command prints with ``--json``. File names come from :mod:`sosalgo.schema`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sosalgo import inputs
from sosalgo.batch.executor import check_scheduler
from sosalgo.certificates import describe_family, spec_family
from sosalgo.documents import vouch_run
from sosalgo.errors import InputError
from sosalgo.kernel import budget
from sosalgo.kinds import ANALYSIS_KIND, DESIGN_KIND, GRID_KIND, TABLE1_KIND
from sosalgo.schema import analysis_csv, design_stem, grid_stem, rate_stem
from sosalgo.spec import Spec
from sosalgo.store import output_lock

__all__ = ["analyze_run", "design_run", "grid_run", "set_field", "spec_with_text",
           "table1_run"]

Kappas = float | Sequence[float] | None


def spec_with_text(spec: Spec | str | Path, spec_text: str | None = None,
                   overrides: Mapping[str, str] | None = None, varying: bool = False
                   ) -> tuple[Spec, str]:
    """(spec, its YAML text): batch runs send the text to workers and settings files. A
    path is read once (a pipe works; a shipped example's name reads the example); a Spec
    needs its ``spec_text``. ``overrides`` (``--set NAME=EXPR``) fix parameters: the text
    returned is the spec's with them applied (:mod:`sosalgo.spec.overrides`). A method
    that changes with k is refused (one line naming ``sosalgo pep --steps``) unless the
    command takes one (``varying``)."""
    from sosalgo.steps import one_method

    spec, text = _spec_and_text(spec, spec_text, overrides)
    return (spec if varying else one_method(spec)), text


def analyzed_for_every_n(spec: Spec | str | Path,
                         overrides: Mapping[str, str] | None = None) -> bool:
    """Whether ``sosalgo analyze`` takes the spec as a method that changes with k (then
    :func:`sosalgo.runs.allk.allk_run` answers it, or refuses it in one line)."""
    from sosalgo.steps import changes_with_k

    if isinstance(spec, Spec):
        return changes_with_k(spec)
    path = Path(spec)
    if str(spec) == "-" or (path.exists() and not path.is_file()):
        return False  # a pipe (/dev/stdin) is read once, by the run
    found, _ = _spec_and_text(spec, None, overrides)
    return changes_with_k(found)


def _spec_and_text(spec: Spec | str | Path, spec_text: str | None,
                   overrides: Mapping[str, str] | None) -> tuple[Spec, str]:
    from sosalgo.spec import read_spec_text, spec_from_text
    from sosalgo.spec.overrides import apply_overrides

    if isinstance(spec, Spec):
        if spec_text is None:
            raise InputError(f"{spec.source}: a batch run needs the spec's text: pass a path "
                             "or spec_text")
        source, text = spec.source, spec_text
        if not overrides:
            return spec, spec_text
    else:
        source = str(spec)
        text = read_spec_text(spec) if spec_text is None else spec_text
    if overrides:
        text = apply_overrides(text, overrides, source)
    return spec_from_text(text, source=source), text


def set_field(overrides: Mapping[str, str] | None) -> dict[str, Any]:
    """The ``set`` field of a result document: the ``--set`` overrides it was computed
    with (``sosalgo verify`` applies them again); nothing without overrides."""
    return {"set": dict(overrides)} if overrides else {}


def _kappa_list(spec: Spec, kappa: Kappas) -> list[float]:
    if kappa is None:
        return list(spec.kappa)
    if isinstance(kappa, int | float | str) and not isinstance(kappa, bool):
        return [kappa_value(kappa)]
    return [kappa_value(k) for k in kappa]  # type: ignore[union-attr]


def record_kappas(rows: list[dict[str, Any]], kappas: Sequence[float]
                  ) -> list[dict[str, Any]]:
    """Each row with ``kappa_exact`` (and an irrational kappa's ``kappa_enclosure``): the
    exact value of the kappa it was computed at, which ``sosalgo verify`` proves about."""
    from sosalgo.kernel.kappa import kappa_fields

    given = {float(k): k for k in kappas}
    for r in rows:
        if isinstance(r.get("kappa"), int | float):
            r.update(kappa_fields(given.get(float(r["kappa"]), r["kappa"])))
    return rows


def kappa_value(kappa: float | str) -> float:
    """One kappa given to a run: a :class:`~sosalgo.kernel.kappa.Kappa` (from the spec or
    --kappa) kept with its exact value, a string read as written (``"10/3"``), a Python
    number as its float (whose exact value is its shortest decimal)."""
    from sosalgo.kernel.kappa import Kappa

    if isinstance(kappa, Kappa):
        return kappa
    if isinstance(kappa, str):
        from sosalgo.spec import parse_kappa

        return parse_kappa(kappa, "kappa", "value")[0]
    return float(kappa)


def _budget(max_memory: int | str | None, workers: int | None) -> int:
    """Set the run's memory budget (:mod:`sosalgo.kernel.budget`; None: the machine's default) and
    return the local workers it allows (a cap of an explicit ``workers`` said in one line)."""
    budget.set_max_memory(max_memory)
    return budget.announce_workers(workers)


def _figures(stem: Path) -> list[Path]:
    """The PNG and PDF written for a figure stem (they move with their CSV)."""
    return [stem.with_name(f"{stem.name}.{ext}") for ext in ("png", "pdf")]


def _rate_figure_stem(spec: Spec, out: Path, fams: Sequence[Any]) -> Path:
    """``<name>-rate`` for the family ``analyze`` takes by default, ``<name>-rate-<family>...``
    for any other choice (a rerun with another family keeps the first figure)."""
    default = inputs.select_families(spec, None, None, command="analyze")
    same = [describe_family(f) for f in fams] == [describe_family(f) for f in default]
    return rate_stem(out, spec.name, None if same else fams)


def analyze_run(spec: Spec | str | Path, kappa: Kappas = None, out_dir: str | Path = "outputs",
                tol: float = 1e-6, certificate: str | Sequence[str] | None = None,
                options: Mapping[str, Any] | None = None, workers: int | None = None,
                scheduler: str | None = None, restart: bool = False, progress: bool = True,
                plot: bool = True, verify: bool = False,
                spec_text: str | None = None, noise: bool = False,
                brackets: str = "quadratic", cycle_seconds: float = 5.0,
                max_memory: int | str | None = None,
                overrides: Mapping[str, str] | None = None) -> dict[str, Any]:
    """``sosalgo analyze``: one CSV per family, the rate figure, optional checks; returns
    the ``--json`` document (every row names its ``family``; Theorem 1's rows carry P and
    lambda beside rho, no ``certificate`` object).
    ``noise`` (``--noise``) adds the certified noise sensitivity to every row.
    ``brackets`` (quadratic, self-similar, none) and ``cycle_seconds`` (the cycle search's
    time per uncertified row, 0: none) choose the witnesses (:mod:`sosalgo.witnesses`).
    ``overrides`` (``--set``) fix parameters; the document records them in ``set``."""
    from sosalgo.batch.sweeps import csv_row_to_json, run_analysis_sweep
    from sosalgo.report import analysis as rep

    spec, text = spec_with_text(spec, spec_text, overrides)
    inputs.refuse_nonconvex(spec, linear_rates=True)
    if noise:  # one gradient call on F(m, L) only (sosalgo.sensitivity)
        from sosalgo.sensitivity.run import check_noise_spec

        check_noise_spec(spec)
    own = spec_family(spec)
    if own is not None:  # m: 0: the sublinear family's one constant, no kappa
        return _analyze_constant(spec, own, text, kappa, out_dir, plot, verify, restart,
                                 progress, max_memory, workers) | set_field(overrides)
    kappas = _kappa_list(spec, kappa)
    inputs.check_tol(tol, "--tol")
    from sosalgo.witnesses.rows import check_witness_options

    check_witness_options(brackets, cycle_seconds)
    fams = inputs.select_families(spec, certificate, options, command="analyze")
    inputs.check_kappa_points(spec, kappas)
    est = budget.sweep_estimate(f"analyze {spec.name} at {len(kappas)} kappas",
                                f"--kappa ({len(kappas)} values)", len(kappas), spec.n,
                                len(fams), _budget(max_memory, workers))
    workers = budget.check(est).workers if scheduler is None else workers
    out = inputs.out_dir(out_dir)
    check_scheduler(scheduler)
    plain = len(fams) == 1 and fams[0].is_default  # Theorem 1 alone: one CSV, no family columns
    stem = _rate_figure_stem(spec, out, fams)
    runs, figs = [], []
    for fam in fams:
        path = analysis_csv(out, spec.name, fam)
        with output_lock(path):
            rows = run_analysis_sweep(spec, text, kappas, path, tol, workers=workers,
                                      scheduler=scheduler, restart=restart, progress=progress,
                                      family=fam,
                                      companions=_figures(stem)
                                      if len(fams) == 1 else (), noise=noise, brackets=brackets,
                                      cycle_seconds=cycle_seconds)
            jrows = record_kappas([csv_row_to_json(spec, r, None if plain else fam)
                                   for r in rows], kappas)
            if plain and plot and len(jrows) >= 2:  # one point is not a curve
                figs = rep.analysis_figure(spec, jrows, stem)
        runs.append((fam, path, jrows))
    if not plain:
        figs = rep.families_figure(spec, runs, stem) if plot else []
    for fam, _, jrows in runs:
        for r in jrows:  # every row names its family (Theorem 1's too)
            r["family"] = fam.name
        if verify:
            rep.attach_checks(spec, jrows, out / "certificates", family=None if plain else fam)
    doc = {"kind": ANALYSIS_KIND, "spec": spec.name, "source": spec.source, "spec_text": text,
           "tol": tol, "csv": str(runs[0][1])} | set_field(overrides)
    if not plain:
        doc["csvs"] = {f.name: str(p) for f, p, _ in runs}
    doc |= {"figures": [str(p) for p in figs],
            "rows": [r for _, _, jrows in runs for r in jrows], "estimate": est.to_dict()}
    return doc | (vouch_run(spec, doc) if verify else {})


def _analyze_constant(spec: Spec, fam: Any, text: str, kappa: Kappas, out_dir: str | Path,
                      plot: bool, verify: bool, restart: bool, progress: bool,
                      max_memory: int | str | None, workers: int | None) -> dict[str, Any]:
    """``analyze`` of a sublinear spec: the analysis sweep with its family ``fam`` (one
    row keyed by L in ``<name>-analysis.csv``), the bound figure ``<name>-rate``, with
    ``verify`` the exact proof of each row (proof documents in ``out_dir/certificates``)."""
    from sosalgo.batch.sweeps import csv_row_to_json, run_analysis_sweep
    from sosalgo.report.analysis import attach_constant_checks, sublinear_figure

    _no_kappa(spec, kappa)
    est = budget.check(budget.sweep_estimate(
        f"analyze {spec.name}", "", 1, spec.n, 1, _budget(max_memory, workers),
        seconds_each=budget.SUBLINEAR_SECONDS))
    out = inputs.out_dir(out_dir)
    path, stem = analysis_csv(out, spec.name, None), rate_stem(out, spec.name)
    with output_lock(path):
        rows = run_analysis_sweep(spec, text, [], path, 0.0, restart=restart,
                                  progress=progress, family=fam,
                                  companions=_figures(stem))
        jrows = [csv_row_to_json(spec, r, fam) for r in rows]
        figs = sublinear_figure(spec, jrows[0], stem) if plot else []
    if verify:
        attach_constant_checks(spec, jrows, out / "certificates")
    doc = {"kind": ANALYSIS_KIND, "spec": spec.name, "source": spec.source, "spec_text": text,
           "csv": str(path), "figures": [str(p) for p in figs], "rows": jrows,
           "estimate": est.to_dict()}
    return doc | (vouch_run(spec, doc) if verify else {})


def _design_options(spec: Spec, kappas: list[float], free: str | Sequence[str] | None,
                    fam: Any, settings: Mapping[str, Any]) -> dict[str, Any]:
    """The design options checked (free names, gap, time limit, method), as the sweep
    takes them; nothing is computed or written."""
    from sosalgo.batch.sweeps import family_options
    from sosalgo.design_search.polymodel import check_polynomial

    inputs.check_method(settings["method"], settings["scalarize"], fam, "--method")
    names = inputs.free_names(spec, free)
    inputs.check_gap(settings["gap"], "--gap")
    inputs.check_time_limit(settings["time_limit"], "--time-limit")
    inputs.check_kappa_points(spec, kappas)
    inputs.parameter_boxes(spec, kappas, names, design=True)
    check_polynomial(spec, names)
    return {"free": names, **settings, "certificate": family_options(fam)}


def design_run(spec: Spec | str | Path, kappa: Kappas = None, out_dir: str | Path = "outputs",
               free: str | Sequence[str] | None = None, scalarize: str = "pmi",
               order: int | None = None, gap: float = 1e-4, time_limit: float = 120.0,
               method: str = "dual", certificate: str | None = None,
               options: Mapping[str, Any] | None = None, workers: int | None = None,
               scheduler: str | None = None, restart: bool = False, progress: bool = True,
               verify: bool = False, progress_steps: bool = False,
               spec_text: str | None = None, objective: str = "rate",
               max_rate: float | None = None, max_noise: float | None = None,
               max_memory: int | str | None = None,
               overrides: Mapping[str, str] | None = None) -> dict[str, Any]:
    """``sosalgo design``: the design sweep over kappa into ``<name>-design[...].csv``;
    returns ``{"spec", "source", "spec_text", "csv", "figures", "rows"}``, one design
    document per kappa (``--json`` prints the single document for one kappa).
    ``objective="noise"`` with ``max_rate`` (or ``max_noise`` with the default objective)
    designs with the noise sensitivity (:mod:`sosalgo.design_search.objectives`) into
    ``<name>-design[...]-min-noise.csv`` (``-min-rate.csv``). ``overrides`` (``--set``)
    fix parameters (a fixed parameter is not free); every document records them in
    ``set``."""
    from sosalgo.batch.sweeps import design_csv_to_json, run_design_sweep
    from sosalgo.design_search.objectives import check_objective
    from sosalgo.report import design as rep

    spec, text = spec_with_text(spec, spec_text, overrides)
    inputs.refuse_nonconvex(spec, linear_rates=True)  # operators with m > 0: no lower bound
    own = spec_family(spec)  # m: 0: the sublinear family's constant (no kappa)
    check_objective(spec, [] if own is not None else _kappa_list(spec, kappa), objective,
                    max_rate, max_noise)
    two = objective != "rate" or max_noise is not None  # a noise objective or cap
    if own is not None:  # minimize the constant
        return _design_constant(spec, text, kappa, out_dir, free, time_limit, verify,
                                restart, progress, max_memory) | set_field(overrides)
    fam = inputs.select_families(spec, certificate, options, single=True,
                                 command="noise" if two else "design")[0]
    kappas = _kappa_list(spec, kappa)
    opts = _design_options(spec, kappas, free, fam, {
        "scalarize": scalarize, "order": order, "gap": gap, "time_limit": time_limit,
        "method": method})
    est = budget.check(budget.design_estimate(
        f"design {spec.name} at {len(kappas)} kappa{'s' * (len(kappas) > 1)}",
        f"--kappa ({len(kappas)} values)", len(kappas), time_limit,
        _budget(max_memory, workers)))
    workers = est.workers if scheduler is None else workers
    out = inputs.out_dir(out_dir)
    check_scheduler(scheduler)
    one = len(kappas) == 1
    opts |= {"progress_steps": one and progress_steps,  # one kappa: workers go inside
             "inner_workers": (workers or os.cpu_count() or 1) if one and scheduler is None
             else 1}
    stem = design_stem(out, spec.name, fam)
    if two:  # only then: a rate design's settings (and files) stay as they are without
        opts |= {"objective": objective, "max_rate": max_rate, "max_noise": max_noise}
        stem = stem.with_name(stem.name + ("-min-noise" if objective == "noise"
                                           else "-min-rate"))
    csv_path = stem.with_name(stem.name + ".csv")
    with output_lock(csv_path):
        rows, fresh = run_design_sweep(spec, text, kappas, csv_path, opts, workers=workers,
                                       scheduler=scheduler, restart=restart,
                                       progress=progress, companions=_figures(stem))
        docs = record_kappas([fresh.get(float(r["kappa"]))
                              or design_csv_to_json(spec, opts["free"], r, fam) for r in rows],
                             kappas)
        for d in docs:
            _design_certificates(csv_path, d)
        for d in docs:  # each a whole design document (``--json`` prints it alone)
            d["kind"], d["source"], d["spec_text"] = DESIGN_KIND, spec.source, text
            d.update(set_field(overrides))
        how = ("dual certificates" if method == "dual" else f"moment relaxation, {scalarize}")
        figs = (rep.design_figure(spec, opts["free"], rows, docs, stem, fam, how)
                if len(docs) > 1 else [])
    if verify:
        from sosalgo.proofs.results import verify_document_rows

        checks = verify_document_rows(spec, docs, out / "certificates")
        for d, v in zip(docs, checks, strict=True):
            d["verification"] = v
    return {"kind": DESIGN_KIND, "spec": spec.name, "source": spec.source, "spec_text": text,
            "csv": str(csv_path), "figures": [str(p) for p in figs], "rows": docs,
            "estimate": est.to_dict()} | set_field(overrides) | (
        _vouch_designs(spec, docs) if verify else {})


def _vouch_designs(spec: Spec, docs: list[dict[str, Any]]) -> dict[str, Any]:
    """The claim ledger of each design document (``design --json`` prints one alone), added
    to it (:func:`sosalgo.documents.vouch_run`), and its totals for the run's document."""
    claims: dict[str, int] = {}
    unbacked = []
    for i, d in enumerate(docs):
        d |= vouch_run(spec, d)
        claims = {k: claims.get(k, 0) + v for k, v in d["claims"].items()}
        unbacked += [e | {"row": i} for e in d["unbacked"]]
    return {"claims": claims, "vouched": all(d["vouched"] for d in docs),
            "unbacked": unbacked}


def _no_kappa(spec: Spec, kappa: Kappas) -> None:
    """A sublinear spec (m: 0) has no kappa: one given is refused."""
    if kappa not in (None, [], ()):
        raise InputError(f"{spec.source}: --kappa: undefined for a sublinear spec (m: 0)")


def _design_constant(spec: Spec, text: str, kappa: Kappas, out_dir: str | Path,
                     free: str | Sequence[str] | None, time_limit: float, verify: bool,
                     restart: bool, progress: bool,
                     max_memory: int | str | None) -> dict[str, Any]:
    """``design`` of a sublinear spec: minimize the certified constant over the box
    (:func:`sosalgo.sublinear_design.sublinear_design`), simulate the design, write
    ``<name>-design.csv`` (one row, in this process); the document holds that row."""
    from sosalgo.batch.sweeps import run_constant_design
    from sosalgo.report.analysis import attach_constant_checks

    _no_kappa(spec, kappa)
    inputs.check_time_limit(time_limit, "--time-limit")
    est = budget.check(budget.design_estimate(  # one process: no workers
        f"design {spec.name}", "", 1, time_limit, _budget(max_memory, 1)))
    names = inputs.free_names(spec, free)
    out = inputs.out_dir(out_dir)
    path = out / f"{spec.name}-design.csv"
    row = run_constant_design(spec, text, names, time_limit, path, restart, progress)
    row |= {"kind": DESIGN_KIND, "spec": spec.name, "source": spec.source,
            "spec_text": text}  # self-contained
    if verify:
        attach_constant_checks(spec, [row], out / "certificates")
    return {"kind": DESIGN_KIND, "spec": spec.name, "source": spec.source, "spec_text": text,
            "csv": str(path), "figures": [], "rows": [row], "estimate": est.to_dict()} | (
        _vouch_designs(spec, [row]) if verify else {})


def _grid_constant(spec: Spec, fam: Any, text: str, kappa: Kappas, out_dir: str | Path,
                   points: int,
                   free: str | Sequence[str] | None, workers: int | None,
                   scheduler: str | None, restart: bool, progress: bool,
                   max_memory: int | str | None) -> dict[str, Any]:
    """``grid`` of a sublinear spec: the certified constant at every point of a grid over
    the free parameters' box, row by row into ``<name>-grid.csv`` (resumable, on
    ``workers`` processes or a Dask ``scheduler`` like every grid)."""
    from sosalgo.batch.sweeps import run_grid
    from sosalgo.model import parameter_box

    _no_kappa(spec, kappa)
    names = inputs.free_names(spec, free)
    est = _grid_budget(spec, names, points, 1, max_memory, workers)
    workers = est.workers if scheduler is None else workers
    box = parameter_box(spec, float("nan"), names)
    out = inputs.out_dir(out_dir)
    if scheduler is not None:
        check_scheduler(scheduler)
    path = out / f"{spec.name}-grid.csv"
    rows = run_grid(spec, text, float("nan"), names, box, points, path, 0.0,
                    workers=workers, scheduler=scheduler, restart=restart,
                    progress=progress, family=fam)
    constants = [float(r["constant"]) for r in rows if r["constant"] != ""]
    return {"kind": GRID_KIND, "spec": spec.name, "rate_type": fam.rate_type, "free": names,
            "csv": str(path), "best": min(constants, default=None), "grids": [],
            "estimate": est.to_dict()}


DESIGN_CERTIFICATES = ("bound_certificate", "values_certificate")


def _design_certificates(csv_path: Path, doc: dict[str, Any]) -> None:
    """The certificates a design row's CSV cells have no room for (the proofs of its
    lower bound, the certificate of its rate at the spec's values) kept beside the CSV,
    ``<csv stem>-k<kappa>-certificates.json``: written with a fresh result, attached
    again to a result read back from the CSV when they are for its numbers (``sosalgo
    verify`` re-proves them either way). Called under the CSV's output lock."""
    from sosalgo.kinds import DESIGN_CERTIFICATES_KIND
    from sosalgo.proofs.exact import write_certificate
    from sosalgo.schema import kappa_label

    path = csv_path.with_name(f"{csv_path.stem}-k{kappa_label(doc['kappa'])}"
                              "-certificates.json")
    key = {k: doc.get(k) for k in ("lower_bound", "rho_at_values", "theta", "free")}
    if any(k in doc for k in DESIGN_CERTIFICATES):
        write_certificate({"kind": DESIGN_CERTIFICATES_KIND, "for": key,
                           **{k: doc.get(k) for k in DESIGN_CERTIFICATES}}, path)
        return
    try:
        kept = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return
    if isinstance(kept, dict) and kept.get("for") == json.loads(json.dumps(key)):
        doc.update({k: kept[k] for k in DESIGN_CERTIFICATES if kept.get(k) is not None})


def grid_run(spec: Spec | str | Path, kappa: Kappas, out_dir: str | Path = "outputs",
             points: int = 60, free: str | Sequence[str] | None = None, tol: float = 1e-6,
             certificate: str | None = None, options: Mapping[str, Any] | None = None,
             workers: int | None = None, scheduler: str | None = None, restart: bool = False,
             progress: bool = True, spec_text: str | None = None,
             max_memory: int | str | None = None,
             overrides: Mapping[str, str] | None = None) -> dict[str, Any]:
    """``sosalgo grid``: one CSV (and figure, for one or two free parameters) per kappa;
    returns ``{"spec", "free", "fixed", "grids"}`` (``fixed``: the parameters that are not
    free, with their values at each kappa in the grid entries; ``set``: the ``--set``
    overrides, when given)."""
    from sosalgo.batch.sweeps import run_grid
    from sosalgo.kernel.kappa import kappa_fields
    from sosalgo.model import parameter_values
    from sosalgo.report import grid as rep
    from sosalgo.schema import GRID_COLUMNS, grid_fixed

    spec, text = spec_with_text(spec, spec_text, overrides)
    inputs.refuse_nonconvex(spec)
    own = spec_family(spec)
    if own is not None:  # m: 0: the sublinear family's constant on the grid (no kappa)
        return _grid_constant(spec, own, text, kappa, out_dir, points, free, workers,
                              scheduler, restart, progress, max_memory) | set_field(overrides)
    if kappa in (None, [], ()):
        raise InputError("--kappa: required (one or more condition numbers)")
    kappas = _kappa_list(spec, kappa)
    names = inputs.free_names(spec, free)
    inputs.check_grid_points(points, len(names))
    for p in names + grid_fixed(spec, names):
        if p in GRID_COLUMNS:
            raise InputError(f"{spec.source}: parameters.{p}: name clashes with a grid column")
    inputs.check_tol(tol, "--tol")
    fam = inputs.select_families(spec, certificate, options, single=True, command="grid")[0]
    boxes = inputs.parameter_boxes(spec, kappas, names)
    est = _grid_budget(spec, names, points, len(dict.fromkeys(kappas)), max_memory, workers)
    workers = est.workers if scheduler is None else workers
    out = inputs.out_dir(out_dir)
    check_scheduler(scheduler)
    docs = []
    for k in dict.fromkeys(kappas):
        stem = grid_stem(out, spec.name, k, fam)
        csv_path = stem.with_name(stem.name + ".csv")
        with output_lock(csv_path):
            rows = run_grid(spec, text, k, names, boxes[k], points, csv_path, tol,
                            workers=workers, scheduler=scheduler, restart=restart,
                            progress=progress, companions=_figures(stem), family=fam)
            rho = rep.grid_rates(rows)
            figs = ([] if len(names) > 2 else
                    rep.grid_plot(spec, k, names, boxes[k], points, rho, stem))
        values = parameter_values(spec, k)
        docs.append(rep.grid_document(float(k), csv_path, figs, rows, rho, names)
                    | kappa_fields(k)
                    | {"fixed": {p: values[p] for p in grid_fixed(spec, names)}})
    return {"kind": GRID_KIND, "spec": spec.name, "free": names, "fixed": grid_fixed(spec, names),
            "grids": docs, "estimate": est.to_dict()} | set_field(overrides)


def _grid_budget(spec: Spec, names: list[str], points: int, kappas: int,
                 max_memory: int | str | None, workers: int | None) -> budget.Estimate:
    """The estimate of a grid (every point of every axis at every kappa; a sublinear
    spec's points cost more each), checked against the memory budget."""
    inputs.check_grid_points(points, len(names))
    total = points ** len(names) * kappas
    return budget.check(budget.grid_estimate(
        f"grid {spec.name} of {total} points", f"--points {points}", total, spec.n,
        _budget(max_memory, workers),
        seconds_each=None if spec_family(spec) is None else budget.SUBLINEAR_SECONDS))


def _has_rates(spec: Spec) -> bool:
    """Whether a Lyapunov family may certify the spec's rate (not a spec that only
    ``sosalgo pep`` answers: a finite sum, Bregman or inexact steps, a nonconvex or
    Gram-level class)."""
    from sosalgo.certificates import inhomogeneous_functions
    from sosalgo.inputs import refuse_nonconvex

    if inhomogeneous_functions(spec):
        return False
    try:
        refuse_nonconvex(spec, linear_rates=True)
    except InputError:
        return False
    return True


def table1_run(specs: Sequence[str | Path] = (), kappa: Sequence[float] = (),
               tol: float = 1e-6, out_dir: str | Path = "outputs",
               certificate: str | None = None,
               options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``sosalgo table1``: each spec's certified rate beside its closed form, written to
    ``table1.csv``; returns ``{"rows", "columns", "csv"}``. Default specs: ``specs/*.yaml``,
    else the shipped examples."""
    from sosalgo.batch.sweeps import kappa_settings
    from sosalgo.runs.table1 import table1_rows, write_table1
    from sosalgo.spec import read_spec_text, spec_from_text

    inputs.check_tol(tol, "--tol")
    paths = [str(p) for p in specs] or sorted(str(p) for p in Path("specs").glob("*.yaml"))
    if paths:
        texts = {p: read_spec_text(p) for p in paths}
    else:  # outside a checkout: the example specs shipped with sosalgo
        from sosalgo.kernel.resources import example_specs

        texts = {f"examples/{name}.yaml": f.read_text(encoding="utf-8")
                 for name, f in example_specs().items()}
    parsed = [spec_from_text(t, source=src) for src, t in texts.items()]
    # m: 0: no kappa, no linear rate; what no Lyapunov family takes: sosalgo pep only
    kept = [s for s in parsed if spec_family(s) is None and _has_rates(s)]
    if not kept and parsed:
        raise InputError(f"--specs: {', '.join(s.source for s in parsed)}: no spec with a "
                         "linear rate (m: 0 specs have no kappa; Table 1 compares rates)")
    if not kept:
        raise InputError("--specs: no spec files given and none in specs/")
    parsed = kept
    kappas = [kappa_value(k) for k in kappa] or [2.0, 10.0, 100.0]
    chosen = certificate is not None or any(v is not None for v in (options or {}).values())
    fams = [inputs.select_families(s, certificate, options, applicable_only=True) if chosen
            else [None] for s in parsed]
    rows, cols = table1_rows(parsed, kappas, tol, fams)
    settings = {"job": "table1", "specs": texts, "kappa": [float(k) for k in kappas],
                "tol": tol, "certificate": certificate, "lag": None,  # lag: None unless given
                **dict(options or {})} | kappa_settings(kappas)
    path = write_table1(inputs.out_dir(out_dir), rows, cols, settings)
    return {"kind": TABLE1_KIND, "rows": record_kappas(rows, kappas), "columns": cols,
            "csv": str(path)}
