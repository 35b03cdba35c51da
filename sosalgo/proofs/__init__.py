"""Independent verification of Theorem 1 certificates.

- :func:`verify_exact`: a proof in exact rational arithmetic (with rigorous enclosures of
  irrational parameters) that (rho, P, lambda) satisfies Theorem 1 (eq. 15).
- :func:`simulate_check`: runs the method on functions of F(m, L) (:func:`function_suite`)
  and checks V_{k+1} <= rho^2 V_k along trajectories (evidence, or a counterexample).
"""

from sosalgo.proofs.exact import (
    ExactAlgorithm,
    ExactResult,
    exact_algorithm,
    theorem1_exact,
    verify_exact,
    write_certificate,
)
from sosalgo.proofs.functions import (
    Objective,
    function_suite,
    huber_like,
    logsumexp,
    lrp_counterexample,
    quadratic,
)
from sosalgo.proofs.simulate import SimulationResult, Violation, simulate_check

__all__ = [
    "ExactAlgorithm",
    "ExactResult",
    "Objective",
    "SimulationResult",
    "Violation",
    "exact_algorithm",
    "function_suite",
    "huber_like",
    "logsumexp",
    "lrp_counterexample",
    "quadratic",
    "simulate_check",
    "theorem1_exact",
    "verify_exact",
    "write_certificate",
]
