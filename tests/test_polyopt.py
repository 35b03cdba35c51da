"""Tests of sosalgo.polyopt against global optima published in the literature.

References (values quoted in the comments of each test):
  [L01]   J.B. Lasserre, "Global optimization with polynomials and the problem of moments",
          SIAM J. Optim. 11(3), 2001.
  [HL03]  D. Henrion, J.B. Lasserre, "GloptiPoly: global optimization over polynomials with
          Matlab and SeDuMi", ACM TOMS 29(2), 2003 (and the GloptiPoly 3 manual/demo).
  [HL05]  D. Henrion, J.B. Lasserre, "Detecting global optimality and extracting solutions
          in GloptiPoly", 2005.
  [HL06]  D. Henrion, J.B. Lasserre, "Convergent relaxations of polynomial matrix
          inequalities and static output feedback", IEEE TAC 51(2), 2006.
  [CEC06] J.J. Liang et al., "Problem definitions and evaluation criteria for the CEC 2006
          special session on constrained real-parameter optimization" (problem g24, which
          is Floudas & Pardalos' test problem also used in [L01]).
"""

from __future__ import annotations

import math

import cvxpy as cp
import numpy as np
import pytest
import sympy as sp

from sosalgo.polyopt import PolyProblem, RelaxationResult, solve_moment_relaxation

x1, x2, x3 = sp.symbols("x1 x2 x3")


def _points(res: RelaxationResult, variables: list[sp.Symbol]) -> np.ndarray:
    pts = np.array([[m[v] for v in variables] for m in res.minimizers], dtype=float)
    return pts[np.lexsort(pts.T[::-1])] if len(pts) else pts.reshape(0, len(variables))


def _assert_same_points(res: RelaxationResult, variables, expected, tol=1e-3) -> None:
    got = _points(res, variables)
    exp = np.array(expected, dtype=float)
    exp = exp[np.lexsort(exp.T[::-1])]
    assert got.shape == exp.shape, f"extracted {got.tolist()}, expected {exp.tolist()}"
    assert np.max(np.abs(got - exp)) < tol, f"extracted {got.tolist()}, expected {exp.tolist()}"


# --------------------------------------------------------------------------------------
# Unconstrained problems
# --------------------------------------------------------------------------------------


def test_six_hump_camel_back() -> None:
    # [HL03] GloptiPoly demo / [L01]: min = -1.0316284535 at +-(0.0898, -0.7126), certified
    # at the 3rd relaxation (the objective has degree 6). Benchmark pages (e.g.
    # benchmarkfcns.info "sixhumpcamel") list the same two global minimizers.
    f = 4 * x1**2 + x1 * x2 - 4 * x2**2 - sp.Rational(21, 10) * x1**4 + 4 * x2**4 + x1**6 / 3
    res = solve_moment_relaxation(PolyProblem([x1, x2], f), order=3)
    assert res.status == "optimal"
    assert res.order == 3 and res.solver == "CLARABEL"
    assert abs(res.bound - (-1.0316284535)) < 1e-5
    assert res.flat
    _assert_same_points(res, [x1, x2], [[0.0898, -0.7126], [-0.0898, 0.7126]])
    # the optimal measure is symmetric: its mean is the origin
    assert abs(res.first_moments[x1]) < 1e-4 and abs(res.first_moments[x2]) < 1e-4
    assert len(res.ranks) == 3 and res.seconds > 0


def test_univariate_quartic() -> None:
    # f = 3x^4 - 4x^3 - 12x^2 + 5, f' = 12 x (x - 2)(x + 1): f(-1) = 0, f(0) = 5,
    # f(2) = -27, so the global minimum is -27 at x = 2 (univariate nonnegative polynomials
    # are SOS, so the first admissible relaxation, order 2, is exact [L01, Sec. 2]).
    x = sp.Symbol("x")
    res = solve_moment_relaxation(PolyProblem([x], 3 * x**4 - 4 * x**3 - 12 * x**2 + 5))
    assert res.order == 2  # order=None picks the minimal order
    assert res.status == "optimal"
    assert abs(res.bound - (-27.0)) < 1e-5
    assert res.flat
    _assert_same_points(res, [x], [[2.0]])
    assert abs(res.first_moments[x] - 2.0) < 1e-3


def test_rosenbrock_2d() -> None:
    # Rosenbrock's function 100 (x2 - x1^2)^2 + (1 - x1)^2: global minimum 0 at (1, 1).
    # With a box containing (1, 1) the bound is proven (box certificate) and exact.
    f = 100 * (x2 - x1**2) ** 2 + (1 - x1) ** 2
    boxed = PolyProblem([x1, x2], f, bounds={x1: (-1.5, 1.5), x2: (-1.5, 1.5)})
    res = solve_moment_relaxation(boxed, order=2)
    assert res.status == "optimal" and res.certified
    assert -1e-5 < res.bound <= 0.0
    assert res.flat and res.ranks[0] == 1
    _assert_same_points(res, [x1, x2], [[1.0, 1.0]])
    # Without a box every SOS certificate has a singular Gram matrix (the square
    # (x2 - x1^2)^2 is forced), so no floating-point check can prove it; the exact one
    # over p = (1, x1, x1^2 - x2) does (was "inaccurate", 3e-6 above the minimum 0).
    free = solve_moment_relaxation(PolyProblem([x1, x2], f), order=2)
    _assert_honest(free, 0.0)
    assert free.status == "optimal" and free.certified and free.flat
    assert -1e-5 < free.bound <= 0.0
    _assert_same_points(free, [x1, x2], [[1.0, 1.0]])


def test_exact_certificate_proves_only_true_bounds() -> None:
    # Rosenbrock f = 100 (x2 - x1^2)^2 + (1 - x1)^2 >= 0 with f(1, 1) = 0, so f - G is a
    # sum of squares for every G <= 0 and nonnegative for no G > 0. The Gram matrix given
    # is the hand-made one for G = 0 over (1, x1, x2, x1^2, x1 x2, x2^2), perturbed by 1e-7.
    from fractions import Fraction

    from sosalgo.polyopt.certificate import newton_keep
    from sosalgo.polyopt.exact import exact_sos_bound
    from sosalgo.polyopt.moment import MomentIndex

    f = {(0, 0): 1, (1, 0): -2, (2, 0): 1, (0, 2): 100, (2, 1): -200, (4, 0): 100}
    f = {e: Fraction(c) for e, c in f.items()}
    index = MomentIndex(2, 2)
    keep = newton_keep(index, [e for e in f if e != (0, 0)])
    assert keep.tolist() == [True, True, True, True, False, False]
    Z = np.zeros((6, 6))
    Z[:2, :2] = [[1, -1], [-1, 1]]
    Z[2:4, 2:4] = [[100, -100], [-100, 100]]
    Z += 1e-7 * np.random.default_rng(0).normal(size=(6, 6))
    assert exact_sos_bound(index, Z, keep, f, Fraction(0)) == 0
    assert exact_sos_bound(index, Z, keep, f, Fraction(-1, 10**3)) == Fraction(-1, 10**3)
    for G in (Fraction(1, 10**9), Fraction(1)):
        assert exact_sos_bound(index, Z, keep, f, G) is None
    # bisection from -1e-3 towards 1e-3 stays <= 0 and gets within 2e-3 / 2^8 of it
    best = exact_sos_bound(index, Z, keep, f, Fraction(-1, 10**3), Fraction(1, 10**3))
    assert best is not None and -1e-5 < best <= 0


def _assert_honest(res: RelaxationResult, true_min: float, rel: float = 1e-9) -> None:
    """The contract of RelaxationResult against a hand-derived global minimum."""
    slack = rel * max(1.0, abs(true_min))
    if res.status == "optimal" or res.certified:
        assert res.bound <= true_min + slack, (res.status, res.bound, true_min)
    if res.status == "optimal":
        assert res.certified
    if res.flat or res.minimizers:
        assert res.status == "optimal" and res.flat and res.minimizers
        assert abs(res.bound - true_min) <= 1e-6 * max(1.0, abs(true_min))


def test_motzkin_relaxation_is_not_exact() -> None:
    # The Motzkin polynomial x^4 y^2 + x^2 y^4 - 3 x^2 y^2 + 1 is nonnegative (min 0 at
    # |x| = |y| = 1) but M - gamma is a sum of squares for no gamma (Motzkin 1967; see the
    # discussion of this example in [L01]). The order-3 moment relaxation is therefore
    # unbounded: it must not certify 0, nor report minimizers.
    f = x1**4 * x2**2 + x1**2 * x2**4 - 3 * x1**2 * x2**2 + 1
    res = solve_moment_relaxation(PolyProblem([x1, x2], f), order=3)
    assert not (res.status == "optimal" and abs(res.bound) < 1e-3)
    assert res.status == "failed" or res.bound < -1e-2
    assert not res.flat
    assert res.minimizers == []


# --------------------------------------------------------------------------------------
# Constrained problems
# --------------------------------------------------------------------------------------


def test_henrion_lasserre_2005_three_minimizers() -> None:
    # [HL05], Section 2.3: min -(x1-1)^2 - (x1-x2)^2 - (x2-3)^2 s.t. 1-(x1-1)^2 >= 0,
    # 1-(x1-x2)^2 >= 0, 1-(x2-3)^2 >= 0. The first relaxation gives -3, the second one is
    # exact with optimum -2 and rank M_1 = rank M_2 = 3: global minimizers (1,2), (2,2),
    # (2,3).
    f = -((x1 - 1) ** 2) - (x1 - x2) ** 2 - (x2 - 3) ** 2
    prob = PolyProblem(
        [x1, x2], f, inequalities=[1 - (x1 - 1) ** 2, 1 - (x1 - x2) ** 2, 1 - (x2 - 3) ** 2]
    )
    first = solve_moment_relaxation(prob, order=1)
    assert abs(first.bound - (-3.0)) < 1e-5 and not first.flat
    res = solve_moment_relaxation(prob, order=2)
    assert res.status == "optimal"
    assert abs(res.bound - (-2.0)) < 1e-5
    assert res.flat and res.ranks == [3, 3]
    _assert_same_points(res, [x1, x2], [[1, 2], [2, 2], [2, 3]])


def test_floudas_g24_and_box_scaling() -> None:
    # [CEC06] g24 = [L01]'s Floudas-Pardalos example: min -x1 - x2 s.t.
    # x2 <= 2x1^4 - 8x1^3 + 8x1^2 + 2, x2 <= 4x1^4 - 32x1^3 + 88x1^2 - 96x1 + 36,
    # 0 <= x1 <= 3, 0 <= x2 <= 4; optimum -5.5080132716 at (2.32952, 3.17849).
    # Stated here in u = (100 x1 / 3, 25 x2) in [0, 100]^2, which only scaling makes
    # numerically tractable (unscaled, moments up to 100^8 ruin the solver's accuracy).
    u1, u2 = sp.symbols("u1 u2")
    a, b = 3 * u1 / 100, u2 / 25
    prob = PolyProblem(
        [u1, u2],
        -a - b,
        inequalities=[
            2 * a**4 - 8 * a**3 + 8 * a**2 + 2 - b,
            4 * a**4 - 32 * a**3 + 88 * a**2 - 96 * a + 36 - b,
        ],
        bounds={u1: (0, 100), u2: (0, 100)},
    )
    res = solve_moment_relaxation(prob, order=4, scale=True)
    assert res.status == "optimal"
    assert abs(res.bound - (-5.5080132716)) < 1e-5
    assert res.flat
    _assert_same_points(res, [u1, u2], [[2.32952 * 100 / 3, 3.17849 * 25]], tol=1e-2)
    # first moments are reported in the original (unscaled) coordinates
    assert abs(res.first_moments[u1] - 77.6507) < 1e-2
    assert abs(res.first_moments[u2] - 79.4623) < 1e-2


def test_gloptipoly_constrained_example() -> None:
    # GloptiPoly manual example ([HL03]; a Floudas et al. test problem): min -2x1 + x2 - x3
    # s.t. 24 - 20x1 + 9x2 - 13x3 + 4x1^2 - 4x1x2 + 4x1x3 + 2x2^2 - 2x2x3 + 2x3^2 >= 0,
    # x1 + x2 + x3 <= 4, 3x2 + x3 <= 6, 0 <= x1 <= 2, 0 <= x2, 0 <= x3 <= 3.
    # Global optimum -4 at (0.5, 0, 3) and (2, 0, 0) (both points satisfy the quadratic
    # constraint with equality). With the box stated linearly, GloptiPoly needs order 4;
    # the manual lists lower bounds -6, -5.6923, -4.0685 for orders 1-3 (recalled from the
    # manual, not re-verifiable here). x2 <= 2 is implied by 3x2 + x3 <= 6, x3 >= 0.
    g = (
        24
        - 20 * x1
        + 9 * x2
        - 13 * x3
        + 4 * x1**2
        - 4 * x1 * x2
        + 4 * x1 * x3
        + 2 * x2**2
        - 2 * x2 * x3
        + 2 * x3**2
    )
    f = -2 * x1 + x2 - x3
    linear = PolyProblem(
        [x1, x2, x3],
        f,
        inequalities=[g, 4 - x1 - x2 - x3, 6 - 3 * x2 - x3, x1, 2 - x1, x2, x3, 3 - x3],
    )
    low = [solve_moment_relaxation(linear, order=k) for k in (1, 2)]
    assert abs(low[0].bound - (-6.0)) < 1e-4
    assert abs(low[1].bound - (-5.6923)) < 1e-4
    assert all(not r.flat and r.minimizers == [] for r in low)

    boxed = PolyProblem(
        [x1, x2, x3],
        f,
        inequalities=[g, 4 - x1 - x2 - x3, 6 - 3 * x2 - x3],
        bounds={x1: (0, 2), x2: (0, 2), x3: (0, 3)},
    )
    res = solve_moment_relaxation(boxed, order=3)
    assert res.status == "optimal"
    assert abs(res.bound - (-4.0)) < 1e-5
    assert res.flat
    _assert_same_points(res, [x1, x2, x3], [[0.5, 0, 3], [2, 0, 0]])

    # GloptiPoly's own statement (linear box) at order 4: the implied ranges x1 in [0, 2],
    # x2 in [0, 2], x3 in [0, 3] rescale the variables and make the box certificate apply
    # (was "inaccurate", -3.99992, uncertified, 18 s).
    res = solve_moment_relaxation(linear, order=4)
    assert res.status == "optimal" and res.certified
    assert -4.0 - 1e-5 < res.bound <= -4.0
    assert res.flat
    _assert_same_points(res, [x1, x2, x3], [[0.5, 0, 3], [2, 0, 0]])


@pytest.mark.slow
@pytest.mark.deep  # make test-all (about 10-15 s)
def test_floudas_pardalos_2_1() -> None:
    # Floudas-Pardalos (1990) problem 2.1, solved by [L01] (concave QP):
    # min 42x1 + 44x2 + 45x3 + 47x4 + 47.5x5 - 50 sum xi^2
    # s.t. 20x1 + 12x2 + 11x3 + 7x4 + 4x5 <= 40, 0 <= xi <= 1 (stated linearly).
    # Published optimum -17 at (1, 1, 0, 1, 0): 42 + 44 + 47 - 150 = -17, and the
    # constraint 20 + 12 + 7 = 39 <= 40 holds. Order 2 gives a lower bound only; order 3
    # is exact (was "inaccurate", uncertified, 121 s: no box certificate without bounds).
    xs = sp.symbols("x1:6")
    c = [42, 44, 45, 47, sp.Rational(95, 2)]
    f = sum(ci * xi for ci, xi in zip(c, xs, strict=True)) - 50 * sum(xi**2 for xi in xs)
    budget = 40 - (20 * xs[0] + 12 * xs[1] + 11 * xs[2] + 7 * xs[3] + 4 * xs[4])
    prob = PolyProblem(list(xs), f, inequalities=[budget, *xs, *(1 - xi for xi in xs)])
    res = solve_moment_relaxation(prob, order=3)
    assert res.status == "optimal" and res.certified
    assert -17.0 - 1e-5 < res.bound <= -17.0
    assert res.flat
    _assert_same_points(res, list(xs), [[1, 1, 0, 1, 0]])


def test_equality_constraint_sphere() -> None:
    # min -x1 x2 x3 s.t. x1^2 + x2^2 + x3^2 = 1. By AM-GM, (x1 x2 x3)^2 <= (1/3)^3, so the
    # minimum is -3^(-3/2) = -0.19245..., attained exactly at the four points
    # (s1, s2, s3)/sqrt(3) with s_i = +-1 and s1 s2 s3 = 1.
    prob = PolyProblem([x1, x2, x3], -x1 * x2 * x3, equalities=[x1**2 + x2**2 + x3**2 - 1])
    res = solve_moment_relaxation(prob, order=2)
    assert res.status == "optimal"
    assert abs(res.bound - (-(3**-1.5))) < 1e-5
    assert res.flat
    a = 1 / math.sqrt(3)
    _assert_same_points(res, [x1, x2, x3], [[a, a, a], [a, -a, -a], [-a, a, -a], [-a, -a, a]])


def test_polynomial_matrix_inequality() -> None:
    # [HL06] 2x2 PMI example: min -x1^2 - x2^2 s.t. G(x) = [[1 - 4x1x2, x1],
    # [x1, 4 - x1^2 - x2^2]] ⪰ 0. By hand: G ⪰ 0 needs G22 = 4 - x1^2 - x2^2 >= 0, so the
    # objective is >= -4; equality forces G22 = 0, then det G = -x1^2 >= 0 gives x1 = 0,
    # and G(0, +-2) = diag(1, 0) ⪰ 0. Optimum -4 at (0, 2) and (0, -2). The first
    # relaxation already gives -4 but without certificate; the second is flat.
    G = sp.Matrix([[1 - 4 * x1 * x2, x1], [x1, 4 - x1**2 - x2**2]])
    prob = PolyProblem([x1, x2], -(x1**2) - x2**2, matrix_inequalities=[G])
    first = solve_moment_relaxation(prob, order=1)
    assert abs(first.bound - (-4.0)) < 1e-5 and not first.flat
    res = solve_moment_relaxation(prob, order=2)
    assert res.status == "optimal"
    assert abs(res.bound - (-4.0)) < 1e-5
    assert res.flat
    _assert_same_points(res, [x1, x2], [[0, -2], [0, 2]])


# --------------------------------------------------------------------------------------
# Solvers, failures, validation
# --------------------------------------------------------------------------------------


def test_scs_agrees_with_published_value() -> None:
    # [HL05] example again, solved with SCS: a second opinion within 1e-3.
    f = -((x1 - 1) ** 2) - (x1 - x2) ** 2 - (x2 - 3) ** 2
    prob = PolyProblem(
        [x1, x2], f, inequalities=[1 - (x1 - 1) ** 2, 1 - (x1 - x2) ** 2, 1 - (x2 - 3) ** 2]
    )
    scs = solve_moment_relaxation(prob, order=2, solver="scs")
    clarabel = solve_moment_relaxation(prob, order=2, solver="clarabel")
    assert scs.solver == "SCS" and scs.status in ("optimal", "inaccurate")
    assert abs(scs.bound - (-2.0)) < 1e-3
    assert abs(scs.bound - clarabel.bound) < 1e-3


def test_solver_failure_is_reported_not_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    def broken_solve(self, *args, **kwargs):
        raise cp.error.SolverError("Solver 'CLARABEL' failed: NumericalError")

    monkeypatch.setattr(cp.Problem, "solve", broken_solve)
    res = solve_moment_relaxation(PolyProblem([x1], x1**2 - x1), order=1)
    assert res.status == "failed"
    assert math.isnan(res.bound)
    assert res.minimizers == [] and not res.flat
    assert "NumericalError" in res.solver_status


def test_unexpected_solver_status_maps_to_failed(monkeypatch: pytest.MonkeyPatch) -> None:
    def limit_solve(self, *args, **kwargs):
        self._status = cp.USER_LIMIT
        return None

    monkeypatch.setattr(cp.Problem, "solve", limit_solve)
    res = solve_moment_relaxation(PolyProblem([x1], x1**2 - x1), order=1)
    assert res.status == "failed" and math.isnan(res.bound)


def test_reduced_accuracy_solve_is_repeated_cautiously(monkeypatch: pytest.MonkeyPatch) -> None:
    # A solver that stops at reduced accuracy the first time: the relaxation is solved
    # once more with CAUTIOUS_OPTIONS, and that (full-accuracy) result is the one kept.
    # min (x - 1)^2 + 2 = 2 at x = 1 (a box, so no interior duals or re-centring).
    from sosalgo.polyopt import CAUTIOUS_OPTIONS

    original = cp.Problem.solve
    calls: list[dict] = []

    def stalling_solve(self, *args, **kwargs):
        calls.append(kwargs)
        out = original(self, *args, **kwargs)
        if len(calls) == 1:
            self._status = cp.OPTIMAL_INACCURATE
        return out

    monkeypatch.setattr(cp.Problem, "solve", stalling_solve)
    prob = PolyProblem([x1], (x1 - 1) ** 2 + 2, bounds={x1: (-3, 3)})
    res = solve_moment_relaxation(prob, order=1, solver_options={"time_limit": 100.0})
    assert len(calls) == 2
    assert calls[1]["max_step_fraction"] == CAUTIOUS_OPTIONS["CLARABEL"]["max_step_fraction"]
    assert "max_step_fraction" not in calls[0] and calls[1]["time_limit"] < 100.0
    assert res.status == "optimal" and res.solver_status == "optimal"
    assert 2.0 - 1e-5 < res.bound <= 2.0
    # an option the caller set is respected: no second solve
    calls.clear()
    res = solve_moment_relaxation(prob, order=1, solver_options={"max_step_fraction": 0.99})
    assert len(calls) == 1 and res.status == "inaccurate"


def test_failed_extraction_means_not_flat(monkeypatch: pytest.MonkeyPatch) -> None:
    # flat is claimed only with a consistent extraction: no atoms, no claim.
    import sosalgo.polyopt.relaxation as relaxation

    monkeypatch.setattr(relaxation, "extract_atoms", lambda *args, **kwargs: None)
    res = solve_moment_relaxation(PolyProblem([x1], (x1 - 1) ** 2 * (x1 + 2) ** 2), order=2)
    assert res.status == "optimal" and abs(res.bound) < 1e-5
    assert not res.flat and res.minimizers == [] and res.flat_order is None


def test_infeasible_problem() -> None:
    # x^2 <= -1 has no real solution; already the first relaxation is infeasible.
    res = solve_moment_relaxation(PolyProblem([x1], x1, inequalities=[-1 - x1**2]), order=1)
    assert res.status == "infeasible"
    assert math.isnan(res.bound)


def test_order_validation_and_bad_input() -> None:
    prob = PolyProblem([x1, x2], x1**4 + x2**2, inequalities=[1 - x1**2 - x2**2])
    with pytest.raises(ValueError):
        solve_moment_relaxation(prob, order=1)
    assert solve_moment_relaxation(prob).order == 2
    with pytest.raises(ValueError):
        PolyProblem([x1], x1 * x2)  # x2 is not a variable
    with pytest.raises(ValueError):
        solve_moment_relaxation(PolyProblem([x1], sp.sin(x1)))
    with pytest.raises(ValueError):
        PolyProblem([x1, x2], x1, matrix_inequalities=[sp.Matrix([[1, x1], [x2, 1]])])
    with pytest.raises(ValueError):
        PolyProblem([x1], x1, bounds={x1: (1, 0)})
    with pytest.raises(ValueError):
        solve_moment_relaxation(PolyProblem([x1], x1**2), solver="no-such-solver")


# --------------------------------------------------------------------------------------
# Honest bounds: large coefficients, unbounded problems, flatness.
# True minima derived by hand in each comment.
# --------------------------------------------------------------------------------------

x, y = sp.symbols("x y")


@pytest.mark.parametrize(
    "objective, inequalities, order, true_min",
    [
        # 1e12 (x - 1)^2 + 1 >= 1 with equality at x = 1 (was reported 1378.9 "optimal, flat")
        (1e12 * (x - 1) ** 2 + 1, [], None, 1.0),
        # both squares vanish at x = 1e-6, y = 2 (was 131.5)
        ((1e6 * x - 1) ** 2 + (y - 2) ** 2, [], None, 0.0),
        # x^2 <= 1e12 means |x| <= 1e6, so min x = -1e6 (was -999845)
        (x, [1e12 - x**2], None, -1e6),
        # 1e4 x Rosenbrock: a sum of squares vanishing at (1, 1) (was 0.1095)
        (1e4 * (100 * (y - x**2) ** 2 + (1 - x) ** 2), [], 2, 0.0),
        # Rosenbrock at order 3 (was 1.1e-5 above 0)
        (100 * (y - x**2) ** 2 + (1 - x) ** 2, [], 3, 0.0),
    ],
)
def test_large_coefficients_never_overstate(objective, inequalities, order, true_min) -> None:
    for solver in ("clarabel", "scs"):
        res = solve_moment_relaxation(
            PolyProblem([x, y], objective, inequalities=inequalities), order=order, solver=solver
        )
        _assert_honest(res, true_min)


def test_scaled_rosenbrock_with_box_is_proven() -> None:
    # The same 1e4 x Rosenbrock with a box around (1, 1): the box certificate proves a
    # bound <= 0, and it is accurate at the problem's scale or the status says otherwise.
    f = 1e4 * (100 * (y - x**2) ** 2 + (1 - x) ** 2)
    res = solve_moment_relaxation(PolyProblem([x, y], f, bounds={x: (0, 2), y: (0, 2)}), order=2)
    _assert_honest(res, 0.0)
    assert res.certified and res.bound <= 0.0


def test_unbounded_problem_is_not_flat() -> None:
    # min x over the reals is unbounded below: no finite bound can be optimal, nothing is
    # flat (was "optimal, flat, -1.2e7").
    for solver in ("clarabel", "scs"):
        res = solve_moment_relaxation(PolyProblem([x], x), order=1, solver=solver)
        assert res.status != "optimal"
        assert not res.flat and res.minimizers == []
        assert not res.certified


@pytest.mark.parametrize(
    "objective, true_min",
    [
        # Motzkin: >= 0 by AM-GM on (x^4 y^2, x^2 y^4, 1), equality at |x| = |y| = 1
        (x**4 * y**2 + x**2 * y**4 - 3 * x**2 * y**2 + 1, 0.0),
        # with u = x^2, v = y^2 >= 0: u v (u + v - 1); on u = v = t, t^2 (2t - 1) is
        # minimal at t = 1/3, value -1/27 (the global minimum, attained at |x| = |y| = 1/sqrt3)
        (x**2 * y**2 * (x**2 + y**2 - 1), -1.0 / 27.0),
    ],
)
def test_non_sos_examples_are_not_flat_at_order_5(objective, true_min) -> None:
    # Neither f - f* is SOS; the order-5 relaxations are unbounded or below f*, and were
    # reported flat.
    res = solve_moment_relaxation(PolyProblem([x, y], objective), order=5)
    _assert_honest(res, true_min)
    assert not res.flat and res.minimizers == []


def test_no_minimizers_unless_optimal() -> None:
    # min x s.t. 1e12 - x^2 >= 0 with SCS ended "inaccurate" and still listed a minimizer
    # (-90.6 for the true -1e6).
    res = solve_moment_relaxation(PolyProblem([x], x, inequalities=[1e12 - x**2]), solver="scs")
    _assert_honest(res, -1e6)
    if res.status != "optimal":
        assert res.minimizers == [] and not res.flat


def test_random_boxed_problems_bound_is_proven() -> None:
    # Random quartics on a box, coefficients from 1e-3 to 1e8: a certified bound never
    # exceeds the minimum found by a fine grid (an upper estimate of the true minimum).
    rng = np.random.default_rng(7)
    gx, gy = np.meshgrid(np.linspace(-2, 3, 301), np.linspace(-1, 2, 301))
    terms = [(i, j) for i in range(5) for j in range(5 - i)]
    certified = 0
    for _ in range(8):
        coef = rng.normal(size=len(terms)) * 10.0 ** rng.integers(-3, 9)
        f = sum(float(c) * x**i * y**j for c, (i, j) in zip(coef, terms, strict=True))
        grid = sum(c * gx**i * gy**j for c, (i, j) in zip(coef, terms, strict=True))
        res = solve_moment_relaxation(
            PolyProblem([x, y], f, bounds={x: (-2, 3), y: (-1, 2)}), order=3
        )
        if res.certified:
            certified += 1
            assert res.bound <= float(grid.min())
    assert certified >= 6


def test_implied_bounds_from_linear_constraints() -> None:
    # By hand: x >= 0, y >= 0 and x + 2y <= 4 give x in [0, 4], y in [0, 2]; z = 1 - x
    # (an equality) then gives z in [-3, 1]. w only has w >= 1: no range.
    from sosalgo.polyopt.problem import compile_problem, implied_bounds

    z, w = sp.symbols("z w")
    prob = PolyProblem(
        [x, y, z, w],
        x + y + z + w,
        inequalities=[x, y, 4 - x - 2 * y, w - 1],
        equalities=[z - 1 + x],
    )
    got = implied_bounds(prob)
    assert set(got) == {x, y, z}
    for v, (lo, hi) in {x: (0, 4), y: (0, 2), z: (-3, 1)}.items():
        assert got[v][0] <= lo and got[v][0] > lo - 1e-12
        assert got[v][1] >= hi and got[v][1] < hi + 1e-12
    assert compile_problem(prob).box_radius() is None  # w is free
    # stated bounds win over implied ones; a third has no exact float (1/3): not used
    prob = PolyProblem([x, y], x + y, inequalities=[x, y, 1 - x - sp.Rational(1, 3) * y],
                       bounds={x: (0, 0.5)})
    assert implied_bounds(prob) == {}
    # with every variable ranged, the box certificate applies: min x + y = 0 at (0, 0)
    prob = PolyProblem([x, y], x + y, inequalities=[x, y, 4 - x - 2 * y])
    assert np.allclose(compile_problem(prob).box_radius(), 1.0)
    res = solve_moment_relaxation(prob, order=1)
    _assert_honest(res, 0.0, rel=0.0)
    assert res.status == "optimal" and res.certified and -1e-5 < res.bound <= 0.0


def test_strings_are_parsed_not_evaluated() -> None:
    import sys

    attack = "__import__('sys').modules.__setitem__('polyopt_probe', 1)"
    with pytest.raises(ValueError):
        PolyProblem([x], attack)
    with pytest.raises(ValueError):
        PolyProblem([x], x, inequalities=["x.__class__"])
    with pytest.raises(ValueError):
        PolyProblem([x], x, matrix_inequalities=[[[attack, "x"], ["x", "1"]]])
    assert "polyopt_probe" not in sys.modules
    with pytest.raises(TypeError):
        PolyProblem([x], object())
    # plain arithmetic over the variables' names is accepted
    res = solve_moment_relaxation(PolyProblem([x], "(x - 1)**2 + 3", inequalities=["x"]))
    assert res.status == "optimal" and abs(res.bound - 3.0) < 1e-6 and res.bound <= 3.0


def test_large_coefficients_solved_accurately_after_recentring() -> None:
    # The same hand-derived minima: re-centring at the first moments, equilibrated
    # scales and exact substitution make these provable to full accuracy with Clarabel.
    cases = [
        (PolyProblem([x], 1e12 * (x - 1) ** 2 + 1), 1.0, [[1.0]]),
        (PolyProblem([x, y], (1e6 * x - 1) ** 2 + (y - 2) ** 2), 0.0, [[1e-6, 2.0]]),
        (PolyProblem([x], x, inequalities=[1e12 - x**2]), -1e6, [[-1e6]]),
    ]
    for prob, true_min, points in cases:
        res = solve_moment_relaxation(prob)
        _assert_honest(res, true_min)
        assert res.status == "optimal" and res.flat
        assert true_min - 1e-5 * max(1.0, abs(true_min)) <= res.bound <= true_min
        got = _points(res, list(prob.variables))
        scale = np.maximum(1e-6, np.abs(np.array(points)))
        assert got.shape == (1, len(prob.variables))
        assert np.all(np.abs(got - np.array(points)) <= 1e-3 * scale)


def test_overstated_dual_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    # A solver that reports its dual level and its value 0.5 (normalized units) too high:
    # the certificate recomputes the residual from the data, so the bound stays below the
    # true minimum 3 of (x - 1)^2 + (y + 2)^2 + 3, and on the box, where no re-solve
    # happens, the status is not "optimal". (Without the box the re-solve zooms in on the
    # first moments, where the same lie is tiny in the problem's units: only honesty is
    # checked there.)
    original = cp.Problem.solve

    def lying_solve(self, *args, **kwargs):
        out = original(self, *args, **kwargs)
        first = self.constraints[0]  # y_0 == 1, whose dual is -gamma
        first.dual_variables[0].save_value(first.dual_value - 0.5)
        self._value = self._value + 0.5
        return out

    monkeypatch.setattr(cp.Problem, "solve", lying_solve)
    f = (x - 1) ** 2 + (y + 2) ** 2 + 3
    boxed = solve_moment_relaxation(PolyProblem([x, y], f, bounds={x: (-4, 4), y: (-4, 4)}))
    _assert_honest(boxed, 3.0)
    assert boxed.certified and boxed.solver_bound > 3.1  # the lie was told, and caught
    assert boxed.status == "inaccurate" and not boxed.flat and boxed.minimizers == []
    _assert_honest(solve_moment_relaxation(PolyProblem([x, y], f)), 3.0)


def test_float_coefficients_are_expanded_exactly() -> None:
    # 1e9 (x - 1/3)^2 + 7 has minimum exactly 7 at x = 1/3. Expanded in sympy Float
    # arithmetic, its constant 1e9/9 + 7 is rounded before the relaxation sees it, which
    # would move the proven bound to 7.0000000066; Floats are taken at their exact binary
    # values and expanded exactly.
    res = solve_moment_relaxation(PolyProblem([x], 1e9 * (x - sp.Rational(1, 3)) ** 2 + 7))
    _assert_honest(res, 7.0, rel=0.0)
    assert res.status == "optimal" and 7.0 - 1e-5 <= res.bound <= 7.0
