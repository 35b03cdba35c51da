"""The worst case after N steps at given parameter values: the one function the N-step
design (:mod:`sosalgo.design.steps`) and its verification evaluate. It is the PEP of
``sosalgo pep`` at the spec with the values fixed (``--set``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction
from typing import Any

from sosalgo.design.steps import value_text
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
    from sosalgo.pep.core import pep
    from sosalgo.spec import spec_from_text
    from sosalgo.spec.overrides import apply_overrides

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
    """The worst case at θ: ``sosalgo pep``'s (its proof) for a time-invariant spec, and
    for a spec that varies with k when ``sosalgo pep`` binds it and agrees with the
    parametric model at the spec's own values (to 1e-6); otherwise the parametric model's
    own PEP and dual proof (:func:`sosalgo.design.steps.point_evaluator`). InputError
    when neither exists."""
    from sosalgo.design.steps import pack, point_evaluator

    if not getattr(spec, "time_varying", False):
        return worst_case_evaluator(spec, text, kappa, steps)
    if prob.model is None:
        raise InputError(f"{spec.source}: design --steps: the worst case of this method "
                         f"cannot be evaluated per step here: {prob.reason}")
    own = point_evaluator(prob.model, prob.layout)
    if prob.seeds:
        values = pack(prob.layout, prob.seeds[0])
        theirs = worst_case_evaluator(spec, text, kappa, steps)
        a, b = own[0](values), theirs[0](values)
        if math.isfinite(a) and math.isfinite(b) and abs(a - b) <= 1e-6 * max(abs(a), 1e-12):
            return theirs
    return own
