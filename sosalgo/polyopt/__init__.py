"""General polynomial optimization by Lasserre's moment-SOS hierarchy.

``PolyProblem`` states a POP with sympy; ``solve_moment_relaxation`` solves one moment
relaxation, detects exactness (flat extension) and extracts global minimizers
(Henrion-Lasserre). See docs/polyopt.md.
"""

from .problem import PolyProblem
from .relaxation import (
    CAUTIOUS_OPTIONS,
    DEFAULT_SOLVER_OPTIONS,
    RelaxationResult,
    RelaxationStatus,
    solve_moment_relaxation,
)

__all__ = [
    "PolyProblem",
    "RelaxationResult",
    "RelaxationStatus",
    "solve_moment_relaxation",
    "DEFAULT_SOLVER_OPTIONS",
    "CAUTIOUS_OPTIONS",
]
