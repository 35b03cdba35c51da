"""Design (Section III, eq. 17): minimize the certified rate over the parameters in a box Θ.

Two numbers come out, never mixed:

* ``rho_certified``: an ordinary analysis (eq. 16) at the designed θ, with its
  certificate checked in floating point (``sosalgo verify`` proves it exactly). θ comes
  from a global search over Θ (a grid of certified rates, then local polishing of the
  best points, then every point the bound search finds better).
* ``lower_bound``: a proof that no θ ∈ Θ is certified below it. Default (``method="dual"``,
  :mod:`sosalgo.design_search.dualbound`): Θ × [0, T²] is covered by boxes, each carrying a dual
  certificate of infeasibility valid on the whole box, with T = rho_certified - gap/2.
  ``method="moment"`` uses the paper's moment (sum-of-squares) relaxation of the
  homogenized problem (:mod:`sosalgo.design_search.moment`).

``floor`` = 1 - 1/√κ is reported beside them: no first-order method has a smaller
worst-case rate on F(m, L) (a theorem, not a computed bound); on composite specs only
where it is a theorem for the problem class (:mod:`sosalgo.design_search.floor`), else None.

Every phase respects ``time_limit`` (wall clock per κ): no step starts that the remaining
time cannot cover, and the best proven results so far are returned.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import product
from typing import Any

import numpy as np

from sosalgo.analysis import AnalysisResult, analyze_spec, jsonable, spec_family
from sosalgo.certificates import CertificateFamily, get_family
from sosalgo.design_search.boundcheck import bound_certificate
from sosalgo.design_search.dualbound import ARITHMETIC, BoundSearch, BoundStatus, dual_structure
from sosalgo.design_search.floor import class_floor
from sosalgo.design_search.polymodel import check_polynomial
from sosalgo.kernel.phases import show_phase
from sosalgo.kernel.solvers import solve_margin
from sosalgo.model import ModelError, bind, design_box
from sosalgo.spec import Spec

__all__ = ["BoundModel", "BoundResult", "DesignResult", "bound_model", "design",
           "design_problem", "prove_bound", "relaxation_bound", "METHODS"]


def __getattr__(name: str) -> Any:
    """``design_problem`` and ``relaxation_bound`` (the paper's relaxation, which imports
    cvxpy) load on first use."""
    if name in ("design_problem", "relaxation_bound"):
        from sosalgo.design_search import moment

        return getattr(moment, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

CERT_TOL = 1e-7  # tolerance of the certifying analyses
# The share of the time limit the lower bound's polynomial model may take to build (its
# symbolic expansion, checked between entries); past it the design goes without a bound
MODEL_SHARE = 0.5
GRID_TOL = 1e-5  # tolerance of the screening grid
METHODS = ("dual", "moment")
GRID_POINTS = {1: 21, 2: 13, 3: 7}  # per axis, by number of free parameters
POLISH_TOL = 1e-6  # tolerance of the analyses inside local polishing
# imported by its fork server
POOL_PRELOAD = ("sosalgo.design_search", "clarabel", "scipy.optimize")


@dataclass
class DesignResult:
    """Lower bound, designed parameters, certified rate and how they were obtained."""

    spec: str
    kappa: float
    free: list[str]
    lower_bound: float | None
    theta: dict[str, float]
    rho_certified: float | None
    gap: float | None
    certificate: dict[str, Any]
    relaxation: dict[str, Any]
    seconds: float
    steps: list[str] = field(default_factory=list)
    gap_met: bool = False
    rho_at_values: float | None = None  # certified rate at the spec's own values
    method: str = "dual"
    floor: float | None = None  # 1 - 1/sqrt(kappa): the class lower bound (a theorem)
    time_limited: bool = False
    family: str = "theorem1"
    lag: int | None = None
    bound_certificate: dict[str, Any] | None = None  # the proofs of a dual lower bound
    values_certificate: dict[str, Any] | None = None  # the certificate of rho_at_values

    def to_dict(self) -> dict[str, Any]:
        """JSON document of ``sosalgo design --json`` (a contract: extend, never rename)."""
        return {
            "spec": self.spec,
            "kappa": self.kappa,
            "free": list(self.free),
            "lower_bound": self.lower_bound,
            "theta": dict(self.theta),
            "rho_certified": self.rho_certified,
            "gap": self.gap,
            "certificate": self.certificate,
            "relaxation": self.relaxation,
            "seconds": self.seconds,
            "steps": list(self.steps),
            "gap_met": self.gap_met,
            "rho_at_values": self.rho_at_values,
            "method": self.method,
            "floor": self.floor,
            "gap_to_floor": (None if self.rho_certified is None or self.floor is None
                             else self.rho_certified - self.floor),
            "time_limited": self.time_limited,
            "family": self.family,
        } | ({} if self.lag is None else {"lag": self.lag}) | {
            k: v for k, v in (("bound_certificate", self.bound_certificate),
                              ("values_certificate", self.values_certificate))
            if v is not None}


def _rate(res: AnalysisResult | None) -> float:
    return res.rho if (res is not None and res.certified and res.rho is not None) else math.inf


class _Run:
    """State of one design at one κ: the best certified point, the clock, the log."""

    def __init__(self, spec: Spec, kappa: float, free: list[str], box, deadline: float,
                 on_step: Callable[[str], None] | None, family: CertificateFamily,
                 bound: bool = True):
        self.spec, self.kappa, self.free, self.box = spec, kappa, free, box
        self.family = family
        self.deadline = deadline
        self.best: AnalysisResult | None = None
        self.best_theta: dict[str, float] | None = None
        self.steps: list[str] = []
        self.on_step = on_step
        self.analysis_seconds = 0.02  # running estimate of one certifying analysis
        self.out_of_time = False
        self.phase_end = deadline  # the search phases stop earlier to leave time for bounds
        self.workers = 1  # processes for the grid and the local searches
        self.bound = bound  # a lower-bound phase follows the search
        self.live_phase: str | None = None  # a phase whose bar counts analyses
        self.live_count = 0
        self.live_budget = ""  # the time the shown phase may take
        self.floor = class_floor(spec, kappa)  # None: no floor is a theorem here

    def log(self, msg: str, record: bool = True) -> None:
        if record:
            self.steps.append(msg)
        if self.on_step is not None:
            self.on_step(msg)

    def show(self, name: str, detail: str = "", per_analysis: bool = False) -> None:
        """Put the phase in the progress bar (when this process draws one);
        ``per_analysis``: refresh it at each analysis (count, best rate) until the next."""
        self.live_phase, self.live_count = (name if per_analysis else None), 0
        left = min(self.deadline, self.phase_end) - time.perf_counter()
        self.live_budget = f"budget {max(left, 0.0):.0f} s"  # the phase's share of the limit
        show_phase(name, f"{detail}, {self.live_budget}" if detail else self.live_budget)

    def left(self) -> float:
        return self.deadline - time.perf_counter()

    def can_afford(self, seconds: float, phase: bool = True) -> bool:
        """Whether ``seconds`` fit before the phase's end (``phase=False``: the deadline)."""
        now = time.perf_counter()
        if now + seconds < (min(self.deadline, self.phase_end) if phase else self.deadline):
            return True
        if now + seconds >= self.deadline:
            self.out_of_time = True
        return False

    def clip(self, theta: dict[str, float]) -> dict[str, float]:
        return {p: float(min(max(theta[p], lo), hi))
                for p, (lo, hi) in zip(self.free, self.box, strict=True) if p in theta}

    def certify(self, theta: dict[str, float], tol: float = CERT_TOL,
                phase: bool = True) -> AnalysisResult | None:
        """Analysis at θ (None if out of time or the point cannot be evaluated);
        ``phase=False`` lets it run past the current phase's end (not past the deadline)."""
        if not self.can_afford(2 * self.analysis_seconds, phase):
            return None
        t = time.perf_counter()
        try:
            res = analyze_spec(self.spec, self.kappa, self.clip(theta), tol=tol,
                               family=self.family)
        except ModelError:
            return None
        finally:
            dt = time.perf_counter() - t
            self.analysis_seconds = 0.8 * self.analysis_seconds + 0.2 * dt
            if self.live_phase is not None:
                self.live_count += 1
                best = f", best {self.upper:.6f}" if math.isfinite(self.upper) else ""
                show_phase(self.live_phase,
                           f"{self.live_count} analyses{best}, {self.live_budget}")
        return res

    def consider(self, theta: dict[str, float] | None, why: str) -> bool:
        """Certify θ precisely; keep it if it beats the best. True when it did."""
        if theta is None:
            return False
        theta = self.clip(theta)
        res = self.certify(theta, phase=False)  # a found point is always worth certifying
        if _rate(res) < _rate(self.best):
            self.best, self.best_theta = res, theta
            self.log(f"{why}: certified {res.rho:.8f}")
            return True
        return False

    @property
    def upper(self) -> float:
        return _rate(self.best)


def design(
    spec: Spec,
    kappa: float,
    free: Sequence[str] | None = None,
    scalarize: str = "pmi",
    order: int | None = None,
    gap: float = 1e-4,
    time_limit: float = 120.0,
    max_order: int | None = None,
    method: str = "dual",
    on_step: Callable[[str], None] | None = None,
    family: CertificateFamily | str | None = None,
    workers: int | None = None,
) -> DesignResult:
    """Design the free parameters at ``kappa`` (eq. 17): search, certify, bound.

    Steps: certify the spec's own values; a grid of certified rates over Θ and local
    polishing of its best points (the certified design); then the lower bound by
    ``method`` ("dual": box-wide dual certificates, which also certifies every better
    point it meets; "moment": the paper's moment relaxation, order ``order``, raised up to
    ``max_order``). ``time_limit`` is a wall-clock limit for all of it; ``on_step``
    receives progress messages (the phases also go to this process's progress bar, if
    any). ``family`` overrides the spec's certificate family. ``workers`` > 1 evaluates
    the grid and the local searches on that many processes. A range too large for design
    (:func:`sosalgo.model.design_box`) is a :class:`ModelError`. ``steps`` in the result
    records what happened.
    """
    t0 = time.perf_counter()
    free, box, family = _setup(spec, kappa, free, method, family)
    model, late = None, None
    if method == "dual":  # the model's expansion counts against the limit (MODEL_SHARE)
        show_phase("model building", f"budget {MODEL_SHARE * time_limit:.0f} s")
        model, late = _timed_bound_model(spec, kappa, free, family,
                                         t0 + MODEL_SHARE * time_limit)
    run = _Run(spec, kappa, free, box, t0 + time_limit, on_step, family,
               bound=method == "moment" or model is not None
               or (method == "dual" and _witness_applies(spec)))
    run.workers = _usable_workers(workers)
    if late is not None:
        run.out_of_time = True
        run.log(f"no lower bound: {late} within {MODEL_SHARE:.0%} of the time limit; "
                "the search has the rest")
    with np.errstate(all="ignore"), warnings.catch_warnings():
        # overflow and NaN are handled (a point that cannot be certified is no point)
        warnings.simplefilter("ignore", RuntimeWarning)
        values_res = _certify_values(run)
        # without a bound phase to come (a family the dual bound does not cover), the
        # search may use all the time
        _search(run, polish_share=0.5 if run.bound else 0.95)
        run.phase_end = run.deadline
        if late is not None:
            lb, relax = None, {"method": "dual", "status": BoundStatus.PARTIAL,
                               "scalarize": None, "order": None, "flat": None, "ranks": []}
        elif method == "dual":
            lb, relax = _dual_bound(run, model, gap)
        else:
            lb, relax = _moment_bound(run, scalarize, order, max_order, gap)
    return _result(run, values_res, lb, relax, gap, method, time.perf_counter() - t0,
                   time_limit)


def _setup(spec: Spec, kappa: float, free: Sequence[str] | None, method: str,
           family: CertificateFamily | str | None
           ) -> tuple[list[str], list[tuple[float, float]], CertificateFamily]:
    """The free parameters, the box Θ and the family, or the input error that stops it."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}")
    free = list(spec.ranged if free is None else free)
    if not free:
        raise ModelError("parameters", "nothing to design: no parameter has a range")
    spec.check_free(free)
    box = design_box(spec, kappa, free)
    bind(spec, kappa)  # the spec's own values must make sense here
    if family is None:
        family = spec_family(spec)
    elif isinstance(family, str):
        family = get_family(family)
    lags = family.auto_lags(spec.n)
    if lags:  # designs keep the first auto lag (n - 1): choosing it at every θ is ~5x slower
        family = family.with_options(lag=lags[0])
    if method == "moment" and not family.supports_moment:
        raise ModelError("certificate", "--method moment is built on Theorem 1 only")
    check_polynomial(spec, free)  # refuses non-polynomial θ
    return free, box, family


def _certify_values(run: _Run) -> AnalysisResult | None:
    """The analysis at the spec's own values (the first design, when certified)."""
    run.log("certifying the spec's values", record=False)
    run.show("spec values")
    res = run.certify({})
    if res is not None and res.certified:
        run.consider({p: res.params[p] for p in run.free}, "spec values")
    return res


def _result(run: _Run, values_res: AnalysisResult | None, lb: float | None,
            relax: dict[str, Any], gap: float, method: str, seconds: float,
            time_limit: float) -> DesignResult:
    """The design's numbers: a bound above the certified rate is clipped to it."""
    relax = dict(relax)
    bound_cert = relax.pop("_certificate", None)
    rho_c = None if run.best is None else run.best.rho
    if lb is not None and rho_c is not None and lb > rho_c:
        run.log(f"bound {lb:.10f} above the certified rate {rho_c:.10f}: clipped to it")
        lb = rho_c
    g = None if (lb is None or rho_c is None) else rho_c - lb
    best = run.best
    cert: dict[str, Any] = {}
    if best is not None:  # the family's named parts (P and lambda for Theorem 1)
        cert = {**jsonable(best.certificate or {}), "max_eig_M": best.max_eig_M,
                "min_eig_P": best.min_eig_P}
    gap_met = g is not None and g <= gap
    if run.out_of_time and not gap_met:
        run.log(f"time limit {time_limit:g} s reached")
    return DesignResult(
        spec=run.spec.name, kappa=float(run.kappa), free=run.free, lower_bound=lb,
        theta=dict(run.best_theta or {}), rho_certified=rho_c, gap=g, certificate=cert,
        relaxation=relax, seconds=seconds, steps=run.steps, gap_met=gap_met,
        rho_at_values=None if values_res is None or not values_res.certified
        else values_res.rho,
        method=method, floor=run.floor, family=run.family.name,
        lag=run.family.options().get("lag"), time_limited=run.out_of_time and not gap_met,
        bound_certificate=bound_cert,
        values_certificate=None if values_res is None or not values_res.certified
        else jsonable(values_res.certificate or {}),
    )


# --------------------------------------------------------------------------- upper bound
def _search(run: _Run, polish_share: float = 0.5) -> None:
    """Grid of certified rates over Θ (the first 30 % of the time), then polish the best
    few points locally (``polish_share`` of what is left), then restart from the best."""
    run.phase_end = time.perf_counter() + 0.3 * (run.deadline - time.perf_counter())
    pts = GRID_POINTS.get(len(run.free), 5)
    scored = _grid(run, pts)
    good = [th for r, th in scored if math.isfinite(r)]
    run.log(f"grid: {len(scored)} points, {len(good)} certified"
            + (f", best {scored[0][0]:.6f}" if good else ""))
    starts = _starts(run, good, pts)
    run.phase_end = time.perf_counter() + polish_share * max(run.left(), 0.0)  # polishing
    _polish_starts(run, starts)
    while (len(run.free) > 1 and run.best_theta is not None  # restarts while they help
           and run.can_afford(40 * run.analysis_seconds)):
        run.log("polishing the best point again", record=False)
        run.show("polish again", per_analysis=True)
        before = run.upper
        run.consider(_polish(run, run.best_theta), "polished again")
        if not run.upper < before - CERT_TOL:  # no real progress: stop
            break


def _grid(run: _Run, pts: int) -> list[tuple[float, dict[str, float]]]:
    """(certified rate, θ) on the grid, best first, as far as the grid phase allows."""
    k = len(run.free)
    axes = [np.linspace(lo, hi, pts) if hi > lo else np.array([lo]) for lo, hi in run.box]
    run.log(f"grid search: {pts}^{k} points", record=False)
    thetas = [dict(zip(run.free, map(float, pt), strict=True)) for pt in product(*axes)]
    if run.workers > 1:
        run.show("grid", f"{len(thetas)} points on {run.workers} processes")
        n = 4 * run.workers
        rates = _parallel(run, _grid_task, [thetas[i::n] for i in range(n)])
        scored = [(r, th) for i in range(n)
                  for r, th in zip(rates[i] or [], thetas[i::n], strict=False)]
    else:
        scored = []
        for i, theta in enumerate(thetas):
            run.show("grid", f"{i}/{len(thetas)} points")
            if not run.can_afford(2 * run.analysis_seconds):
                break
            scored.append((_rate(run.certify(theta, tol=GRID_TOL)), theta))
    if len(scored) < len(thetas):
        run.log("grid cut short by the time limit" if run.out_of_time else
                "grid cut short to leave time for polishing"
                + (" and the bound" if run.bound else ""))
    scored.sort(key=lambda item: item[0])
    return scored


def _starts(run: _Run, good: list[dict[str, float]], pts: int) -> list[dict[str, float]]:
    """Where to polish: the best certified point so far (e.g. the spec's own values) and
    the best grid points that are not neighbours of a better one."""
    k = len(run.free)
    widths = np.array([max(hi - lo, 1e-300) for lo, hi in run.box])
    wanted = 1 if k == 1 else 2
    starts: list[dict[str, float]] = []
    candidates = ([run.best_theta] if run.best_theta and k > 1 else []) + good
    for theta in candidates:
        x = np.array([theta[p] for p in run.free])
        if all(np.max(np.abs(x - np.array([s[p] for p in run.free])) / widths) > 1.5 / (pts - 1)
               for s in starts):
            starts.append(theta)
        if len(starts) == wanted:
            break
    return starts


def _polish_starts(run: _Run, starts: list[dict[str, float]]) -> None:
    """Polish from each start, in parallel when there are workers and several starts;
    one after the other, each start gets its share of the phase."""
    if run.workers > 1 and len(starts) > 1:
        run.log(f"polishing locally from {len(starts)} points in parallel", record=False)
        run.show("polish", f"{len(starts)} starts on {run.workers} processes")
        for theta in _parallel(run, _polish_task, starts):
            run.consider(theta, "polished locally")
        return
    polish_end = run.phase_end
    for i, theta in enumerate(starts):
        run.phase_end = time.perf_counter() + (polish_end - time.perf_counter()) / (
            len(starts) - i)
        if not run.can_afford(10 * run.analysis_seconds):
            continue
        run.log("polishing locally", record=False)
        run.show(f"polish {i + 1}/{len(starts)}", per_analysis=True)
        run.consider(_polish(run, theta), "polished locally")
    run.phase_end = polish_end


def _usable_workers(workers: int | None) -> int:
    """Processes for one design: 1 inside a pool's worker (no pools within pools). With
    more, the pool's fork server starts now and loads its modules in the background."""
    import multiprocessing as mp

    if (not workers or workers <= 1 or mp.parent_process() is not None
            or mp.current_process().daemon):
        return 1
    from sosalgo.kernel.parallel import start_pool_server

    start_pool_server(POOL_PRELOAD)
    return int(workers)


def _worker_run(run: _Run) -> tuple:
    """What a worker needs to rebuild the run (no callbacks), with the phase's end as a
    wall-clock time (the same instant in every process, however late a worker starts)."""
    end = time.time() + min(run.deadline, run.phase_end) - time.perf_counter()
    return (run.spec, run.kappa, run.family, run.free, run.box, end)


def _rebuild(spec, kappa, family, free, box, end) -> _Run:
    return _Run(spec, kappa, free, box, time.perf_counter() + end - time.time(), None, family)


def _grid_task(args: tuple) -> list[float]:
    """Certified rates of a list of grid points, as many as the phase's end allows."""
    *base, thetas = args
    run = _rebuild(*base)
    out = []
    for theta in thetas:
        res = run.certify(theta, tol=GRID_TOL)
        if res is None and run.out_of_time:
            break
        out.append(_rate(res))
    return out


def _polish_task(args: tuple) -> dict[str, float] | None:
    *base, theta = args
    return _polish(_rebuild(*base), theta)


def _parallel(run: _Run, fn: Callable, items: list) -> list:
    """fn((*worker_run, item)) for every item on run.workers processes, within the phase
    (:func:`sosalgo.kernel.parallel.map_until`).

    The tasks stop themselves at the phase's end; a task not finished a second later
    gives None (its pool is killed, a busy worker is never waited for). Unfinished or
    failed tasks are logged, so a cut phase never passes for a complete one. A phase
    shorter than a pool's start-up (about a second) runs here, one task after the other."""
    from sosalgo.kernel.parallel import map_until

    base = _worker_run(run)
    if base[-1] - time.time() < 2.0:
        return [fn((*base, item)) for item in items]
    out, errors = map_until(fn, [(*base, item) for item in items], run.workers, base[-1],
                            preload=POOL_PRELOAD)
    run.can_afford(0.0, phase=False)  # marks the run out of time past its deadline
    lost = sum(o is None for o in out)
    if lost:
        why = (f"failed: {type(errors[0]).__name__}: {errors[0]}"[:200] if errors
               else "not finished by the phase's end")
        run.log(f"{lost} of {len(items)} parallel tasks {why}")
    return out


def _polish(run: _Run, theta: dict[str, float]) -> dict[str, float] | None:
    """Local minimization of the certified rate within Θ (scipy), within the deadline."""
    from scipy.optimize import minimize, minimize_scalar

    free, box = run.free, run.box

    def f(z: np.ndarray) -> float:
        res = run.certify(dict(zip(free, map(float, z), strict=True)), tol=POLISH_TOL)
        r = _rate(res)
        return r if math.isfinite(r) else 2.0

    if len(free) == 1:
        lo, hi = box[0]
        if hi <= lo:
            return {free[0]: lo}
        step = (hi - lo) / (GRID_POINTS[1] - 1)
        a, b = max(lo, theta[free[0]] - step), min(hi, theta[free[0]] + step)
        out = minimize_scalar(lambda s: f(np.array([s])), bounds=(a, b), method="bounded",
                              options={"xatol": 1e-7 * (hi - lo), "maxiter": 60})
        return {free[0]: float(out.x)}
    lo = np.array([b[0] for b in box])
    hi = np.array([b[1] for b in box])
    widths = hi - lo
    x = np.array([theta[p] for p in free])
    fx = f(x)
    # Nelder-Mead, restarted from its result with smaller simplices (the certified rate
    # has kinks where restarts help); each simplex steps away from the nearer bound.
    for frac in (0.5 / GRID_POINTS.get(len(free), 5), 0.01, 0.001):
        if not run.can_afford(40 * run.analysis_seconds):
            break
        steps = np.where(x - lo > hi - x, -1.0, 1.0) * widths * frac
        simplex = np.array([x] + [x + np.eye(len(free))[i] * steps[i]
                                  for i in range(len(free))])
        out = minimize(f, x, method="Nelder-Mead", bounds=box,
                       options={"xatol": 1e-9, "fatol": 1e-9, "maxfev": 80 * len(free),
                                "initial_simplex": np.clip(simplex, lo, hi)})
        if out.fun < fx - 1e-9:
            x, fx = np.clip(out.x, lo, hi), float(out.fun)
        elif frac < 0.01:
            break
    return dict(zip(free, map(float, x), strict=True))


# --------------------------------------------------------------------------- lower bounds
@dataclass
class BoundModel:
    """What the dual bound needs at one κ: the exact polynomial data, their dual
    structure and the mode argument."""

    poly: Any  # polymodel.PolyLMI
    structure: Any  # dualbound.DualStructure
    modes: Any  # modes.ModeTest

    def search(self, target_r: float, record: bool = False) -> BoundSearch:
        return BoundSearch(self.poly, self.structure, target_r, self.modes, record=record)


def bound_model(spec: Spec, kappa: float, free: list[str],
                 family: CertificateFamily, deadline: float | None = None
                 ) -> BoundModel | None:
    """The exact data of the family over Θ, or None when the family has no dual bound
    (no exact form, or variables outside θ-free cones). ``deadline``
    (``time.perf_counter``): :class:`~sosalgo.design_search.polymodel.ModelTimeout` once the
    symbolic expansion passes it."""
    from sosalgo.design_search.modes import ModeTest
    from sosalgo.design_search.polymodel import exact_method, numeric_template, poly_lmi
    from sosalgo.kernel.kappa import exact_kappa

    if not spec.has_seed_form:  # the exact form is the seed's (A, B, C, E); no family has one here
        return None
    if not exact_kappa(kappa).is_Rational:  # the exact data are rational
        return None
    method = exact_method(spec, kappa, free)
    poly = poly_lmi(method, family, numeric_template(spec, kappa, method, family), deadline)
    structure = None if poly is None else dual_structure(poly)
    if structure is None:
        return None
    return BoundModel(poly, structure, ModeTest(method))


def _timed_bound_model(spec: Spec, kappa: float, free: list[str], family: CertificateFamily,
                       deadline: float) -> tuple[BoundModel | None, str | None]:
    """(the bound model, None), or (None, what was done) when its symbolic expansion
    did not end by ``deadline``."""
    from sosalgo.design_search.polymodel import ModelTimeout

    try:
        return bound_model(spec, kappa, free, family, deadline), None
    except ModelTimeout as exc:
        return None, str(exc)


def _bound_info(state, status: BoundStatus, seconds: float) -> dict[str, Any]:
    """The ``relaxation`` fields of a dual bound (a contract: extend, never rename)."""
    return {"method": "dual", "status": status, "scalarize": None, "order": None,
            "flat": None, "ranks": [], "boxes_proven": state.proven,
            "boxes_dual": state.dual, "boxes_mode": state.quadratic,
            "boxes_quadratic": state.quadratic,
            "boxes_inherited": state.proven - state.dual - state.quadratic,
            "boxes_open": len(state.heap) + len(state.stuck), "solves": state.solves,
            "boxes_refuted": state.refuted, "target": math.sqrt(state.target),
            "arithmetic": ARITHMETIC, "seconds": seconds}


def _dual_bound(run: _Run, model: BoundModel | None, gap: float
                ) -> tuple[float | None, dict[str, Any]]:
    """Cover Θ × [0, T²], T = rho_certified - gap/2, by proven boxes."""
    if model is None and _witness_applies(run.spec):
        lb, info = _witness_bound(run, gap)
        if lb is not None:
            return lb, info
    if model is None:
        run.log(f"no proven lower bound for the {run.family.name} family (the box-wide dual "
                "bound needs Lyapunov variables that are all sign-constrained; this family "
                "has no exact_problem); "
                + ("see floor" if run.floor is not None else
                   "no floor is a theorem for this problem class either"))
        return None, {"method": "dual", "status": BoundStatus.UNSUPPORTED, "scalarize": None,
                      "order": None, "flat": None, "ranks": []}

    def target() -> float:
        u = run.upper
        return (1.0 if not math.isfinite(u) else max(0.0, u - 0.5 * gap)) ** 2

    search = model.search(target())
    spec, kappa, poly = run.spec, run.kappa, model.poly

    def on_open(z: np.ndarray, r: float) -> float | None:
        """No dual certificate at this center: certify it if it is feasible below T."""
        theta = poly.theta(z)
        try:
            problem = run.family.problem(bind(spec, kappa, run.clip(theta)))
        except ModelError:
            return None
        mg = solve_margin(problem, math.sqrt(r))
        if not (mg.ok and mg.t is not None and mg.t > 0):
            return None
        if run.consider(theta, "better point found by the bound search"):
            polished = _polish(run, run.best_theta) if run.can_afford(
                20 * run.analysis_seconds) else None
            run.consider(polished, "polished locally")
            return target()
        return None

    run.log(f"bound: proving no certificate below {math.sqrt(target()):.8f}", record=False)
    t = time.perf_counter()
    budget = f"budget {max(run.deadline - t, 0.0):.0f} s"
    show_phase("bound", f"below {math.sqrt(target()):.6f}, {budget}")
    state = search.run(run.deadline, on_open, on_box=lambda st: show_phase(
        "bound", f"{st.proven} boxes proven, {len(st.heap) + len(st.stuck)} open, "
                 f"below {math.sqrt(st.target):.6f}, {budget}"))
    if state.heap:
        run.out_of_time = run.out_of_time or time.perf_counter() >= run.deadline
    lb = state.lower_bound()
    status = BoundStatus.PROVED if state.complete else BoundStatus.PARTIAL
    info = _bound_info(state, status, time.perf_counter() - t)
    info["_certificate"] = bound_certificate(state, run.free)  # the document's, not info's
    run.log(f"dual bound ({status}): {state.dual} boxes by dual certificates, "
            f"{state.quadratic} by the mode argument, {info['boxes_open']} open, "
            + (f"bound {lb:.8f}" if lb > 0 else "no bound above 0 proven"))
    return lb, info


def _witness_applies(spec: Spec) -> bool:
    """An operator spec with a one-dimensional state: the linear witnesses of
    :mod:`sosalgo.design_search.witness` may bound its design."""
    from sosalgo.spec.loading import operator_functions

    return bool(operator_functions(spec)) and spec.n == 1


def _witness_bound(run: _Run, gap: float) -> tuple[float | None, dict[str, Any]]:
    """Every θ of the box has a rate at least the bound, proven on linear instances (a
    bound of the true worst case, so of every certified rate)."""
    from sosalgo.design_search.witness import witness_bound

    u = run.upper
    target = 1.0 if not math.isfinite(u) else max(0.0, u - 0.5 * gap)
    t = time.perf_counter()
    show_phase("bound", f"linear witnesses below {target:.6f}, "
                        f"budget {max(run.deadline - t, 0.0):.0f} s")
    lb, info = witness_bound(run.spec, run.kappa, run.free, target, run.deadline)
    if lb is None:
        run.log(f"no bound by linear witnesses: {info.get('reason')}")
        return None, info
    if info["status"] != BoundStatus.PROVED and time.perf_counter() >= run.deadline:
        run.out_of_time = True
    info["status"] = BoundStatus(info["status"])
    info.update(scalarize=None, order=None, flat=None, ranks=[])
    run.log(f"bound by linear witnesses ({info['status']}): {info['boxes']} boxes, bound "
            f"{lb:.8f} (the rate on normal linear operators of the classes, proven over "
            "every box: a lower bound of the worst case, so of every certified rate)")
    return lb, info


@dataclass
class BoundResult:
    """:func:`prove_bound`'s answer: no θ in Θ is certified by the family below
    ``lower_bound`` (None: no bound for this family)."""

    spec: str
    kappa: float
    free: list[str]
    target: float
    lower_bound: float | None
    status: str
    info: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        return {"spec": self.spec, "kappa": self.kappa, "free": list(self.free),
                "target": self.target, "lower_bound": self.lower_bound,
                "status": str(self.status), **{k: v for k, v in self.info.items()
                                               if k not in ("status", "target")}}


def prove_bound(spec: Spec, kappa: float, target: float, free: Sequence[str] | None = None,
                time_limit: float = 60.0, family: CertificateFamily | str | None = None
                ) -> BoundResult:
    """Try to prove that no θ in Θ is certified by the family below ``target`` (a rate):
    the dual bound of :func:`design` without the search. ``lower_bound`` is what was
    proven within ``time_limit`` seconds (``status`` "proved" when it is ``target``)."""
    t0 = time.perf_counter()
    if not 0 < target <= 1:
        raise ValueError("target must be in (0, 1]")
    free = list(spec.ranged if free is None else free)
    spec.check_free(free)
    fam = spec_family(spec) if family is None else (
        get_family(family) if isinstance(family, str) else family)
    model = bound_model(spec, kappa, free, fam)
    if model is None:
        return BoundResult(spec.name, float(kappa), free, target, None,
                           BoundStatus.UNSUPPORTED, {})
    state = model.search(target**2).run(t0 + time_limit, None)
    status = BoundStatus.PROVED if state.complete else BoundStatus.PARTIAL
    return BoundResult(spec.name, float(kappa), free, target, state.lower_bound(), status,
                       _bound_info(state, status, time.perf_counter() - t0))


def _moment_bound(run: _Run, scalarize: str, order: int | None, max_order: int | None,
                  gap: float) -> tuple[float | None, dict[str, Any]]:
    """The paper's moment relaxation over Θ (order raised once if the gap is not met)."""
    # imported here: the relaxation needs cvxpy (about 2 s to import), the default bound not
    from sosalgo.design_search.moment import relaxation_bound
    from sosalgo.polyopt import RelaxationStatus

    lb: float | None = None
    info: dict[str, Any] = {"method": "moment"}
    cur = order
    top = None
    while True:
        if not run.can_afford(1.0):
            break
        run.log(f"moment relaxation (order {cur or 'default'})", record=False)
        run.show("bound", f"moment relaxation, order {cur or 'default'}")
        b = relaxation_bound(run.spec, run.kappa, run.free, run.box, cur, scalarize,
                             seconds=run.left())
        st = b.info["status"]
        run.log(f"relaxation order {b.info['order']} ({scalarize}): status {st}, "
                f"flat {b.info['flat']}, bound {'-' if b.rho is None else f'{b.rho:.8f}'}"
                + (f" ({b.info['why']})" if st == RelaxationStatus.SKIPPED else ""))
        if b.rho is not None and (lb is None or b.rho > lb):
            lb, info = b.rho, {"method": "moment", **b.info}
        elif lb is None:
            info = {"method": "moment", **b.info}
        for cand in b.info.get("candidates", [b.theta] if b.theta else []):
            run.consider(cand, f"theta from {b.source}")
        cur = b.info["order"]
        top = max_order if max_order is not None else (top or cur + 1)
        skipped = st == RelaxationStatus.SKIPPED
        if (lb is not None and run.upper - lb <= gap) or cur >= top or skipped:
            break
        cur += 1
    if lb is not None and lb > run.upper + 1e-7:
        run.log(f"relaxation bound {lb:.8f} exceeds a certified rate: discarded as "
                "numerically invalid")
        lb = None
        info["status"] = RelaxationStatus.INCONSISTENT
    return lb, info
