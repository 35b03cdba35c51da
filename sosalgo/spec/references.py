"""The closed-form reference rates a spec names (``references:``), evaluated at kappa: the
Table 1 column, the dashed curves of the figures, the ``references`` of documents."""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np

from sosalgo.kernel.expr.compile import compile_expression
from sosalgo.spec.types import BASE_NAMES, Spec

__all__ = ["reference_curves", "reference_values"]

_REFERENCES: weakref.WeakKeyDictionary[Spec, dict[str, Any]] = weakref.WeakKeyDictionary()


def _reference_fns(spec: Spec) -> dict[str, Any]:
    """The spec's references compiled once (None for one that cannot be compiled)."""
    fns = _REFERENCES.get(spec)
    if fns is None:
        fns = {}
        for name, expr in spec.references.items():
            try:
                fns[name] = compile_expression(expr, BASE_NAMES)
            except ValueError:
                fns[name] = None
        _REFERENCES[spec] = fns
    return fns


def reference_values(spec: Spec, kappa: float) -> dict[str, float | None]:
    """Closed-form reference rates at kappa, the values beside an analysis or a design
    (None where not defined, and for a reference that ``pep.references`` names: a value
    of pep's question, the spec's measure after N steps, not of the rate or constant)."""
    out: dict[str, float | None] = {}
    m, L = spec.mL(kappa)
    pep_only = set(spec.pep.get("references", ()))
    for name, fn in _reference_fns(spec).items():
        try:
            out[name] = None if fn is None or name in pep_only else fn([m, L, kappa])
        except ValueError:
            out[name] = None
    return out


def reference_curves(
    spec: Spec, kappas: Sequence[float], points: int = 400
) -> tuple[list[float], dict[str, list[float | None]]] | None:
    """The references on a fine kappa grid spanning ``kappas`` (log-spaced over a decade or
    more, else linear), for smooth curves in figures; None for fewer than two kappas."""
    ks = [float(k) for k in kappas]
    if len(set(ks)) < 2:
        return None
    lo, hi = min(ks), max(ks)
    grid = np.geomspace(lo, hi, points) if hi >= 10 * lo else np.linspace(lo, hi, points)
    grid = np.union1d(grid, ks)  # the data kappas stay on the curve
    out: dict[str, list[float | None]] = {name: [] for name in spec.references}
    for k in grid:
        for name, v in reference_values(spec, float(k)).items():
            out[name].append(v)
    return [float(k) for k in grid], out
