"""The PEP of the parametric model (:mod:`sosalgo.design.steps_model`) at one point θ:
its value and gradient in θ (for the schedule search) and a dual certificate proven
exactly (an upper bound tau_N(θ) <= tau_proven, for methods ``sosalgo pep`` does not
bind yet).

Primal: max F_N (+ eps tr G, the margin) subject to G_00 <= 1, G ⪰ 0 and, for every pair
k = (i, j), F_i - F_j + <P_k(θ), G> >= 0 with P_k(θ) = sum_alpha θ^alpha Q_{k,alpha}.
Dual: lambda >= 0, tau with e_N + sum_k lambda_k (e_i - e_j) = 0 (x* left out) and
S = tau E_00 - sum_k lambda_k P_k(θ) ⪰ 0; then every feasible (G, F) has
F_N <= <sum lambda_k P_k, G> <= tau G_00 <= tau (weak duality). The gradient of the value
in θ is sum_k lambda_k <dP_k/dθ, G> at the optimum (the envelope theorem; a
subgradient where the optimum is not unique).

The proof rounds lambda to rationals >= 0, repairs the balance of each point exactly on
its pair with x* (which touches no other point's balance), and checks S positive
definite exactly (a Cholesky factorization in rationals): the margin eps tr G of the
solve makes S ⪰ eps I, room for the rounding.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.design.steps_model import ParametricPEP
from sosalgo.kernel.solvers import SolverStatus, cvxpy_solve

__all__ = ["PointPEP", "positive_definite"]

# relative margins eps / tau of the certificate's solves, in order (tau_proven is about
# eps tr G above tau): the first whose rounded certificate is proven
MARGINS = (1e-7, 1e-6, 1e-5)
TIGHT = {"tol_gap_abs": 1e-11, "tol_gap_rel": 1e-11, "tol_feas": 1e-11}


class PointPEP:
    """The PEP of ``pp`` at one θ (floating point, cvxpy), see the module."""

    def __init__(self, pp: ParametricPEP):
        import cvxpy as cp

        self.pp = pp
        K, A, d = len(pp.pairs), len(pp.monomials), pp.d
        self.forms = pp.float_forms().reshape(K, A, d * d)
        self.G = cp.Variable((d, d), PSD=True)
        self.F = cp.Variable(pp.npts)
        self.P = cp.Parameter((K, d * d))
        self.eps = cp.Parameter(nonneg=True)
        diff = pp.value_differences()
        self.pairs_con = diff @ self.F + self.P @ cp.vec(self.G, order="C") >= 0
        self.norm_con = self.G[0, 0] <= 1
        self.problem = cp.Problem(
            cp.Maximize(self.F[pp.measure_point] + self.eps * cp.trace(self.G)),
            [self.pairs_con, self.norm_con])
        self.exps = np.array(pp.monomials, dtype=float)  # (A, p)

    def _monomials(self, theta: np.ndarray) -> np.ndarray:
        return np.prod(np.power(theta[None, :], self.exps), axis=1)

    def _dmonomials(self, theta: np.ndarray) -> np.ndarray:
        """(A, p): the derivative of each monomial in each θ_i."""
        out = np.zeros_like(self.exps)
        for i in range(self.exps.shape[1]):
            e = self.exps.copy()
            c = e[:, i].copy()
            e[:, i] = np.maximum(e[:, i] - 1, 0)
            out[:, i] = c * np.prod(np.power(theta[None, :], e), axis=1)
        return out

    def solve(self, theta: Sequence[float], eps: float = 0.0, tight: bool = False
              ) -> dict[str, Any] | None:
        """value, G, lam (K), tau at θ (None when the solve fails); ``tight``: Clarabel
        at tight tolerances (the certificates)."""
        th = np.asarray(theta, float)
        self.P.value = np.einsum("a,kaj->kj", self._monomials(th), self.forms)
        self.eps.value = eps
        end = cvxpy_solve(self.problem, "CLARABEL", **(TIGHT if tight else {}))
        if end.status not in (SolverStatus.SOLVED, SolverStatus.ALMOST_SOLVED) \
                or self.G.value is None:
            return None
        return {"value": float(self.F.value[self.pp.measure_point]),
                "G": np.array(self.G.value), "lam": np.maximum(
                    np.asarray(self.pairs_con.dual_value, float), 0.0),
                "tau": float(self.norm_con.dual_value)}

    def value_grad(self, theta: Sequence[float]) -> tuple[float, np.ndarray]:
        """The PEP value at θ and its gradient (inf and zeros when the solve fails)."""
        th = np.asarray(theta, float)
        sol = self.solve(th)
        if sol is None:
            return math.inf, np.zeros(len(th))
        g = sol["G"].reshape(-1)
        inner = np.einsum("kaj,j->ka", self.forms, g)  # <Q_{k,a}, G>
        grad = (sol["lam"] @ inner) @ self._dmonomials(th)
        return sol["value"], grad

    def prove(self, theta: Sequence[Fraction]) -> Fraction | None:
        """tau_proven >= tau_N(θ) at the exact θ (see the module), or None."""
        th = [Fraction(x) for x in theta]
        sol = self.solve([float(x) for x in th])
        if sol is None:
            return None
        scale = max(sol["value"], 1e-300)
        for rel in MARGINS:
            for tight in (False, True):
                cand = self.solve([float(x) for x in th], rel * scale, tight)
                if cand is None:
                    continue
                lam = self._balanced([Fraction(float(v)) for v in cand["lam"]])
                tau = Fraction(cand["tau"])
                if positive_definite(self._slack(th, lam, tau)):
                    return tau
        return None

    def _balanced(self, lam: list[Fraction]) -> list[Fraction]:
        """lambda with every point's balance e_N + sum lambda_k (e_i - e_j) = 0 exact,
        repaired on the pairs with x* (nonnegative)."""
        pp = self.pp
        star = pp.npts
        res = [Fraction(0)] * pp.npts
        res[pp.measure_point] += 1
        index = {}
        for k, (i, j) in enumerate(pp.pairs):
            if i < star:
                res[i] += lam[k]
            if j < star:
                res[j] -= lam[k]
            index[(i, j)] = k
        for v in range(star):
            r = res[v]
            if r < 0:
                lam[index[(v, star)]] -= r  # (v, *) adds lambda to v's balance
            elif r > 0:
                lam[index[(star, v)]] += r  # (*, v) takes it away
        return lam

    def _slack(self, theta: list[Fraction], lam: list[Fraction], tau: Fraction
               ) -> list[list[Fraction]]:
        pp = self.pp
        d = pp.d
        S = [[Fraction(0)] * d for _ in range(d)]
        S[0][0] = tau
        mono = {e: math.prod((t ** k for t, k in zip(theta, e, strict=True)),
                             start=Fraction(1)) for e in pp.monomials}
        for k, form in enumerate(pp.forms):
            if not lam[k]:
                continue
            for e, M in form.items():
                c = lam[k] * mono[e]
                if not c:
                    continue
                for r in range(d):
                    for s in range(d):
                        if M[r, s]:
                            S[r][s] -= c * M[r, s]
        return S


def positive_definite(S: list[list[Fraction]]) -> bool:
    """Exact: every pivot of the Cholesky (LDL') factorization is positive."""
    n = len(S)
    M = [row[:] for row in S]
    for i in range(n):
        piv = M[i][i]
        if piv <= 0:
            return False
        for r in range(i + 1, n):
            f = M[r][i] / piv
            if f:
                for c in range(i + 1, n):
                    M[r][c] -= f * M[i][c]
    return True
