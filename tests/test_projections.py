"""Indicators alone (alternate, averaged and Dykstra's projections), Douglas-Rachford on a
smooth convex f (m: 0) and the initial term sdist(x_0).

Judged against PEPit 0.5.1's values (its examples run with Clarabel, the values recorded
here with their arguments), closed forms, and explicit sets in numpy that share no code
with sosalgo: the projections' measure never exceeds the proven bound.
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

from .conftest import pep_json

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"
SUITE = ROOT / "bench" / "conformance" / "specs"


def _row(doc: dict) -> dict:
    return doc["rows"][-1] if "rows" in doc else doc


def _proven(doc: dict) -> float:
    cert = _row(doc)["certificate"]
    assert cert["check_kind"].startswith("exact"), cert.get("proof")
    return float(Fraction(cert["tau_proven"]))


# (spec, steps, extra arguments, PEPit's value at the same question)
PEPIT = [
    (SPECS / "alternate-projections.yaml", 3, (), 0.06697959566815895),  # n = 3
    (SPECS / "averaged-projections.yaml", 3, (), 0.1963479604951259),  # n = 3
    (SUITE / "dykstra.yaml", 2, (), 0.08771254510788705),  # n = 3 (--steps n - 1)
    # L = 1, alpha = 1, theta = 1, n = 3 (PESTO: 0.0838); n = 1: PESTO's 1/4 (the
    # measure f(x_N-1) at N = 1 is g's prox point of step 0, not the start)
    (SPECS / "douglas-rachford-convex.yaml", 3, (), 0.08383964120882736),
    (SPECS / "douglas-rachford-convex.yaml", 1, (), 0.25),
    # mu = 0.1, L = 1, alpha = 0.9, n = 2: |w_0 - w*|^2 from rest
    (SUITE / "accelerated-douglas-rachford.yaml", 2, ("--kappa", "10"), 0.19291481839341718),
]


@pytest.mark.parametrize("spec,steps,extra,pepit", PEPIT,
                         ids=[f"{p[0].stem}-N{p[1]}" for p in PEPIT])
def test_agrees_with_pepit_and_is_proven(spec, steps, extra, pepit, tmp_path):
    doc = pep_json(spec, tmp_path, steps, *extra, "--no-plot", "--no-witness")
    assert _row(doc)["tau"] == pytest.approx(pepit, rel=1e-6)
    proven = _proven(doc)
    assert proven >= pepit * (1 - 1e-7)
    assert proven <= pepit * (1 + 1e-5)


def test_sdist_at_the_start_is_the_distance_for_one_state(tmp_path):
    # gradient descent h = 1/L from rest: xi = x, so sdist(x_0) = |x_0 - x*|^2 and the
    # worst case of |x_N - x*|^2 is (1 - 1/kappa)^(2N) = 0.81^N at kappa = 10
    doc = pep_json(SPECS / "gradient.yaml", tmp_path, 3, "--kappa", "10", "--measure", "dist",
                   "--initial", "sdist(x_0)", "--no-plot", "--no-witness")
    assert _row(doc)["tau"] == pytest.approx(0.81 ** 3, rel=1e-6)
    assert _proven(doc) >= 0.81 ** 3 * (1 - 1e-12)


def _projection_ball(c: np.ndarray, r: float):
    return lambda z: c + (z - c) * min(1.0, r / max(np.linalg.norm(z - c), 1e-300))


def _projection_halfspace(a: np.ndarray, b: float):
    return lambda z: z - a * max(0.0, (a @ z - b) / (a @ a))


def _random_set(rng: np.random.Generator, xs: np.ndarray):
    """The projection onto a random ball or half-space containing xs."""
    d = len(xs)
    if rng.random() < 0.5:
        c = xs + rng.normal(size=d)
        return _projection_ball(c, np.linalg.norm(c - xs) * (1 + rng.random() * 0.2))
    a = rng.normal(size=d)
    return _projection_halfspace(a, a @ xs + rng.random() * 0.1)


def _alternate(p1, p2, x, n):
    for _ in range(n):
        x = p2(p1(x))
    return np.sum((x - p1(x)) ** 2)


def _averaged(p1, p2, x, n):
    for _ in range(n):
        x = (p1(x) + p2(x)) / 2
    return np.sum((p1(x) - p2(x)) ** 2)


def _dykstra(p1, p2, x, n):  # the spec's N steps: PEPit's n = N + 1
    p = q = np.zeros_like(x)
    for _ in range(n + 1):
        y = p1(x + p)
        p = x + p - y
        x_new = p2(y + q)
        q = y + q - x_new
        x = x_new
    return np.sum((x - p1(x)) ** 2)


@pytest.mark.parametrize("spec,run", [(SPECS / "alternate-projections.yaml", _alternate),
                                      (SPECS / "averaged-projections.yaml", _averaged),
                                      (SUITE / "dykstra.yaml", _dykstra)],
                         ids=["alternate", "averaged", "dykstra"])
def test_explicit_sets_never_exceed_the_proven_bound(spec, run, tmp_path):
    n = 3
    bound = _proven(pep_json(spec, tmp_path, n, "--no-plot", "--no-witness"))
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(400):
        d = int(rng.integers(1, 4))
        xs = rng.normal(size=d)
        p1, p2 = _random_set(rng, xs), _random_set(rng, xs)
        x0 = xs + rng.normal(size=d) * rng.uniform(0.5, 3)
        worst = max(worst, run(p1, p2, x0, n) / np.sum((x0 - xs) ** 2))
    assert 0 < worst <= bound * (1 + 1e-9)


def test_projection_witness_verifies_and_a_tampered_one_is_refused(tmp_path):
    doc = pep_json(SPECS / "alternate-projections.yaml", tmp_path, 3, "--no-plot")
    wfile = tmp_path / "alternate-projections-pep-N3-witness.json"
    assert _row(doc)["witness"]["check"]["verified"], _row(doc)["witness"]["search"]
    ok = CliRunner().invoke(cli, ["verify", str(wfile)])
    assert ok.exit_code == 0, ok.output
    w = json.loads(wfile.read_text())
    pt = w["functions"]["f1"]["points"][0]
    pt["g"] = [str(-Fraction(v) - 1) for v in pt["g"]]  # a normal vector pointing inwards
    bad = tmp_path / "tampered.json"
    bad.write_text(json.dumps(w))
    assert CliRunner().invoke(cli, ["verify", str(bad)]).exit_code == 3


@pytest.mark.parametrize("argv,field", [
    (["analyze", str(SPECS / "alternate-projections.yaml")], "indicators alone"),
    (["pep", str(SPECS / "gradient.yaml"), "--kappa", "10", "--steps", "2",
      "--measure", "sdist(x_0)"], "sdist(x_0): an initial term"),
])
def test_bad_input_is_one_line_exit_2(argv, field, tmp_path):
    r = CliRunner().invoke(cli, [*argv, "--out", str(tmp_path)])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and field in lines[0], r.output
