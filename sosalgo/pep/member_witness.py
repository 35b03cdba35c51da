"""Witnesses that are explicit members of the classes: one quadratic f_j = q_j/2 |x|^2
per function (for an operator class, the linear operator q_j I), each least at x* = 0.

A class with Gram-level conditions (:mod:`sosalgo.pep.blocks`) has equalities among its
pairwise conditions (symmetry, the values of a quadratic), which no rounded trajectory
meets exactly. Its witness is therefore not a list of points checked against the
pairwise inequalities but the functions themselves: the document's ``members`` gives each
q_j (a rational), and the check (:func:`member_measure`) trusts nothing else than the
spec and x_0:

- every q_j lies in its class's exact curvature interval
  (:meth:`~sosalgo.classes.base.FunctionClass.exact_curvatures`, from rational bounds of
  the exact parameters): q_j/2 |x|^2 is a member;
- x* = 0 solves the problem (every f_j is least there: the optimal subgradients are 0);
- the run of the method on those functions is recomputed from x_0 in ball arithmetic
  (each call's answer q_j y, a proximal call solved from (I - D q) y = C xi), and the
  measure and the initial condition evaluated on it.

So the measure over the initial condition is a proven lower bound of the worst case.
The candidates scan each class's interval (its ends included: no inequality is checked
with a slack) and keep the largest proven ratio.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np
from flint import arb, arb_mat

from sosalgo.pep.structure import Method

__all__ = ["member_interval", "member_measure", "member_witness"]

MEMBER_AT = np.linspace(0.0, 1.0, 201)  # positions in each class's interval
MEMBER_TRIES = 3  # the best ones checked exactly


def member_interval(cls: Any, params: dict[str, Any]) -> tuple[Fraction, Fraction] | None:
    """The class's exact curvature interval at exact parameters (balls or rationals)."""
    from sosalgo.kernel.exact import Ball

    def lower(name: str) -> Fraction:
        b = Ball.of(params[name])
        return b.c - b.r

    def upper(name: str) -> Fraction:
        b = Ball.of(params[name])
        return b.c + b.r

    return cls.exact_curvatures(lower, upper)


def _member_curvatures(exact_mt: Method, at: float) -> list[Fraction] | None:
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


def member_witness(spec: Any, mt: Method, st: Any, ex: Any, exact_mt: Method | None,
                   solved: tuple[float, Any]) -> dict[str, Any] | None:
    """The witness of explicit quadratics with the largest proven measure / initial
    among the :data:`MEMBER_TRIES` best of :data:`MEMBER_AT` (floating point first);
    None when none is proven."""
    from sosalgo.pep.check import check_witness, q_str, set_quadratic_calls
    from sosalgo.pep.witness import _document, quadratic_point

    tau, res = solved
    if ex is None or exact_mt is None or mt.G0 is not None or mt.line_search:
        return None
    scored = []
    for at in MEMBER_AT:
        q = _member_curvatures(exact_mt, float(at))
        if q is None:
            return None
        qf = [float(v) for v in q]
        v = quadratic_point(mt, st, curvatures=qf)
        if v is None:
            continue
        ratio = _member_ratio(mt, st, v, qf)
        if ratio is not None:
            scored.append((ratio, q, v))
    scored.sort(key=lambda e: -e[0])
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


def _member_ratio(mt: Method, st: Any, v: np.ndarray, q: list[float]) -> float | None:
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


def member_measure(doc: dict[str, Any], av: Any, mterms: list[Any], iterms: list[Any]
                   ) -> tuple[arb, arb]:
    """(measure, initial) of the explicit members' run (see the module); ValueError when
    a member is not in its class or the document is not such a witness."""
    from sosalgo.pep.check import _start, _terms_value, positions
    from sosalgo.pep.exact import ball

    mt = av.mt
    if av.G0 is not None or mt.line_search or doc.get("xi0") is not None:
        raise ValueError("members: a run from x_0 without an initial gradient or line "
                         "search")
    q = []
    for name, cls, params in mt.functions:
        qj = Fraction(doc["members"][name])
        iv = member_interval(cls, params)
        if iv is None or not iv[0] <= qj <= iv[1]:
            raise ValueError(f"members: {name}: {qj} is outside the curvatures of "
                             f"{cls.name} at these parameters")
        if any(Fraction(v) != 0 for v in doc["functions"][name]["optimal_subgradient"]):
            raise ValueError(f"members: {name}: its optimal subgradient must be 0")
        q.append(qj)
    r, p, N = int(doc["dimension"]), mt.p, int(doc["steps"])
    Qs, eye = arb_mat(p, p), arb_mat(p, p)
    for i, j in enumerate(mt.oracles):
        Qs[i, i], eye[i, i] = ball(q[j]), arb(1)
    xi, calls = _start(doc, av, r), []
    for k in range(int(doc["call_steps"])):
        A, B, C, D = av.step(k)
        y = (eye - D * Qs).solve(C * xi)
        u = Qs * y
        calls.append([[u[i, c] for c in range(r)] for i in range(p)])
        if k < N:
            xi = A * xi + B * u
    run = dict(doc, calls=calls)
    pos = positions(run, av)
    funcs = {}
    for j, (name, _, _) in enumerate(mt.functions):
        qb = ball(q[j])
        pts = []
        for pt in doc["functions"][name]["points"]:
            x = pos[pt["label"]]
            pts.append({"label": pt["label"], "g": [qb * v for v in x],
                        "h": qb * sum((v * v for v in x), arb(0)) / 2})
        funcs[name] = {"points": pts}
    run["functions"] = funcs
    return _terms_value(mterms, run, av, pos), _terms_value(iterms, run, av, pos)
