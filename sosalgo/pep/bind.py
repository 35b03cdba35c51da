"""The float method of a spec for the PEP: ``evaluate_algorithm`` at kappa, or
``bind_sublinear`` for an m: 0 spec (where kappa is refused)."""

from __future__ import annotations

import math
from typing import Any

from sosalgo.errors import InputError
from sosalgo.spec import Spec

__all__ = ["bound_method"]


def bound_method(spec: Spec, kappa: float | None) -> tuple[Any, float]:
    """(OracleMethod, kappa used in expressions): ``bind_sublinear`` for m: 0 specs (no
    kappa allowed), ``evaluate_algorithm`` otherwise (kappa required)."""
    from sosalgo.model import bind_sublinear, evaluate_algorithm
    from sosalgo.oracles import as_oracle_method

    if spec.sublinear:
        if kappa is not None:
            raise InputError(f"{spec.source}: --kappa: an m: 0 spec has no condition number "
                             f"(L = {spec.L:g} is given)")
        return bind_sublinear(spec), math.nan
    if kappa is None:
        raise InputError(f"{spec.source}: --kappa: required (the condition number L/m)")
    return as_oracle_method(evaluate_algorithm(spec, float(kappa))), float(kappa)
