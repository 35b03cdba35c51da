"""The witness of an exact line search PEP (:mod:`sosalgo.worstcase.linesearch`): a run on the
class's own extremal function in exact rationals, checked exactly."""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np

__all__ = ["line_search_witness"]

# A run on the class's own extremal function, in exact rationals: f = (m x_1^2 + L x_2^2)/2
# (m, L as written), whose exact line search step t = <g, d>/<d, H d> is rational, so that
# <g_{k+1}, d_k> = 0 holds exactly; an inexact answer d_k (inside its error ball, checked
# in rationals) and the start are chosen by a float search (greedy per step).

START_GRID = 201  # start angles tried (twice: coarse, then around the best)
TURN_GRID = 721  # directions of an inexact answer's error tried per step
INSIDE = Fraction(1, 10 ** 7)  # the curvatures' distance inside [m, L] (relative to L - m)


def _run(H: np.ndarray, x: np.ndarray, steps: int, eps: float | None
         ) -> tuple[float, list[float]]:
    """(f(x_N)/f(x_0), error angles) of the float run from x (greedy inexact answers, all
    TURN_GRID directions of the error at once)."""
    f0 = 0.5 * x @ H @ x
    ths = np.linspace(0, 2 * np.pi, TURN_GRID) if eps else np.zeros(1)
    turns = []
    for _ in range(steps):
        g = H @ x
        c, s = np.cos(ths), np.sin(ths)
        d = g[None, :] + (eps or 0.0) * np.stack([c * g[0] - s * g[1], s * g[0] + c * g[1]], 1)
        den = np.einsum("ti,ij,tj->t", d, H, d)
        with np.errstate(all="ignore"):
            xn = x[None, :] - ((d @ g) / den)[:, None] * d
            val = np.where(den > 0, 0.5 * np.einsum("ti,ij,tj->t", xn, H, xn), -1.0)
        best = int(np.argmax(val))
        turns.append(float(ths[best]))
        x = xn[best]
    return (0.5 * x @ H @ x) / f0 if f0 > 0 else 0.0, turns


def _best_start(H: np.ndarray, N: int, eps: float | None
                ) -> tuple[tuple[float, list[float]], float]:
    """((ratio, error angles), start angle) of the worst start: a grid of START_GRID
    angles, then START_GRID more around the best."""
    width = np.pi / START_GRID
    grid = np.linspace(1e-3, np.pi - 1e-3, START_GRID)
    for _ in range(2):
        best = max(((_run(H, np.array([np.cos(a), np.sin(a)]), N, eps), a) for a in grid),
                   key=lambda r: r[0][0])
        grid = np.linspace(best[1] - width, best[1] + width, START_GRID)
    return best


def _rotate(g: np.ndarray, th: float) -> np.ndarray:
    c, s = np.cos(th), np.sin(th)
    return np.array([c * g[0] - s * g[1], s * g[0] + c * g[1]])


def _q(v: float) -> Fraction:
    return Fraction(float(v)).limit_denominator(10 ** 12)


def _dot(a: list[Fraction], b: list[Fraction]) -> Fraction:
    return sum((x * y for x, y in zip(a, b, strict=True)), Fraction(0))


def _exact_answer(g: list[Fraction], eps: Fraction | None, th: float) -> list[Fraction]:
    """g, or g plus a rational error of norm at most eps |g| (checked exactly) in the
    direction th from g."""
    if not eps:
        return list(g)
    e = [_q(v) for v in float(eps) * _rotate(np.array([float(v) for v in g]), th)]
    for shrink in (Fraction(1), Fraction(999999, 1000000), Fraction(99, 100)):
        d = [a + shrink * b for a, b in zip(g, e, strict=True)]
        diff = [a - b for a, b in zip(d, g, strict=True)]
        if _dot(diff, diff) <= eps * eps * _dot(g, g):
            return d
    return list(g)


def line_search_witness(spec: Any, kappa: Any, mt: Any, st: Any, res: Any,
                        exact_mt: Any) -> dict[str, Any] | None:
    """The witness document of a line search PEP: f = (m' x_1^2 + L' x_2^2)/2 with m', L'
    just inside [m, L], in the format of :mod:`sosalgo.worstcase.witness` plus
    ``line_search_steps`` (x_{k+1} = x_k + t_k d_k), checked exactly; None when the
    class's m or L is not rational."""
    from sosalgo.kinds import WITNESS_KIND
    from sosalgo.worstcase.check import arb_view, check_witness, q_str
    from sosalgo.worstcase.witness import finish_witness

    if exact_mt is None:
        return None
    name, cls, params = exact_mt.functions[0]
    vals = [params.get("m"), params.get("L")]
    if any(v is None or getattr(v, "r", 0) for v in vals):
        return None
    m, L = (Fraction(getattr(v, "c", v)) for v in vals)
    written = {"m": float(m), "L": float(L)}  # the class's parameters
    # curvatures just inside [m, L]: the class inequalities then hold strictly (at m and L
    # themselves every one is an equality, which ball arithmetic cannot prove)
    m, L = m + INSIDE * (L - m), L - INSIDE * (L - m)
    eps = exact_mt.errors.get(0)
    if eps is not None and getattr(eps, "r", 0):
        return None
    eps = None if eps is None else Fraction(getattr(eps, "c", eps))
    H = np.diag([float(m), float(L)])
    N = st.steps
    (_, turns), a = _best_start(H, N, None if eps is None else float(eps))
    x = [_q(np.cos(a)), _q(np.sin(a))]
    ys, ds, ts = [], [], []
    for k in range(N + 1):
        g = [m * x[0], L * x[1]]
        d = _exact_answer(g, eps, turns[k]) if k < N else list(g)
        ys.append(x)
        ds.append(d)
        if k < N:
            t = -_dot(g, d) / (m * d[0] ** 2 + L * d[1] ** 2)
            ts.append(t)
            x = [xi + t * di for xi, di in zip(x, d, strict=True)]
    pts = [{"label": f"y{k}", "g": [q_str(m * y[0]), q_str(L * y[1])],
            "h": q_str((m * y[0] ** 2 + L * y[1] ** 2) / 2), "x": [float(v) for v in y]}
           for k, y in enumerate(ys)]
    doc: dict[str, Any] = {
        "kind": WITNESS_KIND, "spec": spec.name, "kappa": res.kappa, "steps": N,
        "calls_per_step": 1, "call_steps": N + 1, "measure": res.measure,
        "initial": res.initial, "dimension": 2, "x0": [q_str(v) for v in ys[0]],
        "calls": [[[q_str(v) for v in d]] for d in ds],
        "line_search_steps": [q_str(t) for t in ts],
        "functions": {name: {"class": cls.name,
                             "params": written,
                             "optimal_subgradient": ["0", "0"], "points": pts}},
        "evaluations": {f"{key}|{mt.functions[j][0]}": st.points[j][i].label
                        for (key, j), i in st.at.items()},
        "iterates": [[float(v) for v in y] for y in ys],
        "tau_float": res.tau, "search": {"start_angles": START_GRID,
                                         "error_directions": TURN_GRID if eps else 0},
    }
    doc["check"] = check_witness(doc, spec, arb_view(exact_mt))
    return finish_witness(doc, spec, kappa, exact_mt, res)
