"""Linear, symmetric and skew-symmetric linear operator classes (Gram-level conditions):
the worst cases of x+ = x - gamma M x and of the resolvent step against closed forms, and
explicit matrices in numpy never above the proven bound."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import sosalgo
from sosalgo.spec import load_spec

SPEC = """name: {name}
description: x+ = x - gamma M x (a forward step), or the resolvent step, on one operator
functions:
  M: {{class: {cls}{params}}}
parameters:
  gamma: {{value: {gamma}}}
matrices:
  A: [[1]]
  B: [[-gamma]]
  C: [[1]]
  D: [[{d}]]
  E: [[1]]
oracles: [M]
measure: distance
m: 0
L: 1
pep:
  measure: dist
  initial: dist(x_0)
references:
  "none": 1
"""


def _spec(tmp_path, cls, gamma, params="", resolvent=False):
    path = tmp_path / f"{cls}.yaml"
    path.write_text(SPEC.format(name=cls.replace("_", "-"), cls=cls, params=params,
                                gamma=gamma, d="-gamma" if resolvent else "0"))
    return load_spec(path)


def _proven(res) -> float:
    return float(Fraction(res.certificate["tau_proven"]))


@pytest.mark.parametrize("gamma,n", [("1/2", 3), ("3/2", 2), ("1/5", 4)])
def test_symmetric_forward_step_closed_form(tmp_path, gamma, n):
    """Spectrum in [mu, L] = [1/4, 1]: |x_n - x*|^2 <= max |1 - gamma q|^(2n) over it."""
    spec = _spec(tmp_path, "symmetric_linear_operator", gamma, ", mu: 1/4, L: 1")
    res = sosalgo.pep(spec, None, n)
    g = float(Fraction(gamma))
    exact = max(abs(1 - g / 4), abs(1 - g)) ** (2 * n)
    assert exact * (1 - 1e-9) <= _proven(res) <= exact * (1 + 1e-6)
    assert res.witness["check"]["verified"]
    assert res.witness["check"]["tau_lower_float"] >= exact * (1 - 1e-3)


@pytest.mark.parametrize("gamma,n", [("1/2", 2), ("1", 3)])
def test_skew_forward_step_closed_form(tmp_path, gamma, n):
    """|x - gamma M x|^2 = |x|^2 + gamma^2 |Mx|^2 for skew M: (1 + gamma^2 L^2)^n."""
    spec = _spec(tmp_path, "skew_symmetric_linear_operator", gamma, ", L: 1")
    res = sosalgo.pep(spec, None, n, witness=False)
    exact = (1 + float(Fraction(gamma)) ** 2) ** n
    assert exact * (1 - 1e-9) <= _proven(res) <= exact * (1 + 1e-6)


def test_skew_resolvent_closed_form(tmp_path):
    """(I + gamma M)^-1 for skew M with |M| <= L: the factor 1/(1 + gamma^2 s^2) per
    step, s the singular value: worst at s = 0, 1 (no contraction)."""
    spec = _spec(tmp_path, "skew_symmetric_linear_operator", "1", ", L: 1", resolvent=True)
    res = sosalgo.pep(spec, None, 2, witness=False)
    assert 1 - 1e-9 <= _proven(res) <= 1 + 1e-6


def test_linear_operator_forward_step_closed_form(tmp_path):
    """|M| <= L, any linear M: |(I - gamma M)^n| <= (1 + gamma L)^n, attained by -L I."""
    spec = _spec(tmp_path, "linear_operator", "1/2", ", L: 1")
    res = sosalgo.pep(spec, None, 3)
    exact = 1.5 ** 6
    assert exact * (1 - 1e-9) <= _proven(res) <= exact * (1 + 1e-6)
    assert res.witness["check"]["verified"]


def test_random_matrices_never_exceed_the_proof(tmp_path):
    """Explicit matrices in numpy (symmetric with spectrum in [1/4, 1], skew and general
    with |M| <= 1): |x_n - x*|^2 / |x_0 - x*|^2 never above tau_proven."""
    rng = np.random.default_rng(3)
    n, gamma = 3, 0.5
    cases = {"symmetric_linear_operator": ", mu: 1/4, L: 1",
             "skew_symmetric_linear_operator": ", L: 1", "linear_operator": ", L: 1"}
    for cls, params in cases.items():
        proven = _proven(sosalgo.pep(_spec(tmp_path, cls, "1/2", params), None, n,
                                     witness=False))
        worst = 0.0
        for _ in range(200):
            d = int(rng.integers(1, 6))
            R, _ = np.linalg.qr(rng.standard_normal((d, d)))
            if cls == "symmetric_linear_operator":
                M = (R * rng.uniform(0.25, 1, d)) @ R.T
            elif cls == "skew_symmetric_linear_operator":
                S = rng.standard_normal((d, d))
                M = S - S.T
                M = M / max(1.0, np.linalg.norm(M, 2))
            else:
                M = rng.standard_normal((d, d))
                M = M / np.linalg.norm(M, 2) * rng.uniform(0.5, 1)
            c = rng.standard_normal(d)  # M(x) = M (x - c): zero at c
            x0 = c + rng.standard_normal(d)
            x = x0.copy()
            for _ in range(n):
                x = x - gamma * M @ (x - c)
            worst = max(worst, ((x - c) @ (x - c)) / ((x0 - c) @ (x0 - c)))
        assert worst <= proven * (1 + 1e-12), cls


def test_bad_parameters_are_refused(tmp_path):
    from click.testing import CliRunner

    from sosalgo.cli import cli

    spec = tmp_path / "bad.yaml"
    spec.write_text(SPEC.format(name="bad", cls="symmetric_linear_operator",
                                params=", mu: 2, L: 1", gamma="1/2", d="0"))
    out = CliRunner().invoke(cli, ["pep", str(spec), "--steps", "2", "--out",
                                   str(tmp_path)])
    assert out.exit_code == 2
    assert "mu" in out.output and "bad.yaml" in out.output
    assert "Traceback" not in out.output


def test_witness_with_norm_above_L_is_refused(tmp_path):
    """The witness of the linear operator class is the explicit matrix q I (|q| <= L); the
    same witness with |q| > L is refused by the exact check."""
    import copy

    from sosalgo.worstcase.check import check_witness

    spec = _spec(tmp_path, "linear_operator", "1/2", ", L: 1")
    doc = sosalgo.pep(spec, None, 2).witness
    assert doc["check"]["verified"] and abs(Fraction(doc["members"]["M"])) <= 1
    for q in ("-1000001/1000000", "3/2"):
        bad = copy.deepcopy(doc)
        bad["members"]["M"] = q
        out = check_witness(bad, spec)
        assert not out["verified"] and "outside" in out["detail"]
