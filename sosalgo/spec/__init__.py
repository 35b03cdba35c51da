"""Algorithm specs: YAML in, validated symbolic templates out.

A spec describes a first-order method in the state-space form of eq. (10) of the paper,

    xi_{k+1} = A xi_k + B grad f(y_k),   y_k = C xi_k,   x_k = E xi_k,

through the reduced templates A (n x n), B (n x 1), C and E (1 x n) of Remark 1. Modules:
:mod:`~sosalgo.spec.types` (Spec, Parameter, SpecError, parameter dependency graph) and
:mod:`~sosalgo.spec.loading` (strict YAML, validation, kappa parsing).
"""

from typing import Any

from sosalgo.spec.loading import (
    load_spec,
    parse_kappa,
    read_spec_text,
    spec_from_dict,
    spec_from_text,
)
from sosalgo.spec.types import BASE_NAMES, MATRIX_NAMES, Parameter, Spec, SpecError

# The input limits (MAX_FILE_BYTES, MAX_STATE, ...) live in sosalgo.spec.types.
__all__ = [
    "SpecError", "Parameter", "Spec", "load_spec", "read_spec_text", "spec_from_dict",
    "spec_from_text", "parse_kappa", "BASE_NAMES", "BASE_SYMBOLS", "MATRIX_NAMES",
]


def __getattr__(name: str) -> Any:
    if name == "BASE_SYMBOLS":  # sympy symbols: built on first use (see spec.types)
        from sosalgo.spec import types

        return types.BASE_SYMBOLS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
