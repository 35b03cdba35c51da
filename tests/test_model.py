"""The numeric model: binding kappa and parameters, the fixed point of eq. (11)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sosalgo.model import (
    Algorithm,
    ModelError,
    bind,
    design_box,
    evaluate_algorithm,
    fixed_point,
)
from sosalgo.spec import load_spec, spec_from_text

from .conftest import SPECS


def test_nesterov_templates_at_10_match_the_formulas():
    alg = bind(load_spec(SPECS / "nesterov.yaml"), 10.0)
    beta = (np.sqrt(10) - 1) / (np.sqrt(10) + 1)
    assert alg.m == pytest.approx(1.0) and alg.L == pytest.approx(10.0)
    np.testing.assert_allclose(alg.A, [[0, 1], [-beta, 1 + beta]], rtol=1e-14)
    np.testing.assert_allclose(alg.B, [[0], [-0.1]], rtol=1e-14)
    np.testing.assert_allclose(alg.C, [[-beta, 1 + beta]], rtol=1e-14)
    np.testing.assert_allclose(fixed_point(alg), [1.0, 1.0], atol=1e-12)


def test_theta_overrides_and_tied_parameters_follow():
    spec = load_spec(SPECS / "nesterov.yaml")
    alg = bind(spec, 10.0, {"beta": 0.25})
    assert alg.params["beta"] == pytest.approx(0.25) and alg.params["gamma"] == pytest.approx(
        0.25)
    with pytest.raises(ModelError, match="tied"):
        bind(spec, 10.0, {"gamma": 0.1})


def test_loader_refuses_a_spec_without_fixed_point():
    text = ("name: drift\nparameters:\n  h: {value: 1/L, range: [0, 2/L]}\nmatrices:\n"
            "  A: [[1, 1], [0, 1]]\n  B: [[0], [-h]]\n  C: [[0, 1]]\n  E: [[0, 1]]\n"
            "kappa: 10\n")
    with pytest.raises(Exception, match="fixed point"):
        spec_from_text(text)  # the loader refuses it at every kappa of the spec


def test_algorithm_accepts_lists_and_refuses_no_fixed_point():
    alg = Algorithm([[1.0]], [[-0.1]], [[1.0]], [[1.0]], 1.0, 10.0)
    assert alg.n == 1 and alg.kappa == pytest.approx(10.0)
    with pytest.raises(ValueError):
        Algorithm([[0.5]], [[-0.1]], [[1.0]], [[1.0]], 1.0, 10.0)  # (1 - A) u = 0 forces u = 0


def test_bind_refuses_kappa_at_most_one_and_a_parameter_without_fixed_point():
    spec = load_spec(SPECS / "gradient.yaml")
    with pytest.raises(ModelError, match="kappa"):
        bind(spec, 1.0)  # kappa must be > 1
    drift = spec_from_text("name: d\nparameters:\n  a: {value: 1, range: [0.5, 1]}\n"
                           "matrices:\n  A: [[a]]\n  B: [[-1/L]]\n  C: [[1]]\n  E: [[1]]\n"
                           "kappa: 10\n")
    assert bind(drift, 10.0).n == 1
    with pytest.raises(ModelError, match="fixed point"):
        bind(drift, 10.0, {"a": 0.75})  # (1 - a) u = 0 forces u = 0: no fixed point
    with pytest.raises(ModelError, match="fixed point"):
        evaluate_algorithm(drift, 10.0, {"a": 0.75})  # the same check, one place


def _gradient_with_range(hi: str):
    return spec_from_text("name: g\nparameters:\n  h: {value: 1/L, range: [0, " + hi + "]}\n"
                          "matrices:\n  A: [[1]]\n  B: [[-h]]\n  C: [[1]]\n  E: [[1]]\n"
                          "kappa: 10\n")


def test_design_box_refuses_a_range_too_large_and_names_the_parameter():
    with pytest.raises(ModelError, match="too large for design") as err:
        design_box(_gradient_with_range("1e300"), 10.0, ["h"])
    assert err.value.field == "parameters.h.range" and "h = 1e+300" in err.value.message
    # an ordinary range is the parameter box itself: [0, 2/L] at L = 10
    assert design_box(_gradient_with_range("2/L"), 10.0, ["h"]) == [(0.0, 0.2)]


def test_design_box_blames_an_entry_that_overflows_not_the_parameter_value():
    # h = 1e30 is a modest number, but B = -h*h reaches 1e60: too large for design
    spec = spec_from_text("name: g\nparameters:\n  h: {value: 1/L, range: [0, 1e30]}\n"
                          "matrices:\n  A: [[1]]\n  B: [[-h*h]]\n  C: [[1]]\n  E: [[1]]\n"
                          "kappa: 10\n")
    with pytest.raises(ModelError, match=r"reach 1e\+60"):
        design_box(spec, 10.0, ["h"])


def test_fixed_point_of_overflowing_matrices_is_none_without_a_warning():
    alg = Algorithm([[1e300, 1e300], [1e300, 1e300]], [[1.0], [1.0]], [[1e300, 1.0]],
                    [[1.0, 1e300]], 1.0, 10.0, require_fixed_point=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning would fail the test
        assert fixed_point(alg) is None
    with pytest.raises(ModelError, match=r"matrices.A\[0\]\[0\].*magnitudes"):
        Algorithm([[1e306, 1.0], [1.0, 1.0]], [[1.0], [1.0]], [[1.0, 1.0]],
                  [[1.0, 1.0]], 1.0, 10.0, require_fixed_point=False)
    from sosalgo.oracles import consistent_solution

    lhs = np.array([[1 - 1e300, -1e300], [-1e300, 1 - 1e300], [1e300, 1.0], [1.0, 1e300]])
    rhs = np.array([[0.0], [0.0], [1.0], [1.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning would fail the test
        assert consistent_solution(lhs, rhs) is None
