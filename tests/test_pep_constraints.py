"""Constraints on the instance (``pep: {constraints: [...]}``): Polyak's step conditions
(``specs/polyak-steps.yaml``, ``specs/polyak-steps-function-value.yaml``) against the
tight closed forms of PEPit's examples and PEPit's values; the proven bound against
instances built here (numpy only) on the constraint's surface; a tampered certificate
and a witness of a constrained spec refused; bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

ROOT = Path(__file__).resolve().parents[1]
DIST = ROOT / "specs" / "polyak-steps.yaml"
VALUE = ROOT / "specs" / "polyak-steps-function-value.yaml"
SETS = [(1, 0.1, 1.8181818181818181), (1, 0.2, 1.5), (2, 0.1, 0.8)]  # PEPit's (L, mu, gamma)
# PEPit 0.5.1 (Clarabel), adaptive_methods/polyak_steps_in_{distance_to_optimum,
# function_value} at SETS
PEPIT = {DIST: [0.6694214881468535, 0.4375000246990655, 0.811764731],
         VALUE: [0.669421442, 0.400000001, 0.667199994]}


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def theory(spec, L, mu, g):
    """PEPit's theoretical (tight) values."""
    if spec == DIST:
        return (g * L - 1) * (1 - g * mu) / (g * (L + mu) - 1)
    return (g * L - 1) * (L * g * (3 - g * (L + mu)) - 1)


def pep_doc(out, spec, L, mu, g):
    """The example at (L, mu, gamma): f scaled by 1/(10 mu) (the spec's mu = 1/10)."""
    res = run(["pep", spec, "--kappa", L / mu, "--steps", 1, "--set",
               f"gamma={g * 10 * mu!r}", "--out", out, "--json", "--no-plot"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


@pytest.fixture(scope="module")
def docs(tmp_path_factory):
    return {(spec, k): pep_doc(tmp_path_factory.mktemp("polyak"), spec, *SETS[k])
            for spec in (DIST, VALUE) for k in range(3)}


@pytest.mark.parametrize("spec", [DIST, VALUE], ids=["distance", "value"])
@pytest.mark.parametrize("k", range(3))
def test_tight_values_proven(docs, spec, k):
    doc = docs[(spec, k)]
    proof = doc["certificate"]["proof"]
    assert proof["proven"], proof
    proven, closed = proof["tau_proven_float"], theory(spec, *SETS[k])
    assert closed * (1 - 1e-9) <= proven <= closed * (1 + 1e-6)
    assert proven >= PEPIT[spec][k] * (1 - 1e-7)
    assert doc["witness"] is None and "constraints" in doc["note"]


def test_the_constraint_changes_the_answer(tmp_path, docs):
    """Without the constraint, one step of gamma = 0.8 on F(0.1, 2) has worst case
    max(|1 - gamma mu|, |1 - gamma L|)^2 = 0.8464, above the constrained 0.8118."""
    text = DIST.read_text()
    free = tmp_path / "free.yaml"
    free.write_text(text.replace("  constraints:\n    - gamma*grad(x_0) == 2*f(x_0)", ""))
    doc = pep_doc(tmp_path, free, *SETS[2])
    assert abs(doc["certificate"]["proof"]["tau_proven_float"] / 0.8464 - 1) <= 1e-6
    assert docs[(DIST, 2)]["certificate"]["proof"]["tau_proven_float"] < 0.82


@pytest.mark.parametrize("k", range(3))
def test_instances_on_the_constraint_stay_below_the_proof(docs, k):
    """Quadratics 1/2 x'Hx (eigenvalues in [mu, L], dimension 2 and 3) started on the
    surface gamma |H x_0|^2 = x_0' H x_0 (Polyak's step), resp. |Hx_0|^2 = L (2 - L
    gamma) x_0' H x_0: the ratios never exceed the proven bounds, and come near them."""
    L, mu, g = SETS[k]
    rng = np.random.default_rng(11 + k)
    best = {DIST: 0.0, VALUE: 0.0}
    for trial in range(400):
        lam = np.sort(rng.uniform(mu, L, 2 + trial % 2))
        lam[0], lam[-1] = (mu, L) if trial % 3 == 0 else (lam[0], lam[-1])
        for spec, w in ((DIST, 1 / g), (VALUE, L * (2 - L * g))):
            # x_0 = sum c_i e_i with sum c_i^2 lam_i (lam_i - w) = 0: two coordinates
            i, j = 0, len(lam) - 1
            a, b = lam[i] * (lam[i] - w), lam[j] * (lam[j] - w)
            if a * b >= 0:
                continue
            x0 = np.zeros(len(lam))
            x0[i], x0[j] = np.sqrt(abs(b)), np.sqrt(abs(a))  # a |b| + b |a| = 0
            assert abs(x0 @ (lam * (lam - w) * x0)) <= 1e-9 * (x0 @ x0)
            x1 = x0 - g * lam * x0
            ratio = (x1 @ x1 / (x0 @ x0) if spec == DIST
                     else (x1 @ (lam * x1)) / (x0 @ (lam * x0)))
            best[spec] = max(best[spec], ratio)
    for spec in (DIST, VALUE):
        proven = docs[(spec, k)]["certificate"]["proof"]["tau_proven_float"]
        assert best[spec] <= proven * (1 + 1e-12)
        assert best[spec] >= 0.999 * theory(spec, *SETS[k])


def _proven_claim(path, out):
    """The status of the verify ledger's tau_proven claim (the float tau has no witness
    from below: 'unsupported' either way)."""
    res = run(["verify", path, "--out", out, "--json"])
    claims = json.loads(res.stdout)["results"][0]["claims"]
    return next(c["status"] for c in claims if c["field"].endswith("certificate.tau_proven"))


def test_a_certificate_without_its_constraint_multipliers_is_refused(tmp_path):
    out = tmp_path / "o"
    pep_doc(out, DIST, *SETS[2])
    path = next(out.glob("polyak-steps-pep-*N1.json"))
    assert _proven_claim(path, tmp_path / "v") == "backed"
    doc = json.loads(path.read_text())
    exact = doc["certificate"]["proof"]["multipliers_exact"]
    assert {"constraint[0]+", "constraint[0]-"} <= set(exact)
    for key in ("constraint[0]+", "constraint[0]-"):
        exact[key] = "0"
    path.write_text(json.dumps(doc))
    assert _proven_claim(path, tmp_path / "v2") != "backed"


def test_a_witness_of_a_constrained_spec_is_refused(tmp_path):
    """A run of the plain gradient step (no constraint) checked against the constrained
    spec: refused, whatever it holds."""
    from sosalgo.spec import load_spec
    from sosalgo.worstcase.check import check_witness

    free = tmp_path / "free.yaml"
    free.write_text(DIST.read_text().replace(
        "  constraints:\n    - gamma*grad(x_0) == 2*f(x_0)", ""))
    res = run(["pep", free, "--kappa", 10, "--steps", 1, "--out", tmp_path, "--json",
               "--no-plot"])
    wit = json.loads(res.stdout)["witness"]
    assert check_witness(wit, load_spec(free))["verified"]
    out = check_witness(wit, load_spec(DIST))
    assert not out["verified"] and "constraints" in out["detail"]


@pytest.mark.parametrize("new,field", [
    ("    - gamma*grad(x_0) = 2*f(x_0)", "pep.constraints[0]"),
    ("    - gamma*grad(x_0) == 2*f(x_0) <= f(x_0)", "pep.constraints[0]"),
    ("    - gamma*grad(x_0) == 2", "pep.constraints[0]"),
    ("    - zeta*grad(x_0) == 2*f(x_0)", "pep.constraints[0]"),
    ("    - grad(x_0)*f(x_0) == 2*f(x_0)", "pep.constraints[0]"),
    ("    - mingrad == f(x_0)", "pep.constraints[0]"),
    ("    - grad(x_0) + dist(x_0) + dist(x_1) + grad(x_1) + dist(x_1, x_0) == f(x_0)",
     "pep.constraints[0]"),
    ("    - 3", "pep.constraints"),
])
def test_bad_constraints_are_one_line_exit_2(tmp_path, new, field):
    text = DIST.read_text()
    old = "    - gamma*grad(x_0) == 2*f(x_0)"
    assert old in text
    path = tmp_path / "bad.yaml"
    path.write_text(text.replace(old, new))
    res = run(["pep", path, "--kappa", 10, "--steps", 1, "--out", tmp_path / "o"])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and field in lines[0] and "bad.yaml" in lines[0], res.output
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


@pytest.mark.parametrize("rel,expected", [
    # the quadratic mu/2 x^2 has gamma |g|^2 = gamma mu^2 x^2 <= mu x^2 = 2 f: it meets
    # "<=" and attains the step's unconstrained worst case (1 - gamma mu)^2
    ("<=", (1 - 0.8 * 0.1) ** 2),
    # ">=" holds at the Polyak step itself: the equality's tight value bounds it below,
    # the unconstrained one above; with "<=" also listed it is the equality
    (">=", None),
])
def test_inequalities_take_their_side(tmp_path, rel, expected):
    old = "    - gamma*grad(x_0) == 2*f(x_0)"
    text = DIST.read_text()
    one = tmp_path / "one.yaml"
    one.write_text(text.replace(old, f"    - gamma*grad(x_0) {rel} 2*f(x_0)"))
    proven = pep_doc(tmp_path / "a", one, *SETS[2])["certificate"]["proof"]["tau_proven_float"]
    eq = theory(DIST, *SETS[2])
    if expected is not None:
        assert abs(proven / expected - 1) <= 1e-6
        return
    assert eq * (1 - 1e-9) <= proven <= 0.8464
    both = tmp_path / "both.yaml"
    both.write_text(text.replace(old, "    - gamma*grad(x_0) <= 2*f(x_0)\n"
                                      "    - gamma*grad(x_0) >= 2*f(x_0)"))
    proven = pep_doc(tmp_path / "b", both, *SETS[2])["certificate"]["proof"]["tau_proven_float"]
    assert eq * (1 - 1e-9) <= proven <= eq * (1 + 1e-6)
