"""sosalgo: certify and design first-order methods for L-smooth, m-strongly convex functions.

The Python API (see docs/api.md): :func:`load_spec`, :func:`analyze`,
:func:`design`, :func:`verify`, the twins of the commands (:func:`analyze_run`,
:func:`design_run`, :func:`grid_run`, :func:`verify_document`, :func:`lmi`,
:func:`table1_run`, :func:`copy_examples`), and the result types :class:`AnalysisResult`,
:class:`DesignResult`, :class:`ExactResult`, plus :class:`Spec` and :class:`Algorithm`.
Everything is imported on first use, so ``import sosalgo`` stays fast.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

from sosalgo.spec.checks import provide_checks

__version__ = "0.1.0"


def _spec_checks() -> dict[str, Any]:
    """The checks every spec load runs after parsing (:data:`sosalgo.spec.checks.STAGES`),
    each from the layer that owns it. Provided here, by the module Python runs before any
    of sosalgo's, so that a load never depends on what was imported; imported on the first
    load, so that ``import sosalgo`` stays fast."""
    from sosalgo.certificates.spec_field import check_certificate_field
    from sosalgo.oracles import check_oracle_spec
    from sosalgo.spec_values import check_values

    return {"oracles": lambda spec, data, fail: check_oracle_spec(spec, fail),
            "certificate": check_certificate_field, "values": check_values}


provide_checks(_spec_checks)

_EXPORTS = {
    "load_spec": "sosalgo.spec",
    "spec_from_text": "sosalgo.spec",
    "Spec": "sosalgo.spec",
    "SpecError": "sosalgo.spec",
    "Algorithm": "sosalgo.model",
    "ModelError": "sosalgo.model",
    "bind": "sosalgo.model",
    "analyze": "sosalgo.api",
    "example": "sosalgo.api",
    "copy_examples": "sosalgo.api",
    "lmi": "sosalgo.api",
    "analyze_run": "sosalgo.runs",
    "design_run": "sosalgo.runs",
    "grid_run": "sosalgo.runs",
    "table1_run": "sosalgo.runs",
    "verify_document": "sosalgo.documents",
    "read_result": "sosalgo.documents",
    "InputError": "sosalgo.errors",
    "set_max_memory": "sosalgo.kernel.budget",
    "prove_bound": "sosalgo.design_search",
    "design": "sosalgo.api",
    "verify": "sosalgo.api",
    "pep": "sosalgo.api",
    "verify_exact": "sosalgo.proofs.exact",
    "simulate_check": "sosalgo.proofs",
    "write_certificate": "sosalgo.proofs",
    "pep_run": "sosalgo.runs.pep",
    "pareto_run": "sosalgo.runs.pareto",
    "steps_design_run": "sosalgo.runs.steps_design",
    "noise": "sosalgo.api",
    "AnalysisResult": "sosalgo.analysis",
    "analyze_algorithm": "sosalgo.analysis",
    "DesignResult": "sosalgo.design_search",
    "ExactResult": "sosalgo.proofs.exact",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'sosalgo' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
