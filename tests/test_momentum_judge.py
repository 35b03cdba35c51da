"""The independent judge of the momentum soundness suites (``tests/independent_momentum.py``)
against closed forms, and refusing a tampered cycle."""

from __future__ import annotations

import pytest

from .independent_momentum import (
    Momentum,
    check_cycle,
    gamma_quadratic,
    gd_tau_convex,
    gd_tau_strong,
    max_radius,
    noise_monte_carlo,
    pep_floor,
    sublinear_floor,
)
from .momentum_cases import (
    F,
)

pytestmark = pytest.mark.xdist_group("soundness-momentum")


# ---------------------------------------------------------------- the judge itself


def test_judge_against_closed_forms():
    """The judge's floors on gradient descent and heavy ball against closed forms."""
    gd = Momentum(F(1), F(0), F(0), F(0), F(1))
    c, _ = sublinear_floor(gd)
    assert 0.2499 <= c <= 0.25  # sup_k k/(4k + 2) = L/4 (Drori-Teboulle), k <= 2000
    for N in (1, 3):
        v, what = pep_floor(gd, N, "f")
        assert 0.999 * gd_tau_convex(1.0, N) <= v <= gd_tau_convex(1.0, N) * (1 + 1e-12), what
    for hL in (F(1, 2), F(1), F(19, 10)):
        g = Momentum(hL, F(0), F(0), F(1), F(10))
        v, _ = pep_floor(g, 3, "dist")
        assert v == pytest.approx(gd_tau_strong(float(g.h), 1.0, 10.0, 3), rel=1e-12)
        h = float(g.h)
        gam, _ = gamma_quadratic(g)  # gamma_q^2 = h / (q (2 - h q)), largest at q = m or L
        assert gam**2 == pytest.approx(max(h / (q * (2 - h * q)) for q in (1.0, 10.0)),
                                       rel=1e-10)
        assert max_radius(g)[0] == pytest.approx(max(abs(1 - h), abs(1 - 10 * h)), rel=1e-12)
    s = 5.0  # heavy ball tuned for quadratics, kappa 25: every mode at sqrt(beta) = 2/3
    hb = Momentum(F(25, 9), F(4, 9), F(0), F(1), F(25))
    assert max_radius(hb)[0] == pytest.approx((s - 1) / (s + 1), rel=1e-7)
    mean, se = noise_monte_carlo(Momentum(F(1, 2), F(0), F(0), F(1), F(4)), 1e9, False, 0.1)
    h = 1 / 8  # f = 2 x^2 (delta beyond reach): h / (L (2 - h L))
    assert abs(mean - h / (4 * (2 - h * 4))) <= 5 * se


def test_judge_rejects_tampered_cycle():
    """A hand-made 2-cycle of x+ = x - h f'(x), h L = 2, on f = 2 x^2 of F(1, 4) (points
    1, -1, gradients 4, -4, values 2): accepted; a changed value or gradient is refused."""
    meth = Momentum(F(2), F(0), F(0), F(1), F(4))
    cyc = {"length": 2, "factor": "1", "points": [["1"], ["-1"]], "gradients": [["4"], ["-4"]],
           "values": ["2", "2"], "states": [[["-1"], ["1"]], [["1"], ["-1"]]]}
    assert check_cycle(meth, cyc) is None
    assert check_cycle(meth, cyc | {"values": ["2", "1"]}) is not None
    assert check_cycle(meth, cyc | {"gradients": [["4"], ["-3"]]}) is not None
