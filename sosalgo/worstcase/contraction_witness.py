"""The witness of the contraction measure (:mod:`sosalgo.worstcase.contraction`) and its check.

Two runs on quadratics f_j = (q_j/2) x^2 (one dimension), q_j just inside each class's
curvatures (or a few curvatures for a merely convex class), the first run at rest at 0,
the second from the top singular direction of the N-step map: a pair of real runs,
checked exactly (:func:`check_contraction_witness`: both runs recomputed from their starts
and answers, every answer its point's gradient, every class inequality between every
ordered pair of each function's points, in ball arithmetic), so its ratio is a lower
bound. The document has the second run's start ``xi0_second`` and answers
``calls_second``; its points are labelled with a prime.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.kernel.exact import fraction_str

__all__ = ["check_contraction_witness", "contraction_positions", "contraction_witness"]


INSIDE = 1e-6  # the curvatures' distance inside [lo, hi] (relative): strict inequalities
CONVEX_Q = (0.0, 1.0, 10.0, 100.0, 1e3, 1e4)  # tried for a convex class (times L)


def _curvature_choices(mt: Any) -> list[list[float]] | None:
    out = []
    for _, cls, params in mt.functions:
        cur = cls.curvatures({k: float(getattr(v, "c", v)) for k, v in params.items()})
        if cur is None:
            return None
        lo, hi = cur
        if cls.free_curvature:
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
    """The witness document of the contraction measure, unchecked (see the module); None
    when a class has no quadratic or the exact method is missing."""
    from itertools import product

    from sosalgo.kinds import WITNESS_KIND

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
                    pts.append({"label": _label(i, k, p) + tag, "g": [fraction_str(us[k][i])],
                                "h": fraction_str(qf[j] * y * y / 2), "x": [float(y)]})
        funcs[name] = {"class": cls.name, "params": {k: float(getattr(v, "c", v))
                                                     for k, v in params.items()},
                       "optimal_subgradient": ["0"],
                       "points": pts}
    doc = {"kind": WITNESS_KIND, "spec": spec.name, "kappa": res.kappa, "steps": N,
           "calls_per_step": p, "call_steps": N, "measure": res.measure,
           "initial": res.initial, "dimension": 1,
           "xi0": [["0"] for _ in range(mt.n)], "xi0_second": [[fraction_str(x)] for x in start],
           "calls": [[[fraction_str(u)] for u in row] for row in runs[0][1]],
           "calls_second": [[[fraction_str(u)] for u in row] for row in runs[1][1]],
           "functions": funcs, "evaluations": {}, "tau_float": res.tau,
           "iterates": _states(ex, start, runs[1][1], N)}
    return doc  # the caller checks it (:func:`sosalgo.worstcase.check.check_witness`)


def _states(steps: list[list[np.ndarray]], xi0: list[Fraction], us: list[list[Fraction]],
            N: int) -> list[list[float]]:
    """The second run's first state entry xi'_k[0], k = 0..N (floats; ``iterates``)."""
    xi = np.array([float(x) for x in xi0])
    out = [[float(xi[0])]]
    for k in range(N):
        A, B = (np.array([[float(_centre(v)) for v in row] for row in M])
                for M in steps[k][:2])
        xi = A @ xi + B @ np.array([float(v) for v in us[k]])
        out.append([float(xi[0])])
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


def _arb_mat(rows: Any) -> Any:
    from flint import arb_mat

    from sosalgo.worstcase.exact import ball

    vals = [[ball(v) for v in row] for row in rows]
    return arb_mat(len(vals), len(vals[0]) if vals else 0, [v for r in vals for v in r])


def contraction_positions(doc: dict[str, Any], av: Any) -> tuple[dict[str, Any], list[Any]]:
    """(label -> (point ball, answer text), [xi_0, ..., xi_N] of each run) of a contraction
    witness, recomputed from its starts and answers (arb, at the current precision);
    ValueError when its sizes are not the method's."""
    N, p = int(doc["steps"]), av.mt.p
    states, pos = [], {}
    if (int(doc["call_steps"]) != N or int(doc["dimension"]) != 1
            or int(doc["calls_per_step"]) != p):
        raise ValueError("call_steps, calls_per_step, dimension: expected N, p and 1")
    for key, calls, tag in (("xi0", "calls", ""), ("xi0_second", "calls_second", "'")):
        xi = _arb_mat(doc[key])
        if xi.nrows() != av.mt.n or xi.ncols() != 1 or len(doc[calls]) != N:
            raise ValueError(f"{key}, {calls}: expected {av.mt.n} states and {N} steps")
        run = [xi]
        for k in range(N):
            if len(doc[calls][k]) != p or any(len(u) != 1 for u in doc[calls][k]):
                raise ValueError(f"{calls}[{k}]: expected {p} answers of 1 coordinate")
            u = _arb_mat(doc[calls][k])
            A, B, C, D = av.step(k)
            y = C * xi + D * u
            for i in range(p):
                pos[_label(i, k, p) + tag] = (y[i, 0], doc[calls][k][i][0])
            xi = A * xi + B * u
            run.append(xi)
        states.append(run)
    return pos, states


def check_contraction_witness(doc: dict[str, Any], spec: Any, av: Any) -> dict[str, Any]:
    """Check a contraction witness against the exact method ``av`` (an ArbView): both runs
    recomputed from their starts and answers, every answer its point's gradient, every
    class inequality between every ordered pair of each function's points (both runs),
    in ball arithmetic; tau_N >= |xi_N - xi'_N|^2 / |xi_0 - xi'_0|^2."""
    import time

    from flint import arb

    from sosalgo.kernel.arb import arb_fraction
    from sosalgo.worstcase.exact import ball

    t0 = time.perf_counter()
    out: dict[str, Any] = {"verified": False, "check_kind": "exact (rational and ball "
                           "arithmetic)", "tau_lower": None, "tau_lower_float": None}
    mt = av.mt
    try:  # at the caller's precision (:data:`sosalgo.worstcase.check.PREC`)
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
        (s0, sN), (t0_, tN) = (states[0][0], states[0][-1]), (states[1][0], states[1][-1])
        for name, _, _ in mt.functions:
            if any(Fraction(v) != 0 for v in doc["functions"][name]["optimal_subgradient"]):
                raise ValueError(f"{name}: optimal_subgradient: no minimizer here (0)")
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
    return out | {"verified": True, "tau_lower": fraction_str(lower),
                  "tau_lower_float": float(lower),
                  "detail": f"{checked} conditions proven; both runs recomputed from their "
                            "starts and answers", "seconds": time.perf_counter() - t0}
