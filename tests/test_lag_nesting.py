"""A certificate of lag l is one of lag l + 1: P padded with zeros, the weights of the new
oldest values 0, every multiplier moved one step later in the window and the new pairs'
multipliers 0. Here the lifting is done by the test itself and the lifted certificate is
proven by the exact verifier (which rebuilds the windows on rational numbers), for random
single-gradient and composite methods; and the rate the solver certifies at lag 1 is never
slower than at lag 0 (up to the search tolerance).

Chambolle-Pock (K = I, tau = sigma = theta = 1, kappa 1000): a state in the kernel of A
that only its dual call sees makes every lag >= 1 window carry a direction on which every
quadratic form vanishes, so that without care no lag >= 1 certificate is strictly
feasible and the solver certifies nothing at lags 1 and 2. The construction removes
those directions (:func:`sosalgo.certificates.composite.facial_reduction`); the test
checks that the lifted lag-0 certificate does not use anything the reduction removes."""

from __future__ import annotations

import re
from collections import defaultdict
from fractions import Fraction

import numpy as np
import pytest

from sosalgo.analysis import REL_TOL, analyze_algorithm
from sosalgo.certificates.composite import composite_structure, facial_reduction
from sosalgo.certificates.interpolation import Interpolation
from sosalgo.model import bind
from sosalgo.spec import load_spec

from .test_lag_fallback import CHAMBOLLE_POCK

TOL = 1e-6

SEED = """\
name: random-momentum
description: y = x + g (x - x-), x+ = x + b (x - x-) - h grad f(y)
matrices:
  A: [[0, 1], [{mb}, {a22}]]
  B: [[0], [{mh}]]
  C: [[{mg}, {c2}]]
  E: [[0, 1]]
kappa: [{kappa}]
"""

PROX_GRAD_MOMENTUM = """\
name: random-proximal-momentum
description: proximal gradient with momentum on f + g
functions:
  f: {{class: smooth_strongly_convex}}
  g: {{class: convex}}
matrices:
  A: [[0, 1], [{mbg}, {a22}]]
  B: [[0, 0], [{bh}, {bh}]]
  C: [[{mg}, {c2}], [{mg}, {c2}]]
  D: [[0, 0], [{mh}, {mh}]]
  E: [[0, 1]]
oracles: [f, g]
measure: distance
kappa: [{kappa}]
"""


def _num(v: Fraction) -> str:
    return str(v)


def _frac(rng: np.random.Generator, lo: float, hi: float) -> Fraction:
    """A random rational in [lo, hi] (exact: the fixed point of the method then holds
    exactly, as the exact verifier requires)."""
    return Fraction(int(rng.integers(round(lo * 1000), round(hi * 1000) + 1)), 1000)


def _seed_spec(rng: np.random.Generator) -> tuple[str, float]:
    """A 2-state momentum method (one gradient call) with random h, b, g, kappa."""
    kappa = round(float(np.exp(rng.uniform(np.log(1.5), np.log(50)))), 2)
    h = _frac(rng, 0.2, 1.5) / Fraction(str(kappa))
    b, g = _frac(rng, 0, 0.6), _frac(rng, 0, 0.6)
    return SEED.format(mb=_num(-b), a22=_num(1 + b), mh=_num(-h), mg=_num(-g), c2=_num(1 + g),
                       kappa=_num(kappa)), kappa


def _composite_spec(rng: np.random.Generator) -> tuple[str, float]:
    """Proximal gradient with momentum on f + g (two calls): state (x_{k-1}, x_k),
    y1 = x_k + g (x_k - x_{k-1}), y2 = prox_{h g}(y1 - h u1), x_{k+1} = y2 + b (y2 - x_k),
    written with y2 = y1 - h (u1 + u2)."""
    kappa = round(float(np.exp(rng.uniform(np.log(1.5), np.log(30)))), 2)
    h = _frac(rng, 0.3, 1.5) / Fraction(str(kappa))
    b, g = _frac(rng, 0, 0.6), _frac(rng, 0, 0.6)
    # x+ = (1 + b) y2 - b x_k = (1 + b)(-g x- + (1 + g) x - h u1 - h u2) - b x
    mbg = -(1 + b) * g
    a22 = (1 + b) * (1 + g) - b
    return PROX_GRAD_MOMENTUM.format(
        mbg=_num(mbg), a22=_num(a22), bh=_num(-(1 + b) * h), mg=_num(-g), c2=_num(1 + g),
        mh=_num(-h), kappa=_num(kappa)), kappa


def _chambolle_pock_spec(rng: np.random.Generator) -> tuple[str, float]:
    """Chambolle-Pock (K = I) with random steps tau, sigma, extrapolation theta, the dual
    step by Moreau's identity prox_{sigma g*}(v) = v - sigma prox_{g/sigma}(v/sigma):
    y1 = prox_{tau f}(x - tau y), w = x + (1/sigma - (1 + theta) tau) y - (1 + theta) tau u1,
    y2 = prox_{g/sigma}(w), x+ = y1, y+ = sigma (w - y2) = u2."""
    kappa = round(float(np.exp(rng.uniform(np.log(2), np.log(200)))), 2)
    tau, sigma, theta = _frac(rng, 0.3, 2), _frac(rng, 0.3, 2), _frac(rng, 0.5, 1)
    c2, d21 = 1 / sigma - (1 + theta) * tau, -(1 + theta) * tau
    text = (CHAMBOLLE_POCK.replace("A: [[1, -1], [0, 0]]", f"A: [[1, {-tau}], [0, 0]]")
            .replace("B: [[-1, 0], [0, 1]]", f"B: [[{-tau}, 0], [0, 1]]")
            .replace("C: [[1, -1], [1, -1]]", f"C: [[1, {-tau}], [1, {c2}]]")
            .replace("D: [[-1, 0], [-2, -1]]", f"D: [[{-tau}, 0], [{d21}, {-1 / sigma}]]")
            .replace("kappa: [1000]", f"kappa: [{kappa}]"))
    return text, kappa


def _later(label: str) -> str:
    """A pair label of lag l's window, one step later (lag l + 1's names): y1[0] -> y1[1],
    y0 -> y1, x[0] -> x[1], x0 -> x1; the optimum stays."""
    label = re.sub(r"\[(\d+)\]", lambda m: f"[{int(m.group(1)) + 1}]", label)
    return re.sub(r"(?<![\w\[])([yx])(\d+)(?![\w\]])", lambda m: f"{m[1]}{int(m[2]) + 1}",
                  label) if "[" not in label else label


def lift(cert: dict, n: int, calls: int) -> dict:
    """The lag-(l + 1) certificate of a lag-l one, built here: P padded with zero rows and
    columns for the older inputs, zero weights for the older values, the multipliers one
    step later, every other multiplier 0."""
    P = np.asarray(cert["P"], dtype=float)
    side = len(P) + calls
    big = np.zeros((side, side))
    big[: len(P), : len(P)] = P
    mult = {part: defaultdict(float, {_later(k): float(v) for k, v in vals.items()})
            for part, vals in cert["multipliers"].items()}
    return {**cert, "lag": int(cert["lag"]) + 1, "P": big.tolist(),
            "p": [float(v) for v in cert["p"]] + [0.0] * calls, "multipliers": mult}


def test_later_labels():
    assert _later("y0>x1") == "y1>x2"
    assert _later("*>y3") == "*>y4"
    assert _later("f:y1[0]>y1[1]") == "f:y1[1]>y1[2]"
    assert _later("g:x[1]>*#2") == "g:x[2]>*#2"


def _slack(rho: float) -> float:
    """Two bracket widths at rho (each search closes to min(tol, REL_TOL (1 - rho)))."""
    return 2 * min(TOL, max(REL_TOL * (1 - rho), 1e-13)) + 1e-12


def _nesting(tmp_path, text: str, kappa: float) -> None:
    path = tmp_path / "method.yaml"
    path.write_text(text)
    spec = load_spec(path)
    alg = bind(spec, kappa)
    zero = analyze_algorithm(alg, tol=TOL, family=Interpolation(0))
    one = analyze_algorithm(alg, tol=TOL, family=Interpolation(1))
    assert zero.rho is not None, "a case that certifies nothing tests nothing"
    assert one.rho is not None, f"lag 0 certifies {zero.rho}, lag 1 nothing"
    assert one.rho <= zero.rho + _slack(zero.rho), (zero.rho, one.rho)
    calls = getattr(alg, "p", 1)
    lifted = lift(zero.certificate, alg.n, calls)
    proof = Interpolation(1).exact_check(spec, kappa, zero.rho, lifted)
    assert proof.verified == "exact", proof.reason
    assert proof.rho_proven_float <= zero.rho * (1 + 1e-9) + 1e-9
    if calls > 1:  # the reduced lag-1 problem keeps every multiplier the lifted one uses
        st = composite_structure(alg, 1)
        for part, win in (("decrease", st.dec), ("positivity", st.pos)):
            gone = facial_reduction(win)[1]
            used = [lab for lab, g in zip(win.labels, gone, strict=True)
                    if g and lifted["multipliers"][part][lab] != 0]
            assert not used, used


@pytest.mark.parametrize("seed", [1, 2, 3, 5])
def test_lag_zero_lifts_to_lag_one_single_gradient(tmp_path, seed):
    rng = np.random.default_rng(seed)
    _nesting(tmp_path, *_seed_spec(rng))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_lag_zero_lifts_to_lag_one_composite(tmp_path, seed):
    rng = np.random.default_rng(seed)
    _nesting(tmp_path, *_composite_spec(rng))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_lag_zero_lifts_to_lag_one_chambolle_pock(tmp_path, seed):
    rng = np.random.default_rng(seed)
    _nesting(tmp_path, *_chambolle_pock_spec(rng))


def test_chambolle_pock_lag_one_is_not_slower(tmp_path):
    """The method of the report: lag 1 certifies a rate no slower than lag 0 and the
    lifted lag-0 certificate is a lag-1 certificate (proven exactly)."""
    _nesting(tmp_path, CHAMBOLLE_POCK, 1000.0)


def test_chambolle_pock_isotropic_direction(tmp_path):
    """The direction the reduction removes is the one the analysis predicts: xi_0 in
    ker A = span (1, 1) (with C (1, 1) = 0 for the primal call, only the dual call's point
    moves, by -2), no input; none at lag 0."""
    path = tmp_path / "cp.yaml"
    path.write_text(CHAMBOLLE_POCK)
    alg = bind(load_spec(path), 1000.0)
    assert composite_structure(alg, 0).dec.iso.shape[1] == 0
    assert composite_structure(alg, 0).pos.iso.shape[1] == 0
    for lag in (1, 2):
        st = composite_structure(alg, lag)
        for win in (st.dec, st.pos):
            W = win.iso
            assert W.shape[1] == 1
            w = W[:, 0] / W[0, 0]
            expect = np.zeros(win.width)
            expect[:2] = 1.0
            np.testing.assert_allclose(w, expect, atol=1e-12)


@pytest.mark.parametrize("lag", [1, 2])
def test_chambolle_pock_every_lag_certifies(tmp_path, lag):
    path = tmp_path / "cp.yaml"
    path.write_text(CHAMBOLLE_POCK)
    spec = load_spec(path)
    alg = bind(spec, 1000.0)
    res = analyze_algorithm(alg, tol=TOL, family=Interpolation(lag))
    assert res.certified and res.rho < 1
    proof = Interpolation(lag).exact_check(spec, 1000.0, res.rho, res.certificate)
    assert proof.verified == "exact", proof.reason



DEAD_STATE = """\
name: gradient-dead-state
description: gradient descent with a second state that is reset every step and never read
parameters:
  h: {value: 1/L, range: [0, 2/L]}
matrices:
  A: [[1, 0], [0, 0]]
  B: [[-h], [0]]
  C: [[1, 0]]
  E: [[1, 0]]
kappa: [10]
"""


@pytest.mark.parametrize("lag", [1, 2])
def test_a_dead_state_leaves_the_rate_of_gradient_descent(tmp_path, lag):
    """A state killed by A and never read adds a direction on which every matrix of a
    lag >= 1 window vanishes; without it the rate is gradient descent's, 1 - 1/kappa with
    h = 1/L (Taylor, Hendrickx, Glineur 2018), proven exactly at that lag."""
    path = tmp_path / "dead.yaml"
    path.write_text(DEAD_STATE)
    spec = load_spec(path)
    res = analyze_algorithm(bind(spec, 10.0), tol=TOL, family=Interpolation(lag))
    assert res.certified and abs(res.rho - 0.9) <= _slack(0.9)
    assert res.max_eig_M <= 0 <= res.min_eig_P
    proof = Interpolation(lag).exact_check(spec, 10.0, res.rho, res.certificate)
    assert proof.verified == "exact", proof.reason


def test_chambolle_pock_summary_has_no_sign_noise(tmp_path):
    """The reported eigenvalues leave out the directions where every certificate's
    matrices vanish (there they are 0, rounded to either sign)."""
    path = tmp_path / "cp.yaml"
    path.write_text(CHAMBOLLE_POCK)
    res = analyze_algorithm(bind(load_spec(path), 1000.0), tol=TOL, family=Interpolation(1))
    assert res.max_eig_M < 0 < res.min_eig_P


IRRATIONAL_CP = """\
name: chambolle-pock-irrational
description: Chambolle-Pock, tau = 1/sqrt(2), sigma = theta = 1, K = I
functions:
  f: {class: smooth_strongly_convex}
  g: {class: convex}
parameters:
  t: {value: 1/sqrt(2), range: [0, 2]}
matrices:
  A: [[1, -t], [0, 0]]
  B: [[-t, 0], [0, 1]]
  C: [[1, -t], [1, 1 - 2*t]]
  D: [[-t, 0], [-2*t, -1]]
  E: [[1, 0]]
oracles: [f, g]
measure: distance
kappa: [10]
"""


def test_irrational_chambolle_pock_default_rate_is_proven(tmp_path):
    """With tau irrational the removed direction (tau, 1) is irrational: a lag-1
    certificate has an exact zero eigenvalue there that the enclosures of the exact
    verifier cannot prove. The choice of lag then keeps lag 0 when its rate is within two
    tolerances, and the default analysis is proven exactly."""
    import sosalgo

    path = tmp_path / "cp.yaml"
    path.write_text(IRRATIONAL_CP)
    spec = load_spec(path)
    alg = bind(spec, 10.0)
    assert Interpolation().has_null_directions(alg, 1)
    assert not Interpolation().has_null_directions(alg, 0)
    one = analyze_algorithm(alg, tol=TOL, family=Interpolation(1))
    res = sosalgo.analyze(spec, 10.0)
    assert res.certified and res.rho <= one.rho + 2 * _slack(one.rho)
    check = sosalgo.verify(spec, res, simulate=False)
    assert check["verified"] == "exact", check
