"""The interpolation certificate family against facts that do not come from our output:
closed forms, the triple momentum rate, Taylor-Van Scoy-Lessard's published Nesterov rate,
Theorem 1 (which this family contains) and the rate on quadratics (a lower bound)."""

from __future__ import annotations

import copy
from fractions import Fraction

import numpy as np
import pytest

from sosalgo.analysis import analyze_algorithm, analyze_spec
from sosalgo.certificates import get_family
from sosalgo.certificates.interpolation import Interpolation
from sosalgo.model import Algorithm, bind
from sosalgo.proofs import lrp_counterexample, simulate_check
from sosalgo.proofs.results import verify_family_certificate
from sosalgo.spec import SpecError, load_spec, spec_from_text

from .conftest import SPECS

TIGHT = Interpolation()


def _spec(name: str):
    return load_spec(SPECS / f"{name}.yaml")


def _quadratic_rate(alg: Algorithm, points: int = 801) -> float:
    """max over q in [m, L] of the spectral radius of A + q B C (grid max <= true max)."""
    qs = np.linspace(alg.m, alg.L, points)
    return max(np.abs(np.linalg.eigvals(alg.A + q * alg.B @ alg.C)).max() for q in qs)


# --------------------------------------------------------------------------- closed forms
@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
def test_gradient_closed_forms(kappa):
    res = analyze_spec(_spec("gradient"), kappa, family=TIGHT)
    assert res.rho == pytest.approx(1 - 1 / kappa, abs=1e-5)
    assert res.rho >= 1 - 1 / kappa - 1e-9
    res = analyze_spec(_spec("gradient-optimal"), kappa, family=TIGHT)
    assert res.rho == pytest.approx((kappa - 1) / (kappa + 1), abs=1e-5)
    assert res.rho >= (kappa - 1) / (kappa + 1) - 1e-9


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0, 1000.0])
def test_triple_momentum_is_tight(kappa):
    alg = bind(_spec("triple-momentum"), kappa)
    target = 1 - 1 / np.sqrt(kappa)
    res = analyze_algorithm(alg, family=TIGHT)
    assert res.certified and abs(res.rho - target) <= 1e-5
    # the family does not depend on the output point: x_k = xi_k[1] instead
    alg2 = Algorithm(alg.A, alg.B, alg.C, np.array([[0.0, 1.0]]), alg.m, alg.L)
    res2 = analyze_algorithm(alg2, family=TIGHT)
    assert res2.certified and abs(res2.rho - target) <= 1e-5


def test_triple_momentum_lag0():
    res = analyze_spec(_spec("triple-momentum"), 10.0, family=Interpolation(0))
    assert abs(res.rho - (1 - 1 / np.sqrt(10))) <= 1e-5


def test_nesterov_published_value():
    """Taylor, Van Scoy, Lessard (ICML 2018) report 0.7518 for Nesterov (h = 1/L) at kappa 10."""
    res = analyze_spec(_spec("nesterov"), 10.0, family=TIGHT)
    assert abs(res.rho - 0.7518) <= 2e-4
    assert res.max_eig_M <= 0 and res.min_eig_P >= 0


def test_heavy_ball_certified_at_10_not_at_25():
    spec = _spec("heavy-ball")
    res = analyze_spec(spec, 10.0, family=TIGHT)
    assert res.certified and _quadratic_rate(bind(spec, 10.0)) - 1e-6 <= res.rho < 1
    res25 = analyze_spec(spec, 25.0, family=TIGHT)
    assert not res25.certified and res25.rho is None
    # Lessard-Recht-Packard: the method cycles on their function, so no Lyapunov function of
    # this family can decrease along that trajectory, whatever P, p, c
    alg = bind(spec, 25.0)
    f = lrp_counterexample(1, np.random.default_rng(0), alg.m, alg.L)
    for P, p, c in ((np.eye(4), [1.0, 0.0], 1.0), (np.diag([1.0, 2.0, 0.1, 0.1]), [0.5, 0.5], 2.0)):
        sim = simulate_check(alg, 0.99, P, functions=[f], starts=4, iters=400,
                             lyapunov={"lag": 1, "p": p, "c": c})
        assert not sim.ok and sim.violations_by_function.get("lrp (d=1)", 0) > 0


# --------------------------------------------------------------------------- Theorem 1 inside
def test_contains_theorem1():
    """A Theorem 1 certificate (P, lambda) embeds: P' = [P 0; 0 0], p = 0, c = 1 and the
    multipliers 1/(L-m) (y_l > x_{l+1}), r/(L-m) (x_l > y_l), (1-r)/(L-m) (* > y_l), and
    lambda/(m+L) on both (y_l > *) and (* > y_l)."""
    for name, kappa in (("nesterov", 10.0), ("heavy-ball", 2.0), ("triple-momentum", 2.0)):
        alg = bind(_spec(name), kappa)
        t1 = analyze_algorithm(alg)
        assert t1.certified
        fam = Interpolation()
        lag = fam.lag_for(alg.n)
        r, m, L = t1.rho**2, alg.m, alg.L
        P = np.zeros((alg.n + lag + 1,) * 2)
        P[: alg.n, : alg.n] = t1.P
        pl = f"y{lag}"
        dec = {k: 0.0 for k in fam._structure(alg, False).dec.labels}
        pos = {k: 0.0 for k in fam._structure(alg, False).pos.labels}
        hx = fam._structure(alg, False).has_x  # x = y (E = C): the x-points are y-points
        x = "x" if hx else "y"
        dec[f"{pl}>{x}{lag + 1}"] += 1 / (L - m)
        if hx:
            dec[f"x{lag}>{pl}"] += r / (L - m)
        dec[f"*>{pl}"] += (1 - r) / (L - m) + t1.lam / (m + L)
        dec[f"{pl}>*"] += t1.lam / (m + L)
        cert = {"lag": lag, "P": P, "p": [0.0 if hx else 1.0] + [0.0] * lag,
                "c": 1.0 if hx else None, "multipliers": {"decrease": dec, "positivity": pos}}
        parts = fam.parts(alg, t1.rho, cert)
        scale = 1 + np.abs(parts["D"]).max()
        assert np.linalg.eigvalsh(parts["D"])[-1] <= 1e-9 * scale
        assert np.all(parts["Df"] <= 1e-12) and np.all(parts["Pf"] >= -1e-12)
        assert np.linalg.eigvalsh(parts["Pq"])[0] >= -1e-9 * scale
        tight = analyze_algorithm(alg, family=fam)
        assert tight.rho <= t1.rho + 1e-6


def _random_methods(count: int, seed: int):
    """Random 2- and 3-state methods with a fixed point (A u = u, C u = E u = 1)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        kappa = float(np.exp(rng.uniform(np.log(1.5), np.log(100))))
        n = 2 if i % 3 else 3
        if n == 2 and i % 2:
            h, b, g = rng.uniform(0, 2 / kappa), rng.uniform(0, 1), rng.uniform(0, 1)
            A = np.array([[0, 1], [-b, 1 + b]])
            B = np.array([[0], [-h]])
            C = np.array([[-g, 1 + g]])
            E = np.array([[0.0, 1.0]])
        else:
            u = rng.normal(size=n)
            V = np.column_stack([u, rng.normal(size=(n, n - 1))])
            A = V @ np.diag([1.0, *rng.uniform(-0.9, 0.9, n - 1)]) @ np.linalg.inv(V)
            c, e = rng.normal(size=n), rng.normal(size=n)
            C = (c + (1 - c @ u) * u / (u @ u))[None, :]
            E = (e + (1 - e @ u) * u / (u @ u))[None, :]
            B = rng.normal(size=(n, 1)) / kappa
        out.append(Algorithm(A, B, C, E, 1.0, kappa))
    return out


def test_between_quadratic_bound_and_theorem1():
    """On 210 seeded random methods: quadratic rate <= interpolation rate <= Theorem 1 rate
    (3-state methods alternate lag 0 and 1; the default would be 2)."""
    tol = 1e-5
    both = tight_only = 0
    for i, alg in enumerate(_random_methods(210, seed=11)):
        fam = Interpolation(i % 2) if alg.n == 3 else TIGHT
        res = analyze_algorithm(alg, tol=tol, family=fam)
        t1 = analyze_algorithm(alg, tol=tol)
        if t1.certified:
            assert res.certified and res.rho <= t1.rho + 2 * tol, (alg, res.rho, t1.rho)
            both += 1
        if res.certified:
            assert res.rho >= _quadratic_rate(alg) - 1e-6, (alg, res.rho)
            assert res.max_eig_M <= 0 and res.min_eig_P >= 0
            tight_only += not t1.certified
    assert both >= 60 and tight_only >= 5  # both cases must be exercised


# --------------------------------------------------------------------------- verification
@pytest.fixture(scope="module")
def nesterov_cert():
    spec = _spec("nesterov")
    res = analyze_spec(spec, 10.0, family=TIGHT)
    return spec, res


def test_certificates_verify_exactly(nesterov_cert):
    spec, res = nesterov_cert
    ex = TIGHT.exact_check(spec, 10.0, res.rho, res.certificate)
    assert ex.verified == "exact", ex.reason
    assert res.rho <= ex.rho_proven_float <= res.rho * (1 + 1e-7)
    # exact rational P and multipliers, and a method with irrational entries (sqrt(10))
    assert "/" in ex.certificate["P"][0][0] or ex.certificate["P"][0][0].lstrip("-").isdigit()
    for name, kappa in (("triple-momentum", 10.0), ("gradient", 10.0)):
        sp_ = _spec(name)
        r = analyze_spec(sp_, kappa, family=TIGHT)
        out = verify_family_certificate(sp_, TIGHT, kappa, r.rho, r.certificate)
        assert out["verified"] == "exact", out["reason"]
        assert out["simulation"]["ok"], out["simulation"]


def test_simulation_accepts_certificate(nesterov_cert):
    spec, res = nesterov_cert
    cert = res.certificate
    sim = simulate_check(bind(spec, 10.0), res.rho, **TIGHT.lyapunov(cert))
    assert sim.ok and sim.n_violations == 0 and sim.worst_ratio <= 1 + 1e-9


def test_tampered_certificates_fail(nesterov_cert):
    spec, res = nesterov_cert
    cert = res.certificate

    def tampered(fn):
        c = copy.deepcopy(cert)
        c["P"] = np.array(c["P"], dtype=float)
        fn(c)
        return c

    # a faster rate than the tight one cannot be proven with this certificate
    assert TIGHT.exact_check(spec, 10.0, res.rho - 1e-3, cert,
                                      rho_steps=(0.0,)).verified == "failed"
    # nor with a changed P, a dropped multiplier or a wrong weight
    big = max(cert["multipliers"]["decrease"], key=cert["multipliers"]["decrease"].get)
    for fn in (lambda c: c["P"].__setitem__((0, 0), c["P"][0, 0] * 1.01),
               lambda c: c["multipliers"]["decrease"].__setitem__(big, 0.0),
               lambda c: c["p"].__setitem__(0, c["p"][0] + 1.0),
               lambda c: c.__setitem__("c", None)):
        ex = TIGHT.exact_check(spec, 10.0, res.rho, tampered(fn), rho_steps=(0.0,))
        assert ex.verified == "failed"
    # the simulation check also sees a tampered decrease (V grows along some trajectory)
    sim = simulate_check(bind(spec, 10.0), res.rho - 0.05, **TIGHT.lyapunov(cert))
    assert not sim.ok


def test_exact_rationals_are_accepted(nesterov_cert):
    spec, res = nesterov_cert
    cert = copy.deepcopy(res.certificate)
    cert["P"] = [[Fraction(v).limit_denominator(10**12) for v in row] for row in cert["P"]]
    assert TIGHT.exact_check(spec, 10.0, res.rho, cert).verified == "exact"


# --------------------------------------------------------------------------- spec and options
def test_spec_certificate_field():
    text = (SPECS / "nesterov.yaml").read_text()
    s1 = spec_from_text(text + "certificate: interpolation\n", "t.yaml")
    assert s1.certificate == "interpolation" and s1.certificate_options == {}
    s2 = spec_from_text(text + "certificate: {family: interpolation, lag: 0}\n", "t.yaml")
    assert s2.certificate_options == {"lag": 0}
    assert analyze_spec(s2, 10.0).family == "interpolation"
    for bad, field in (("{family: interpolation, lag: -1}", "certificate.lag"),
                       ("{family: theorem1, lag: 0}", "certificate.lag"),
                       ("{family: nope}", "certificate.family"), ("tight", "certificate")):
        with pytest.raises(SpecError, match=field):
            spec_from_text(text + f"certificate: {bad}\n", "t.yaml")
    assert get_family("interpolation", {"lag": 0}).lag == 0
    with pytest.raises(ValueError):
        get_family("theorem1", {"lag": 0})


# --------------------------------------------------------------------------- command line
def _run(args):
    from click.testing import CliRunner

    from sosalgo.cli import cli

    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def test_cli_triple_momentum_and_verify(tmp_path):
    import csv
    import json

    spec = _spec("triple-momentum")
    res = _run(["analyze", SPECS / "triple-momentum.yaml", "--certificate", "interpolation",
                "--out", tmp_path, "--quiet", "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert [r["kappa"] for r in doc["rows"]] == list(spec.kappa)
    for r in doc["rows"]:
        assert r["certified"] and abs(r["rho"] - (1 - r["kappa"] ** -0.5)) <= 1e-5
        assert r["family"] == "interpolation" and r["lambda"] is None
        cert = r["certificate"]
        assert np.array(cert["P"]).shape == (4, 4) and len(cert["p"]) == 2
        assert set(cert["multipliers"]) == {"decrease", "positivity"}
    rows = list(csv.DictReader(open(tmp_path / "triple-momentum-analysis-interpolation.csv")))
    assert {"P44", "p0", "p1", "c", "multipliers", "family", "lag"} <= set(rows[0])
    assert not (tmp_path / "triple-momentum-analysis.csv").exists()
    (tmp_path / "tm.json").write_text(json.dumps({**doc, "rows": doc["rows"][:2]}))
    res = _run(["verify", tmp_path / "tm.json", "--out", tmp_path])
    assert res.exit_code == 0, res.output
    assert res.stdout.split("claims:")[0].count("exact") == 2  # the checks table


def test_cli_compare_families_and_table1(tmp_path):
    import csv

    res = _run(["analyze", SPECS / "nesterov.yaml", "--certificate", "theorem1,interpolation",
                "--kappa", "2", "--kappa", "10", "--out", tmp_path, "--quiet"])  # a figure
    assert res.exit_code == 0, res.output
    t1 = list(csv.DictReader(open(tmp_path / "nesterov-analysis.csv")))
    ti = list(csv.DictReader(open(tmp_path / "nesterov-analysis-interpolation.csv")))
    assert "p0" not in t1[0] and float(ti[0]["rho"]) < float(t1[0]["rho"])
    assert (tmp_path / "nesterov-rate-theorem1-interpolation.png").stat().st_size > 1000
    res = _run(["table1", "--specs", SPECS / "gradient.yaml", "--kappa", "10",
                "--certificate", "theorem1,interpolation", "--out", tmp_path])
    assert res.exit_code == 0, res.output
    row = next(csv.DictReader(open(tmp_path / "table1.csv")))
    assert float(row["rho_certified"]) == pytest.approx(0.9, abs=1e-5)
    assert float(row["rho_interpolation"]) == pytest.approx(0.9, abs=1e-5)
    res = _run(["analyze", SPECS / "nesterov.yaml", "--certificate", "tight", "--out", tmp_path])
    assert res.exit_code == 2 and "--certificate tight" in res.output
    res = _run(["lmi", SPECS / "nesterov.yaml", "--certificate", "interpolation", "--lag", "0"])
    assert res.exit_code == 0 and "lag l = 0" in res.output and "*>y0" in res.output


# --------------------------------------------------------------------------- lag chosen
# Independent values (another SDP tool, same family): heavy ball at kappa = 10 is 0.8602212
# with lag 1, 0.8459062 with lag 2 and 0.8458462 with lag 4; at kappa = 2, 0.3361077 with
# lag 1 and 0.3310540 with larger lags.
HB_LAG1 = {10.0: 0.8602212, 2.0: 0.3361077}
HB_TIGHT = {10.0: (0.8458462, 0.8459062), 2.0: (0.3310540, 0.3310540)}


@pytest.mark.parametrize("kappa", [10.0, 2.0])
def test_heavy_ball_default_lag_is_tight(kappa):
    spec = _spec("heavy-ball")
    res = analyze_spec(spec, kappa, family=TIGHT)
    lo, hi = HB_TIGHT[kappa]
    assert res.certified and lo - 2e-4 <= res.rho <= hi + 2e-4
    assert res.rho < HB_LAG1[kappa] - 3e-3  # clearly below the lag-1 rate
    assert res.lag >= 2 and res.certificate["lag"] == res.lag
    assert np.shape(res.certificate["P"]) == (spec.n + res.lag + 1,) * 2
    assert res.rho >= _quadratic_rate(bind(spec, kappa)) - 1e-6
    ex = TIGHT.exact_check(spec, kappa, res.rho, res.certificate)
    assert ex.verified == "exact", ex.reason


def test_explicit_lag_is_used_as_given():
    spec = _spec("heavy-ball")
    res = analyze_spec(spec, 10.0, family=Interpolation(1))
    assert res.lag == 1 and res.certificate["lag"] == 1
    assert abs(res.rho - HB_LAG1[10.0]) <= 2e-4
    text = (SPECS / "heavy-ball.yaml").read_text()
    s1 = spec_from_text(text + "certificate: {family: interpolation, lag: 1}\n", "t.yaml")
    assert analyze_spec(s1, 10.0).lag == 1
    s0 = spec_from_text(text + "certificate: interpolation\n", "t.yaml")
    assert analyze_spec(s0, 10.0).lag >= 2  # no lag in the spec: chosen


@pytest.mark.parametrize(("name", "kappa"), [
    ("nesterov", 10.0), ("nesterov-quadratic", 2.0), ("triple-momentum", 2.0),
    ("gradient", 10.0), ("heavy-ball", 25.0),
])
def test_default_lag_never_worse_than_n_minus_1(name, kappa):
    spec = _spec(name)
    auto = analyze_spec(spec, kappa, family=TIGHT)
    fixed = analyze_spec(spec, kappa, family=Interpolation(spec.n - 1))
    assert auto.certified == fixed.certified or auto.certified
    if fixed.certified:
        assert auto.rho <= fixed.rho + 1e-12 and auto.lag >= spec.n - 1
        assert auto.max_eig_M <= 0 and auto.min_eig_P >= 0


def test_cli_reports_the_chosen_lag_and_verify_proves_it(tmp_path):
    import csv
    import json

    res = _run(["analyze", SPECS / "heavy-ball.yaml", "--certificate", "interpolation",
                "--kappa", "10", "--out", tmp_path, "--quiet", "--json"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)["rows"][0]
    cert = row["certificate"]
    assert cert["lag"] >= 2 and abs(row["rho"] - 0.8459) <= 2e-4
    assert np.shape(cert["P"]) == (2 + cert["lag"] + 1,) * 2 and len(cert["p"]) == cert["lag"] + 1
    rows = list(csv.DictReader(open(tmp_path / "heavy-ball-analysis-interpolation.csv")))
    assert int(rows[0]["lag"]) == cert["lag"]
    (tmp_path / "hb.json").write_text(res.stdout)
    out = _run(["verify", tmp_path / "hb.json", "--out", tmp_path, "--json"])
    assert out.exit_code == 0, out.output
    checked = json.loads(out.stdout)["results"][0]
    assert checked["verified"] == "exact" and checked["simulation"]["ok"], checked
    res = _run(["analyze", SPECS / "heavy-ball.yaml", "--certificate", "interpolation",
                "--lag", "1", "--kappa", "10", "--out", tmp_path, "--quiet"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(tmp_path / "heavy-ball-analysis-interpolation-lag1.csv")))
    assert rows[0]["lag"] == "1" and abs(float(rows[0]["rho"]) - HB_LAG1[10.0]) <= 2e-4


def test_design_keeps_lag_n_minus_1_and_reports_it():
    from sosalgo.design_search import design

    spec = _spec("gradient-optimal")  # n = 1: lag 0; its best rate is (kappa-1)/(kappa+1)
    res = design(spec, 10.0, family=TIGHT, time_limit=60)
    assert res.lag == 0 and res.certificate["lag"] == 0 and res.to_dict()["lag"] == 0
    assert abs(res.rho_certified - 9 / 11) <= 1e-5
