"""Analysis: the best rate a certificate family certifies for fixed parameters (eq. 16).

For fixed rho a family's inequalities are an LMI (Theorem 1: in (P, lambda)); a bracketed
search on rho in [0, 1] (Newton-type steps on a continuous feasibility margin, secant steps
without its slope, bisection with a custom solver chain) returns the smallest rho found
feasible, with its certificate. Only a step the solver reports *solved* and whose point
passes the eigenvalue check counts as feasible (see :mod:`sosalgo.kernel.solvers`), so a reported
rate always comes with a checked certificate.

A family with several members to choose from (the interpolation family without a given
lag: ``auto_lags``) is searched member by member (:func:`_choose_lag`); the result is the
best certified rate over the members tried, with that member's certificate.

The bracket is closed to ``tol`` and to ``REL_TOL`` (1 - rho), so that 1 - rho keeps three
significant digits however close to 1 the rate is (large kappa); where the solver's
default accuracy cannot tell the margin's sign at the needed resolution, the point is
solved again at a hundred times tighter tolerances.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sosalgo.certificates import FAMILIES, default_family_name, get_family
from sosalgo.certificates.base import CertificateFamily
from sosalgo.kernel import solvers as _solvers
from sosalgo.kernel.conic import LMIProblem
from sosalgo.kernel.solvers import (
    DEFAULT_SOLVERS,
    Feasibility,
    Margin,
    Outcome,
    check_point,
    solve_lmi,
    solve_margin,
)
from sosalgo.model import Algorithm, bind
from sosalgo.spec import Spec

__all__ = [
    "AnalysisResult", "SublinearResult", "analyze_algorithm", "analyze_spec",
    "analyze_sublinear", "DEFAULT_TOL", "quadratic_rate", "spec_family",
]

DEFAULT_TOL = 1e-6
REL_TOL = 1e-3  # the bracket is also closed to REL_TOL * (1 - rho)
FLOOR_TOL = 1e-13  # ... but not below this width (rates within ~1e-12 of 1 are not resolved)
LAG_PATIENCE = 2  # auto lag: stop after this many lags in a row that do not improve the rate
LAG_SECONDS = 60.0  # auto lag: no further lag is tried once the analysis took this long
Tolerance = Callable[[float], float]  # bracket width needed when its lower end is at rho
UNDECIDED_AT_ONE = ("not decided at rho = 1: the feasibility margin there is below the "
                    "solver's accuracy (kappa too large; see docs/commands/analyze.md, "
                    "'How large κ can be')")
UNRESOLVED = ("1 - rho not resolved: the rate is too close to 1 for the solver's accuracy "
              "(kappa too large; see docs/commands/analyze.md, 'How large κ can be')")


def _tolerance(tol: float) -> Tolerance:
    """The width a bracket [lo, hi] must reach: ``tol``, and at most ``REL_TOL`` (1 - lo)
    (not below ``FLOOR_TOL``), so that 1 - rho is resolved to three digits at any kappa."""
    return lambda lo: min(tol, max(REL_TOL * (1.0 - lo), FLOOR_TOL))


@dataclass(frozen=True)
class AnalysisResult:
    """Best certified rate and its certificate (P, lambda, or the family's parts) for one
    algorithm; ``lag`` is the interpolation family's lag of that certificate."""

    kappa: float
    rho: float | None  # None when not even rho = 1 is certified
    certified: bool
    P: np.ndarray | None
    lam: float | None
    max_eig_M: float | None
    min_eig_P: float | None
    solves: int
    seconds: float
    solver: str | None  # which solver produced the returned certificate
    rho_infeasible: float | None = None  # largest rho found infeasible (lower end of bracket)
    params: dict[str, float] = field(default_factory=dict)
    family: str = "theorem1"
    certificate: dict[str, Any] | None = None  # the family's named parts (unpack)
    warning: str | None = None  # a limit of the solver's accuracy met (large kappa)
    lag: int | None = None  # the certificate's lag (interpolation family), else None
    # witnessed lower bound on the worst-case rate, checked exactly (sosalgo.witnesses)
    rho_lower: float | None = None
    rho_lower_kind: str | None = None  # "quadratic", "self-similar" or "cycle"
    rho_lower_witness: dict[str, Any] | None = None
    cycle: dict[str, Any] | None = None  # a checked cycle: the method does not converge
    # the lags a choice of lag tried (:func:`_choose_lag`; () without a choice): the rate is
    # never slower than one certified at any of them
    lags_tried: tuple[int, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the `rows` entries of ``sosalgo analyze --json``)."""
        return {
            "rate_type": "linear",
            "kappa": self.kappa,
            "rho": self.rho,
            "certified": self.certified,
            "P": None if self.P is None else self.P.tolist(),
            "lambda": self.lam,
            "max_eig_M": self.max_eig_M,
            "min_eig_P": self.min_eig_P,
            "solves": self.solves,
            "seconds": self.seconds,
            "solver": self.solver,
            "rho_infeasible": self.rho_infeasible,
            "params": dict(self.params),
            "family": self.family,
        } | ({} if _is_default(self.family) else {"certificate": jsonable(self.certificate)}) | (
            {} if self.warning is None else {"warning": self.warning}) | (
            {} if self.lag is None else {"lag": self.lag}) | {
            "rho_lower": self.rho_lower, "rho_lower_kind": self.rho_lower_kind,
            "rho_lower_witness": self.rho_lower_witness, "cycle": self.cycle}


def _is_default(family: str) -> bool:
    """Rows of the default family (Theorem 1) carry P and lambda only, no ``certificate``."""
    fam = FAMILIES.get(family)
    return fam is not None and fam.is_default


def jsonable(v: Any) -> Any:
    """Certificate parts as JSON values (arrays become nested lists)."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, dict):
        return {k: jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [jsonable(x) for x in v]
    return v


class _Search:
    """Counts solves and classifies one rho: certified (with a checked point) or not."""

    def __init__(self, problem: LMIProblem, solvers: Sequence[str], use_margin: bool,
                 tol: Tolerance):
        self.problem, self.solvers, self.use_margin = problem, solvers, use_margin
        self.tol = tol
        self.solves = 0
        self.slope: float | None = None  # dt/drho of the last margin solve
        self.undecided = False  # the last margin's sign was within the solver's accuracy
        # rho -> how far the margin's root may be from where t and the slope put it (the
        # duality gap over the slope, or above an uncertified rho with t > 0)
        self.spread: dict[float, float] = {}
        # below this rho (a tolerance above a tight family's lower bound) the certificate
        # degenerates: refined solves, equilibrated first (set by _start_near)
        self.degenerate_below = -math.inf

    def plain(self, rho: float) -> Outcome:
        self.solves += 1
        return solve_lmi(self.problem, rho, self.solvers)

    @staticmethod
    def tiny(rho: float) -> bool:
        """Whether t(rho) may be below the solver's tolerance, so that its duality gap does
        not show all of its error: at rho = 1 and near it (1 - rho < REL_TOL)."""
        return rho >= 1.0 - REL_TOL

    def margin(self, rho: float, rough: bool = True) -> Margin:
        """t(rho), solved again precisely when its sign is within the default accuracy and
        that uncertainty would move the root by more than a quarter tolerance; ``rough``:
        without iterative refinement (:func:`sosalgo.kernel.solvers.solve_margin`), except where
        the certificate degenerates (below ``degenerate_below``: :meth:`degenerate`)."""
        self.solves += 1
        if rho < self.degenerate_below:
            mg = self.degenerate(rho)
        else:
            mg = solve_margin(self.problem, rho, rough=rough)
        floor = self.tiny(rho)
        if mg.undecided(floor):
            d = mg.slope
            if d is None or not d > 0 or mg.noise(floor) / d > 0.25 * self.tol(rho):
                return self.precise(rho, mg)
        self.undecided = mg.undecided(floor)
        return mg

    def degenerate(self, rho: float) -> Margin:
        """t(rho) where the certificate degenerates: the equilibrated solve first, kept
        when its point passes the check or its t is negative beyond its accuracy, else the
        unequilibrated one (and the equilibrated one only when that fails), as
        :func:`solve_margin` orders them."""
        first = solve_margin(self.problem, rho, equilibrate=True)
        if self.checked(rho, first) is not None or (
                first.ok and first.t is not None and first.t + first.noise() < 0):
            return first  # certified, or clearly not (t < 0 beyond its accuracy)
        plain = solve_margin(self.problem, rho, equilibrate=False)
        return plain if plain.ok else first

    def precise(self, rho: float, mg: Margin) -> Margin:
        """t(rho) at the solver's tighter tolerances (``mg`` if that fails)."""
        self.solves += 1
        again = _solvers.solve_margin(self.problem, rho, precise=True)
        mg = again if again.ok else mg
        self.undecided = mg.undecided(self.tiny(rho))
        return mg

    def checked(self, rho: float, mg: Margin) -> Outcome | None:
        """The checked certificate of a margin t > 0 (None when there is none)."""
        if mg.ok and mg.t is not None and mg.t > 0 and mg.x is not None:
            out = check_point(self.problem, rho, mg.x, "clarabel-margin")
            return out if out.feasible else None
        return None

    def test(self, rho: float, ask_plain: bool = True) -> tuple[Outcome, float | None]:
        """(outcome, margin t); the margin is None when not computed or not trusted. A
        positive margin whose point fails the check is asked plainly only with
        ``ask_plain`` (else it is not certified: the caller tries elsewhere). The first
        solve is rough (see :meth:`margin`); with ``ask_plain``, a rough answer that
        certifies nothing although t > 0 (or a failed one) is solved again with
        refinement."""
        if not self.use_margin:
            return self.plain(rho), None
        mg = self.margin(rho)
        out = self.checked(rho, mg)
        if out is None and ask_plain and rho >= self.degenerate_below and not mg.precise and (
                not mg.ok or (mg.t is not None and mg.t > 0)):
            mg = self.margin(rho, rough=False)
            out = self.checked(rho, mg)
        if out is None and mg.t is not None and mg.t > 0 and not mg.precise and (
                self.tiny(rho) or _spread(mg, False) > 0.25 * self.tol(rho)):
            mg = self.precise(rho, mg)  # a rescaled point too close to call: solve precisely
            out = self.checked(rho, mg)
        self.slope = mg.slope if mg.ok else None
        if not mg.ok or mg.t is None:
            return self.plain(rho), None
        if out is None and mg.t > 0 and ask_plain:
            out = self.plain(rho)  # still too close to call: ask plainly
        elif out is None and mg.t > 0:
            out = Outcome(Feasibility.FAILED, None, "clarabel-margin", "point not checkable")
        elif out is None:
            out = Outcome(Feasibility.INFEASIBLE, None, "clarabel-margin", f"margin {mg.t:.3g}")
        self.spread[rho] = _spread(mg, out.feasible)
        return out, mg.t


def _spread(mg: Margin, certified: bool) -> float:
    """How far the margin's root may be from where t and its slope put it: the duality gap
    over the slope at a certified rho; at an uncertified one, how far below rho the root
    may be (t > 0 that could not be checked, or a gap that reaches above 0)."""
    d = mg.slope
    if d is None or not d > 0:
        return math.inf if certified else 0.0
    gap = 0.0 if mg.t_upper is None else max(mg.t_upper - mg.t, 0.0)
    return gap / d if certified else max(mg.t if mg.t > 0 else mg.t + gap, 0.0) / d


def _bisect(search: _Search, lo: float, hi: float, best: Outcome, tol: Tolerance):
    while hi - lo > tol(lo):
        mid = 0.5 * (lo + hi)
        out, _ = search.test(mid)
        if out.feasible:
            hi, best = mid, out
        else:
            lo = mid
    return lo, hi, best


def _line_root(p: tuple[float, float], q: tuple[float, float]) -> float | None:
    """Root of the line through two (rho, t) points, if the line is not flat."""
    (x0, t0), (x1, t1) = p, q
    if t1 == t0 or x1 == x0:
        return None
    return x1 - t1 * (x1 - x0) / (t1 - t0)


def _estimate(lo: float, hi: float, upper: list, lower: list) -> float:
    """Root estimate: a secant on the side whose latest margin is smallest, else regula
    falsi across the bracket, else the midpoint."""
    sides = [pts for pts in (upper, lower) if len(pts) >= 2]
    sides.sort(key=lambda pts: abs(pts[-1][1]))
    for pts in sides:
        est = _line_root(pts[-2], pts[-1])
        if est is not None and lo < est < hi:
            return est
    if upper and lower:
        est = _line_root(lower[-1], upper[-1])
        if est is not None and lo < est < hi:
            return est
    return 0.5 * (lo + hi)


def _secant(search: _Search, t_one: float, best: Outcome, tol: Tolerance):
    """Bracketed root-finding on the margin t(rho).

    Near the threshold t is close to piecewise linear with a kink at the root, so the
    estimate comes from a secant through the last two points on one side (certified side
    first), else regula falsi on the bracket, with a bisection step whenever the bracket
    fails to halve. Each estimate is tested a quarter tolerance above and then below, which
    closes the bracket in two solves once the estimate is good. Invariant: hi is certified
    by a checked point, lo is not certified.
    """
    lo, hi = 0.0, 1.0
    upper: list[tuple[float, float]] = [(1.0, t_one)]
    lower: list[tuple[float, float]] = []

    def record(x: float, out: Outcome, t: float | None) -> None:
        nonlocal lo, hi, best
        if out.feasible:
            hi, best = x, out
            if t is not None and t > 0:
                upper.append((x, t))
        else:
            lo = x
            if t is not None and t < 0:
                lower.append((x, t))

    out, t = search.test(0.5)
    record(0.5, out, t)
    if out.feasible:
        out0, t0 = search.test(0.0)
        if out0.feasible:
            return 0.0, 0.0, out0
        record(0.0, out0, t0)
    while hi - lo > (tl := tol(lo)):
        width = hi - lo
        est = _estimate(lo, hi, upper, lower)
        x = min(max(est + 0.25 * tl, lo + 0.25 * tl), hi - 0.25 * tl)
        out, t = search.test(x)
        record(x, out, t)
        if out.feasible and hi - lo > tl and len(upper) >= 2:
            again = _line_root(upper[-2], upper[-1])
            if again is not None and abs(again - est) < 0.25 * tl and lo < est - 0.25 * tl:
                below = est - 0.25 * tl  # the estimate is confirmed: close from below
                out, t = search.test(below)
                record(below, out, t)
                continue
        if hi - lo > 0.5 * width and hi - lo > tol(lo):
            mid = 0.5 * (lo + hi)  # poor progress: one bisection step
            out, t = search.test(mid)
            record(mid, out, t)
    return lo, hi, best


def _newton(search: _Search, ups: list, down: tuple | None, lo: float, hi: float,
            best: Outcome, tol: Tolerance, skip_stale: bool = False,
            pause: _Pending | None = None):
    """Bracketed Newton-type iteration on the margin t(rho), slopes from the dual solution.

    Above the threshold t is smooth and convex-like; the estimate from the certified side is
    the root of the quadratic through the last two certified points (value and slope at the
    last), else a Newton step. From the other side a Newton step is used, and with both the
    larger estimate (both tend to fall short), unless the step from the certified side is
    short (< 20 tol), which is then accurate. A step is tested a quarter tolerance above
    its estimate; once the next step from a certified point is shorter than half a
    tolerance, one test just below closes the bracket. Estimates outside the bracket fall
    back to bisection. With ``skip_stale`` (the search started near a tight family's rate),
    a step from below that lands within half a tolerance of hi (the point already tested)
    is dropped. With ``pause``, the search stops instead of that test just below, its state
    kept in ``pause`` (:func:`_choose_lag` tests a larger lag there, which also decides this
    one). Invariant: hi is certified by a checked point, lo is not certified.
    """
    def inside(est: float | None) -> float | None:
        return float(est) if est is not None and np.isfinite(est) and lo < est < hi else None

    def newton(pt) -> float | None:
        x, t, d = pt
        return None if d is None or not d > 0 else inside(x - t / d)

    def from_above() -> float | None:
        est = newton(ups[-1])
        if len(ups) < 2 or est is None:
            return est
        (x1, t1, _), (x2, t2, d2) = ups[-2], ups[-1]
        a = (t1 - t2 - d2 * (x1 - x2)) / (x1 - x2) ** 2  # t ~ t2 + d2 s + a s^2, s = x - x2
        disc = d2 * d2 - 4 * a * t2
        if a <= 0 or disc < 0:
            return est
        return inside(x2 + (-d2 + np.sqrt(disc)) / (2 * a)) or est

    confirmed_at = None
    for step in range(200):
        tl = tol(lo)
        if hi - lo <= tl:
            break
        nxt = newton(ups[-1]) if ups and ups[-1][0] == hi else None
        if nxt is not None and hi - nxt < 0.5 * tl and confirmed_at != hi:
            if pause is not None:
                pause.keep(ups, down, lo, hi, best)
                return lo, hi, best
            confirmed_at = hi  # the estimate is confirmed: close from below, once per hi
            below = max(hi - 0.999 * tl, lo + 0.5 * tl)
            out, t = search.test(below)
            if out.feasible:
                hi, best = below, out
                if t is not None and t > 0:
                    ups.append((below, t, search.slope))
            else:
                lo = below
                down = (below, t, search.slope) if t is not None and t < 0 else down
            continue
        est_u, est_l = from_above(), newton(down) if down else None
        if skip_stale and est_l is not None and est_l > hi - 0.5 * tl:
            est_l = None  # already tested (it gave hi): a step there barely narrows the bracket
        ests = [e for e in (est_u, est_l) if e is not None]
        if est_u is not None and hi - est_u < 20 * tl:
            est = est_u  # a short step from a certified point is accurate
        else:
            est = max(ests) if ests and step < 60 else 0.5 * (lo + hi)
        x = min(max(est + 0.25 * tl, lo + 0.25 * tl), hi - 0.25 * tl)
        out, t = search.test(x)
        if not out.feasible:
            lo = x
            down = (x, t, search.slope) if t is not None and t < 0 else down
            continue
        hi, best = x, out
        if t is not None and t > 0:
            ups.append((x, t, search.slope))
    return lo, hi, best


def analyze_algorithm(
    alg: Algorithm,
    tol: float = DEFAULT_TOL,
    family: CertificateFamily | str = "theorem1",
    solvers: Sequence[str] = DEFAULT_SOLVERS,
    method: str = "secant",
) -> AnalysisResult:
    """Smallest certified rho in [0, 1] to width ``tol`` and ``REL_TOL`` (1 - rho) (eq. 16).

    ``method="secant"`` (default) root-finds on the continuous margin of
    :func:`sosalgo.kernel.solvers.solve_margin` (Newton-type steps with its slope from the dual
    solution, secant steps without); ``"bisection"`` (also used whenever ``solvers`` is not
    the default chain) bisects on plain feasibility.
    Both keep a bracket [lo, hi] with hi certified by a checked certificate. ``warning``
    says when the solver's accuracy decided the outcome (a rate too close to 1). A family
    whose ``auto_lags`` names several lags (the interpolation family without a given lag)
    gets the best rate over the lags tried (:func:`_choose_lag`).
    """
    if not tol > 0:
        raise ValueError("tol must be positive")
    if method not in ("secant", "bisection"):
        raise ValueError("method must be 'secant' or 'bisection'")
    fam = get_family(family) if isinstance(family, str) else family
    lags = fam.auto_lags(alg.n)
    if len(lags) > 1:
        return _choose_lag(alg, tol, fam, solvers, method, lags)
    return _analyze_one(alg, tol, fam, solvers, method)


def _analyze_one(alg: Algorithm, tol: float, fam: CertificateFamily,
                 solvers: Sequence[str], method: str,
                 quad: float | None = None, pause: _Pending | None = None) -> AnalysisResult:
    """:func:`analyze_algorithm` for one member of a family (its problem as it is);
    ``quad``: the method's rate on quadratics when already computed; ``pause``: leave the
    last test below the rate to a larger lag (:func:`_newton`), the state kept there."""
    start = time.perf_counter()
    problem = fam.problem(alg)
    # The margin problem is solved by Clarabel; a custom solver chain means plain bisection.
    use_margin = method == "secant" and tuple(solvers) == DEFAULT_SOLVERS
    # a family may name a shorter fallback chain for points the margin path cannot check
    fallback = fam.fallback_solvers if use_margin else None
    width = _tolerance(tol)
    search = _Search(problem, fallback or solvers, use_margin, width)
    if pause is not None:
        pause.search, pause.problem, pause.fam, pause.start = search, problem, fam, start
    if use_margin and fam.tight and quad is None:
        quad = quadratic_rate(alg, 201)
    quad = quad if use_margin and fam.tight else None
    lo0, down0 = 0.0, None
    if quad is not None and quad < 1 - width(quad):
        proxy = fam.guess_problem(alg)
        lo, hi, best_near, ups, down0 = _start_near(search, quad, width(quad), proxy,
                                                    defer=pause is not None)
        if best_near is not None:
            lo, hi, best = _newton(search, ups, down0, lo, hi, best_near, width,
                                   skip_stale=True, pause=pause)
            return _paused(pause, _result(alg, fam, problem, search, lo, hi, best, start))
        lo0 = lo
    best, t_one = search.test(1.0)
    slope_one = search.slope
    if not best.feasible:
        return AnalysisResult(
            kappa=alg.kappa, rho=None, certified=False, P=None, lam=None, max_eig_M=None,
            min_eig_P=None, solves=search.solves, seconds=time.perf_counter() - start,
            solver=None, rho_infeasible=1.0, params=dict(alg.params), family=fam.name,
            # the margin's sign within the solver's accuracy, or a positive margin whose
            # point is too close to 0 to check: the solver cannot decide this kappa
            warning=UNDECIDED_AT_ONE if search.undecided or (t_one or 0) > 0 else None,
            lag=fam.options().get("lag"),
        )
    if method == "secant" and t_one is not None and slope_one is not None:
        lo, hi, best = _newton(search, [(1.0, t_one, slope_one)], down0, lo0, 1.0, best, width,
                               pause=pause)
    elif method == "secant" and t_one is not None:
        lo, hi, best = _secant(search, t_one, best, width)
    else:
        lo, hi, best = _bisect(search, 0.0, 1.0, best, width)
    return _paused(pause, _result(alg, fam, problem, search, lo, hi, best, start))


def _choose_lag(alg: Algorithm, tol: float, fam: CertificateFamily, solvers: Sequence[str],
                method: str, lags: Sequence[int]) -> AnalysisResult:
    """The best certified rate over the lags tried, in the order of ``lags``: the first is
    searched in full; each further lag only has to beat the best rate so far by the
    tolerance (:func:`_improve`: one test there, a search below it when it does).
    Lags are raised until ``LAG_PATIENCE`` in a row do not improve, the last of ``lags``
    or ``LAG_SECONDS``, or (families that say so: several oracle calls) once a lag certifies
    a rate; then the family's ``fallback_lags`` (lag 0) are tried the same way, each
    only kept where it beats the best by the tolerance, so the rate returned is never
    slower than one certified at any lag tried (``lags_tried``), up to the tolerance.
    When the best lag's windows were reduced (:func:`_reduced`), lag 0 is searched in full
    and kept when its rate is within two tolerances of the best.
    The largest lag of those next ``LAG_PATIENCE`` is tested first: a
    certificate of lag l is one of lag l + 1, so when it does not beat the best rate none
    of the smaller ones does and the choice stops after that one test. Larger lags never
    certify less in exact arithmetic, but their solves are less accurate on degenerate
    (tight) certificates, so the best is kept, never the last. For the same reason the
    best's search pauses before its last test below its rate (:func:`_newton`): a larger
    lag found infeasible at that point (the next test of the choice) closes its bracket
    (:func:`_close`), else the test is made at the end (:func:`_resume`). The result
    carries that lag's certificate and bracket (``lag`` None when no lag certifies a
    rate), and the solves and seconds of the whole choice."""
    start = time.perf_counter()
    members = [fam.with_options(lag=lag) for lag in lags]  # type: ignore[call-arg]
    # no valid certificate goes below the rate on quadratics (a grid max, not above it)
    floor = quadratic_rate(alg, 201)
    pend = _Pending()  # best's search, paused before its last test below (see _close)
    best = _analyze_one(alg, tol, members[0], solvers, method, floor, pend)
    solves, misses, i = best.solves, 0, 1
    tried = [lags[0]]
    ahead: dict[int, _Probe] = {}  # a window's top, tested against the current best
    while i < len(members) and misses < LAG_PATIENCE:
        if time.perf_counter() - start > LAG_SECONDS or (
                best.certified and not fam.searches_past_certified(alg)):
            break
        top = min(i + LAG_PATIENCE - misses, len(members)) - 1
        if top > i and top not in ahead:
            probe = _probe(alg, tol, members[top], solvers, method, best, floor)
            solves += 0 if probe is None else probe.search.solves
            tried.append(lags[top])
            best = _close(best, pend, probe)
            if probe is None or not probe.out.feasible:
                break  # the largest lag of the window does not beat best: none does
            ahead = {top: probe}
        probe = ahead.pop(i, None)
        if probe is None:
            probe = _probe(alg, tol, members[i], solvers, method, best, floor)
            solves += 0 if probe is None else probe.search.solves
            best = _close(best, pend, probe)
        tried.append(lags[i])
        nxt = _Pending()
        res, spent = _improve(alg, tol, members[i], solvers, method, best, floor, probe,
                              nxt if i + 1 < len(members) else None)
        solves += spent
        if res is None:
            misses += 1
        else:
            best, misses, ahead, pend = res, 0, {}, nxt
        i += 1
    if pend.result is not None and pend.result is best:  # no larger lag closed it
        best, spent = _resume(alg, pend, tol)
        solves += spent
    for lag in getattr(fam, "fallback_lags", lambda n: ())(alg.n):
        res, spent = _fallback(alg, tol, fam.with_options(lag=lag),  # type: ignore[call-arg]
                               solvers, method, best, floor)
        solves += spent
        tried.append(lag)
        best = best if res is None else res
    if best.certified and best.lag and _reduced(fam, alg, best.lag):
        res = _analyze_one(alg, tol, fam.with_options(lag=0),  # type: ignore[call-arg]
                           solvers, method, floor)
        solves += res.solves
        tried.append(0)
        width = _tolerance(tol)(best.rho)
        best = res if res.certified and res.rho <= best.rho + 2 * width else best
    return dataclasses.replace(best, solves=solves, seconds=time.perf_counter() - start,
                               lag=best.lag if best.certified else None,
                               lags_tried=tuple(sorted(set(tried))))


def _reduced(fam: CertificateFamily, alg: Algorithm, lag: int) -> bool:
    """Whether lag ``lag``'s windows have directions where every certificate's matrices
    vanish (removed before solving): its certificates then have exact zero eigenvalues,
    which ``verify`` cannot prove along an irrational direction (a method with irrational
    entries), so the choice prefers lag 0 (which has none) whenever lag 0's rate is within
    two tolerances of it (:func:`_choose_lag`)."""
    has = getattr(fam, "has_null_directions", None)
    return bool(has is not None and has(alg, lag))


def _fallback(alg: Algorithm, tol: float, fam: CertificateFamily, solvers: Sequence[str],
              method: str, best: AnalysisResult,
              floor: float) -> tuple[AnalysisResult | None, int]:
    """(result of ``fam``, solves) when it beats ``best`` (:func:`_improve`); a full
    search (:func:`_analyze_one`, from the rate on quadratics) when ``best`` certifies
    nothing."""
    if best.rho is not None:
        return _improve(alg, tol, fam, solvers, method, best, floor)
    res = _analyze_one(alg, tol, fam, solvers, method, floor)
    return (res if res.certified else None), res.solves


@dataclass
class _Probe:
    """One test of a member of a family just below the best rate so far."""

    search: _Search
    problem: LMIProblem
    x: float
    out: Outcome
    t: float | None
    start: float


@dataclass
class _Pending:
    """A search paused before its last test below the rate (:func:`_newton`): its state,
    and the result it gave so far (bracket not closed)."""

    search: Any = None
    problem: Any = None
    fam: Any = None
    start: float = 0.0
    state: tuple | None = None  # (ups, down, lo, hi, best outcome) where it paused
    result: AnalysisResult | None = None

    def keep(self, ups: list, down: tuple | None, lo: float, hi: float, best: Outcome) -> None:
        self.state = (ups, down, lo, hi, best)


def _paused(pause: _Pending | None, res: AnalysisResult) -> AnalysisResult:
    """``res``, remembered in ``pause`` when its search paused with a certified rate."""
    if pause is not None:
        pause.result = res if pause.state is not None and res.certified else None
    return res


def _close(best: AnalysisResult, pend: _Pending, probe: _Probe | None) -> AnalysisResult:
    """``best`` with its bracket closed by ``probe``, a larger lag found infeasible at
    best.rho less the tolerance: a certificate of a smaller lag is one of the larger lag
    (module docstring of :mod:`sosalgo.certificates.interpolation`), so ``best``'s own
    member is infeasible there too. Unchanged unless ``best`` is ``pend``'s paused result
    and the probe's verdict is a solver's infeasible (not a failure)."""
    if (pend.result is not best or probe is None or best.rho is None
            or probe.out.status != Feasibility.INFEASIBLE or best.rho_infeasible is None
            or not best.rho_infeasible < probe.x):
        return best
    spread = max(pend.search.spread.get(best.rho, 0.0), probe.search.spread.get(probe.x, 0.0))
    unresolved = max(best.rho - probe.x, spread) > 2 * REL_TOL * (1 - best.rho)
    pend.result = None
    return dataclasses.replace(best, rho_infeasible=probe.x,
                               warning=UNRESOLVED if unresolved else None)


def _resume(alg: Algorithm, pend: _Pending, tol: float) -> tuple[AnalysisResult, int]:
    """(pend's result with its search finished, the solves that took) when it is still
    paused: the test below the rate that no larger lag made."""
    assert pend.result is not None and pend.state is not None
    ups, down, lo, hi, out = pend.state
    before = pend.search.solves
    lo, hi, out = _newton(pend.search, ups, down, lo, hi, out, _tolerance(tol))
    res = _result(alg, pend.fam, pend.problem, pend.search, lo, hi, out, pend.start)
    pend.result = None
    return res, pend.search.solves - before


def _probe(alg: Algorithm, tol: float, fam: CertificateFamily, solvers: Sequence[str],
           method: str, best: AnalysisResult, floor: float = 0.0) -> _Probe | None:
    """``fam`` tested at the best rate less the tolerance (at 1 when ``best`` has none);
    None when that point is at or below ``floor``, a lower bound of every rate."""
    width = _tolerance(tol)
    x = 1.0 if best.rho is None else best.rho - width(best.rho)
    if x <= floor:
        return None
    start = time.perf_counter()
    problem = fam.problem(alg)
    use_margin = method == "secant" and tuple(solvers) == DEFAULT_SOLVERS
    fallback = fam.fallback_solvers if use_margin else None
    search = _Search(problem, fallback or solvers, use_margin, width)
    out, t = search.test(x)
    return _Probe(search, problem, x, out, t, start)


def _improve(alg: Algorithm, tol: float, fam: CertificateFamily, solvers: Sequence[str],
             method: str, best: AnalysisResult, floor: float = 0.0,
             probe: _Probe | None = None,
             pause: _Pending | None = None) -> tuple[AnalysisResult | None, int]:
    """(result of ``fam``, solves) when ``fam`` certifies a rate below ``best.rho`` by at
    least the tolerance there (any rate <= 1 when ``best`` has none), else (None, solves):
    one test at that point (:func:`_probe`, or ``probe`` when already made, whose solves
    are then not counted again), and a search below it only when it is certified
    (paused before its last test with ``pause``, see :func:`_newton`)."""
    spent = 0
    if probe is None:
        probe = _probe(alg, tol, fam, solvers, method, best, floor)
        spent = 0 if probe is None else probe.search.solves
    if probe is None or not probe.out.feasible:
        return None, spent
    search, x, out, t, width = probe.search, probe.x, probe.out, probe.t, _tolerance(tol)
    before = search.solves
    if pause is not None:
        pause.search, pause.problem, pause.fam, pause.start = (search, probe.problem, fam,
                                                               probe.start)
    if t is not None and t > 0 and search.slope is not None:
        lo, hi, out = _newton(search, [(x, t, search.slope)], None, 0.0, x, out, width,
                              pause=pause)
    else:
        lo, hi, out = _bisect(search, 0.0, x, out, width)
    res = _paused(pause, _result(alg, fam, probe.problem, search, lo, hi, out, probe.start))
    better = res.certified and res.rho is not None and (best.rho is None or res.rho < best.rho)
    return (res if better else None), spent + search.solves - before


def _start_near(search: _Search, guess: float, tol: float, proxy: LMIProblem | None = None,
                defer: bool = False):
    """For families expected to be tight: test just above ``guess`` (the method's rate on
    quadratics, where gradient descent and triple momentum are certified) and close the
    bracket below it, or climb with Newton steps from below until a certified point. With
    a ``proxy`` (a cheaper problem of the family, usually with the same rate), the first
    climb goes to the proxy's root (:func:`_proxy_root`), so that only its end is tested
    on the problem itself.

    ``guess`` is a lower bound of every rate: a certificate within ``tol`` above it closes
    the bracket at once (lo = guess). A positive margin at the first point that cannot be
    checked (a degenerate certificate: the rate is the bound) goes on to ``guess`` + 0.99
    ``tol`` without asking the slower solvers there. With ``defer``, a certified first point
    is not closed from below here (the caller's search pauses there instead).

    Returns (lo, hi, best, certified points, last uncertified point); ``best`` is None when
    no certified point turned up (lo and the last point below then seed the usual search).
    """
    x = first = min(guess + 0.25 * tol, 1.0)
    lo, down = 0.0, None
    search.degenerate_below = guess + tol
    est = _proxy_root(search, proxy, x, tol) if proxy is not None else None
    if est is not None and est > x:  # the proxy climbed: start at its root
        if est >= 1.0:
            return lo, 1.0, None, [], down
        x = min(est + 0.25 * tol, 1.0)
    for _ in range(8):
        out, t = search.test(x, ask_plain=x != first)
        if out.feasible:
            if t is None or not t > 0:
                return lo, 1.0, None, [], down
            ups = [(x, t, search.slope)]
            if x - guess < tol:  # within tol of a lower bound: the bracket is closed
                return max(lo, guess), x, out, ups, down
            if lo == 0.0 and x - tol > 0 and not defer:  # certified at the first guess:
                # close below it
                below = x - 0.999 * tol
                out2, t2 = search.test(below)
                if out2.feasible and t2 is not None and t2 > 0 and est is not None:
                    # the proxy's root is above the rate: go on down from there
                    return 0.0, below, out2, ups + [(below, t2, search.slope)], None
                if out2.feasible:
                    return 0.0, 1.0, None, [], None  # not a bound here: search anew
                lo = below
                down = (below, t2, search.slope) if t2 is not None and t2 < 0 else None
            return lo, x, out, ups, down
        lo = x
        if t is not None and t >= 0 and x + tol < 1:  # margin >= 0 but not checkable: the
            # certificate degenerates here (a tight rate); try just under a tol above the bound
            x = guess + 0.99 * tol if x == first else x + tol
            continue
        if t is None or not t < 0 or search.slope is None or not search.slope > 0:
            break
        prev, down = down, (x, t, search.slope)
        est = _climb_estimate(prev, down)
        if not x < est < 1:
            break
        x = min(est + 0.25 * tol, 1.0)
    return lo, 1.0, None, [], down


def _proxy_root(search: _Search, proxy: LMIProblem, x: float, tol: float,
                limit: int = 8) -> float | None:
    """Estimate of the root of the margin t(rho) of ``proxy`` (a cheaper problem with the
    same rate), from ``x`` = the rate on quadratics (a lower bound) up: Newton-type steps
    (:func:`_climb_estimate` from below, Newton from above) kept inside the bracket, until
    a step is shorter than 10 ``tol`` (at most sqrt(tol) / 100): the steps converge
    superlinearly, so the estimate after such a step is much closer than the step. Only a
    guess: nothing is certified here.
    Returns ``x`` when the proxy is already feasible there, None when a solve fails, an
    estimate >= 1 when the proxy's root seems to be there (no rate below 1)."""
    start, lo, hi, prev, est = x, 0.0, 1.0, None, None
    stop = max(0.25 * tol, min(10 * tol, 0.01 * math.sqrt(tol)))
    for _ in range(limit):
        search.solves += 1
        mg = solve_margin(proxy, x, rough=True)
        if not mg.ok or mg.t is None or mg.slope is None or not mg.slope > 0:
            return est
        if mg.t >= 0:
            if est is None:
                return x  # feasible where the search starts
            hi, est = x, x - mg.t / mg.slope
        else:
            cur = (x, mg.t, mg.slope)
            lo, est, prev = x, _climb_estimate(prev, cur), cur
            if est >= 1.0 and hi == 1.0:  # the step leaves [0, 1]: is there a root at all?
                search.solves += 1
                top = solve_margin(proxy, 1.0, rough=True)
                if not top.ok or top.t is None or top.t < 0 or not (top.slope or 0) > 0:
                    return est
                hi, est = 1.0, 1.0 - top.t / top.slope
            if x == start and est - x < tol:
                return x  # on the boundary where the search starts (a tight rate there)
        if not lo < est < hi:
            est = 0.5 * (lo + hi)
        if abs(est - x) < stop:
            return est
        x = est
    return est


def _climb_estimate(prev: tuple | None, cur: tuple) -> float:
    """Root estimate from below: the root of the quadratic through the previous uncertified
    point (value) and the current one (value and slope) when it bends down (below the
    threshold t is concave, so a Newton step falls short), else a Newton step."""
    x2, t2, d2 = cur
    est = x2 - t2 / d2
    if prev is None or prev[0] >= x2:
        return est
    x1, t1, _ = prev
    a = (t1 - t2 - d2 * (x1 - x2)) / (x1 - x2) ** 2  # t ~ t2 + d2 s + a s^2, s = x - x2
    disc = d2 * d2 - 4 * a * t2
    if not (a < 0 and disc > 0):
        return est
    return x2 - 2 * t2 / (d2 + float(np.sqrt(disc)))


def _result(alg: Algorithm, fam: CertificateFamily, problem: LMIProblem, search: _Search,
            lo: float, hi: float, best: Outcome, start: float) -> AnalysisResult:
    solves = search.solves
    # the bracket closes to REL_TOL (1 - lo) (> REL_TOL (1 - hi)) unless the floor stopped
    # it; and the margins at its ends must place the root that well
    spread = max(search.spread.get(hi, 0.0), search.spread.get(lo, 0.0))
    unresolved = max(hi - lo, spread) > 2 * REL_TOL * (1 - hi)
    warning = UNRESOLVED if unresolved else None
    assert best.x is not None
    cert = problem.unpack(best.x)
    P = np.asarray(cert["P"])
    eigs = _final_check(fam, alg, hi, cert, P)
    if eigs is None:  # NaN/overflow in M or P: a check that cannot be evaluated never passes
        return AnalysisResult(
            kappa=alg.kappa, rho=None, certified=False, P=None, lam=None, max_eig_M=None,
            min_eig_P=None, solves=solves, seconds=time.perf_counter() - start,
            solver=best.solver, rho_infeasible=lo, params=dict(alg.params), family=fam.name,
            lag=fam.options().get("lag"),
        )
    lam = cert.get("lambda")
    return AnalysisResult(
        kappa=alg.kappa, rho=hi, certified=True, P=P,
        lam=None if lam is None else float(lam), max_eig_M=eigs[0], min_eig_P=eigs[1],
        solves=solves, seconds=time.perf_counter() - start, solver=best.solver,
        rho_infeasible=lo, params=dict(alg.params), family=fam.name, certificate=cert,
        warning=warning, lag=cert.get("lag"),
    )


def _final_check(fam: CertificateFamily, alg: Algorithm, rho: float, cert: dict[str, Any],
                 P: np.ndarray) -> tuple[float, float] | None:
    """(max eig of the main inequality, min eig of P) in floats (the family's ``summary``),
    or None when not finite."""
    try:
        with np.errstate(all="ignore"):
            eigs = fam.summary(alg, rho, cert)
            top, low = float(eigs["max_eig_M"]), float(eigs["min_eig_P"])
    except (np.linalg.LinAlgError, ValueError, OverflowError, TypeError):
        return None
    lam = cert.get("lambda", 0.0)
    if not (np.isfinite(top) and np.isfinite(low) and np.all(np.isfinite(P))
            and (lam is None or np.isfinite(lam))):
        return None
    return top, low


def analyze_spec(
    spec: Spec,
    kappa: float,
    theta: Mapping[str, float] | None = None,
    tol: float = DEFAULT_TOL,
    solvers: Sequence[str] = DEFAULT_SOLVERS,
    family: CertificateFamily | str | None = None,
) -> AnalysisResult:
    """Analysis of a spec at one kappa (parameters at their values unless set by theta).

    ``family`` overrides the spec's certificate family (default: the spec's, with its
    options)."""
    fam = spec_family(spec) if family is None else family
    return analyze_algorithm(bind(spec, kappa, theta), tol, fam, solvers)


def spec_family(spec: Spec, command: str | None = None) -> CertificateFamily:
    """The certificate family ``command`` uses for a spec by default
    (:func:`sosalgo.certificates.default_family_name`; None: the family the spec declares),
    with the spec's options when it is the spec's own, sized for the spec's oracle calls
    when it has several."""
    name = default_family_name(spec, command)
    options = spec.certificate_options if name == spec.certificate else {}
    return for_spec(get_family(name, options), spec)


def for_spec(fam: CertificateFamily, spec: Spec) -> CertificateFamily:
    """``fam`` sized for ``spec``'s oracle calls (families that have ``for_inputs``)."""
    sized = getattr(fam, "for_inputs", None)
    return sized(spec.p) if sized is not None and spec.p != 1 else fam


def quadratic_rate(alg: Algorithm, points: int = 2001) -> float:
    """max over q in [m, L] of the spectral radius of A + q B C (grid): the method's rate on
    quadratics, a lower bound for any certificate family (drawn on comparison plots). For
    a method of the oracle model: every function a quadratic of its class
    (:func:`sosalgo.oracles.composite_quadratic_rate`)."""
    if not alg.has_seed_form:
        from sosalgo.oracles import composite_quadratic_rate

        return composite_quadratic_rate(alg, min(points, 201))  # type: ignore[arg-type]
    qs = np.linspace(alg.m, alg.L, points)
    mats = alg.A[None, :, :] + qs[:, None, None] * (alg.B @ alg.C)[None, :, :]
    if alg.n == 2:  # roots of z^2 - 2 half z + det: |half| + sqrt(disc), or sqrt(det)
        half = 0.5 * (mats[:, 0, 0] + mats[:, 1, 1])  # when complex (|z|^2 = det)
        det = mats[:, 0, 0] * mats[:, 1, 1] - mats[:, 0, 1] * mats[:, 1, 0]
        disc = half * half - det
        radius = np.where(disc >= 0, np.abs(half) + np.sqrt(np.maximum(disc, 0.0)),
                          np.sqrt(np.maximum(det, 0.0)))
        return float(radius.max())
    return float(np.abs(np.linalg.eigvals(mats)).max())


# --------------------------------------------------------------------------- sublinear rates
SUBLINEAR_SLACK = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2)  # C tried at C*(1 + slack) until checked
FULL_TOL = 1e-10  # largest eigenvalue / row allowed on the unreduced blocks (rounding)
SUBLINEAR_DEGREES = (2, 1)  # potentials tried in this order (the first certified is kept)
FLOAT_CHECK = "floating-point check"


@dataclass(frozen=True)
class SublinearResult:
    """Smallest constant c certified in measure(x_k) <= c |x_0 - x*|^2 / k, k >= 1 (None
    when no certificate passed the check), its certificate and how it was checked."""

    L: float
    constant: float | None
    certified: bool
    solves: int
    seconds: float
    solver: str | None
    constant_estimate: float | None = None  # the solver's optimum (not itself checked)
    params: dict[str, float] = field(default_factory=dict)
    certificate: dict[str, Any] | None = None
    check: dict[str, float] | None = None  # largest eigenvalue of each block, residual
    measure: str = "function"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (``rate_type: sublinear``)."""
        return {"rate_type": "sublinear", "constant": self.constant,
                "certified": self.certified, "L": self.L, "measure": self.measure,
                "constant_estimate": self.constant_estimate, "solves": self.solves,
                "seconds": self.seconds, "solver": self.solver, "params": dict(self.params),
                "check_kind": FLOAT_CHECK if self.certified else None,
                "check": self.check, "certificate": jsonable(self.certificate),
                "family": "sublinear"}


def _tight_rows(data: Any, sp: Any, y: np.ndarray) -> frozenset[int]:
    """Scalar rows (and multipliers) at 0 at the solver's interior point: every
    certificate has them at 0, so they are solved for as equalities."""
    x = sp.x0 + sp.N @ y
    vals = np.array([c + row @ x for _, c, row in data.rows])
    scale = max(1.0, float(np.abs(x).max()))
    return frozenset(np.flatnonzero(vals >= -1e-7 * scale).tolist())


def _certify_constant(data: Any, r_star: float, solvers: Sequence[str],
                      count: list[int]) -> tuple[float, Any, Outcome] | None:
    """(r, problem, checked outcome) at the first r = r*(1 + slack) whose strict problem
    passes the floating-point check; the rows and block directions at 0 at the solver's
    interior point (0 for every certificate) are solved for as equalities first."""
    from sosalgo.certificates.sublinear import block_kernels, full_violation, sublinear_problem

    for slack in SUBLINEAR_SLACK:
        r = r_star * (1.0 + slack)
        tight: frozenset[int] = frozenset()
        kernels: dict[str, np.ndarray] = {}
        for _ in range(3):  # each round: the interior point, its zeros, the strict check
            sp = sublinear_problem(data, tight, kernels, r)
            status, z = _solvers.lmi_point(sp.problem, math.sqrt(r))
            count[0] += 1
            if z is None:
                break
            x = sp.x0 + sp.N @ z
            tight, kernels = tight | _tight_rows(data, sp, z), block_kernels(data, x, r)
            sp = sublinear_problem(data, tight, kernels, r)
            out = solve_lmi(sp.problem, math.sqrt(r), solvers)
            count[0] += 1
            if out.feasible and full_violation(data, sp.x0 + sp.N @ out.x, r) <= FULL_TOL:
                from sosalgo.certificates.sublinear import original_kernels

                sp.kernels = original_kernels(data, kernels)  # for the exact verification
                return r, sp, out
    return None


def analyze_sublinear(spec: Spec, theta: Mapping[str, float] | None = None,
                      solvers: Sequence[str] = DEFAULT_SOLVERS,
                      degrees: Sequence[int] = SUBLINEAR_DEGREES) -> SublinearResult:
    """Smallest constant c certified by a potential with weights polynomial in k
    (:mod:`sosalgo.certificates.sublinear`; degree 2, else degree 1: ``degrees``, the first
    certified kept) for a sublinear spec
    (``m: 0``, L given): the SDP minimizes c, then c (1 + slack) is solved with a strict
    margin and its point checked in floating point; a solver status other than solved
    certifies nothing (an almost-solved optimum is only where the search starts)."""
    from sosalgo.method import bind

    start = time.perf_counter()
    from sosalgo.certificates.composite import residual_measured

    om = residual_measured(bind(spec, None, theta))  # no condition number: at the spec's L
    count = [0]
    base = dict(L=float(om.L), params=dict(om.params), measure=om.measure)
    estimate = None
    for deg in degrees:
        est, found = _sublinear_degree(om, deg, solvers, count)
        estimate = est if estimate is None or (est is not None and est < estimate) else estimate
        if found is not None:
            r, sp, out, s, full = found
            assert out.x is not None
            from sosalgo.certificates.sublinear import sublinear_parts

            check = sublinear_parts(sp, out.x, r) | {"unreduced": full}
            return SublinearResult(constant=r * s, certified=True, solves=count[0],
                                   seconds=time.perf_counter() - start, solver=out.solver,
                                   constant_estimate=est,
                                   certificate=sp.problem.unpack(out.x) | {
                                       "kernels": sp.kernels},
                                   check=check, **base)
    return SublinearResult(constant=None, certified=False, solves=count[0],
                           seconds=time.perf_counter() - start, solver=None,
                           constant_estimate=estimate, **base)


def _sublinear_degree(om: Any, deg: int, solvers: Sequence[str],
                      count: list[int]) -> tuple[float | None, tuple | None]:
    """(the SDP's optimum c (an estimate), (r, problem, outcome, units) when certified) for
    the potential of degree ``deg``."""
    from sosalgo.certificates.sublinear import (
        full_violation,
        sublinear_data,
        sublinear_problem,
    )

    data = sublinear_data(om, deg)
    status, z = _solvers.lmi_point(sublinear_problem(data).problem, None, near=True)
    count[0] += 1
    if z is None or not z[-1] > 0:
        return None, None
    found = _certify_constant(data, float(z[-1]), solvers, count)
    solved = _solvers.solver_status(status) == _solvers.SolverStatus.SOLVED
    est = float(z[-1]) * data.s if solved else None
    if found is None:
        return est, None
    r, sp, out = found
    return est, (r, sp, out, data.s, full_violation(data, sp.x0 + sp.N @ out.x, r))
