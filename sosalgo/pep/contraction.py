"""The two-trajectory contraction measure of the PEP (``--measure contraction``).

Two runs of the same method on the same functions, from two starts xi_0 and xi'_0
(anywhere): a proven bound on

    |xi_N - xi'_N|^2  when  |xi_0 - xi'_0|^2 <= 1,

the squared distance over every state block (for a one-state method, |x_N - x'_N|^2;
Douglas-Rachford: its state). No minimizer enters, and the bound is class-agnostic: it
uses each class's inequalities (:mod:`sosalgo.classes`) and nothing else, any number of
functions, proximal calls included.

The PEP is written on the differences of the runs: Delta xi_{k+1} = A Delta xi_k + B
Delta u_k, Delta y_k = C Delta xi_k + D Delta u_k (the method is linear), with basis the
start difference (``dxi0_<a>``, n vectors) and each call's answer difference
(``du_<call>``). Each call's two points (y, g) and (y', g') of function j must admit
values: for two points, alpha (F_a - F_b) + Q_ab >= 0 and alpha (F_b - F_a) + Q_ba >= 0
have a solution iff alpha_r' Q^r_ab + alpha_r Q^r'_ba >= 0 (every pair of inequalities
r, r' with alpha > 0; Q^r >= 0 both ways when alpha_r = 0), and these forms depend on
the differences alone (the classes are invariant under adding a linear function). They
are the PEP's rows (``contraction:<call>#r,r'``, extra constraints without values,
:mod:`sosalgo.pep.inexact`).

This keeps the conditions between the two points of the same call and drops those
between different calls: an upper bound of the PEP over the union of both runs' points
(a relaxation), equal to it for one step, and at N steps the product of the one-step
factors (tight wherever the worst case compounds step by step: gradient descent,
max(|1 - gamma m|, |1 - gamma L|)^(2N); Douglas-Rachford, PEPit's
``douglas_rachford_splitting_contraction``). Over the union, the dual's S vanishes on
every pair of identical runs (their measure and start distance are 0): no certificate
there can be proven positive definite.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.errors import InputError

__all__ = ["KIND", "build_contraction", "check_contraction_witness", "contraction_positions",
           "contraction_witness", "is_contraction"]

KIND = "contraction"


def is_contraction(measure: Any, initial: Any) -> bool:
    """Whether the terms ask the contraction measure (InputError when only one side, or
    with other terms)."""
    m = [t.kind == KIND for t in measure]
    i = [t.kind == KIND for t in initial]
    if not any(m) and not any(i):
        return False
    if not (len(m) == 1 and m[0] and len(i) == 1 and i[0]):
        which = "--measure" if not (len(m) == 1 and m[0]) else "--initial"
        raise InputError(f"{which}: contraction: the measure and the initial condition are "
                         "both contraction alone (|xi_N - xi'_N|^2 against |xi_0 - "
                         "xi'_0|^2)")
    return True


def build_contraction(mt: Any, steps: int, measure: Any, initial: Any) -> Any:
    """The PEP structure of the contraction measure (see the module)."""
    from sosalgo.pep.structure import PEPStructure, _call_label, _obj_eye

    if mt.errors or mt.line_search or mt.per_step is not None or mt.G0 is not None:
        raise InputError("--measure: contraction: not with inexact calls, a line search, a "
                         "method that changes with k or an initial_state")
    n, p = mt.n, mt.p
    d = n + p * steps
    eye = np.eye(d) if not mt.exact else _obj_eye(d)
    cols = [f"dxi0_{a + 1}" for a in range(n)]
    cols += [f"du_{_call_label(i, k, p)}" for k in range(steps) for i in range(p)]
    xi, Y, U = [eye[:n]], [], []
    for k in range(steps):
        u = eye[n + p * k: n + p * (k + 1)]
        U.append(u)
        Y.append(mt.C @ xi[k] + mt.s * (mt.D @ u))
        xi.append(mt.A @ xi[k] + mt.s * (mt.B @ u))
    zero = eye[0] * 0
    extras = []
    for k in range(steps):
        for i, j in enumerate(mt.oracles):
            X = np.vstack([Y[k][i], zero, U[k][i] * mt.s, zero])
            for tag, Qc in _two_point_forms(mt.ineqs[j]):
                extras.append((f"contraction:{_call_label(i, k, p)}{tag}", X, Qc))
    cm, ci = mt.coef(measure[0]), mt.coef(initial[0])
    meas = sum(np.outer(row, row) for row in xi[steps]) * cm
    init = sum(np.outer(eye[a], eye[a]) for a in range(n)) * ci
    dt = object if mt.exact else float
    out = (mt.E @ xi[steps])[0] if mt.E is not None else Y[-1][mt.output]
    return PEPStructure(steps, steps, cols, [[] for _ in mt.functions], 0, [],
                        [lab for lab, _, _ in extras], meas, np.zeros(0, dtype=dt), init,
                        np.zeros(0, dtype=dt), {"xi": xi, "y": Y, "u": U, "x": out}, {},
                        True, extras=extras)


def _two_point_forms(ineqs: list[tuple[Any, np.ndarray]]) -> list[tuple[str, np.ndarray]]:
    """(tag, Qc) on X = (x_a - x_b, 0, g_a - g_b, 0): the conditions under which two points
    admit values (see the module): alpha_r' Q^r_ab + alpha_r Q^r'_ba >= 0 for alpha_r,
    alpha_r' > 0; Q^r_ab >= 0 and Q^r_ba >= 0 for alpha_r = 0 (a negative alpha is read
    with the points swapped)."""
    swap = [1, 0, 3, 2]  # Q_ba: the same form with the points exchanged
    out = []
    pos = [(r, a, Q) for r, (a, Q) in enumerate(ineqs) if _sign(a) != 0]
    for r, a, Q in pos:
        for r2, a2, Q2 in pos:
            if not (_sign(a) > 0 and _sign(a2) > 0):
                raise InputError("--measure: contraction: a class inequality with a "
                                 "negative value coefficient")
            Qs = np.asarray(Q2)[np.ix_(swap, swap)]
            out.append((f"#{r},{r2}", np.asarray(Q) * a2 + Qs * a))
    for r, (a, Q) in enumerate(ineqs):
        if _sign(a) == 0:
            Q = np.asarray(Q)
            out += [(f"#{r}", Q), (f"#{r}'", Q[np.ix_(swap, swap)])]
    return out


def _sign(a: Any) -> float:
    """The sign of a value coefficient (a float, a rational, or an exact ball's centre:
    the classes' coefficients are exact rationals or 0)."""
    return float(np.sign(float(getattr(a, "c", a))))


# --------------------------------------------------------------------------- the witness
# Two runs on quadratics f_j = (q_j/2) x^2 (one dimension), q_j just inside each class's
# curvatures (or a few convex curvatures for a merely convex class), the first run at
# rest at 0, the second from the top singular direction of the N-step map: a pair of real
# runs, checked exactly (:func:`check_contraction_witness`), so its ratio is a lower bound.

INSIDE = 1e-6  # the curvatures' distance inside [lo, hi] (relative): strict inequalities
CONVEX_Q = (0.0, 1.0, 10.0, 100.0, 1e3, 1e4)  # tried for a convex class (times L)


def _curvature_choices(mt: Any) -> list[list[float]] | None:
    out = []
    for _, cls, params in mt.functions:
        cur = cls.curvatures({k: float(getattr(v, "c", v)) for k, v in params.items()})
        if cur is None:
            return None
        lo, hi = cur
        if cls.name == "convex":
            out.append([q * float(mt.s) for q in CONVEX_Q])
        elif hi > lo:
            out.append([lo + INSIDE * (hi - lo), hi - INSIDE * (hi - lo)])
        else:
            out.append([lo])
    return out


def _float_map(A, B, C, D, q: np.ndarray) -> np.ndarray | None:
    """The state map of the method on the quadratics (u = Q y): A + B (I - Q D)^-1 Q C."""
    Q = np.diag(q)
    try:
        return A + B @ np.linalg.solve(np.eye(len(q)) - Q @ D, Q @ C)
    except np.linalg.LinAlgError:
        return None


def contraction_witness(spec: Any, kappa: Any, mt: Any, res: Any, exact_mt: Any
                        ) -> dict[str, Any] | None:
    """The witness of the contraction measure (see above), None when a class has no
    quadratic or the exact method is missing."""
    from itertools import product

    from sosalgo.kinds import WITNESS_KIND
    from sosalgo.pep.check import arb_view, q_str

    choices = None if exact_mt is None else _curvature_choices(mt)
    if choices is None:
        return None
    A, B, C, D = (np.asarray(M, float) for M in (mt.A, mt.B, mt.C, mt.D))
    N, p = res.steps, mt.p
    best = None
    for qs in product(*choices):
        q = np.array([qs[j] for j in mt.oracles])
        T = _float_map(A, B, C, D, q)
        if T is None:
            continue
        _, sv, vt = np.linalg.svd(np.linalg.matrix_power(T, N))
        if best is None or sv[0] > best[0]:
            best = (sv[0], qs, vt[0])
    if best is None:
        return None
    _, qs, v = best
    qf = [Fraction(x).limit_denominator(10 ** 9) for x in qs]
    start = [Fraction(float(x)).limit_denominator(10 ** 12) for x in v]
    ex = [[np.asarray(M, dtype=object) for M in exact_mt.step(k)] for k in range(N)]
    runs = [_exact_run(ex, [Fraction(0)] * mt.n, qf, mt.oracles, N),
            _exact_run(ex, start, qf, mt.oracles, N)]
    funcs: dict[str, Any] = {}
    for j, (name, cls, params) in enumerate(mt.functions):
        pts = []
        for (ys, us), tag in zip(runs, ("", "'"), strict=True):
            for k in range(N):
                for i in (i for i in range(p) if mt.oracles[i] == j):
                    y = ys[k][i]
                    pts.append({"label": _label(i, k, p) + tag, "g": [q_str(us[k][i])],
                                "h": q_str(qf[j] * y * y / 2), "x": [float(y)]})
        funcs[name] = {"class": cls.name, "params": {k: float(getattr(v, "c", v))
                                                     for k, v in params.items()},
                       "curvature": q_str(qf[j]), "optimal_subgradient": ["0"],
                       "points": pts}
    doc = {"kind": WITNESS_KIND, "spec": spec.name, "kappa": res.kappa, "steps": N,
           "calls_per_step": p, "call_steps": N, "measure": res.measure,
           "initial": res.initial, "dimension": 1,
           "xi0": [["0"] for _ in range(mt.n)], "xi0_second": [[q_str(x)] for x in start],
           "calls": [[[q_str(u)] for u in row] for row in runs[0][1]],
           "calls_second": [[[q_str(u)] for u in row] for row in runs[1][1]],
           "functions": funcs, "evaluations": {}, "tau_float": res.tau,
           "iterates": _iterates(ex, start, runs[1][1], mt, N)}
    doc["check"] = check_contraction_witness(doc, spec, arb_view(exact_mt))
    from sosalgo.pep.witness import _finish

    return _finish(doc, spec, kappa, None, res)


def _iterates(steps: list[list[np.ndarray]], xi0: list[Fraction], us: list[list[Fraction]],
              mt: Any, N: int) -> list[list[float]]:
    """The second run's outputs x_0 .. x_N (floats): E xi_k, or the output call's point."""
    xi = np.array([float(x) for x in xi0])
    out = []
    for k in range(N + 1):
        A, B, C, D = (np.array([[float(_centre(v)) for v in row] for row in M])
                      for M in steps[min(k, N - 1)])
        if k < N:
            u = np.array([float(v) for v in us[k]])
            x = (np.array([float(_centre(v)) for v in mt.E[0]]) @ xi if mt.E is not None
                 else (C @ xi + D @ u)[mt.output])
            xi = A @ xi + B @ u
        else:
            x = (np.array([float(_centre(v)) for v in mt.E[0]]) @ xi if mt.E is not None
                 else float("nan"))
        out.append([float(x)])
    return out


def _label(i: int, k: int, p: int) -> str:
    return f"y{k}" if p == 1 else f"y{i + 1}_{k}"


def _centre(v: Any) -> Fraction:
    return Fraction(getattr(v, "c", v))


def _exact_run(steps: list[list[np.ndarray]], xi0: list[Fraction], q: list[Fraction],
               oracles: tuple[int, ...], N: int) -> tuple[list[list[Fraction]],
                                                          list[list[Fraction]]]:
    """(points, answers) of a run on the quadratics: each answer the rational u_i = q y_i
    of the point solved in floating point (rounded), the points then exact (centres)."""
    xi = list(xi0)
    ys, us = [], []
    for k in range(N):
        A, B, C, D = steps[k]
        p = C.shape[0]
        Cf = np.array([[float(_centre(v)) for v in row] for row in C])
        Df = np.array([[float(_centre(v)) for v in row] for row in D])
        qd = np.array([float(q[j]) for j in oracles])
        yf = np.linalg.solve(np.eye(p) - Df * qd, Cf @ np.array([float(x) for x in xi]))
        u = [Fraction(float(qd[i] * yf[i])).limit_denominator(10 ** 15) for i in range(p)]
        y = [sum((_centre(C[i][a]) * xi[a] for a in range(len(xi))), Fraction(0))
             + sum((_centre(D[i][b]) * u[b] for b in range(p)), Fraction(0))
             for i in range(p)]
        ys.append(y)
        us.append(u)
        xi = [sum((_centre(A[a][c]) * xi[c] for c in range(len(xi))), Fraction(0))
              + sum((_centre(B[a][b]) * u[b] for b in range(p)), Fraction(0))
              for a in range(len(xi))]
    return ys, us


def contraction_positions(doc: dict[str, Any], av: Any) -> tuple[dict[str, Any], list[Any]]:
    """(label -> (point ball, answer text), [(xi_0, xi_N)] of each run) of a contraction
    witness, recomputed from its starts and answers (arb, at the current precision)."""
    from sosalgo.pep.check import _mat

    N, p = int(doc["steps"]), av.mt.p
    states, pos = [], {}
    for key, calls, tag in (("xi0", "calls", ""), ("xi0_second", "calls_second", "'")):
        xi = _mat(doc[key])
        if xi.nrows() != av.mt.n or xi.ncols() != 1 or len(doc[calls]) != N:
            raise ValueError(f"{key}, {calls}: expected {av.mt.n} states and {N} steps")
        for k in range(N):
            u = _mat(doc[calls][k])
            A, B, C, D = av.step(k)
            y = C * xi + D * u
            for i in range(p):
                pos[_label(i, k, p) + tag] = (y[i, 0], doc[calls][k][i][0])
            xi = A * xi + B * u
        states.append((_mat(doc[key]), xi))
    return pos, states


def check_contraction_witness(doc: dict[str, Any], spec: Any, av: Any) -> dict[str, Any]:
    """Check a contraction witness against the exact method ``av`` (an ArbView): both runs
    recomputed from their starts and answers, every answer its point's gradient, every
    class inequality between every ordered pair of each function's points (both runs),
    in ball arithmetic; tau_N >= |xi_N - xi'_N|^2 / |xi_0 - xi'_0|^2."""
    import time

    from flint import arb

    from sosalgo.kernel.arb import arb_fraction, precision
    from sosalgo.pep.check import PREC, q_str
    from sosalgo.pep.exact import ball

    t0 = time.perf_counter()
    out: dict[str, Any] = {"verified": False, "check_kind": "exact (rational and ball "
                           "arithmetic)", "tau_lower": None, "tau_lower_float": None}
    mt = av.mt
    try:
        with precision(PREC):
            pos, states = contraction_positions(doc, av)
            checked = bad = 0
            for j, (name, _, _) in enumerate(mt.functions):
                pts = doc["functions"][name]["points"]
                for pt in pts:
                    checked += 1
                    bad += Fraction(pos[pt["label"]][1]) != Fraction(pt["g"][0])
                data = [(pos[pt["label"]][0], ball(pt["g"][0]), ball(pt["h"])) for pt in pts]
                for a, (xa, ga, ha) in enumerate(data):
                    for b, (xb, gb, hb) in enumerate(data):
                        if a == b:
                            continue
                        for alpha, Q in av.ineqs[j]:
                            X = (xa, xb, ga, gb)
                            q = sum((Q[r][c] * X[r] * X[c] for r in range(4) for c in range(4)
                                     if not Q[r][c].is_zero()), arb(0))
                            checked += 1
                            bad += not (alpha * (ha - hb) + q >= 0)
            (s0, sN), (t0_, tN) = states
            meas = sum(((sN[a, 0] - tN[a, 0]) * (sN[a, 0] - tN[a, 0]) for a in range(mt.n)),
                       arb(0))
            init = sum(((s0[a, 0] - t0_[a, 0]) * (s0[a, 0] - t0_[a, 0]) for a in range(mt.n)),
                       arb(0))
    except (KeyError, ValueError, TypeError, IndexError, ZeroDivisionError,
            ArithmeticError) as exc:
        return out | {"detail": f"malformed or inconsistent witness: {type(exc).__name__}: "
                                f"{exc}", "seconds": time.perf_counter() - t0}
    out["pairs_checked"] = checked
    if bad or not init > 0:
        why = f"{bad} conditions not proven" if bad else "the starts coincide"
        return out | {"detail": why, "seconds": time.perf_counter() - t0}
    lower = arb_fraction(meas.lower()) / arb_fraction(init.upper())
    return out | {"verified": True, "tau_lower": q_str(lower), "tau_lower_float": float(lower),
                  "detail": f"{checked} conditions proven; both runs recomputed from their "
                            "starts and answers", "seconds": time.perf_counter() - t0}
