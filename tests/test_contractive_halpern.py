"""The residual of an L-Lipschitz map with a fixed point (``lipschitz_map``) and the optimal
contractive Halpern iteration (``specs/contractive-halpern.yaml``, PEPit's
``optimal_contractive_halpern_iteration``): proven bounds against Park and Ryu's tight
closed form and PEPit, random contractive maps in numpy run through the method (observed
<= proven), tampered documents and witnesses refused, bad parameters refused."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.spec import spec_from_text
from sosalgo.spec.overrides import apply_overrides

SPECS = Path(__file__).resolve().parent.parent / "specs"
SPEC = SPECS / "contractive-halpern.yaml"

# PEPit 0.5.1 with cvxpy's Clarabel (the conformance suite's run, bench/conformance/
# results.csv): wc_optimal_contractive_halpern_iteration(n, gamma), |x_n - A x_n|^2 against
# |x_0 - x*|^2, A (1/gamma)-Lipschitz with a fixed point.
PEPIT = {(10, "11/10"): 0.010613242711387685, (5, "11/10"): 0.06122273061998969}


def _park_ryu(n: int, gamma: Fraction) -> Fraction:
    """Park, Ryu (2022), Cor. 3.3 and Thm. 4.1 (tight): (1 + 1/gamma)^2 ((gamma - 1)/
    (gamma^(n+1) - 1))^2, exactly."""
    return (1 + 1 / gamma) ** 2 * ((gamma - 1) / (gamma ** (n + 1) - 1)) ** 2


def _proven(steps: int, gamma: str, text: str | None = None):
    text = apply_overrides(text or SPEC.read_text(), {"gamma": gamma}, str(SPEC))
    res = sosalgo.pep(spec_from_text(text, str(SPEC)), None, steps)
    assert res.status == "solved"
    assert res.certificate["check_kind"].startswith("exact")
    return res, Fraction(res.certificate["tau_proven"])


@pytest.mark.parametrize("steps, gamma", [(5, "11/10"), (3, "3/2"), (10, "11/10")])
def test_proven_bound_is_park_and_ryus_tight_value(steps, gamma):
    """Never below the tight value, within 1e-6 of it (and of PEPit where recorded); the
    witness is checked exactly and lies below the bound, within 1e-3 of it."""
    res, proven = _proven(steps, gamma)
    tight = _park_ryu(steps, Fraction(gamma))
    assert proven >= tight
    assert float(proven) == pytest.approx(float(tight), rel=1e-6)
    if (steps, gamma) in PEPIT:
        assert float(proven) == pytest.approx(PEPIT[steps, gamma], rel=1e-6)
    chk = res.witness["check"]
    assert chk["verified"] and Fraction(chk["tau_lower"]) <= proven
    assert chk["tau_lower_float"] >= float(tight) * (1 - 1e-3)


def test_lipschitz_constant_one_is_halperns_nonexpansive_case():
    """lipschitz_map at its default L = 1 in Halpern's spec (anchoring 1/(k+2)) proves
    Lieder's tight (2/(N+1))^2."""
    text = (SPECS / "halpern.yaml").read_text().replace(
        "T: {class: nonexpansive}", "T: {class: lipschitz_map}", 1)
    assert "lipschitz_map" in text
    res = sosalgo.pep(spec_from_text(text, "halpern-lipschitz-map.yaml"), None, 4)
    proven = Fraction(res.certificate["tau_proven"])
    assert proven >= Fraction(4, 25)
    assert float(proven) == pytest.approx(4 / 25, rel=1e-6)


def test_class_form_is_the_lipschitz_condition_on_the_map():
    """The class's inequality on (x_a, x_b, u_a, u_b), u = x - T x, holds exactly when
    |T x_a - T x_b| <= L |x_a - x_b| (d = 1 template, checked on random pairs)."""
    from sosalgo.classes import get_class

    cls = get_class("lipschitz_map")
    rng = np.random.default_rng(3)
    for L in (0.5, 10 / 11, 1.0, 2.0):
        (ineq,) = cls.inequalities({"L": L})
        for _ in range(200):
            xa, xb = rng.standard_normal(2)
            ratio = rng.uniform(-1.5, 1.5) * L  # (T x_a - T x_b) = ratio (x_a - x_b)
            ta = rng.standard_normal()
            tb = ta - ratio * (xa - xb)
            X = np.array([xa, xb, xa - ta, xb - tb])
            value = X @ ineq.Q @ X
            if abs(abs(ratio) - L) > 1e-6:
                assert (value >= 0) == (abs(ratio) <= L), (L, ratio, value)


def _rotation(d: int, rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((d, d)))
    return q * np.sign(np.diag(r))


def _random_contraction(gamma: float, d: int, rng: np.random.Generator):
    """A (1/gamma)-Lipschitz map with the fixed point c: a scaled orthogonal map, followed
    by the projection onto a box around c, or through a coordinatewise sine (1-Lipschitz,
    0 at 0) between two orthogonal maps."""
    c = rng.uniform(-1, 1, d)
    Q1, Q2 = _rotation(d, rng), _rotation(d, rng)
    lo, hi = np.minimum(c, -1) - rng.uniform(0, 1, d), np.maximum(c, 1) + rng.uniform(0, 1, d)
    kind = rng.integers(3)
    if kind == 0:
        return c, lambda z: c + Q1 @ (z - c) / gamma
    if kind == 1:
        return c, lambda z: np.clip(c + Q1 @ (z - c) / gamma, lo, hi)
    return c, lambda z: c + Q2 @ np.sin(Q1 @ (z - c)) / gamma


def _ratio(gamma: float, n: int, rng: np.random.Generator) -> float:
    """x_{k+1} = x_0/phi_{k+1} + (1 - 1/phi_{k+1}) T x_k, phi_k = sum_{i<=k} gamma^(2i):
    |x_n - T x_n|^2 / |x_0 - c|^2."""
    c, T = _random_contraction(gamma, int(rng.integers(2, 5)), rng)
    x = x0 = c + 3 * rng.standard_normal(len(c))
    for k in range(n):
        phi = sum(gamma ** (2 * i) for i in range(k + 2))
        x = x0 / phi + (1 - 1 / phi) * T(x)
    return float(np.sum((x - T(x)) ** 2) / np.sum((x0 - c) ** 2))


@pytest.mark.parametrize("gamma", ["11/10", "3/2"])
def test_random_contractive_maps_stay_below_the_proven_bound(gamma):
    _, proven = _proven(4, gamma)
    rng = np.random.default_rng(19)
    worst = max(_ratio(float(Fraction(gamma)), 4, rng) for _ in range(400))
    assert 0 < worst <= float(proven) * (1 + 1e-9)


def _pep_document(tmp_path) -> Path:
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(SPEC), "--steps", "3", "--set", "gamma=3/2",
                                 "--json", "--out", str(out)])
    assert r.exit_code == 0, r.output
    path = tmp_path / "pep.json"
    path.write_text(r.stdout)
    return path


def _refused(tmp_path, doc: dict) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    r = CliRunner().invoke(cli, ["verify", str(bad), "--out", str(tmp_path / "v")])
    assert r.exit_code != 0, r.output
    assert "not verified" in r.output.lower() or "contradicted" in r.output.lower(), r.output


def test_verify_accepts_the_document_and_refuses_tampered_ones(tmp_path):
    """verify re-proves the bound; a smaller tau_proven (below the tight value) or a
    smaller Lipschitz constant in the recorded class is refused."""
    path = _pep_document(tmp_path)
    ok = CliRunner().invoke(cli, ["verify", str(path), "--out", str(tmp_path / "v")])
    assert ok.exit_code == 0, ok.output
    doc = json.loads(path.read_text())
    assert doc["class"]["functions"]["T"]["params"]["L"] == "2/3"
    low = json.loads(path.read_text())
    low_tau = _park_ryu(3, Fraction(3, 2)) * Fraction(99, 100)
    low["certificate"]["tau_proven"] = str(low_tau)
    low["certificate"]["proof"]["tau_proven"] = str(low_tau)
    _refused(tmp_path, low)
    smaller = json.loads(path.read_text())
    for where in (smaller["class"], smaller["certificate"]["proof"]["class"]):
        where["functions"]["T"]["params"]["L"] = "1/2"
    _refused(tmp_path, smaller)


def test_a_tampered_witness_is_refused(tmp_path):
    """The witness verifies (its check and ``sosalgo verify``); with T's answer at the
    first call turned around (u -> -u: the pair with x* is no longer (2/3)-Lipschitz for
    T) it does not."""
    from sosalgo.worstcase.check import check_witness

    _pep_document(tmp_path)
    witness = tmp_path / "o" / "contractive-halpern-pep-N3-witness.json"
    spec = spec_from_text(apply_overrides(SPEC.read_text(), {"gamma": "3/2"}, str(SPEC)),
                          str(SPEC))
    doc = json.loads(witness.read_text())
    assert check_witness(doc, spec)["verified"]
    bad = json.loads(witness.read_text())
    bad["calls"][0][0] = [str(-Fraction(v)) for v in bad["calls"][0][0]]  # step 0's call
    for pt in bad["functions"]["T"]["points"]:
        if pt["label"] == "y0":
            pt["g"] = list(bad["calls"][0][0])
    assert not check_witness(bad, spec)["verified"]
    ok = CliRunner().invoke(cli, ["verify", str(witness), "--out", str(tmp_path / "v")])
    assert ok.exit_code == 0, ok.output
    _refused(tmp_path, bad)


def _one_line_exit_2(r, *words: str) -> None:
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and all(w in lines[0] for w in words), r.output
    assert "Traceback" not in r.output


@pytest.mark.parametrize("entry", ["L: 0", "L: -2", "L: 1/0"])
def test_a_lipschitz_constant_not_positive_is_refused(tmp_path, entry):
    path = tmp_path / "bad.yaml"
    path.write_text(SPEC.read_text().replace("L: 1/gamma", entry, 1))
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(path), "--steps", "3", "--out", str(out)])
    _one_line_exit_2(r, "bad.yaml", "functions.T.L")
    assert not out.exists()


@pytest.mark.parametrize("value", ["0", "-2"])
def test_a_gamma_giving_no_lipschitz_constant_is_refused(tmp_path, value):
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["pep", str(SPEC), "--steps", "3", "--set",
                                 f"gamma={value}", "--out", str(out)])
    _one_line_exit_2(r, "gamma", "functions.T.L")
    assert not out.exists()
