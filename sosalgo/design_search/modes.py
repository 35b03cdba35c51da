"""The mode argument of the design bound: boxes where the method is provably slower
than T on a quadratic, for every θ in the box.

On f(x) = q x²/2 (q = m or q = L, both in F(m, L)) the method is ξ+ = X_q ξ with
X_q = A + q B C. If X_q has an eigenvalue μ with |μ| > T whose eigenvector v is seen by
the output (E v ≠ 0), the trajectories from Re v and Im v have |x_k|² summing to
|μ|^{2k} |E v|², so no certificate of any family proves f(x_k) − f* ≤ ρ^{2k} V_0 with
ρ ≤ T there. Over a box of θ this is proven in ball arithmetic from the exact
polynomials (:mod:`sosalgo.design_search.polymodel`), every part for every θ of the box:

* a root outside the disc of radius T: with c(t) = det(t I − X_q) = Σ_j c_j(θ) t^j,
  c(T) < 0 (a real root > T), or (−1)^n c(−T) < 0 (a real root < −T), or
  |det X_q| > T^n (some |μ| > T) — each a polynomial in θ shown of one sign on the box;
* visibility: an eigenvector v ∈ ker E is v = K w with K a basis of ker E and K^L a left
  inverse, so μ is an eigenvalue of N = K^L X_q K; when the spectral radius of N is
  below T on the whole box (bounded by the row and column sums of entrywise bounds),
  every eigenvector with |μ| > T is seen by the output.

Near a θ where the slow mode becomes invisible (a pole–zero cancellation) the visibility
bound fails on every box around it, so such boxes are never proven by this argument.
E must not depend on θ (else the argument is not used).
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from flint import arb, arb_mat

import sosalgo.design_search.enclosure as enc
from sosalgo.design_search.polymodel import ExactMethod, ball_coefficients

__all__ = ["ModeTest"]


class ModeTest:
    """Proves boxes by the mode argument (see module docstring)."""

    def __init__(self, method: ExactMethod):
        A, B, C, E = (method.matrices[k] for k in ("A", "B", "C", "E"))
        self.n = n = A.shape[0]
        zs = method.box.zs
        self.ok = not any(e.free_symbols & set(zs) for e in E)
        if not self.ok:  # E depends on θ: the argument is not used
            self.degrees, self.balls, self.even = (), arb_mat(0, 0), np.array([True])
            return
        t = sp.Symbol("t")
        polys: list[sp.Expr] = []
        self.nk = n - 1
        K, KL = _kernel(E, n)
        for q in (method.m, method.L):
            X = A + q * B * C
            cp = sp.Poly(sp.expand((t * sp.eye(n) - X).det(method="berkowitz")), t)
            polys += [cp.coeff_monomial(t**j) for j in range(n + 1)]
            if self.nk:
                polys += list(KL * X * K)
        self.per = n + 1 + self.nk * self.nk
        self.degrees, rows = ball_coefficients([sp.sympify(p) for p in polys], zs)
        self.balls = arb_mat(rows)
        self.even = enc.even_mask(self.degrees)

    def proves(self, zc: np.ndarray, w: np.ndarray, T2: float) -> bool:
        """True when every θ of the box has a visible mode with |μ|² > T2 on q = m or L."""
        if not self.ok or not 0 < T2 < 1:
            return False
        T = arb(enc.upper(arb(T2).sqrt()))  # T >= sqrt(T2), a float
        S = enc.box_shift(zc, w, self.degrees)
        data = (S * self.balls).tolist() if self.balls.nrows() else []
        cols = list(zip(*data, strict=True)) if data else []
        for j in range(2):  # q = m, q = L
            col = cols[j * self.per:(j + 1) * self.per]
            if self.nk and not self._visible(col[self.n + 1:], T):
                continue
            if self._slow_root(col[:self.n + 1], T):
                return True
        return False

    def _visible(self, entries, T: arb) -> bool:
        """Spectral radius of N = K^L X K below T on the box: every row sum, or every
        column sum, of entrywise bounds |N_ab(u)| <= Σ_α |n_α| is below T."""
        nk = self.nk
        mag = [[arb(0)] * nk for _ in range(nk)]
        for idx, coef in enumerate(entries):
            mag[idx // nk][idx % nk] = sum((abs(a) for a in coef), arb(0))
        rows = [sum(r, arb(0)) for r in mag]
        cols = [sum((mag[i][j] for i in range(nk)), arb(0)) for j in range(nk)]
        return all(v < T for v in rows) or all(v < T for v in cols)

    def _slow_root(self, c, T: arb) -> bool:
        """Some root of det(t I − X) outside |t| <= T on the whole box."""
        n, mono = self.n, len(c[0])

        def at(t: arb) -> list[arb]:
            return [sum((c[j][a] * t**j for j in range(n + 1)), arb(0)) for a in range(mono)]

        sign = -1 if n % 2 else 1
        det = [sign * v for v in c[0]]  # det X = (-1)^n c_0
        tn = T**n
        tests = ([-v for v in at(T)], [-sign * v for v in at(-T)],
                 [det[0] - tn, *det[1:]], [-det[0] - tn, *[-v for v in det[1:]]])
        return any(enc.poly_positive(p, self.even) for p in tests)


def _kernel(E: sp.Matrix, n: int) -> tuple[sp.Matrix, sp.Matrix]:
    """K (n x n-1) with columns spanning ker E and K^L with K^L K = I, exactly: pivot on
    the entry of E with the largest magnitude, k_i = e_i − (E_i / E_j) e_j."""
    vals = [abs(float(sp.N(E[0, i]))) for i in range(n)]
    j = int(np.argmax(vals))
    others = [i for i in range(n) if i != j]
    K = sp.zeros(n, n - 1)
    KL = sp.zeros(n - 1, n)
    for c, i in enumerate(others):
        K[i, c] = 1
        K[j, c] = -E[0, i] / E[0, j]
        KL[c, i] = 1
    return K, KL
