"""Exact rational sum-of-squares certificates with facial reduction (unconstrained POPs).

The floating-point check of :mod:`sosalgo.polyopt.certificate` needs a Gram matrix with a
safe margin inside the PSD cone. Some polynomials have none: every Gram matrix of
Rosenbrock's ``100 (x2 - x1^2)^2 + (1 - x1)^2 - gamma`` is singular, because its
``(x2, x1^2)`` block is forced to be ``100 [[1, -1], [-1, 1]]`` by the coefficients of
``x2^2, x1^2 x2, x1^4``. Such a certificate lives on a face of the cone, and only exact
arithmetic can verify it (Peyrl and Parrilo 2008; facial reduction: Permenter and Parrilo
2018). Here:

1. a small SDP finds an exposing vector: a pseudo-moment vector ``y`` with ``y_0 = 0``,
   ``L_y(f) = 0`` and ``M_B(y) ⪰ 0``, so that every Gram matrix ``Z`` has
   ``Z M_B(y) = 0``; it is rounded to small rationals and ``W`` is an exact basis of
   ``ker M_B(y)``, so the squares are built from the polynomials ``p = W^T m`` (for
   Rosenbrock: ``1, x1, x1^2 - x2``; without an exposing vector, ``W = I``);
2. ``Q`` with ``f - G = p^T Q p`` *exactly* is found in rational arithmetic, starting from
   ``Q_0 = W^+ Z W^+T`` and correcting the pivot entries of the linear system;
3. ``Q`` is checked PSD exactly (``LDL^T`` over the rationals).

Success proves ``f >= G`` on all of ``R^n`` with no rounding left: ``f`` is the problem's
exact objective and ``G`` a rational. Failure proves nothing and returns None.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from sosalgo.kernel.solvers import cvxpy_solve

from .moment import MomentIndex
from .polynomial import Exponent

__all__ = ["exact_sos_bound"]

#: Largest size of the reduced Gram matrix tried (exact elimination grows fast).
MAX_REDUCED = 15

#: Largest denominator of the rounded kernel vectors.
MAX_DENOMINATOR = 1000

RatPoly = dict[Exponent, Fraction]


def exact_sos_bound(
    index: MomentIndex,
    Z: np.ndarray,
    keep: np.ndarray,
    f: RatPoly,
    level: Fraction,
    top: Fraction | None = None,
    steps: int = 8,
) -> Fraction | None:
    """The largest ``G`` found with ``f - G`` proven a sum of squares, or None.

    ``Z`` is an approximate Gram matrix of ``f - level`` over the monomial basis of
    ``M_k`` (only the rows and columns in ``keep`` are used; for an unconstrained problem
    the Newton polytope's, :func:`~sosalgo.polyopt.certificate.newton_keep`), ``f`` the
    objective with exact rational coefficients. ``level`` is tried first; after a success,
    ``steps`` bisection steps towards ``top`` (if given) look for a higher proven ``G``.
    """
    kept = np.flatnonzero(keep)
    basis = [tuple(int(a) for a in e) for e in index.exponents[kept]]
    Zk = np.asarray(Z, dtype=float)[np.ix_(keep, keep)]
    candidates = [_identity(len(basis))]
    exposing = _exposing_matrix(index, kept, f)
    if exposing is not None:
        candidates.insert(0, _nullspace(exposing))
    for W in candidates:
        if not W or not W[0] or len(W[0]) > MAX_REDUCED:
            continue
        if not _proves(W, basis, f, level, Zk):
            continue
        best, hi = level, top
        for _ in range(steps if top is not None and top > level else 0):
            mid = (best + hi) / 2
            if _proves(W, basis, f, mid, Zk):
                best = mid
            else:
                hi = mid
        return best
    return None


def _proves(
    W: list[list[Fraction]], basis: list[Exponent], f: RatPoly, G: Fraction, Z: np.ndarray
) -> bool:
    """Is ``f - G = p^T Q p`` with ``p = W^T m`` and an exactly PSD rational ``Q``?"""
    target = dict(f)
    zero = (0,) * len(basis[0])
    target[zero] = target.get(zero, Fraction(0)) - G
    Q = _exact_gram(W, basis, target, Z)
    return Q is not None and _is_psd(Q)


def _exposing_matrix(
    index: MomentIndex, kept: np.ndarray, f: RatPoly
) -> list[list[Fraction]] | None:
    """A rational ``M_B(y)`` (``B`` the kept basis) with ``y_0 = 0``, ``L_y(f) = 0``, ``⪰ 0``.

    For such ``y`` every Gram matrix ``Z`` of ``f - G`` satisfies ``<Z, M_B(y)> =
    L_y(f - G) = 0``, hence ``Z M_B(y) = 0``: the squares lie in ``ker M_B(y)`` (an
    exposing vector of the face of the certificates, Permenter-Parrilo). Found by a small
    SDP (``tr M_B(y) = 1``, interior point: maximal rank) and rounded to small rationals;
    None if there is none. A wrong rounding only makes the exact check fail.
    """
    import cvxpy as cp

    B = index.exponents[kept]
    pos = index.lookup(B[:, None, :] + B[None, :, :])
    used = np.unique(pos)
    y = cp.Variable(used.size)
    where = {int(m): i for i, m in enumerate(used)}
    sel = np.zeros((pos.size, used.size))
    sel[np.arange(pos.size), [where[int(m)] for m in pos.ravel()]] = 1.0
    M = cp.reshape(sel @ y, pos.shape, order="C")
    cf = np.zeros(used.size)
    for e, c in f.items():
        m = index.index_of(e)
        if m not in where:
            return None
        cf[where[m]] = float(c)
    cons = [M >> 0, cp.trace(M) == 1, cf @ y == 0]
    if 0 in where:
        cons.append(y[where[0]] == 0)
    if cvxpy_solve(cp.Problem(cp.Minimize(0), cons), "CLARABEL").error is not None:
        return None  # no exposing vector: no reduction
    if y.value is None:
        return None
    vals = [Fraction(0) if abs(v) < 1e-7 else Fraction(float(v)).limit_denominator(
        MAX_DENOMINATOR) for v in y.value]
    return [[vals[where[int(m)]] for m in row] for row in pos]


def _identity(n: int) -> list[list[Fraction]]:
    return [[Fraction(int(i == j)) for j in range(n)] for i in range(n)]


def _rref(M: list[list[Fraction]]) -> tuple[list[list[Fraction]], list[int]]:
    """Exact reduced row echelon form and pivot columns (``M`` is modified)."""
    pivots: list[int] = []
    r = 0
    cols = len(M[0]) if M else 0
    for c in range(cols):
        p = next((i for i in range(r, len(M)) if M[i][c] != 0), None)
        if p is None:
            continue
        M[r], M[p] = M[p], M[r]
        inv = 1 / M[r][c]
        M[r] = [v * inv for v in M[r]]
        for i in range(len(M)):
            if i != r and M[i][c] != 0:
                f = M[i][c]
                M[i] = [a - f * b for a, b in zip(M[i], M[r], strict=True)]
        pivots.append(c)
        r += 1
        if r == len(M):
            break
    return M[:r], pivots


def _nullspace(U: list[list[Fraction]]) -> list[list[Fraction]]:
    """Exact basis of ``{v: U v = 0}`` as the columns of a ``n x d`` matrix."""
    R, pivots = _rref([row[:] for row in U])
    n = len(U[0])
    free = [c for c in range(n) if c not in pivots]
    W = [[Fraction(0)] * len(free) for _ in range(n)]
    for j, c in enumerate(free):
        W[c][j] = Fraction(1)
        for row, p in zip(R, pivots, strict=True):
            W[p][j] = -row[c]
    return W


def _exact_gram(
    W: list[list[Fraction]], basis: list[Exponent], target: RatPoly, Z: np.ndarray
) -> list[list[Fraction]] | None:
    """Symmetric rational ``Q`` with ``target = p^T Q p`` exactly (``p = W^T m``), or None.

    Unknowns are the entries ``Q_ij, i <= j``, diagonal first, so the corrections of the
    constant term and of the even monomials fall on the diagonal where possible.
    """
    d = len(W[0])
    polys = [{basis[b]: W[b][i] for b in range(len(basis)) if W[b][i] != 0} for i in range(d)]
    pairs = [(i, i) for i in range(d)] + [(i, j) for i in range(d) for j in range(i + 1, d)]
    columns = [_product(polys[i], polys[j], 1 if i == j else 2) for i, j in pairs]
    monos = sorted(set(target).union(*columns))
    Wf = np.array([[float(v) for v in row] for row in W])
    pinv = np.linalg.pinv(Wf)
    Q0f = pinv @ Z @ pinv.T
    q0 = [Fraction(float(Q0f[i, j])) for i, j in pairs]
    rows = []
    for m in monos:
        coeffs = [col.get(m, Fraction(0)) for col in columns]
        rhs = target.get(m, Fraction(0)) - sum(
            (a * q for a, q in zip(coeffs, q0, strict=True) if a), Fraction(0))
        rows.append([*coeffs, rhs])
    R, pivots = _rref(rows)
    if pivots and pivots[-1] == len(pairs):
        return None  # inconsistent: target is not in the span of the products
    q = list(q0)
    for row, p in zip(R, pivots, strict=True):
        q[p] += row[-1]
    Q = [[Fraction(0)] * d for _ in range(d)]
    for (i, j), v in zip(pairs, q, strict=True):
        Q[i][j] = Q[j][i] = v
    return Q


def _product(p: RatPoly, q: RatPoly, factor: int) -> RatPoly:
    out: RatPoly = {}
    for a, u in p.items():
        for b, v in q.items():
            e = tuple(x + y for x, y in zip(a, b, strict=True))
            out[e] = out.get(e, Fraction(0)) + factor * u * v
    return {e: v for e, v in out.items() if v != 0}


def _is_psd(Q: list[list[Fraction]]) -> bool:
    """Exact test of ``Q ⪰ 0`` by symmetric elimination (``LDL^T``) over the rationals."""
    A = [row[:] for row in Q]
    n = len(A)
    for i in range(n):
        p = A[i][i]
        if p < 0:
            return False
        if p == 0:
            if any(A[i][j] != 0 for j in range(i + 1, n)):
                return False
            continue
        for j in range(i + 1, n):
            f = A[j][i] / p
            if f != 0:
                for m in range(i + 1, n):
                    A[j][m] -= f * A[i][m]
    return True
