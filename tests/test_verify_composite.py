"""Exact verification and simulation of composite certificates (proximal steps, several
functions, other classes): sosalgo.certificates.exact_composite, the classes' test functions,
simulate_composite.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.optimize import minimize

from sosalgo.certificates import get_family
from sosalgo.certificates.exact_composite import exact_class_inequalities, verify_exact_composite
from sosalgo.classes import CLASSES
from sosalgo.classes.members import ProxFunction
from sosalgo.cli import cli
from sosalgo.kernel.exact import Ball
from sosalgo.model import bind
from sosalgo.proofs.prox_functions import ProxProblem
from sosalgo.proofs.simulate_composite import run_method, simulate_composite
from sosalgo.spec import load_spec
from tests.conftest import spec_path

SPECS = ["proximal-gradient", "projected-gradient", "proximal-point", "douglas-rachford",
         "accelerated-proximal-gradient"]
KAPPAS = [2.0, 10.0, 100.0]
FAM = get_family("interpolation")


@pytest.fixture(scope="module")
def documents(tmp_path_factory) -> dict[str, tuple[str, dict]]:
    """``analyze --json`` of every composite spec at kappa 2, 10, 100 (path, document)."""
    out = {}
    root = tmp_path_factory.mktemp("composite")
    for name in SPECS:
        args = ["analyze", str(spec_path(name)), "--json", "--out", str(root / name),
                "--no-plot", "--quiet", "--workers", "1"]
        for k in KAPPAS:
            args += ["--kappa", str(k)]
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 0, res.output
        path = root / f"{name}.json"
        path.write_text(res.stdout)
        out[name] = (str(path), json.loads(res.stdout))
    return out


@pytest.mark.parametrize("name", SPECS)
def test_exact_verification_of_every_spec(documents, name):
    spec = load_spec(spec_path(name))
    rows = documents[name][1]["rows"]
    assert [r["kappa"] for r in rows] == KAPPAS
    for row in rows:
        res = verify_exact_composite(spec, row["kappa"], row["rho"], row["certificate"])
        assert res.ok, (row["kappa"], res.reason)
        assert res.rho_proven_float >= row["rho"]
        assert res.rho_proven_float <= row["rho"] * (1 + 1e-6)
        assert res.to_dict()["measure"] == spec.measure


def _tamper(cert: dict, how: str) -> dict:
    bad = copy.deepcopy(cert)
    if how == "multiplier":  # the largest decrease multiplier to 0
        mult = bad["multipliers"]["decrease"]
        mult[max(mult, key=lambda k: abs(mult[k]))] = 0.0
    elif how == "P":
        bad["P"][0][0] = 0.5 * bad["P"][0][0]
    return bad


@pytest.mark.parametrize("name", SPECS)
@pytest.mark.parametrize("how", ["rho", "multiplier", "P"])
def test_tampered_certificates_fail(documents, name, how):
    spec = load_spec(spec_path(name))
    row = documents[name][1]["rows"][1]  # kappa 10
    rho = row["rho"] * (0.97 if how == "rho" else 1.0)
    res = verify_exact_composite(spec, row["kappa"], rho, _tamper(row["certificate"], how))
    assert not res.ok and res.reason


def test_a_certificate_for_another_measure_is_refused(documents):
    spec = load_spec(spec_path("proximal-gradient"))
    row = documents["proximal-gradient"][1]["rows"][0]
    res = verify_exact_composite(spec, row["kappa"], row["rho"],
                                 {**row["certificate"], "measure": "function"})
    assert not res.ok and "measure" in res.reason


def test_verify_command_exact_and_tampered(documents, tmp_path):
    path, doc = documents["douglas-rachford"]
    res = CliRunner().invoke(cli, ["verify", path, "--out", str(tmp_path / "ok"), "--json"])
    assert res.exit_code == 0, res.output
    checks = json.loads(res.stdout)["results"]
    assert all(c["verified"] == "exact" and c["simulation"]["ok"] for c in checks)
    bad = copy.deepcopy(doc)
    bad["rows"][0]["rho"] *= 0.97
    bad_path = tmp_path / "bad.json"
    bad_path.write_text(json.dumps(bad))
    res = CliRunner().invoke(cli, ["verify", str(bad_path), "--out", str(tmp_path / "bad")])
    assert res.exit_code == 3, res.output


def test_analyze_verify_on_a_composite_spec(tmp_path):
    res = CliRunner().invoke(cli, ["analyze", str(spec_path("proximal-point")), "--kappa", "10",
                                   "--verify", "--json", "--out", str(tmp_path), "--no-plot",
                                   "--quiet", "--workers", "1"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["rows"][0]["verified"] == "exact"


@pytest.mark.parametrize("name", SPECS)
def test_simulation_passes_and_a_lower_rate_is_caught(documents, name):
    spec = load_spec(spec_path(name))
    row = documents[name][1]["rows"][1]
    om = bind(spec, row["kappa"])
    sim = simulate_composite(om, row["rho"], **FAM.lyapunov(row["certificate"]))
    assert sim.ok and sim.trajectories > 0 and sim.steps_checked > 0
    lower = simulate_composite(om, 0.9 * row["rho"], **FAM.lyapunov(row["certificate"]))
    assert not lower.ok


# --------------------------------------------------------------------------- test functions


def _prox_objective(f: ProxFunction, v: np.ndarray, t: float):
    return lambda y: float(f.value(y[None, :])[0] + ((y - v) ** 2).sum() / (2 * t))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # Powell on +inf outside the sets
@pytest.mark.parametrize("cls,params", [
    ("smooth_strongly_convex", {"m": 1.0, "L": 10.0}), ("convex", {}),
    ("strongly_convex", {"m": 0.5}), ("indicator", {})])
def test_prox_closed_forms_against_numeric_minimization(cls, params):
    rng = np.random.default_rng(3)
    d = 2
    xs = rng.standard_normal(d)
    for f in CLASSES[cls].test_functions(params, xs, rng):
        for t in (0.1, 1.0, 3.0):
            v = xs + 2 * rng.standard_normal(d)
            y = f.prox(v[None, :], t)[0]
            obj = _prox_objective(f, v, t)
            num = minimize(obj, xs, method="Powell", options={"xtol": 1e-10, "ftol": 1e-14})
            assert obj(y) <= num.fun + 1e-6 * (1 + abs(num.fun)), (f.name, t)  # set tolerance
            if np.isfinite(f.value(xs + 5 * rng.standard_normal((20, d)))).all():
                # (Powell stalls on the boundary of a set: the subgradient check below
                # decides there, u in ∂f(y) being equivalent to y = prox_{t f}(v))
                assert np.abs(y - num.x).max() < 1e-4, (f.name, t)
            # u = (v - y)/t is a subgradient at y, s one at x*: f(z) >= f(y) + <u, z - y>
            u = (v - y) / t
            z = xs + 3 * rng.standard_normal((50, d))
            fz = f.value(z)
            assert np.all(fz >= f.value(y[None])[0] + (z - y) @ u - 1e-9), f.name
            assert np.all(fz >= f.value(xs[None])[0] + (z - xs) @ f.s - 1e-9), f.name


def test_smooth_test_functions_are_in_the_class():
    """Every pair of points of the F(m, L) test functions satisfies the class's
    interpolation inequality (Taylor, Hendrickx, Glineur 2017, Thm. 4)."""
    cls, params = CLASSES["smooth_strongly_convex"], {"m": 1.0, "L": 10.0}
    (ineq,) = cls.inequalities(params)
    rng = np.random.default_rng(5)
    xs = rng.standard_normal(3)
    for f in cls.test_functions(params, xs, rng):
        pts = xs + 2 * rng.standard_normal((30, 3))
        vals, grads = f.value(pts), f.grad(pts)
        for a in range(30):
            for b in range(30):
                X = np.array([pts[a], pts[b], grads[a], grads[b]])
                q = ineq.alpha * (vals[a] - vals[b]) + np.einsum("id,ij,jd->", X, ineq.Q, X)
                assert q >= -1e-8 * (1 + abs(vals[a])), f.name


@pytest.mark.parametrize("name", ["smooth_strongly_convex", "convex", "strongly_convex",
                                  "indicator"])
def test_exact_class_data_match_the_classes(name):
    cls = CLASSES[name]
    params = {k: v for k, v in {"m": 0.5, "L": 7.0}.items() if k in cls.parameters}
    exact, source = exact_class_inequalities(cls, {k: Ball(v) for k, v in
                                                   {"m": 0.5, "L": 7}.items()
                                                   if k in cls.parameters})
    assert source == "exact"
    fl = cls.tilted(params)
    assert len(exact) == len(fl)
    for (alpha, Q), ineq in zip(exact, fl, strict=True):
        assert float(alpha.c) == pytest.approx(ineq.alpha, abs=1e-15)
        assert np.allclose([[float(b.c) for b in row] for row in Q], ineq.Q, atol=1e-15)


# --------------------------------------------------------------------------- proximal gradient


def _pg(kappa: float, h_frac: float):
    spec = load_spec(spec_path("proximal-gradient"))
    m, L = spec.mL(kappa)
    return bind(spec, kappa, {"h": h_frac / L}), m, L, h_frac / L


def _quad_plus_abs(q: float, a: float = 5.0) -> ProxProblem:
    """q/2 (x - a)^2 + |x|, minimizer a - 1/q > 0 (a >= 1/q): the prox is a shift there."""
    xs = np.array([a - 1 / q])
    f = ProxFunction("quad", lambda x: 0.5 * q * ((x - a) ** 2).sum(axis=1),
                     lambda v, t: (v + t * q * a) / (1 + t * q), lambda x: q * (x - a),
                     q * (xs - a), "")
    g = ProxFunction("abs", lambda x: np.abs(x).sum(axis=1),
                     lambda v, t: np.sign(v) * np.maximum(np.abs(v) - t, 0),
                     lambda x: np.sign(x), np.sign(xs), "")
    return ProxProblem("quad+abs", 1, (f, g), xs)


@pytest.mark.parametrize("h_frac", [0.5, 1.0, 1.5, 1.9])
def test_proximal_gradient_rate_on_the_worst_quadratic(h_frac):
    """On q/2 (x - a)^2 + |x| with q in {m, L}, |x_k - x*| = |1 - hq|^k |x_0 - x*|: the
    simulated rate is max(|1 - hm|, |1 - hL|) (Taylor, Hendrickx, Glineur 2018), and the
    certified rate is not below it."""
    from sosalgo.analysis import analyze_spec

    kappa = 10.0
    om, m, L, h = _pg(kappa, h_frac)
    rates = []
    for q in (m, L):
        prob = _quad_plus_abs(q)
        tr = run_method(om, prob, np.array([[[prob.x_star[0] + 0.5]]]), 30)
        err = np.abs(tr["xi"][:, 0, 0, 0] - prob.x_star[0])
        rates.append((err[20] / err[0]) ** (1 / 20))
    ref = max(abs(1 - h * m), abs(1 - h * L))
    assert max(rates) == pytest.approx(ref, rel=1e-9)
    res = analyze_spec(load_spec(spec_path("proximal-gradient")), kappa, {"h": h})
    assert ref - 1e-9 <= res.rho <= ref + 2e-6


def test_proximal_gradient_distance_ratio_never_exceeds_the_certified_rate(documents):
    """|x_k - x*|^2 / |x_0 - x*|^2 <= rho^(2k) on F(m, L) + |x|_1 problems (random starts,
    d = 1, 3), rho the certified rate."""
    spec = load_spec(spec_path("proximal-gradient"))
    rng = np.random.default_rng(11)
    for row in documents["proximal-gradient"][1]["rows"]:
        om = bind(spec, row["kappa"])
        m, L = om.m, om.L
        for d in (1, 3):
            xs = rng.standard_normal(d)
            for f in CLASSES["smooth_strongly_convex"].test_functions({"m": m, "L": L},
                                                                      xs, rng):
                g = CLASSES["convex"].test_functions({}, xs, rng)[0]  # the l1 norm
                prob = ProxProblem("pg", d, (f.tilt(-(f.s + g.s)), g), xs)
                x0 = xs + 10 ** rng.uniform(-1, 1, (8, 1, 1)) * rng.standard_normal((8, 1, d))
                tr = run_method(om, prob, x0, 40)
                err = ((tr["xi"][:, :, 0, :] - xs) ** 2).sum(axis=2)
                k = np.arange(41)[:, None]
                assert np.all(err <= row["rho"] ** (2 * k) * err[0] * (1 + 1e-9) + 1e-24)
