"""The worst case itself: a low-dimensional trajectory and functions that attain tau_N,
written as JSON and checked exactly (a theorem: tau_N >= its value).

Construction (:func:`make_witness`): the PEP again, minimizing tr H with the measure at
least (1 - eta) tau_N and every interpolation inequality at least a slack (the
:data:`LADDER`). Candidates, smallest dimension first: G = V V' in 1, 2, 3 dimensions and
its full rank; G mixed with a strictly feasible quadratic trajectory
(:func:`quadratic_point`, one more dimension); G mixed with an interior point G0 of the
PEP (:func:`interior_point`: every inequality at least a slack of its scale), V_theta =
[sqrt(1 - theta) V, sqrt(theta) V0] for theta in :data:`MIX` — every inequality is linear
in (G, F), so the mix has slack theta times G0's, which absorbs the solver's small
violations and the rounding, for a measure (1 - theta) as large. A floating-point
pre-check (:func:`plausible`: values exist with a margin, Bellman-Ford on the difference
constraints) skips hopeless candidates; the others are rounded to binary rationals, the
trajectory recomputed exactly, the values fitted exactly (:func:`fit_values`), and the
first that passes the exact check is kept. When none does (the float answer is not
accurate enough: Nesterov past N = 50), the last resort is a quadratic strictly inside
the class (:func:`quadratic_candidates`), its calls computed in ball arithmetic: a
proven, weaker bound. The trace solves are capped
(:data:`sosalgo.worstcase.sdp.TRACE_ITER` iterations per attempt, a failed one is not retried
on every pair): a rank reduction that does not converge costs about a second, and the
PEP's own answer mixed with the interior point takes over.

Document (``kind: pep-witness``): ``x0``; ``xi0`` (a free start: the initial state,
every block); ``calls`` (the gradient u_{k,i} of every call,
actual, not tilted); per function its class, optimal subgradient s_j* (summing to 0) and
points: ``at`` (where: ``y<i>_<k>``, ``x_0``, ``x_N``), the subgradient g there and the
tilted value h = f_j(x) - f_j(x*) - <s_j*, x - x*>; ``evaluations``: which point of each
function a term reads. Numbers are exact rationals as strings ("p/q").

The check (:func:`sosalgo.worstcase.check.check_witness`) trusts nothing but the spec: it
recomputes the trajectory with the exact method and checks every class inequality in
ball arithmetic.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.kinds import WITNESS_KIND
from sosalgo.spec import Spec
from sosalgo.worstcase.check import (
    ArbView,
    arb_view,
    check_witness,
    fit_values,
    member_interval,
    q_str,
    set_quadratic_calls,
)
from sosalgo.worstcase.sdp import PEPData, SDPAnswer, solve_pep
from sosalgo.worstcase.structure import PEPFrame, last_calls
from sosalgo.worstcase.terms import Term

__all__ = ["WITNESS_KIND", "check_witness", "finish_witness", "fit_values", "interior_point",
           "make_witness", "plausible"]

# (slack, eta) of the reduced solves, in order: every inequality >= slack (scaled rows),
# the measure kept at (1 - eta) tau_N; a larger eta leaves room for a larger slack
LADDER = ((1e-9, 1e-6), (1e-8, 1e-5), (1e-7, 1e-4), (1e-6, 1e-3))
MAX_TRIES = 3  # dimensions tried per reduced solve (then the full rank)
THETAS = (1e-6, 1e-4)  # weights of the strictly feasible quadratic mixed in
MIX = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1)  # weights of the interior point mixed in
# positions of the quadratics' curvatures in each class's interval [m, L] (the last
# resort of the search: :func:`quadratic_candidates`), and how many are checked exactly;
# never the ends (there a quadratic meets some inequalities with equality, and the
# rounding of its calls could break them), close to them (often the slowest mode)
QUADRATIC_AT = np.concatenate([[1e-4, 1e-3], np.linspace(0.02, 0.98, 49), [0.999, 0.9999]])
QUADRATIC_TRIES = 2
INTERIOR = (1e-3, 1e-4, 1e-5, 1e-6)  # slacks tried for the interior point
ALL_PAIRS = 2000  # the interior point's solve takes every pair up to this many
ACCEPT = 1e-3  # a verified witness this close to tau (relative) ends the search
# the search's own solves (the rank reductions, the interior point) start only within a
# share of the run, in CPU seconds of this process (the machine's load does not spend
# it): SHARE times what the PEP itself took, at least FLOOR; past it the candidates at
# hand are checked, then the quadratics (a long horizon's solves do not converge:
# Nesterov at N = 60 spent over 40 minutes in them, for no geometry; at N = 40 the
# search takes about 60 s, its interior point the verified witness)
SHARE, FLOOR = 2.0, 150.0
# a source whose candidates failed the exact check this many times is left for the next
# (its float answer is not accurate enough: the other mixes of it fail as well)
SOURCE_FAILS = 6
PRECHECK = 1e-9  # margin of the floating-point pre-check (relative to each row's scale)
# the witness's ``search``: candidate geometries tried, refused by the floating-point
# pre-check (:func:`plausible`), with no exact values (:func:`fit_values`), checked
# exactly; an unverified witness adds whether an interior point of the PEP was found;
# when they happen, ``sources_left`` counts the sources given up after SOURCE_FAILS exact
# failures and ``out_of_time`` says the search's share of the run ended its solves
SEARCH = ("candidates", "refused_in_floating_point", "no_exact_values", "checked_exactly")
_q = q_str


def _vec(v: np.ndarray) -> list[str]:
    return [_q(float(t)) for t in v]


def _factors(G: np.ndarray, slack: float) -> list[np.ndarray]:
    """V (d x r) with G ~ V V' for r = 1, 2, ... (at most MAX_TRIES, and while the
    dropped eigenvalues are not negligible), then the factor of full numerical rank."""
    e, V = np.linalg.eigh(0.5 * (G + G.T))
    e, V = e[::-1].clip(min=0.0), V[:, ::-1]
    rank = max(1, int(np.sum(e > 1e-15 * e[0]))) if e[0] > 0 else 1
    out = [V[:, :r] * np.sqrt(e[:r]) for r in range(1, min(rank, MAX_TRIES) + 1)]
    if rank > MAX_TRIES:
        out.append(V[:, :rank] * np.sqrt(e[:rank]))
    return out


def _candidates(mt: PEPFrame, st: Any, G: np.ndarray, slack: float,
                interior: Callable[[], np.ndarray | None]) -> Iterator[tuple[np.ndarray, float]]:
    """(V, theta), smallest dimension first (see the module): the factors of G
    (:func:`_factors`); G mixed with the quadratic trajectory of :func:`quadratic_point`
    (theta in THETAS); G (its factors) mixed with the interior point (theta in MIX)."""
    fs = _factors(G, slack)
    for V in fs:
        yield V, 0.0
    v0 = quadratic_point(mt, st)
    for theta in THETAS if v0 is not None else ():
        yield np.hstack([math.sqrt(1 - theta) * fs[-1], math.sqrt(theta) * v0[:, None]]), theta
    V0 = interior()
    for theta in MIX if V0 is not None else ():
        for V in fs:
            yield np.hstack([math.sqrt(1 - theta) * V, math.sqrt(theta) * V0]), theta


def _curvatures(mt: PEPFrame, at: float) -> list[float]:
    """q_j strictly inside each function's class: lo + at (hi - lo) of [m, L] (or lo + s/2
    for a class without an upper curvature)."""
    s, q = float(mt.s), []
    for _, cls, params in mt.functions:
        lo, hi = cls.curvatures({k: float(v) for k, v in params.items()}) or (0.0, 0.0)
        q.append(lo + at * (hi - lo) if hi > lo else lo + s / 2)
    return q


def quadratic_point(mt: PEPFrame, st: Any, at: float = 0.5,
                    curvatures: list[float] | None = None) -> np.ndarray | None:
    """The basis coordinates (one dimension) of the method run from x_0 = 1 (xi_0 = u, or
    the fixed-point direction for a free start) on f_j = q_j/2 x^2, q_j strictly inside
    its class (:func:`_curvatures`: the middle of [m, L] by default); None when a prox step
    is singular; ``curvatures``: the q_j themselves)."""
    p, s = mt.p, float(mt.s)
    q = _curvatures(mt, at) if curvatures is None else curvatures
    qc = np.array([q[j] for j in mt.oracles])
    col = {name: c for c, name in enumerate(st.basis)}
    if st.free_values:
        return None  # the origin at x_0 (no x*): no direction from x_0 = 1
    v = np.zeros(st.d)
    xi = np.asarray(mt.X0, float).copy()
    v[0] = 1.0
    if mt.G0 is not None and "x0-x*" in col:  # initial_state: xi_0 = X0 + G0 q_j (x_0 = 1)
        j = mt.smooth
        v[col[f"g_{mt.functions[j][0]}(x0)/s"]] = q[j] / s
        xi = xi + np.asarray(mt.G0, float) * q[j]
    for k in range(st.calls):
        A, B, C, D, K = (np.asarray(M, float) for M in (*mt.step(k), mt.gain(k)))
        try:
            y = np.linalg.solve(np.eye(p) - D * qc, C @ xi)
        except np.linalg.LinAlgError:
            return None
        u = qc * y / s
        for i in range(p):
            c = col.get(f"b_{'y' + str(k) if p == 1 else f'y{i + 1}_{k}'}")
            if c is not None:
                v[c] = u[i] - K[i] @ xi
            c = col.get(f"g_{'y' + str(k) if p == 1 else f'y{i + 1}_{k}'}/s")
            if c is not None:  # an inexact call's true gradient: the exact one here
                v[c] = u[i]
        xi = A @ xi + s * (B @ u)
    for j, fp in enumerate(st.points):
        for pt in fp:
            if pt.t is None and pt.label != "x*":  # a term's extra point: its gradient
                c = int(np.argmax(np.abs(pt.g)))
                v[c] = q[j] * float(pt.x @ v) / s
    return v


def quadratic_candidates(mt: PEPFrame, st: Any, tries: int = QUADRATIC_TRIES
                         ) -> list[tuple[list[Fraction], np.ndarray]]:
    """The one-dimensional trajectories (d x 1) of the quadratics f_j = q_j/2 x^2, q_j at
    one position of every class's interval (:data:`QUADRATIC_AT`), the ``tries`` with the
    largest measure (floating point) first, each with its curvatures q_j (exact: the
    floats'). A quadratic strictly inside its class meets every inequality with a slack
    of its own scale at every step, however small the iterates get: its exact check
    does not depend on the solver's accuracy."""
    scored = []
    for at in QUADRATIC_AT:
        v = quadratic_point(mt, st, float(at))
        ratio = None if v is None else _quadratic_ratio(mt, st, v, float(at))
        if ratio is not None:
            scored.append((ratio, float(at), v))
    scored.sort(key=lambda e: -e[0])
    return [([Fraction(q) for q in _curvatures(mt, at)], v[:, None])
            for _, at, v in scored[:tries]]


def _quadratic_ratio(mt: PEPFrame, st: Any, v: np.ndarray, at: float) -> float | None:
    """measure / initial of the quadratic trajectory ``v`` (values q_j/2 x^2, tilted by
    nothing: every f_j is least at x* = 0), None when it is not finite and positive."""
    return _member_ratio(mt, st, v, _curvatures(mt, at))


def make_witness(spec: Spec, kappa: float | None, mt: PEPFrame, data: PEPData,
                 ans: SDPAnswer, mterms: list[Term], iterms: list[Term],
                 res: Any, exact_mt: PEPFrame | None = None, spent: float = 0.0
                 ) -> dict[str, Any] | None:
    """The witness document in the smallest dimension that passes the exact check with a
    lower bound within :data:`ACCEPT` of tau (else the best verified one, else the last
    one tried, not verified), or None when no reduction solves (see the module).
    ``exact_mt``: the exact method (built here when not given). The search's solves
    start only within its share of the run: :data:`SHARE` times ``spent`` (the CPU
    seconds the PEP took), at least :data:`FLOOR` CPU seconds."""
    from sosalgo.worstcase.exact import exact_or_none

    if any(mt.lmis):  # the check cannot verify a class's tuple LMIs: no witness
        return None
    tau = float(ans.primal)  # type: ignore[arg-type]
    unit = tau if tau > 1e-200 else 1.0
    exact_mt = (exact_mt if exact_mt is not None
                else exact_or_none(spec, kappa, data.st.steps))
    ex: ArbView | None = None if exact_mt is None else arb_view(exact_mt)
    coef = np.array([float(mt.ineqs[j][r][0]) * float(mt.s) for j, _, _, r in data.st.pairs]
                    + [0.0] * len(data.st.extras))  # the extra constraints: no values
    inner: list[np.ndarray | None] = []
    search = _Search(spec, mt, data, res, ex, tau, coef)
    search.deadline = time.process_time() + max(FLOOR, SHARE * spent)

    def interior() -> np.ndarray | None:
        if not inner:
            inner.append(None if search.late() else interior_point(data, unit, search.late))
        return inner[0]

    if any(mt.blocks):  # Gram-level conditions: an explicit quadratic per function
        found = member_witness(spec, mt, data.st, ex, exact_mt, (tau, res))
        return None if found is None else finish_witness(found, spec, kappa, exact_mt, res)
    for G, F, slack, eta in _sources(data, ans, tau, unit, search.late):
        found = search.source(G, F, slack, eta, interior)
        if found is not None:
            return finish_witness(found, spec, kappa, exact_mt, res)
    last, best, tally = search.last, search.best, search.tally
    if best is not None:  # verified, but further below tau than ACCEPT
        return finish_witness(best, spec, kappa, exact_mt, res)
    quad = _quadratic_witness(spec, mt, data.st, ex, (tau, res), tally)
    if quad is not None:  # a weaker lower bound, proven whatever the solver's accuracy
        return finish_witness(quad, spec, kappa, exact_mt, res)
    if last is not None and "check" not in last:
        last["check"] = check_witness(last, spec, ex)
    if last is not None:  # not verified: what the search tried, and why each failed
        last["search"]["interior_point"] = bool(inner and inner[0] is not None)
    return None if last is None else finish_witness(last, spec, kappa, exact_mt, res)


class _Search:
    """The state of :func:`make_witness`'s search: the counts (:data:`SEARCH`), the last
    document tried, the best verified one, and the time its solves may start by."""

    def __init__(self, spec: Spec, mt: PEPFrame, data: PEPData, res: Any,
                 ex: ArbView | None, tau: float, coef: np.ndarray) -> None:
        self.spec, self.mt, self.data, self.res, self.ex = spec, mt, data, res, ex
        self.tau, self.coef = tau, coef
        self.tally: dict[str, Any] = dict.fromkeys(SEARCH, 0)
        self.last: dict[str, Any] | None = None
        self.best: dict[str, Any] | None = None
        self.deadline = math.inf

    def late(self) -> bool:
        """Whether the search's share of the run is spent (then said in ``search``)."""
        if time.process_time() <= self.deadline:
            return False
        self.tally["out_of_time"] = True
        return True

    def source(self, G: np.ndarray, F: np.ndarray, slack: float, eta: float,
               interior: Callable[[], np.ndarray | None]) -> dict[str, Any] | None:
        """The candidates of one source (:func:`_candidates`) in turn: the first whose
        exact lower bound is within :data:`ACCEPT` of tau, or None; the source is left
        after :data:`SOURCE_FAILS` candidates that fail the exact check."""
        tally, fails = self.tally, 0
        for V, theta in _candidates(self.mt, self.data.st, G, slack, interior):
            if fails >= SOURCE_FAILS:
                tally["sources_left"] = tally.get("sources_left", 0) + 1
                return None
            tally["candidates"] += 1
            if self.last is not None and not plausible(self.data, self.coef, V):
                tally["refused_in_floating_point"] += 1
                continue  # no values fit this geometry in floating point: skip it
            doc = _document(self.spec, self.mt, self.data.st, V, F, self.res)
            doc.update(tau_float=self.tau, objective_floor=1 - eta, slack=slack,
                       mixed=theta, search=tally)
            self.last = doc
            if self.ex is None or not fit_values(doc, self.ex):
                tally["no_exact_values"] += 1
                fails += 1
                continue  # no values fit this geometry: the check would fail
            doc["check"] = check_witness(doc, self.spec, self.ex)
            tally["checked_exactly"] += 1
            low = doc["check"]["tau_lower_float"]
            if low is None:
                fails += 1
            elif self.best is None or low > self.best["check"]["tau_lower_float"]:
                self.best = doc
            if low is not None and low >= (1 - ACCEPT) * self.tau:
                return doc
        return None


def _quadratic_witness(spec: Spec, mt: PEPFrame, st: Any, ex: ArbView | None,
                       solved: tuple[float, Any], tally: dict[str, Any]
                       ) -> dict[str, Any] | None:
    """When no geometry of the SDP's answer passes the exact check (its float answer is
    not accurate enough: at N = 60 the late iterates are far below the solver's
    tolerance): the quadratics of :func:`quadratic_candidates`, the first that passes
    the exact check, marked ``search.quadratic`` (its lower bound is the worst case
    over those quadratics, usually well below tau); None when none does. ``solved``:
    (tau, the PEP's result)."""
    tau, res = solved
    if ex is None:
        return None
    for q, V in quadratic_candidates(mt, st):
        tally["candidates"] += 1
        doc = _document(spec, mt, st, V, np.zeros(st.nF), res)
        try:  # the calls of the quadratic itself, in ball arithmetic (not V's floats)
            set_quadratic_calls(doc, ex, q)
        except (ValueError, ArithmeticError, ZeroDivisionError, KeyError, IndexError):
            continue
        doc.update(tau_float=tau, objective_floor=0.0, slack=0.0, mixed=1.0, search=tally)
        if not fit_values(doc, ex):
            tally["no_exact_values"] += 1
            continue
        doc["check"] = check_witness(doc, spec, ex)
        tally["checked_exactly"] += 1
        if doc["check"]["verified"]:
            doc["search"] = tally | {"quadratic": True}
            return doc
    return None


def _sources(data: PEPData, ans: SDPAnswer, tau: float, unit: float,
             late: Callable[[], bool] = lambda: False
             ) -> Iterator[tuple[np.ndarray, np.ndarray, float, float]]:
    """(G, F, slack, eta) to take candidates from: the reduced solves of :data:`LADDER`
    that solve, and the PEP's own answer (full rank; mixed with the interior point it
    still gives a witness when a reduced solve fails — then it comes next, before the
    other rungs, each of which costs several solver attempts). No rung is solved once
    ``late()`` (the search's share of the run spent): the PEP's own answer alone."""
    own = ans.G is not None and ans.F is not None
    for slack, eta in LADDER:
        if late():
            break
        red = solve_pep(data, objective="trace", floor=(1 - eta) * tau, slack=slack,
                        unit=unit)
        if red.status == "solved" and red.G is not None and red.F is not None:
            yield red.G, red.F, slack, eta
        elif own:
            own = False
            yield ans.G, ans.F, 0.0, 0.0  # type: ignore[misc]
    if own:
        yield ans.G, ans.F, 0.0, 0.0  # type: ignore[misc]


def interior_point(data: PEPData, unit: float,
                   late: Callable[[], bool] = lambda: False) -> np.ndarray | None:
    """A factor V0 (d x rank) of a point of the PEP where every inequality holds with a
    slack of its scale (the first of :data:`INTERIOR` that solves; least trace), or None
    (also when ``late()`` before a solve: the search's share of the run spent).
    Up to :data:`ALL_PAIRS` pairs, every pair is in the solve from the start (one solve,
    and a lower rank than constraint generation gives)."""
    saved = data.active
    if data.st.count <= ALL_PAIRS:
        data.active = np.arange(data.st.count)
    try:
        for slack in INTERIOR:
            if late():
                return None
            ans = solve_pep(data, objective="trace", slack=slack, unit=unit)
            if ans.status == "solved" and ans.G is not None:
                return _factors(ans.G, slack)[-1]
        return None
    finally:
        data.active = saved  # the later rank reductions start lean again


def plausible(data: PEPData, coef: np.ndarray, V: np.ndarray,
              margin: float = PRECHECK) -> bool:
    """Floating-point pre-check of a candidate G = V V': values F exist with every
    inequality c_k (F_a - F_b) + q_k >= margin * (its scale) (c_k = alpha_k s, the row's
    coefficient on F), i.e. the difference
    constraints have no negative cycle (Bellman-Ford from the points x*, value 0)."""
    st = data.st
    G = V @ V.T
    q = np.einsum("kuv,kuv->k", data.Qc, np.einsum("kui,kvi->kuv", data.X @ G, data.X))
    q = q + data.consts()
    xw = np.abs(data.X * data.w).max(axis=2).max(axis=1)
    size = (np.abs(data.Qc).max(axis=(1, 2)) * xw ** 2
            + np.abs(data.a * data.v).max(axis=1, initial=0.0))
    if st.equalities is not None:  # half of an equality: held exactly by the values, no
        size = np.where(st.equality_rows(len(size)), 0.0, size)  # margin (fit_values)
    q = q - margin * size
    first = np.cumsum([0] + [len(fp) for fp in st.points])
    extra = [0] * len(st.extras)  # no values (coef 0): q >= 0 alone
    na = np.array([first[j] + a for j, a, _, _ in st.pairs] + extra, dtype=int)
    nb = np.array([first[j] + b for j, _, b, _ in st.pairs] + extra, dtype=int)
    if np.any((coef == 0) & (q < 0)):
        return False
    on = coef != 0
    src = np.where(coef[on] > 0, na[on], nb[on])
    dst = np.where(coef[on] > 0, nb[on], na[on])
    w = q[on] / np.abs(coef[on])
    star = first[1:] - 1  # x* is each function's last point
    dist = np.full(first[-1], np.inf)
    dist[star] = 0.0
    for _ in range(first[-1] + 1):
        new = dist.copy()
        np.minimum.at(new, dst, dist[src] + w)
        if np.all(new >= dist):
            return bool(np.all(dist[star] >= 0))
        dist = new
    return False


def finish_witness(doc: dict[str, Any], spec: Spec, kappa: float | None,
            exact_mt: PEPFrame | None, res: Any) -> dict[str, Any]:
    """The chosen witness: the class it is about (exact strings), the proven upper bound
    of the same PEP (``upper``: its exact multipliers, re-proven by ``sosalgo verify``),
    every point and iterate exactly (:func:`add_exact_points`), the 1-d interpolant."""
    from sosalgo.kernel.kappa import kappa_fields
    from sosalgo.worstcase.exact import class_description

    try:
        doc["class"] = class_description(spec, kappa)
    except (ValueError, ArithmeticError):  # no exact class: the check fails and says why
        pass
    doc |= kappa_fields(kappa)  # the exact kappa the witness is about
    loose = necessary_only_classes(spec)
    if loose:  # its points meet necessary conditions: a lower bound of this PEP only
        doc["interpolating"] = False
        doc["necessary_only"] = loose
    proof = ((getattr(res, "certificate", None) or {}).get("proof")) or {}
    if proof.get("proven"):
        doc["upper"] = {k: proof[k] for k in ("tau_proven", "multipliers_exact", "scale",
                                              "cuts") if k in proof}
    if exact_mt is not None:
        add_exact_points(doc, exact_mt)
    if doc["dimension"] == 1:
        doc["interpolant"] = interpolant_1d(doc)
    return doc


def necessary_only_classes(spec: Spec) -> list[str]:
    """The spec's function classes whose conditions are necessary only (no interpolation
    theorem): a witness meeting them bounds this PEP from below, not the class's worst
    case (the PEP itself is then an upper bound of that worst case)."""
    from sosalgo.classes import get_class

    names = sorted({decl.cls for decl in spec.functions.values()})
    return [n for n in names if not get_class(n).interpolating]


def add_exact_points(doc: dict[str, Any], exact_mt: PEPFrame) -> None:
    """``x_exact`` on every point and ``iterates_exact``: the coordinates recomputed from
    the start and the calls in exact arithmetic (rationals ``p/q``; ``[lo, hi]`` where the
    method's irrational entries leave a ball), so that the class inequalities can be
    checked on the stored data alone (the float ``x`` and ``iterates`` stay)."""
    from sosalgo.worstcase.check import exact_points, exact_str

    try:
        pts, its = exact_points(doc, exact_mt)
    except (KeyError, ValueError, TypeError, IndexError, ArithmeticError, StopIteration):
        return
    for fd in doc["functions"].values():
        for pt in fd["points"]:
            if pt["label"] in pts:
                pt["x_exact"] = [exact_str(v) for v in pts[pt["label"]]]
    doc["iterates_exact"] = [[exact_str(v) for v in x] for x in its]


def _call_of(label: str, p: int) -> int:
    """The call index of a call point's label (``y3``, ``y2_3``)."""
    return 0 if p == 1 else int(label[1:].split("_")[0]) - 1


def _document(spec: Spec, mt: PEPFrame, st: Any, V: np.ndarray, F: np.ndarray,
              res: Any) -> dict[str, Any]:
    """The witness JSON of the factor V (see the module docstring)."""
    s = Fraction(mt.s)
    col = {name: c for c, name in enumerate(st.basis)}
    J = len(mt.functions)
    sstar = []
    for j in range(J - 1):
        c = col.get(f"s*_{mt.functions[j][0]}/s")
        sstar.append([s * Fraction(float(v)) for v in V[c]] if c is not None
                     else [Fraction(0)] * V.shape[1])
    sstar.append([-sum(col_) for col_ in zip(*sstar, strict=True)] if sstar
                 else [Fraction(0)] * V.shape[1])
    p = mt.p
    calls = []
    for k in range(st.calls):
        row = []
        for i, j in enumerate(mt.oracles):
            u = [s * Fraction(float(v)) for v in st.rows["u"][k][i] @ V]
            row.append([_q(a + b) for a, b in zip(u, sstar[j], strict=True)])
        calls.append(row)
    # a call's point answers what the method was given (the same rationals, not the
    # point's own row rounded apart from the call's)
    answered = {(f"y{k}" if p == 1 else f"y{i + 1}_{k}"): row[i]
                for k, row in enumerate(calls) for i in range(p) if i not in mt.errors}
    funcs: dict[str, Any] = {}
    for j, (name, cls, params) in enumerate(mt.functions):
        pts = []
        for pt in st.points[j][:-1]:
            gt = [s * Fraction(float(v)) for v in pt.g @ V]
            g = [a + b for a, b in zip(gt, sstar[j], strict=True)]
            if pt.label in answered and mt.oracles[_call_of(pt.label, p)] == j:
                g = [Fraction(v) for v in answered[pt.label]]
            h = Fraction(0) if pt.f is None else s * Fraction(float(F[pt.f]))  # operator: 0
            pts.append({"label": pt.label, "g": list(map(_q, g)), "h": _q(h),
                        "x": [float(v) for v in pt.x @ V]})
        funcs[name] = {"class": cls.name, "params": {k: float(v) for k, v in params.items()},
                       "optimal_subgradient": list(map(_q, sstar[j])), "points": pts}
    doc: dict[str, Any] = {}
    if st.basis[0].startswith("xi0_"):  # a free start: xi_0 = xi~_0 + X_s s~ (x* = 0)
        xs = np.asarray(mt.Xs, float) @ np.array([[float(v) for v in r] for r in sstar[:-1]]
                                                 ).reshape(len(sstar) - 1, V.shape[1])
        doc["xi0"] = [_vec(r) for r in st.rows["xi"][0] @ V + xs]
    return doc | {"kind": WITNESS_KIND, "spec": spec.name, "kappa": res.kappa,
            "steps": st.steps, "calls_per_step": p, "call_steps": st.calls,
            "measure": res.measure, "initial": res.initial, "dimension": int(V.shape[1]),
            "x0": _vec(0 * V[0] if st.free_values else V[0]),  # no x*: x_0 = 0
            "calls": calls, "functions": funcs,
            "evaluations": {f"{key}|{mt.functions[j][0]}": st.points[j][a].label
                            for (key, j), a in st.at.items()},
            "iterates": [[float(v) for v in _out(mt, st, k) @ V]
                         for k in range(st.steps + 1)]}


def _out(mt: PEPFrame, st: Any, k: int) -> np.ndarray:
    """The output row at step k (x_k = E xi_k, or the output call's point)."""
    if mt.output is None:
        return (mt.E @ st.rows["xi"][k])[0]
    if last_calls(mt):  # step k - 1's call; x_0 the start (the first basis vector)
        return st.rows["y"][k - 1][mt.output] if k else np.eye(st.d)[0]
    return st.rows["y"][k][mt.output] if k < len(st.rows["y"]) else st.rows["x"]


def interpolant_1d(doc: dict[str, Any]) -> dict[str, Any]:
    """For r = 1: each function as the smallest convex piecewise quadratic through its
    points of its smooth class, max_a h_a + g_a (x - x_a) + (m/2)(x - x_a)^2 ... drawn
    on a grid; values are tilted (h_j, minimal 0 at x* = 0)."""
    out: dict[str, Any] = {}
    for name, fd in doc["functions"].items():
        s = float(Fraction(fd["optimal_subgradient"][0]))
        pts = [(float(np.mean(p["x"])), float(Fraction(p["g"][0])) - s,
                float(Fraction(p["h"]))) for p in fd["points"]] + [(0.0, 0.0, 0.0)]
        m = float(fd["params"].get("m", 0.0))
        L = fd["params"].get("L")
        xs = np.linspace(min(p[0] for p in pts) - 0.2, max(p[0] for p in pts) + 0.2, 201)
        lo = np.max([h + g * (xs - x) + 0.5 * m * (xs - x) ** 2 for x, g, h in pts], axis=0)
        if L is not None:  # smooth: the Moreau-type upper interpolant of the lower one
            from scipy.ndimage import minimum_filter1d  # noqa: F401  (cheap, always present)

            up = np.min([h + g * (xs - x) + 0.5 * float(L) * (xs - x) ** 2
                         for x, g, h in pts], axis=0)
            lo = np.minimum(np.maximum(lo, 0.0), np.maximum(up, lo))
        out[name] = {"x": xs.tolist(), "h": lo.tolist(),
                     "points": [[p[0], p[2]] for p in pts]}
    return out


# ------------------------------------------------------------ explicit members
MEMBER_AT = np.linspace(0.0, 1.0, 201)  # positions in each class's curvature interval
MEMBER_TRIES = 3  # the best ones checked exactly
MEMBER_STEP = 1.0 / 200  # the spacing of MEMBER_AT: the refinement's bracket
GOLD = (np.sqrt(5.0) - 1) / 2


def _member_curvatures(exact_mt: PEPFrame, at: float) -> list[Fraction] | None:
    """q_j = lo + at (hi - lo) of each function's exact interval (a binary rational,
    clamped into it), None when a class has none."""
    out = []
    for _, cls, params in exact_mt.functions:
        iv = member_interval(cls, params)
        if iv is None or iv[0] > iv[1]:
            return None
        lo, hi = iv
        q = Fraction(float(lo + Fraction(at) * (hi - lo)))
        out.append(min(max(q, lo), hi))
    return out


def member_witness(spec: Any, mt: PEPFrame, st: Any, ex: Any, exact_mt: PEPFrame | None,
                   solved: tuple[float, Any]) -> dict[str, Any] | None:
    """The witness of explicit quadratics with the largest proven measure / initial
    among the :data:`MEMBER_TRIES` best of :data:`MEMBER_AT` (floating point first);
    None when none is proven."""
    tau, res = solved
    if ex is None or exact_mt is None or mt.G0 is not None or mt.line_search:
        return None
    def score(at: float) -> tuple[float, list[Fraction], np.ndarray] | None:
        q = _member_curvatures(exact_mt, at)  # type: ignore[arg-type]
        v = None if q is None else quadratic_point(mt, st, curvatures=[float(t) for t in q])
        ratio = None if v is None else _member_ratio(mt, st, v, [float(t) for t in q])
        return None if ratio is None else (ratio, q, v)  # type: ignore[return-value]

    if _member_curvatures(exact_mt, 0.0) is None:
        return None
    scored = [(e, float(at)) for at in MEMBER_AT if (e := score(float(at))) is not None]
    if scored:  # the best position refined between its neighbours (golden section)
        top = max(scored, key=lambda e: e[0][0])[1]
        lo, hi = max(0.0, top - MEMBER_STEP), min(1.0, top + MEMBER_STEP)
        for _ in range(60):
            a, b = hi - GOLD * (hi - lo), lo + GOLD * (hi - lo)
            ea, eb = score(a), score(b)
            if ea is None or eb is None:
                break
            lo, hi = (lo, b) if ea[0] >= eb[0] else (a, hi)
        if (e := score(0.5 * (lo + hi))) is not None:
            scored.append((e, 0.5 * (lo + hi)))
    scored.sort(key=lambda e: -e[0][0])
    scored = [e for e, _ in scored]
    best = None
    for _, q, v in scored[:MEMBER_TRIES]:
        doc = _document(spec, mt, st, v[:, None], np.zeros(st.nF), res)
        try:
            set_quadratic_calls(doc, ex, q)  # the calls as stored (the check recomputes)
        except (ValueError, ArithmeticError, ZeroDivisionError, KeyError, IndexError):
            continue
        doc["members"] = {name: q_str(qj) for (name, _, _), qj in zip(
            mt.functions, q, strict=True)}
        doc.update(tau_float=tau, objective_floor=0.0, slack=0.0, mixed=1.0)
        doc["check"] = check_witness(doc, spec, ex)
        if doc["check"]["verified"] and (best is None or doc["check"]["tau_lower_float"]
                                         > best["check"]["tau_lower_float"]):
            best = doc
    return best


def _member_ratio(mt: PEPFrame, st: Any, v: np.ndarray, q: list[float]) -> float | None:
    """measure / initial of the quadratics' one-dimensional run (floating point)."""
    s = float(mt.s)
    G, F = np.outer(v, v), np.zeros(st.nF)
    for j, fp in enumerate(st.points):
        for pt in fp:
            if pt.f is not None:
                F[pt.f] = q[j] / 2 * float(pt.x @ v) ** 2 / s
    meas = float(np.sum(st.meas_q.astype(float) * G) + st.meas_f.astype(float) @ F)
    init = float(np.sum(st.init_q.astype(float) * G) + st.init_f.astype(float) @ F)
    ratio = meas / init if init > 0 else float("nan")
    return ratio if np.isfinite(ratio) and ratio > 0 else None
