"""``design SPEC --steps N``: minimize the N-step worst case tau_N(θ) over the box Θ.

Three numbers come out, never mixed:

* ``tau_certified``: the worst case at the designed θ (``schedule``, decimals), its dual
  certificate proven exactly as ``sosalgo pep`` proves it (:func:`sosalgo.worstcase.pep`), so
  tau_N(schedule) <= tau_certified. θ comes from a local search of the float PEP value
  (the ``evaluator`` given: :func:`sosalgo.worstcase.evaluate.worst_case_evaluator`) from
  a grid, polished, and from the centres of the boxes the bound search splits.
* ``lower_bound``: proven over the whole box: tau_N(θ) >= lower_bound for every θ in Θ
  (:mod:`sosalgo.design_search.steps_bound`: branch and bound over boxes, each proven in exact
  rational arithmetic).
* ``floor``: only where a theorem gives it: for m = 0, one L-smooth convex f queried by
  its gradient and a method whose iterates stay in x_0 + span(g_0, ...) (every linear
  method started at rest), no method has a worst case below L / (2 theta_N^2) after N
  gradient calls, OGM's theta (Drori 2017). None otherwise.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.design_search.steps_bound import BranchResult, branch_and_bound
from sosalgo.design_search.steps_model import Unsupported, parametric_pep
from sosalgo.errors import InputError
from sosalgo.kernel.phases import show_phase
from sosalgo.spec import Spec

__all__ = ["StepsDesign", "StepsProblem", "design_steps", "drori_floor", "exact_box",
           "flat_names", "obs_f", "ogm_theta", "pack", "steps_problem",
           "value_text"]

DIGITS = 12  # significant digits of the designed values (the exact θ of the proof)
SEARCH_SHARE = 0.3  # of the time limit, for the upper bound's search before the bound
STOP_SHARE = 0.9  # the bound search stops at a relative gap of this share of --gap (the
# rest: the certificate's margin over the float worst case, about 1e-6 relative)
STALL_HOPS = 12  # up to 4 free values: the random restarts end after this many fail


@dataclass
class StepsDesign:
    """The result of :func:`design_steps` (``to_dict``: the ``design --steps --json``
    document; ``schedule``, ``tau_certified``, ``lower_bound``, ``gap``, ``floor`` are
    contracts)."""

    spec: str
    kappa: float | None
    steps: int
    free: list[str]
    schedule: dict[str, Any]
    schedule_exact: dict[str, Any]
    tau_certified: float | None
    tau_certified_exact: str | None
    tau_float: float | None
    lower_bound: float | None
    lower_bound_exact: str | None
    floor: float | None
    seconds: float
    time_limited: bool = False
    bound: dict[str, Any] = field(default_factory=dict)
    log: list[str] = field(default_factory=list)

    @property
    def gap(self) -> float | None:
        if self.tau_certified is None or self.lower_bound is None:
            return None
        return self.tau_certified - self.lower_bound

    def to_dict(self) -> dict[str, Any]:
        gap = self.gap
        rel = (None if gap is None or not self.tau_certified
               else gap / self.tau_certified)
        return {"spec": self.spec, "kappa": self.kappa, "steps": self.steps,
                "free": list(self.free), "schedule": self.schedule,
                "schedule_exact": self.schedule_exact,
                "tau_certified": self.tau_certified,
                "tau_certified_exact": self.tau_certified_exact,
                "tau_float": self.tau_float, "lower_bound": self.lower_bound,
                "lower_bound_exact": self.lower_bound_exact, "gap": gap,
                "gap_relative": rel, "floor": self.floor,
                "floor_theorem": None if self.floor is None else
                "Drori 2017: L/(2 theta_N^2), OGM's theta, every method in the span of "
                "the gradients on L-smooth convex f",
                "seconds": self.seconds, "time_limited": self.time_limited,
                "bound": self.bound, "log": list(self.log)}


def ogm_theta(steps: int) -> float:
    """OGM's theta_N: theta_0 = 1, theta_{i+1} = (1 + sqrt(1 + 4 theta_i^2)) / 2, the last
    (1 + sqrt(1 + 8 theta_{N-1}^2)) / 2."""
    th = 1.0
    for i in range(steps):
        c = 8.0 if i == steps - 1 else 4.0
        th = (1 + math.sqrt(1 + c * th * th)) / 2
    return th


def drori_floor(spec: Spec, steps: int) -> float | None:
    """L / (2 theta_N^2) where the theorem applies (see the module), else None."""
    if spec.has_condition_number or spec.L is None:
        return None
    from sosalgo.design_search.steps_model import check_setting

    try:
        check_setting(spec)  # one smooth convex f by its gradient, linear, at rest
    except Unsupported:
        return None
    return float(spec.L) / (2 * ogm_theta(steps) ** 2)


# ------------------------------------------------------------------ the worst case at θ
Values = dict[str, Any]  # parameter -> number (or per-step list)


def _decimal(x: float) -> str:
    return f"{x:.{DIGITS}g}"


def value_text(v: Any) -> str:
    """A parameter value as the decimal (or list of decimals) the proofs use."""
    if isinstance(v, list | tuple):
        return "[" + ", ".join(value_text(x) for x in v) + "]"
    return v if isinstance(v, str) else _decimal(float(v))


# ------------------------------------------------------------------ the search
Layout = Sequence[tuple[str, int | None]]  # (parameter, N values per step, or None: one)


def flat_names(layout: Layout) -> list[str]:
    """The names of the free values: ``h`` for one value, ``h_0, ..., h_{N-1}`` per step."""
    from sosalgo.design_search.steps_model import step_symbol

    return [step_symbol(p, None if n is None else k) for p, n in layout for k in range(n or 1)]


def pack(layout: Layout, z: Sequence[Any]) -> Values:
    """The flat values as parameter -> value (or per-step list)."""
    out: Values = {}
    i = 0
    for p, n in layout:
        out[p] = z[i] if n is None else list(z[i:i + n])
        i += n or 1
    return out


class _Stop(Exception):
    """The search's time is up (raised inside a scipy minimizer)."""


class _Search:
    """The best θ found (float PEP values), over the box [lo, hi] of the flat values;
    ``point``: the parametric model's float PEP at a point (value and gradient,
    :class:`sosalgo.design_search.steps_model.PointSearch`), else the evaluator's value alone."""

    def __init__(self, layout: Layout, lo: np.ndarray, hi: np.ndarray,
                 value: Callable[[Values], float], point: Any = None):
        self.layout, self.lo, self.hi = layout, lo, hi
        self.value, self.point = value, point
        self.best_z: np.ndarray | None = None
        self.best = math.inf
        self.evals = 0
        self.stop = math.inf  # the minimizers stop at this time

    def _record(self, z: np.ndarray, v: float) -> None:
        self.evals += 1
        if v < self.best:
            self.best, self.best_z = v, z

    def __call__(self, z: Sequence[float]) -> float:
        if time.time() > self.stop:
            raise _Stop
        zc = self.round(np.clip(np.asarray(z, float), self.lo, self.hi))
        v = (self.point.value_grad(zc)[0] if self.point is not None
             else self.value(pack(self.layout, [float(x) for x in zc])))
        self._record(zc, v)
        return v

    def with_grad(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        if time.time() > self.stop:
            raise _Stop
        zc = np.clip(np.asarray(z, float), self.lo, self.hi)
        v, g = self.point.value_grad(zc)
        if v < self.best:  # the decimals the proof uses, checked
            self(zc)
        return v, g

    def hop(self, deadline: float, scale: float = 0.05, seed: int = 0) -> int:
        """Restarts of the gradient descent from random points near the best (a normal
        step of ``scale`` times the box, wider after failures) until ``deadline``: the
        worst case is a max over functions, its kinks stop a descent early. Up to 4 free
        values, :data:`STALL_HOPS` restarts in a row that improve nothing end it (the
        bound's time then starts sooner; the bound's probes keep searching)."""
        from scipy.optimize import minimize

        rng = np.random.default_rng(seed)
        bounds = list(zip(self.lo, self.hi, strict=True))
        hops, sigma, failed = 0, scale, 0
        self.stop = deadline
        while time.time() < deadline and self.best_z is not None:
            before = self.best
            z = np.clip(self.best_z + rng.normal(0.0, sigma, len(self.lo)) *
                        (self.hi - self.lo), self.lo, self.hi)
            try:
                minimize(self.with_grad, z, jac=True, method="L-BFGS-B", bounds=bounds,
                         options={"maxiter": 150, "ftol": 1e-12, "gtol": 1e-10})
            except _Stop:
                break
            finally:
                self.stop = deadline
            hops += 1
            better = self.best < before * (1 - 1e-9)
            failed = 0 if better else failed + 1
            if failed >= STALL_HOPS and len(self.lo) <= 4:
                break
            sigma = scale if better else min(4 * scale, sigma * 1.5)
        self.stop = math.inf
        return hops

    def round(self, z: np.ndarray) -> np.ndarray:
        """The decimals the proof will use, inside the box."""
        r = np.array([float(_decimal(float(x))) for x in z])
        return np.clip(r, self.lo, self.hi)

    def polish(self, z0: np.ndarray, deadline: float, tol: float = 1e-9) -> None:
        """Local descent from z0 until ``deadline`` (see :meth:`_polish`)."""
        if time.time() >= deadline:
            return
        self.stop = deadline
        try:
            self._polish(z0, tol)
        except _Stop:
            pass
        finally:
            self.stop = math.inf

    def _polish(self, z0: np.ndarray, tol: float) -> None:
        from scipy.optimize import minimize, minimize_scalar

        bounds = list(zip(self.lo, self.hi, strict=True))
        if len(z0) == 1:
            w = (self.hi[0] - self.lo[0]) / 20
            a, b = max(self.lo[0], z0[0] - w), min(self.hi[0], z0[0] + w)
            minimize_scalar(lambda x: self([x]), bounds=(a, b), method="bounded",
                            options={"xatol": tol * max(1.0, abs(z0[0]))})
            return
        if self.point is not None:
            minimize(self.with_grad, z0, jac=True, method="L-BFGS-B", bounds=bounds,
                     options={"maxiter": 300, "ftol": 1e-13, "gtol": 1e-11})
            z0 = self.best_z if self.best_z is not None else z0
        minimize(self, z0, method="Nelder-Mead",
                 options={"xatol": tol, "fatol": tol * max(self.best, 1e-12),
                          "maxfev": 400 * len(z0),
                          "initial_simplex": _simplex(z0, self.lo, self.hi)},
                 bounds=bounds)


def _simplex(z0: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """A small simplex around z0 (a twentieth of the box), inside the box."""
    step = (hi - lo) / 20
    pts = [z0]
    for i in range(len(z0)):
        z = z0.copy()
        z[i] = z[i] + step[i] if z[i] + step[i] <= hi[i] else z[i] - step[i]
        pts.append(z)
    return np.array(pts)


def _starts(search: _Search, seeds: list[np.ndarray], deadline: float) -> list[np.ndarray]:
    """A grid (one parameter) or random points and the seeds, best first."""
    k = len(search.lo)
    if k == 1:
        pts = [np.array([x]) for x in np.linspace(search.lo[0], search.hi[0], 41)]
    else:
        rng = np.random.default_rng(0)
        pts = [search.lo + rng.random(k) * (search.hi - search.lo)
               for _ in range(4 * k if search.point is not None else 12 * k)]
    scored = []
    for z in seeds + pts:
        if time.time() >= deadline:
            break
        scored.append((search(z), len(scored), z))
    scored.sort(key=lambda t: (t[0], t[1]))
    return [z for _, _, z in scored]


# ------------------------------------------------------------------ the design
def design_steps(spec: Spec, text: str, kappa: float | None, steps: int, layout: Layout,
                 box: Sequence[tuple[Fraction, Fraction]],
                 evaluator: tuple[Callable, Callable], time_limit: float = 120.0,
                 gap: float = 1e-3, seeds: Sequence[Sequence[float]] = (),
                 model: Any = None, no_model: str | None = None,
                 box_workers: int = 1) -> StepsDesign:
    """The N-step design of ``spec`` over ``box`` (exact ends, one per flat free value,
    :func:`flat_names` of ``layout``): schedule, tau_certified, lower_bound, floor (see
    the module). ``evaluator``: (float worst case at θ, proven worst case at θ), θ a dict
    of parameter values (:func:`sosalgo.worstcase.evaluate.worst_case_evaluator`); ``model``:
    the parametric PEP (:func:`sosalgo.design_search.steps_model.parametric_pep`; built here for
    a time-invariant spec when None, unless ``no_model`` says why there is none: then no
    box-wide bound, and the search uses the evaluator's values); ``gap``: the relative
    gap at which the bound search stops; ``box_workers``: the processes the bound proves
    boxes on (:func:`sosalgo.design_search.steps_bound.branch_and_bound`)."""
    t0 = time.time()
    deadline = t0 + time_limit
    names = flat_names(layout)
    value, proven = evaluator
    lo = np.array([float(a) for a, _ in box])
    hi = np.array([float(b) for _, b in box])
    log: list[str] = []
    if no_model is not None:
        log.append(f"no box-wide lower bound: {no_model}")
    elif model is None:
        try:
            model = parametric_pep(spec, kappa, steps, names)
        except Unsupported as exc:
            log.append(f"no box-wide lower bound: {exc}")
    point = None
    if model is not None:
        from sosalgo.design_search.steps_model import PointSearch

        point = PointSearch(model)
    search = _Search(layout, lo, hi, value, point)
    show_phase("searching")  # the task names N (:func:`sosalgo.runs.pep.task_kappa`)
    span = (SEARCH_SHARE if len(lo) <= 4 else 2 * SEARCH_SHARE) * time_limit
    share = t0 + span
    starts = _starts(search, [np.asarray(s, float) for s in seeds], t0 + 0.2 * span)
    hopping = point is not None and len(lo) > 1
    for i, z in enumerate(starts[:3]):
        search.polish(z, t0 + (0.2 + 0.2 * (i + 1)) * span if hopping else share)
    hops = search.hop(share) if hopping else 0
    log.append(f"search: {search.evals} PEPs" + (
        f" ({hops} random restarts near the best)" if hopping else "")
        + f", best {search.best:.12g}")
    bound = None
    if model is not None:
        bound, reason = _bound(model, box, search, deadline, gap, box_workers)
        log.append(reason)
    if search.best_z is not None:
        search.polish(search.best_z, deadline - 0.1 * time_limit)
    return _finish(spec, kappa, steps, layout, search, proven, bound, log, t0, deadline)


def _bound(pp: Any, box: Sequence[tuple[Fraction, Fraction]], search: _Search,
           deadline: float, gap: float, workers: int = 1) -> tuple[BranchResult, str]:
    def report(boxes: int, low: float) -> None:
        show_phase("lower bound", f"{boxes} boxes, bound {low:.6g}, best {search.best:.6g}")

    def probe(z: list[float]) -> Any:
        if time.time() >= deadline:
            return None
        if search.point is None:
            search(z)
            return None
        v, g = search.with_grad(np.asarray(z, float))
        return g

    res = branch_and_bound(pp, [a for a, _ in box], [b for _, b in box],
                           lambda: search.best, deadline - 0.15 * (deadline - time.time()),
                           STOP_SHARE * gap, probe, report, workers=workers)
    return res, (f"bound: {res.boxes} boxes in {res.seconds:.1f} s"
                 + (f" on {workers} processes" if workers > 1 else "")
                 + (f" ({res.lost} lost by a worker, proven here)" if res.lost else "")
                 + ", leaves proven by "
                 + ", ".join(f"{k} {v}" for k, v in sorted(res.hows.items())))


def _finish(spec: Spec, kappa: float | None, steps: int, layout: Layout, search: _Search,
            proven: Callable, bound: BranchResult | None, log: list[str], t0: float,
            deadline: float) -> StepsDesign:
    show_phase("proving the worst case")
    sched: dict[str, Any] = {}
    exact: dict[str, Any] = {}
    tp, tf = None, None
    if search.best_z is not None:
        exact = pack(layout, [_decimal(float(x)) for x in search.best_z])
        sched = {k: ([float(x) for x in v] if isinstance(v, list) else float(v))
                 for k, v in exact.items()}
        tp, tf = proven(exact)
    lb = None if bound is None else bound.lower_bound
    res = StepsDesign(spec.name, kappa, steps, [p for p, _ in layout], sched, exact,
                      None if tp is None else _up(tp), None if tp is None else str(tp),
                      tf, None if lb is None else _down(lb),
                      None if lb is None else str(lb), drori_floor(spec, steps),
                      time.time() - t0, time_limited=time.time() >= deadline or (
                          bound is not None and not bound.finished))
    res.log = log
    if bound is not None:
        res.bound = _bound_doc(bound)
    return res


def _up(q: Fraction) -> float:
    f = float(q)
    return f if Fraction(f) >= q else float(np.nextafter(f, math.inf))


def _down(q: Fraction) -> float:
    f = float(q)
    return f if Fraction(f) <= q else float(np.nextafter(f, -math.inf))


def _bound_doc(b: BranchResult) -> dict[str, Any]:
    """The leaves of the bound (boxes, how each was proven, its bound)."""
    return {"boxes": b.boxes, "seconds": b.seconds, "finished": b.finished,
            "proven_by": dict(b.hows),
            "leaves": [_leaf_doc(leaf) for leaf in b.leaves]}


def _leaf_doc(leaf: Any) -> dict[str, Any]:
    doc = {"lo": [str(x) for x in leaf.lo], "hi": [str(x) for x in leaf.hi],
           "how": leaf.how, "bound": str(leaf.bound)}
    if leaf.rung:
        doc["rung"] = leaf.rung
    if leaf.point is not None:  # V: the point G = V V' / 4^52, re-checked by verify
        doc["point"] = [[str(v) for v in row] for row in leaf.point]
    if leaf.slopes is not None and any(v for row in leaf.slopes for v in row):
        doc["slopes"] = [[str(v) for v in row] for row in leaf.slopes]
    if leaf.gram is not None:  # the affine point G_0, G_1, ..., re-checked by verify
        doc["gram"] = [[[str(v) for v in row] for row in G] for G in leaf.gram]
        doc.setdefault("slopes", [[str(v) for v in row] for row in leaf.slopes or []])
    if leaf.proven_on is not None:  # proven on an ancestor box, which contains it
        doc["proven_on"] = [[str(x) for x in leaf.proven_on[0]],
                            [str(x) for x in leaf.proven_on[1]]]
    return doc


def exact_box(spec: Spec, kappa: float | None, names: Sequence[str]
              ) -> list[tuple[Fraction, Fraction]]:
    """Each free parameter's range as exact rationals (an irrational end rounded outward
    to a float: a larger box, on which the lower bound still holds); InputError naming
    ``parameters.<name>.range`` when missing or empty."""
    import sympy as sp

    from sosalgo.design_search.steps_model import exact_class
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.spec.types import BASE_SYMBOLS

    try:
        m, L = exact_class(spec, kappa)
    except Unsupported as exc:
        raise InputError(f"{spec.source}: --kappa: {exc}") from None
    env = {BASE_SYMBOLS["m"]: sp.Rational(m.numerator, m.denominator),
           BASE_SYMBOLS["L"]: sp.Rational(L.numerator, L.denominator)}
    if m:
        kq = L / m
        env[BASE_SYMBOLS["kappa"]] = sp.Rational(kq.numerator, kq.denominator)
    out = []
    for p in names:
        par = spec.parameters[p]
        if par.range is None:
            raise InputError(f"{spec.source}: parameters.{p}.range: missing (design "
                             "--steps needs the box of every free parameter)")
        lo, hi = (_rational_end(to_sympy(e).xreplace(env), down)
                  for e, down in zip(par.range, (True, False), strict=True))
        if lo > hi:
            raise InputError(f"{spec.source}: parameters.{p}.range: empty box "
                             f"[{float(lo):g}, {float(hi):g}]")
        out.append((lo, hi))
    return out


def _rational_end(v: Any, down: bool) -> Fraction:
    import sympy as sp

    if v.is_Rational:
        return Fraction(int(v.p), int(v.q))
    f = float(v)
    q = Fraction(f)
    exact = sp.Rational(q.numerator, q.denominator)
    if (down and exact > v) or (not down and exact < v):
        q = Fraction(float(np.nextafter(f, -math.inf if down else math.inf)))
    return q


@dataclass
class StepsProblem:
    """What an N-step design runs on: the layout of the free values, their exact box,
    the parametric PEP (None: no box-wide bound, ``reason`` says why) and the spec's own
    values as a start."""

    layout: list[tuple[str, int | None]]
    box: list[tuple[Fraction, Fraction]]
    model: Any
    seeds: list[list[float]]
    reason: str | None = None


def steps_problem(spec: Spec, kappa: float | None, steps: int, names: Sequence[str]
                  ) -> StepsProblem:
    """The problem of ``design --steps`` (see :class:`StepsProblem`): a parameter that
    varies with k (``per_step``) is free at every step k = 0..N-1 of a spec that varies
    with k, one value otherwise."""
    from sosalgo.design_search.steps_model import step_symbol, varying_matrices

    ranges = exact_box(spec, kappa, names)
    from sosalgo.steps import changes_with_k

    varying = changes_with_k(spec)
    per = [(p, varying and bool(getattr(spec.parameters[p], "per_step", False)))
           for p in names]
    layout: list[tuple[str, int | None]] = [(p, steps if v else None) for p, v in per]
    box = [r for r, (_, n) in zip(ranges, layout, strict=True) for _ in range(n or 1)]
    if not varying:
        return StepsProblem(layout, box, None, [])
    flat = [step_symbol(p, k if n else None) for p, n in layout for k in range(n or 1)]
    try:
        at, own = varying_matrices(spec, kappa, steps, per)
        model = parametric_pep(spec, kappa, steps, flat, at)
    except Unsupported as exc:
        return StepsProblem(layout, box, None, [], str(exc))
    seed = [own[k][i] for i, (_, n) in enumerate(layout)  # parameter-major, as flat
            for k in range(n or 1)]
    ok = all(math.isfinite(x) for x in seed)
    seeds = [seed] if ok else []
    if ok and any(n for _, n in layout):  # long-step starts for the per-step values
        obs = obs_f(steps)[0]
        for pattern in (long_step, lambda k: obs[k]):
            seeds.append([min(max(x * (pattern(k) if n else 1.0), float(a)), float(b))
                          for (x, (a, b)), k, n in zip(zip(seed, box, strict=True),
                                                       _step_index(layout), _per(layout),
                                                       strict=True)])
    return StepsProblem(layout, box, model, seeds)


SILVER = 1 + math.sqrt(2)


def long_step(k: int) -> float:
    """The silver pattern (Altschuler and Parrilo) at step k = 0, 1, ...: 1 + rho^(nu - 1),
    rho = 1 + sqrt 2, nu the 2-adic valuation of k + 1 (1.41, 2, 1.41, 3.41, ..., 6.83 at
    k = 7): a start of the design's local search for a per-step value, in units of the
    spec's own value (OGM-like long steps sit in its basin; the constant own value does
    not: at N = 10 on L-smooth convex f the search from it ends 9 % above the best known
    schedule, from this start 0.3 %)."""
    return 1 + SILVER ** (((k + 1) & -(k + 1)).bit_length() - 2)


def _silver_block(n: int) -> tuple[list[float], float]:
    """Grimmer, Shu and Wang's straight block of n steps (their "s-composition": the
    two halves joined by the step that balances them) and its rate r, in units of 1/L."""
    if n == 0:
        return [], 1.0
    left, a = _silver_block(n // 2)
    right, b = _silver_block(n - 1 - n // 2)
    sa, sb = (1 - a) / a, (1 - b) / b
    mu = (-sa - sb + math.sqrt((4 + a * b * (2 + sa + sb) ** 2) / (a * b))) / 2
    return left + [mu] + right, 1 / (1 + sa + sb + mu)


def _join_rate(a: float, b: float) -> float:
    """The rate of a straight block of rate a followed by a final block of rate b."""
    return 2 * a * b / (a + 4 * b + math.sqrt(a * a + 8 * a * b))


def obs_f(steps: int) -> tuple[list[float], float]:
    """The optimized basic schedule OBS-F of Grimmer, Shu and Wang (2024) for the
    objective gap after ``steps`` gradient steps on L-smooth convex f, in units of 1/L,
    and its rate r: f(x_N) - f* <= r L |x_0 - x*|^2 / 2. A straight block
    (:func:`_silver_block`) of p steps, a joining step, then OBS-F of the remaining
    N - 1 - p steps; p chosen by their dynamic programme (the split of N - 1 grows by at
    most one with N). A start of the design's local search, which then certifies."""
    if steps == 0:
        return [], 1.0
    silver = [_silver_block(n)[1] for n in range(steps + 1)]
    split, rate = [0, 0], [1.0, 0.25]
    for n in range(2, steps + 1):
        cands = [(_join_rate(silver[q], rate[n - 1 - q] if n - 1 - q else 1.0), q)
                 for q in (split[n - 1], split[n - 1] + 1) if q <= n - 1]
        r, q = min(cands, key=lambda t: (t[0], -t[1]))
        split.append(q)
        rate.append(r)

    def build(n: int) -> tuple[list[float], float]:
        if n == 0:
            return [], 1.0
        left, a = _silver_block(split[n])
        right, b = build(n - 1 - split[n])
        mu = 1 + (math.sqrt(1 + 8 * b / a) - 1) / (4 * b)
        return left + [mu] + right, 1 / (1 / b + 2 * mu + 2 * (1 / a - 1))

    return build(steps)


def _step_index(layout: Layout) -> list[int]:
    return [k for _, n in layout for k in range(n or 1)]


def _per(layout: Layout) -> list[bool]:
    return [bool(n) for _, n in layout for _ in range(n or 1)]
