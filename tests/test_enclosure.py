"""Ball-arithmetic proofs of the design bound (sosalgo.design_search.enclosure, .modes): each
"proven" answer is checked against dense sampling with numpy, and statements that are
false (by a hair) are refused."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from flint import arb

from sosalgo.design_search import enclosure as enc
from sosalgo.design_search.modes import ModeTest
from sosalgo.design_search.polymodel import exact_method
from sosalgo.spec.loading import spec_from_text


def _balls(a):
    return [arb(float(v)) for v in a]


def _grid_values(coef: np.ndarray, degrees, n=41):
    """p(u) on a grid of [-1, 1]^k (numpy, independent of the code under test)."""
    axes = [np.linspace(-1, 1, n)] * len(degrees)
    vals = []
    for u in itertools.product(*axes):
        terms = coef.reshape(tuple(d + 1 for d in degrees))
        v = 0.0
        for idx in np.ndindex(*terms.shape):
            v += terms[idx] * np.prod([ui**e for ui, e in zip(u, idx, strict=True)])
        vals.append(v)
    return np.array(vals)


@pytest.mark.parametrize("seed", range(30))
def test_poly_positive_is_never_wrong(seed):
    rng = np.random.default_rng(seed)
    degrees = (int(rng.integers(1, 4)),) * int(rng.integers(1, 3))
    size = int(np.prod([d + 1 for d in degrees]))
    coef = rng.normal(size=size) * 0.3
    coef[0] = abs(coef[0]) + rng.uniform(0, 1.5)
    even = enc.even_mask(degrees)
    if enc.poly_positive(_balls(coef), even):
        assert _grid_values(coef, degrees, n=21).min() > 0


def test_poly_positive_decides_tight_cases():
    # p(u) = u^2 + 1e-12 > 0 (even term), p(u) = u + 1 - 1e-12 has a root at -1 + 1e-12
    assert enc.poly_positive(_balls([1e-12, 0.0, 1.0]), enc.even_mask((2,)))
    assert not enc.poly_positive(_balls([1 - 1e-12, 1.0]), enc.even_mask((1,)))
    assert not enc.poly_positive(_balls([1.0, 1.0]), enc.even_mask((1,)))  # p(-1) = 0
    # 1/10 is not a float: a ball around it minus the float 0.1 is not provably positive
    tenth = arb(1) / 10
    assert not enc.poly_positive([tenth - arb(0.1)], np.array([True]))


def test_is_pd_on_hard_matrices():
    n = 6
    hilbert = [[arb(1) / (i + j + 1) for j in range(n)] for i in range(n)]
    assert enc.is_pd(hilbert)  # PD, condition number ~1e7
    assert not enc.is_pd([[arb(1), arb(1)], [arb(1), arb(1)]])  # singular PSD
    wide = [[arb(1), arb(1, 1e-6)], [arb(1, 1e-6), arb(1)]]  # contains a singular matrix
    assert not enc.is_pd(wide)
    eps = 1e-14
    assert enc.is_pd([[arb(1), arb(1 - eps)], [arb(1 - eps), arb(1)]])


@pytest.mark.parametrize("seed", range(20))
def test_psd_on_box_is_never_wrong(seed):
    rng = np.random.default_rng(100 + seed)
    s, degrees = 3, (2, 1)
    nmono = 6
    mats = [rng.normal(size=(s, s)) * 0.2 for _ in range(nmono)]
    mats = [0.5 * (m + m.T) for m in mats]
    mats[0] += np.eye(s) * rng.uniform(0.2, 2.0)
    coef = [[[arb(float(v)) for v in row] for row in m] for m in mats]
    if enc.psd_on_box(coef, enc.even_mask(degrees)):
        for u in itertools.product(np.linspace(-1, 1, 15), repeat=2):
            pw = [1, u[1], u[0], u[0] * u[1], u[0] ** 2, u[0] ** 2 * u[1]]
            M = sum(p * m for p, m in zip(pw, mats, strict=True))
            assert np.linalg.eigvalsh(M)[0] > 0


HIDDEN = """
name: hidden
parameters:
  h: {value: 1.5/L, range: [0, 2/L]}
  b: {value: 1, range: [-2, 2]}
  g: {value: 0.5, range: [-0.5, 0.5]}
matrices:
  A: [[1, 0], [0, 0.9375]]
  B: [[-h], [b]]
  C: [[1, g]]
  E: [[1, 0]]
kappa: [10]
"""


def test_mode_argument_never_proves_a_box_with_a_hidden_mode():
    """On g = 0 the slow mode 0.9375 is invisible to the output (a cancellation): the
    method is gradient descent there (rate 0.85). Boxes containing g = 0 are never proven
    by the mode argument at T = 0.9; boxes away from it may be."""
    spec = spec_from_text(HIDDEN, "hidden.yaml")
    method = exact_method(spec, 10.0, ["b", "g"])
    modes = ModeTest(method)
    T2 = 0.9**2
    rng = np.random.default_rng(5)
    for _ in range(40):
        w = rng.uniform(1e-4, 0.3, size=2)
        zc = np.array([rng.uniform(-1 + w[0], 1 - w[0]), rng.uniform(-w[1], w[1]) * 0.9])
        assert not modes.proves(zc, w, T2), (zc, w)  # g = 0 (z_g = 0) inside
    away = [modes.proves(np.array([zb, 0.6]), np.array([0.05, 0.05]), T2)
            for zb in np.linspace(-0.9, 0.9, 7)]
    assert any(away)
