"""Batch jobs built on :mod:`sosalgo.batch.executor`: kappa sweeps of the analysis (and grids).

Each job has a module-level chunk function (runs in workers), a column list, and a
driver that writes rows to a resumable CSV as they finish.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.analysis import AnalysisResult, analyze_spec, spec_family
from sosalgo.batch.executor import Progress, note, run_batch
from sosalgo.certificates import CertificateFamily, describe_family, family_from_description
from sosalgo.certificates.sublinear import SUBLINEAR, SublinearFamily
from sosalgo.kernel.kappa import Kappa
from sosalgo.kernel.phases import begin_task, show_phase
from sosalgo.kernel.solvers import DEFAULT_SOLVERS
from sosalgo.model import ModelError, parameter_values
from sosalgo.schema import (
    analysis_columns,
    design_columns,
    grid_columns,
    grid_fixed,
    kappa_label,
    p_columns,
)
from sosalgo.spec import Spec, spec_from_text
from sosalgo.spec.references import reference_values
from sosalgo.store import ResumableCSV

__all__ = [
    "analysis_columns",
    "cached_spec",
    "seed_spec",
    "design_columns",
    "grid_columns",
    "p_columns",
    "analysis_chunk",
    "run_analysis_sweep",
    "csv_row_to_json",
]

_SPECS: dict[tuple[str, str], Spec] = {}


def seed_spec(spec: Spec, text: str) -> None:
    """Let in-process chunks reuse the caller's parsed spec (no second parse)."""
    _SPECS.clear()
    _SPECS[(text, spec.source)] = spec


def cached_spec(text: str, source: str) -> Spec:
    """Per-process cache of parsed specs (workers get the YAML text, not objects)."""
    key = (text, source)
    if key not in _SPECS:
        _SPECS.clear()
        _SPECS[key] = spec_from_text(text, source)
    return _SPECS[key]


def p_entries(n: int, P: Any) -> dict[str, float | None]:
    """CSV cells P11, P12, ... of a certificate matrix (None when there is none)."""
    pairs = [(i, j) for i in range(n) for j in range(i, n)]
    return {c: None if P is None else float(np.asarray(P)[i, j])
            for c, (i, j) in zip(p_columns(n), pairs, strict=True)}


def p_size(spec: Spec, fam: CertificateFamily | None) -> int:
    """Side of the family's P (n for Theorem 1, and when no family is given)."""
    return spec.n if fam is None else fam.p_size(spec.n)


# a family as plain data for workers and settings files (its name and set options)
family_options = describe_family
family_from_options = family_from_description


def _family_settings(fam: CertificateFamily) -> dict[str, Any] | None:
    """The family's entry in a run's settings: None for the default family without options
    (so that Theorem 1 runs keep their settings files)."""
    desc = describe_family(fam)
    return None if fam.is_default and desc == {"family": fam.name} else desc


def result_row(spec: Spec, res: AnalysisResult,
               family: CertificateFamily | None = None) -> dict[str, Any]:
    """A CSV row of the analysis table."""
    row: dict[str, Any] = {
        "kappa": float(res.kappa),
        "rho": res.rho,
        "certified": res.certified,
        "lambda": res.lam,
        "max_eig_M": res.max_eig_M,
        "min_eig_P": res.min_eig_P,
        "solves": res.solves,
        "seconds": round(res.seconds, 6),
        "solver": res.solver,
        "rho_infeasible": res.rho_infeasible,
        "error": None,
        "warning": res.warning,
        "rate_type": "linear",
        "family": res.family,
    }
    row.update(_certificate_cells(spec, family, res.kappa, res.P, res.certificate))
    from sosalgo.witnesses.rows import EMPTY, witness_cells

    row.update(witness_cells({k: getattr(res, k, None) for k in EMPTY}))
    return row


def _with_witnesses(spec: Spec, kappa: float, theta: Any, res: AnalysisResult,
                    opts: dict[str, Any]) -> AnalysisResult:
    """``res`` with its cycle or rate bracket (:mod:`sosalgo.witnesses`)."""
    import dataclasses

    from sosalgo.witnesses.rows import witness_fields

    return dataclasses.replace(res, **witness_fields(spec, kappa, theta, res.certified,
                                                     res.rho, **opts))


def _certificate_cells(spec: Spec, family: CertificateFamily | None, kappa: float, P: Any,
                       cert: dict[str, Any] | None) -> dict[str, Any]:
    """The cells every row shares: P's entries, the references at kappa, and a family's
    own parts (families other than Theorem 1)."""
    cells: dict[str, Any] = p_entries(p_size(spec, family), P)
    cells.update(reference_values(spec, kappa))
    if family is not None:
        cells.update(family.csv_cells(spec.n, cert))
    return cells


def _worker_setup(spec_text: str, source: str, options: dict[str, Any]):
    """(spec, family) in a worker: the spec parsed from its text, the family asked for."""
    spec = cached_spec(spec_text, source)
    return spec, family_from_options(options.get("certificate")) or spec_family(spec)


def kappa_settings(kappas: Sequence[float]) -> dict[str, Any]:
    """The settings entry of kappas whose exact value is not their float's shortest
    decimal (``10/3``, ``5*sqrt(2)``): a row proven about another value is not resumed.
    Nothing for plain decimals, so their settings files stay as they are."""
    from fractions import Fraction

    from sosalgo.kernel.kappa import exact_kappa, plain_kappa

    def plain(k: float) -> bool:  # no sympy for plain numbers
        return plain_kappa(k) == Fraction(repr(float(k)))

    odd = [str(exact_kappa(k)) for k in kappas if isinstance(k, Kappa) and not plain(k)]
    return {"kappa_exact": odd} if odd else {}


def _run_chunk(spec_text: str, source: str, options: dict[str, Any],
               chunk: list[dict[str, Any]], one: Any) -> list[dict[str, Any]]:
    """Worker loop shared by the jobs: ``one(spec, fam, kappa, task)`` makes a row; a
    point the model cannot evaluate gives a row with its error (and the references)."""
    spec, fam = _worker_setup(spec_text, source, options)
    rows = []
    for task in chunk:
        kappa = task["kappa"] if isinstance(task["kappa"], Kappa) else float(task["kappa"])
        begin_task(f"kappa {kappa:g}")
        try:
            row = one(spec, fam, kappa, task)
        except ModelError as exc:  # e.g. a grid point outside a function's domain
            row = {"kappa": kappa, "certified": False, "error": str(exc), "family": fam.name}
            row.update(reference_values(spec, kappa))
            row.update(fam.csv_cells(spec.n, None))
        row.update(task.get("extra", {}))
        rows.append(row)
    return rows


def analysis_chunk(
    spec_text: str, source: str, options: dict[str, Any], chunk: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    """Worker: analysis at each task's kappa (and parameter overrides in task['theta'])."""

    def one(spec: Spec, fam: CertificateFamily, kappa: float, task: dict) -> dict[str, Any]:
        res = analyze_spec(spec, kappa, task.get("theta"), tol=options["tol"],
                           solvers=options.get("solvers", DEFAULT_SOLVERS), family=fam)
        if options.get("witnesses") is not None:  # analyze: cycles, rate brackets
            show_phase("witnessed lower bound" if res.certified else "cycle search")
            res = _with_witnesses(spec, kappa, task.get("theta"), res, options["witnesses"])
        row = result_row(spec, res, fam)
        if options.get("noise"):  # analyze --noise: sosalgo.sensitivity
            from sosalgo.sensitivity.run import analyze_noise, noise_cells

            show_phase("noise sensitivity")
            row.update(noise_cells(analyze_noise(spec, kappa, task.get("theta"))))
        return row

    return _run_chunk(spec_text, source, options, chunk, one)


def run_store(
    store: ResumableCSV, tasks: list[dict[str, Any]], label: str, progress: bool,
    fn: Any, spec_text: str, source: str, options: dict[str, Any],
    on_row: Any, workers: int | None, scheduler: str | None,
) -> None:
    """Open (lock, reconcile) the store, then run the tasks not done yet into it."""
    with store:
        todo = [t for t in tasks if not store.is_done(t)]
        bar = Progress(len(tasks), label, progress, done=len(tasks) - len(todo),
                       resumed_from=store.path)
        try:
            run_batch(fn, spec_text, source, options, todo, on_row or store.write,
                      workers=workers, scheduler=scheduler, progress=bar)
        finally:
            bar.close()


def run_analysis_sweep(
    spec: Spec,
    spec_text: str,
    kappas: Sequence[float],
    out_csv: Path,
    tol: float,
    workers: int | None = None,
    scheduler: str | None = None,
    restart: bool = False,
    progress: bool = True,
    solvers: Sequence[str] | None = None,
    family: CertificateFamily | None = None,
    companions: Sequence[Path] = (),
    noise: bool = False,
    brackets: str = "quadratic",
    cycle_seconds: float = 5.0,
) -> list[dict[str, str]]:
    """Analysis over kappa, resumable; returns the rows (as CSV strings) in kappa order.

    ``family`` overrides the spec's certificate family (recorded in the settings unless it
    is Theorem 1, so that Theorem 1 runs keep their settings files); ``noise`` adds the
    columns of ``--noise`` (recorded in the settings only when on); ``brackets`` (quadratic,
    self-similar, none) and ``cycle_seconds`` (0: no cycle search) choose the witnesses of
    :mod:`sosalgo.witnesses` (recorded when not the defaults)."""
    fam = family or spec_family(spec)
    if isinstance(fam, SublinearFamily):  # m: 0: one row at L, the family's cells
        return _run_constant_sweep(spec, spec_text, fam, out_csv, workers, scheduler,
                                   restart, progress, companions)
    options: dict[str, Any] = {"tol": tol, "certificate": family_options(fam)}
    if solvers:
        options["solvers"] = tuple(solvers)
    settings = {"job": "analyze", "spec": spec_text, "tol": tol,
                "solvers": list(solvers) if solvers else None,
                "kappa": [float(k) for k in kappas]} | kappa_settings(kappas)
    if _family_settings(fam) is not None:
        settings["certificate"] = _family_settings(fam)
    if noise:
        options["noise"] = settings["noise"] = True
    options["witnesses"] = {"brackets": brackets, "cycle_seconds": cycle_seconds}
    if (brackets, cycle_seconds) != ("quadratic", 5.0):  # the defaults keep old settings
        settings["witnesses"] = options["witnesses"]
    store = ResumableCSV(out_csv, analysis_columns(spec, fam, noise), ["kappa"], settings,
                         restart=restart, companions=companions)
    tasks = [{"kappa": k if isinstance(k, Kappa) else float(k)} for k in kappas]
    seed_spec(spec, spec_text)
    run_store(store, tasks, f"analyze {spec.name}", progress, analysis_chunk, spec_text,
               spec.source, options, None, workers, scheduler)
    by_key = {store.row_key({"kappa": float(k)}): None for k in kappas}
    rows = [r for r in store.rows() if store.row_key(r) in by_key]
    return sorted(rows, key=lambda r: float(r["kappa"]))


# --------------------------------------------------------------------------- sublinear rows
def sublinear_simulation(spec: Spec, constant: float | None,
                         theta: dict[str, float] | None = None) -> dict[str, Any] | None:
    """The simulation check of a certified constant (evidence, not proof:
    :mod:`sosalgo.proofs.simulate_sublinear`), or None when nothing is certified."""
    from sosalgo.method import bind
    from sosalgo.proofs.simulate_sublinear import simulate_sublinear

    if constant is None:
        return None
    return simulate_sublinear(bind(spec, None, theta), constant).to_dict()


def sublinear_row(spec: Spec) -> dict[str, Any]:
    """The analysis of a sublinear spec as a JSON row, with the references' values."""
    from sosalgo.analysis import analyze_sublinear

    row = analyze_sublinear(spec).to_dict()
    row["references"] = reference_values(spec, float("nan"))
    return row


def sublinear_chunk(spec_text: str, source: str, options: dict[str, Any],
                    chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: the certified constant of a sublinear spec, as the family's CSV cells."""
    spec = cached_spec(spec_text, source)
    return [SUBLINEAR.analysis_cells(spec, sublinear_row(spec)) for _ in chunk]


def _run_constant_sweep(spec: Spec, spec_text: str, fam: SublinearFamily, out_csv: Path,
                        workers: int | None, scheduler: str | None, restart: bool,
                        progress: bool, companions: Sequence[Path]) -> list[dict[str, str]]:
    """The analysis of a sublinear spec (its one row, keyed by L), resumable."""
    store = ResumableCSV(out_csv, fam.analysis_columns(spec), list(fam.key),
                         {"job": "analyze", "spec": spec_text}, restart=restart,
                         companions=companions)
    tasks = fam.analysis_tasks(spec)
    seed_spec(spec, spec_text)
    run_store(store, tasks, f"analyze {spec.name}", progress, sublinear_chunk, spec_text,
              spec.source, {}, None, workers, scheduler)
    wanted = {store.row_key(t) for t in tasks}
    return [r for r in store.rows() if store.row_key(r) in wanted]


def _num(v: str) -> float | None:
    return None if v in ("", None) else float(v)


def csv_row_to_json(spec: Spec, row: dict[str, str],
                    family: CertificateFamily | SublinearFamily | None = None
                    ) -> dict[str, Any]:
    """The JSON form of an analysis row (the `rows` entries of ``analyze --json``).

    A family other than Theorem 1 adds ``family`` and ``certificate`` (its named parts);
    the sublinear family reads its own cells (and the constant is simulated again)."""
    if isinstance(family, SublinearFamily):
        out = family.analysis_json(spec, row)
        return out | {"simulation": sublinear_simulation(spec, out["constant"])}
    n = p_size(spec, family)
    P = None
    if row.get("P11", "") != "":
        P = np.zeros((n, n))  # a certificate of a smaller lag fills only its leading block
        for i in range(n):
            for j in range(i, n):
                cell = row[f"P{i + 1}{j + 1}"]
                P[i, j] = P[j, i] = float(cell) if cell != "" else 0.0
    return {
        "kappa": float(row["kappa"]),
        "rho": _num(row["rho"]),
        "certified": row["certified"] == "true",
        "P": None if P is None else P.tolist(),
        "lambda": _num(row["lambda"]),
        "max_eig_M": _num(row["max_eig_M"]),
        "min_eig_P": _num(row["min_eig_P"]),
        "solves": int(row["solves"]) if row.get("solves") else None,
        "seconds": _num(row["seconds"]),
        "solver": row.get("solver") or None,
        "rho_infeasible": _num(row.get("rho_infeasible", "")),
        "error": row.get("error") or None,
        "warning": row.get("warning") or None,
        "rate_type": row.get("rate_type") or "linear",
        "references": {name: _num(row[name]) for name in spec.references},
    } | _family_json(spec, row, family, P) | _noise_json(row) | _witness_json(row)


def _witness_json(row: dict[str, str]) -> dict[str, Any]:
    """``rho_lower``, ``rho_lower_kind``, ``rho_lower_witness`` and ``cycle`` of a row."""
    from sosalgo.witnesses.rows import witness_json

    return witness_json(row)


def _noise_json(row: dict[str, str]) -> dict[str, Any]:
    """The ``--noise`` fields of a row (none when the run had no ``--noise``)."""
    if "noise_check" not in row:
        return {}
    from sosalgo.sensitivity.run import noise_json

    return noise_json(row)


def _family_json(spec: Spec, row: dict[str, str], family: CertificateFamily | None,
                 P: Any) -> dict[str, Any]:
    """``family``, ``certificate`` and ``lag`` of a row of a family with its own columns;
    the top-level ``P`` is the certificate's whole P (as in ``AnalysisResult.to_dict``),
    not only the leading block the common columns hold."""
    if family is None or not family.csv_columns(spec.n):
        return {}
    cert = family.cert_from_csv(spec.n, row, None if P is None else P.tolist())
    out: dict[str, Any] = {"family": family.name, "certificate": cert}
    if cert is not None and cert.get("P") is not None:
        out["P"] = np.asarray(cert["P"], dtype=float).tolist()
    if row.get("lag", "") != "":
        out["lag"] = int(row["lag"])
    return out


# --------------------------------------------------------------------------- design sweeps
RUNTIME_OPTIONS = ("progress_steps", "inner_workers")  # how to run, not what: not settings


def design_row(spec: Spec, res: Any, family: CertificateFamily | None = None) -> dict[str, Any]:
    """A CSV row from a :class:`sosalgo.design_search.DesignResult`."""
    row: dict[str, Any] = {
        "kappa": res.kappa, "lower_bound": res.lower_bound, "rho_certified": res.rho_certified,
        "gap": res.gap, "gap_met": res.gap_met, "rho_at_values": res.rho_at_values,
        "lambda": res.certificate.get("lambda"),
        "scalarize": res.relaxation.get("scalarize"), "order": res.relaxation.get("order"),
        "status": res.relaxation.get("status"), "flat": res.relaxation.get("flat"),
        "ranks": " ".join(map(str, res.relaxation.get("ranks", []))),
        "seconds": round(res.seconds, 4), "steps": " | ".join(res.steps), "error": None,
        "method": res.method, "floor": res.floor, "time_limited": res.time_limited,
    }
    for p, v in res.theta.items():
        row[f"theta_{p}"] = v
    row.update(_certificate_cells(spec, family, res.kappa, res.certificate.get("P"),
                                  res.certificate or None))
    return row


def design_chunk(
    spec_text: str, source: str, options: dict[str, Any], chunk: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    """Worker: one design per task's kappa."""
    from sosalgo.design_search import design

    def one(spec: Spec, fam: CertificateFamily, kappa: float, task: dict) -> dict[str, Any]:
        on_step = None
        if options.get("progress_steps"):
            def on_step(msg: str) -> None:
                note(f"  [kappa {kappa:g}] {msg}")
        if "objective" in options:  # --objective noise / --max-noise: design.objectives
            from sosalgo.design_search.objectives import objective_design

            res = objective_design(spec, kappa, options["objective"], options["max_rate"],
                                   options["max_noise"], options["free"], fam,
                                   options["time_limit"], options.get("inner_workers"),
                                   on_step)
            return {**design_row(spec, res, fam), **res.objective_cells(),
                    "_result": res.to_dict()}
        res = design(spec, kappa, free=options["free"], scalarize=options["scalarize"],
                     order=options["order"], gap=options["gap"],
                     time_limit=options["time_limit"], method=options.get("method", "dual"),
                     on_step=on_step, family=fam, workers=options.get("inner_workers"))
        return {**design_row(spec, res, fam), "_result": res.to_dict()}

    return _run_chunk(spec_text, source, options, chunk, one)


design_chunk.max_chunk = 1  # type: ignore[attr-defined]  # a design takes seconds or more


def run_design_sweep(
    spec: Spec, spec_text: str, kappas: Sequence[float], out_csv: Path,
    options: dict[str, Any], workers: int | None = None, scheduler: str | None = None,
    restart: bool = False, progress: bool = True, companions: Sequence[Path] = (),
) -> tuple[list[dict[str, str]], dict[float, dict[str, Any]]]:
    """Design over kappa, resumable. Returns the CSV rows (kappa order) and the full
    results of the rows computed in this run (keyed by kappa)."""
    settings = {"job": "design", "spec": spec_text,
                **{k: v for k, v in options.items() if k not in RUNTIME_OPTIONS},
                "kappa": [float(k) for k in kappas]} | kappa_settings(kappas)
    fam = family_from_options(options.get("certificate")) or spec_family(spec)
    store = ResumableCSV(out_csv, design_columns(spec, options["free"], fam,
                                                 "objective" in options), ["kappa"],
                         settings, restart=restart, companions=companions)
    tasks = [{"kappa": k if isinstance(k, Kappa) else float(k)} for k in kappas]
    fresh: dict[float, dict[str, Any]] = {}

    def on_row(row: dict[str, Any]) -> None:
        full = row.pop("_result", None)
        if full is not None:
            fresh[float(row["kappa"])] = full
        store.write(row)

    seed_spec(spec, spec_text)
    run_store(store, tasks, f"design {spec.name}", progress, design_chunk, spec_text,
               spec.source, options, on_row, workers, scheduler)
    wanted = {store.row_key({"kappa": float(k)}) for k in kappas}
    rows = [r for r in store.rows() if store.row_key(r) in wanted]
    return sorted(rows, key=lambda r: float(r["kappa"])), fresh


def design_csv_to_json(spec: Spec, free: Sequence[str], row: dict[str, str],
                       family: CertificateFamily | None = None) -> dict[str, Any]:
    """JSON form of a design CSV row (same keys as the single-kappa document)."""
    n = p_size(spec, family)
    P = None
    if row.get("P11", "") != "":
        P = [[0.0] * n for _ in range(n)]
        for i in range(n):
            for j in range(i, n):
                P[i][j] = P[j][i] = float(row[f"P{i + 1}{j + 1}"])
    return {
        "spec": spec.name,
        "kappa": float(row["kappa"]),
        "free": list(free),
        "lower_bound": _num(row["lower_bound"]),
        "theta": {p: _num(row[f"theta_{p}"]) for p in free},
        "rho_certified": _num(row["rho_certified"]),
        "gap": _num(row["gap"]),
        "certificate": _design_certificate(spec, row, family, P),
        "relaxation": {"scalarize": row["scalarize"] or None,
                       "order": int(row["order"]) if row["order"] else None,
                       "status": row["status"] or None,
                       "flat": {"true": True, "false": False}.get(row["flat"]),
                       "ranks": [int(x) for x in row["ranks"].split()]},
        "method": row.get("method") or None,
        "floor": _num(row.get("floor", "")),
        "time_limited": row.get("time_limited") == "true",
        "seconds": _num(row["seconds"]),
        "steps": row["steps"].split(" | ") if row["steps"] else [],
        "gap_met": row["gap_met"] == "true",
        "rho_at_values": _num(row["rho_at_values"]),
        "error": row.get("error") or None,
        "warning": row.get("warning") or None,
        "references": {name: _num(row[name]) for name in spec.references},
        "family": (family or spec_family(spec)).name,
    } | _objective_json(row)


def _objective_json(row: dict[str, str]) -> dict[str, Any]:
    """The fields of a design with a noise objective or cap (none for other rows)."""
    if "objective" not in row:
        return {}
    from sosalgo.design_search.objectives import objective_json

    return objective_json(row)


def _design_certificate(spec: Spec, row: dict[str, str], family: CertificateFamily | None,
                        P: Any) -> dict[str, Any]:
    """The certificate of a design row: the family's parts (P and lambda by default)."""
    if family is None or not family.csv_columns(spec.n):
        return {"P": P, "lambda": _num(row["lambda"])}
    return family.cert_from_csv(spec.n, row, P) or {}


# --------------------------------------------------------------------------- grids
def grid_points(box: Sequence[tuple[float, float]], points: int) -> list[tuple[float, ...]]:
    """Cartesian grid with ``points`` values per axis, endpoints included."""
    axes = [np.linspace(lo, hi, points) for lo, hi in box]
    mesh = np.meshgrid(*axes, indexing="ij")
    return [tuple(float(v) for v in vals) for vals in zip(*(m.ravel() for m in mesh), strict=True)]


def grid_chunk(
    spec_text: str, source: str, options: dict[str, Any], chunk: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    """Worker: analysis at each grid point (task: kappa and theta)."""
    rows = analysis_chunk(spec_text, source, options, chunk)
    spec, fam = _worker_setup(spec_text, source, options)
    cols = set(grid_columns(spec, options["free"], fam))
    return [{k: v for k, v in r.items() if k in cols} for r in rows]


def run_grid(
    spec: Spec, spec_text: str, kappa: float, free: Sequence[str],
    box: Sequence[tuple[float, float]], points: int, out_csv: Path, tol: float,
    workers: int | None = None, scheduler: str | None = None, restart: bool = False,
    progress: bool = True, family: CertificateFamily | None = None,
    companions: Sequence[Path] = (),
) -> list[dict[str, str]]:
    """Analysis on a grid over Θ at one kappa (the sublinear family: no kappa, rows keyed
    by the free parameters), resumable; rows in grid order."""
    fam = family or spec_family(spec)
    if isinstance(fam, SublinearFamily):
        return _run_constant_grid(spec, spec_text, fam, free, box, points, out_csv, workers,
                                  scheduler, restart, progress)
    options = {"tol": tol, "free": list(free), "certificate": family_options(fam)}
    settings = {"job": "grid", "spec": spec_text, "tol": tol, "kappa": float(kappa),
                "free": list(free), "points": points, "box": [list(b) for b in box]
                } | kappa_settings([kappa])
    if _family_settings(fam) is not None:
        settings["certificate"] = _family_settings(fam)
    values = parameter_values(spec, kappa)
    fixed = {p: values[p] for p in grid_fixed(spec, free)}
    store = ResumableCSV(out_csv, grid_columns(spec, free, fam), ["kappa", *free], settings,
                         restart=restart, companions=companions)
    tasks = []
    for vals in grid_points(box, points):
        theta = dict(zip(free, vals, strict=True))
        tasks.append({"kappa": kappa if isinstance(kappa, Kappa) else float(kappa),
                      "theta": theta, "extra": {**theta, **fixed},
                      **theta})
    seed_spec(spec, spec_text)
    run_store(store, tasks, f"grid {spec.name} k={kappa_label(kappa)}", progress, grid_chunk,
               spec_text, spec.source, options, None, workers, scheduler)
    order = {store.row_key(t): i for i, t in enumerate(tasks)}
    rows = [r for r in store.rows() if store.row_key(r) in order]
    return sorted(rows, key=lambda r: order[store.row_key(r)])


def sublinear_grid_chunk(spec_text: str, source: str, options: dict[str, Any],
                         chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: the certified constant at each task's point (its free parameters' values)."""
    from sosalgo import analysis

    spec = cached_spec(spec_text, source)
    rows = []
    for task in chunk:
        theta = {p: float(task[p]) for p in options["free"]}
        try:
            res = analysis.analyze_sublinear(spec, theta)
        except ModelError:  # no fixed point or a domain error there
            res = None
        rows.append(SUBLINEAR.grid_cells(theta, res))
    return rows


sublinear_grid_chunk.max_chunk = 1  # type: ignore[attr-defined]  # a point takes ~0.5 s


def _run_constant_grid(spec: Spec, spec_text: str, fam: SublinearFamily,
                       free: Sequence[str], box: Sequence[tuple[float, float]], points: int,
                       out_csv: Path, workers: int | None, scheduler: str | None,
                       restart: bool, progress: bool) -> list[dict[str, str]]:
    """The certified constant of a sublinear spec on a grid, resumable; rows in grid order."""
    names = list(free)
    settings = {"job": "grid", "spec": spec_text, "free": names, "points": points,
                "box": [list(b) for b in box]}
    store = ResumableCSV(out_csv, fam.grid_columns(names), names, settings, restart=restart)
    tasks = [dict(zip(names, pt, strict=True)) for pt in grid_points(box, points)]
    seed_spec(spec, spec_text)
    run_store(store, tasks, f"grid {spec.name}", progress, sublinear_grid_chunk, spec_text,
              spec.source, {"free": names}, None, workers, scheduler)
    order = {store.row_key(t): i for i, t in enumerate(tasks)}
    return sorted((r for r in store.rows() if store.row_key(r) in order),
                  key=lambda r: order[store.row_key(r)])


def sublinear_design_chunk(spec_text: str, source: str, options: dict[str, Any],
                           chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: the design minimizing the certified constant (with its simulation), as the
    family's CSV cells and the whole row (``_result``)."""
    from sosalgo.sublinear_design import sublinear_design

    spec = cached_spec(spec_text, source)
    rows = []
    for _ in chunk:
        show_phase("search", f"time limit {options['time_limit']:g} s")
        row = sublinear_design(spec, options["free"], options["time_limit"])
        row["simulation"] = sublinear_simulation(spec, row["constant"], row["theta"])
        rows.append(SUBLINEAR.design_cells(options["free"], row) | {"_result": row})
    return rows


sublinear_design_chunk.max_chunk = 1  # type: ignore[attr-defined]  # a design takes seconds


def run_constant_design(spec: Spec, spec_text: str, free: list[str], time_limit: float,
                        out_csv: Path, restart: bool = False,
                        progress: bool = True) -> dict[str, Any]:
    """The design of a sublinear spec (one row keyed by L, in this process), resumable:
    the row computed now, or read back from the CSV (its simulation run again: evidence
    about the constant, cheap next to the design)."""
    fam = SUBLINEAR
    settings = {"job": "design", "spec": spec_text, "free": free,
                "time_limit": float(time_limit)}
    store = ResumableCSV(out_csv, fam.design_columns(spec), list(fam.key), settings,
                         restart=restart)
    fresh: list[dict[str, Any]] = []

    def on_row(row: dict[str, Any]) -> None:
        fresh.append(row.pop("_result"))
        store.write(row)

    tasks = fam.analysis_tasks(spec)
    seed_spec(spec, spec_text)
    run_store(store, tasks, f"design {spec.name}", progress, sublinear_design_chunk,
              spec_text, spec.source, {"free": free, "time_limit": time_limit}, on_row, 1,
              None)
    if fresh:
        return fresh[0]
    wanted = {store.row_key(t) for t in tasks}
    cells = next(r for r in store.rows() if store.row_key(r) in wanted)
    row = fam.design_json(spec, free, cells)
    return row | {"simulation": sublinear_simulation(spec, row["constant"], row["theta"])}
