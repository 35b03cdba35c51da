"""Exact line search in the PEP: x_{k+1} = x_k - gamma_k u_k, gamma_k chosen at every step
so that the next gradient is orthogonal to the step (spec: ``line_search: gamma`` on
x+ = x - gamma u, :meth:`sosalgo.spec.loading.SpecLoader.line_search`).

The step gamma_k is not a number the method knows in advance, so the PEP does not follow
the matrices there: as in PEPit's ``exact_linesearch_step`` (de Klerk, Glineur and
Taylor 2017), every iterate x_{k+1} is a free point of its own (a basis vector
``x<k+1>-x*``), tied to the run by the equalities

    <g_{k+1}, x_{k+1} - x_k> = 0,    <g_{k+1}, u_k> = 0,

g_{k+1} the (true) gradient at x_{k+1} and u_k the answer that set the direction (the
gradient, or an inexact one: :mod:`sosalgo.worstcase.inexact`). A span search (spec:
``span_search: true``, conjugate gradient: x_{k+1} minimizes f over x_0 + span{g_0, ...,
g_k}) adds <g_{k+1}, u_j> = 0 and <g_{k+1}, x_{j+1} - x_j> = 0 for every j < k, as
PEPit's ``exact_linesearch_step`` over a list of directions. Every exact line search step
satisfies them, so the PEP bounds the method (a relaxation: x_{k+1} - x_k need not be
parallel to u_k; de Klerk et al. show it is tight for gradient descent). Each equality is
two rows of the extra constraints (``>= 0`` both ways, multipliers >= 0), in the float
SDP and the exact proof alike. The PEP makes a call at x_N (its gradient enters the last
equalities). The witness (:mod:`sosalgo.worstcase.linesearch_witness`) is a run on the
class's extremal
quadratic, whose exact line search steps are rational: the check
(:func:`sosalgo.worstcase.check.check_witness`) moves x_{k+1} = x_k + t_k d_k with the
document's steps t_k and proves <g_{k+1}, d_k> = 0 exactly (the step minimizes f on the
line: an exact line search).
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np

__all__ = ["line_search_rows", "line_search_trajectory"]


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
        dirs = [("step", Y[k + 1][0] - Y[k][0]), ("direction", U[k][0])]
        if mt.span_search:  # every past gradient and step: the span of the gradients
            dirs += [(f"direction{j}", U[j][0]) for j in range(k)]
            dirs += [(f"step{j}", Y[j + 1][0] - Y[j][0]) for j in range(k)]
        for name, b in dirs:
            for sign, tag in ((1, "+"), (-1, "-")):
                Qc = np.zeros((4, 4), dtype=object if mt.exact else float)
                Qc[0, 1] = Qc[1, 0] = sign * half
                out.append((f"linesearch:{calls[k + 1].label},{name}{tag}",
                            np.vstack([g, b, zero, zero]), Qc))
    return out

