"""What the operator classes share: the pairwise forms on X = (x_a, x_b, u_a, u_b) and a
base class with no function values.

An operator class stands in a spec's ``functions:`` for a (possibly set-valued) operator
M: a "gradient" or "subgradient" call y -> u evaluates u in M(y), a proximal call
y = v - t u, u in M(y) is the resolvent y = J_{tM}(v) = (I + tM)^{-1}(v) (for a maximally
monotone M it exists and is unique). The problem is the inclusion 0 in sum_j M_j(x*): the
optimal "subgradients" s_j* in M_j(x*) sum to 0, exactly as for the functions of a
composite problem, so the oracle model and the PEP are unchanged. Every condition below
is on differences (x_a - x_b, u_a - u_b) only, so it holds for M - s* too (tilt
invariant), and has alpha = 0: an operator has no function values (``has_values``
False), and a measure or initial condition in f is refused. ``curvatures`` are the q with
q I in the class (the gradients of the quadratics (q/2)|x|^2: the linear systems of the
rate on quadratics are the same).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import FunctionClass, Inequality
from sosalgo.classes.members import ProxFunction

__all__ = ["OperatorClass", "linear_member", "operator_form", "positive", "rotation", "skew_unit"]


def operator_form(cross: Any, xx: Any, uu: Any, exact: bool = False) -> np.ndarray:
    """Q of ``cross <u_a - u_b, x_a - x_b> + xx |x_a - x_b|^2 + uu |u_a - u_b|^2 >= 0`` on
    (x_a, x_b, u_a, u_b): floats, or (``exact``) an object array of the exact numbers
    given (rationals or balls)."""
    dx = [1, -1, 0, 0]
    du = [0, 0, 1, -1]
    half = Fraction(1, 2) if exact else 0.5
    Q = np.full((4, 4), Fraction(0) if exact else 0.0, dtype=object if exact else float)
    for i in range(4):
        for j in range(4):
            c = dx[i] * du[j] + du[i] * dx[j]
            for coef, k in ((cross * half, c), (xx, dx[i] * dx[j]), (uu, du[i] * du[j])):
                if k:
                    Q[i, j] = Q[i, j] + coef * k
    return Q


def rotation(d: int, rng: np.random.Generator) -> np.ndarray:
    """A random orthogonal matrix."""
    q, r = np.linalg.qr(rng.standard_normal((d, d)))
    return q * np.sign(np.diag(r))


def skew_unit(d: int, rng: np.random.Generator) -> np.ndarray:
    """A random skew matrix with every singular value 1 (0 once when d is odd): rotation
    generators in orthogonal planes, so that |mu I + w K| = sqrt(mu^2 + w^2)."""
    K = np.zeros((d, d))
    for i in range(0, d - 1, 2):
        K[i, i + 1], K[i + 1, i] = -1.0, 1.0
    R = rotation(d, rng)
    return R @ K @ R.T


def linear_member(M0: np.ndarray, xs: np.ndarray, rng: np.random.Generator, name: str,
                  note: str, resolvent: bool = True) -> ProxFunction:
    """The affine operator M(x) = M0 (x - c) (c random) as a test member: ``grad`` its
    evaluation, ``prox`` its resolvent (I + t M0)^{-1} (v + t M0 c) (``resolvent``: M0 is
    monotone), ``s`` = M(x*); the value is 0 (an operator has none; unused)."""
    d = len(xs)
    c = xs + rng.standard_normal(d)

    def prox(v: np.ndarray, t: float) -> np.ndarray:
        return np.linalg.solve(np.eye(d) + t * M0, (v + t * (M0 @ c)).T).T

    return ProxFunction(name, lambda x: np.zeros(len(x)), prox if resolvent else _no_prox,
                        lambda x: (x - c) @ M0.T, M0 @ (xs - c), note)


def _no_prox(v: np.ndarray, t: float) -> np.ndarray:
    raise ValueError("this operator class has no resolvent")


class OperatorClass(FunctionClass):
    """An operator class: no values, pairs only; a subclass gives :meth:`forms` (the
    (cross, xx, uu) coefficients of each condition, over any numbers)."""

    has_values = False
    tilt_invariant = True

    def forms(self, params: Mapping[str, Any]) -> list[tuple[Any, Any, Any]]:
        raise NotImplementedError

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        return [Inequality(0.0, operator_form(float(a), float(b), float(c)))
                for a, b, c in self.forms(params)]

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        return [(Fraction(0), operator_form(a, b, c, exact=True))
                for a, b, c in self.forms(params)]


def positive(params: Mapping[str, float], name: str) -> None:
    """ValueError('<name>: ...') unless the parameter is positive and finite."""
    v = params[name]
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name}: must be positive and finite, got {v:g}")
