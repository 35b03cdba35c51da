"""``sosalgo design`` on a sublinear spec (``m: 0``): minimize the certified constant c.

The objective at theta is the constant certified by :func:`sosalgo.analysis.analyze_sublinear`
(inf where none is): a grid over the box of the free parameters, then Nelder–Mead from the
best points, within the time limit. The reported constant is the certified one at the
reported theta (an upper bound on the best c over the box); there is no box-wide lower
bound for sublinear potentials (``bound_status: unsupported``).

The reported point is the best one whose certificate the exact proof
(:func:`sosalgo.certificates.exact_sublinear.verify_exact_sublinear`, what ``--verify``
and ``sosalgo verify`` run) accepts, among the :data:`PROVEN_CANDIDATES` best points of the
search: near a box's edge the solver's certificate of the very best point may be too
inaccurate to prove (the proximal point at alpha near 10), and a design claims only what
can be proven. When none of them is proven, the best point is reported as it is (its
verification then fails, and says so).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from sosalgo.spec import Spec

__all__ = ["sublinear_design"]

PROVEN_CANDIDATES = 4  # the best points of the search whose exact proof is tried, in order


class _Objective:
    """Certified c at theta (cached), counting evaluations, honouring a deadline: no
    evaluation starts unless 1.5 times the slowest one so far (the first, which pays for
    the imports, excepted) still fits before it."""

    def __init__(self, spec: Spec, names: list[str], deadline: float):
        self.spec, self.names, self.deadline = spec, names, deadline
        self.cache: dict[tuple[float, ...], Any] = {}
        self.slowest = 0.0

    def result(self, point: Sequence[float]) -> Any:
        from sosalgo.analysis import analyze_sublinear
        from sosalgo.model import ModelError

        key = tuple(float(v) for v in point)
        if key not in self.cache:
            t0 = time.monotonic()
            if t0 + 1.5 * self.slowest > self.deadline:
                raise TimeoutError
            try:
                self.cache[key] = analyze_sublinear(self.spec, dict(zip(self.names, key,
                                                                        strict=True)))
            except ModelError:
                self.cache[key] = None  # no fixed point or a domain error there
            if len(self.cache) > 1:
                self.slowest = max(self.slowest, time.monotonic() - t0)
        return self.cache[key]

    def __call__(self, point: Sequence[float]) -> float:
        if time.monotonic() > self.deadline:
            raise TimeoutError
        res = self.result(point)
        return math.inf if res is None or res.constant is None else float(res.constant)


def _box(spec: Spec, names: list[str]) -> list[tuple[float, float]]:
    from sosalgo.model import parameter_box

    return parameter_box(spec, math.nan, names)


def _polish(obj: _Objective, start: tuple[float, ...], box: list[tuple[float, float]]) -> None:
    from scipy.optimize import minimize

    lo, hi = np.array([b[0] for b in box]), np.array([b[1] for b in box])

    def clipped(z: np.ndarray) -> float:
        return obj(tuple(np.clip(z, lo, hi)))

    try:
        minimize(clipped, np.array(start), method="Nelder-Mead",
                 options={"xatol": 1e-6 * max(1.0, float(np.abs(hi - lo).max())),
                          "fatol": 1e-7, "maxfev": 200,
                          "initial_simplex": _simplex(start, lo, hi)})
    except TimeoutError:
        pass


def _simplex(start: tuple[float, ...], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    x0 = np.array(start)
    rows = [x0]
    for i in range(len(x0)):
        step = 0.05 * (hi[i] - lo[i]) or 0.05
        e = x0.copy()
        e[i] = e[i] + step if e[i] + step <= hi[i] else e[i] - step
        rows.append(e)
    return np.array(rows)


def sublinear_design(spec: Spec, names: list[str], time_limit: float = 120.0,
                     points: int = 9) -> dict[str, Any]:
    """Minimize the certified constant over the box of ``names`` (module docstring);
    returns the design row (``rate_type: sublinear``, ``constant``, ``theta``, ...)."""
    start = time.monotonic()
    # the search leaves a tenth of the time to the exact proofs of its best points
    obj = _Objective(spec, names, start + 0.9 * time_limit)
    box = _box(spec, names)
    axes = [np.linspace(lo, hi, points)[1:-1] if hi > lo else np.array([lo])
            for lo, hi in box]
    timed_out = False
    try:
        for pt in itertools.product(*axes):
            obj(pt)
        ranked = sorted((k for k in obj.cache if obj(k) < math.inf), key=obj)
        for pt in ranked[:2]:
            _polish(obj, pt, box)
    except TimeoutError:
        timed_out = True
    done = {k: r for k, r in obj.cache.items() if r is not None and r.constant is not None}
    best, res = _proven_best(spec, names, done, start + time_limit)
    return _row(spec, names, box, best, res, len(obj.cache), time.monotonic() - start,
                time_limit, timed_out)


def _proven(spec: Spec, theta: dict[str, float], res: Any) -> bool:
    """Whether the exact proof accepts ``res``'s certificate at ``theta``, as a document
    stores it (what ``--verify`` and ``sosalgo verify`` run)."""
    import json

    from sosalgo.certificates.exact_sublinear import verify_exact_sublinear
    from sosalgo.kernel.exact import Verdict

    row = json.loads(json.dumps(res.to_dict()))
    return verify_exact_sublinear(spec, row, theta).verified == Verdict.EXACT


def _proven_best(spec: Spec, names: list[str], done: dict[tuple[float, ...], Any],
                 deadline: float) -> tuple[tuple[float, ...] | None, Any]:
    """(point, result) of smallest constant proven exactly among the
    :data:`PROVEN_CANDIDATES` best points (the first always tried, the others while the
    deadline allows), each with its certificate or, when that one is not proven and has
    degree 2, the degree-1 potential's at the same point; else the best point as it is
    ((None, None): no point certified)."""
    from sosalgo.analysis import analyze_sublinear

    ranked = sorted(done, key=lambda k: done[k].constant)
    found: tuple[tuple[float, ...] | None, Any] = (None, None)
    for i, point in enumerate(ranked[:PROVEN_CANDIDATES]):
        if i and time.monotonic() > deadline:
            break
        if found[1] is not None and done[point].constant >= found[1].constant:
            break  # no later point can beat the proven one
        theta = dict(zip(names, point, strict=True))
        res = done[point]
        ok = _proven(spec, theta, res)
        if not ok and res.certificate.get("degree", 1) > 1:
            res = analyze_sublinear(spec, theta, degrees=(1,))
            ok = res.constant is not None and _proven(spec, theta, res)
        if ok and (found[1] is None or res.constant < found[1].constant):
            found = (point, res)
    if found[1] is None and ranked:
        return ranked[0], done[ranked[0]]
    return found


def _row(spec: Spec, names: list[str], box: list, best: tuple[float, ...] | None, res: Any,
         evaluations: int, seconds: float, time_limit: float, timed_out: bool
         ) -> dict[str, Any]:
    return {"rate_type": "sublinear", "L": float(spec.L), "free": names,
            "box": [list(b) for b in box], "constant": None if res is None else res.constant,
            "certified": res is not None,
            "theta": None if best is None else dict(zip(names, best, strict=True)),
            "params": {} if res is None else dict(res.params),
            "lower_bound": None, "bound_status": "unsupported",
            "evaluations": evaluations, "seconds": seconds, "time_limit": time_limit,
            "timed_out": timed_out, "check_kind": None if res is None else
            "floating-point check", "certificate": None if res is None else
            res.to_dict()["certificate"], "family": "sublinear"}
