"""``sosalgo.pep(spec, kappa, steps)``: the worst case after N steps, its dual certificate
(checked exactly, :mod:`sosalgo.worstcase.exact`) and its worst-case trajectory
(:mod:`sosalgo.worstcase.witness`). See :mod:`sosalgo.worstcase.structure` for the problem."""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field, replace
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.errors import InputError
from sosalgo.kernel.kappa import Kappa, kappa_fields
from sosalgo.kernel.phases import show_phase
from sosalgo.spec import Spec
from sosalgo.worstcase.bind import bound_method, class_kappa, initial_gradient
from sosalgo.worstcase.constraints import spec_constraints
from sosalgo.worstcase.sdp import PEPData, SDPAnswer, pep_data, solve_pep, value_residual
from sosalgo.worstcase.steps import StepMethods, float_step_method, spec_steps
from sosalgo.worstcase.structure import (
    PEPFrame,
    PEPStructure,
    build_structure,
    deadbeat_gain,
    output_call,
)
from sosalgo.worstcase.terms import Term, parse_terms

__all__ = ["MAX_STEPS", "PEPResult", "float_method", "parse_steps", "pep", "pep_problem",
           "run_sizes"]

MAX_STEPS = 200


def parse_steps(text: object) -> list[int]:
    """``N`` or ``1..N`` (any ``a..b``), 1 <= a <= b <= MAX_STEPS."""
    src = str(text).strip()
    hit = re.fullmatch(r"(\d+)(?:\s*\.\.\s*(\d+))?", src)
    if hit is None:
        raise InputError(f"--steps: expected N or a range a..b, got {src!r}")
    a = int(hit.group(1))
    b = int(hit.group(2)) if hit.group(2) else a
    if not 1 <= a <= b <= MAX_STEPS:
        raise InputError(f"--steps: need 1 <= N <= {MAX_STEPS} (and a <= b), got {src!r}")
    return list(range(a if hit.group(2) else a, b + 1))


MARGINS = (1e-9, 1e-8, 1e-7, 1e-6)  # relative margins of the certificate solve, in order
# beyond LONG steps the float dual's error (late vectors orders of magnitude below the
# first) exceeds 1e-6 of tau: only the larger margins, tau_proven about 1e-5 above tau;
# up to LONG they follow MARGINS when those fail (Nesterov and triple momentum at N = 16:
# an error of 5e-8 tau in one direction that a margin up to 1e-6 does not cover)
LONG, LONG_MARGINS = 30, (1e-5, 1e-4)
# the relative margins of the certificate whose class-LMI cuts the PEP keeps, in order
LMI_CUT_MARGINS = (1e-6, 1e-5, 1e-4)
# past LONG, when those fail (Nesterov at N = 80: with the margin 1e-4 the exact S
# still had a least eigenvalue of -9e-8 tau, scaled); below verify's UPPER_REL (a proof
# at most 1e-3 above its tau)
LAST_MARGIN = 5e-4
# past LONG, the constraint generation ends when no omitted pair is violated by more
# than this (relative to its row; 1e-9 up to LONG): the last rounds of a long horizon
# add a few pairs violated by 1e-9 to 3e-7, each a solve of the whole PEP (Nesterov
# N = 60: 15 pairs, 30 s of 106 s); tau is then the value of a relaxation (at least
# tau_N), and its proof on the same pairs is at least that
LONG_VIOLATION = 1e-6


@dataclass
class PEPResult:
    """tau_N (float SDP value), its certificate and the worst case (``to_dict``: the
    ``pep --json`` document)."""

    spec: str
    kappa: float | None
    steps: int
    measure: str
    initial: str
    status: str
    tau: float | None
    gap: float | None = None
    certificate: dict[str, Any] | None = None
    witness: dict[str, Any] | None = None
    seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"spec": self.spec, "kappa": self.kappa, "steps": self.steps,
                "tau": self.tau, "measure": self.measure, "initial": self.initial,
                "status": self.status, "gap": self.gap, "certificate": self.certificate,
                "witness": self.witness, "seconds": self.seconds} | self.extra \
            | kappa_fields(self.kappa)  # the exact kappa the proofs are about


def _load(spec: Spec | str | Path) -> Spec:
    if isinstance(spec, Spec):
        return spec
    from sosalgo.spec import load_spec

    return load_spec(spec)


def float_method(om: Any, kappa: float) -> PEPFrame:
    """The float :class:`PEPFrame` around an OracleMethod ``om`` (the frame's method)."""
    from sosalgo.oracles import fixed_point_basis, pinned_optimum

    X = fixed_point_basis(om)
    assert X is not None  # the OracleMethod checked it

    params = dict(getattr(om, "params", None) or {})

    def coef(t: Term) -> float:
        v = t.value(om.m, om.L, kappa, params)
        if not math.isfinite(v):
            raise InputError(f"coefficient {t.coef} of {t.kind}: not a finite number here "
                             "(kappa is undefined on an m: 0 spec)")
        return v

    scale = 1.0 + float(np.abs(X).max(initial=0.0))

    def same(a: np.ndarray, b: np.ndarray) -> bool:
        return bool(np.abs(a - b).max(initial=0.0) <= 1e-12 * scale * (1 + np.abs(a).max()))

    pinned = pinned_optimum(om.functions)  # s_j* = 0: the classes' own conditions
    tilted = [fn.cls.pinned(fn.params) if pinned else fn.cls.tilted(fn.params)
              for fn in om.functions]
    ineqs = [[(float(i.alpha), np.asarray(i.Q, float)) for i in fi] for fi in tilted]
    mt = PEPFrame(om, X[:, 0], X[:, 1:], float(om.L), ineqs, coef, same,
                  deadbeat_gain(om.A, om.B, float(om.L)),
                  errors=dict(getattr(om, "errors", None) or {}),
                  lmo=dict(getattr(om, "lmo", None) or {}))
    mt.blocks = [list(fn.cls.blocks(fn.params)) for fn in om.functions]
    mt.lmis = [list(fn.cls.lmis(fn.params)) for fn in om.functions]
    if any(i.constant or i.scope != "pairs" for fi in tilted for i in fi):
        mt.constants = [[float(i.constant) for i in fi] for fi in tilted]
        mt.scopes = [[i.scope for i in fi] for fi in tilted]
        if any(c < 0 or not math.isfinite(c) for fc in mt.constants for c in fc):
            raise InputError("functions: a class inequality has a negative or infinite "
                             "constant (must be >= 0)")
    if om.output is None:
        mt.out_call = output_call(om.E, np.asarray(om.C, float), np.asarray(om.D, float),
                                  same)
    if getattr(om, "adjoint", None) is not None:  # transpose calls
        from sosalgo.worstcase.adjoint import split_transposes

        split_transposes(mt, om)
    return mt


def _check_kappa(spec: Spec, kappa: float | None) -> None:
    """A kappa exactly when the spec's class has one (as :func:`bound_method` asks)."""
    from sosalgo.worstcase.bind import has_kappa

    if not has_kappa(spec) and kappa is not None:
        raise InputError(f"{spec.source}: --kappa: an m: 0 spec has no condition number "
                         f"(L = {spec.L:g} is given)")
    if has_kappa(spec) and kappa is None:
        raise InputError(f"{spec.source}: --kappa: required (the condition number L/m)")


def _default_measure(spec: Spec) -> str:
    return "dist" if spec.measure == "distance" else "f"


def default_initial(om: Any) -> str:
    """``sdist`` (a free start, |xi_0 - xi*|^2) when the method's fixed point moves with
    the optimal subgradients (X_s != 0: from xi_0 = u x_0 the distance |x_0 - x*| cannot
    bound the measure), ``dist`` otherwise."""
    from sosalgo.oracles import fixed_point_basis

    X = fixed_point_basis(om)
    scale = 1.0 + float(np.abs(X).max(initial=0.0)) if X is not None else 1.0
    moves = X is not None and float(np.abs(X[:, 1:]).max(initial=0.0)) > 1e-12 * scale
    return "sdist" if moves else "dist"


def run_sizes(spec: Spec, kappas: list[float | None], steps: list[int],
              measure: str | None, initial: str | None
              ) -> tuple[list[tuple[int, int]], bool]:
    """Every input error of a run (``steps`` x ``kappas``) before anything is written
    (InputError naming the option), and the (constraints, basis) size of each of its
    PEPs, for the memory budget; False with a finite sum's sizes (a tree of outcomes,
    counted exactly), True with sizes scaled from the largest horizon's."""
    if spec.finite_sum is not None:
        from sosalgo.worstcase.finite_sum import finite_sum_sizes

        return finite_sum_sizes(spec, kappas, steps, measure, initial), False
    # the first horizon asked: a schedule's is its length, and a term may name a step
    # (x_2, y_1, x_N-1) that a shorter one has not reached
    top = max(steps)
    if spec.mirror:  # Bregman steps: their own PEP (sosalgo.worstcase.mirror)
        from sosalgo.worstcase.mirror import mirror_problem

        npairs, d = mirror_problem(spec, kappas, top, measure, initial)
    else:
        for k in kappas:
            pep_problem(spec, k, min(steps), measure, initial, solve_min=False)
        _, st, *_ = pep_problem(spec, kappas[0], top, measure, initial, solve_min=False)
        npairs, d = len(st.pairs), st.d
    return [(round(npairs * ((n + 1) / (top + 1)) ** 2),
             max(1, round(d * (n + 1) / (top + 1)))) for n in steps] * len(kappas), True


def pep_problem(spec: Spec, kappa: float | None, steps: int, measure: str | None = None,
                initial: str | None = None, schedule: StepMethods | None = None,
                solve_min: bool = True
                ) -> tuple[PEPFrame, PEPStructure, list[Term], list[Term], tuple[str, str]]:
    """The float method, structure, terms and the (measure, initial) texts, defaults
    resolved (InputError naming the option for bad input). ``schedule``: a method that
    changes with k (:mod:`sosalgo.worstcase.steps`; the spec gives its class and terms). A
    ``mingrad`` measure is replaced by its weighted sum at the minimax weights
    (:mod:`sosalgo.worstcase.minimum`; uniform weights when not ``solve_min``: the structure's
    size only); the returned terms are then the weighted sum's, and ``mt.bound`` its
    text."""
    if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= MAX_STEPS:
        raise InputError(f"--steps: must be an integer in 1..{MAX_STEPS}, got {steps!r}")
    _no_expectation(spec, measure, initial)
    if schedule is None:  # the problem layer's per-step methods (None: one method)
        schedule = spec_steps(spec, kappa, steps)
    if schedule is not None:
        _check_kappa(spec, kappa)
        om, kq = schedule.floats[0], (math.nan if kappa is None else float(kappa))
    else:
        om, kq = bound_method(spec, kappa)
    mopt = "--measure" if measure or "measure" not in spec.pep else "pep.measure"
    measure = measure or spec.pep.get("measure") or _default_measure(spec)
    if not initial and measure.strip() == "contraction":  # two runs: its own start
        initial = "contraction"
    iopt = "--initial" if initial or "initial" not in spec.pep else "pep.initial"
    initial = initial or spec.pep.get("initial") or default_initial(om)
    try:
        mterms = parse_terms(measure, mopt, False, om.p, spec.parameters)
        iterms = parse_terms(initial, iopt, True, om.p, spec.parameters)
    except InputError as exc:  # a spec's field: named with its file
        raise (InputError(f"{spec.source}: {exc}") if str(exc).startswith("pep.")
               else exc) from None
    from sosalgo.worstcase.terms import MIN_OF

    if not iterms and any(t.kind in MIN_OF for t in mterms):
        raise InputError(f"{spec.source}: {iopt}: none: a minimum over the iterates needs an "
                         "initial condition (with none it is 0 or unbounded as its terms are)")
    mt = float_method(om, kq)
    if schedule is not None:
        mt = float_step_method(schedule, mt, steps)
    mt.constraints = spec_constraints(spec, om.p)
    mt.error_refs = {i: tuple(float(c) for c in ref)
                     for i, ref in (getattr(spec, "error_refs", None) or {}).items()}
    mt.twins = dict(getattr(spec, "twins", None) or {})
    from sosalgo.worstcase.epsilon import float_epsilons

    mt.epsilons = float_epsilons(spec, om, kq, mt)
    if mt.epsilons:  # the plain basis (the exact rows keep short denominators)
        mt.K = np.zeros_like(mt.K)
    if mt.constraints and schedule is not None:
        raise InputError(f"{spec.source}: pep.constraints: not for a method that changes "
                         "with k")
    mt.G0, mt.smooth = initial_gradient(spec, om, kq)
    mt.line_search = bool(spec.line_search)
    mt.span_search = bool(getattr(spec, "span_search", False))
    if mt.line_search and schedule is not None:
        raise InputError(f"{spec.source}: line_search: not for a method that changes with k")
    try:
        bound = _resolve_min(mt, steps, mterms, iterms, kq, solve_min)
        st = build_structure(mt, steps, bound, iterms, (mopt, iopt))
        if bound is not mterms and solve_min:
            from sosalgo.worstcase.minimum import min_floors

            st.floors = min_floors(mt, steps, mterms, iterms)
        mterms = bound
    except InputError as exc:
        raise InputError(f"{spec.source}: {exc}") from None
    return mt, st, mterms, iterms, (measure, initial)


def _no_expectation(spec: Spec, measure: str | None, initial: str | None) -> None:
    """An expectation ``E[...]`` needs a drawn oracle (a finite-sum spec): InputError
    naming the field otherwise."""
    for opt, text, key in (("--measure", measure, "measure"), ("--initial", initial,
                                                                "initial")):
        field_ = opt if text else f"pep.{key}"
        text = text or spec.pep.get(key) or ""
        if re.search(r"\bE\s*\[", text):
            raise InputError(f"{spec.source}: {field_}: E[...] is an expectation over a "
                             "stochastic oracle; this spec draws none (a function with "
                             "count: and finite_sum:)")


def _resolve_min(mt: PEPFrame, steps: int, mterms: list[Term], iterms: list[Term],
                 kappa: float, solve_min: bool) -> list[Term]:
    """``mterms`` with a mingrad term replaced by its weighted sum (see
    :func:`pep_problem`); the text is kept as ``mt.bound``."""
    from sosalgo.worstcase.terms import MIN_OF, expand_min

    mins = [t for t in mterms if t.kind in MIN_OF]
    if not mins:
        return mterms
    if len(mins) > 1 or not mt.coef(mins[0]) > 0:
        raise InputError(f"--measure: {mins[0].kind}: one minimum term, with a positive "
                         "coefficient (a minimum is bounded from above, not from below)")
    if solve_min:
        from sosalgo.worstcase.minimum import min_weights, rational_weights

        w = rational_weights(min_weights(mt, steps, mterms, iterms))
    else:
        w = [Fraction(1, steps + 1)] * (steps + 1)
    mt.bound = expand_min(mterms, steps, w)
    return parse_terms(mt.bound, "--measure", False, mt.p)


def pep(spec: Spec | str | Path, kappa: float | None = None, steps: int = 1,
        measure: str | None = None, initial: str | None = None, exact: bool = True,
        witness: bool = True, schedule: StepMethods | None = None) -> PEPResult:
    """The PEP of ``spec`` at ``kappa`` over ``steps`` steps (see the module);
    ``schedule``: the per-step methods of a method that changes with k
    (:mod:`sosalgo.worstcase.steps`), the spec giving the class, the units and the terms."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    spec = _load(spec)
    if spec.mirror:  # Bregman steps: their own PEP (sosalgo.worstcase.mirror)
        from sosalgo.worstcase.mirror import mirror_pep

        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= MAX_STEPS:
            raise InputError(f"--steps: must be an integer in 1..{MAX_STEPS}, got {steps!r}")
        return mirror_pep(spec, kappa, steps, measure, initial, exact, PEPResult)
    if spec.finite_sum is not None:  # one of n functions drawn per step: a tree of outcomes
        from sosalgo.worstcase.finite_sum import finite_sum_pep

        _check_kappa(spec, kappa)
        got = finite_sum_pep(spec, kappa, steps, measure, initial, exact)
        k = class_kappa(spec, kappa)
        res = PEPResult(spec.name, None if k is None else (
            k if isinstance(k, Kappa) else float(k)),  # type: ignore[arg-type]
            steps, got["measure"], got["initial"], got["status"], got["tau"], got["gap"],
            got["certificate"], None, extra=got["extra"])
        res.seconds = time.perf_counter() - t0
        return res
    if schedule is None:  # the problem layer's per-step methods (None: one method)
        schedule = spec_steps(spec, kappa, steps)
    mt, st, mterms, iterms, names = pep_problem(spec, kappa, steps, measure, initial,
                                                schedule)
    data = pep_data(mt, st)
    if schedule is not None:  # dense rows (the plain basis): every pair from the start
        data.active, data.strong = np.arange(st.count), True
    if steps > LONG:  # its proof is about LONG_MARGINS above tau anyway
        data.violation = LONG_VIOLATION
    show_phase("solving the PEP", f"{len(st.pairs)} interpolation pairs")
    others: list[Any] = []  # the class LMIs' other cut sets (:func:`_lmi_cut_pep`)
    if st.bare:  # no initial condition: its own solves
        st, data, ans = _bare_solve(mt, st, data, steps, mterms, iterms)
    else:
        ans = solve_pep(data)
        if ans.status == "failed" and not data.strong:
            # every attempt "almost solved" (the inexact gradient method at N = 5, 6 on all
            # its pairs): again with the strong regularization, whose multipliers the exact
            # proof accepts or refuses as ever
            data.strong = True
            ans = solve_pep(data)
        if ans.status == "failed" and schedule is None and np.any(mt.K) \
                and steps <= PLAIN_RETRY_STEPS:
            # a direction of G the question leaves free (a free start under a Lyapunov
            # function) drifts: the plain basis, no rescaling (the robust momentum method)
            mt.K = np.zeros_like(mt.K)
            st = build_structure(mt, steps, mterms, iterms)
            data = pep_data(mt, st)
            ans = solve_pep(data, rescale=False)
        if data.blocks and ans.status == "solved":  # Gram-level conditions: their cuts
            st, data, ans = _cut_pep(mt, st, data, ans)
        if data.lmis and ans.status == "solved":  # class LMIs on tuples: their cuts
            (st, data, ans), others = _lmi_cut_pep(mt, st, data, ans)
    k = class_kappa(spec, kappa)
    kf = None if k is None else (  # a Kappa keeps its exact value
        k if isinstance(k, Kappa) else float(k))  # type: ignore[arg-type]
    res = PEPResult(spec.name, kf,
                    steps, *names, ans.status, ans.primal if ans.status == "solved" else None)
    if mt.bound is not None:  # mingrad: every number is about this upper bound of it
        res.extra["measure_bound"] = mt.bound
    if ans.status == "unbounded":
        res.tau = math.inf
        res.extra["note"] = ("the measure is unbounded for this initial condition (e.g. the "
                             "start does not control the method's fixed point)")
    if schedule is not None:
        res.extra["schedule"] = schedule.schedule
    if ans.status == "solved" and st.bare:  # no initial condition: 0 or unbounded
        _bare_result(spec, kappa, steps, mt, data, ans, exact, mterms, iterms, res)
    elif ans.status == "solved":
        res.gap = abs(float(ans.primal) - float(ans.dual))  # type: ignore[arg-type]
        from sosalgo.worstcase.exact import exact_or_none

        if schedule is None:
            ex = exact_or_none(spec, kappa, steps) if exact or witness else None  # built once
            if ex is not None and not np.any(mt.K):  # the float solve's basis (K = 0)
                ex.K = np.full(ex.K.shape, Fraction(0), dtype=object)
                ex.structures.clear()
        else:
            ex = _exact_schedule(spec, kappa, schedule, len(mt.per_step or ()))
            exact, witness = exact and ex is not None, witness and ex is not None
            if ex is None:
                res.extra["note"] = "no exact per-step matrices: the certificate is not proven"
        show_phase("proving the certificate" if exact else "checking the certificate")
        res.certificate = _certificate(spec, kappa, mt, data, ans, exact, mterms, iterms, ex)
        for alt in others if exact else ():  # the class LMIs' other cut sets
            if res.certificate.get("tau_proven"):
                break
            cert = _certificate(spec, kappa, mt, alt[1], alt[2], exact, mterms, iterms, ex)
            if cert.get("tau_proven"):
                (st, data, ans), res.certificate = alt, cert
        if witness and any(t.kind == "contraction" for t in mterms):  # two runs
            from sosalgo.worstcase.contraction_witness import contraction_witness
            from sosalgo.worstcase.witness import check_witness, finish_witness

            show_phase("worst-case witness")
            res.witness = contraction_witness(spec, kappa, mt, res, ex)
            if res.witness is not None:
                res.witness["check"] = check_witness(res.witness, spec, ex)
                res.witness = finish_witness(res.witness, spec, kappa, None, res)
        elif witness and _quadratic_terms(mterms + iterms):  # not in the witness file
            res.extra["note"] = ("no worst-case witness for inner, free or call-point terms "
                                 "(tau_proven is the proven upper bound)")
        elif witness and mt.lmo:  # no witness construction for a linear minimization call
            res.extra["note"] = ("no worst-case witness for a linear minimization oracle "
                                 "(tau_proven is the proven upper bound)")
        elif witness and mt.epsilons:  # no witness construction for an eps-subgradient
            res.extra["note"] = ("no worst-case witness for epsilon-subgradient calls "
                                 "(tau_proven is the proven upper bound)")
        elif witness and mt.constraints:  # the witness check does not prove constraints
            res.extra["note"] = ("no worst-case witness for a PEP with constraints on the "
                                 "instance (tau_proven is the proven upper bound)")
        elif witness and mt.span_search:  # no witness construction for a span search
            res.extra["note"] = ("no worst-case witness for a span search "
                                 "(tau_proven is the proven upper bound)")
        elif witness and mt.adjoint is not None:  # transpose calls: not in the witness file
            res.extra["note"] = ("no worst-case witness for transpose calls (tau_proven is "
                                 "the proven upper bound)")
        elif witness and mt.line_search:  # a run on the class's extremal quadratic
            from sosalgo.worstcase.linesearch_witness import line_search_witness

            show_phase("worst-case witness")
            res.witness = line_search_witness(spec, kappa, mt, st, res, ex)
        elif witness:
            from sosalgo.worstcase.witness import make_witness

            show_phase("worst-case witness")
            res.witness = make_witness(spec, kappa, mt, data, ans, mterms, iterms, res, ex,
                                       spent=time.process_time() - cpu0)
    res.seconds = time.perf_counter() - t0
    return res


def _bare_solve(mt: PEPFrame, st: PEPStructure, data: PEPData, steps: int,
                mterms: list[Term], iterms: list[Term]
                ) -> tuple[PEPStructure, PEPData, SDPAnswer]:
    """The solves of a question with no initial condition: tight tolerances first (the
    proof needs the null space of S), then the default ones; in the deadbeat basis, then
    in the plain one (K = 0: the accelerated potential ends "almost solved" in the
    first, the second gradient potential in the second)."""
    for plain in (False, True):
        if plain:
            if not np.any(mt.K):
                break
            mt.K = np.zeros_like(mt.K)
            st = build_structure(mt, steps, mterms, iterms)
            st.bare = True
            data = pep_data(mt, st)
        for precise in (True, False):
            ans = solve_pep(data, precise=precise)
            if ans.status == "solved":
                return st, data, ans
    return st, data, ans


BARE_TOL = 1e-6  # with no initial condition: a normalized worst case above this is > 0


def _bare_result(spec: Spec, kappa: float | None, steps: int, mt: PEPFrame, data: PEPData,
                 ans: SDPAnswer, exact: bool, mterms: list[Term], iterms: list[Term],
                 res: PEPResult) -> None:
    """A question with no initial condition (``--initial none``): the measure is
    homogeneous in the instance, so its worst case is 0 (the instance at x*, every vector
    0) when it is <= 0 everywhere, else unbounded. The solver's normalized worst case t
    decides (t > BARE_TOL: unbounded); tau = 0 is then proven exactly at tau = 0
    (:func:`sosalgo.worstcase.exact.prove_bare`). No witness: 0 is reached by x_0 = x*."""
    t = float(ans.primal)  # type: ignore[arg-type]
    res.extra["normalized_tau"] = t
    if t > BARE_TOL:
        res.status, res.tau = "unbounded", math.inf
        res.extra["note"] = ("the measure is positive at some instance: with no initial "
                             "condition it grows with the instance, unbounded")
        return
    res.tau, res.gap = 0.0, abs(float(ans.primal) - float(ans.dual))  # type: ignore[arg-type]
    lam, S = ans.lam, ans.S
    assert lam is not None and S is not None
    cert: dict[str, Any] = {"tau": 0.0, "check_kind": "floating-point check",
                            "tau_proven": None, "proof": None}
    if exact:
        from sosalgo.worstcase.exact import exact_or_none, prove_bare

        show_phase("proving the certificate")
        proof = prove_bare(spec, kappa, data.st, mterms, iterms, lam, S, data.w,
                           exact_or_none(spec, kappa, steps), plain=not np.any(mt.K))
        cert["proof"] = proof
        if proof["proven"]:
            cert.update(check_kind="exact (rational and ball arithmetic)",
                        tau_proven=proof["tau_proven"], margin=0.0)
        elif mt.per_step is None:  # a singular S along an irrational direction
            _field_proof(spec, kappa, mt, data, ans, mterms, iterms, cert, 0.0)
    top = float(lam.max(initial=0.0))
    cert["multipliers"] = {lab: float(v) for lab, v in zip(data.st.labels, lam, strict=True)
                           if v > 1e-12 * top}
    cert["basis"] = data.st.basis
    cert["slack"] = S.tolist()
    cert["min_eig_slack"] = float(np.linalg.eigvalsh(S)[0])
    res.certificate = cert
    res.extra["note"] = ("no initial condition: the worst case 0 is reached at x_0 = x* "
                         "(every vector 0)" + ("; tau_proven = 0 proves measure <= 0 "
                                               "everywhere" if cert["tau_proven"] else ""))


PLAIN_RETRY_STEPS = 5  # a failed solve is retried in the plain basis up to this horizon


def _quadratic_terms(terms: list[Term]) -> bool:
    """Whether a term is one the witness file does not evaluate: ``inner``, ``free`` or a
    call's point at a given step (:mod:`sosalgo.worstcase.terms`)."""
    from sosalgo.worstcase.terms import CALL_AT, FREE_KIND, GRAD_OF, INNER_KIND

    return any(t.kind in (INNER_KIND, FREE_KIND) or any(
        CALL_AT.match(q.removeprefix(GRAD_OF)) for q in t.point.split("__")) for t in terms)


def _cut_pep(mt: PEPFrame, st: PEPStructure, data: PEPData, ans: SDPAnswer
             ) -> tuple[PEPStructure, PEPData, SDPAnswer]:
    """(structure, data, answer) of the PEP with the rank-one cuts of the block
    multipliers of ``ans`` (:mod:`sosalgo.worstcase.blocks`), solved again from the same pairs
    and scale."""
    from sosalgo.worstcase.blocks import cut_vectors, with_cuts

    cut = with_cuts(mt, st, cut_vectors(st, ans.blocks))
    new = pep_data(mt, cut)
    new.w, new.v, new.strong, new.violation = data.w, data.v, data.strong, data.violation
    new.active = np.union1d(data.active, np.arange(len(cut.pairs), cut.count))
    return cut, new, solve_pep(new)


def _lmi_cut_pep(mt: PEPFrame, st: PEPStructure, data: PEPData, ans: SDPAnswer
                 ) -> tuple[tuple[PEPStructure, PEPData, SDPAnswer], list[Any]]:
    """(structure, data, answer) of the PEP with cuts of the class LMIs from the
    multipliers of ``ans`` (:mod:`sosalgo.worstcase.lmis`), solved again from the same
    pairs and scale; and the other cut sets' (tried when the first is not proven)."""
    from sosalgo.worstcase.lmis import lmi_cuts

    tight = solve_pep(data, precise=True)  # the cuts are as good as the multipliers
    if tight.status == "solved":
        ans = tight
    cuts = lmi_cuts(st, mt, ans.lmis)
    # and the cuts of a certificate with a margin (S ⪰ eps): the margin solves of the
    # cut PEP can then reach one (a cut's direction is fixed)
    tau = float(ans.primal)  # type: ignore[arg-type]
    more: list[Any] = []
    for rel in LMI_CUT_MARGINS:  # the first that solves
        margin = solve_pep(data, margin=rel / max(1.0, ans.size),
                           unit=tau if tau > 1e-200 else 1.0)
        if margin.status == "solved":
            more = [c for c in lmi_cuts(st, mt, margin.lmis) if c not in cuts]
            break
    # with them, then without (the other cut set's certificate is tried when the first
    # one's is not proven: either proof may fail where the other holds)
    found = [_cut_try(mt, st, data, c) for c in ([cuts + more, cuts] if more else [cuts])]
    found = [f for f in found if f[2].status == "solved"] or found[:1]
    return found[0], found[1:]


def _cut_try(mt: PEPFrame, st: PEPStructure, data: PEPData, cuts: list[Any]
             ) -> tuple[PEPStructure, PEPData, SDPAnswer]:
    """The PEP with these cuts, solved from the same pairs and scale."""
    from sosalgo.worstcase.lmis import with_lmi_cuts

    cut = with_lmi_cuts(mt, st, cuts)
    new = pep_data(mt, cut)
    new.w, new.v, new.strong, new.violation = data.w, data.v, data.strong, data.violation
    new.active = np.union1d(data.active, np.arange(len(cut.pairs), cut.count))
    return cut, new, solve_pep(new)


def _exact_schedule(spec: Spec, kappa: float | None, schedule: StepMethods,
                    count: int) -> PEPFrame | None:
    """The exact method of a schedule's first ``count`` steps, None when it cannot be
    built (no exact matrices, or their fixed point not proven)."""
    from sosalgo.worstcase.exact import exact_step_method

    try:
        return exact_step_method(spec, kappa, schedule, count)
    except (ValueError, ArithmeticError):
        return None


def _ladder(steps: int, mixed: bool = False, precise: bool = False
            ) -> list[tuple[float, bool]]:
    """(relative margin, tight tolerances) of the certificate solves, in order: the first
    margin at Clarabel's default tolerances, then again at tight ones (a default solve's
    dual may miss the proof by its accuracy), then the larger margins. ``mixed`` (an
    interior certificate to mix with, :func:`_mixed`): the measure's own answer first
    (margin 0), then every margin at default tolerances. ``precise``: every margin at
    tight tolerances only (a PEP whose free points are tied to the run by equalities
    alone: :func:`_certificate`)."""
    if mixed:
        return [(0.0, False)] + [(r, False) for r in MARGINS + LONG_MARGINS]
    rels = MARGINS + LONG_MARGINS if steps <= LONG else LONG_MARGINS + (LAST_MARGIN,)
    if precise:
        return [(r, True) for r in rels]
    return [(rels[0], False), (rels[0], True)] + [(r, False) for r in rels[1:]]


INTERIOR_MARGINS = (1e-3, 1e-2)  # relative margins of the interior certificate


def _interior_certificate(data: PEPData, tau: float, scale: float) -> SDPAnswer | None:
    """A dual certificate with S clearly positive definite (a large margin: its tau is
    about 1e-3 above), None when none solves; mixed into the candidates of a degenerate
    SDP (:func:`_mixed`)."""
    for rel in INTERIOR_MARGINS:
        cand = solve_pep(data, margin=rel / scale, unit=tau if tau > 1e-200 else 1.0)
        if cand.status == "solved" and cand.S is not None and _min_eig(cand.S, data.w) > 0:
            return cand
        if cand.status == "unbounded":  # no certificate with this margin: none with a
            return None  # larger one either
    return None


def _min_eig(S: np.ndarray, w: np.ndarray) -> float:
    return float(np.linalg.eigvalsh(S * np.outer(w, w))[0])


def _mixed(cand: SDPAnswer, inner: SDPAnswer, w: np.ndarray,
           floor_rel: float | None = None) -> SDPAnswer:
    """cand mixed with the interior certificate: (tau, lambda) = (1 - theta) cand +
    theta inner (S and c_F are affine in them), theta the smallest that makes the scaled S
    clearly positive definite in floating point (min eig at least cand.s
    deficit): tau grows by theta (tau_inner - tau). cand itself when already so.
    ``floor_rel``: that floor relative to the largest entry of the scaled S (a polished
    candidate, :mod:`sosalgo.worstcase.polish`, is that accurate); else 1e-12, absolute for
    entries below 1."""
    a, b = _min_eig(cand.S, w), _min_eig(inner.S, w)  # type: ignore[arg-type]
    top = float(np.abs(cand.S * np.outer(w, w)).max())  # type: ignore[operator]
    floor = 1e-12 * max(1.0, top) if floor_rel is None else floor_rel * top
    if a >= floor or b <= 0:
        return cand
    theta = min(1.0, 2 * (floor - a) / (b - a))
    lam = (1 - theta) * cand.lam + theta * inner.lam  # type: ignore[operator]
    tau = (1 - theta) * float(cand.tau) + theta * float(inner.tau)  # type: ignore[arg-type]
    const = (1 - theta) * cand.const + theta * inner.const
    return replace(cand, tau=tau, lam=lam, S=(1 - theta) * cand.S + theta * inner.S,
                   const=const)


NULL_DIRECTIONS = 3  # the null-row proof on S with at most this many free directions,
NULL_EQUATIONS = 16  # or more when its exact system (d equations per direction) is this small


LOOSE_REL = 1e-7  # a proven bound further above tau than this invites a tighter proof


LOOSE_RUNGS = 2  # rungs of the ladder tried further after a loose proof


def _tighter(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether certificate ``a`` proves a smaller bound than ``b`` (both proven)."""
    return Fraction(a["tau_proven"]) < Fraction(b["tau_proven"])


def _loose(cert: dict[str, Any], tau: float) -> bool:
    """Whether ``cert`` is proven but more than LOOSE_REL (relative) above ``tau``."""
    proven = cert.get("tau_proven")
    return bool(proven) and float(Fraction(proven)) > tau + LOOSE_REL * abs(tau)


def _own_bound(cert: dict[str, Any], answer: SDPAnswer, best: SDPAnswer, tau: float) -> bool:
    """Whether the proven ``cert`` is this rung's own answer (no polish, no mix) proven at
    its own bound (the first bound step): the loose proof is the margin's cost, and the
    larger margins' answers cost more (a proof at a later bound step may still be
    tightened by the next rung's answer)."""
    own = max(answer.tau + answer.const, tau)
    return best is answer and float(Fraction(cert["tau_proven"])) <= own + 1e-9 * abs(own)


def _null_row_proof(spec: Spec, kappa: float | None, mt: PEPFrame, data: PEPData,
                    ans: SDPAnswer, mterms: list[Term], iterms: list[Term],
                    ex: PEPFrame | None, cert: dict[str, Any], tau: float,
                    null_tol: float | None = None) -> None:
    """The measure's own certificate with its near-zero rows of S made exactly zero in
    rationals (a PEP with a free direction has no certificate with S ≻ 0, so no margin
    proves it; :func:`sosalgo.worstcase.exact.null_row_multipliers`); ``cert`` updated when
    proven."""
    from sosalgo.worstcase.exact import NULL_ROW, prove_certificate

    Sh = ans.S * np.outer(data.w, data.w)  # type: ignore[operator]
    scale = max(1.0, float(np.abs(Sh).max()))
    free = int(np.sum(np.abs(np.linalg.eigvalsh(0.5 * (Sh + Sh.T)))
                      <= (NULL_ROW * scale if null_tol is None else null_tol)))
    # none: a margin's job; many on a large S: a tight worst case's large exact system
    # (each null vector brings d equations); on a small S even all of its directions (the
    # gradient method on PL functions, N = 2: S = 0 on d = 4)
    if free < 1 or (free > NULL_DIRECTIONS and free * len(Sh) > NULL_EQUATIONS):
        return
    proof = prove_certificate(spec, kappa, data.st, mterms, iterms, tau, ans.lam, data.w,
                              ex, null=ans.S, null_tol=null_tol)  # type: ignore[arg-type]
    if mt.bound is not None:
        proof["measure_bound"] = mt.bound
    if proof["proven"]:
        cert.update(proof=proof, check_kind="exact (rational and ball arithmetic)",
                    tau_proven=proof["tau_proven"], tau=ans.tau, margin=0.0)


def _field_proof(spec: Spec, kappa: float | None, mt: PEPFrame, data: PEPData,
                 ans: SDPAnswer, mterms: list[Term], iterms: list[Term],
                 cert: dict[str, Any], tau: float) -> None:
    """The measure's own certificate proven over the spec's quadratic field Q(sqrt d)
    (:mod:`sosalgo.worstcase.field_proof`: a singular S along an irrational direction);
    ``cert`` updated when proven."""
    from sosalgo.worstcase.field_proof import FIELD_CHECK, prove_in_field

    if mt.bound is not None:  # a mingrad measure's bound: not re-provable from the field
        return
    answers = []
    for cand in (_polished(data, ans, tau), ans):  # the polished one is the most accurate
        if cand is not None and cand.S is not None and cand.lam is not None:
            answers.append((cand.S, float(cand.tau), cand.lam,  # type: ignore[arg-type]
                            value_residual(data, float(cand.tau), cand.lam)))
    proof = prove_in_field(spec, kappa, mt, data.st, mterms, iterms, answers, data.w)
    if proof["proven"]:
        cert.update(proof=proof, check_kind=FIELD_CHECK, tau_proven=proof["tau_proven"],
                    margin=0.0)
        if not data.st.bare:
            cert["tau"] = ans.tau + ans.const
    elif cert.get("proof") is None:
        cert["proof"] = proof


def _centered_proof(spec: Spec, kappa: float | None, mt: PEPFrame, data: PEPData,
                    ans: SDPAnswer, mterms: list[Term], iterms: list[Term],
                    ex: PEPFrame | None, cert: dict[str, Any], tau: float) -> None:
    """A slightly larger bound tau (1 + rel) proven from a certificate pushed into the
    interior (:mod:`sosalgo.worstcase.centered`: an optimum of high degree whose S is
    singular on a large subspace), for each rel of its CENTER_RELS until one proves;
    ``cert`` updated when proven."""
    from sosalgo.worstcase.centered import (
        CENTER_RELS,
        centerable,
        centered_multipliers,
        prove_centered,
    )
    from sosalgo.worstcase.exact import prove_certificate

    if not tau > 0 or not centerable(data):
        return
    for rel, values in ((r, v) for r in CENTER_RELS for v in (True, False)):
        got = centered_multipliers(data, tau * (1 + rel), values)
        if got is None:
            continue
        proof = prove_certificate(
            spec, kappa, data.st, mterms, iterms, tau * (1 + rel), got[0], data.w, ex,
            prover=lambda mx, sx, tq, lam=got[0]: prove_centered(mx, sx, data, lam, tq))
        if mt.bound is not None:
            proof["measure_bound"] = mt.bound
        if proof["proven"]:
            proof["centered_margin"] = got[1]
            cert.update(proof=proof, check_kind="exact (rational and ball arithmetic)",
                        tau_proven=proof["tau_proven"], tau=ans.tau + ans.const,
                        margin=rel * tau)
            return


def _linear_only(data: PEPData) -> list[int] | None:
    """With constants, the basis directions no form has a square of (S is 0 on their
    diagonal: its rows there are made exactly zero in the proof,
    :func:`sosalgo.worstcase.sdp.linear_only`); None when there are none or no constants (the
    margin proofs as they are)."""
    from sosalgo.worstcase.sdp import linear_only

    return [c for c, v in enumerate(linear_only(data)) if v == 0] or None


POLISH_FLOORS = (1e-12, 1e-9)  # a polished candidate's floor on S, relative to |S|


def _polished(data: PEPData, ans: SDPAnswer, tau: float) -> SDPAnswer | None:
    """The measure's answer polished (:mod:`sosalgo.worstcase.polish`), its tau held at the
    reported ``tau`` first; None when it does not converge."""
    from sosalgo.worstcase.polish import polished

    return polished(data, ans, tau) if ans.status == "solved" else None


def _polish_tries(polish: SDPAnswer | None, toward: SDPAnswer, w: np.ndarray,
                  raw: bool) -> list[SDPAnswer]:
    """The polished answer's candidates: mixed toward ``toward`` (the interior
    certificate or this margin's answer) when its S is positive definite, at each floor
    of :data:`POLISH_FLOORS`; else, when ``raw``, as it is (rounding tau up may be all it
    needs: S's null space meets I0)."""
    if polish is None:
        return []
    if _min_eig(toward.S, w) > 0:
        return [_mixed(polish, toward, w, rel_floor) for rel_floor in POLISH_FLOORS]
    return [polish] if raw else []


def _prove_candidate(spec: Spec, kappa: float | None, mt: PEPFrame, data: PEPData,
                     cand: SDPAnswer, tau: float, eps: float, mterms: list[Term],
                     iterms: list[Term], ex: PEPFrame | None, units: list[int] | None,
                     cert: dict[str, Any]) -> bool:
    """Prove one candidate certificate exactly; ``cert`` updated (its ``proof``, and the
    proven bound when proven)."""
    from sosalgo.worstcase.exact import prove_certificate

    Sh = cand.S * np.outer(data.w, data.w)  # type: ignore[operator]
    if not units and np.linalg.eigvalsh(Sh)[0] < -1e-9 * max(1.0, float(np.abs(Sh).max())):
        cert["proof"] = {"proven": False, "tau_proven": None,
                         "detail": "floating-point pre-check: S is not PSD (scaled)"}
        return False  # the exact proof would fail: the next candidate
    # at least the reported tau (its float value, up to the solver's accuracy)
    proof = prove_certificate(spec, kappa, data.st, mterms, iterms,
                              max(cand.tau + cand.const, tau), cand.lam, data.w, ex,
                              units=units)
    if mt.bound is not None:  # what the proof is about (a mingrad measure's bound)
        proof["measure_bound"] = mt.bound
    cert["proof"] = proof
    if proof["proven"]:
        cert.update(check_kind="exact (rational and ball arithmetic)",
                    tau_proven=proof["tau_proven"], tau=cand.tau + cand.const,
                    margin=eps * tau)
    return bool(proof["proven"])


def _certificate(spec: Spec, kappa: float | None, mt: PEPFrame, data: PEPData,
                 ans: SDPAnswer, exact: bool, mterms: list[Term],
                 iterms: list[Term], ex: PEPFrame | None = None) -> dict[str, Any]:
    """The dual certificate (multipliers by pair, S, float checks), proven exactly when
    ``exact`` (the margin ladder :data:`MARGINS` then :data:`LONG_MARGINS`; only the
    latter past LONG; :func:`_ladder`)."""
    st = data.st
    tau = float(ans.primal)  # type: ignore[arg-type]
    scale = max(1.0, ans.size)  # tr H + sum F': the margin's units
    cert: dict[str, Any] = {"tau": ans.tau + ans.const, "check_kind": "floating-point check",
                            "tau_proven": None, "proof": None}
    best = ans
    raw: list[tuple[SDPAnswer, float]] = []  # the margin solves before any mixing
    units = _linear_only(data)
    # directions no form has a square of: S is 0 on their rows, never positive definite
    inner = (_interior_certificate(data, tau, scale) if exact and data.strong
             and units is None else None)
    polish = _polished(data, ans, tau) if exact and units is None else None
    polish_raw = True  # the polished answer as it is: tried once
    kept: tuple[dict[str, Any], SDPAnswer] | None = None  # a loose proof, while looking on
    extra = LOOSE_RUNGS
    # a span search's iterates are free points tied to the run by equalities only: the
    # proof makes their rows of S exactly zero and each value residual the solver left
    # without slack exactly zero, moving the multipliers by the solver's error; at default
    # tolerances (1e-8) that error exceeds every margin up to 1e-6 of tau (conjugate
    # gradient on quadratic growth, N = 12: only the margin 1e-5 proves, 6e-6 above tau),
    # at tight ones (1e-10) the margin 1e-8 proves, 1e-7 above it
    ladder = _ladder(st.steps, inner is not None, st.margin_seen)
    for rel, precise in ladder if exact else ():
        eps = rel / scale  # relative to tau: the measure is divided by tau
        cand = ans if rel == 0 else solve_pep(data, margin=eps, unit=tau if tau > 1e-200
                                              else 1.0, precise=precise)
        if cand.status == "unbounded":  # no certificate with this margin: none with the
            break  # larger ones either (the ladder's margins grow)
        if cand.status != "solved" or cand.tau + cand.const > 2 * abs(tau) + 1e-9:
            continue  # not solved, or "solved" at twice tau or more (a solver's bad answer)
        if rel > 0:
            raw.append((cand, eps))
        answer = cand
        tries = _polish_tries(polish, inner if inner is not None else cand, data.w,
                              polish_raw)
        polish_raw = False
        tries.append(cand if inner is None else _mixed(cand, inner, data.w))
        if kept is not None:  # a proof is at least its tau: none tighter than the kept one
            tries = [c for c in tries
                     if c.tau + c.const < float(Fraction(kept[0]["tau_proven"]))]
            if not tries:
                break
        for cand in tries:
            best = cand
            if _prove_candidate(spec, kappa, mt, data, cand, tau, eps, mterms, iterms, ex,
                                units, cert):
                break
        if cert.get("tau_proven"):
            if kept is None or _tighter(cert, kept[0]):
                kept = dict(cert), best
            if not _loose(cert, tau) or extra == 0 or _own_bound(cert, answer, best, tau):
                break
            extra -= 1  # a loose proof (a polished mix): the next rungs' own answers
            cert["tau_proven"], polish = None, None  # may prove tighter
    if kept is not None and (not cert.get("tau_proven") or _tighter(kept[0], cert)):
        cert.update(kept[0])
        best = kept[1]
    # the measure's own answer, then each margin solve as it came (S >= its margin but
    # on the free directions, which no margin and no mix with an interior certificate
    # can lift: their rows are made exactly zero)
    for cand, eps in [(ans, None), *raw]:
        # a margin's proof above tau by more than LOOSE_REL: the own answer's null rows
        # may prove tau itself (kept only when proven)
        again = eps is None and _loose(cert, tau)
        if exact and (again or not cert.get("tau_proven")) and cand.S is not None \
                and not st.free_values:
            _null_row_proof(spec, kappa, mt, data, cand, mterms, iterms, ex, cert,
                            tau if eps is None else max(cand.tau + cand.const, tau),
                            None if eps is None else 0.1 * eps)
    if exact and not cert.get("tau_proven") and ans.S is not None and mt.per_step is None:
        _field_proof(spec, kappa, mt, data, ans, mterms, iterms, cert, tau)
    if exact and not cert.get("tau_proven"):
        _centered_proof(spec, kappa, mt, data, ans, mterms, iterms, ex, cert, tau)
    lam = best.lam
    S = best.S
    assert lam is not None and S is not None
    top = float(lam.max(initial=0.0))
    cert["multipliers"] = {lab: float(v) for lab, v in zip(st.labels, lam, strict=True)
                           if v > 1e-12 * top}
    cert["basis"] = st.basis
    cert["slack"] = S.tolist()
    cert["min_eig_slack"] = float(np.linalg.eigvalsh(S)[0])
    cert["min_value_slack"] = float(value_residual(data, float(best.tau), lam).min(initial=0))
    return cert
