"""Smooth strongly convex quadratics (a class with a Gram-level condition): closed forms,
explicit quadratics run in numpy never above the proven bound, tampered proofs and
witnesses refused."""

from __future__ import annotations

import copy
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import sosalgo
from sosalgo.spec import load_spec
from sosalgo.worstcase.exact import reprove_certificate

SPECS = Path(__file__).resolve().parents[1] / "specs"
GD, PGM = SPECS / "gradient-quadratics.yaml", SPECS / "proximal-gradient-quadratics.yaml"


def _with_gamma(path: Path, gamma: str, tmp_path: Path):
    """The spec with its step fixed (as ``--set gamma=...`` does)."""
    from sosalgo.spec.overrides import apply_overrides

    out = tmp_path / path.name
    out.write_text(apply_overrides(path.read_text(), {"gamma": gamma}, str(path)))
    return load_spec(out)


def _gd_closed_form(kappa: float, h: float, n: int) -> float:
    """max over q in [1, kappa] of q/2 (1 - h q / kappa)^(2n) (m = 1, L = kappa, step h/L):
    the worst case of f(x_n) - f* over |x_0 - x*| = 1, attained on one eigenvector."""
    q = np.concatenate([np.linspace(1.0, kappa, 200001), [kappa / (h * (2 * n + 1))]])
    q = q[(q >= 1.0) & (q <= kappa)]
    return float(np.max(q / 2 * (1 - h * q / kappa) ** (2 * n)))


@pytest.mark.parametrize("kappa,h,n", [(10, 1.0, 4), (10, 1.5, 3), (4, 0.5, 2), (20, 1.9, 1)])
def test_gradient_on_quadratics_matches_closed_form(kappa, h, n, tmp_path):
    res = sosalgo.pep(_with_gamma(GD, f"{h}/L", tmp_path), kappa, n)
    exact = _gd_closed_form(kappa, h, n)
    proven = float(Fraction(res.certificate["tau_proven"]))
    assert exact * (1 - 1e-9) <= proven <= exact * (1 + 1e-6)
    check = res.witness["check"]
    assert check["verified"] and check["tau_lower_float"] <= proven
    assert check["tau_lower_float"] >= exact * (1 - 1e-3)


def test_proximal_gradient_on_quadratics_matches_closed_form(tmp_path):
    res = sosalgo.pep(_with_gamma(PGM, "1.5/L", tmp_path), 10, 3)
    exact = max((1 - 1.5 / 10) ** 2, (1 - 1.5) ** 2) ** 3
    proven = float(Fraction(res.certificate["tau_proven"]))
    assert exact * (1 - 1e-9) <= proven <= exact * (1 + 1e-6)
    assert res.witness["check"]["verified"]


def _random_quadratic(rng: np.random.Generator, d: int, mu: float, L: float
                      ) -> np.ndarray:
    q = rng.uniform(mu, L, d)
    q[0], q[-1] = mu, L
    R, _ = np.linalg.qr(rng.standard_normal((d, d)))
    return (R * q) @ R.T


def test_gradient_runs_on_random_quadratics_never_exceed_the_proof():
    """Explicit quadratics f = (x - c)'Q(x - c)/2 + b'x with spectrum in [1, kappa], run in
    numpy (no sosalgo code): (f(x_n) - f*)/|x_0 - x*|^2 never above tau_proven."""
    kappa, n = 10.0, 3
    res = sosalgo.pep(GD, kappa, n)
    proven = float(Fraction(res.certificate["tau_proven"]))
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(300):
        d = int(rng.integers(1, 6))
        Q = _random_quadratic(rng, d, 1.0, kappa)
        b = rng.standard_normal(d)
        xs = np.linalg.solve(Q, -b)  # f = x'Qx/2 + b'x
        f = lambda x, Q=Q, b=b: 0.5 * x @ Q @ x + b @ x  # noqa: E731
        x0 = xs + rng.standard_normal(d)
        x = x0.copy()
        for _ in range(n):
            x = x - (1 / kappa) * (Q @ x + b)
        worst = max(worst, (f(x) - f(xs)) / ((x0 - xs) @ (x0 - xs)))
    assert worst <= proven * (1 + 1e-12)
    assert worst >= 0.9 * proven  # the random quadratics come close to the worst case


def test_proximal_gradient_runs_never_exceed_the_proof():
    """f quadratic in F_Q(1, kappa), h = lam |x|_1 (convex, soft thresholding), run in
    numpy: |x_n - x*|^2 / |x_0 - x*|^2 never above tau_proven."""
    kappa, n, gamma = 10.0, 2, 1.0 / 10.0
    res = sosalgo.pep(PGM, kappa, n)
    proven = float(Fraction(res.certificate["tau_proven"]))
    rng = np.random.default_rng(11)

    def step(x, Q, b, lam):
        y = x - gamma * (Q @ x + b)
        return np.sign(y) * np.maximum(np.abs(y) - gamma * lam, 0.0)

    worst = 0.0
    for _ in range(100):
        d = int(rng.integers(1, 5))
        Q, b, lam = _random_quadratic(rng, d, 1.0, kappa), rng.standard_normal(d), \
            float(rng.uniform(0, 1))
        xs = np.zeros(d)
        for _ in range(3000):  # the fixed point (a contraction of factor 0.9)
            xs = step(xs, Q, b, lam)
        x0 = xs + rng.standard_normal(d)
        x = x0.copy()
        for _ in range(n):
            x = step(x, Q, b, lam)
        worst = max(worst, ((x - xs) @ (x - xs)) / ((x0 - xs) @ (x0 - xs)))
    assert worst <= proven * (1 + 1e-9)


def test_tampered_cuts_and_multipliers_are_refused():
    spec = load_spec(GD)
    res = sosalgo.pep(spec, 10, 3, witness=False)
    proof = res.certificate["proof"]
    assert proof["proven"] and proof["cuts"]
    args = (spec, 10.0, 3, res.measure, res.initial)
    assert reprove_certificate(*args, proof)[0]
    # every cut v'Tv >= 0 is valid (T is PSD on the class): another vector in place of
    # one that carries weight leaves S indefinite
    used = [int(lab.rsplit(".", 1)[1]) - 1 for lab in proof["multipliers_exact"]
            if lab.startswith("f:block1.")]
    assert used
    bent = copy.deepcopy(proof)
    j, r, vec = bent["cuts"][used[-1]]
    bent["cuts"][used[-1]] = [j, r, ["1"] + ["0"] * (len(vec) - 1)]
    assert not reprove_certificate(*args, bent)[0]
    none = copy.deepcopy(proof)
    none.pop("cuts")  # the block's multipliers name cuts the PEP does not have
    assert not reprove_certificate(*args, none)[0]
    low = copy.deepcopy(proof)
    low["tau_proven"] = str(Fraction(proof["tau_proven"]) * Fraction(99, 100))
    assert not reprove_certificate(*args, low)[0]


def test_member_witness_outside_the_class_is_refused():
    from sosalgo.worstcase.check import check_witness

    spec = load_spec(GD)
    res = sosalgo.pep(spec, 10, 2)
    doc = res.witness
    assert doc["check"]["verified"] and "members" in doc
    for q in ("11", "1/2", "-1"):  # spectrum [m, L] = [1, 10]
        bad = copy.deepcopy(doc)
        bad["members"]["f"] = q
        out = check_witness(bad, spec)
        assert not out["verified"] and "outside" in out["detail"]
    moved = copy.deepcopy(doc)
    moved["functions"]["f"]["optimal_subgradient"] = ["1"]
    assert not check_witness(moved, spec)["verified"]


def test_analyze_refuses_the_quadratic_class(tmp_path):
    from click.testing import CliRunner

    from sosalgo.cli import cli

    out = CliRunner().invoke(cli, ["analyze", str(GD), "--kappa", "10", "--out",
                                   str(tmp_path)])
    assert out.exit_code == 2
    assert "smooth_strongly_convex_quadratic" in out.output


def test_verify_backs_the_pep_document_and_refuses_a_bent_member(tmp_path):
    import json

    from click.testing import CliRunner

    from sosalgo.cli import cli

    run = CliRunner()
    out = run.invoke(cli, ["pep", str(GD), "--kappa", "10", "--steps", "3", "--out",
                           str(tmp_path), "--no-plot", "--quiet"])
    assert out.exit_code == 0, out.output
    doc, wit = (tmp_path / "gradient-quadratics-pep-k10-N3.json",
                tmp_path / "gradient-quadratics-pep-k10-N3-witness.json")
    for path in (doc, wit):
        res = run.invoke(cli, ["verify", str(path), "--out", str(tmp_path / "v")])
        assert res.exit_code == 0, res.output
    bent = json.loads(wit.read_text())
    bent["members"]["f"] = "21/2"  # curvature 10.5 > L = 10
    wit.write_text(json.dumps(bent))
    res = run.invoke(cli, ["verify", str(wit), "--out", str(tmp_path / "v")])
    assert res.exit_code == 3
