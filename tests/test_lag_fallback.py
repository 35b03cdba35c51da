"""The interpolation family's choice of lag never returns a rate slower than one it
certified at a lag it tried. A certificate of lag l is one of lag l + 1, but near
kappa 1000 the solver may certify a slightly slower rate at a larger lag (a
Chambolle-Pock-like method, two proximal calls, unit steps: lag 2 slower than lag 0), so
the choice also tries lag 0. Each lag tried is searched again on its own here, as an
independent reference (the nesting itself: tests/test_lag_nesting.py)."""

from __future__ import annotations

import numpy as np
import pytest

import sosalgo
from sosalgo.analysis import REL_TOL, analyze_algorithm
from sosalgo.certificates.interpolation import Interpolation
from sosalgo.model import Algorithm, bind
from sosalgo.spec import load_spec

TOL = 1e-6

# Chambolle-Pock on f + g (K = I), tau = sigma = theta = 1, the dual step written with
# Moreau's identity prox_{g*}(v) = v - prox_g(v): state (x, y),
#   y1 = prox_f(x - y),  v = y + 2 y1 - x,  y2 = prox_g(v),  x+ = y1,  y+ = v - y2.
CHAMBOLLE_POCK = """\
name: chambolle-pock
description: Chambolle-Pock, tau = sigma = theta = 1, K = I
functions:
  f: {class: smooth_strongly_convex}
  g: {class: convex}
matrices:
  A: [[1, -1], [0, 0]]
  B: [[-1, 0], [0, 1]]
  C: [[1, -1], [1, -1]]
  D: [[-1, 0], [-2, -1]]
  E: [[1, 0]]
oracles: [f, g]
measure: distance
kappa: [1000]
"""


def _slack(rho: float) -> float:
    """Two bracket widths at rho: each search closes its bracket to min(tol, REL_TOL
    (1 - rho)), and a lag only replaces the best when it beats it by one width."""
    return 2 * min(TOL, max(REL_TOL * (1 - rho), 1e-13)) + 1e-12


def _check_never_slower(alg) -> tuple[object, dict[int, float | None]]:
    """The chosen result and every lag it tried, searched alone: the chosen rate is
    certified whenever one of them is, and never slower than any of them."""
    auto = analyze_algorithm(alg, tol=TOL, family=Interpolation())
    assert auto.lags_tried, "the choice names the lags it tried"
    alone = {lag: analyze_algorithm(alg, tol=TOL, family=Interpolation(lag)).rho
             for lag in auto.lags_tried}
    for lag, rho in alone.items():
        if rho is not None:
            assert auto.certified, f"lag {lag} alone certifies {rho}, the choice nothing"
            assert auto.rho <= rho + _slack(rho), (lag, rho, auto.rho)
    return auto, alone


def test_chambolle_pock_gets_the_rate_of_lag_zero(tmp_path):
    path = tmp_path / "cp.yaml"
    path.write_text(CHAMBOLLE_POCK)
    spec = load_spec(path)
    alg = bind(spec, 1000.0)
    auto, alone = _check_never_slower(alg)
    assert 0 in auto.lags_tried and alone[0] is not None
    # the quadratic rate is a floor of every certified rate; 1 is not a rate
    assert sosalgo.analysis.quadratic_rate(alg) <= auto.rho < 1
    # the default command (interpolation, chosen lag) proves it exactly
    res = sosalgo.analyze(spec, 1000.0)
    check = sosalgo.verify(spec, res, simulate=False)
    assert check["verified"] == "exact" and check["rho_proven_float"] <= res.rho + 1e-9


def _random_method(rng: np.random.Generator) -> Algorithm:
    """A 2-state momentum method y = x_k + g (x_k - x_{k-1}), x+ = x_k + b (x_k - x_{k-1})
    - h grad f(y), random h, b, g at a random kappa."""
    kappa = float(np.exp(rng.uniform(np.log(1.5), np.log(60))))
    h, b, g = rng.uniform(0, 2 / kappa), rng.uniform(0, 1), rng.uniform(0, 1)
    return Algorithm(np.array([[0, 1], [-b, 1 + b]]), np.array([[0], [-h]]),
                     np.array([[-g, 1 + g]]), np.array([[0.0, 1.0]]), 1.0, kappa)


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_random_methods_never_slower_than_a_lag_tried(seed):
    rng = np.random.default_rng(seed)
    for _ in range(3):
        _check_never_slower(_random_method(rng))


def _chambolle_pock(tmp_path, tau: float, sigma: float, theta: float) -> str:
    """Chambolle-Pock with K = I and steps tau, sigma, extrapolation theta, the dual step
    by Moreau's identity prox_{sigma g*}(v) = v - sigma prox_{g/sigma}(v/sigma):
    y1 = prox_{tau f}(x - tau y), w = x + (1/sigma - (1 + theta) tau) y - (1 + theta) tau u1,
    y2 = prox_{g/sigma}(w), x+ = y1, y+ = sigma (w - y2) = u2."""
    c2 = 1 / sigma - (1 + theta) * tau
    path = tmp_path / f"cp-{tau:.6g}-{sigma:.6g}-{theta:.6g}.yaml"
    path.write_text(CHAMBOLLE_POCK.replace(
        "A: [[1, -1], [0, 0]]", f"A: [[1, {-tau!r}], [0, 0]]").replace(
        "B: [[-1, 0], [0, 1]]", f"B: [[{-tau!r}, 0], [0, 1]]").replace(
        "C: [[1, -1], [1, -1]]", f"C: [[1, {-tau!r}], [1, {c2!r}]]").replace(
        "D: [[-1, 0], [-2, -1]]", f"D: [[{-tau!r}, 0], [{-(1 + theta) * tau!r}, {-1 / sigma!r}]]"))
    return str(path)


@pytest.mark.parametrize("seed", [3, 4])
def test_random_chambolle_pock_never_slower_than_a_lag_tried(tmp_path, seed):
    rng = np.random.default_rng(seed)
    tau, sigma = float(np.exp(rng.uniform(-1.5, 1))), float(np.exp(rng.uniform(-1.5, 1)))
    theta = float(rng.uniform(0.5, 1))
    kappa = float(np.exp(rng.uniform(np.log(2), np.log(1000))))
    _check_never_slower(bind(load_spec(_chambolle_pock(tmp_path, tau, sigma, theta)), kappa))


def test_chambolle_pock_builder_is_the_unit_step_spec(tmp_path):
    """The general builder at tau = sigma = theta = 1 is the spec above (same matrices)."""
    ours = load_spec(_chambolle_pock(tmp_path, 1.0, 1.0, 1.0))
    (tmp_path / "unit.yaml").write_text(CHAMBOLLE_POCK)
    unit = load_spec(tmp_path / "unit.yaml")
    a, b = bind(ours, 1000.0), bind(unit, 1000.0)
    for name in ("A", "B", "C", "D", "E"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


@pytest.mark.deep
@pytest.mark.parametrize("seed", range(20, 30))
def test_random_methods_never_slower_than_a_lag_tried_deep(seed):
    rng = np.random.default_rng(seed)
    for _ in range(4):
        _check_never_slower(_random_method(rng))
