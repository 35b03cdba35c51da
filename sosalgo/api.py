"""The Python API in a few functions (re-exported by :mod:`sosalgo`).

    >>> import sosalgo
    >>> spec = sosalgo.load_spec("specs/nesterov.yaml")
    >>> res = sosalgo.analyze(spec, kappa=10)          # one AnalysisResult
    >>> rows = sosalgo.analyze(spec, kappa=[2, 10])    # a list, one per kappa
    >>> check = sosalgo.verify(spec, res)              # exact proof + simulation

Specs may be given as a :class:`~sosalgo.spec.Spec` or a path. Heavy modules (the design
code, the exact verifier) are imported only when used. Every command has a twin here
(``analyze_run``, ``design_run``, ``grid_run``, ``verify_document``, ``lmi``,
``table1_run``, ``example``/``copy_examples``): the command line only parses and prints.
Bad input raises ValueError (:class:`~sosalgo.errors.InputError`) naming the field.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sosalgo.spec import Spec, load_spec

if TYPE_CHECKING:  # pragma: no cover
    from sosalgo.analysis import AnalysisResult
    from sosalgo.design_search import DesignResult

__all__ = ["analyze", "as_spec", "copy_examples", "design", "example", "lmi", "noise",
           "pep", "verify"]


def example(name: str) -> Spec:
    """A shipped example spec by name (``sosalgo examples`` lists them), from the
    installed package: no checkout needed. ValueError names the available ones."""
    from sosalgo.kernel.resources import example_specs
    from sosalgo.spec import spec_from_text

    specs = example_specs()
    if name not in specs:
        raise ValueError(f"no example {name!r}; shipped: {', '.join(specs)}")
    return spec_from_text(specs[name].read_text(), source=f"{name}.yaml")


def as_spec(spec: Spec | str | Path, varying: bool = False) -> Spec:
    """A Spec, loading it when given a path; a method that changes with k is refused (one
    line naming ``sosalgo pep --steps``) unless the caller takes one (``varying``)."""
    from sosalgo.steps import one_method

    out = spec if isinstance(spec, Spec) else load_spec(spec)
    return out if varying else one_method(out)


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
    certificate: str | None = None,
    options: Mapping[str, Any] | None = None,
    brackets: str = "none",
    cycle_seconds: float = 0.0,
) -> AnalysisResult | list[AnalysisResult]:
    """Best rate certified by the spec's certificate family (Theorem 1, eq. 15-16), or by
    ``certificate`` (a family name) with ``options`` (e.g. ``{"lag": 0}``).

    ``kappa``: a number (one :class:`AnalysisResult`), a list (a list of results, in
    order) or None (the spec's own kappa list). ``theta`` overrides parameter values.
    ``brackets`` (quadratic, self-similar, none) and ``cycle_seconds`` (the cycle search
    per uncertified result, 0: none) fill ``rho_lower``, ``rho_lower_kind``,
    ``rho_lower_witness`` and ``cycle`` as ``sosalgo analyze`` does (its defaults:
    ``brackets="quadratic", cycle_seconds=5``); the defaults here compute no witness.
    """
    from sosalgo.analysis import analyze_spec
    from sosalgo.inputs import (
        check_kappa_points,
        check_tol,
        refuse_oracle_options,
        select_families,
    )
    from sosalgo.witnesses.rows import check_witness_options, with_witnesses

    s = as_spec(spec)
    refuse_oracle_options(s)  # a rate of the exact method would not bound these
    kappas, single = _kappas(s, kappa)
    check_tol(tol)
    check_witness_options(brackets, cycle_seconds)
    fam = select_families(s, certificate, options, single=True, command="analyze")[0]
    check_kappa_points(s, kappas, theta)
    results = [analyze_spec(s, k, theta, tol=tol, family=fam) for k in kappas]
    if brackets != "none" or cycle_seconds > 0:
        results = [with_witnesses(s, k, theta, r, brackets, cycle_seconds)
                   for k, r in zip(kappas, results, strict=True)]
    return results[0] if single else results


def design(
    spec: Spec | str | Path, kappa: float | Sequence[float] | None = None, **options: Any
) -> DesignResult | list[DesignResult]:
    """Design the free parameters by sum-of-squares (eq. 17) at each kappa; ``options``
    are those of :func:`sosalgo.design_search.design` (free, scalarize, order, gap, time_limit,
    method, family), checked as ``sosalgo design`` checks them (ValueError).
    ``objective="noise", max_rate=R`` (or ``max_noise=G``) designs with the noise
    sensitivity instead (:func:`sosalgo.design_search.objectives.objective_design`: options free,
    family, time_limit, workers; an ObjectiveDesignResult per kappa)."""
    from sosalgo.design_search import design as design_one

    s = as_spec(spec)
    kappas, single = _kappas(s, kappa)
    objective, caps = options.pop("objective", "rate"), {
        k: options.pop(k) for k in ("max_rate", "max_noise") if k in options}
    if objective != "rate" or any(v is not None for v in caps.values()):
        from sosalgo.design_search.objectives import check_objective, objective_design

        check_objective(s, kappas, objective, caps.get("max_rate"), caps.get("max_noise"))
        extra = sorted(set(options) - {"free", "family", "time_limit", "workers", "on_step"})
        if extra:
            raise ValueError(f"{extra[0]}: not an option of a design with a noise objective "
                             "or cap (free, family, time_limit, workers)")
        _check_design(s, options)
        results = [objective_design(s, k, objective, **caps, **options) for k in kappas]
        return results[0] if single else results
    _check_design(s, options)
    results = [design_one(s, k, **options) for k in kappas]
    return results[0] if single else results


def verify(spec: Spec | str | Path, result: Any, simulate: bool = True,
           out_dir: str | Path | None = None) -> dict[str, Any] | None:
    """Exact proof (and simulation) of the certificate in ``result``: an AnalysisResult,
    a DesignResult or a row/document dict of ``--json`` output. None when the result
    claims no certificate; ``verified == "exact"`` when proven."""
    from sosalgo.proofs.results import verify_document_rows

    s = as_spec(spec)
    row = result.to_dict() if hasattr(result, "to_dict") else dict(result)
    out = None if out_dir is None else Path(out_dir)
    return verify_document_rows(s, [row], out, simulate)[0]


def pep(spec: Spec | str | Path, kappa: float | None = None, steps: int = 1,
        measure: str | None = None, initial: str | None = None, exact: bool = True,
        witness: bool = True) -> Any:
    """The worst case after ``steps`` steps (:class:`sosalgo.worstcase.PEPResult`): tau_N, its
    dual certificate (proven exactly), the worst-case witness (checked exactly)."""
    from sosalgo.worstcase.core import pep as run

    return run(as_spec(spec, varying=True), kappa, steps, measure, initial, exact, witness)


def noise(spec: Spec | str | Path, kappa: float | Sequence[float] | None = None,
          theta: Mapping[str, float] | None = None, lag: int | None = None,
          exact: bool = True) -> Any:
    """Certified sensitivity to gradient noise (``sosalgo analyze --noise``;
    docs/noise.md): a :class:`sosalgo.sensitivity.run.NoiseResult` per
    kappa (one for a number), with the bound proven exactly when ``exact``; ``lag`` fixes
    the certificate's lag (default: the best of 0 .. n + 1)."""
    from sosalgo.inputs import check_kappa_points
    from sosalgo.sensitivity.run import analyze_noise, check_noise_spec

    s = as_spec(spec)
    check_noise_spec(s)
    kappas, single = _kappas(s, kappa)
    check_kappa_points(s, kappas, theta)
    results = [analyze_noise(s, k, theta, lag, exact) for k in kappas]
    return results[0] if single else results


def _check_design(spec: Spec, options: Mapping[str, Any]) -> None:
    """The checks of ``sosalgo design`` on :func:`design`'s options."""
    from sosalgo import inputs
    from sosalgo.certificates import get_family

    fam = options.get("family")
    fam = get_family(spec.certificate, spec.certificate_options) if fam is None else (
        get_family(fam) if isinstance(fam, str) else fam)
    inputs.check_method(options.get("method", "dual"), options.get("scalarize", "pmi"), fam)
    if options.get("free") is not None:
        inputs.free_names(spec, options["free"])
    inputs.check_gap(options.get("gap", 1e-4))
    inputs.check_time_limit(options.get("time_limit", 120.0))


def lmi(spec: Spec | str | Path, free: str | Sequence[str] | None = None, latex: bool = False,
        certificate: str | None = None, options: Mapping[str, Any] | None = None,
        overrides: Mapping[str, str] | None = None) -> str:
    """The symbolic certificate inequality (``sosalgo lmi``): plain text, or a LaTeX
    snippet ready to paste (``latex``); ``free`` parameters stay symbols; ``overrides``
    (``--set NAME=EXPR``) fix parameters first."""
    from sosalgo.inputs import free_names, select_families
    from sosalgo.runs import spec_with_text
    from sosalgo.symbolic import symbolic_lmi

    s = spec_with_text(spec, None, overrides)[0] if overrides else as_spec(spec)
    names = None if free is None else free_names(s, free, need_range=False)
    fam = select_families(s, certificate, options, single=True, command="lmi")[0]
    return symbolic_lmi(s, free=names, latex=latex, family=fam)


def copy_examples(names: Sequence[str] = (), out_dir: str | Path = ".") -> dict[str, bool]:
    """Copy shipped example specs (default: all) into ``out_dir`` as ``NAME.yaml``; returns
    each target path and whether it was written (a different existing file is kept)."""
    from sosalgo.inputs import out_dir as checked_dir
    from sosalgo.kernel.resources import example_specs

    found = example_specs()
    unknown = [n for n in names if n not in found]
    if unknown:
        raise ValueError(f"{unknown[0]}: no such example (known: {', '.join(found)})")
    out = checked_dir(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = {}
    for name in names or found:
        target, text = out / f"{name}.yaml", found[name].read_text(encoding="utf-8")
        keep = target.exists() and target.read_text(encoding="utf-8") != text
        if not keep:
            target.write_text(text, encoding="utf-8")
        written[str(target)] = not keep
    return written
