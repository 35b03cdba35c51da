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
:mod:`sosalgo.worstcase.inexact`).

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

from typing import Any

import numpy as np

from sosalgo.errors import InputError

__all__ = ["KIND", "contraction_parts", "contraction_size", "is_contraction"]

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


def contraction_size(mt: Any, steps: int) -> int:
    """The dimension of the contraction PEP's basis: n + p N."""
    return mt.n + mt.p * steps


def contraction_parts(mt: Any, steps: int, measure: Any, initial: Any, eye: np.ndarray
                      ) -> dict[str, Any]:
    """The contraction PEP's data (see the module) on the basis ``eye`` (floats or exact
    numbers, :func:`contraction_size` square): ``basis``, the rows ``xi``, ``y``, ``u``,
    ``x`` (the output's difference after N steps), ``extras`` (the two-point conditions),
    the measure's and initial condition's forms ``meas``, ``init``."""
    if (mt.errors or mt.line_search or mt.lmo or mt.per_step is not None
            or mt.G0 is not None or mt.constraints):
        raise InputError("--measure: contraction: not with inexact calls, a line search, a "
                         "linear minimization call, a method that changes with k, an "
                         "initial_state or pep.constraints")
    n, p = mt.n, mt.p
    cols = [f"dxi0_{a + 1}" for a in range(n)]
    cols += [f"du_{_label(i, k, p)}" for k in range(steps) for i in range(p)]
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
                extras.append((f"contraction:{_label(i, k, p)}{tag}", X, Qc))
    cm, ci = mt.coef(measure[0]), mt.coef(initial[0])
    return {"basis": cols, "xi": xi, "y": Y, "u": U, "extras": extras,
            "x": (mt.E @ xi[steps])[0] if mt.E is not None else Y[-1][mt.output],
            "meas": sum(np.outer(row, row) for row in xi[steps]) * cm,
            "init": sum(np.outer(eye[a], eye[a]) for a in range(n)) * ci}


def _label(i: int, k: int, p: int) -> str:
    return f"y{k}" if p == 1 else f"y{i + 1}_{k}"


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

