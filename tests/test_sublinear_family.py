"""The sublinear family in the family seam: an ``m: 0`` spec selects it by itself (not a
``--certificate`` choice), its float build and its exact check answer through the
``CertificateFamily`` protocol, checked against the closed form c = L/4 of gradient descent
with h = 1/L (Drori, Teboulle 2014: worst case L/(4k + 2) after k steps, so every valid
constant is at least sup_k k L/(4k + 2) = L/4)."""

from __future__ import annotations

import json

import pytest
import yaml
from click.testing import CliRunner

from sosalgo.analysis import analyze_sublinear
from sosalgo.certificates import FAMILIES, spec_family
from sosalgo.certificates.sublinear import SUBLINEAR, sublinear_data
from sosalgo.cli import cli
from sosalgo.kernel.exact import Verdict
from sosalgo.kernel.solvers import lmi_point
from sosalgo.model import bind_sublinear
from sosalgo.schema import SUBLINEAR_COLUMNS
from sosalgo.spec import load_spec, spec_from_dict

from .conftest import SPECS

GD = yaml.safe_load((SPECS / "gradient-convex.yaml").read_text())
TIGHT = 0.25  # L/4 at L = 1 (module docstring)


@pytest.fixture(scope="module")
def gd_row() -> dict:
    """The analysis row of gradient descent h = 1/L, L = 1, as JSON carries it."""
    return json.loads(json.dumps(analyze_sublinear(spec_from_dict(GD)).to_dict()))


def test_an_m0_spec_selects_the_sublinear_family_and_a_rate_spec_none():
    assert spec_family(spec_from_dict(GD)) is SUBLINEAR
    assert spec_family(load_spec(SPECS / "nesterov.yaml")) is None
    assert SUBLINEAR.applies_to(load_spec(SPECS / "nesterov.yaml")) is not None


def test_it_is_no_certificate_choice(tmp_path):
    assert "sublinear" not in FAMILIES
    res = CliRunner().invoke(cli, ["analyze", str(SPECS / "nesterov.yaml"), "--kappa", "2",
                                   "--certificate", "sublinear", "--out", str(tmp_path)])
    assert res.exit_code == 2
    assert "--certificate sublinear: unknown family" in res.output
    assert not list(tmp_path.iterdir())


def test_theorem1_refuses_an_m0_spec_through_its_applies_to(tmp_path):
    path = tmp_path / "gd-theorem1.yaml"
    path.write_text(yaml.safe_dump({**GD, "certificate": "theorem1"}))
    res = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "certificate" in res.output and "theorem1 applies only" in res.output
    assert FAMILIES["interpolation"].applies_to(spec_from_dict(GD)) is None


def test_the_float_build_reaches_the_closed_form():
    """The SDP of the family's ``problem`` (minimizing the constant) at the tight L/4."""
    om = bind_sublinear(spec_from_dict(GD))
    _, z = lmi_point(SUBLINEAR.problem(om), None, near=True)
    assert z is not None
    assert z[-1] * sublinear_data(om).s == pytest.approx(TIGHT, rel=2e-3)


def test_the_exact_check_proves_the_certified_constant_and_refuses_below_l_over_4(gd_row):
    spec = spec_from_dict(GD)
    cert, c = gd_row["certificate"], gd_row["constant"]
    assert TIGHT <= c < 1.01 * TIGHT
    proof = SUBLINEAR.exact_check(spec, None, c, cert)
    assert proof.verified == Verdict.EXACT
    assert proof.constant_proven_float >= TIGHT
    below = SUBLINEAR.exact_check(spec, None, 0.24, cert)
    assert below.verified != Verdict.EXACT
    with pytest.raises(ValueError, match="kappa"):
        SUBLINEAR.exact_check(spec, 10.0, c, cert)


def test_verify_of_an_analysis_document_goes_through_the_family(tmp_path, gd_row):
    """A claimed constant below L/4 in an otherwise valid document is not proven."""
    doc = {"kind": "analysis", "spec": GD["name"], "spec_text": yaml.safe_dump(GD),
           "source": "gd.yaml", "rows": [{**gd_row, "constant": 0.24}]}
    path = tmp_path / "doc.json"
    path.write_text(json.dumps(doc))
    res = CliRunner().invoke(cli, ["verify", str(path), "--no-simulate",
                                   "--out", str(tmp_path / "v")])
    assert res.exit_code == 3, res.output


def test_its_printed_columns_are_the_sublinear_table_columns():
    assert SUBLINEAR.printed_columns(["kappa", "rho"]) == SUBLINEAR_COLUMNS
    assert SUBLINEAR.printed_columns(["kappa", "verified"]) == SUBLINEAR_COLUMNS + ["verified"]
    assert SUBLINEAR.listing(spec_from_dict(GD), {}, latex=False).startswith(
        "gradient-convex: measure(x_k) <= c |x_0 - x*|^2 / k")


def test_lmi_prints_the_potential_and_its_conditions():
    """``sosalgo lmi`` of an m: 0 spec: the family's listing (there is no kappa to bind the
    method at, so no matrix of a rate family)."""
    for extra, lines in (([], ["c |x_0 - x*|^2 / k", "phi_{k+1} <= phi_k"]),
                         (["--latex"], [r"\begin{aligned}", r"\phi_{k+1} \le \phi_k"])):
        res = CliRunner().invoke(cli, ["lmi", str(SPECS / "gradient-convex.yaml"), *extra])
        assert res.exit_code == 0, res.output
        assert all(line in res.output for line in lines), res.output
