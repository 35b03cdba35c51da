"""The exact checks' public path: Theorem 1's exact verification
(:mod:`sosalgo.certificates.exact_theorem1`) and the exact method
(:mod:`sosalgo.exact_method`), importable from here as documented."""

from sosalgo.certificates.exact_theorem1 import (
    ExactResult,
    ProofResult,
    theorem1_exact,
    verify_exact,
    write_certificate,
)
from sosalgo.exact_method import ExactAlgorithm, exact_algorithm, exact_fixed_point

__all__ = ["ExactAlgorithm", "ExactResult", "ProofResult", "exact_algorithm", "exact_fixed_point",
           "theorem1_exact", "verify_exact", "write_certificate"]
