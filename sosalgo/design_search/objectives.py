"""Design with two objectives: the certified rate and the certified noise sensitivity.

``sosalgo design --objective noise --max-rate R``: the least sensitive θ in Θ whose
certified rate is <= R; ``--objective rate --max-noise G``: the fastest θ whose certified
sensitivity is <= G (docs/noise.md, "Design on the front").

The search is a heuristic (there is no box-wide lower bound for these objectives:
``bound_status: unsupported``): a grid over Θ (the *cloud*: screened rate and noise at
each point), then Nelder–Mead from the best points that meet the constraint, within the
time limit. Inside the search a θ meets a rate cap R when the family's LMI at
rho = R - CAP_SLACK has a floating-point-checked solution (one SDP), and its noise is the
certified bound at lag SEARCH_LAG (one SDP). The returned θ is then certified on both
axes by the public analyses (:func:`certify_point`): ``analyze_spec`` for the rate
(tolerance 1e-7, floating-point-checked certificate) and ``analyze_noise`` for the noise
(the best lag, proven in exact arithmetic), and the constraint is checked on *those*
values, never on the search's estimates.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from itertools import product
from typing import Any

import numpy as np

from sosalgo.analysis import AnalysisResult, analyze_spec, jsonable, spec_family
from sosalgo.certificates import CertificateFamily, get_family
from sosalgo.design_search import DesignResult
from sosalgo.errors import InputError
from sosalgo.model import ModelError, bind, design_box
from sosalgo.spec import Spec

__all__ = ["OBJECTIVES", "Evaluator", "ObjectiveDesignResult", "Point", "Sample",
           "certify_first", "certify_point", "check_noise_spec_for", "check_objective",
           "cloud", "design_family", "float_up", "min_noise", "min_rate", "objective_design",
           "objective_json", "prove_rate"]

OBJECTIVES = ("rate", "noise")
SEARCH_LAG = 1  # lag of the noise certificates inside the search (the final one is chosen)
CAP_SLACK = 1e-6  # the search aims below the cap so that the final analysis stays under it
NOISE_SLACK = 1e-5  # relative: likewise for a noise cap (the exact proof rounds up)
SCREEN_TOL = 1e-5  # tolerance of the rate analyses inside the search
CERT_TOL = 1e-7  # tolerance of the certifying analysis
CLOUD_POINTS = {1: 21, 2: 9, 3: 5}  # grid points per axis, by number of free parameters
PENALTY = 1e3  # objective value of a point that breaks the constraint


def design_family(spec: Spec, family: CertificateFamily | str | None) -> CertificateFamily:
    """The family as a design with the noise sensitivity uses it: the one named, else the
    tightest that applies (:func:`sosalgo.certificates.default_family_name`, ``noise``), at
    its first automatic lag when it has several (choosing the lag at every θ is ~5x
    slower)."""
    fam = spec_family(spec, "noise") if family is None else (
        get_family(family) if isinstance(family, str) else family)
    lags = fam.auto_lags(spec.n)
    return fam.with_options(lag=lags[0]) if lags else fam


class Evaluator:
    """Screened values at θ (keys: tuples of the free parameters, clipped to Θ), cached;
    every call raises TimeoutError once ``deadline`` (``time.perf_counter``) has passed."""

    def __init__(self, spec: Spec, kappa: float, free: Sequence[str],
                 family: CertificateFamily, deadline: float):
        self.spec, self.kappa, self.free, self.family = spec, float(kappa), list(free), family
        self.deadline = deadline
        self.box = design_box(spec, kappa, self.free)
        self._algs: dict[tuple[float, ...], Any] = {}
        self._rates: dict[tuple[float, ...], float] = {}
        self._caps: dict[tuple[tuple[float, ...], float], bool] = {}
        self._noise: dict[tuple[float, ...], float] = {}

    def key(self, z: Sequence[float] | Mapping[str, float]) -> tuple[float, ...]:
        vals = [z[p] for p in self.free] if isinstance(z, Mapping) else list(z)
        return tuple(float(min(max(v, lo), hi))
                     for v, (lo, hi) in zip(vals, self.box, strict=True))

    def theta(self, key: tuple[float, ...]) -> dict[str, float]:
        return dict(zip(self.free, key, strict=True))

    def _tick(self) -> None:
        if time.perf_counter() > self.deadline:
            raise TimeoutError

    def alg(self, key: tuple[float, ...]) -> Any:
        if key not in self._algs:
            try:
                self._algs[key] = bind(self.spec, self.kappa, self.theta(key))
            except ModelError:
                self._algs[key] = None
        return self._algs[key]

    def rate(self, key: tuple[float, ...]) -> float:
        """Certified rate (analysis at SCREEN_TOL; inf when none)."""
        if key not in self._rates:
            self._tick()
            alg = self.alg(key)
            res = None if alg is None else _analysis(alg, self.family, SCREEN_TOL)
            self._rates[key] = _rate(res)
        return self._rates[key]

    def meets(self, key: tuple[float, ...], cap: float) -> bool:
        """Whether the family certifies rate ``cap`` at θ (a screened rate <= cap, or one
        margin SDP at rho = cap with a floating-point-checked solution)."""
        if self._rates.get(key, math.inf) <= cap:
            return True
        if (key, cap) not in self._caps:
            self._tick()
            alg = self.alg(key)
            self._caps[(key, cap)] = alg is not None and _certified_at(self.family, alg, cap)
        return self._caps[(key, cap)]

    def noise(self, key: tuple[float, ...]) -> float:
        """Certified noise bound at lag SEARCH_LAG, floating-point checked (inf: none)."""
        if key not in self._noise:
            self._tick()
            from sosalgo.sensitivity.sdp import noise_certificate

            alg = self.alg(key)
            g = None if alg is None else noise_certificate(alg, min(SEARCH_LAG, alg.n)).gamma
            self._noise[key] = math.inf if g is None else float(g)
        return self._noise[key]


def _analysis(alg: Any, fam: CertificateFamily, tol: float) -> AnalysisResult | None:
    from sosalgo.analysis import analyze_algorithm

    try:
        with np.errstate(all="ignore"):
            return analyze_algorithm(alg, tol, fam)
    except (ModelError, ValueError, np.linalg.LinAlgError):
        return None


def _rate(res: AnalysisResult | None) -> float:
    ok = res is not None and res.certified and res.rho is not None
    return float(res.rho) if ok else math.inf  # type: ignore[union-attr]


def _certified_at(fam: CertificateFamily, alg: Any, rho: float) -> bool:
    """One margin solve of the family's LMI at ``rho``, its point checked in floats."""
    from sosalgo.kernel.solvers import check_point, solve_margin

    try:
        with np.errstate(all="ignore"):
            problem = fam.problem(alg)
            mg = solve_margin(problem, rho)
            if not (mg.ok and mg.t is not None and mg.t > 0 and mg.x is not None):
                return False
            return check_point(problem, rho, mg.x, "clarabel-margin").feasible
    except (ModelError, ValueError, np.linalg.LinAlgError):
        return False


# --------------------------------------------------------------------------- the search
@dataclass(frozen=True)
class Sample:
    """A screened point of the cloud."""

    key: tuple[float, ...]
    rate: float
    noise: float


def cloud(ev: Evaluator, points: int | None = None) -> list[Sample]:
    """Screened rate and noise on a grid over Θ (noise only where a rate is certified);
    stops quietly at the deadline with the points done."""
    k = len(ev.free)
    pts = points or CLOUD_POINTS.get(k, 4)
    axes = [np.linspace(lo, hi, pts) if hi > lo else np.array([lo]) for lo, hi in ev.box]
    out = []
    try:
        for z in product(*axes):
            key = ev.key(z)
            r = ev.rate(key)
            out.append(Sample(key, r, ev.noise(key) if r < 1 else math.inf))
    except TimeoutError:
        pass
    return out


class _Best:
    """The objective, remembering its best point (so that a timeout loses nothing)."""

    def __init__(self, ev: Evaluator, f: Callable[[tuple[float, ...]], float]):
        self.ev, self.f = ev, f
        self.key: tuple[float, ...] | None = None
        self.value = math.inf

    def __call__(self, z: Sequence[float]) -> float:
        key = self.ev.key(z)
        v = self.f(key)
        if v < self.value:
            self.key, self.value = key, v
        return v


def _nelder_mead(best: _Best, start: tuple[float, ...],
                 fractions: Sequence[float] = (0.15, 0.03, 0.005)) -> None:
    """Nelder–Mead from ``start``, restarted from its result with smaller simplices
    (each steps away from the nearer bound); stops at the deadline."""
    from scipy.optimize import minimize

    lo = np.array([b[0] for b in best.ev.box])
    hi = np.array([b[1] for b in best.ev.box])
    width = np.maximum(hi - lo, 1e-300)
    x = np.array(start, dtype=float)
    k = len(x)
    try:
        best(x)
        for frac in fractions:
            steps = np.where(x - lo > hi - x, -1.0, 1.0) * width * frac
            simplex = np.clip(np.vstack([x, x + np.diag(steps)]), lo, hi)
            minimize(best, x, method="Nelder-Mead",
                     options={"initial_simplex": simplex, "maxfev": 60 * k,
                              "xatol": 1e-7 * float(width.max()), "fatol": 1e-9})
            if best.key is not None:
                x = np.array(best.key)
    except TimeoutError:
        pass


def _distinct(keys: Sequence[tuple[float, ...]], ev: Evaluator, wanted: int,
              apart: float = 0.1) -> list[tuple[float, ...]]:
    """The first ``wanted`` keys that are not within ``apart`` (box widths) of an earlier
    one."""
    width = np.array([max(hi - lo, 1e-300) for lo, hi in ev.box])
    out: list[tuple[float, ...]] = []
    for key in keys:
        if all(np.max(np.abs(np.subtract(key, o)) / width) > apart for o in out):
            out.append(key)
        if len(out) == wanted:
            break
    return out


def min_noise(ev: Evaluator, cap: float, starts: Sequence[tuple[float, ...]],
              polish: int = 2) -> tuple[tuple[float, ...] | None, float]:
    """The least sensitive θ found that meets the rate cap ``cap`` - CAP_SLACK:
    (key, screened noise), or (None, inf) when no start meets it. Nelder–Mead from the
    ``polish`` best distinct starts."""
    target = cap - CAP_SLACK

    def f(key: tuple[float, ...]) -> float:
        return ev.noise(key) if ev.meets(key, target) else PENALTY

    return _minimize(ev, f, starts, polish)


def min_rate(ev: Evaluator, max_noise: float, starts: Sequence[tuple[float, ...]],
             polish: int = 2) -> tuple[tuple[float, ...] | None, float]:
    """The fastest θ found whose screened noise is <= ``max_noise`` (1 - NOISE_SLACK):
    (key, screened rate), or (None, inf) when no start meets it."""
    bound = max_noise * (1 - NOISE_SLACK)

    def f(key: tuple[float, ...]) -> float:
        return ev.rate(key) if ev.noise(key) <= bound else PENALTY

    return _minimize(ev, f, starts, polish)


def _minimize(ev: Evaluator, f: Callable[[tuple[float, ...]], float],
              starts: Sequence[tuple[float, ...]], polish: int
              ) -> tuple[tuple[float, ...] | None, float]:
    best = _Best(ev, f)
    scored = []
    try:
        for key in dict.fromkeys(ev.key(s) for s in starts):
            v = best(key)
            if v < PENALTY:
                scored.append((v, key))
    except TimeoutError:
        pass
    scored.sort()
    for key in _distinct([k for _, k in scored], ev, polish):
        _nelder_mead(best, key)
    ok = best.key is not None and best.value < PENALTY
    return (best.key, best.value) if ok else (None, math.inf)


# --------------------------------------------------------------------------- certifying
@dataclass
class Point:
    """A θ certified on both axes: ``rho`` (proven in exact arithmetic when ``rho_check``
    is "exact": a float >= the proven rational ``rho_proven``; else the analysis's
    floating-point-checked rate, "float") and ``noise`` (the best lag, proven exactly when
    ``noise_check`` is "exact"). ``certificate`` is the rate certificate proven."""

    theta: dict[str, float]
    rho: float | None
    noise: float | None
    noise_quadratic: float | None
    noise_lag: int | None
    noise_check: str
    analysis: AnalysisResult | None = None
    noise_certificate: dict[str, Any] | None = None
    seconds: float = 0.0
    rho_check: str = "none"  # "exact", "float" (the proof failed) or "none"
    rho_proven: str | None = None  # the proven rational rate ("p/q")
    certificate: dict[str, Any] | None = None  # the rate certificate (family's parts)

    @property
    def certified(self) -> bool:
        return self.rho is not None and self.noise is not None

    @property
    def proven(self) -> bool:
        """Both axes proven in exact arithmetic."""
        return self.certified and self.rho_check == "exact" and self.noise_check == "exact"

    def to_dict(self) -> dict[str, Any]:
        return {"rho": self.rho, "noise": self.noise, "theta": dict(self.theta),
                "noise_quadratic": self.noise_quadratic, "noise_lag": self.noise_lag,
                "noise_check": self.noise_check, "rho_check": self.rho_check,
                "rho_proven": self.rho_proven, "certificate": self.certificate,
                "noise_certificate": self.noise_certificate}


RECERTIFY_STEPS = (1e-6, 1e-5, 1e-4)  # rho + step (1 - rho) tried when the proof fails


def float_up(q: Any) -> float:
    """The smallest float >= the rational ``q`` (a Fraction or "p/q")."""
    from sosalgo.kernel.exact import rational

    x = rational(q)
    f = float(x)
    return f if Fraction(f) >= x else math.nextafter(f, math.inf)


def _exact_rate(spec: Spec, kappa: float, theta: Mapping[str, float],
                family: CertificateFamily, rho: float, cert: dict[str, Any]) -> str | None:
    """The proven rational rate ("p/q") of ``cert`` at ``rho`` (the family's exact
    verifier, as ``sosalgo analyze --verify`` uses it), or None when not proven."""
    from sosalgo.kernel.exact import Verdict

    try:
        ex = family.exact_check(spec, kappa, rho, cert, theta)
    except (KeyError, TypeError, ValueError, ArithmeticError):
        return None
    return ex.rho_proven if ex.verified == Verdict.EXACT else None


def prove_rate(spec: Spec, kappa: float, theta: Mapping[str, float],
               family: CertificateFamily, res: AnalysisResult | None
               ) -> tuple[str | None, dict[str, Any] | None]:
    """(proven rational rate, its certificate) for the analysis ``res`` at θ: its own
    certificate proven exactly, else a margin solution of the family's LMI at
    rho + step (1 - rho) (RECERTIFY_STEPS, floating-point checked, then proven); (None,
    the analysis's certificate) when nothing is proven."""
    from sosalgo.kernel.solvers import check_point, solve_margin

    if res is None or not res.certified or res.rho is None or res.certificate is None:
        return None, None
    cert = jsonable(res.certificate)
    proven = _exact_rate(spec, kappa, theta, family, res.rho, cert)
    if proven is not None:
        return proven, cert
    try:
        with np.errstate(all="ignore"):
            problem = family.problem(bind(spec, kappa, theta))
    except (ModelError, ValueError, np.linalg.LinAlgError):
        return None, cert
    for step in RECERTIFY_STEPS:
        r = min(res.rho + step * (1 - res.rho), 1.0)
        with np.errstate(all="ignore"):
            mg = solve_margin(problem, r)
            ok = mg.ok and mg.t is not None and mg.t > 0 and mg.x is not None and \
                check_point(problem, r, mg.x, "clarabel-margin").feasible
        if ok:
            again = jsonable(problem.unpack(mg.x))
            proven = _exact_rate(spec, kappa, theta, family, r, again)
            if proven is not None:
                return proven, again
    return None, cert


def certify_point(spec: Spec, kappa: float, theta: Mapping[str, float],
                  family: CertificateFamily, exact: bool = True) -> Point:
    """Both axes at θ through the public analyses: the certified rate (``analyze_spec``,
    tol 1e-7, then proven exactly by :func:`prove_rate` with ``exact``) and the certified
    sensitivity (``analyze_noise``: the best lag, proven in exact arithmetic with
    ``exact``) with the sensitivity on quadratics."""
    from sosalgo.sensitivity.run import analyze_noise

    t0 = time.perf_counter()
    th = {p: float(v) for p, v in theta.items()}
    try:
        with np.errstate(all="ignore"):
            res: AnalysisResult | None = analyze_spec(spec, kappa, th, tol=CERT_TOL,
                                                      family=family)
        nz = analyze_noise(spec, kappa, th, exact=exact, limsup=False)
    except ModelError:
        return Point(th, None, None, None, None, "none", seconds=time.perf_counter() - t0)
    rho = None if math.isinf(_rate(res)) else _rate(res)
    proven, cert = prove_rate(spec, kappa, th, family, res) if exact and rho is not None \
        else (None, None if res is None or res.certificate is None
              else jsonable(res.certificate))
    q = nz.noise_quadratic
    return Point(th, rho if proven is None else float_up(proven), nz.noise,
                 q if math.isfinite(q) else None, nz.lag if nz.noise is not None else None,
                 nz.check_kind, res, nz.certificate, time.perf_counter() - t0,
                 "none" if rho is None else "exact" if proven is not None else "float",
                 proven, cert)


# --------------------------------------------------------------------------- the design
@dataclass
class ObjectiveDesignResult(DesignResult):
    """A design with a second objective: the :class:`DesignResult` fields (``lower_bound``
    None, ``relaxation.status`` "unsupported") plus the noise axis and the constraint."""

    objective: str = "rate"
    rho_check: str = "none"  # "exact": rho_certified is proven in exact arithmetic
    rho_proven: str | None = None  # the proven rational rate
    max_rate: float | None = None
    max_noise: float | None = None
    noise: float | None = None
    noise_quadratic: float | None = None
    noise_lag: int | None = None
    noise_check: str = "none"
    objective_status: str = "none found"  # "met": certified values meet the constraint
    noise_certificate: dict[str, Any] | None = field(default=None, repr=False)

    def objective_cells(self) -> dict[str, Any]:
        """The fields this design adds to a design document and CSV row."""
        return {"objective": self.objective, "max_rate": self.max_rate,
                "max_noise": self.max_noise, "noise": self.noise,
                "noise_quadratic": self.noise_quadratic, "noise_lag": self.noise_lag,
                "noise_check": self.noise_check, "objective_status": self.objective_status,
                "bound_status": "unsupported", "rho_check": self.rho_check,
                "rho_proven": self.rho_proven,
                "noise_certificate": None if self.noise_certificate is None
                else json.dumps(self.noise_certificate, separators=(",", ":"))}

    def to_dict(self) -> dict[str, Any]:
        return super().to_dict() | self.objective_cells() | {
            "noise_certificate": self.noise_certificate}


def check_noise_spec_for(spec: Spec, label: str) -> None:
    """InputError naming the file and ``label`` unless the spec has one gradient call on
    F(m, L) (what the noise sensitivity needs: :mod:`sosalgo.sensitivity`)."""
    if not spec.has_seed_form:  # m: 0 is not the seed's form either
        raise InputError(f"{spec.source}: {label}: noise sensitivity needs one gradient "
                         "call on F(m, L) (a spec without functions/oracles/D/output/measure "
                         "and with m > 0)")


def check_objective(spec: Spec, kappas: Sequence[float], objective: str,
                    max_rate: float | None, max_noise: float | None) -> None:
    """InputError (one line naming the option) unless the objective and its cap make
    sense; a rate cap below 1 - 1/sqrt(kappa) is infeasible for every first-order method
    on F(m, L) (a theorem), so it is refused too."""
    if objective not in OBJECTIVES:
        raise InputError(f"--objective {objective}: must be rate or noise")
    if objective == "noise" and max_rate is None:
        raise InputError("--objective noise: needs --max-rate R (the cap on the rate)")
    if objective == "rate" and max_rate is not None:
        raise InputError("--max-rate: only with --objective noise")
    if objective == "noise" and max_noise is not None:
        raise InputError("--max-noise: only with --objective rate")
    for label, v, hi in (("--max-rate", max_rate, 1.0), ("--max-noise", max_noise, math.inf)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)
                              or not 0 < v < hi):
            raise InputError(f"{label} {v}: must be " + ("in (0, 1)" if hi == 1.0
                                                         else "positive and finite"))
    if objective == "rate" and max_noise is None:
        return
    check_noise_spec_for(spec, "--objective noise" if objective == "noise" else "--max-noise")
    for k in kappas if max_rate is not None else ():
        floor = 1 - 1 / math.sqrt(k)
        if max_rate < floor:  # type: ignore[operator]
            raise InputError(f"--max-rate {max_rate}: infeasible at kappa {k:g}: below "
                             f"1 - 1/sqrt(kappa) = {floor:.6f}, no first-order method is "
                             "that fast on F(m, L)")


def _starts(ev: Evaluator, samples: Sequence[Sample], objective: str, cap: float
            ) -> list[tuple[float, ...]]:
    """The cloud's points that meet the constraint, best first."""
    if objective == "noise":
        ok = [s for s in samples if s.rate <= cap - CAP_SLACK and math.isfinite(s.noise)]
        return [s.key for s in sorted(ok, key=lambda s: s.noise)]
    ok = [s for s in samples if s.noise <= cap * (1 - NOISE_SLACK) and s.rate < 1]
    return [s.key for s in sorted(ok, key=lambda s: s.rate)]


def _meets(pt: Point, objective: str, cap: float) -> bool:
    """The constraint on the values proven exactly (both axes)."""
    if not pt.proven:
        return False
    return pt.rho <= cap if objective == "noise" else pt.noise <= cap  # type: ignore[operator]


def objective_design(spec: Spec, kappa: float, objective: str = "noise",
                     max_rate: float | None = None, max_noise: float | None = None,
                     free: Sequence[str] | None = None,
                     family: CertificateFamily | str | None = None,
                     time_limit: float = 120.0, workers: int | None = None,
                     on_step: Callable[[str], None] | None = None) -> ObjectiveDesignResult:
    """The least sensitive θ with certified rate <= ``max_rate`` (``objective="noise"``)
    or the fastest θ with certified sensitivity <= ``max_noise`` (``objective="rate"``),
    searched over Θ within ``time_limit`` seconds (module docstring); both axes of the
    result certified at the returned θ."""
    t0 = time.perf_counter()
    check_objective(spec, [kappa], objective, max_rate, max_noise)
    cap = float(max_rate if objective == "noise" else max_noise)  # type: ignore[arg-type]
    names = list(spec.ranged if free is None else free)
    spec.check_free(names)
    fam = design_family(spec, family)
    ev = Evaluator(spec, kappa, names, fam, t0 + 0.85 * time_limit)
    steps: list[str] = []

    def log(msg: str) -> None:
        steps.append(msg)
        if on_step is not None:
            on_step(msg)

    samples = cloud(ev)
    starts = _starts(ev, samples, objective, cap)
    log(f"cloud: {len(samples)} points, {len(starts)} meet the constraint")
    if not starts and objective == "noise":  # the fastest θ first (the rate design)
        starts = _fast_start(spec, kappa, names, fam, ev, time_limit, workers, log)
    search = min_noise if objective == "noise" else min_rate
    key, val = search(ev, cap, starts)
    if key is not None:
        log(f"search: screened {'noise' if objective == 'noise' else 'rate'} {val:.8f}")
    chosen = certify_first(spec, kappa, fam, ev, [key] + starts, objective, cap, log)
    return _objective_result(spec, kappa, names, fam, chosen, objective, max_rate,
                             max_noise, steps, time.perf_counter() - t0,
                             time.perf_counter() > ev.deadline)


def _fast_start(spec: Spec, kappa: float, names: list[str], fam: CertificateFamily,
                ev: Evaluator, time_limit: float, workers: int | None,
                log: Callable[[str], None]) -> list[tuple[float, ...]]:
    """No cloud point meets the rate cap: the rate design (:func:`sosalgo.design_search.design`)
    with half the time left gives the fastest θ it finds."""
    from sosalgo.design_search import design

    left = ev.deadline - time.perf_counter()
    if left < 2.0:
        return []
    res = design(spec, kappa, free=names, family=fam, time_limit=0.5 * left, workers=workers)
    log(f"no cloud point meets the cap: rate design certified {res.rho_certified}")
    return [ev.key(res.theta)] if res.theta else []


def certify_first(spec: Spec, kappa: float, fam: CertificateFamily, ev: Evaluator,
                   keys: Sequence[tuple[float, ...] | None], objective: str, cap: float,
                   log: Callable[[str], None], tries: int = 3,
                   until: float | None = None) -> Point | None:
    """Certify the candidates in order; the first whose certified values meet the
    constraint (None when none of the first ``tries`` does, or when the time.perf_counter
    instant ``until`` has passed before the next candidate: the first is always tried)."""
    keys = list(dict.fromkeys(k for k in keys if k is not None))[:tries]
    for i, key in enumerate(keys):
        if i and until is not None and time.perf_counter() > until:
            log("out of time: no further candidate certified")
            return None
        pt = certify_point(spec, kappa, ev.theta(key), fam)
        if _meets(pt, objective, cap):
            log(f"certified: rate {pt.rho:.8f} ({pt.rho_check}), noise {pt.noise:.8f} "
                f"({pt.noise_check})")
            return pt
        log(f"candidate {ev.theta(key)} certified rate {pt.rho} ({pt.rho_check}), noise "
            f"{pt.noise} ({pt.noise_check}): constraint not met on proven values, next "
            "candidate")
    return None


def _objective_result(spec: Spec, kappa: float, names: list[str], fam: CertificateFamily,
                      pt: Point | None, objective: str, max_rate: float | None,
                      max_noise: float | None, steps: list[str], seconds: float,
                      timed_out: bool) -> ObjectiveDesignResult:
    from sosalgo.design_search.floor import class_floor

    res = None if pt is None else pt.analysis
    cert: dict[str, Any] = {}
    if pt is not None and res is not None and pt.certificate is not None:
        cert = {**pt.certificate, **_summary(spec, kappa, pt, fam)}
    values = _analysis(bind(spec, kappa), fam, CERT_TOL)
    if pt is None:
        steps.append("no θ found whose certified values meet the constraint (not a proof "
                     "that none exists)")
    return ObjectiveDesignResult(
        spec=spec.name, kappa=float(kappa), free=names, lower_bound=None,
        theta={} if pt is None else dict(pt.theta), rho_certified=None if pt is None
        else pt.rho, gap=None, certificate=cert,
        relaxation={"method": None, "status": "unsupported", "scalarize": None,
                    "order": None, "flat": None, "ranks": []},
        seconds=seconds, steps=steps, rho_at_values=None if math.isinf(_rate(values))
        else _rate(values), method="search", floor=class_floor(spec, kappa),
        values_certificate=None if math.isinf(_rate(values))
        else jsonable(values.certificate or {}),
        time_limited=timed_out, family=fam.name, lag=fam.options().get("lag"),
        objective=objective, rho_check="none" if pt is None else pt.rho_check,
        rho_proven=None if pt is None else pt.rho_proven, max_rate=max_rate,
        max_noise=max_noise, noise=None if pt is None else pt.noise,
        noise_quadratic=None if pt is None else pt.noise_quadratic,
        noise_lag=None if pt is None else pt.noise_lag,
        noise_check="none" if pt is None else pt.noise_check,
        objective_status="none found" if pt is None else "met",
        noise_certificate=None if pt is None else pt.noise_certificate)


def _summary(spec: Spec, kappa: float, pt: Point, fam: CertificateFamily
             ) -> dict[str, float | None]:
    """max_eig_M and min_eig_P of the proven rate certificate at the proven rate."""
    try:
        with np.errstate(all="ignore"):
            eigs = fam.summary(bind(spec, kappa, pt.theta), float(pt.rho),  # type: ignore[arg-type]
                               pt.certificate)  # type: ignore[arg-type]
        return {k: float(eigs[k]) for k in ("max_eig_M", "min_eig_P")}
    except (ModelError, ValueError, TypeError, KeyError, np.linalg.LinAlgError):
        return {"max_eig_M": None, "min_eig_P": None}


def objective_json(row: Mapping[str, str]) -> dict[str, Any]:
    """The JSON fields of a design CSV row's OBJECTIVE_COLUMNS."""
    def num(v: str | None) -> float | None:
        return None if v in (None, "") else float(v)

    return {"objective": row["objective"], "max_rate": num(row.get("max_rate")),
            "max_noise": num(row.get("max_noise")), "noise": num(row.get("noise")),
            "noise_quadratic": num(row.get("noise_quadratic")),
            "noise_lag": int(row["noise_lag"]) if row.get("noise_lag") else None,
            "noise_check": row.get("noise_check") or "none",
            "objective_status": row.get("objective_status") or None,
            "bound_status": row.get("bound_status") or "unsupported",
            "rho_check": row.get("rho_check") or "none",
            "rho_proven": row.get("rho_proven") or None,
            "noise_certificate": json.loads(row["noise_certificate"])
            if row.get("noise_certificate") else None}
