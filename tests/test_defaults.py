"""Which certificate family each command uses by default (docs/families.md): the tightest
that applies for analyses, fronts and noise designs; Theorem 1 for rate designs (its
box-wide lower bound), the paper's table and figures; a spec's own ``certificate:``
and ``--certificate`` always win. Rates are compared with closed forms."""

from __future__ import annotations

import math

import pytest

import sosalgo
from sosalgo.certificates import default_family_name
from sosalgo.inputs import select_families
from sosalgo.report.design import tighter_family_note

from .conftest import SPECS


def _spec(name: str) -> sosalgo.Spec:
    return sosalgo.load_spec(SPECS / f"{name}.yaml")


@pytest.mark.parametrize(("command", "family"), [
    ("analyze", "interpolation"), ("pareto", "interpolation"), ("noise", "interpolation"),
    ("design", "theorem1"), ("grid", "theorem1"), ("table1", "theorem1"), ("lmi", "theorem1"),
    (None, "theorem1"),
])
def test_seed_spec_defaults_per_command(command, family):
    spec = _spec("nesterov")
    assert default_family_name(spec, command) == family
    assert select_families(spec, None, command=command, single=True)[0].name == family


def test_composite_spec_defaults_to_interpolation_everywhere():
    spec = _spec("proximal-gradient")
    for command in ("analyze", "design", "grid", "table1", None):
        assert default_family_name(spec, command) == "interpolation"


def test_the_spec_and_the_command_line_win(tmp_path):
    path = tmp_path / "t1.yaml"
    path.write_text((SPECS / "gradient.yaml").read_text() + "certificate: theorem1\n")
    spec = sosalgo.load_spec(path)
    assert spec.certificate_given and default_family_name(spec, "analyze") == "theorem1"
    assert select_families(_spec("nesterov"), "theorem1", command="analyze")[0].name == \
        "theorem1"
    # --lag alone goes to the default family (it has the option)
    (fam,) = select_families(_spec("nesterov"), None, {"lag": 0}, command="analyze")
    assert fam.name == "interpolation" and fam.lag == 0


def test_api_analyze_defaults_to_the_tightest_family():
    """Gradient descent h = 1/L: max(|1 - hm|, |1 - hL|) = 1 - 1/kappa; Nesterov at kappa
    10: AutoLyap's value of the same family, 0.7518212, within 1e-6; Theorem 1 one
    argument away, slower (its certificates are a special case)."""
    gd = sosalgo.analyze(SPECS / "gradient.yaml", 10)
    assert gd.family == "interpolation" and gd.rho == pytest.approx(0.9, abs=1e-5)
    nest = sosalgo.analyze(SPECS / "nesterov.yaml", 10)
    assert nest.family == "interpolation" and nest.rho == pytest.approx(0.7518212, abs=1e-6)
    t1 = sosalgo.analyze(SPECS / "nesterov.yaml", 10, certificate="theorem1")
    assert t1.family == "theorem1" and t1.rho > nest.rho + 0.05


def test_triple_momentum_default_reaches_one_minus_one_over_sqrt_kappa():
    res = sosalgo.analyze(SPECS / "triple-momentum.yaml", 10)
    assert res.rho == pytest.approx(1 - 1 / math.sqrt(10), abs=1e-5)


def test_a_document_without_family_is_read_as_theorem1():
    """A row written before rows named their family (no ``family``, P and lambda beside
    rho) is Theorem 1's: verified as Theorem 1, never reinterpreted."""
    spec = _spec("gradient-optimal")
    row = sosalgo.analyze(spec, 10, certificate="theorem1").to_dict()
    row.pop("family")
    check = sosalgo.verify(spec, row, simulate=False)
    assert check["verified"] == "exact" and "family" not in check
    assert check["rho_proven_float"] == pytest.approx(9 / 11, abs=1e-5)


def test_design_note_names_what_the_tighter_family_gives_up():
    note = tighter_family_note(_spec("gradient"), "theorem1", None)
    assert note is not None and "--certificate interpolation" in note
    assert "no box-wide lower bound" in note and "floor" in note
    assert tighter_family_note(_spec("gradient"), "theorem1", "theorem1") is None
    assert tighter_family_note(_spec("proximal-gradient"), "interpolation", None) is None
