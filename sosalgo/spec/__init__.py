"""Algorithm specs: YAML in, validated symbolic templates out.

A spec describes a first-order method in the state-space form of eq. (10) of the paper,

    xi_{k+1} = A xi_k + B grad f(y_k),   y_k = C xi_k,   x_k = E xi_k,

through the reduced templates A (n x n), B (n x 1), C and E (1 x n) of Remark 1. Modules:
:mod:`~sosalgo.spec.types` (Spec, Parameter, SpecError, parameter dependency graph),
:mod:`~sosalgo.spec.loading` (strict YAML, structure, kappa parsing) and
:mod:`~sosalgo.spec.checks` (the checks each load runs that bind the spec or ask its
certificate family, provided by the layers that own them).
"""

from typing import Any

# The input limits (MAX_FILE_BYTES, MAX_STATE, ...) live in sosalgo.spec.types. Names are
# imported on first use: sosalgo's root module provides the loader's checks
# (sosalgo.spec.checks) without loading YAML, numpy or sympy.
_EXPORTS = {
    "load_spec": "loading", "parse_kappa": "loading", "read_spec_text": "loading",
    "spec_from_dict": "loading", "spec_from_text": "loading",
    "BASE_NAMES": "types", "BASE_SYMBOLS": "types", "MATRIX_NAMES": "types",
    "Parameter": "types", "Spec": "types", "SpecError": "types",
}
__all__ = [
    "SpecError", "Parameter", "Spec", "load_spec", "read_spec_text", "spec_from_dict",
    "spec_from_text", "parse_kappa", "BASE_NAMES", "BASE_SYMBOLS", "MATRIX_NAMES",
]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:  # BASE_SYMBOLS: sympy symbols, built on first use (see spec.types)
        from importlib import import_module

        return getattr(import_module(f"sosalgo.spec.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
