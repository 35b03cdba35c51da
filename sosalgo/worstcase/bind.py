"""The float method of a spec for the PEP, through the one entry point
:func:`sosalgo.method.bind`: at kappa, or for an m: 0 spec (where kappa is refused) at its
own L with a state at the optimum that may move with the optimal subgradients."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sosalgo.errors import InputError
from sosalgo.spec import Spec

__all__ = ["bound_method", "class_kappa", "has_kappa", "initial_gradient"]


def has_kappa(spec: Spec) -> bool:
    """Whether the class a spec's results are about has a kappa: not when the spec's
    certificate family answers a constant (:func:`sosalgo.certificates.spec_family`:
    m: 0, L given)."""
    from sosalgo.certificates import spec_family

    return spec_family(spec) is None


def class_kappa(spec: Spec, kappa: float | None) -> float | None:
    """``kappa`` when the spec's class has one (:func:`has_kappa`), else None."""
    return kappa if has_kappa(spec) else None


def bound_method(spec: Spec, kappa: float | None) -> tuple[Any, float]:
    """(OracleMethod, kappa used in expressions) bound by :func:`sosalgo.method.bind`:
    without kappa for m: 0 specs (none allowed; ``moving_optimum``: the PEP takes a state
    at the optimum that moves with the optimal subgradients), at kappa otherwise (kappa
    required)."""
    from sosalgo.method import bind
    from sosalgo.oracles import as_oracle_method

    if not has_kappa(spec):
        if kappa is not None:
            raise InputError(f"{spec.source}: --kappa: an m: 0 spec has no condition number "
                             f"(L = {spec.L:g} is given)")
        return bind(spec, moving_optimum=True), math.nan
    if kappa is None:
        raise InputError(f"{spec.source}: --kappa: required (the condition number L/m)")
    return as_oracle_method(bind(spec, float(kappa))), float(kappa)


def initial_gradient(spec: Spec, om: Any, kappa: float) -> tuple[np.ndarray | None, int]:
    """(b, j) of the spec's ``initial_state`` xi_0 = u x0 + b g0 (g0 the gradient of
    function j at x0) in floating point; b is None when the field is absent or b = 0."""
    if spec.initial_state is None:
        return None, 0
    from sosalgo.model import parameter_values
    from sosalgo.spec.initial_state import initial_state_values

    env = {"m": float(om.m), "L": float(om.L), "kappa": kappa,
           **parameter_values(spec, kappa)}
    _, b = initial_state_values(spec.initial_state, env)
    smooth = [j for j, fn in enumerate(om.functions) if "gradient" in fn.cls.oracles]
    if not np.any(b != 0) or len(smooth) != 1:
        return None, 0
    return b, smooth[0]
