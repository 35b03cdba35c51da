"""Rigorous enclosures for the design bound: ball arithmetic (python-flint's ``arb``).

Every quantity a proof rests on is an ``arb`` ball [mid ± rad] that contains the exact
value; each operation rounds outwards, so a comparison such as ``x > 0`` is True only when
it holds for every point of the ball. On top of that, this module proves three kinds of
statements over a box u ∈ [-1, 1]^k for a polynomial with ball coefficients
p(u) = Σ_α a_α u^α (α a multi-index; "even" when every exponent is even, so u^α ∈ [0, 1]):

* :func:`poly_positive`: p(u) > 0 on the box, from
  a_0 - Σ_{α odd} |a_α| - Σ_{α even} max(0, -a_α) > 0;
* :func:`psd_on_box`: Σ_α u^α A_α ≻ 0 on the box for symmetric matrices A_α, from
  A_0 - Σ_{α≠0} S_α ≻ 0 with S_α ± A_α ⪰ 0 (even α: S_α + A_α ⪰ 0, S_α ⪰ 0);
* :func:`is_pd`: a symmetric ball matrix is positive definite for every matrix in it
  (LDLᵀ with pivots that are proven positive).

The shift of a polynomial to a sub-box (``center + half·u``) is a product with a
Kronecker product of binomial matrices (:func:`shift_matrix`), also in ball arithmetic.
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction
from math import comb

import numpy as np
from flint import arb, arb_mat, fmpq

__all__ = ["ball", "ball_matrix", "box_shift", "shift_matrix", "poly_positive", "psd_on_box",
           "is_pd", "even_mask", "sympy_ball", "upper"]


def ball(x: float | int | Fraction) -> arb:
    """The exact value of a float, int or Fraction as a ball (a point unless the
    Fraction has no finite binary expansion, then a tiny enclosing ball)."""
    if isinstance(x, Fraction):
        return arb(fmpq(x.numerator, x.denominator))
    return arb(float(x)) if not isinstance(x, int) else arb(x)


def ball_matrix(a: np.ndarray) -> arb_mat:
    """A float matrix as an exact ball matrix (2-D)."""
    a = np.atleast_2d(np.asarray(a, dtype=float))
    return arb_mat([[arb(float(v)) for v in row] for row in a])


def sympy_ball(expr) -> arb:
    """A ball containing a real constant sympy expression (exact for rationals)."""
    from sosalgo.kernel.exact import enclose

    if expr.is_Rational:
        return arb(fmpq(int(expr.p), int(expr.q)))
    b = enclose(expr)
    out = ball(b.c)
    if b.r:
        out += arb(0, float(_up(b.r)))
    return out


def _up(x: Fraction) -> float:
    """A float >= x."""
    f = float(x)
    return f if Fraction(f) >= x else float(np.nextafter(f, np.inf))


def upper(x: arb) -> float:
    """A float >= every point of the ball."""
    u = x.upper()  # an exact point ball
    mant, exp = u.mid().man_exp()
    val = Fraction(int(mant)) * (Fraction(2) ** int(exp))
    return _up(val)


def shift_matrix(center: float, half: float, degree: int) -> arb_mat:
    """S with p(center + half·u) = Σ_i u^i (S a)_i for p(z) = Σ_j a_j z^j (balls)."""
    c, h = arb(center), arb(half)
    rows = [[arb(0)] * (degree + 1) for _ in range(degree + 1)]
    for j in range(degree + 1):
        for i in range(j + 1):
            rows[i][j] = comb(j, i) * c ** (j - i) * h**i
    return arb_mat(rows)


def box_shift(center: Sequence[float], half: Sequence[float], degrees: Sequence[int]
              ) -> arb_mat:
    """The shift to the sub-box center + half·u of coefficient rows on a tensor grid
    (row-major): the Kronecker product of the per-axis :func:`shift_matrix`."""
    S = arb_mat([[1]])
    for c, h, d in zip(center, half, degrees, strict=True):
        S = kron(S, shift_matrix(float(c), float(h), d))
    return S


def kron(a: arb_mat, b: arb_mat) -> arb_mat:
    """Kronecker product of two ball matrices."""
    ra, ca, rb, cb = a.nrows(), a.ncols(), b.nrows(), b.ncols()
    out = [[arb(0)] * (ca * cb) for _ in range(ra * rb)]
    for i in range(ra):
        for j in range(ca):
            x = a[i, j]
            if x.is_zero():
                continue
            for p in range(rb):
                for q in range(cb):
                    out[i * rb + p][j * cb + q] = x * b[p, q]
    return arb_mat(out)


def even_mask(degrees: Sequence[int]) -> np.ndarray:
    """Which monomials of a (D_1+1) x ... x (D_k+1) grid (row-major) are even."""
    grids = np.meshgrid(*[np.arange(d + 1) for d in degrees], indexing="ij")
    even = np.ones(tuple(d + 1 for d in degrees), dtype=bool)
    for g in grids:
        even &= g % 2 == 0
    return even.reshape(-1)


def poly_positive(coef: Sequence[arb], even: np.ndarray) -> bool:
    """p(u) > 0 on [-1, 1]^k, proven (``coef[0]`` the constant term, see module doc)."""
    low = coef[0]
    for a, ev in zip(coef[1:], even[1:], strict=True):
        if a.is_zero():
            continue
        low -= (-a).nonnegative_part() if ev else abs(a)
    return bool(low > 0)


def is_pd(a: list[list[arb]]) -> bool:
    """Every symmetric matrix in the ball matrix ``a`` is positive definite: LDLᵀ with
    pivots proven > 0 (the lower triangle is read; both triangles enclose the same
    exact symmetric matrix)."""
    n = len(a)
    L = [[arb(0)] * n for _ in range(n)]
    d = [arb(0)] * n
    for j in range(n):
        dj = a[j][j]
        for k in range(j):
            dj -= L[j][k] * L[j][k] * d[k]
        if not dj > 0:
            return False
        d[j] = dj
        for i in range(j + 1, n):
            s = a[i][j]
            for k in range(j):
                s -= L[i][k] * L[j][k] * d[k]
            L[i][j] = s / dj
    return True


def _cover(A: list[list[arb]], S0: np.ndarray | None, even: bool) -> list[list[arb]]:
    """A matrix S with S ± A ⪰ 0 (even: S + A ⪰ 0, S ⪰ 0), proven: the candidate ``S0``
    as given, then raised by a margin; without one |mid A| raised; else ||A||_F I."""
    n = len(A)
    mid = np.array([[float(A[i][j].mid()) for j in range(n)] for i in range(n)])
    mid = 0.5 * (mid + mid.T)
    tries = [] if S0 is None else [0.5 * (S0 + S0.T)]
    if S0 is None:
        w, V = np.linalg.eigh(mid)
        part = np.maximum(-w, 0.0) if even else np.abs(w)
        S0 = (V * part) @ V.T
    S0 = 0.5 * (S0 + S0.T)
    checks = (S0 + mid, S0) if even else (S0 + mid, S0 - mid)
    deficiency = max(-float(np.linalg.eigvalsh(M)[0]) for M in checks)
    scale = 1.0 + float(np.abs(mid).max())
    tries.append(S0 + (max(deficiency, 0.0) + 1e-9 * scale) * np.eye(n))
    signs = [(1, 1), (1, 0)] if even else [(1, 1), (1, -1)]
    for S in tries:
        Sb = [[arb(float(S[i][j])) for j in range(n)] for i in range(n)]
        if all(is_pd([[s * Sb[i][j] + a * A[i][j] for j in range(n)] for i in range(n)])
               for s, a in signs):
            return Sb
    return _norm_cover(A)


def _norm_cover(A: list[list[arb]]) -> list[list[arb]]:
    """c I with c >= ||A||_F >= ||A||_2 for every matrix in the ball (so c I ± A ⪰ 0)."""
    n = len(A)
    sq = sum((A[i][j] * A[i][j] for i in range(n) for j in range(n)), arb(0))
    c = arb(upper(sq.sqrt()))
    return [[c if i == j else arb(0) for j in range(n)] for i in range(n)]


def psd_on_box(coef: Sequence[list[list[arb]]], even: np.ndarray,
               candidates: dict[int, np.ndarray] | None = None) -> bool:
    """Σ_α u^α A_α ≻ 0 on [-1, 1]^k, proven (see module doc); ``candidates`` maps a
    monomial index to a float S_α to try first (e.g. from the SDP)."""
    n = len(coef[0])
    total = [[coef[0][i][j] for j in range(n)] for i in range(n)]
    for a in range(1, len(coef)):
        A = coef[a]
        if all(A[i][j].is_zero() for i in range(n) for j in range(n)):
            continue
        S = _cover(A, None if candidates is None else candidates.get(a), bool(even[a]))
        for i in range(n):
            for j in range(n):
                total[i][j] -= S[i][j]
    return is_pd(total)
