"""The Python API in a few functions (re-exported by :mod:`sosalgo`).

    >>> import sosalgo
    >>> spec = sosalgo.load_spec("specs/nesterov.yaml")
    >>> res = sosalgo.analyze(spec, kappa=10)          # one AnalysisResult
    >>> rows = sosalgo.analyze(spec, kappa=[2, 10])    # a list, one per kappa
    >>> check = sosalgo.verify(spec, res)              # exact proof + simulation

Specs may be given as a :class:`~sosalgo.spec.Spec` or a path. Heavy modules (the design
code, the exact verifier) are imported only when used.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sosalgo.spec import Spec, load_spec

if TYPE_CHECKING:  # pragma: no cover
    from sosalgo.analysis import AnalysisResult
    from sosalgo.design import DesignResult

__all__ = ["analyze", "design", "example", "verify", "as_spec"]


def example(name: str) -> Spec:
    """A shipped example spec by name (``sosalgo examples`` lists them), from the
    installed package: no checkout needed. ValueError names the available ones."""
    from sosalgo.resources import example_specs
    from sosalgo.spec import spec_from_text

    specs = example_specs()
    if name not in specs:
        raise ValueError(f"no example {name!r}; shipped: {', '.join(specs)}")
    return spec_from_text(specs[name].read_text(), source=f"{name}.yaml")


def as_spec(spec: Spec | str | Path) -> Spec:
    """A Spec, loading it when given a path."""
    return spec if isinstance(spec, Spec) else load_spec(spec)


def _kappas(spec: Spec, kappa: float | Sequence[float] | None) -> tuple[list[float], bool]:
    """(kappas, single): the spec's list when None; a number gives one result."""
    if kappa is None:
        return list(spec.kappa), False
    if isinstance(kappa, numbers.Real) and not isinstance(kappa, bool):
        return [float(kappa)], True
    if isinstance(kappa, str | bytes | bool):
        raise TypeError("kappa must be a number or a list of numbers")
    try:
        return [float(k) for k in kappa], False  # lists, tuples, numpy arrays
    except TypeError:
        raise TypeError("kappa must be a number or a list of numbers") from None


def analyze(
    spec: Spec | str | Path,
    kappa: float | Sequence[float] | None = None,
    theta: Mapping[str, float] | None = None,
    tol: float = 1e-6,
) -> AnalysisResult | list[AnalysisResult]:
    """Best rate certified by the spec's certificate family (Theorem 1, eq. 15-16).

    ``kappa``: a number (one :class:`AnalysisResult`), a list (a list of results, in
    order) or None (the spec's own kappa list). ``theta`` overrides parameter values.
    """
    from sosalgo.analysis import analyze_spec

    s = as_spec(spec)
    kappas, single = _kappas(s, kappa)
    results = [analyze_spec(s, k, theta, tol=tol) for k in kappas]
    return results[0] if single else results


def design(
    spec: Spec | str | Path, kappa: float | Sequence[float] | None = None, **options: Any
) -> DesignResult | list[DesignResult]:
    """Design the free parameters by sum-of-squares (eq. 17) at each kappa; ``options``
    are those of :func:`sosalgo.design.design` (free, scalarize, order, gap, time_limit)."""
    from sosalgo.design import design as design_one

    s = as_spec(spec)
    kappas, single = _kappas(s, kappa)
    results = [design_one(s, k, **options) for k in kappas]
    return results[0] if single else results


def verify(spec: Spec | str | Path, result: Any, simulate: bool = True,
           out_dir: str | Path | None = None) -> dict[str, Any] | None:
    """Exact proof (and simulation) of the certificate in ``result``: an AnalysisResult,
    a DesignResult or a row/document dict of ``--json`` output. None when the result
    claims no certificate; ``verified == "exact"`` when proven."""
    from sosalgo.verify.results import verify_document_rows

    s = as_spec(spec)
    row = result.to_dict() if hasattr(result, "to_dict") else dict(result)
    out = None if out_dir is None else Path(out_dir)
    return verify_document_rows(s, [row], out, simulate)[0]
