"""Non-convergence witnesses: cycles of length K <= 8, checked exactly.

When no rate is certified, :func:`find_cycle` looks for a periodic trajectory of the
method on functions of its classes (Goujaud, Taylor, Dieuleveut, "Counter-examples in
first-order optimization: a constructive approach", 2023): a Gram SDP per length K
(:mod:`sosalgo.witnesses.search`), rounded to integer coordinates in the smallest
dimension that passes, made exact through the method's exact matrices, and checked by
:func:`sosalgo.witnesses.trajectory.check` (recursion, every interpolation inequality of
every class with exact parameters, an output point other than x*). A candidate that does
not pass is dropped: only checked cycles are returned.

A cycle proves non-convergence when the minimizer is unique: some function of the sum
must have a quadratic lower curvature > 0 (strongly convex); otherwise nothing is searched.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.verify.exact import Ball
from sosalgo.witnesses.balls import ball_str, exact
from sosalgo.witnesses.search import gram_search, rounded_factors
from sosalgo.witnesses.trajectory import build_layout, check

__all__ = ["MAX_LENGTH", "CYCLE_SECONDS", "Context", "check_cycle", "context", "find_cycle",
           "search_trajectory"]

MAX_LENGTH = 8
CYCLE_SECONDS = 5.0  # default time budget of a search (one analysis row)
SCALES = (2**4, 2**8, 2**12, 2**18, 2**26)  # integer coordinates up to this size
EXACT_NOTE = "exact rational arithmetic"
BALL_NOTE = ("outward-rounded balls: the method's matrices are irrational here; the "
             "trajectory is the real one through these integer coordinates")


@dataclass
class Context:
    """A method at one kappa: float (search) and exact (check) matrices, class data."""

    om: Any  # OracleMethod
    ex: Any  # ExactOracleMethod
    fl: dict[str, np.ndarray]
    balls: dict[str, np.ndarray]
    ineqs: list[list[tuple[Ball, Any]]]
    class_data: str

    @property
    def exact(self) -> bool:
        return all(exact(v) for v in self.balls.values())


def _rows(A, B, C, D, E, output, balls: bool) -> dict[str, np.ndarray]:
    p = B.shape[1]
    if output is None:
        erow = E[0]
        drow = np.full(p, Ball(0), dtype=object) if balls else np.zeros(p)
    else:
        erow, drow = C[output], D[output]
    return {"A": A, "B": B, "C": C, "D": D, "erow": erow, "drow": drow}


def context(spec: Any, kappa: float, theta: Mapping[str, float] | None = None) -> Context:
    """The method of ``spec`` at ``kappa`` in floats and exact balls (ValueError, ModelError
    when it cannot be built)."""
    from sosalgo.certificates.exact_composite import exact_class_inequalities, exact_oracle_method
    from sosalgo.model import evaluate_algorithm
    from sosalgo.oracles import as_oracle_method

    om = as_oracle_method(evaluate_algorithm(spec, kappa, theta))
    ex = exact_oracle_method(spec, kappa, theta)
    fl = _rows(om.A, om.B, om.C, om.D, om.E, om.output, False)
    bl = _rows(ex.A, ex.B, ex.C, ex.D, ex.E, ex.output, True)
    ineqs, notes = [], set()
    for _, cls, params in ex.functions:
        rows, note = exact_class_inequalities(cls, params)
        ineqs.append(rows)
        notes.add(note)
    return Context(om, ex, fl, bl, ineqs, ", ".join(sorted(notes)))


def _strongly_convex(om: Any) -> bool:
    """Whether some function's class makes it strongly convex (a positive modulus)."""
    return any(fn.cls.strong_convexity(fn.params) > 0 for fn in om.functions)


def search_trajectory(ctx: Context, K: int, s: Fraction, deadline: float
                      ) -> dict[str, Any] | None:
    """A checked trajectory with xi_K = s xi_0 (balls), or None."""
    lay = build_layout(ctx.fl, K, float(s))
    if lay is None or time.perf_counter() > deadline:
        return None
    found = gram_search(lay, ctx.om, K * ctx.om.p)
    if found is None:
        return None
    exl = build_layout(ctx.balls, K, s, piv=lay.piv)
    if exl is None:
        return None
    H, vals = found
    for d, V, vq in rounded_factors(H, vals, range(1, lay.r + 1), SCALES):
        if time.perf_counter() > deadline:
            return None
        traj = {"s": s, "values": vq, "dimension": d,
                **{key: [rows @ V for rows in getattr(exl, key)]
                   for key in ("xi", "u", "y", "out")}}
        ok, _ = check(ctx.ex, traj, ctx.ineqs)
        if ok:
            return traj
    return None


def find_cycle(spec: Any, kappa: float, theta: Mapping[str, float] | None = None,
               max_length: int = MAX_LENGTH, seconds: float = CYCLE_SECONDS,
               ctx: Context | None = None) -> dict[str, Any] | None:
    """The shortest checked cycle found (K = 2..max_length, within ``seconds``) as its
    JSON form (:func:`cycle_json`), or None."""
    ctx = ctx or context(spec, kappa, theta)
    if not _strongly_convex(ctx.om):
        return None
    deadline = time.perf_counter() + seconds
    for K in range(2, max_length + 1):
        traj = search_trajectory(ctx, K, Fraction(1), deadline)
        if traj is not None:
            return trajectory_json(ctx, traj)
        if time.perf_counter() > deadline:
            break
    return None


def _vec(v: Any) -> list[str]:
    return [ball_str(b) for b in v]


def trajectory_json(ctx: Context, traj: dict[str, Any]) -> dict[str, Any]:
    """The JSON form: ``length``, ``points``, ``gradients``, ``values`` (call points in the
    order step, call: entry k p + i is call i + 1 at step k), ``states`` xi_k,
    ``outputs`` x_k, ``calls``, ``dimension``, ``factor`` s, the optimum x* = 0 (every
    function minimized there, value 0), and how it was checked."""
    om, K = ctx.om, len(traj["u"])
    names = [fn.name for fn in om.functions]
    d = traj["dimension"]
    doc = {
        "length": K,
        "points": [_vec(traj["y"][k][i]) for k in range(K) for i in range(om.p)],
        "gradients": [_vec(traj["u"][k][i]) for k in range(K) for i in range(om.p)],
        "values": [str(v) for v in traj["values"]],
        "states": [[_vec(row) for row in traj["xi"][k]] for k in range(K)],
        "outputs": [_vec(traj["out"][k]) for k in range(K)],
        "calls": [{"step": k, "call": i + 1, "function": names[om.oracles[i]]}
                  for k in range(K) for i in range(om.p)],
        "dimension": d,
        "factor": str(traj["s"]),
        "optimum": {"point": ["0"] * d, "gradient": ["0"] * d, "value": "0"},
    }
    # exact: a rational method and every number a plain rational (no ball left by rounding)
    numbers = [v for key in ("points", "gradients", "outputs") for row in doc[key] for v in row]
    numbers += [v for x in doc["states"] for row in x for v in row] + doc["values"]
    ok = ctx.exact and not any("+-" in v for v in numbers)
    return doc | {"exact": ok, "checked": True,
                  "check": (EXACT_NOTE if ok else BALL_NOTE)
                  + f"; class data: {ctx.class_data}"}


def _parse(v: str) -> Ball:
    if "+-" in v:
        c, r = v.split("+-")
        return Ball(Fraction(c.strip()), Fraction(r.strip()))
    return Ball(Fraction(v))


def check_cycle(spec: Any, kappa: float, cycle: Mapping[str, Any],
                theta: Mapping[str, float] | None = None) -> tuple[bool, str]:
    """Re-check a cycle's JSON form from scratch (exact numbers only): the recursion with
    the method's exact matrices, every interpolation inequality, an output point other
    than x*. Returns (passed, reason)."""
    ctx = context(spec, kappa, theta)
    if not ctx.exact or not cycle.get("exact"):
        return False, "only exact (rational) cycles can be re-checked from their JSON"
    K, p = int(cycle["length"]), ctx.om.p

    def arr(rows: Any) -> np.ndarray:
        return np.array([[_parse(v) for v in row] for row in rows], dtype=object)

    try:
        pts = arr(cycle["points"])
        grads = arr(cycle["gradients"])
        traj = {"s": Fraction(cycle.get("factor", "1")),
                "values": [Fraction(v) for v in cycle["values"]],
                "xi": [arr(x) for x in cycle["states"]],
                "y": [pts[k * p:(k + 1) * p] for k in range(K)],
                "u": [grads[k * p:(k + 1) * p] for k in range(K)],
                "out": [arr([o])[0] for o in cycle["outputs"]]}
        if len(traj["values"]) != K * p or len(traj["xi"]) != K:
            return False, "wrong sizes"
        return check(ctx.ex, traj, ctx.ineqs)
    except (ValueError, ZeroDivisionError, IndexError, KeyError, TypeError) as exc:
        return False, f"malformed cycle: {exc}"
