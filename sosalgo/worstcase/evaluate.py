"""The worst case after N steps at given parameter values: the one function the N-step
design (:mod:`sosalgo.design_search.steps`) and its verification evaluate and prove. It is the
PEP of ``sosalgo pep`` at the spec with the values fixed (``--set``): one per-step PEP
and one dual proof for ``pep``, ``design --steps`` and ``verify``."""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction
from typing import Any

from sosalgo.design_search.steps import value_text
from sosalgo.errors import InputError
from sosalgo.spec import Spec

__all__ = ["steps_evaluator", "worst_case_evaluator"]

Values = dict[str, Any]  # parameter -> number, decimal text (or per-step list)


def worst_case_evaluator(spec: Spec, text: str, kappa: float | None, steps: int,
                         ) -> tuple[Callable[[Values], float],
                                    Callable[[Values], tuple[Fraction | None, float]]]:
    """(float tau_N at θ, proven tau_N at θ): the PEP of ``sosalgo pep`` at the spec
    with the parameters fixed to θ's values (``--set``). The proven one returns
    (tau_proven or None, float tau). The values are written as given (decimals)."""
    from sosalgo.spec import spec_from_text
    from sosalgo.spec.overrides import apply_overrides
    from sosalgo.worstcase.core import pep

    def at(values: Values) -> Spec:
        over = {k: value_text(v) for k, v in values.items()}
        return spec_from_text(apply_overrides(text, over, spec.source), spec.source)

    def value(values: Values) -> float:
        try:
            res = pep(at(values), kappa, steps, exact=False, witness=False)
        except (InputError, ArithmeticError, ValueError):
            return math.inf
        return math.inf if res.tau is None else float(res.tau)

    def proven(values: Values) -> tuple[Fraction | None, float]:
        res = pep(at(values), kappa, steps, exact=True, witness=False)
        cert = res.certificate or {}
        tp = cert.get("tau_proven")
        return (Fraction(tp) if isinstance(tp, str) else None,
                math.inf if res.tau is None else float(res.tau))

    return value, proven


def steps_evaluator(spec: Spec, text: str, kappa: float | None, steps: int,
                    prob: Any) -> tuple[Callable, Callable]:
    """The worst case at θ of ``design --steps`` and ``verify``: always ``sosalgo pep``'s
    (:func:`worst_case_evaluator`, its exact proof). For a spec that varies with k, the
    parametric model ``prob.model`` (the box-wide bound's and the search's) must agree
    with ``sosalgo pep`` on the spec as written (its own values, to 1e-6), else it is
    dropped (``prob.model`` None, ``prob.reason`` says why): a bound about another method
    is never reported. InputError when ``sosalgo pep`` cannot bind the spec."""
    from sosalgo.design_search.steps_model import PointSearch
    from sosalgo.worstcase.core import pep

    evaluator = worst_case_evaluator(spec, text, kappa, steps)
    if prob.model is None and prob.reason is None:  # time-invariant: same matrices
        return evaluator
    ours = pep(spec, kappa, steps, exact=False, witness=False).tau  # InputError: unbound
    if prob.model is not None and not prob.seeds:
        prob.model, prob.reason = None, ("the parametric model cannot be checked against "
                                         "sosalgo pep (the spec's own values are not numbers)")
    if prob.model is not None:
        theirs = PointSearch(prob.model).value_grad(prob.seeds[0])[0]
        if ours is None or not math.isfinite(theirs) or \
                abs(theirs - ours) > 1e-6 * max(abs(ours), 1e-12):
            prob.model, prob.reason = None, (
                f"the parametric model's worst case at the spec's values ({theirs:.9g}) "
                f"differs from sosalgo pep's ({ours})")
    return evaluator
