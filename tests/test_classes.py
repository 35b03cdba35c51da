"""The function-class seam: the shipped classes' inequalities hold on functions of the
class, and a new class plugs in by one module (here, this file) and one registry line."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from sosalgo.analysis import analyze_spec
from sosalgo.classes import CLASSES, FunctionClass, Inequality, register_class
from sosalgo.cli import cli
from sosalgo.spec import SpecError, spec_from_dict


def _values(cls: FunctionClass, params: dict, f, grad, pts: np.ndarray) -> float:
    """Smallest value of the class's inequalities over all ordered pairs of ``pts``."""
    worst = np.inf
    for a in pts:
        for b in pts:
            X = np.array([a, b, grad(a), grad(b)])
            for q in cls.inequalities(params):
                worst = min(worst, q.alpha * (f(a) - f(b)) + X @ q.Q @ X)
    return worst


def test_inequalities_hold_on_members_of_each_class():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=40) * 3
    huber = (lambda x: np.where(abs(x) < 1, x * x / 2, abs(x) - 0.5),
             lambda x: np.clip(x, -1, 1))  # convex, 1-smooth
    cases = [
        ("smooth_strongly_convex", {"m": 1.0, "L": 4.0},
         lambda x: 0.5 * x * x + 1.5 * huber[0](x), lambda x: x + 1.5 * huber[1](x)),
        ("convex", {}, lambda x: abs(x - 0.3), lambda x: np.sign(x - 0.3)),
        ("strongly_convex", {"m": 2.0}, lambda x: x * x + abs(x), lambda x: 2 * x + np.sign(x)),
    ]
    for name, params, f, g in cases:
        assert _values(CLASSES[name], params, f, g, pts) >= -1e-9, name


def test_inequalities_exclude_functions_outside_the_class():
    pts = np.array([-1.0, 0.5, 2.0])
    steep = (lambda x: 5 * x * x, lambda x: 10 * x)  # 10-smooth, not 4-smooth
    assert _values(CLASSES["smooth_strongly_convex"], {"m": 1.0, "L": 4.0}, *steep, pts) < 0
    concave = (lambda x: -x * x, lambda x: -2 * x)
    assert _values(CLASSES["convex"], {}, *concave, pts) < 0


class SmoothConvexGradientOnly(FunctionClass):
    """A test class: L-smooth convex functions answering gradient calls only."""

    name = "test_smooth_gradient_only"
    parameters = ("L",)
    defaults = {"L": "L"}
    oracles = frozenset({"gradient"})
    finite_everywhere = True

    def inequalities(self, params):
        L = params["L"]  # Taylor, Hendrickx, Glineur (2017), m = 0, scaled by 1/L
        Q = 0.5 / L * np.array([[0, 0, 0, -L], [0, 0, 0, L], [0, 0, -1, 1], [-L, L, 1, -1]])
        return [Inequality(1.0, Q)]

    def curvatures(self, params):
        return 0.0, params["L"]


register_class(SmoothConvexGradientOnly())  # the one registry line


def _prox_grad(f_class: str, g_class: str, **extra) -> dict:
    return {"name": "pg-test", "functions": {"f": {"class": f_class}, "g": {"class": g_class}},
            "parameters": {"h": {"value": "1/L", "range": [0, "2/L"]}},
            "matrices": {"A": [[1]], "B": [["-h", "-h"]], "C": [[1], [1]],
                         "D": [[0, 0], ["-h", "-h"]], "E": [[1]]},
            "oracles": ["f", "g"], "measure": "distance", "kappa": [10], **extra}


@pytest.mark.parametrize("kappa", [2.0, 10.0])
@pytest.mark.parametrize("frac", [0.5, 1.0, 1.8])
def test_a_new_class_runs_through_analyze(kappa, frac):
    """Prox-grad, f smooth convex (the test class), g m-strongly convex: the prox of h g is
    1/(1 + hm)-Lipschitz and x - h grad f(x) nonexpansive for h <= 2/L, equality at f = 0:
    the rate is 1/(1 + hm)."""
    spec = spec_from_dict(_prox_grad("test_smooth_gradient_only", "strongly_convex"))
    m, L = spec.mL(kappa)
    h = frac / L
    res = analyze_spec(spec, kappa, {"h": h})
    assert res.certified
    assert 1 / (1 + h * m) - 1e-9 <= res.rho <= 1 / (1 + h * m) + 2e-6


def test_a_new_class_through_the_command_line(tmp_path):
    path = tmp_path / "pg.yaml"
    path.write_text(yaml.safe_dump(_prox_grad("test_smooth_gradient_only", "strongly_convex")))
    res = CliRunner().invoke(cli, ["analyze", str(path), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert list((tmp_path / "o").glob("pg-test-analysis-interpolation.csv"))


def test_a_prox_on_a_class_without_one_is_refused():
    data = _prox_grad("convex", "test_smooth_gradient_only")
    with pytest.raises(SpecError) as err:
        spec_from_dict(data, source="x.yaml")
    assert err.value.field == "matrices.D[1][1]" and "no proximal oracle" in str(err.value)


def test_a_parameter_the_class_does_not_have_is_refused():
    data = _prox_grad("smooth_strongly_convex", "convex")
    data["functions"]["g"]["L"] = 3
    with pytest.raises(SpecError) as err:
        spec_from_dict(data, source="x.yaml")
    assert err.value.field == "functions.g.L"


def test_registry_refuses_a_class_without_oracles():
    class Nothing(FunctionClass):
        name = "nothing"

    with pytest.raises(ValueError, match="oracles"):
        register_class(Nothing())
