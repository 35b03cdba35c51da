"""Analysis: the best rate a certificate family certifies for fixed parameters (eq. 16).

For fixed rho the inequality of Theorem 1 is an LMI in (P, lambda); bisection on rho in
[0, 1] returns the smallest rho found feasible, with its certificate. Only a step the
solver reports *solved* and whose point passes the eigenvalue check counts as feasible
(see :mod:`sosalgo.solvers`), so a reported rate always comes with a checked certificate.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sosalgo.certificates import get_family
from sosalgo.certificates.base import CertificateFamily
from sosalgo.model import Algorithm, bind
from sosalgo.solvers import DEFAULT_SOLVERS, Outcome, solve_lmi
from sosalgo.spec import Spec

__all__ = ["AnalysisResult", "analyze_algorithm", "analyze_spec", "DEFAULT_TOL"]

DEFAULT_TOL = 1e-6


@dataclass(frozen=True)
class AnalysisResult:
    """Best certified rate and its certificate (P, lambda) for one algorithm."""

    kappa: float
    rho: float | None  # None when not even rho = 1 is certified
    certified: bool
    P: np.ndarray | None
    lam: float | None
    max_eig_M: float | None
    min_eig_P: float | None
    solves: int
    seconds: float
    solver: str | None  # which solver produced the returned certificate
    rho_infeasible: float | None = None  # largest rho found infeasible (lower end of bracket)
    params: dict[str, float] = field(default_factory=dict)
    family: str = "theorem1"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the `rows` entries of ``sosalgo analyze --json``)."""
        return {
            "kappa": self.kappa,
            "rho": self.rho,
            "certified": self.certified,
            "P": None if self.P is None else self.P.tolist(),
            "lambda": self.lam,
            "max_eig_M": self.max_eig_M,
            "min_eig_P": self.min_eig_P,
            "solves": self.solves,
            "seconds": self.seconds,
            "solver": self.solver,
            "rho_infeasible": self.rho_infeasible,
            "params": dict(self.params),
            "family": self.family,
        }


def analyze_algorithm(
    alg: Algorithm,
    tol: float = DEFAULT_TOL,
    family: CertificateFamily | str = "theorem1",
    solvers: Sequence[str] = DEFAULT_SOLVERS,
) -> AnalysisResult:
    """Bisection on rho in [0, 1] to width ``tol`` (eq. 16)."""
    if not tol > 0:
        raise ValueError("tol must be positive")
    fam = get_family(family) if isinstance(family, str) else family
    start = time.perf_counter()
    problem = fam.problem(alg)
    solves = 0

    def test(rho: float) -> Outcome:
        nonlocal solves
        solves += 1
        return solve_lmi(problem, rho, solvers)

    best = test(1.0)
    if not best.feasible:
        return AnalysisResult(
            kappa=alg.kappa, rho=None, certified=False, P=None, lam=None, max_eig_M=None,
            min_eig_P=None, solves=solves, seconds=time.perf_counter() - start, solver=None,
            rho_infeasible=1.0, params=dict(alg.params), family=fam.name,
        )
    lo, hi = 0.0, 1.0
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        out = test(mid)
        if out.feasible:
            hi, best = mid, out
        else:
            lo = mid
    assert best.x is not None
    cert = problem.unpack(best.x)
    M = fam.matrix(alg, hi, cert)
    P = np.asarray(cert["P"])
    return AnalysisResult(
        kappa=alg.kappa, rho=hi, certified=True, P=P, lam=float(cert["lambda"]),
        max_eig_M=float(np.linalg.eigvalsh(M)[-1]), min_eig_P=float(np.linalg.eigvalsh(P)[0]),
        solves=solves, seconds=time.perf_counter() - start, solver=best.solver,
        rho_infeasible=lo, params=dict(alg.params), family=fam.name,
    )


def analyze_spec(
    spec: Spec,
    kappa: float,
    theta: Mapping[str, float] | None = None,
    tol: float = DEFAULT_TOL,
    solvers: Sequence[str] = DEFAULT_SOLVERS,
) -> AnalysisResult:
    """Analysis of a spec at one kappa (parameters at their values unless set by theta)."""
    return analyze_algorithm(bind(spec, kappa, theta), tol, spec.certificate, solvers)
