"""The polish of a float dual certificate (:mod:`sosalgo.worstcase.polish`) against closed
forms: the refined (tau, lambda) is a certificate to double precision, its tau the true
worst case, where the solver's answer is only accurate to its tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sosalgo.spec import load_spec
from sosalgo.worstcase.core import pep_problem
from sosalgo.worstcase.polish import polished
from sosalgo.worstcase.sdp import pep_data, solve_pep, value_residual
from sosalgo.worstcase.steps import spec_steps
from tests.conftest import spec_path


def _ogm_bound(N: int) -> float:
    """L/(2 theta_N^2) (L = 1), theta_N by OGM's last-step rule."""
    th = 1.0
    for k in range(N):
        th = (1 + math.sqrt(1 + (8 if k == N - 1 else 4) * th * th)) / 2
    return 1 / (2 * th * th)


def _answer(name: str, kappa: float | None, N: int, measure: str | None = None):
    spec = load_spec(spec_path(name))
    sched = spec_steps(spec, kappa, N)
    mt, st, *_ = pep_problem(spec, kappa, N, measure, None, sched)
    data = pep_data(mt, st)
    if sched is not None:
        data.active, data.strong = np.arange(st.count), True
    return data, solve_pep(data)


def _least_eig(data, ans) -> float:
    Sh = ans.S * np.outer(data.w, data.w)
    return float(np.linalg.eigvalsh(Sh)[0] / np.abs(Sh).max())


@pytest.mark.parametrize("N", [3, 10])
def test_polished_ogm_is_kim_fessler(N):
    """OGM: the solver's tau is about 1e-8 off L/(2 theta_N^2) and its S has eigenvalues
    of about -1e-9 |S|; the polished tau is the closed form to 1e-12, with S's least
    eigenvalue above -1e-12 |S|, every multiplier >= 0 and c_F >= 0 to round-off."""
    data, ans = _answer("ogm", None, N)
    got = polished(data, ans)
    assert got is not None
    closed = _ogm_bound(N)
    assert got.tau == pytest.approx(closed, rel=1e-12)
    assert _least_eig(data, got) > -1e-12
    assert np.all(got.lam >= 0)
    assert value_residual(data, got.tau, got.lam).min() > -1e-14


def test_polished_gradient_distance_at_the_closed_form():
    """Gradient descent h = 1/L on F(1, 10), |x_N - x*|^2 / |x_0 - x*|^2, N = 20: the
    polished certificate holds tau at the reported value, which is 0.9^(2N) up to the
    solver's accuracy, and its S is PSD to round-off."""
    data, ans = _answer("gradient", 10.0, 20, "dist")
    got = polished(data, ans, float(ans.primal))
    assert got is not None
    assert got.tau == pytest.approx(0.81 ** 20, rel=1e-7)
    assert got.tau >= 0.81 ** 20 * (1 - 1e-7)
    assert _least_eig(data, got) > -1e-12
    assert np.all(got.lam >= 0)
