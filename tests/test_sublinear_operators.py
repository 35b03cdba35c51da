"""O(1/k) residual constants of operator methods (m: 0, one operator class): the sublinear
family bounds |u_k|^2 <= C |x_0 - x*|^2 / k, u_k the answer of the call at step k
(x_k - T x_k for Krasnosel'skii-Mann; (x_k - x_{k+1}) / alpha for the proximal point),
against closed forms (tight worst cases below it, the elementary Lyapunov argument's
constant above it), against ``sosalgo pep`` at N = 1..5, and proven exactly."""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli
from sosalgo.spec import spec_from_text
from sosalgo.spec.overrides import apply_overrides

SPECS = Path(__file__).resolve().parent.parent / "specs"
HORIZON = range(1, 400)  # the k over which the tight worst cases bound C from below


def _spec(name: str, **values: str):
    path = SPECS / f"{name}.yaml"
    return spec_from_text(apply_overrides(path.read_text(), values, str(path)), str(path))


def _km_worst(n: int, gamma: float) -> float:
    """Lieder (2018), Thm. 4.9 (tight, as PEPit's example states it): the worst
    |x_n - T x_n|^2 / |x_0 - x*|^2 (four times the bound on 1/4 |x_n - T x_n|^2)."""
    if gamma <= 0.5 * (1 + math.sqrt(n / (n + 1))):
        return 4 * (n / (n + 1)) ** n / ((n + 1) * 4 * gamma * (1 - gamma))
    return 4 * (2 * gamma - 1) ** (2 * n)


def _ppm_worst(k: int, alpha: float) -> float:
    """Gu, Yang (2020), tight: |x_k - x_{k+1}|^2 <= (1 - 1/N)^(N-1)/N |x_0 - x*|^2 with
    N = k + 1 steps; u_k = (x_k - x_{k+1}) / alpha."""
    N = k + 1
    return (1 - 1 / N) ** (N - 1) / N / alpha ** 2


def _constant(spec):
    from sosalgo.analysis import analyze_sublinear
    from sosalgo.certificates.exact_sublinear import verify_exact_sublinear

    res = analyze_sublinear(spec)
    assert res.certified and res.measure == "residual"
    proof = verify_exact_sublinear(spec, json.loads(json.dumps(res.to_dict())))
    assert proof.ok, proof.reason
    assert proof.to_dict()["measure"] == "residual"
    return res.constant, float(Fraction(proof.constant_proven))


@pytest.mark.parametrize("gamma", ["1/2", "3/4", "9/10"])
def test_krasnoselskii_mann_constant_between_closed_forms(gamma):
    """C >= max_k k * (Lieder's tight worst case at k) (else a worst case breaks the
    bound), C <= 1/(gamma (1 - gamma)) (|x_{k+1} - x*|^2 <= |x_k - x*|^2 - gamma (1 -
    gamma) |r_k|^2 and |r_k| nonincreasing give (k + 1) gamma (1 - gamma) |r_k|^2 <=
    |x_0 - x*|^2, a potential of the family); the proven constant as well."""
    g = float(Fraction(gamma))
    c, proven = _constant(_spec("krasnoselskii-mann", gamma=gamma))
    floor = max(k * _km_worst(k, g) for k in HORIZON)
    for value in (c, proven):
        assert value >= floor * (1 - 1e-12)
        assert value <= 1 / (g * (1 - g)) * (1 + 1e-5)
    assert proven >= c * (1 - 1e-9)


@pytest.mark.parametrize("alpha", ["1/2", "1", "2"])
def test_proximal_point_constant_between_closed_forms(alpha):
    """C >= max_k k * (Gu and Yang's tight worst case of |u_k|^2) and C <= 1/alpha^2
    (firm nonexpansiveness of the resolvent: |x_{k+1} - x*|^2 <= |x_k - x*|^2 -
    |x_k - x_{k+1}|^2, the steps nonincreasing: (k + 1) |x_k - x_{k+1}|^2 <= |x_0 - x*|^2)."""
    a = float(Fraction(alpha))
    c, proven = _constant(_spec("operator-proximal-point", alpha=alpha))
    floor = max(k * _ppm_worst(k, a) for k in HORIZON)
    assert floor == pytest.approx(math.exp(-1) / a ** 2, rel=1e-2)  # (k/(k+1))^(k+1) -> 1/e
    for value in (c, proven):
        assert value >= floor * (1 - 1e-12)
        assert value <= 1 / a ** 2 * (1 + 1e-5)


@pytest.mark.parametrize("name", ["krasnoselskii-mann", "operator-proximal-point"])
def test_constant_never_below_pep(name):
    """Soundness against ``sosalgo pep`` at N = 1..5: C / N is at least its proven worst
    case of |u_N|^2 (Krasnosel'skii-Mann: pep bounds 1/4 |u_N|^2 after N steps; the
    proximal point: |x_N - x_{N+1}|^2 = alpha^2 |u_N|^2 after N + 1 steps, alpha = 2)."""
    spec = _spec(name)
    c, proven = _constant(spec)
    scale, extra = (4.0, 0) if name == "krasnoselskii-mann" else (1 / 4, 1)
    for N in range(1, 6):
        res = sosalgo.pep(spec, None, N + extra)
        tau = float(Fraction(res.certificate["tau_proven"])) * scale
        assert res.witness["check"]["verified"]
        assert min(c, proven) / N >= tau


def test_exact_check_refuses_a_constant_below_a_worst_case():
    """The certificate with a constant below the tight worst case's floor is not proven."""
    from sosalgo.analysis import analyze_sublinear
    from sosalgo.certificates.exact_sublinear import verify_exact_sublinear

    spec = _spec("operator-proximal-point")
    res = analyze_sublinear(spec)
    cert = json.loads(json.dumps(res.to_dict()))["certificate"]
    false = 0.9 * max(k * _ppm_worst(k, 2.0) for k in HORIZON)
    proof = verify_exact_sublinear(spec, cert, constant=false)
    assert not proof.ok


def test_analyze_cli_verifies_the_residual_constant(tmp_path):
    """``analyze --verify --json`` on the shipped Krasnosel'skii-Mann spec: exit 0, the
    row's measure is the residual, proven exactly, and the legend says what c bounds."""
    args = ["analyze", str(SPECS / "krasnoselskii-mann.yaml"), "--verify", "--json",
            "--out", str(tmp_path), "--no-plot", "--quiet", "--workers", "1"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    row = json.loads(r.stdout)["rows"][0]
    assert row["measure"] == "residual" and row["verified"] == "exact"
    assert row["constant"] <= 16 / 3 * (1 + 1e-5)
    doc = tmp_path / "km.json"
    doc.write_text(r.stdout)
    v = CliRunner().invoke(cli, ["verify", str(doc)])
    assert v.exit_code == 0 and "0 contradicted" in v.output, v.output
    false = json.loads(r.stdout)
    false["rows"][0]["constant"] = 1.0  # below Lieder's floor 4 max_k k tau_k (about 1.96)
    doc.write_text(json.dumps(false))
    v = CliRunner().invoke(cli, ["verify", str(doc)])
    assert v.exit_code == 3, v.output
    r = CliRunner().invoke(cli, ["analyze", str(SPECS / "krasnoselskii-mann.yaml"),
                                 "--out", str(tmp_path / "t"), "--no-plot"])
    assert r.exit_code == 0, r.output
    assert "c bounds: |u1_k|^2 <= c |x_0 - x*|^2 / k" in r.output


@pytest.mark.parametrize("name, edit, words", [
    ("krasnoselskii-mann", ("{class: nonexpansive}", "{class: linear_operator}"),
     "T (linear_operator) is an operator class not given by pairwise conditions"),
    ("forward-backward", None, "the squared residual of one operator only"),
])
def test_analyze_refuses_other_operator_specs(tmp_path, name, edit, words):
    """m: 0 with an operator class the residual constant does not take (a Gram-level
    linear operator; several functions): one line naming the file and field, exit 2,
    nothing written."""
    path = SPECS / f"{name}.yaml"
    if edit is not None:
        text = path.read_text()
        assert edit[0] in text
        path = tmp_path / f"{name}.yaml"
        path.write_text(text.replace(*edit))
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(out)])
    assert r.exit_code == 2
    assert "Traceback" not in r.output and len(r.output.strip().splitlines()) == 1
    assert f"{path}: functions: " in r.output and words in r.output
    assert not out.exists()


@pytest.mark.parametrize("name, L, floor, top", [
    ("krasnoselskii-mann", "2", max(k * _km_worst(k, 0.75) for k in HORIZON), 16 / 3),
    ("operator-proximal-point", "4", max(k * _ppm_worst(k, 2.0) for k in HORIZON), 1 / 4),
])
def test_constant_does_not_depend_on_units(name, L, floor, top):
    """L is units only for these classes (the methods do not read it): the constant,
    float and proven, stays between the same closed forms at another L (the solver's
    scaled units: within 1e-2 of the elementary constant)."""
    path = SPECS / f"{name}.yaml"
    text = path.read_text()
    assert "\nL: 1 " in text
    c, proven = _constant(spec_from_text(text.replace("\nL: 1 ", f"\nL: {L} "), str(path)))
    for value in (c, proven):
        assert floor * (1 - 1e-12) <= value <= top * (1 + 1e-2)


@pytest.mark.parametrize("name, peps, comparable", [
    ("krasnoselskii-mann", "(n/(n + 1))**n/((n + 1) 4 gamma (1 - gamma)) at n = 3",
     {"c = 1/(gamma (1 - gamma)) at gamma = 3/4": 1 / (0.75 * 0.25)}),
    ("operator-proximal-point", "(1 - 1/N)**(N - 1)/N at N = 10",
     {"c = 1/alpha^2 at alpha = 2": 1 / 4, "best c = 1/(e alpha^2) at alpha = 2":
      1 / (math.e * 4)}),
])
def test_analyze_shows_the_constants_closed_forms_not_peps_value(tmp_path, name, peps,
                                                                 comparable):
    """Beside the certified constant c the table shows the closed forms of c (computed
    here), not the spec's pep reference (the worst measure after N steps, another
    quantity): its CSV column is kept and empty, its column is not printed."""
    import csv

    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["analyze", str(SPECS / f"{name}.yaml"), "--out", str(out),
                                 "--no-plot", "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert peps not in r.output
    row = next(csv.DictReader((out / f"{name}-analysis.csv").open()))
    pep_col = [c for c in row if c.startswith(peps)]
    assert len(pep_col) == 1 and row[pep_col[0]] == ""
    for words, value in comparable.items():
        col = [c for c in row if c.startswith(words)]
        assert len(col) == 1 and f"reference: {col[0]}" in r.output
        assert float(row[col[0]]) == pytest.approx(value, rel=1e-12)
        if words.startswith("best"):  # no valid c is below the best c
            assert float(row["constant"]) >= value
    if name == "operator-proximal-point":  # the best c: sup_k k * Gu-Yang's worst case
        best = max(k * _ppm_worst(k, 2.0) for k in HORIZON)
        assert best <= 1 / (math.e * 4) <= best * (1 + 1e-2)


def test_pep_references_must_name_references():
    """``pep.references`` names references of the spec, else one line naming the field."""
    from sosalgo.spec.types import SpecError

    path = SPECS / "krasnoselskii-mann.yaml"
    text = path.read_text().replace('    - "(n/(n + 1))**n', '    - "(n/(n + 2))**n')
    with pytest.raises(SpecError) as exc:
        spec_from_text(text, str(path))
    assert exc.value.field == "pep.references"


def test_design_reports_a_point_whose_certificate_is_proven():
    """Near the box's edge (alpha about 10) the degree-2 certificate of the proximal point
    may not be provable; the design's choice of its reported point keeps the best point
    whose certificate the exact proof accepts (else the degree-1 potential's at the same
    point), and its constant lies between Gu and Yang's best c and the elementary 1/alpha^2."""
    import time

    from sosalgo.analysis import analyze_sublinear
    from sosalgo.certificates.exact_sublinear import verify_exact_sublinear
    from sosalgo.sublinear_design import _proven_best

    spec = _spec("operator-proximal-point")
    points = [(9.998064041137695,), (9.5,)]
    done = {p: analyze_sublinear(spec, {"alpha": p[0]}) for p in points}
    point, res = _proven_best(spec, ["alpha"], done, time.monotonic() + 600)
    alpha = point[0]
    proof = verify_exact_sublinear(spec, json.loads(json.dumps(res.to_dict())),
                                   {"alpha": alpha})
    assert proof.ok, proof.reason
    assert 1 / (math.e * alpha ** 2) <= res.constant <= (1 + 1e-5) / alpha ** 2


@pytest.mark.deep
def test_design_verify_proves_what_design_claims(tmp_path):
    """``design --verify`` on the shipped proximal point spec (the best step is the box's
    edge): exit 0, the reported constant proven exactly, between the best c 1/(e alpha^2)
    and 1/alpha^2 at the reported alpha, which is near the edge alpha = 10."""
    args = ["design", str(SPECS / "operator-proximal-point.yaml"), "--verify", "--json",
            "--out", str(tmp_path), "--quiet", "--time-limit", "60"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    row = json.loads(r.stdout)  # a design document: one row
    alpha = row["theta"]["alpha"]
    assert row["verified"] == "exact" and alpha > 9
    assert 1 / (math.e * alpha ** 2) <= row["constant"] <= (1 + 1e-5) / alpha ** 2
