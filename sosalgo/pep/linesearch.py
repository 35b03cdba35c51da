"""Exact line search in the PEP: x_{k+1} = x_k - gamma_k u_k, gamma_k chosen at every step
so that the next gradient is orthogonal to the step (spec: ``line_search: gamma`` on
x+ = x - gamma u, :meth:`sosalgo.spec.loading.SpecLoader.line_search`).

The step gamma_k is not a number the method knows in advance, so the PEP does not follow
the matrices there: as in PEPit's ``exact_linesearch_step`` (de Klerk, Glineur and
Taylor 2017), every iterate x_{k+1} is a free point of its own (a basis vector
``x<k+1>-x*``), tied to the run by the equalities

    <g_{k+1}, x_{k+1} - x_k> = 0,    <g_{k+1}, u_k> = 0,

g_{k+1} the (true) gradient at x_{k+1} and u_k the answer that set the direction (the
gradient, or an inexact one: :mod:`sosalgo.pep.inexact`). Every exact line search step
satisfies them, so the PEP bounds the method (a relaxation: x_{k+1} - x_k need not be
parallel to u_k; de Klerk et al. show it is tight for gradient descent). Each equality is
two rows of the extra constraints (``>= 0`` both ways, multipliers >= 0), in the float
SDP and the exact proof alike. The PEP makes a call at x_N (its gradient enters the last
equalities). The witness (:func:`line_search_witness`) is a run on the class's extremal
quadratic, whose exact line search steps are rational: the check
(:func:`sosalgo.pep.check.check_witness`) moves x_{k+1} = x_k + t_k d_k with the
document's steps t_k and proves <g_{k+1}, d_k> = 0 exactly (the step minimizes f on the
line: an exact line search).
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np

__all__ = ["line_search_rows", "line_search_trajectory", "line_search_witness"]


def line_search_trajectory(mt: Any, xi0: np.ndarray, new: list[np.ndarray], calls: int,
                           steps: int, cols: list[str], eye: np.ndarray
                           ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """(xi, y, u/s) rows of the run: u_k/s = b_k (its own basis vector), y_k = x_k, and
    x_1 .. x_N free basis vectors (appended to ``cols``)."""
    xi, Y, U = [xi0], [], []
    for k in range(calls):
        U.append(new[k])
        Y.append(xi[k])  # C = [[1]], no D: the call is at x_k
        if k < steps:
            c = len(cols)
            cols.append(f"x{k + 1}-x*")
            xi.append(eye[c][None, :])
    return xi, Y, U


def line_search_rows(mt: Any, pts: list[list[Any]], Y: list[np.ndarray],
                     U: list[np.ndarray], steps: int
                     ) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The equalities of every step, as pairs of rows (label, X, Qc): <a, b> >= 0 and
    -<a, b> >= 0 with X = (a, b, 0, 0)."""
    calls = {pt.t: pt for pt in pts[0] if pt.t is not None}
    zero = Y[0][0] * 0
    half = Fraction(1, 2) if mt.exact else 0.5
    out = []
    for k in range(steps):
        g = calls[k + 1].g
        for name, b in (("step", Y[k + 1][0] - Y[k][0]), ("direction", U[k][0])):
            for sign, tag in ((1, "+"), (-1, "-")):
                Qc = np.zeros((4, 4), dtype=object if mt.exact else float)
                Qc[0, 1] = Qc[1, 0] = sign * half
                out.append((f"linesearch:{calls[k + 1].label},{name}{tag}",
                            np.vstack([g, b, zero, zero]), Qc))
    return out


# --------------------------------------------------------------------------- the witness
# A run on the class's own extremal function, in exact rationals: f = (m x_1^2 + L x_2^2)/2
# (m, L as written), whose exact line search step t = <g, d>/<d, H d> is rational, so that
# <g_{k+1}, d_k> = 0 holds exactly; an inexact answer d_k (inside its error ball, checked
# in rationals) and the start are chosen by a float search (greedy per step).

START_GRID = 2001  # start angles tried
TURN_GRID = 721  # directions of an inexact answer's error tried per step
INSIDE = Fraction(1, 10 ** 7)  # the curvatures' distance inside [m, L] (relative to L - m)


def _run(H: np.ndarray, x: np.ndarray, steps: int, eps: float | None
         ) -> tuple[float, list[float]]:
    """(f(x_N)/f(x_0), error angles) of the float run from x (greedy inexact answers)."""
    f0 = 0.5 * x @ H @ x
    turns = []
    for _ in range(steps):
        g = H @ x
        best = (-1.0, 0.0, x)
        for th in (np.linspace(0, 2 * np.pi, TURN_GRID) if eps else (0.0,)):
            d = g + (eps or 0.0) * _rotate(g, th)
            den = d @ H @ d
            if not den > 0:
                continue
            xn = x - (g @ d) / den * d
            if 0.5 * xn @ H @ xn > best[0]:
                best = (0.5 * xn @ H @ xn, th, xn)
        turns.append(best[1])
        x = best[2]
    return (0.5 * x @ H @ x) / f0 if f0 > 0 else 0.0, turns


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
    just inside [m, L], in the format of :mod:`sosalgo.pep.witness` plus
    ``line_search_steps`` (x_{k+1} = x_k + t_k d_k), checked exactly; None when the
    class's m or L is not rational."""
    from sosalgo.kinds import WITNESS_KIND
    from sosalgo.pep.check import arb_view, check_witness, q_str
    from sosalgo.pep.witness import _finish

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
    best = max(((_run(H, np.array([np.cos(a), np.sin(a)]), N,
                      None if eps is None else float(eps)), a)
                for a in np.linspace(1e-3, np.pi - 1e-3, START_GRID)),
               key=lambda r: r[0][0])
    (_, turns), a = best
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
    return _finish(doc, spec, kappa, exact_mt, res)
