"""Composite test problems for simulations, from the test functions of each class.

A composite problem min_x sum_j f_j(x) is simulated with actual functions: each function
of the method gets the test functions of its class
(:meth:`~sosalgo.classes.base.FunctionClass.test_functions`, built from
:mod:`sosalgo.classes.members`: value, subgradient selection, closed-form prox). A problem
(:func:`composite_problems`) knows its minimizer x* and optimal subgradients
s_j* in ∂f_j(x*) with sum_j s_j* = 0: the functions are built around a random x* and one
function that is closed under adding linear terms gets the tilt <a, x> with
a = -sum_j s_j.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from sosalgo.classes.members import ProxFunction

__all__ = ["ProxProblem", "composite_problems"]

Array = np.ndarray


@dataclass(frozen=True, eq=False)
class ProxProblem:
    """min sum_j f_j with minimizer ``x_star`` and optimal subgradients ``s_star``."""

    name: str
    d: int
    functions: tuple[ProxFunction, ...]
    x_star: Array

    @property
    def s_star(self) -> list[Array]:
        return [f.s for f in self.functions]


def composite_problems(om: Any, d: int, rng: np.random.Generator,
                       limit: int = 24) -> list[ProxProblem]:
    """Problems for an :class:`~sosalgo.oracles.OracleMethod`: one test function per
    function of the method (all combinations, at most ``limit``), the ones its calls cannot
    query left out (a gradient call on a prox-only function), x* and s* (sum 0) set."""
    xs = rng.standard_normal(d)
    explicit = {om.oracles[i] for i in range(om.p) if om.D[i, i] == 0}
    lists = []
    for j, fn in enumerate(om.functions):
        fs = fn.cls.test_functions(fn.params, xs, rng)
        lists.append([f for f in fs if j not in explicit or f.grad is not None])
    out = []
    for combo in itertools.islice(itertools.product(*lists), limit):
        a = -sum(f.s for f in combo)
        k = next((j for j, f in enumerate(combo) if f.tiltable), None)
        if k is None and np.abs(a).max() > 0:
            continue
        funcs = list(combo)
        if k is not None:
            funcs[k] = funcs[k].tilt(a)
        out.append(ProxProblem(" + ".join(f.name for f in funcs), d, tuple(funcs), xs))
    return out
