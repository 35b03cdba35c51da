"""The checks a parsed spec still has to pass that the spec package cannot make itself.

The loader (:mod:`sosalgo.spec.loading`) parses a spec and checks its structure: fields,
names, shapes, expressions, ranges that are constants. Three checks need more, and live in
the layers that own what they ask:

- ``oracles``: each oracle call's kind is one its function class answers (the oracle model,
  :func:`sosalgo.oracles.check_oracle_spec`);
- ``certificate``: the ``certificate:`` field names a registered family, its options are
  ones the family accepts, and the family applies to the spec (the families' layer,
  :func:`sosalgo.certificates.spec_field.check_certificate_field`);
- ``values``: at every kappa of the spec the method binds (a fixed point exists), the
  references are numbers, each parameter lies in its range, and ``initial_state:`` starts
  at the fixed point (:func:`sosalgo.spec_values.check_values`).

They run in that order (:data:`STAGES`), after the structure, every time a spec is loaded.
The package's root module (``sosalgo/__init__.py``, which Python runs before any submodule)
provides them through :func:`provide_checks`, so the checks never depend on which modules
happen to have been imported; a load with a stage missing is refused, not passed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # only for annotations
    from sosalgo.spec.types import Spec

__all__ = ["STAGES", "SpecCheck", "provide_checks", "run_checks"]

# a check: (the parsed spec, the spec's YAML mapping, fail(field, message) -> the error to
# raise) -> the spec with what the check settled (or None: the spec as it was)
SpecCheck = Callable[["Spec", Mapping[str, Any], Callable[[str, str], Exception]],
                     "Spec | None"]

STAGES: tuple[str, ...] = ("oracles", "certificate", "values")

# the provider (set once, by sosalgo/__init__.py) and the checks it returned (on first use)
_PROVIDER: list[Callable[[], Mapping[str, SpecCheck]]] = []
_CHECKS: list[Mapping[str, SpecCheck]] = []


def provide_checks(provider: Callable[[], Mapping[str, SpecCheck]]) -> None:
    """Set the function that returns the checks of :data:`STAGES` (called on the first load,
    so that the modules holding them are imported only when a spec is loaded)."""
    _PROVIDER[:] = [provider]
    _CHECKS.clear()


def _checks() -> Mapping[str, SpecCheck]:
    if not _CHECKS:
        if not _PROVIDER:
            raise RuntimeError("no spec checks provided (sosalgo/__init__.py provides them)")
        checks = _PROVIDER[0]()
        missing = [s for s in STAGES if s not in checks]
        if missing:
            raise RuntimeError(f"spec checks missing: {', '.join(missing)}")
        _CHECKS.append(checks)
    return _CHECKS[0]


def run_checks(spec: Spec, data: Mapping[str, Any],
               fail: Callable[[str, str], Exception]) -> Spec:
    """``spec`` after every check of :data:`STAGES`, in order (the first failure raises)."""
    checks = _checks()
    for stage in STAGES:
        checked = checks[stage](spec, data, fail)
        spec = spec if checked is None else checked
    return spec
