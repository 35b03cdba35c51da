"""Class LMIs on tuples of points (sosalgo.worstcase.lmis): PEPit's "intermediate" and
"expensive" smooth Lojasiewicz classes and its expensive strongly monotone operators.

Soundness is judged by code that shares none of sosalgo's: explicit functions and
operators of each class, run in numpy, never exceed the proven bound; a certificate whose
LMI cut is not PSD, or that drops the cuts, is refused."""

from __future__ import annotations

import copy
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import sosalgo
from sosalgo.spec.loading import load_spec, spec_from_text
from sosalgo.worstcase.exact import reprove_certificate

SPECS = Path(__file__).resolve().parents[1] / "specs"
BENCH = Path(__file__).resolve().parents[1] / "bench" / "conformance" / "specs"
PL = {v: SPECS / f"gradient-pl-{v}.yaml" for v in ("intermediate", "expensive")}


def _pl_spec(variant: str, gamma: str, mu: str = "0.2"):
    text = (PL[variant].read_text().replace("gamma: {value: 1/L}", f"gamma: {{value: {gamma}}}")
            .replace("mu: {value: 0.2}", f"mu: {{value: {mu}}}"))
    return spec_from_text(text, source=str(PL[variant]))


def _proven(spec, steps: int) -> Fraction:
    res = sosalgo.pep(spec, None, steps, witness=False)
    proof = res.certificate["proof"]
    assert proof["proven"], proof.get("detail")
    return Fraction(proof["tau_proven"])


def _pl_members(rng: np.random.Generator, d: int):
    """L = 1, mu >= 0.2 functions with f* = 0 at 0: separable sums of quadratics h x^2/2
    (h in [0.2, 1]) and of the nonconvex c x^2/2 + e sin^2 x (c = 0.45, e = 0.275:
    f'' in [-0.1, 1], PL constant 0.2075 on a fine grid, c = 0.45 far out)."""
    kinds = rng.integers(0, 2, d)
    h = rng.uniform(0.2, 1.0, d)

    def f(x):
        return float(np.sum(np.where(kinds == 0, h * x ** 2 / 2,
                                     0.45 * x ** 2 / 2 + 0.275 * np.sin(x) ** 2)))

    def grad(x):
        return np.where(kinds == 0, h * x, 0.45 * x + 0.275 * np.sin(2 * x))

    return f, grad


def test_nonconvex_member_is_in_the_class():
    """The nonconvex member's constants, on a grid independent of the test's starts."""
    x = np.linspace(-40, 40, 400001)
    x = x[np.abs(x) > 1e-4]
    f = 0.45 * x ** 2 / 2 + 0.275 * np.sin(x) ** 2
    g = 0.45 * x + 0.275 * np.sin(2 * x)
    assert np.min(g ** 2 / (2 * f)) > 0.2 and np.min(f) > 0
    assert 0.45 + 2 * 0.275 <= 1.0  # |f''| = |0.45 + 0.55 cos 2x| <= 1


@pytest.mark.parametrize("variant", ["intermediate", "expensive"])
def test_gradient_descent_on_pl_members_stays_below_the_proven_bound(variant):
    rng = np.random.default_rng(7)
    for gamma, steps, mu in (("1", 1, "0.2"), ("1/2", 1, "0.2"), ("1", 2, "0.1")):
        tau = _proven(_pl_spec(variant, gamma, mu), steps)  # PEPit's three sets
        g = float(Fraction(gamma))
        worst = 0.0
        for _ in range(300):
            d = int(rng.integers(1, 4))
            f, grad = _pl_members(rng, d)
            x = rng.normal(0, float(rng.choice([0.5, 2.0, 8.0])), size=d)
            x0 = x.copy()
            for _ in range(steps):
                x = x - g * grad(x)
            if f(x0) > 1e-12:
                worst = max(worst, f(x) / f(x0))
        assert 0 < worst <= float(tau) * (1 + 1e-12), (variant, gamma, steps, worst, tau)


def test_expensive_bound_is_below_the_naive_one_and_above_quadratics():
    """The LMIs strengthen the naive conditions (PEPit: 0.683 against 8/11 at n = 1,
    gamma = 1/L); both are above (1 - mu)^2, the quadratic h = mu."""
    naive = _proven(load_spec(SPECS / "gradient-pl.yaml"), 1)
    expensive = _proven(load_spec(PL["expensive"]), 1)
    intermediate = _proven(load_spec(PL["intermediate"]), 1)
    assert Fraction(16, 25) < expensive < Fraction(8, 11) - Fraction(1, 100)
    assert intermediate >= Fraction(8, 11) * (1 - Fraction(1, 10**6))
    assert naive >= Fraction(8, 11) * (1 - Fraction(1, 10**6))


@pytest.mark.parametrize("name,pepit", [("gradient-pl", 0.7346938775),
                                         ("gradient-pl-expensive", 0.6947617)])
def test_two_steps_at_mu_one_tenth_are_proven_at_pepits_value(tmp_path, name, pepit):
    """PEPit's third argument set (mu = 0.1, gamma = 1/L, n = 2; its values): proven
    exactly, at or above PEPit's and within 1e-6 of it. Their certificates are singular
    (the naive one's S is 0 on every direction, the expensive one's exactly 0 once its
    null row is zeroed): the null-row proof must reach them and decide S in rationals."""
    import json

    from click.testing import CliRunner

    from sosalgo.cli import cli

    out = CliRunner().invoke(cli, [
        "pep", str(SPECS / f"{name}.yaml"), "--steps", "2", "--set", "mu=0.1",
        "--set", "gamma=1/L", "--no-witness", "--json", "--out", str(tmp_path / "o")])
    assert out.exit_code == 0, out.output
    cert = json.loads(out.stdout)["certificate"]
    assert cert["check_kind"] == "exact (rational and ball arithmetic)", cert["proof"]
    proven = float(Fraction(cert["tau_proven"]))
    assert pepit <= proven <= pepit + 1e-6, (proven, pepit)


def test_tampered_lmi_cuts_are_refused():
    spec = load_spec(PL["expensive"])
    res = sosalgo.pep(spec, None, 1, witness=False)
    proof = res.certificate["proof"]
    assert proof["proven"] and proof["lmi_cuts"]
    args = (spec, None, 1, res.measure, res.initial)
    assert reprove_certificate(*args, proof)[0]
    used = {lab.rsplit(":", 1)[1] for lab in proof["multipliers_exact"] if ":lmi" in lab}
    assert used
    for k, (j, r, idx, vec) in enumerate(proof["lmi_cuts"]):
        bent = copy.deepcopy(proof)
        # a negative diagonal entry: the cut's matrix is no longer PSD
        bent["lmi_cuts"][k] = [j, r, idx, ["-1"] + list(vec[1:])]
        ok, why = reprove_certificate(*args, bent)
        assert not ok and "positive semidefinite" in why
        break
    none = copy.deepcopy(proof)
    none.pop("lmi_cuts")  # the multipliers name cuts the PEP does not have
    assert not reprove_certificate(*args, none)[0]
    moved = copy.deepcopy(proof)  # a cut at a tuple of points of no LMI
    j, r, idx, vec = moved["lmi_cuts"][0]
    moved["lmi_cuts"][0] = [j, r, [idx[0]] * len(idx), vec]
    assert not reprove_certificate(*args, moved)[0]


def test_bad_alpha_is_refused(tmp_path):
    from click.testing import CliRunner

    from sosalgo.cli import cli

    bad = PL["intermediate"].read_text().replace("alpha: {value: 2*mu/(2*L + mu)}",
                                                 "alpha: {value: 0.5}")
    path = tmp_path / "bad.yaml"
    path.write_text(bad)
    out = CliRunner().invoke(cli, ["pep", str(path), "--steps", "1", "--out",
                                    str(tmp_path / "o")])
    assert out.exit_code == 2 and "alpha" in out.output and "Traceback" not in out.output


# --------------------------------------------------------------------------- operators


def _optimistic(F, proj, x0: np.ndarray, gamma: float, n: int) -> float:
    """PEPit's refined optimistic gradient: |x~_n - x~_n-1|^2 (its measure)."""
    x = proj(x0)
    xt = x
    V = F(xt)
    prev = xt
    for _ in range(n):
        prev = xt
        xt = proj(x - gamma * V)
        Vp, V = V, F(xt)
        x = xt + gamma * (Vp - V)
    return float(np.sum((xt - prev) ** 2))


def _orthant_members(rng: np.random.Generator, d: int, kind: str):
    """Operators with x* = 0 on C = the nonnegative orthant (F(0) = q >= 0): linear
    monotone L = 1 ones (PSD plus skew, norm <= 1) or beta = 1/4 cocoercive ones
    (s (I + Q)/(2 beta), Q orthogonal, s <= 1; symmetric with spectrum in [0, 4]),
    plus q."""
    q = np.abs(rng.normal(size=d)) * rng.choice([0.0, 1.0])
    if kind == "lipschitz":
        P = rng.normal(size=(d, d))
        K = rng.normal(size=(d, d))
        M = rng.uniform(0, 1) * (P @ P.T) + (K - K.T)
        M = M / np.linalg.norm(M, 2) * rng.uniform(0.5, 1.0)
    elif rng.uniform() < 0.5:
        Q, _ = np.linalg.qr(rng.normal(size=(d, d)))
        M = rng.uniform(0.5, 1.0) * (np.eye(d) + Q) / (2 * 0.25)
    else:
        R, _ = np.linalg.qr(rng.normal(size=(d, d)))
        M = (R * rng.uniform(0, 4, d)) @ R.T
    return (lambda x: M @ x + q), (lambda y: np.maximum(y, 0.0))


@pytest.mark.parametrize("kind,spec_name", [
    ("lipschitz", "optimistic-gradient-refined.yaml"),
    ("cocoercive", "optimistic-gradient-refined-cocoercive.yaml")])
def test_optimistic_gradient_on_operators_stays_below_the_proven_bound(kind, spec_name):
    tau = float(_proven(load_spec(BENCH / spec_name), 2))  # PEPit's n = 1
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(400):
        d = int(rng.integers(1, 5))
        F, proj = _orthant_members(rng, d, kind)
        x0 = rng.normal(size=d)
        worst = max(worst, _optimistic(F, proj, x0, 0.25, 1) / float(np.sum(x0 ** 2)))
    assert 0 < worst <= tau * (1 + 1e-12), (worst, tau)


def test_cut_pivots_make_the_multiplier_orthogonal_exactly():
    """A cut's pivot entries are solved for: <Lambda, E_k> = 0 in exact rationals for every
    free multiplier of the 7 x 7 operator LMI, whatever the stored entries; a stored
    negative diagonal entry is refused."""
    from sosalgo.classes.lipschitz_strongly_monotone_expensive import lipschitz_lmis
    from sosalgo.worstcase.lmis import _others, cut_matrix

    lmi = lipschitz_lmis(Fraction(0), Fraction(1), exact=True)[0]
    assert lmi.size == 7 and len(lmi.free) == 9
    rng = np.random.default_rng(1)
    n = len(_others(lmi))
    # diagonally dominant after the pivots: the three pivots tied to the centre entry
    # (4, 4) equal it, the others are entries of size <= 1
    P = rng.integers(-1, 2, size=(7, 7))
    P[4, :] = P[:, 4] = 0
    P = P + P.T + np.diag([100, 100, 100, 100, 10, 100, 100])
    entries = [Fraction(int(P[u, v])) for u, v in _others(lmi)]
    Lam = cut_matrix(lmi, entries, exact=True)
    for E in lmi.free:
        assert sum(Lam[u, v] * E[u, v] for u in range(7) for v in range(7)) == 0
    with pytest.raises(ValueError, match="positive semidefinite"):
        cut_matrix(lmi, [Fraction(-1)] + entries[1:], exact=True)
    assert n == 28 - 9
