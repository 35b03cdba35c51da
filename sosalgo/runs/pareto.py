"""``sosalgo pareto`` (:func:`pareto_run`): the front of (certified rate, certified noise
sensitivity) over Θ, written as it is computed; its pieces are :mod:`sosalgo.pareto`.

At one kappa (docs/noise.md, "Design on the speed–robustness front"):

1. the fast end: today's rate design (:func:`sosalgo.design_search.design`) gives the fastest
   certified rate rho_0 it finds on the box;
2. N - 1 rate caps R_i = 1 - (1 - rho_0)^(1 + i/(N - 1)), i = 1 .. N - 1, evenly spaced in
   log(1 - rho) from rho_0 to the slow end 1 - (1 - rho_0)^2 (1 - 1/kappa when rho_0 is the
   floor 1 - 1/sqrt(kappa): the rate of gradient descent with h = 1/L); for each, the least
   sensitive θ found with certified rate <= R_i (:func:`sosalgo.design_search.objectives.min_noise`,
   started from the points already solved under smaller caps, the fast end and the best
   points of a grid over Θ);
3. every point certified on both axes and proven in exact arithmetic (the rate by the
   family's exact verifier, the noise by :mod:`sosalgo.sensitivity.exact`;
   :func:`sosalgo.design_search.objectives.certify_point`), written to
   ``<name>-pareto-k<kappa>.csv`` with its certificates as it is done (resumable, batch
   layer); the front keeps the points proven on both axes that no other dominates
   (:func:`sosalgo.pareto.pareto_filter`); ``sosalgo verify`` re-checks the ``--json`` document
   (:func:`sosalgo.pareto.pareto_rows`);
4. the known tunings, certified through the same API in the form of eq. (9)
   (specs/three-parameter.yaml): gradient descent h = 2/(m+L) and 1/L, Nesterov, heavy ball
   (Polyak's tuning), the triple momentum method and the robust momentum family.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sosalgo import inputs
from sosalgo.batch.executor import check_scheduler
from sosalgo.errors import InputError
from sosalgo.kernel.phases import begin_task
from sosalgo.kinds import PARETO_KIND
from sosalgo.pareto import front_caps, known_tunings, pareto_filter, reference_spec
from sosalgo.spec import Spec

__all__ = ["pareto_chunk", "pareto_run", "MAX_POINTS"]

MAX_POINTS = 200
DESIGN_SHARE = 0.25  # of the time limit, for the fast end (the rate design)
CLOUD_SHARE = 0.08  # for the grid over Θ that seeds the searches
MIN_CAP_SECONDS = 1.0  # each cap's search gets at least this (a short limit may be exceeded)
TUNING_SECONDS = 0.5  # set aside per known tuning (measured: 0.05 to 0.8 s)

_WARM: dict[str, list[tuple]] = {}  # per run: solved (cap, θ, certified noise)


# --------------------------------------------------------------------------- worker side
def _base_family(spec: Spec, options: Mapping[str, Any]) -> Any:
    from sosalgo.analysis import spec_family
    from sosalgo.certificates import family_from_description

    return family_from_description(options.get("certificate")) or spec_family(spec, "pareto")


def _written(path: str | None) -> list[tuple[float, dict[str, float], float]]:
    """(cap, θ, certified noise) of the front rows in the run's CSV so far (other
    workers' results; rows being written, or a file this worker cannot see, are
    skipped)."""
    import csv

    out = []
    try:
        with open(path or "", encoding="utf-8", newline="") as fh:
            for row in csv.DictReader(fh):
                try:
                    if row["kind"] == "front" and row["rho"] and row["noise"]:
                        out.append((float(row["cap"] or row["rho"]), json.loads(row["theta"]),
                                    float(row["noise"])))
                except (KeyError, TypeError, ValueError):
                    continue
    except OSError:
        pass
    return out


def _solved_below(options: Mapping[str, Any], cap: float
                  ) -> list[tuple[dict[str, float], float]]:
    """(θ, certified noise) of the points solved so far (here, by another worker, or read
    back) whose cap is <= ``cap`` (so they meet it): the least sensitive, then the one of
    the largest cap."""
    solved = (_WARM.get(options["run"], []) + [tuple(w) for w in options.get("warm", [])]
              + _written(options.get("csv")))
    below = [s for s in solved if s[0] <= cap]
    if not below:
        return []
    return [(s[1], s[2]) for s in (min(below, key=lambda s: s[2]),
                                   max(below, key=lambda s: s[0]))]


def _starts(options: Mapping[str, Any], cap: float) -> list[tuple[dict[str, float], float]]:
    """Where a cap's search starts, least sensitive first (noise as known: certified for
    solved points, screened for the grid): the solved points below it
    (:func:`_solved_below`), the fast end, and the best grid points under the cap."""
    from sosalgo.design_search.objectives import CAP_SLACK

    free = options["free"]
    grid = sorted((s for s in options.get("cloud", []) if s[1] <= cap - CAP_SLACK
                   and math.isfinite(s[2])), key=lambda s: s[2])
    out = (_solved_below(options, cap) + [(options["fast"], options["fast_noise"])]
           + [(dict(zip(free, s[0], strict=True)), s[2]) for s in grid[:3]])
    return sorted(out, key=lambda item: item[1])


def _cap_point(spec: Spec, options: Mapping[str, Any], task: Mapping[str, Any]) -> Any:
    """The least sensitive θ found with certified rate <= the task's cap, certified. The
    search runs in two halves: the second restarts from its own best and from any better
    point another worker has solved meanwhile under a smaller cap. Out of time, the least
    sensitive start is certified."""
    from sosalgo.design_search.objectives import Evaluator, certify_first, design_family, min_noise

    fam = design_family(spec, _base_family(spec, options))
    now = time.perf_counter()
    budget = max(min(options["task_seconds"], options["deadline"] - time.time()),
                 MIN_CAP_SECONDS)
    ev = Evaluator(spec, options["kappa"], options["free"], fam, now + 0.4 * budget)
    cap = float(task["cap"])
    starts = [ev.key(th) for th, _ in _starts(options, cap)]
    key, _ = min_noise(ev, cap, starts)
    ev.deadline = now + 0.75 * budget
    again = [k for k in [key, *(ev.key(th) for th, _ in _solved_below(options, cap))] if k]
    if again:
        key, _ = min_noise(ev, cap, again)
    pt = certify_first(spec, options["kappa"], fam, ev, [key] + starts, "noise", cap,
                       lambda msg: None, until=now + 0.9 * budget)
    if pt is not None:
        _WARM.setdefault(options["run"], []).append((cap, dict(pt.theta), pt.noise))
    return pt


def _row(task: Mapping[str, Any], pt: Any, seconds: float, error: str | None = None
         ) -> dict[str, Any]:
    cells = {} if pt is None else pt.to_dict()
    return {"index": task["index"], "kind": task["kind"], "name": task["name"],
            "cap": task.get("cap"), **{k: cells.get(k) for k in (
                "rho", "noise", "noise_quadratic", "noise_lag")},
            "noise_check": cells.get("noise_check", "none"),
            "rho_check": cells.get("rho_check", "none"),
            "theta": json.dumps(cells.get("theta", task.get("theta") or {}), sort_keys=True),
            "seconds": round(seconds, 4), "error": error, "rho_proven": cells.get("rho_proven"),
            **{k: None if cells.get(k) is None else json.dumps(cells[k], separators=(",", ":"))
               for k in ("certificate", "noise_certificate")}}


def pareto_chunk(spec_text: str, source: str, options: dict[str, Any],
                 chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Worker: one row per task, a front point (kind "front": the least sensitive θ under
    the task's cap) or a known tuning (certified in the form of eq. (9))."""
    from sosalgo.batch.sweeps import cached_spec
    from sosalgo.design_search.objectives import certify_point, design_family
    from sosalgo.model import ModelError

    spec = cached_spec(spec_text, source)
    rows = []
    for task in chunk:
        t0 = time.perf_counter()
        cap = task.get("cap")
        begin_task(f"rate cap {cap:.6f}" if cap is not None else str(task.get("name")))
        try:
            if task["kind"] == "front":
                pt = _cap_point(spec, options, task)
                err = None if pt is not None else \
                    f"no θ found with certified rate <= {task['cap']:.8f}"
            else:
                ref = reference_spec()
                pt = certify_point(ref, options["kappa"], task["theta"],
                                   design_family(ref, _base_family(ref, options)))
                err = None
        except ModelError as exc:
            pt, err = None, str(exc)
        rows.append(_row(task, pt, time.perf_counter() - t0, err))
    return rows


pareto_chunk.max_chunk = 1  # type: ignore[attr-defined]  # a front point takes seconds


# --------------------------------------------------------------------------- parent side
def _check(spec: Spec, kappa: Any, points: Any, time_limit: Any) -> list[float]:
    """The kappas, after the checks of ``sosalgo pareto`` (InputError naming the option)."""
    from sosalgo.design_search.objectives import check_noise_spec_for

    check_noise_spec_for(spec, "pareto")
    if kappa in (None, [], ()):
        raise InputError("--kappa: required (one or more condition numbers)")
    from sosalgo.runs import kappa_value  # as written (sosalgo.kernel.kappa)

    kappas = ([kappa_value(kappa)] if isinstance(kappa, int | float | str)
              else [kappa_value(k) for k in kappa])
    if isinstance(points, bool) or not isinstance(points, int) or not 2 <= points <= MAX_POINTS:
        raise InputError(f"--points {points}: must be an integer in 2..{MAX_POINTS} (the "
                         "front needs its two ends)")
    inputs.check_time_limit(time_limit, "--time-limit")
    inputs.check_kappa_points(spec, kappas)
    return list(dict.fromkeys(kappas))


def _fast_end(store: Any, spec: Spec, kappa: float, names: list[str], fam: Any,
              time_limit: float, workers: int | None) -> dict[str, str]:
    """Row 0: the rate design's θ certified on both axes (read back when resumed)."""
    from sosalgo.design_search import design
    from sosalgo.design_search.objectives import certify_point, design_family

    key = store.row_key({"index": 0})
    if key not in store.done:
        t0 = time.perf_counter()
        fam1 = design_family(spec, fam)
        res = design(spec, kappa, free=names, family=fam1,
                     time_limit=DESIGN_SHARE * time_limit, workers=workers)
        pt = certify_point(spec, kappa, res.theta, fam1) if res.theta else None
        task = {"index": 0, "kind": "front", "name": "fast end (rate design)", "cap": None}
        store.write(_row(task, pt, time.perf_counter() - t0,
                         None if pt is not None else "no certified rate on the box"))
    return store.done[key]


def _num(v: str | None) -> float | None:
    return None if v in (None, "") else float(v)


def _parse(row: Mapping[str, str]) -> dict[str, Any]:
    """A CSV row as JSON values."""
    return {"index": int(float(row["index"])), "kind": row["kind"], "name": row["name"],
            "cap": _num(row["cap"]), "rho": _num(row["rho"]), "noise": _num(row["noise"]),
            "theta": json.loads(row["theta"] or "{}"),
            "noise_quadratic": _num(row["noise_quadratic"]),
            "noise_lag": int(row["noise_lag"]) if row["noise_lag"] else None,
            "noise_check": row["noise_check"] or "none",
            "rho_check": row["rho_check"] or "none", "seconds": _num(row["seconds"]),
            "error": row["error"] or None, "rho_proven": row.get("rho_proven") or None,
            **{k: json.loads(row[k]) if row.get(k) else None
               for k in ("certificate", "noise_certificate")}}


def _tasks(spec: Spec, kappa: float, rho_fast: float | None, points: int
           ) -> list[dict[str, Any]]:
    """The known tunings (index points ..), then the caps (index 1 .. points - 1) from
    fast to slow: the tunings go first (they are quick), so that the caps run in order to
    the end, each warm-started from its neighbours."""
    from sosalgo.model import bind

    ref = bind(reference_spec(), kappa)
    tasks: list[dict[str, Any]] = [
        {"index": points + j, "kind": kind, "name": name, "theta": theta}
        for j, (kind, name, theta) in enumerate(known_tunings(kappa, ref.m, ref.L))]
    caps = [] if rho_fast is None else front_caps(rho_fast, points)[1:]
    return tasks + [{"index": i, "kind": "front", "name": f"cap {i}", "cap": c}
                    for i, c in enumerate(caps, 1)]


def _cap_seconds(tasks: list[dict[str, Any]], todo: list[dict[str, Any]], deadline: float,
                 time_limit: float, w: int) -> float:
    """Each cap's search time: its share of what is left, and at most its share of a whole
    run (what is left after the rate design, the grid and the tunings, over all caps), so
    that a resumed run takes only the time of what it still has to do."""
    caps = sum(t["kind"] == "front" for t in tasks)
    todo_caps = sum(t["kind"] == "front" for t in todo)
    tunings = TUNING_SECONDS * (len(tasks) - caps) / w  # all of them, on w processes
    todo_tunings = TUNING_SECONDS * (len(todo) - todo_caps) / w
    whole = (time_limit * (1 - DESIGN_SHARE - CLOUD_SHARE) - tunings) * w / max(caps, 1)
    left = (deadline - time.time() - todo_tunings) * w / max(todo_caps, 1)
    return max(min(whole, left), MIN_CAP_SECONDS)


def _search_options(spec: Spec, kappa: float, names: list[str], fam: Any, store: Any,
                    fast: dict[str, Any], tasks: list[dict[str, Any]], time_limit: float,
                    deadline: float, run: Mapping[str, Any]) -> dict[str, Any]:
    """What the workers need: the grid over Θ (only when caps remain), the points already
    solved, and each cap's time (:func:`_cap_seconds`)."""
    from sosalgo.batch.executor import SERIAL_BELOW
    from sosalgo.certificates import describe_family
    from sosalgo.design_search.objectives import Evaluator, cloud, design_family
    from sosalgo.kernel.parallel import default_workers

    todo = [t for t in tasks if not store.is_done(t)]
    samples = []
    if any(t["kind"] == "front" for t in todo):
        ev = Evaluator(spec, kappa, names, design_family(spec, fam),
                       time.perf_counter() + CLOUD_SHARE * time_limit)
        samples = [[list(s.key), s.rate, s.noise] for s in cloud(ev)]
    done = [_parse(r) for r in store.rows()]
    warm = [(p["cap"] if p["cap"] is not None else p["rho"], p["theta"], p["noise"])
            for p in done if p["kind"] == "front" and p["rho"] is not None
            and p["noise"] is not None]
    serial = (run["workers"] == 1 or len(todo) < SERIAL_BELOW) and not run["scheduler"]
    w = 1 if serial else (run["workers"] or default_workers())
    return {"run": store.digest, "kappa": kappa, "free": names,
            "certificate": describe_family(fam), "fast": fast["theta"],
            "fast_noise": math.inf if fast["noise"] is None else fast["noise"],
            "cloud": samples, "warm": warm, "deadline": deadline, "csv": str(store.path),
            "task_seconds": _cap_seconds(tasks, todo, deadline, time_limit, w)}


def _one_kappa(spec: Spec, text: str, kappa: float, names: list[str], fam: Any,
               points: int, time_limit: float, out: Path, run: Mapping[str, Any]
               ) -> dict[str, Any]:
    """The front at one kappa into ``<name>-pareto-k<kappa>.csv`` (resumable), its
    figure, and the ``--json`` document."""
    from sosalgo.batch.executor import Progress, run_batch
    from sosalgo.batch.sweeps import kappa_settings
    from sosalgo.certificates import describe_family
    from sosalgo.schema import PARETO_COLUMNS, kappa_label, pareto_stem
    from sosalgo.store import ResumableCSV, output_lock

    t0 = time.time()
    stem = pareto_stem(out, spec.name, kappa)
    csv_path = stem.with_name(stem.name + ".csv")
    figures = [stem.with_name(f"{stem.name}.{ext}") for ext in ("png", "pdf")]
    settings = {"job": "pareto", "spec": text, "kappa": kappa, "points": points,
                "free": names, "time_limit": time_limit, "certificate": describe_family(fam)
                } | kappa_settings([kappa])
    with output_lock(csv_path):
        store = ResumableCSV(csv_path, PARETO_COLUMNS, ["index"], settings,
                             restart=run["restart"], companions=figures)
        with store:
            fast_read = store.row_key({"index": 0}) in store.done  # read back, not computed
            fast = _parse(_fast_end(store, spec, kappa, names, fam, time_limit,
                                    run["workers"]))
            tasks = _tasks(spec, kappa, fast["rho"], points)
            todo = [t for t in tasks if not store.is_done(t)]
            opts = _search_options(spec, kappa, names, fam, store, fast, tasks, time_limit,
                                   t0 + time_limit, run)
            bar = Progress(len(tasks) + 1, f"pareto {spec.name} k={kappa_label(kappa)}",
                           run["progress"], done=len(tasks) - len(todo) + fast_read,
                           resumed_from=store.path)
            if not fast_read:
                bar.update(1)  # the fast end, computed above
            try:
                run_batch(pareto_chunk, text, spec.source, opts, todo, store.write,
                          workers=run["workers"], scheduler=run["scheduler"], progress=bar)
            finally:
                bar.close()
        wanted = {store.row_key(t) for t in [{"index": 0}, *tasks]}
        rows = [r for r in store.rows() if store.row_key(r) in wanted]
        doc = _document(spec, text, kappa, fam, names, rows, csv_path)
        if run["plot"]:
            from sosalgo.report.pareto import pareto_figure

            doc["figures"] = [str(p) for p in pareto_figure(doc, stem)]
    return doc


def _document(spec: Spec, text: str, kappa: float, fam: Any, names: list[str],
              rows: Sequence[Mapping[str, str]], csv_path: Path) -> dict[str, Any]:
    """The ``--json`` document: ``{"spec", "kappa", "front": [{"rho", "noise", "theta",
    ...}]}`` (a contract), with every front point computed (``points``), the known
    tunings, the family and the files."""
    from sosalgo.kernel.kappa import kappa_fields

    parsed = sorted((_parse(r) for r in rows), key=lambda p: p["index"])
    mine = [p for p in parsed if p["kind"] == "front"]
    return {"spec": spec.name, "kappa": float(kappa), **kappa_fields(kappa),
            "front": pareto_filter(mine),
            "source": spec.source, "spec_text": text, "kind": PARETO_KIND,
            "points": mine, "tunings": [p for p in parsed if p["kind"] != "front"],
            "family": fam.name, "lag": fam.options().get("lag"), "free": names,
            "floor": 1 - 1 / math.sqrt(kappa), "csv": str(csv_path), "figures": []}


def pareto_run(spec: Spec | str | Path, kappa: float | Sequence[float] | None = None,
               out_dir: str | Path = "outputs", points: int = 20, time_limit: float = 180.0,
               free: str | Sequence[str] | None = None, certificate: str | None = None,
               options: Mapping[str, Any] | None = None, workers: int | None = None,
               scheduler: str | None = None, restart: bool = False, progress: bool = True,
               plot: bool = True, spec_text: str | None = None,
               max_memory: int | str | None = None,
               overrides: Mapping[str, str] | None = None) -> dict[str, Any]:
    """``sosalgo pareto``: the front of (certified rate, certified sensitivity) at each
    kappa (module docstring), ``time_limit`` seconds per kappa; returns
    ``{"spec", "source", "fronts": [document per kappa]}`` (``--json`` prints the single
    document for one kappa). Bad input is an InputError before anything is written.
    ``overrides`` (``--set``) fix parameters; the documents record them in ``set``."""
    from sosalgo.runs import set_field, spec_with_text

    spec, text = spec_with_text(spec, spec_text, overrides)
    inputs.refuse_nonconvex(spec)
    kappas = _check(spec, kappa, points, time_limit)
    names = inputs.free_names(spec, free)
    fam = inputs.select_families(spec, certificate, options, single=True, command="pareto")[0]
    inputs.parameter_boxes(spec, kappas, names, design=True)
    from sosalgo.kernel import budget

    budget.set_max_memory(max_memory)
    est = budget.check(budget.design_estimate(
        f"pareto {spec.name} at {len(kappas)} kappa{'s' * (len(kappas) > 1)}",
        f"--kappa ({len(kappas)} values)", len(kappas), float(time_limit),
        budget.announce_workers(workers)))
    workers = est.workers if scheduler is None else workers
    out = inputs.out_dir(out_dir)
    check_scheduler(scheduler)
    run = {"workers": workers, "scheduler": scheduler, "restart": restart,
           "progress": progress, "plot": plot}
    docs = [_one_kappa(spec, text, k, names, fam, points, float(time_limit), out, run)
            | set_field(overrides) for k in kappas]
    return {"spec": spec.name, "source": spec.source, "spec_text": text, "kind": PARETO_KIND,
            "fronts": docs, "estimate": est.to_dict()} | set_field(overrides)
