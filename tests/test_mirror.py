"""Bregman (mirror) steps: proven values against closed forms, runs of NoLips and the
Bregman proximal point on explicit kernels and functions (numpy, sharing nothing with the
PEP) never above the proven bound, a tampered certificate refused, bad input refused."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import sosalgo
from sosalgo.cli import cli

ROOT = Path(__file__).resolve().parents[1]
MIRROR = ROOT / "specs" / "mirror-descent.yaml"
BPP = ROOT / "specs" / "bregman-proximal-point.yaml"
NONCONVEX = ROOT / "bench" / "conformance" / "specs" / "no-lips-nonconvex.yaml"
MIN_PREV = "min D_h(x_{k-1}, x_k)"


def _proven(spec: Path, steps: int, measure: str | None = None, **sets: str) -> Fraction:
    from sosalgo.spec import spec_from_text
    from sosalgo.spec.overrides import apply_overrides

    text = apply_overrides(spec.read_text(), sets, str(spec))
    res = sosalgo.pep(spec_from_text(text, str(spec)), None, steps, measure)
    assert res.status == "solved"
    proven = Fraction(res.certificate["tau_proven"])
    assert abs(float(proven) - res.tau) <= 1e-7 * max(1.0, res.tau)
    return proven


@pytest.mark.parametrize("gamma,steps", [("1/2", 3), ("1", 2)])
def test_nolips_function_value_is_one_over_gamma_n(gamma, steps):
    """NoLips, F(x_N) - F* <= D_h(x*, x_0) / (gamma N) (Bauschke, Bolte, Teboulle 2017),
    attained (PEPit's values agree): proven exactly equal."""
    assert _proven(MIRROR, steps, gamma=gamma) == 1 / (Fraction(gamma) * steps)


def test_bregman_proximal_point_is_one_over_gamma_n():
    """Bregman proximal point: F(x_N) - F* <= D_h(x*, x_0) / (gamma N) (Chen, Teboulle)."""
    assert _proven(BPP, 4, gamma="2") == Fraction(1, 8)


def test_nolips_bregman_divergence_closed_form():
    """min_k D_h(x_{k-1}, x_k) <= 2 D_h(x*, x_0) / (N (N - 1)) at gamma = 1/L (Dragomir
    et al. 2021): the proven bound is at most that."""
    assert _proven(MIRROR, 4, MIN_PREV, gamma="1") <= Fraction(2, 4 * 3)


def test_nonconvex_nolips_closed_form():
    """Nonconvex NoLips: min_k D_h(x_k, x_{k-1}) <= gamma/(N (1 - L gamma)) (F(x_0) -
    F(x_N)) (Bolte, Sabach, Teboulle, Vaisbourd 2018): the proven bound is at most that."""
    assert _proven(NONCONVEX, 3) <= Fraction(1, 2) / (3 * Fraction(1, 2))


# --------------------------------------------------------------------------- soundness


def _entropy(x):
    from scipy.special import xlogy

    return float(np.sum(xlogy(x, x)))  # 0 log 0 = 0


def _entropy_bregman(a, b):
    return _entropy(a) - _entropy(b) - float((1 + np.log(b)) @ (a - b))


def _box_minimizer(f_grad, x0, L, iters=20000):
    """The minimizer of f over the box (0, 1]^d by many entropic NoLips steps (the method
    itself converges; only its limit is used)."""
    x = x0.copy()
    for _ in range(iters):
        x = np.minimum(1.0, x * np.exp(-f_grad(x) / L))
    return x


@pytest.mark.parametrize("seed", range(4))
def test_nolips_entropy_box_never_above_the_proof(seed):
    """h = sum x log x on the box (0, 1]^d, f = |Ax - b|^2 / (2 |A|^2): f is convex and
    1-smooth relative to h there (A'A <= |A|^2 I <= |A|^2 diag(1/x)); NoLips with the box
    constraint is x+ = min(1, x exp(-gamma grad f(x))). F(x_N) - F* and min D_h(x_{k-1},
    x_k) never exceed the proven bounds times D_h(x*, x_0)."""
    rng = np.random.default_rng(seed)
    d = 4
    A = rng.normal(size=(6, d))
    b = rng.normal(size=6) * 3
    nA = np.linalg.norm(A, 2) ** 2

    def f(x):
        return float(np.sum((A @ x - b) ** 2) / (2 * nA))

    def grad(x):
        return A.T @ (A @ x - b) / nA

    x0 = rng.uniform(0.05, 1.0, d)
    xs = _box_minimizer(grad, np.full(d, 0.5), 1.0)
    fs = f(xs)
    gamma, N = 0.5, 4
    tau_f = float(_proven(MIRROR, N, gamma="1/2"))
    tau_d = float(_proven(MIRROR, N, MIN_PREV, gamma="1/2"))
    xs_run = [x0]
    for _ in range(N):
        xs_run.append(np.minimum(1.0, xs_run[-1] * np.exp(-gamma * grad(xs_run[-1]))))
    D0 = _entropy_bregman(xs, x0)
    assert f(xs_run[-1]) - fs <= tau_f * D0 * (1 + 1e-6) + 1e-9
    mind = min(_entropy_bregman(xs_run[k - 1], xs_run[k]) for k in range(1, N + 1))
    assert mind <= tau_d * D0 * (1 + 1e-6) + 1e-12


def _quartic_grad(x):
    return x * (1 + x @ x)


def _quartic(x):
    r = x @ x
    return r / 2 + r * r / 4


def _quartic_mirror(z):
    """x with grad h(x) = x (1 + |x|^2) = z: x = z / (1 + r^2), r (1 + r^2) = |z|."""
    nz = float(np.linalg.norm(z))
    if nz == 0:
        return z * 0
    roots = np.roots([1, 0, 1, -nz])
    r = float(min(abs(v.real) for v in roots if abs(v.imag) < 1e-9))
    return z / (1 + r * r)


@pytest.mark.parametrize("seed", range(4))
def test_nolips_quartic_kernel_never_above_the_proof(seed):
    """h = |x|^2/2 + |x|^4/4 (Hessian >= I), f = |Ax - b|^2 / (2 |A|^2) (Hessian <= I):
    f convex and 1-smooth relative to h; unconstrained NoLips through the closed-form
    inverse of grad h; its minimizer solves A'(Ax - b) = 0."""
    rng = np.random.default_rng(10 + seed)
    d = 3
    A = rng.normal(size=(5, d))
    b = rng.normal(size=5) * 2
    nA = np.linalg.norm(A, 2) ** 2
    xs = np.linalg.lstsq(A, b, rcond=None)[0]

    def f(x):
        return float(np.sum((A @ x - b) ** 2) / (2 * nA))

    def bregman(a, c):
        return _quartic(a) - _quartic(c) - float(_quartic_grad(c) @ (a - c))

    gamma, N = 1.0, 3
    tau = float(_proven(MIRROR, N, gamma="1"))
    x = rng.normal(size=d) * 2
    D0 = bregman(xs, x)
    for _ in range(N):
        x = _quartic_mirror(_quartic_grad(x) - gamma * (A.T @ (A @ x - b) / nA))
    assert f(x) - f(xs) <= tau * D0 * (1 + 1e-6) + 1e-12


@pytest.mark.parametrize("seed", range(3))
def test_nonconvex_nolips_entropy_box_never_above_the_proof(seed):
    """f = -|Ax - b|^2 / (2 |A|^2) (nonconvex) with h the entropy on (0, 1]^d: h -+ f
    convex (Hessian of h >= I there), so f is 1-smooth adaptable; the box NoLips step.
    min_k D_h(x_k, x_{k-1}) <= tau (F(x_0) - F(x_N))."""
    rng = np.random.default_rng(20 + seed)
    d = 3
    A = rng.normal(size=(4, d))
    b = rng.normal(size=4)
    nA = np.linalg.norm(A, 2) ** 2

    def f(x):
        return -float(np.sum((A @ x - b) ** 2) / (2 * nA))

    gamma, N = 0.5, 3
    tau = float(_proven(NONCONVEX, N, gamma="1/2"))
    xs = [rng.uniform(0.05, 1.0, d)]
    for _ in range(N):
        g = -A.T @ (A @ xs[-1] - b) / nA
        xs.append(np.minimum(1.0, xs[-1] * np.exp(-gamma * g)))
    mind = min(_entropy_bregman(xs[k], xs[k - 1]) for k in range(1, N + 1))
    assert mind <= tau * (f(xs[0]) - f(xs[-1])) * (1 + 1e-6) + 1e-12


def test_tampered_certificate_is_refused():
    """The exact check of a vertex certificate fails when a multiplier is changed."""
    from sosalgo.spec import load_spec
    from sosalgo.worstcase import mirror as M

    pep, *_ = M._problem(load_spec(MIRROR), None, 3, None, None)
    ans = M.solve_linear(pep)
    ans["labels"] = [lab for lab, _, _ in pep.pairs]
    assert M.prove_linear(ans)[0]
    lam = ans["lam"].copy()
    k = int(np.argmax(lam))
    lam[k] = 0.0  # drop the largest multiplier: the remaining support cannot balance
    assert not M.prove_linear(ans | {"lam": lam})[0]


# --------------------------------------------------------------------------- bad input


def _cli(tmp_path, text: str, *args: str):
    p = tmp_path / "s.yaml"
    p.write_text(text)
    return CliRunner().invoke(cli, ["pep", str(p), "--steps", "2", *args, "--out",
                                    str(tmp_path / "o")])


def _without_mirror(text: str) -> str:
    return "\n".join(ln for ln in text.splitlines()
                     if not ln.startswith(("mirror:", "  kernel:", "  set:")))


@pytest.mark.parametrize("edit,field", [
    (_without_mirror, "functions.f.class"),  # a relative class needs a kernel
    (lambda t: t.replace("  E: [[1]]", "  D: [[-gamma]]\n  E: [[1]]"), "matrices.D[0][0]"),
    (lambda t: t.replace("kernel: {class: convex}", "kernel: {class: indicator}"),
     "mirror.kernel.class"),
    (lambda t: t.replace("B: [[-gamma]]", "B: [[gamma]]"), "matrices"),
    (lambda t: t.replace("kernel: {class: convex}", "kernel: {class: nope}"),
     "mirror.kernel.class"),
    (lambda t: t.replace("set: true", "set: 3"), "mirror.set"),
    (lambda t: t.replace("set: true", "sett: true"), "mirror"),
])
def test_bad_mirror_specs_exit_2(tmp_path, edit, field):
    r = _cli(tmp_path, edit(MIRROR.read_text()))
    assert r.exit_code == 2
    lines = [ln for ln in r.output.strip().splitlines() if ln]
    assert len(lines) == 1 and field in lines[0], r.output
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("spec,measure", [(MIRROR, "grad"), (NONCONVEX, "f")])
def test_bad_mirror_measures_exit_2(tmp_path, spec, measure):
    r = _cli(tmp_path, spec.read_text(), "--measure", measure)
    assert r.exit_code == 2 and "--measure" in r.output


def test_analyze_refuses_a_mirror_spec(tmp_path):
    r = CliRunner().invoke(cli, ["analyze", str(MIRROR), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "mirror" in r.output


def _verify(tmp_path, doc: dict) -> dict:
    import json

    p = tmp_path / "doc.json"
    p.write_text(json.dumps(doc))
    r = CliRunner().invoke(cli, ["verify", str(p), "--out", str(tmp_path / "v"), "--json"])
    assert r.exit_code == 3  # tau itself has no witness from below
    return {c["field"].rsplit(".json.", 1)[-1]: c["status"]
            for c in json.loads(r.stdout)["results"][0]["claims"]}


def test_verify_reproves_and_refuses_tampered(tmp_path):
    """`sosalgo verify` re-proves a mirror document's tau_proven from its exact
    multipliers; a changed multiplier or a smaller tau_proven is contradicted."""
    from .conftest import pep_json

    doc = pep_json(MIRROR, tmp_path / "o", 3)
    assert doc["certificate"]["tau_proven"] == "2/3"
    assert _verify(tmp_path, doc)["certificate.tau_proven"] == "backed"
    bad = json_copy(doc)
    proof = bad["certificate"]["proof"]
    first = next(iter(proof["multipliers_exact"]))
    proof["multipliers_exact"][first] = "1/7"
    assert _verify(tmp_path, bad)["certificate.tau_proven"] == "contradicted"
    low = json_copy(doc)
    low["tau"] = low["certificate"]["tau"] = 0.5
    low["certificate"]["tau_proven"] = low["certificate"]["proof"]["tau_proven"] = "1/2"
    assert _verify(tmp_path, low)["certificate.tau_proven"] == "contradicted"


def json_copy(doc: dict) -> dict:
    import json

    return json.loads(json.dumps(doc))


def test_a_step_too_long_is_unbounded():
    """NoLips at gamma = 3/L: the dual has no solution, the worst case is unbounded
    (PEPit's solve fails there too); nothing is claimed."""
    from sosalgo.spec import spec_from_text
    from sosalgo.spec.overrides import apply_overrides

    text = apply_overrides(MIRROR.read_text(), {"gamma": "3"}, str(MIRROR))
    res = sosalgo.pep(spec_from_text(text, str(MIRROR)), None, 3)
    assert res.status == "unbounded" and res.tau == float("inf")
    assert res.certificate is None
