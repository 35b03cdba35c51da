"""A test certificate family: Theorem 1 with a diagonal P (a strict subset of Theorem 1).

It exists to show that a family plugs in through one module and one registry line
(``register_family(DIAGONAL)``) and then runs through analyze, design, verify and the
CSV/JSON writers. P ⪰ 0 is stated as n scalar cones p_i >= 0. A diagonal-P certificate is a
Theorem 1 certificate, so its exact check and its Lyapunov function are Theorem 1's; only
reading a certificate adds a check of its own (P must be diagonal).

Its one option, ``uniform`` (``certificate: {family: theorem1-diagonal, uniform: true}``),
asks for P = p I (one unknown for the whole diagonal): it shows that a family's options
reach the workers, the settings and the file names of batch runs.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from sosalgo.certificates.base import CertificateFamily
from sosalgo.certificates.theorem1 import THEOREM1, theorem1_terms
from sosalgo.kernel.conic import AffineBlock, ExactBlock, LMIProblem


class DiagonalTheorem1(CertificateFamily):
    name = "theorem1-diagonal"
    description = "Theorem 1 with a diagonal P (test family)"
    label = "Theorem 1, diagonal P"
    is_default = False
    supports_moment = False
    certificate_parts = ("P", "lambda")
    option_names = ("uniform",)
    uniform: bool | None = None  # P = p I (None: the default, False)

    def with_options(self, uniform: bool | None = None) -> DiagonalTheorem1:
        if uniform is not None and not isinstance(uniform, bool):
            raise ValueError("uniform: must be true or false")
        fam = DiagonalTheorem1()
        fam.uniform = uniform
        return fam

    def _groups(self, n: int) -> list[list[int]]:
        """The diagonal entries each unknown of P stands for."""
        return [list(range(n))] if self.uniform else [[i] for i in range(n)]

    def problem(self, alg) -> LMIProblem:
        n, s_ = alg.n, alg.L
        A, B, C, E, m, L = alg.A, alg.B * s_, alg.C, alg.E, alg.m / s_, 1.0
        base = theorem1_terms(A, B, C, E, m, L, np.zeros((n, n)))
        groups = self._groups(n)
        nvar, s = len(groups) + 1, n + 1
        l0, l1 = np.zeros((nvar, s, s)), np.zeros((nvar, s, s))
        cones = []
        for i, group in enumerate(groups):
            Ei = np.diag([1.0 if k in group else 0.0 for k in range(n)])
            t = theorem1_terms(A, B, C, E, m, L, Ei)
            l0[i], l1[i] = t["M0P"], -t["PP"]
            sel = np.zeros((nvar, 1, 1))
            sel[i, 0, 0] = -1.0
            cones.append(AffineBlock(f"p{i + 1}", np.zeros((1, 1)), np.zeros((1, 1)), sel,
                                     np.zeros_like(sel), False))
        l0[-1] = base["N4"]
        lam = np.zeros((nvar, 1, 1))
        lam[-1, 0, 0] = -1.0
        blocks = (AffineBlock("M", base["N1"] + base["N3"], base["N2"] - base["N3"], l0, l1),
                  *cones, AffineBlock("lambda", np.zeros((1, 1)), np.zeros((1, 1)), lam,
                                      np.zeros_like(lam), False))

        def project(x: np.ndarray) -> np.ndarray:
            return np.maximum(x, 0.0)

        def unpack(x: np.ndarray) -> dict[str, Any]:
            diag = [x[i] * s_ for i, group in enumerate(groups) for _ in group]
            return {"P": np.diag(diag), "lambda": float(x[-1])}

        return LMIProblem(nvar, blocks, unpack, project)

    def exact_problem(self, A, B, C, E, m, L) -> list[ExactBlock]:
        """The blocks of ``problem`` with sympy entries (design's proven bound)."""
        import sympy as sp

        n = A.shape[0]
        B, m, L = B * L, m / L, sp.Integer(1)
        base = theorem1_terms(A, B, C, E, m, L, sp.zeros(n, n), symbolic=True)
        groups = self._groups(n)
        nvar, z1 = len(groups) + 1, sp.zeros(1, 1)
        l0, l1 = [], []
        for group in groups:
            Ei = sp.diag(*[1 if k in group else 0 for k in range(n)])
            t = theorem1_terms(A, B, C, E, m, L, Ei, symbolic=True)
            l0.append(t["M0P"])
            l1.append(-t["PP"])
        l0.append(base["N4"])
        l1.append(sp.zeros(n + 1, n + 1))

        def scalar(j: int, name: str) -> ExactBlock:
            sel = [-sp.ones(1, 1) if v == j else z1 for v in range(nvar)]
            return ExactBlock(name, z1, z1, sel, [z1] * nvar, False)

        return [ExactBlock("M", base["N1"] + base["N3"], base["N2"] - base["N3"], l0, l1),
                *(scalar(i, f"p{i + 1}") for i in range(len(groups))),
                scalar(len(groups), "lambda")]

    def matrix(self, alg, rho: float, cert: dict[str, Any]) -> np.ndarray:
        return THEOREM1.matrix(alg, rho, cert)

    def symbolic(self, A, B, C, E, m, L):
        return THEOREM1.symbolic(A, B, C, E, m, L)

    def parse_certificate(self, parts: Mapping[str, Any], n: int) -> dict[str, Any]:
        cert = THEOREM1.parse_certificate(parts, n)
        P = cert["P"]
        if P is not None and any(P[i][j] != 0 for i in range(n) for j in range(n) if i != j):
            raise ValueError("P: expected a diagonal matrix")
        if P is not None and self.uniform and len({P[i][i] for i in range(n)}) > 1:
            raise ValueError("P: expected a multiple of the identity (uniform)")
        return cert

    def exact_check(self, spec, kappa, rho, cert, theta=None):
        return THEOREM1.exact_check(spec, kappa, rho, cert, theta)

    def lyapunov(self, cert: Mapping[str, Any]) -> dict[str, Any]:
        return THEOREM1.lyapunov(cert)


DIAGONAL = DiagonalTheorem1()
