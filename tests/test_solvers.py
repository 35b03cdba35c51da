"""The door to the conic solvers: statuses we trust, checked points."""

from __future__ import annotations

import warnings

import numpy as np

from sosalgo.kernel.conic import AffineBlock, LMIProblem
from sosalgo.kernel.solvers import (
    Feasibility,
    SolverStatus,
    check_point,
    solve_lmi,
    solve_margin,
    solver_status,
)


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


# Every status the solvers document (Clarabel's SolverStatus, SCS's info["status"]), with
# the class it must fall in: only a full-accuracy solve is a solution, only a certificate
# of primal infeasibility is infeasible.
DOCUMENTED = {
    "Solved": "solved", "AlmostSolved": "almost solved", "PrimalInfeasible": "infeasible",
    "AlmostPrimalInfeasible": "inaccurate", "AlmostDualInfeasible": "inaccurate",
    "DualInfeasible": "failed", "MaxIterations": "failed", "MaxTime": "failed",
    "NumericalError": "failed", "InsufficientProgress": "failed", "Unsolved": "failed",
    "CallbackTerminated": "failed",
    "solved": "solved", "solved_inaccurate": "almost solved", "infeasible": "infeasible",
    "infeasible_inaccurate": "inaccurate", "unbounded": "failed",
    "unbounded_inaccurate": "inaccurate", "failed": "failed", "indeterminate": "failed",
    "interrupted": "failed", "sigint": "failed",
}


def test_one_status_mapping_covers_both_solvers():
    import clarabel

    clarabel_names = {n for n in dir(clarabel.SolverStatus) if n[0].isupper()}
    assert clarabel_names <= set(DOCUMENTED)  # every status this Clarabel can return
    for raw, want in DOCUMENTED.items():
        assert solver_status(raw) == want, raw
    assert solver_status(clarabel.SolverStatus.AlmostSolved) == SolverStatus.ALMOST_SOLVED
    assert SolverStatus.ALMOST_SOLVED.near and not SolverStatus.SOLVED.near


def test_non_finite_data_fail_quietly(capfd):
    bad = _interval(1.0, np.inf)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = solve_lmi(bad, 0.5)
        mg = solve_margin(bad, 0.5)
    assert out.status == Feasibility.FAILED and not mg.ok
    assert "non-finite" in out.detail and "non-finite" in mg.detail
    captured = capfd.readouterr()
    assert captured.err == "" and captured.out == ""  # the solvers printed nothing
