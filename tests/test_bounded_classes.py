"""``smooth_convex_lipschitz`` (L-smooth convex, |grad f| <= M: PEPit's
SmoothConvexLipschitzFunction) and ``bounded_indicator`` (a set of diameter <= D:
ConvexIndicatorFunction with D), two classes with an inhomogeneous condition.

PEPIT holds PEPit's own values, computed once outside sosalgo: PEPit 0.5.1 (pip, its own
venv), cvxpy with Clarabel, on the PEP written with PEPit's own API (no example uses the
class): ``f = declare_function(SmoothConvexLipschitzFunction, L, M)``, ``(x0 - xs)**2 <=
1``, n steps ``x = x - gamma * f.gradient(x)``, metric ``f(x) - f(xs)``. The soundness
check runs gradient descent on sums of Huber functions (L-smooth and M-Lipschitz by
construction), written here.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from sosalgo.cli import cli

from .conftest import pep_json

SPECS = Path(__file__).resolve().parents[1] / "specs"

# (L, M, N, gamma): PEPit's value (see the module)
PEPIT = {(1, "1/10", 2, "1"): 0.07500034857450907,
         (1, "1/2", 3, "1"): 0.07142855923260381,
         (2, "1", 2, "2/5"): 0.23809523859538984}


def _variant(tmp_path: Path, base: str, **changes) -> Path:
    data = yaml.safe_load((SPECS / f"{base}.yaml").read_text(encoding="utf-8"))
    for key, value in changes.items():
        data[key] = value
    path = tmp_path / f"{base}-variant.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def _pep(spec: Path, tmp_path: Path, steps: int, *extra: str) -> dict:
    return pep_json(spec, tmp_path / "o", steps, *extra)


def _smooth_lipschitz(tmp_path: Path, L: int, M: str, h: str) -> Path:
    return _variant(tmp_path, "gradient-convex", L=L,
                    functions={"f": {"class": "smooth_convex_lipschitz", "M": M}},
                    parameters={"h": {"value": h}},
                    pep={"measure": "f", "initial": "dist(x_0)"})


@pytest.mark.parametrize("L,M,steps,gamma", sorted(PEPIT))
def test_smooth_lipschitz_agrees_with_pepit(tmp_path, L, M, steps, gamma):
    """Gradient descent on L-smooth convex M-Lipschitz f: PEPit's value, proven from
    above (never below PEPit beyond 1e-5, its solver's accuracy here), witnessed below."""
    doc = _pep(_smooth_lipschitz(tmp_path, L, M, gamma), tmp_path, steps)
    pepit = PEPIT[(L, M, steps, gamma)]
    assert doc["tau"] == pytest.approx(pepit, rel=1e-5)
    upper = Fraction(doc["certificate"]["tau_proven"])
    assert upper >= pepit * (1 - 1e-5) and upper <= pepit * (1 + 1e-4)
    check = doc["witness"]["check"]
    assert check["verified"] and pepit * (1 - 1e-4) <= Fraction(check["tau_lower"]) <= upper


@pytest.mark.parametrize("steps", [1, 3])
def test_a_large_m_is_the_smooth_closed_form(tmp_path, steps):
    """With M far above every gradient the worst case is L-smooth convex gradient
    descent's, L/(4N + 2) (Drori and Teboulle 2014), tight."""
    doc = _pep(_smooth_lipschitz(tmp_path, 1, "100", "1"), tmp_path, steps)
    assert float(Fraction(doc["certificate"]["tau_proven"])) == pytest.approx(
        1 / (4 * steps + 2), rel=1e-6)


def test_huber_sums_never_beat_the_proven_bound(tmp_path):
    """Gradient descent (h = 1/L) on f(x) = sum_i w_i H_{a_i}(<u_i, x>) with sum w_i |u_i|^2
    <= L (L-smooth) and sum w_i a_i |u_i| <= M (M-Lipschitz), from the unit sphere:
    f(x_N) - f* stays below the proven bound."""
    L, M, steps = 1.0, 0.3, 2
    doc = _pep(_smooth_lipschitz(tmp_path, 1, "3/10", "1"), tmp_path, steps)
    upper = float(Fraction(doc["certificate"]["tau_proven"]))
    rng = np.random.default_rng(4)
    best = 0.0
    for _ in range(300):
        d, k = int(rng.integers(1, 4)), int(rng.integers(1, 4))
        U = rng.standard_normal((k, d))
        w = rng.uniform(0.1, 1, k)
        w *= L * rng.uniform(0.5, 1) / float(w @ (U * U).sum(axis=1))
        a = rng.uniform(0.1, 1, k)
        a *= M * rng.uniform(0.5, 1) / float(w @ (a * np.linalg.norm(U, axis=1)))

        def f(x, U=U, w=w, a=a):
            t = U @ x
            return float(w @ np.where(np.abs(t) <= a, t * t / 2, a * np.abs(t) - a * a / 2))

        def grad(x, U=U, w=w, a=a):
            return (w * np.clip(U @ x, -a, a)) @ U

        x = rng.standard_normal(d)
        x /= np.linalg.norm(x)
        for _ in range(steps):
            x = x - grad(x) / L
        best = max(best, f(x))
    assert 0 < best <= upper * (1 + 1e-9)


def _projected(tmp_path: Path, D: str) -> Path:
    data = yaml.safe_load((SPECS / "projected-gradient.yaml").read_text(encoding="utf-8"))
    data["functions"]["g"] = {"class": "bounded_indicator", "D": D}
    data["pep"] = {"measure": "dist", "initial": "dist(x_0)"}
    path = tmp_path / "projected-bounded.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def test_a_bounded_set_caps_the_distance(tmp_path):
    """Projected gradient (kappa = 10, h = 1/L): after one step x_1 and x* are in the set,
    so |x_1 - x*|^2 <= D^2, attained (D = 1/10; 0.81 for the whole space), and stays below
    D^2 after two steps; with D = 100 the bound is the unbounded set's (1 - 1/kappa)^2 =
    0.81."""
    small = _pep(_projected(tmp_path, "1/10"), tmp_path, 1, "--kappa", "10")
    upper = Fraction(small["certificate"]["tau_proven"])
    assert Fraction(1, 100) <= upper <= Fraction(1, 100) * (1 + Fraction(1, 10 ** 5))
    assert small["witness"]["check"]["verified"]
    large = _pep(_projected(tmp_path, "100"), tmp_path, 1, "--kappa", "10")
    upper = Fraction(large["certificate"]["tau_proven"])
    assert Fraction(81, 100) <= upper <= Fraction(81, 100) * (1 + Fraction(1, 10 ** 6))
    two = _pep(_projected(tmp_path, "1/10"), tmp_path, 2, "--kappa", "10")
    assert Fraction(two["certificate"]["tau_proven"]) <= Fraction(1, 100)


@pytest.mark.parametrize("D,steps", [("1/10", 2), ("1/2", 3)])
def test_projections_on_boxes_never_beat_the_proven_bound(tmp_path, D, steps):
    """Projected gradient (h = 1/L, kappa = 10) on separable quadratics f = sum_i q_i/2
    (x_i - c_i)^2, q_i in [m, L], over random boxes of diameter <= D (x* = the clipped
    c), from starts at distance 1: |x_N - x*|^2 stays below the proven bound."""
    doc = _pep(_projected(tmp_path, D), tmp_path, steps, "--kappa", "10")
    upper = float(Fraction(doc["certificate"]["tau_proven"]))
    m, L, diameter = 1.0, 10.0, float(Fraction(D))
    rng = np.random.default_rng(8)
    best = 0.0
    for _ in range(300):
        d = int(rng.integers(1, 4))
        side = rng.uniform(0.1, 1, d)
        side *= diameter * rng.uniform(0.5, 1) / np.linalg.norm(side)
        lo = rng.uniform(-1, 1, d)
        hi = lo + side
        q, c = rng.uniform(m, L, d), rng.uniform(-2, 2, d)
        xs = np.clip(c, lo, hi)
        x0 = rng.standard_normal(d)
        x = xs + x0 / np.linalg.norm(x0)
        for _ in range(steps):
            x = np.clip(x - q * (x - c) / L, lo, hi)
        best = max(best, float((x - xs) @ (x - xs)))
    assert 0 < best <= upper * (1 + 1e-9)


@pytest.mark.parametrize("which", ["lipschitz", "bounded"])
def test_analyze_refuses_in_one_line(tmp_path, which):
    spec = (_smooth_lipschitz(tmp_path, 1, "1", "1") if which == "lipschitz"
            else _projected(tmp_path, "1"))
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["analyze", str(spec), "--out", str(out)])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and "functions" in lines[0] and not out.exists()
