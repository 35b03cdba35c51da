"""The affine robust point: a lower bound of the N-step worst case over a box of θ whose
loss shrinks with the square of the box's width.

The robust point of :mod:`sosalgo.design_search.steps_bound` keeps one Gram matrix G for
every θ of a box, so its bound loses in proportion to the box's width (the worst case's
G moves with θ). Here, in the box's own coordinates θ = c + w ∘ u, u ∈ [-1, 1]^p (c the
centre, w the half-widths),

    G(u) = G_0 + Σ_i u_i G_i,     F(u) = F_0 + Σ_i u_i F_i.

G(u) is positive semidefinite on the whole box when it is at the 2^p vertices (it is
affine in u, the box their convex hull). Each interpolation inequality of pair k,
F_i(u) - F_j(u) + Σ_α θ^α <Q_{k,α}, G(u)> >= 0, is a polynomial in u once θ^α is
expanded about c; it holds on the box when its constant term is at least the sum of its
other terms' least values (u^γ ranges over [0, 1] when every exponent of γ is even, over
[-1, 1] otherwise). A convex combination of two worst cases (two branches of a kink of
tau_N) is of this form too, so boxes around the optimum of a design are bounded well.

The proof (:func:`prove_affine`): the float G_i rounded to exact rationals, symmetrized,
G_i[0, 0] set to 0; G_0 + δ I with δ >= 0 such that every vertex matrix is positive
definite, checked by an exact LDLᵀ in rational arithmetic; the least value of each pair's
polynomial on the box, exactly; the largest F_0 for those (a shortest path from x*,
:func:`sosalgo.design_search.steps_model.largest_values`); the bound is the least
F_N(u) on the box divided by G_00. Every step is exact, about the class as written: by the
interpolation theorem each u gives a function of the class with this value, so
tau_N(θ) >= the bound at every θ of the box.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from fractions import Fraction
from math import comb
from typing import Any

import numpy as np

from sosalgo.design_search.steps_model import ParametricPEP, exact_forms, largest_values
from sosalgo.kernel.solvers import SolverStatus, cvxpy_solve

__all__ = ["AffineSolver", "MAX_AFFINE_FREE", "affine_bound", "prove_affine"]

MAX_AFFINE_FREE = 6  # 2^p vertex inequalities: the argument is offered up to p free values
Mono = tuple[int, ...]
AffinePoint = tuple[list[list[list[Fraction]]], list[list[Fraction]]]  # ([G_0..G_p], F1)


def _expansion(alpha: Mono, c: Sequence[Any], w: Sequence[Any]) -> dict[Mono, Any]:
    """(c + w u)^alpha as {beta: coefficient} (exact when c, w are exact)."""
    out: dict[Mono, Any] = {(0,) * len(alpha): 1}
    for i, a in enumerate(alpha):
        if a == 0:
            continue
        terms = [(j, comb(a, j) * c[i] ** (a - j) * w[i] ** j) for j in range(a + 1)]
        nxt: dict[Mono, Any] = {}
        for beta, v in out.items():
            for j, t in terms:
                if not t:
                    continue
                b = beta[:i] + (beta[i] + j,) + beta[i + 1:]
                nxt[b] = nxt.get(b, 0) + v * t
        out = nxt
    return out


def _down(monomials: Sequence[Mono]) -> list[Mono]:
    """Every beta <= some alpha of ``monomials`` (the monomials of the shifted forms)."""
    out: set[Mono] = set()
    for a in monomials:
        out.update(itertools.product(*(range(k + 1) for k in a)))
    return sorted(out)


def _even(g: Mono) -> bool:
    return all(k % 2 == 0 for k in g)


def _plus(b: Mono, i: int) -> Mono:
    return b[:i] + (b[i] + 1,) + b[i + 1:]


def _vertices(p: int) -> list[tuple[int, ...]]:
    return list(itertools.product((-1, 1), repeat=p))


def _center(lo: Sequence[Fraction], hi: Sequence[Fraction]
            ) -> tuple[list[Fraction], list[Fraction]]:
    return ([(a + b) / 2 for a, b in zip(lo, hi, strict=True)],
            [(b - a) / 2 for a, b in zip(lo, hi, strict=True)])


class _AffineSDP:
    """The float SDP of the affine robust point (cvxpy; the box's shifted forms as
    parameters): maximize F_0N - Σ_i |F_Ni| over G(u), F(u) as in the module, for the
    subclass F(m + s (L - m), L (1 - s)), s = ``shrink``."""

    def __init__(self, pp: ParametricPEP, shrink: Fraction):
        import cvxpy as cp

        self.pp = pp
        p, d, K = len(pp.free), pp.d, len(pp.pairs)
        self.betas = _down(pp.monomials)
        forms = pp.float_forms(shrink).reshape(K, len(pp.monomials), d * d)
        self.forms = forms
        alive = np.any(forms != 0, axis=2)  # (K, A): pair k has monomial a
        # pair k's shifted monomial beta can be nonzero when some alpha >= beta is there
        self.mask = np.array([[any(alive[k, a] and all(x <= y for x, y in zip(b, al,
                                                                              strict=True))
                                   for a, al in enumerate(pp.monomials))
                               for b in self.betas] for k in range(K)])
        self.P = [cp.Parameter((K, d * d)) for _ in self.betas]
        self.G = [cp.Variable((d, d), symmetric=True) for _ in range(p + 1)]
        self.F0 = cp.Variable(pp.npts)
        self.F1 = cp.Variable((pp.npts, p))
        gv = [cp.vec(G, order="C") for G in self.G]
        diff = pp.value_differences()
        zero = (0,) * p
        coef: dict[Mono, list[Any]] = {}
        rows: dict[Mono, np.ndarray] = {}
        for bi, b in enumerate(self.betas):  # <Q~_b, G_0> u^b, <Q~_b, G_i> u^(b + e_i)
            for j in range(p + 1):
                g = b if j == 0 else _plus(b, j - 1)
                coef.setdefault(g, []).append(self.P[bi] @ gv[j])
                rows[g] = rows.get(g, np.zeros(K, bool)) | self.mask[:, bi]
        for i in range(p):
            e = tuple(int(j == i) for j in range(p))
            coef.setdefault(e, []).append(diff @ self.F1[:, i])
            rows[e] = np.ones(K, bool)
        total = diff @ self.F0 + sum(coef.pop(zero))
        cons = []
        for g, parts in coef.items():
            r = np.flatnonzero(rows[g])
            if not len(r):
                continue
            c = sum(parts)[r]
            t = cp.Variable(len(r))
            cons += [t >= -c] + ([t >= 0] if _even(g) else [t >= c])
            sel = np.zeros((K, len(r)))
            sel[r, np.arange(len(r))] = 1.0
            total = total - sel @ t
        cons.append(total >= 0)
        for s in _vertices(p):
            cons.append(self.G[0] + sum(si * G for si, G in zip(s, self.G[1:], strict=True))
                        >> 0)
        cons += [self.G[0][0, 0] <= 1] + [G[0, 0] == 0 for G in self.G[1:]]
        a = cp.Variable(p)
        N = pp.measure_point
        cons += [a >= self.F1[N, :], a >= -self.F1[N, :]]
        self.problem = cp.Problem(cp.Maximize(self.F0[N] - cp.sum(a)), cons)

    def solve(self, lo: Sequence[Fraction], hi: Sequence[Fraction],
              options: dict[str, float] | None = None) -> tuple[float, AffinePoint | None]:
        """(float value, the float point as exact binary rationals) on the box, or
        (-inf, None) when the solve fails."""
        c, w = _center(lo, hi)
        cf, wf = [float(x) for x in c], [float(x) for x in w]
        S = np.zeros((len(self.betas), len(self.pp.monomials)))
        index = {b: i for i, b in enumerate(self.betas)}
        for a, al in enumerate(self.pp.monomials):
            for b, v in _expansion(al, cf, wf).items():
                S[index[b], a] += v
        shifted = np.einsum("ba,kaj->bkj", S, self.forms)
        for P, M in zip(self.P, shifted, strict=True):
            P.value = M
        end = cvxpy_solve(self.problem, "CLARABEL", **(options or {}))
        if end.status not in (SolverStatus.SOLVED, SolverStatus.ALMOST_SOLVED) \
                or self.F1.value is None or any(G.value is None for G in self.G):
            return -math.inf, None
        Gs = [[[Fraction(float(v)) for v in row] for row in np.asarray(G.value)]
              for G in self.G]
        F1 = [[Fraction(float(v)) for v in row] for row in np.asarray(self.F1.value)]
        return float(self.problem.value), (Gs, F1)


class AffineSolver:
    """The affine robust points of boxes: the SDP per rung of ``ladder`` ((subclass
    shrink s, tight tolerances), :data:`sosalgo.design_search.steps_bound.LADDER`), built
    when first needed; ``tight``: the solver's tight tolerances."""

    def __init__(self, pp: ParametricPEP, ladder: Sequence[tuple[Fraction, bool]],
                 tight: dict[str, float]):
        self.pp, self.ladder, self.tight = pp, ladder, tight
        self._sdp: dict[Fraction, _AffineSDP] = {}

    def proven(self, lo: Sequence[Fraction], hi: Sequence[Fraction], floor: float = 0.0
               ) -> tuple[float, tuple[Fraction, AffinePoint] | None]:
        """(the first rung's float value, (proven bound, proven point) or None): the
        ladder's rungs in order until a proof holds (a failed first solve, or a first
        value at most ``floor``, the bound in hand, ends it)."""
        first = -math.inf
        for rung, (shrink, tight) in enumerate(self.ladder):
            if shrink not in self._sdp:
                self._sdp[shrink] = _AffineSDP(self.pp, shrink)
            val, pt = self._sdp[shrink].solve(lo, hi, self.tight if tight else None)
            if rung == 0:
                first = val
                if pt is None or val <= floor:
                    return val, None
            if pt is None or val <= max(floor, 0.0):
                continue
            got = prove_affine(self.pp, pt, lo, hi)
            if got is not None:
                return first, got
        return first, None


def _is_pd(M: list[list[Fraction]]) -> bool:
    """Exact: every pivot of the LDLᵀ of the symmetric rational M is positive."""
    A = [row[:] for row in M]
    n = len(A)
    for k in range(n):
        piv = A[k][k]
        if piv <= 0:
            return False
        for i in range(k + 1, n):
            f = A[i][k] / piv
            if f:
                for j in range(k + 1, n):
                    A[i][j] -= f * A[k][j]
    return True


def _vertex(Gs: list[list[list[Fraction]]], s: Sequence[int]) -> list[list[Fraction]]:
    d = len(Gs[0])
    return [[Gs[0][r][q] + sum((si * G[r][q] for si, G in zip(s, Gs[1:], strict=True)),
                               Fraction(0)) for q in range(d)] for r in range(d)]


def _symmetric(G: list[list[Fraction]]) -> list[list[Fraction]]:
    d = len(G)
    return [[(G[r][q] + G[q][r]) / 2 for q in range(d)] for r in range(d)]


def positive_on_box(Gs: list[list[list[Fraction]]]) -> list[list[list[Fraction]]] | None:
    """[G_0 + δ I, G_1, ..., G_p] (symmetrized, G_i[0][0] = 0 for i >= 1) with every
    vertex matrix positive definite (exact), δ >= 0 from the float eigenvalues; None when
    no δ of a few tries proves it."""
    Gs = [_symmetric(G) for G in Gs]
    for G in Gs[1:]:
        G[0][0] = Fraction(0)
    p, d = len(Gs) - 1, len(Gs[0])
    verts = [np.array([[float(v) for v in row] for row in _vertex(Gs, s)])
             for s in _vertices(p)]
    low = min(float(np.linalg.eigvalsh(V)[0]) for V in verts)
    scale = max(1.0, max(float(np.max(np.abs(V))) for V in verts))
    delta = max(0.0, -low) * 1.001 + 1e-12 * scale
    for _ in range(4):
        dq = Fraction(delta)
        G0 = [[Gs[0][r][q] + (dq if r == q else 0) for q in range(d)] for r in range(d)]
        cand = [G0] + Gs[1:]
        if all(_is_pd(_vertex(cand, s)) for s in _vertices(p)):
            return cand
        delta *= 100
    return None


def affine_bound(pp: ParametricPEP, lo: Sequence[Fraction], hi: Sequence[Fraction],
                 Gs: list[list[list[Fraction]]], F1: list[list[Fraction]]
                 ) -> Fraction | None:
    """The exact bound of the box for the (already positive) affine point: G_i as given
    (G_0 + Σ u_i G_i ⪰ 0 on the box is the caller's, :func:`positive_on_box`), F_1 =
    ``F1`` (per point, per u_i), F_0 the largest for them (None: none feasible)."""

    p, d, A = len(pp.free), pp.d, len(pp.monomials)
    if len(Gs) != p + 1 or len(F1) != pp.npts or any(len(r) != p for r in F1):
        return None
    if any(len(G) != d or any(len(r) != d for r in G) for G in Gs) or Gs[0][0][0] <= 0:
        return None
    if any(G[0][0] != 0 for G in Gs[1:]):
        return None
    for s in _vertices(p):
        if not _is_pd(_vertex(Gs, s)):
            return None
    from flint import fmpq, fmpq_mat

    gm = fmpq_mat(d * d, p + 1, [fmpq(Gs[j][r][q].numerator, Gs[j][r][q].denominator)
                                 for r in range(d) for q in range(d) for j in range(p + 1)])
    C = exact_forms(pp) * gm  # row k A + a: <Q_{k,a}, G_j> per column j
    c, w = _center(lo, hi)
    shifts = [_expansion(al, c, w) for al in pp.monomials]
    star = pp.npts
    weights = []
    for k, (i, j) in enumerate(pp.pairs):
        poly: dict[Mono, Fraction] = {}
        for a in range(A):
            vals = [C[k * A + a, jj] for jj in range(p + 1)]
            if not any(vals):
                continue
            vq = [Fraction(int(v.p), int(v.q)) for v in vals]
            for b, sv in shifts[a].items():
                for jj in range(p + 1):
                    if vq[jj]:
                        g = b if jj == 0 else _plus(b, jj - 1)
                        poly[g] = poly.get(g, Fraction(0)) + sv * vq[jj]
        for t in range(p):
            e = tuple(int(q == t) for q in range(p))
            dv = (F1[i][t] if i < star else 0) - (F1[j][t] if j < star else 0)
            poly[e] = poly.get(e, Fraction(0)) + dv
        zero = (0,) * p
        total = poly.pop(zero, Fraction(0))
        for g, v in poly.items():
            if v < 0 or not _even(g):
                total -= abs(v)
        weights.append(total)
    best = largest_values(pp, weights)
    if best is None:
        return None
    N = pp.measure_point
    best -= sum((abs(v) for v in F1[N]), Fraction(0))
    return best / Gs[0][0][0]


def prove_affine(pp: ParametricPEP, point: AffinePoint, lo: Sequence[Fraction],
                 hi: Sequence[Fraction]) -> tuple[Fraction, AffinePoint] | None:
    """(the exact bound, the proven point [G_0 + δ I, G_1, ...], F1) from the float point
    (None: not proven)."""
    Gs, F1 = point
    cand = positive_on_box(Gs)
    if cand is None:
        return None
    b = affine_bound(pp, lo, hi, cand, F1)
    return None if b is None else (b, (cand, F1))
