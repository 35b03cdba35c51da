"""Theorem 1 of Fazlyab, Morari, Preciado (2018): eqs. (13)-(15).

With V_k = f(x_k) - f* + (xi_k - xi*)^T P (xi_k - xi*) (eq. 12), the rate rho is certified by
P ⪰ 0, lambda >= 0 and

    M = M0 + rho^2 M1 + (1 - rho^2) M2 + lambda M3 ⪯ 0,                         (15)
    M0 = [[A'PA - rho^2 P, A'PB], [B'PA, B'PB]],  M1 = N1 + N2,  M2 = N1 + N3,  M3 = N4.

All matrices are the reduced (d = 1) templates of Remark 1; an n-state method gives an
(n+1) x (n+1) inequality. The same code builds the numeric data and the symbolic M, so
what ``sosalgo lmi`` prints is what the solver sees.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from sosalgo.certificates.base import CertificateFamily, check_matrix, check_number
from sosalgo.kernel.conic import AffineBlock, ExactBlock, LMIProblem, sym_basis

if TYPE_CHECKING:  # only for annotations: families do not depend on the model at run time
    import sympy as sp

    from sosalgo.model import Algorithm
    from sosalgo.spec.types import Spec

__all__ = ["THEOREM1", "Theorem1", "theorem1_terms"]

PSD_FLOOR = 1e-13  # relative floor for P's eigenvalues after projection


def _blocks(rows: list[list[Any]], symbolic: bool) -> Any:
    if symbolic:
        import sympy as sp

        return sp.Matrix.vstack(*[sp.Matrix.hstack(*row) for row in rows])
    return np.block(rows)


def theorem1_terms(A, B, C, E, m, L, P, symbolic: bool = False) -> dict[str, Any]:
    """The pieces of eq. (14)-(15) for numpy arrays (``symbolic=False``) or sympy matrices.

    Returns ``M0P`` (M0 without its -rho^2 P block), ``PP`` = [[P, 0], [0, 0]] and N1..N4,
    so that M = M0P - rho^2 PP + rho^2 (N1 + N2) + (1 - rho^2)(N1 + N3) + lambda N4.
    """
    n = A.shape[0]
    if symbolic:
        import sympy as sp

        zeros, eye, half = sp.zeros, sp.eye, sp.Rational(1, 2)
    else:
        zeros, eye, half = (lambda r, c=None: np.zeros((r, c if c is not None else r))), np.eye, 0.5
    z1n, z11, one = zeros(1, n), zeros(1, 1), eye(1)

    def quad(X, Q):
        return X.T * Q * X if symbolic else X.T @ Q @ X

    mul = (lambda a, b: a * b) if symbolic else (lambda a, b: a @ b)
    M0P = _blocks(
        [[mul(mul(A.T, P), A), mul(mul(A.T, P), B)], [mul(mul(B.T, P), A), mul(mul(B.T, P), B)]],
        symbolic,
    )
    PP = _blocks([[P, zeros(n, 1)], [zeros(1, n), z11]], symbolic)

    def qmat(a, b, c):
        return sp.Matrix([[a, b], [b, c]]) if symbolic else np.array([[a, b], [b, c]], float)

    X1 = _blocks([[mul(E, A) - C, mul(E, B)], [z1n, one]], symbolic)
    X2 = _blocks([[C - E, z11], [z1n, one]], symbolic)
    X3 = _blocks([[C, z11], [z1n, one]], symbolic)
    N1 = quad(X1, qmat(L * half, half, 0))
    N2 = quad(X2, qmat(-m * half, half, 0))
    N3 = quad(X3, qmat(-m * half, half, 0))
    N4 = quad(X3, qmat(-m * L / (m + L), half, -1 / (m + L)))
    return {"M0P": M0P, "PP": PP, "N1": N1, "N2": N2, "N3": N3, "N4": N4}


class Theorem1(CertificateFamily):
    """The certificate family of Theorem 1 (eq. 15)."""

    name = "theorem1"
    description = "Theorem 1: V = f(x) - f* + (xi - xi*)' P (xi - xi*), one S-procedure multiplier"
    label = "Theorem 1"
    is_default = True
    supports_moment = True  # the moment relaxation of eq. (17) is built on M of eq. (15)
    box_lower_bound = True  # exact_problem: design proves a lower bound over the whole box
    # points the margin search cannot check are asked of Clarabel alone: there SCS (at
    # 1e-9) ran into its iteration limit or repeated an infeasible verdict, never certified
    # a point (shipped specs at kappa 2..1000, random and 16-state methods: bench/fallback.py),
    # and took up to 65 % of the time on 16-state methods. A point is certified only by a
    # checked certificate either way; plain bisection (``method="bisection"``, a custom
    # solver chain) keeps the whole chain.
    fallback_solvers = ("clarabel-fast", "clarabel")
    certificate_parts = ("P", "lambda")

    def applies_to(self, spec: Spec) -> str | None:
        """Theorem 1 holds only in the seed's setting (see :attr:`Spec.has_seed_form`)."""
        if spec.has_seed_form:
            return None
        return ("theorem1 applies only to one smooth_strongly_convex function with the "
                "spec's m and L, queried by its gradient (no D, x = E xi, measure: function); "
                "use interpolation, the family for this spec")

    def problem(self, alg: Algorithm) -> LMIProblem:
        """x = (P_ij for i <= j, lambda); blocks: M ⪯ 0, -P ⪯ 0, -lambda <= 0.

        The data are built for the normalized class F(m/L, 1) with B scaled by L: with
        u = L u~, M(P, lambda) = L D^-1 M~(P/L, lambda) D^-1, D = diag(I, L), a congruence,
        so both inequalities hold together. ``unpack`` returns the original (P, lambda).
        Only in the seed's setting: a method of the oracle model is refused (InputError).
        """
        if not alg.has_seed_form:
            from sosalgo.errors import InputError

            raise InputError("certificate theorem1: applies only to one smooth_strongly_convex "
                             "function queried by its gradient; use interpolation")
        n = alg.n
        pairs = sym_basis(n)
        nvar = len(pairs) + 1
        s_ = alg.L
        A, B, C, E, m, L = alg.A, alg.B * s_, alg.C, alg.E, alg.m / s_, 1.0
        zero_p = np.zeros((n, n))
        base = theorem1_terms(A, B, C, E, m, L, zero_p)
        s = n + 1
        c0 = base["N1"] + base["N3"]  # (1 - rho^2)(N1 + N3) + rho^2 (N1 + N2)
        c1 = base["N2"] - base["N3"]
        l0 = np.zeros((nvar, s, s))
        l1 = np.zeros((nvar, s, s))
        lp = np.zeros((nvar, n, n))
        for k, (i, j) in enumerate(pairs):
            Eij = np.zeros((n, n))
            Eij[i, j] = Eij[j, i] = 1.0
            t = theorem1_terms(A, B, C, E, m, L, Eij)
            l0[k] = t["M0P"]
            l1[k] = -t["PP"]
            lp[k] = -Eij
        l0[-1] = base["N4"]
        lam = np.zeros((nvar, 1, 1))
        lam[-1, 0, 0] = -1.0
        blocks = (
            AffineBlock("M", c0, c1, l0, l1),
            AffineBlock("P", np.zeros((n, n)), np.zeros((n, n)), lp, np.zeros_like(lp), False),
            AffineBlock(
                "lambda", np.zeros((1, 1)), np.zeros((1, 1)), lam, np.zeros_like(lam), False
            ),
        )

        def project(x: np.ndarray) -> np.ndarray:
            Pn = np.zeros((n, n))
            for k, (i, j) in enumerate(pairs):
                Pn[i, j] = Pn[j, i] = x[k]
            w, V = np.linalg.eigh(Pn)
            floor = PSD_FLOOR * max(1.0, float(np.abs(w).max()))
            Pn = (V * np.maximum(w, floor)) @ V.T
            return np.array([Pn[i, j] for i, j in pairs] + [max(float(x[-1]), 0.0)])

        def unpack(x: np.ndarray) -> dict[str, Any]:
            P = np.zeros((n, n))
            for k, (i, j) in enumerate(pairs):
                P[i, j] = P[j, i] = x[k] * s_
            return {"P": P, "lambda": float(x[-1])}

        return LMIProblem(nvar, blocks, unpack, project)

    def exact_problem(self, A, B, C, E, m, L) -> list[ExactBlock]:
        """The blocks of :meth:`problem` with sympy entries (A..E may hold symbols): the
        same variables, normalization (F(m/L, 1), B scaled by L) and block order."""
        import sympy as sp

        n = A.shape[0]
        pairs = sym_basis(n)
        nvar = len(pairs) + 1
        B, m, L = B * L, m / L, sp.Integer(1)
        base = theorem1_terms(A, B, C, E, m, L, sp.zeros(n, n), symbolic=True)
        zs, z1 = sp.zeros(n + 1, n + 1), sp.zeros(1, 1)
        G = sp.Matrix.hstack(A, B)  # M0P(P) = G' P G for P = E_ij: rows i and j of G
        l0, l1, lp, lam = [], [], [], []
        for i, j in pairs:
            Eij = sp.zeros(n, n)
            Eij[i, j] = Eij[j, i] = 1
            gi, gj = G[i, :], G[j, :]
            l0.append(gi.T * gi if i == j else gi.T * gj + gj.T * gi)
            pp = sp.zeros(n + 1, n + 1)
            pp[i, j] = pp[j, i] = -1
            l1.append(pp)
            lp.append(-Eij)
            lam.append(z1)
        l0.append(base["N4"])
        l1.append(zs)
        lp.append(sp.zeros(n, n))
        lam.append(-sp.ones(1, 1))
        assert len(l0) == nvar
        return [ExactBlock("M", base["N1"] + base["N3"], base["N2"] - base["N3"], l0, l1),
                ExactBlock("P", sp.zeros(n, n), sp.zeros(n, n), lp, [sp.zeros(n, n)] * nvar,
                           False),
                ExactBlock("lambda", z1, z1, lam, [z1] * nvar, False)]

    def pack(self, alg: Algorithm, cert: dict[str, Any]) -> np.ndarray:
        """Inverse of ``unpack``: the (normalized) decision vector of a certificate."""
        P = np.asarray(cert["P"], dtype=float) / alg.L
        n = P.shape[0]
        return np.array([P[i, j] for i, j in sym_basis(n)] + [float(cert["lambda"])])

    def matrix(self, alg: Algorithm, rho: float, cert: dict[str, Any]) -> np.ndarray:
        """M of eq. (15) at a numeric (P, lambda)."""
        t = theorem1_terms(alg.A, alg.B, alg.C, alg.E, alg.m, alg.L, np.asarray(cert["P"]))
        r2 = rho**2
        return (
            t["M0P"] - r2 * t["PP"] + r2 * (t["N1"] + t["N2"]) + (1 - r2) * (t["N1"] + t["N3"])
            + cert["lambda"] * t["N4"]
        )

    def symbolic(self, A, B, C, E, m, L) -> tuple[sp.Matrix, dict[str, Any]]:
        """Symbolic M(theta, rho, lambda, P) of eq. (15) with P = [p_ij] symmetric."""
        import sympy as sp

        n = A.shape[0]
        P = sp.zeros(n, n)
        for i, j in sym_basis(n):
            name = "p" if n == 1 else f"p{i + 1}{j + 1}"
            P[i, j] = P[j, i] = sp.Symbol(name, real=True)
        rho, lam = sp.symbols("rho lambda", nonnegative=True)
        t = theorem1_terms(A, B, C, E, m, L, P, symbolic=True)
        r2 = rho**2
        M = (
            t["M0P"] - r2 * t["PP"] + r2 * (t["N1"] + t["N2"]) + (1 - r2) * (t["N1"] + t["N3"])
            + lam * t["N4"]
        )
        M = M.applyfunc(lambda e: sp.factor_terms(sp.expand(e)))
        return M, {"P": P, "rho": rho, "lambda": lam, "terms": t}

    # -- verification (sosalgo verify) ---------------------------------------------------
    def parse_certificate(self, parts: Mapping[str, Any], n: int) -> dict[str, Any]:
        """(P, lambda) of a result row: P an n x n matrix of numbers, lambda a number."""
        return {"P": check_matrix(parts.get("P"), n, "P"),
                "lambda": check_number(parts.get("lambda"), "lambda")}

    def exact_check(self, spec: Spec, kappa: float, rho: float, cert: Mapping[str, Any],
                    theta: Mapping[str, float] | None = None) -> Any:
        """Exact rational proof of eq. (15)
        (:func:`sosalgo.certificates.exact_theorem1.verify_exact`)."""
        from sosalgo.certificates.exact_theorem1 import verify_exact

        return verify_exact(spec, kappa, rho, np.asarray(cert["P"], dtype=float),
                            cert["lambda"], theta)

    def lyapunov(self, cert: Mapping[str, Any]) -> dict[str, Any]:
        """V = f(x) - f* + (xi - xi*)' P (xi - xi*) of eq. (12): P is all it needs."""
        return {"P": np.asarray(cert["P"], dtype=float)}


THEOREM1 = Theorem1()
