"""The door to the conic solvers: statuses we trust, checked points."""

from __future__ import annotations

import numpy as np

from sosalgo.certificates.base import AffineBlock, LMIProblem
from sosalgo.solvers import check_point, solve_lmi, solve_margin


def _interval(lo: float, hi: float) -> LMIProblem:
    """One variable x with lo <= x <= hi, as two 1x1 blocks (feasible iff lo <= hi)."""
    one = np.ones((1, 1, 1))
    z = np.zeros((1, 1))
    blocks = (AffineBlock("low", np.array([[lo]]), z, -one, 0 * one),  # lo - x <= 0
              AffineBlock("high", np.array([[-hi]]), z, one, 0 * one))  # x - hi <= 0
    return LMIProblem(1, blocks, lambda x: {"x": float(x[0])})


def test_feasible_point_is_checked():
    out = solve_lmi(_interval(1.0, 2.0), 0.5)
    assert out.feasible and 1.0 <= out.x[0] <= 2.0


def test_infeasible_is_reported_as_such():
    out = solve_lmi(_interval(2.0, 1.0), 0.5)
    assert out.status == "infeasible" and not out.feasible


def test_check_point_refuses_violations_and_nan():
    prob = _interval(1.0, 2.0)
    assert check_point(prob, 0.5, np.array([1.5]), "test").feasible
    assert not check_point(prob, 0.5, np.array([3.0]), "test").feasible
    assert not check_point(prob, 0.5, np.array([np.nan]), "test").feasible
    assert not check_point(prob, 0.5, np.array([1.0, 2.0]), "test").feasible  # wrong shape


def test_margin_sign_tells_feasibility():
    assert solve_margin(_interval(1.0, 2.0), 0.5).t > 0
    assert solve_margin(_interval(2.0, 1.0), 0.5).t < 0
