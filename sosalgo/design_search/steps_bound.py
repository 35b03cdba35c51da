"""A lower bound of the N-step worst case proven over a whole box of parameters.

For a sub-box B of θ, three sound bounds of min_{θ in B} tau_N(θ):

* **robust PEP point** (:class:`BoxSolver`, :func:`prove_point`): one (G, F) feasible for
  the PEP of every θ in B (:mod:`sosalgo.design_search.steps_model`: each inequality is
  F_i - F_j + sum_alpha θ^alpha c_alpha >= 0 with c_alpha = <Q_alpha, G>; it holds on B
  when c_0 + sum_alpha min(lo_alpha c_alpha, hi_alpha c_alpha) >= 0, lo/hi the exact
  range of θ^alpha on B). The SDP maximizing F_N over such points is solved in floating
  point for a subclass F(m + s (L - m), L (1 - s)), s = 1e-7 (1e-5 when that is not
  proven, :data:`LADDER`), whose inequalities have slack; the proof rounds G to V V' with
  V rational (positive semidefinite by construction; V is kept for ``sosalgo verify``),
  takes the largest F for that G exactly (a shortest path from x*: F_j <= F_i + w_ij) and
  divides by G_00: every step in exact rational arithmetic, about the class as written.
* **quadratic witnesses** (:func:`quadratic_bound`): f = q x^2 / 2 in one dimension,
  m <= q <= L, its trajectory from x_0 = 1 enclosed in exact interval arithmetic over B.
* **Huber witnesses** (m = 0 only): slope tau, curvature L; while every query stays at
  y >= tau / L the gradients are tau, and f(x_N) >= tau x_N - tau^2 / (2L) everywhere.

The first converges to tau_N as B shrinks (where no two points coincide on B); the
witnesses cover the boxes where it cannot (θ = 0: the iterates stop moving).
:func:`branch_and_bound` splits the box whose proven bound is lowest; the bound over the
whole box is the minimum over the leaves.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.design_search.steps_affine import MAX_AFFINE_FREE, AffineSolver, affine_bound
from sosalgo.design_search.steps_model import (
    ParametricPEP,
    Poly,
    exact_forms,
    largest_values,
    poly_matvec,
    poly_range,
)
from sosalgo.kernel.solvers import SolverStatus, cvxpy_solve

__all__ = ["BoxBound", "BoxSolver", "BranchResult", "branch_and_bound", "huber_bound",
           "prove_box", "quadratic_bound", "reprove"]

# the SDP's class: F(m + s (L - m), L (1 - s)), a subclass whose inequalities have slack
# where points or gradients differ, which absorbs the solver's error and the rounding of
# the proof. The ladder of a box: (s, tight tolerances) in order, the first proven wins
# (the bound loses about s relative); a leaf records its rung for ``sosalgo verify``.
LADDER = ((Fraction(1, 10 ** 7), False), (Fraction(1, 10 ** 7), True),
          (Fraction(1, 10 ** 5), True))
TIGHT = {"tol_gap_abs": 1e-11, "tol_gap_rel": 1e-11, "tol_feas": 1e-11}
Box = tuple[tuple[Fraction, ...], tuple[Fraction, ...]]


def _ranges(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction]
            ) -> list[tuple[Fraction, Fraction]]:
    return [poly_range(e, lo, hi) for e in pp.monomials]


def linear_monomials(pp: ParametricPEP) -> list[int | None]:
    """Per free value i, the index of the monomial θ_i in ``pp.monomials`` (None: none)."""
    p = len(pp.free)
    unit = [tuple(int(j == i) for j in range(p)) for i in range(p)]
    return [pp.monomials.index(e) if e in pp.monomials else None for e in unit]


class _Robust:
    """The robust SDP of a box for one subclass (cvxpy, the box as parameters): one G
    for the whole box and function values affine in θ, F(θ) = F0 + F1 θ (F1 only on the
    free values with a monomial θ_i), F(x*) = 0."""

    def __init__(self, pp: ParametricPEP, shrink: Fraction):
        import cvxpy as cp

        K, A, d = len(pp.pairs), len(pp.monomials), pp.d
        forms = pp.float_forms(shrink).reshape(K, A, d * d)
        lin = linear_monomials(pp)
        self.G = cp.Variable((d, d), PSD=True)
        F = cp.Variable(pp.npts)
        self.F1 = cp.Variable((pp.npts, len(lin)))
        self.lo = cp.Parameter(A)
        self.hi = cp.Parameter(A)
        g = cp.vec(self.G, order="C")
        diff = pp.value_differences()
        slope_of = {a: i for i, a in enumerate(lin) if a is not None}
        zero = pp.monomials.index((0,) * len(pp.free))
        total = forms[:, zero, :] @ g
        cons = [self.G[0, 0] <= 1]
        for a in range(A):
            if a == zero or (a not in slope_of and not np.any(forms[:, a, :])):
                continue
            if a in slope_of:  # every pair: its G part and its slope of F
                c = forms[:, a, :] @ g + diff @ self.F1[:, slope_of[a]]
                rows = np.arange(K)
            else:
                rows = np.flatnonzero(np.any(forms[:, a, :] != 0, axis=1))
                c = forms[rows, a, :] @ g
            t = cp.Variable(len(rows))
            cons += [t <= self.lo[a] * c, t <= self.hi[a] * c]
            sel = np.zeros((K, len(rows)))
            sel[rows, np.arange(len(rows))] = 1.0
            total = total + sel @ t
        for i, a in enumerate(lin):
            if a is None:
                cons.append(self.F1[:, i] == 0)
        cons.append(diff @ F + total >= 0)
        u = cp.Variable(len(lin))  # the measure's least value over the box
        N = pp.measure_point
        cons += [u[i] <= self.lo[a] * self.F1[N, i] for i, a in enumerate(lin) if a is not None]
        cons += [u[i] <= self.hi[a] * self.F1[N, i] for i, a in enumerate(lin) if a is not None]
        cons += [u[i] == 0 for i, a in enumerate(lin) if a is None]
        self.problem = cp.Problem(cp.Maximize(F[N] + cp.sum(u)), cons)


class BoxSolver:
    """The robust SDPs of boxes (floating point), one per subclass of :data:`LADDER`."""

    def __init__(self, pp: ParametricPEP, affine: bool = True):
        self.pp = pp
        self._robust: dict[Fraction, _Robust] = {}
        self.affine = (AffineSolver(pp, LADDER, TIGHT)
                       if affine and len(pp.free) <= MAX_AFFINE_FREE else None)

    def solve(self, lo: Sequence[Fraction], hi: Sequence[Fraction], rung: int = 0
              ) -> tuple[float, np.ndarray | None, np.ndarray | None]:
        """(float value, G, F1) of the robust SDP on the box at ``rung`` of the ladder
        (-inf, None, None on failure)."""
        shrink, tight = LADDER[rung]
        if shrink not in self._robust:
            self._robust[shrink] = _Robust(self.pp, shrink)
        rb = self._robust[shrink]
        r = _ranges(self.pp, lo, hi)
        rb.lo.value = np.array([float(a) for a, _ in r])
        rb.hi.value = np.array([float(b) for _, b in r])
        end = cvxpy_solve(rb.problem, "CLARABEL", **(TIGHT if tight else {}))
        # an inaccurate solve is only a candidate: the proof decides
        if end.status not in (SolverStatus.SOLVED, SolverStatus.ALMOST_SOLVED) \
                or rb.G.value is None or rb.F1.value is None:
            return -math.inf, None, None
        return float(rb.problem.value), np.array(rb.G.value), np.array(rb.F1.value)

    def proven(self, lo: Sequence[Fraction], hi: Sequence[Fraction], floor: float = 0.0
               ) -> tuple[float, tuple[Fraction, list[list[int]], Slopes] | None, int]:
        """(float value, (proven bound, its factor V, its slopes F1) or None, rung): the
        ladder's rungs in order until a proof holds (a failed first solve, or a value
        at most ``floor``, a bound already in hand, or 0, ends it)."""
        first = -math.inf
        for rung in range(len(LADDER)):
            val, G, F1 = self.solve(lo, hi, rung)
            if rung == 0:
                first = val
            if G is None or val <= max(floor, 0.0):
                if rung == 0:
                    return val, None, 0
                continue
            got = prove_point(self.pp, G, F1, lo, hi)
            if got is not None:
                return first, got, rung
        return first, None, 0


FACTOR_BITS = 52  # V = integers / 2^FACTOR_BITS


def rational_factor(G: np.ndarray) -> list[list[int]] | None:
    """V (integers, V / 2^FACTOR_BITS) with V V' close to the float G: U sqrt(lambda)
    rounded, eigenvalues below 1e-11 of the largest dropped (None: G is about 0)."""
    Gs = (G + G.T) / 2
    lam, U = np.linalg.eigh(Gs)
    top = max(float(lam[-1]), 0.0)
    keep = lam > 1e-11 * top if top > 0 else np.zeros_like(lam, dtype=bool)
    V = U[:, keep] * np.sqrt(lam[keep])
    if V.shape[1] == 0:
        return None
    scale = 2 ** FACTOR_BITS
    return [[int(round(float(v) * scale)) for v in row] for row in V]


def _gram(V: list[list[int]]) -> Any:
    """V V' / 4^FACTOR_BITS, exact (positive semidefinite by construction)."""
    from flint import fmpq, fmpq_mat

    scale = 2 ** FACTOR_BITS
    Vq = fmpq_mat(len(V), len(V[0]), [fmpq(v, scale) for row in V for v in row])
    return Vq * Vq.transpose()


Slopes = list[list[Fraction]]  # F1: per point, per free value (exact dyadic rationals)


def prove_point(pp: ParametricPEP, G: np.ndarray, F1: np.ndarray | None,
                lo: Sequence[Fraction], hi: Sequence[Fraction]
                ) -> tuple[Fraction, list[list[int]], Slopes] | None:
    """(the exact lower bound on the box, its factor V, its slopes F1) from the float
    point (G, F1) (None: not proven)."""
    V = rational_factor(G)
    if V is None:
        return None
    p = len(pp.free)
    slopes = [[Fraction(float(F1[i, j])) if F1 is not None else Fraction(0)
               for j in range(p)] for i in range(pp.npts)]
    b = prove_factor(pp, V, lo, hi, slopes)
    return None if b is None else (b, V, slopes)


def prove_factor(pp: ParametricPEP, V: list[list[int]], lo: Sequence[Fraction],
                 hi: Sequence[Fraction], slopes: Slopes | None = None) -> Fraction | None:
    """The exact lower bound on the box of the PEP point G = V V' / 4^FACTOR_BITS with
    function values F0 + F1 θ, F1 = ``slopes`` (zero on the free values without a
    monomial θ_i) and F0 the largest for them (a shortest path): min over the box of
    F_N(θ) / G_00 (None: no F0 is feasible, or G_00 = 0)."""
    from flint import fmpq_mat

    d, A, p = pp.d, len(pp.monomials), len(pp.free)
    if len(V) != d or not V[0] or any(len(r) != len(V[0]) for r in V):
        return None
    lin = linear_monomials(pp)
    F1 = [[Fraction(0)] * p for _ in range(pp.npts)] if slopes is None else slopes
    if len(F1) != pp.npts or any(len(r) != p for r in F1):
        return None
    F1 = [[v if lin[j] is not None else Fraction(0) for j, v in enumerate(r)] for r in F1]
    Gq = _gram(V)
    if Gq[0, 0] <= 0:
        return None
    vec = fmpq_mat(d * d, 1, [Gq[r, c] for r in range(d) for c in range(d)])
    cval = exact_forms(pp) * vec
    ranges = _ranges(pp, lo, hi)
    zero = pp.monomials.index((0,) * len(pp.free))
    slope_at = {a: j for j, a in enumerate(lin) if a is not None}
    star = pp.npts
    weights = []
    for k, (i, j) in enumerate(pp.pairs):
        w = _q(cval[k * A + zero, 0])
        for a, (ra, rb) in enumerate(ranges):
            if a == zero:
                continue
            c = _q(cval[k * A + a, 0])
            if a in slope_at:
                s = slope_at[a]
                c += (F1[i][s] if i < star else 0) - (F1[j][s] if j < star else 0)
            if c:
                w += min(ra * c, rb * c)
        weights.append(w)
    best = largest_values(pp, weights)
    if best is None:
        return None
    N = pp.measure_point
    for s, a in enumerate(lin):
        if a is not None and F1[N][s]:
            ra, rb = ranges[a]
            best += min(ra * F1[N][s], rb * F1[N][s])
    return best / _q(Gq[0, 0])


def _q(v: Any) -> Fraction:
    return Fraction(int(v.p), int(v.q))


# ------------------------------------------------------------------ witnesses
Interval = tuple[Fraction, Fraction]


def _imul(a: Interval, b: Interval) -> Interval:
    c = (a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1])
    return min(c), max(c)


def _iadd(a: Interval, b: Interval) -> Interval:
    return a[0] + b[0], a[1] + b[1]


def _poly_interval(p: Poly, lo: Sequence[Fraction], hi: Sequence[Fraction]) -> Interval:
    out = (Fraction(0), Fraction(0))
    for e, c in p.items():
        a, b = poly_range(e, lo, hi)
        out = _iadd(out, _imul((c, c), (a, b)))
    return out


def _imat(M: list[list[Poly]], lo: Sequence[Fraction], hi: Sequence[Fraction]
          ) -> list[list[Interval]]:
    return [[_poly_interval(p, lo, hi) for p in row] for row in M]


def _imatvec(M: list[list[Interval]], v: list[Interval]) -> list[Interval]:
    out = []
    for row in M:
        acc = (Fraction(0), Fraction(0))
        for a, b in zip(row, v, strict=True):
            acc = _iadd(acc, _imul(a, b))
        out.append(acc)
    return out


def _trajectory(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction],
                grad: Callable[[Interval], Interval], start: int = 1
                ) -> tuple[list[Interval], Interval]:
    """(queries y_k, x_N) in one dimension from x_0 = ``start`` (xi_0 = x_0 1),
    g_k = grad(y_k), enclosed over the box."""
    assert pp.step_polys is not None
    n = len(pp.step_polys[0]["A"])
    xi = [(Fraction(start), Fraction(start))] * n
    ys = []
    for k in range(pp.steps):
        mats = {name: _imat(M, lo, hi) for name, M in pp.step_polys[k].items()}
        y = _imatvec(mats["C"], xi)[0]
        ys.append(y)
        g = grad(y)
        Ax = _imatvec(mats["A"], xi)
        xi = [_iadd(a, _imul(b[0], g)) for a, b in zip(Ax, mats["B"], strict=True)]
    E = _imat(pp.step_polys[-1]["E"], lo, hi)
    return ys, _imatvec(E, xi)[0]


VERTEX_BUDGET = 20000  # exact ranges of multilinear polynomials: vertices x terms at most


def _poly_trajectory(pp: ParametricPEP, q: Fraction, c: Fraction, start: int
                     ) -> list[Poly]:
    """The queries y_0..y_{N-1} and x_N as exact polynomials in θ, in one dimension from
    x_0 = ``start``, with g = q y + c (cached on ``pp``: they do not depend on the box)."""
    cache = pp.__dict__.setdefault("_trajectories", {})
    key = (q, c, start)
    if key in cache:
        return cache[key]
    assert pp.step_polys is not None
    zero = (0,) * len(pp.free)
    one = {zero: Fraction(1)}
    n = len(pp.step_polys[0]["A"])
    xi: list[Poly] = [{zero: Fraction(start)} if start else {} for _ in range(n)]
    out = []
    for k in range(pp.steps):
        mats = pp.step_polys[k]
        y = poly_matvec(mats["C"], xi)[0]
        out.append(y)
        g = poly_matvec([[{zero: q}, {zero: c}]] if c else [[{zero: q}]],
                        [y, one] if c else [y])[0]
        Ax = poly_matvec(mats["A"], xi)
        Bg = poly_matvec(mats["B"], [g])
        xi = [poly_matvec([[one, one]], [a, b])[0] for a, b in zip(Ax, Bg, strict=True)]
    out.append(poly_matvec(pp.step_polys[-1]["E"], xi)[0])
    cache[key] = out
    return out


def _vertex_ranges(polys: list[Poly], lo: Sequence[Fraction], hi: Sequence[Fraction]
                   ) -> list[Interval] | None:
    """The exact ranges over the box of multilinear polynomials: the hull of their
    values at the vertices (a multilinear polynomial is affine in each θ_i alone);
    None when one is not multilinear or the free values are too many for 2^p vertices
    (the stepwise intervals of :func:`_trajectory` lose the steps' correlation,
    x - h q x: these do not). Only within :data:`VERTEX_BUDGET` (vertices times terms):
    gradient descent up to about 6 steps. The values are exact (flint's rationals); each
    monomial's value at a vertex is computed once for all the polynomials."""
    if len(lo) > 16 or 2 ** len(lo) * sum(map(len, polys)) > VERTEX_BUDGET \
            or any(k > 1 for P in polys for e in P for k in e):
        return None
    from flint import fmpq

    def q(x: Fraction) -> Any:
        return fmpq(x.numerator, x.denominator)

    verts = list(itertools.product(*((q(a), q(b)) for a, b in zip(lo, hi, strict=True))))
    mono: dict[tuple[int, ...], list[Any]] = {}
    for P in polys:
        for e in P:
            if e not in mono:
                mono[e] = [math.prod((x for x, k in zip(v, e, strict=True) if k), start=fmpq(1))
                           for v in verts]
    out = []
    for P in polys:
        vals = [fmpq(0)] * len(verts)
        for e, c in P.items():
            cq, me = q(c), mono[e]
            vals = [v + cq * m for v, m in zip(vals, me, strict=True)]
        out.append((_q(min(vals)), _q(max(vals))))
    return out


def _float_last(polys: list[Poly], lo: Sequence[Fraction], hi: Sequence[Fraction]
                ) -> tuple[float, float] | None:
    """The float range of the last polynomial at the box's vertices (multilinear, within
    :data:`VERTEX_BUDGET`; else None): a cheap estimate that only orders the exact
    computations, never a bound."""
    P = polys[-1]
    if len(lo) > 16 or 2 ** len(lo) * len(P) > VERTEX_BUDGET \
            or any(k > 1 for e in P for k in e):
        return None
    V = np.array(list(itertools.product(*zip(map(float, lo), map(float, hi), strict=True))))
    vals = np.zeros(len(V))
    for e, c in P.items():
        vals += float(c) * np.prod(np.where(np.array(e, bool), V, 1.0), axis=1)
    return float(vals.min()), float(vals.max())


def quadratic_bound(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction],
                    qs: Sequence[Fraction]) -> Fraction:
    """max over q of the proven min over the box of f(x_N) for f = q x^2 / 2 (x_0 = 1).
    Float estimates at the box's vertices order the curvatures; a curvature whose
    estimate stays below the exact best so far (by a margin far above float error) is
    not computed exactly: it cannot raise the max."""
    best = Fraction(0)
    order: list[tuple[float, Fraction]] = []
    for q in qs:
        est = _float_last(_poly_trajectory(pp, q, Fraction(0), 1), lo, hi)
        low = math.inf if est is None else (0.0 if est[0] <= 0 <= est[1]
                                            else min(abs(est[0]), abs(est[1])))
        order.append((float(q) * low * low / 2, q))
    order.sort(key=lambda t: -t[0])
    for est, q in order:
        if est < float(best) * (1 - 1e-6) or (est == 0 and best > 0):
            continue
        best = max(best, _quadratic_at(pp, lo, hi, q))
    return best


def _quadratic_at(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction],
                  q: Fraction) -> Fraction:
    """The proven min over the box of f(x_N) for f = q x^2 / 2 (x_0 = 1)."""
    trajectory = _poly_trajectory(pp, q, Fraction(0), 1)
    exact = _vertex_ranges(trajectory[-1:], lo, hi)
    if exact is not None:
        a, b = exact[-1]
    else:
        _, (a, b) = _trajectory(pp, lo, hi, lambda y, q=q: (q * y[0], q * y[1])
                                if q >= 0 else (q * y[1], q * y[0]))
    low = Fraction(0) if a <= 0 <= b else min(abs(a), abs(b))
    return q * low * low / 2


def huber_bound(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction]
                ) -> Fraction:
    """The proven min over the box of f(x_N) for the Huber function of slope tau (m = 0
    only), tau the largest that keeps every query at y >= tau / L (proven), at most the
    best tau for the enclosure x_N = 1 + tau beta of the output."""
    if pp.m != 0:
        return Fraction(0)
    L = pp.L
    unit = _poly_trajectory(pp, Fraction(0), Fraction(1), 0)  # gamma_k, beta
    exact = _vertex_ranges(unit, lo, hi)
    ys, xN = ((exact[:-1], exact[-1]) if exact is not None else
              _trajectory(pp, lo, hi, lambda y: (Fraction(1), Fraction(1)), start=0))
    tau = 1 / (1 / L - 2 * min(xN[0], Fraction(0)))
    for y in ys:  # y_k = 1 + tau gamma_k >= tau / L while tau <= 1 / (1/L - gamma_k)
        tau = min(tau, 1 / (1 / L - min(y[0], Fraction(0))))
    rest = _poly_trajectory(pp, Fraction(0), Fraction(0), 1)
    moved = [{e: rest_p.get(e, Fraction(0)) + tau * u.get(e, Fraction(0))
              for e in set(rest_p) | set(u)} for rest_p, u in zip(rest, unit, strict=True)]
    exact = _vertex_ranges(moved, lo, hi)
    ys, (a, _) = ((exact[:-1], exact[-1]) if exact is not None else
                  _trajectory(pp, lo, hi, lambda y: (tau, tau)))
    if not all(y[0] >= tau / L for y in ys):
        return Fraction(0)
    return max(Fraction(0), tau * a - tau * tau / (2 * L))


def witness_curvatures(pp: ParametricPEP) -> list[Fraction]:
    """The curvatures q of the quadratic witnesses: L, m and a geometric grid between."""
    L, m = pp.L, pp.m
    return sorted({L, m} | {max(m, L * Fraction(2, 3) ** j) for j in range(1, 16)} - {0})


# ------------------------------------------------------------------ branch and bound
@dataclass
class BoxBound:
    """A box with its proven bound (``how``: affine-pep | robust-pep | quadratic | huber |
    none)."""

    lo: tuple[Fraction, ...]
    hi: tuple[Fraction, ...]
    bound: Fraction
    how: str
    estimate: float  # the float SDP value (the bound the box could reach)
    proven_on: Box | None = None  # the box the proof is about (an ancestor), None: this
    rung: int = 0  # the robust point's rung of LADDER
    point: list[list[int]] | None = None  # the robust point's factor V (integers)
    slopes: Slopes | None = None  # its function values' slopes F1 in θ (affine: in u)
    gram: list[list[list[Fraction]]] | None = None  # the affine point's G_0, G_1, ...

    def proof_box(self) -> Box:
        return self.proven_on or (self.lo, self.hi)

    def center(self) -> list[float]:
        return [float((a + b) / 2) for a, b in zip(self.lo, self.hi, strict=True)]


def prove_box(pp: ParametricPEP, solver: BoxSolver | None, lo: Sequence[Fraction],
              hi: Sequence[Fraction], target: float | None = None,
              inherited: Fraction = Fraction(0)) -> BoxBound:
    """The best proven bound of the box, cheapest first, until one reaches ``target``:
    the witnesses (where the method diverges on quadratics a box's robust point is small
    and its quadratic witness large), the constant robust point, then the affine robust
    point (an SDP about ten times larger) where the constant one's float value stays
    below ``target``. Only the witnesses where two points may coincide on the box
    (:func:`may_coincide`: a zero step; their inequalities have no slack there, and the
    SDPs' points fail their proofs). ``inherited``: a bound the box has already (its
    parent's, whose proof holds on it): an SDP point whose float value stays below it is
    not proven exactly."""
    lo, hi = tuple(lo), tuple(hi)
    best = BoxBound(lo, hi, Fraction(0), "none", -math.inf)
    for name, b in (("huber", huber_bound(pp, lo, hi)),
                    ("quadratic", quadratic_bound(pp, lo, hi, witness_curvatures(pp)))):
        if b > best.bound:
            best = BoxBound(lo, hi, b, name, -math.inf)
    goal = math.inf if target is None else target
    if solver is None or best.bound >= goal or may_coincide(pp, lo, hi):
        return best
    val, got, rung = solver.proven(lo, hi, max(float(best.bound), float(inherited)))
    best.estimate = val
    if got is not None and got[0] > best.bound:
        best = BoxBound(lo, hi, got[0], "robust-pep", val, rung=rung, point=got[1],
                        slopes=got[2])
    if solver.affine is None or best.bound >= goal or (val >= goal and got is not None):
        return best
    aval, affine = solver.affine.proven(lo, hi, max(float(best.bound), float(inherited)))
    if affine is not None and affine[0] > best.bound:
        return BoxBound(lo, hi, affine[0], "affine-pep", max(val, aval), gram=affine[1][0],
                        slopes=affine[1][1])
    return best


def may_coincide(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction]
                 ) -> bool:
    """Whether two of the points (queries, output) may be equal at some θ of the box:
    every coordinate of their difference has a range containing 0 (a necessary
    condition, enclosed in exact interval arithmetic)."""
    rows = [pt[0] for pt in (pp._rows or [])[:pp.npts]]
    for i, a in enumerate(rows):
        for b in rows[i + 1:]:
            if all(_poly_interval(_difference(pa, pb), lo, hi)[0] <= 0
                   <= _poly_interval(_difference(pa, pb), lo, hi)[1]
                   for pa, pb in zip(a, b, strict=True)):
                return True
    return False


def _difference(a: Poly, b: Poly) -> Poly:
    out = dict(a)
    for e, v in b.items():
        out[e] = out.get(e, Fraction(0)) - v
    return {e: v for e, v in out.items() if v}


def reprove(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction], how: str,
            point: list[list[int]] | None = None, slopes: Slopes | None = None,
            gram: list[list[list[Fraction]]] | None = None) -> Fraction:
    """The bound of the box by the one argument ``how`` (0 when it proves nothing; the
    robust point is the recorded factor ``point``, the affine point the recorded
    matrices ``gram`` and ``slopes``): what ``sosalgo verify`` re-checks for each leaf,
    exactly."""
    if how == "affine-pep":
        got = affine_bound(pp, lo, hi, gram, slopes) if gram and slopes else None
        return Fraction(0) if got is None else got
    if how == "robust-pep":
        pt = prove_factor(pp, point, lo, hi, slopes) if point else None
        return Fraction(0) if pt is None else pt
    if how == "quadratic":
        return quadratic_bound(pp, lo, hi, witness_curvatures(pp))
    if how == "huber":
        return huber_bound(pp, lo, hi)
    return Fraction(0)


@dataclass
class BranchResult:
    """The proven lower bound over the box (min over the leaves) and the search's log."""

    lower_bound: Fraction
    leaves: list[BoxBound]
    boxes: int
    seconds: float
    finished: bool  # the target gap was reached (else: the time ran out)
    hows: dict[str, int] = field(default_factory=dict)
    lost: int = 0  # boxes a worker process failed on (proven again in this one)


def _split(b: BoxBound, root: Box, slope: Sequence[float] | None = None
           ) -> list[tuple[tuple[Fraction, ...], tuple[Fraction, ...]]]:
    """Halve the box along the side that costs the bound most: width times |slope| of
    the worst case at the centre (``slope``, when known; plus the largest, so that a
    wide side with a small slope is split too: the affine point's loss grows with every
    side's width), else the widest side relative to the root."""
    widths = [float((h - lo_) / max(rh - rl, Fraction(1, 10 ** 30)))
              for lo_, h, rl, rh in zip(b.lo, b.hi, root[0], root[1], strict=True)]
    if slope is not None and len(slope) == len(widths) and all(map(math.isfinite, slope)):
        top = max(abs(float(g)) for g in slope) or 1.0
        cost = [float(h - lo_) * (abs(float(g)) + top)
                for lo_, h, g in zip(b.lo, b.hi, slope, strict=True)]
        if max(cost) > 0:
            widths = cost
    ax = max(range(len(widths)), key=lambda i: widths[i])
    mid = (b.lo[ax] + b.hi[ax]) / 2
    left_hi = tuple(mid if i == ax else v for i, v in enumerate(b.hi))
    right_lo = tuple(mid if i == ax else v for i, v in enumerate(b.lo))
    return [(b.lo, left_hi), (right_lo, b.hi)]


def branch_and_bound(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction],
                     upper: Callable[[], float], deadline: float, gap: float,
                     probe: Callable[[list[float]], Any] | None = None,
                     on_box: Callable[[int, float], None] | None = None,
                     max_boxes: int = 100000, workers: int = 1) -> BranchResult:
    """Split the box with the lowest proven bound until min bound >= upper() (1 - gap)
    or the deadline; ``probe(theta)`` is offered each split box's centre (the upper
    bound's search; it may return the worst case's gradient there, which chooses the
    side to split), ``on_box(boxes, lower)`` reports progress. ``workers`` > 1: the
    children of ``workers // 2`` boxes (at least one) are proven at once, this process
    and ``workers - 1`` worker processes (:class:`_Provers`)."""
    t0 = time.perf_counter()
    provers = _Provers(pp, workers)
    root: Box = (tuple(lo), tuple(hi))
    try:
        (first,) = provers.prove([root], None, [Fraction(0)])
        heap: list[tuple[Fraction, int, BoxBound]] = [(first.bound, 0, first)]
        count, finished = 1, False
        while heap:
            if float(heap[0][0]) >= upper() * (1 - gap):
                finished = True
                break
            if time.time() >= deadline or count >= max_boxes:
                break
            parents, kids = [], []
            while heap and len(parents) < max(1, workers // 2) \
                    and float(heap[0][0]) < upper() * (1 - gap):
                box = heapq.heappop(heap)[2]
                slope = probe(box.center()) if probe is not None else None
                for kid in _split(box, root, slope):
                    parents.append(box)
                    kids.append(kid)
            proven = provers.prove(kids, upper() * (1 - gap), [b.bound for b in parents])
            for box, child in zip(parents, proven, strict=True):
                if child.bound < box.bound:  # the parent's proof holds on the child
                    child = BoxBound(child.lo, child.hi, box.bound, box.how,
                                     child.estimate, box.proof_box(), box.rung, box.point,
                                     box.slopes, box.gram)
                count += 1
                heapq.heappush(heap, (child.bound, count, child))
            if on_box is not None:
                on_box(count, float(heap[0][0]))
    finally:
        provers.close()
    leaves = [b for _, _, b in heap]
    hows: dict[str, int] = {}
    for b in leaves:
        hows[b.how] = hows.get(b.how, 0) + 1
    return BranchResult(min(b.bound for b in leaves), leaves, count,
                        time.perf_counter() - t0, finished, hows, provers.lost)


class _Provers:
    """:func:`prove_box` of several boxes at once: the last in this process, the others
    on a pool of ``workers - 1`` processes (none when ``workers`` is 1), each holding the
    model and its own :class:`BoxSolver` (built on its first box). A worker that fails
    leaves its box to this process."""

    def __init__(self, pp: ParametricPEP, workers: int):
        import copy
        import pickle
        import uuid

        self.pp, self.solver = pp, BoxSolver(pp)
        self.pool, self.lost = None, 0
        if workers > 1:
            from sosalgo.kernel.parallel import worker_pool

            portable = copy.copy(pp)  # without the exact forms' flint matrix (rebuilt there)
            portable.__dict__ = {k: v for k, v in pp.__dict__.items() if k != "_exact"}
            try:
                self.blob = pickle.dumps(portable)
            except (TypeError, pickle.PicklingError):  # a model that cannot travel: here
                return
            self.token = uuid.uuid4().hex
            self.pool = worker_pool(workers - 1)

    def prove(self, boxes: Sequence[Box], target: float | None,
              inherited: Sequence[Fraction]) -> list[BoxBound]:
        """:func:`prove_box` of each box (``inherited``: the bound each has already)."""
        jobs = [(lo_, hi_, target, b) for (lo_, hi_), b in zip(boxes, inherited, strict=True)]
        futures = ([] if self.pool is None else
                   [self.pool.submit(_prove_remote, self.token, self.blob, *job)
                    for job in jobs[:-1]])
        last = prove_box(self.pp, self.solver, *jobs[-1])
        out = []
        for job, fut in zip(jobs, futures, strict=False):
            try:
                out.append(fut.result())
            except Exception:  # noqa: BLE001 - a lost worker: proven here instead
                self.lost += 1
                out.append(prove_box(self.pp, self.solver, *job))
        out += [prove_box(self.pp, self.solver, *job) for job in jobs[len(out):-1]]
        return out + [last]

    def close(self) -> None:
        if self.pool is not None:
            from sosalgo.kernel.parallel import kill_pool

            kill_pool(self.pool)
            self.pool = None


_REMOTE: dict[str, tuple[ParametricPEP, BoxSolver]] = {}  # a worker's model and solver


def _prove_remote(token: str, blob: bytes, lo: Sequence[Fraction], hi: Sequence[Fraction],
                  target: float | None, inherited: Fraction) -> BoxBound:
    """:func:`prove_box` in a worker process: the model ``blob`` (pickled by this run's
    :class:`_Provers`, ``token`` names it) unpickled and its solver built once."""
    if token not in _REMOTE:
        import pickle

        _REMOTE.clear()
        pp = pickle.loads(blob)  # noqa: S301 - pickled by the process that owns this pool
        _REMOTE[token] = (pp, BoxSolver(pp))
    pp, solver = _REMOTE[token]
    return prove_box(pp, solver, lo, hi, target, inherited)
