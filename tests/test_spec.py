"""Spec loading: shipped specs, the issue's example, shapes, ties, fixed points."""

from __future__ import annotations

import numpy as np
import pytest

from sosalgo.model import bind, fixed_point, parameter_values
from sosalgo.spec import SpecError, load_spec, spec_from_text

from .conftest import SPECS

SHIPPED = sorted(SPECS.glob("*.yaml"))


def test_all_required_specs_are_shipped():
    names = {p.stem for p in SHIPPED}
    assert {
        "gradient", "gradient-optimal", "nesterov", "nesterov-quadratic", "heavy-ball",
        "triple-momentum", "three-parameter",
    } <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_specs_load_and_have_references(path):
    spec = load_spec(path)
    assert spec.references, "each shipped spec carries its Table 1 reference rates"
    if spec.finite_sum is not None:  # no matrices: its step is a program (sosalgo pep)
        assert spec.finite_sum.step and not spec.matrices
        return
    if spec.time_varying:  # one method per step, each keeping the optimum fixed
        from sosalgo.oracles import fixed_point_basis
        from sosalgo.steps import float_steps, horizon

        listed = any(p.schedule for p in spec.parameters.values())
        for om in float_steps(spec, None, horizon(spec, None) if listed else 3):
            X = fixed_point_basis(om)
            assert X is not None and np.allclose(om.A @ X[:, 0], X[:, 0])
        return
    for k in (2.0, 10.0, 100.0):
        alg = bind(spec, k)
        u = fixed_point(alg)
        assert u is not None
        assert np.allclose(alg.A @ u, u)
        if spec.adjoint is not None:  # every call at its own point at the solution
            P, U = alg.reference_tables()
            assert np.allclose(alg.C @ u + alg.D @ U[:, 0], P[:, 0])
            continue
        assert np.isclose((alg.C @ u)[0], 1)


def test_nesterov_values_follow_table1():
    spec = load_spec(SPECS / "nesterov.yaml")
    vals = parameter_values(spec, 16.0)
    assert vals["h"] == pytest.approx(1 / 16)
    assert vals["beta"] == pytest.approx(3 / 5)
    assert vals["gamma"] == vals["beta"]  # tied
    assert spec.ranged == ["h", "beta"]


def test_heavy_ball_uses_corrected_parameterization():
    spec = load_spec(SPECS / "heavy-ball.yaml")
    vals = parameter_values(spec, 25.0)
    assert vals["gamma"] == 0
    assert vals["beta"] == pytest.approx(((5 - 1) / (5 + 1)) ** 2)
    assert vals["h"] == pytest.approx(4 / (5 + 1) ** 2)


def test_triple_momentum_parameters():
    spec = load_spec(SPECS / "triple-momentum.yaml")
    k = 49.0
    r = 1 - 1 / 7
    vals = parameter_values(spec, k)
    assert vals["h"] == pytest.approx((1 + r) / k)
    assert vals["beta"] == pytest.approx(r**2 / (2 - r))
    assert vals["gamma"] == pytest.approx(r**2 / ((1 + r) * (2 - r)))
    alg = bind(spec, k)
    d = r**2 / (1 - r**2)
    assert np.allclose(alg.E, [[-d, 1 + d]])


def test_theta_overrides_and_ties_follow():
    spec = load_spec(SPECS / "nesterov.yaml")
    alg = bind(spec, 10.0, {"beta": 0.25, "h": 0.05})
    assert np.allclose(alg.C, [[-0.25, 1.25]])
    assert np.allclose(alg.B, [[0], [-0.05]])


def test_kappa_range_form():
    text = (SPECS / "gradient.yaml").read_text().replace(
        "kappa: [2, 5, 10, 20, 50, 100]", "kappa: {from: 1.5, to: 1000, points: 30, scale: log}"
    )
    spec = spec_from_text(text, "g.yaml")
    assert len(spec.kappa) == 30
    assert spec.kappa[0] == pytest.approx(1.5) and spec.kappa[-1] == pytest.approx(1000)


def test_m_sets_the_scale():
    text = (SPECS / "gradient.yaml").read_text() + "m: 2\n"
    spec = spec_from_text(text, "g.yaml")
    alg = bind(spec, 10.0)
    assert (alg.m, alg.L) == (2.0, 20.0)
    assert alg.B[0, 0] == pytest.approx(-1 / 20)


def test_error_names_file_and_field():
    text = (SPECS / "nesterov.yaml").read_text().replace("B: [[0], [-h]]", "B: [[0, 1], [-h]]")
    with pytest.raises(SpecError) as err:
        spec_from_text(text, "bad.yaml")
    assert str(err.value).startswith("bad.yaml: matrices.B")


def test_duplicate_keys_and_python_tags_are_refused():
    with pytest.raises(SpecError, match="duplicate key"):
        spec_from_text("name: a\nname: b\n", "d.yaml")
    with pytest.raises(SpecError, match="invalid YAML"):
        spec_from_text("name: !!python/object/apply:os.system ['touch x']\n", "t.yaml")
    with pytest.raises(SpecError, match="alias"):
        spec_from_text("name: &a x\ndescription: *a\n", "a.yaml")
