"""Soundness of composite / proximal certificates against an independent judge.

Random composite methods (proximal gradient with momentum, projected gradient with
momentum, Douglas-Rachford with relaxation, proximal point, a coupled two-state method
with a proximal step) and adversarial ones are written as spec YAML and analyzed by
sosalgo. Whenever sosalgo certifies rho: rho >= the judge's lower bound on quadratics of
the classes (``tests/independent_composite.py``, no sosalgo code) - 1e-6, the exact
verification says "exact", and the tail decay of a nonquadratic trajectory (Huber, l1,
box) is at most rho^2 (with slack). The judge is first tested against closed forms.

SOSALGO_COMPOSITE_CASES sets the number of random cases (default 10; ``make soundness``
runs more).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cache

import numpy as np
import pytest

from .independent_composite import (
    Fn,
    Method,
    Separable,
    minimizer,
    quadratic_bound,
    simulate_decay,
)

pytestmark = pytest.mark.xdist_group("soundness-composite")

CASES = max(1, int(os.environ.get("SOSALGO_COMPOSITE_CASES", "10")))
SLACK = 1e-6  # a certified rho may sit this far below the judge's bound (eigenvalue rounding)
SIM_SLACK = 5e-3  # on sqrt(observed tail decay) vs rho: a limit, observed over finite steps
KINDS = ("pgm", "projm", "dr", "pp", "coupled")
ADVERSARIAL = ("pg-h-2/L", "pgm-beta-0.99", "vfista-k1000", "projm-k1000", "dr-t-1e-6",
               "dr-t-large", "pp-t-1e-6", "tm-prox-coupled", "coupled-fixed")


@dataclass(frozen=True)
class Case:
    """A generated method: its spec YAML, the judge's matrices and a test instance."""

    name: str
    kappa: float
    yaml: str
    method: Method
    instance: tuple[Separable, ...]


def _num(x: float) -> str:
    return repr(float(x))


def _yaml(name: str, kappa: float, functions: dict[str, str], params: dict[str, float],
          matrices: dict[str, str], oracles: str, tail: str) -> str:
    fun = "".join(f"  {k}: {{{v}}}\n" for k, v in functions.items())
    par = "".join(f"  {k}: {{value: {_num(v)}}}\n" for k, v in params.items())
    mat = "".join(f"  {k}: {v}\n" for k, v in matrices.items())
    return (f"name: {name}\nm: 1\nfunctions:\n{fun}parameters:\n{par}matrices:\n{mat}"
            f"oracles: {oracles}\n{tail}kappa: [{_num(kappa)}]\n")


def _fns(kappa: float, g: str, rng: np.random.Generator, d: int = 5) -> tuple[Separable, ...]:
    """f: Huber-type in F(1, kappa); g of the named kind (l1, l1+quadratic, box)."""
    a = rng.normal(scale=2.0, size=d)
    lam = float(rng.uniform(0.2, 1.0))
    f = Separable("huber", a, m=1.0, L=kappa, delta=lam / (2 * kappa))
    if g == "box":
        return f, Separable("box", a, lo=-1.0, hi=float(rng.uniform(0.2, 1.5)))
    mu = float(rng.uniform(0.2, 2.0)) if g == "strong" else 0.0
    return f, Separable("l1", rng.normal(size=d), lam=lam, mu=mu)


def momentum_case(name: str, kappa: float, h: float, beta: float, gamma: float, g: str,
                  measure: str, rng: np.random.Generator) -> Case:
    """x+ = prox_{h g}(y - h grad f(z)), y = x + beta (x - x_prev), z = x + gamma (...)."""
    A = np.array([[0, 1], [-beta, 1 + beta]])
    B = np.array([[0, 0], [-h, -h]])
    C = np.array([[-gamma, 1 + gamma], [-beta, 1 + beta]])
    fns = _fns(kappa, g, rng)
    mg = fns[1].mu
    gclass = {"box": "class: indicator", "l1": "class: convex",
              "strong": f"class: strongly_convex, m: {_num(mg)}"}[g]
    out = 1 if measure == "function" else np.array([[0.0, 1.0]])
    tail = (("output: y2\n" if measure == "function" else "") + f"measure: {measure}\n")
    mats = {"A": "[[0, 1], [-beta, 1 + beta]]", "B": "[[0, 0], [-h, -h]]",
            "C": "[[-gamma, 1 + gamma], [-beta, 1 + beta]]", "D": "[[0, 0], [-h, -h]]"}
    if measure != "function":
        mats["E"] = "[[0, 1]]"
    gfn = {"box": Fn("indicator"), "l1": Fn("convex"), "strong": Fn("strongly_convex", mg)}[g]
    method = Method(A, B, C, B.copy(), out, (0, 1),
                    (Fn("smooth_strongly_convex", 1.0, kappa), gfn), measure)
    text = _yaml(name, kappa, {"f": "class: smooth_strongly_convex", "g": gclass},
                 {"h": h, "beta": beta, "gamma": gamma}, mats, "[f, g]", tail)
    return Case(name, kappa, text, method, fns)


def dr_case(name: str, kappa: float, t: float, relax: float, rng: np.random.Generator) -> Case:
    """z+ = z + r (prox_{t g}(2 y1 - z) - y1), y1 = prox_{t f}(z); output y1, distance."""
    B = np.array([[-relax * t, -relax * t]])
    D = np.array([[-t, 0], [-2 * t, -t]])
    method = Method(np.eye(1), B, np.ones((2, 1)), D, 0, (0, 1),
                    (Fn("smooth_strongly_convex", 1.0, kappa), Fn("convex")))
    text = _yaml(name, kappa, {"f": "class: smooth_strongly_convex", "g": "class: convex"},
                 {"t": t, "r": relax},
                 {"A": "[[1]]", "B": "[[-r*t, -r*t]]", "C": "[[1], [1]]",
                  "D": "[[-t, 0], [-2*t, -t]]"}, "[f, g]", "output: y1\nmeasure: distance\n")
    return Case(name, kappa, text, method, _fns(kappa, "l1", rng))


def pp_case(name: str, kappa: float, t: float, rng: np.random.Generator) -> Case:
    """x+ = prox_{t g}(x), g 1-strongly convex (l1 + quadratic instance); distance."""
    method = Method(np.eye(1), np.array([[-t]]), np.eye(1), np.array([[-t]]), np.eye(1), (0,),
                    (Fn("strongly_convex", 1.0),))
    text = _yaml(name, kappa, {"g": "class: strongly_convex"}, {"t": t},
                 {"A": "[[1]]", "B": "[[-t]]", "C": "[[1]]", "D": "[[-t]]", "E": "[[1]]"},
                 "[g]", "measure: distance\n")
    g = Separable("l1", rng.normal(scale=2.0, size=5), lam=float(rng.uniform(0.2, 1)), mu=1.0)
    return Case(name, kappa, text, method, (g,))


def coupled_case(name: str, kappa: float, a: tuple[float, float], b: tuple[float, float],
                 c: float, e: float, h: float, rng: np.random.Generator) -> Case:
    """A generic two-state method with the composite fixed point: rows of A, C, E sum to 1,
    both calls share B's column, y2 = prox_{h g}(x - h u1)."""
    A = np.array([[a[0], 1 - a[0]], [a[1], 1 - a[1]]])
    B = np.array([[b[0] * h, b[0] * h], [b[1] * h, b[1] * h]])
    C = np.array([[c, 1 - c], [0.0, 1.0]])
    D = np.array([[0, 0], [-h, -h]])
    E = np.array([[e, 1 - e]])
    method = Method(A, B, C, D, E, (0, 1), (Fn("smooth_strongly_convex", 1.0, kappa),
                                           Fn("convex")))
    text = _yaml(name, kappa, {"f": "class: smooth_strongly_convex", "g": "class: convex"},
                 {"a1": a[0], "a2": a[1], "b1": b[0], "b2": b[1], "c": c, "e": e, "h": h},
                 {"A": "[[a1, 1 - a1], [a2, 1 - a2]]", "B": "[[b1*h, b1*h], [b2*h, b2*h]]",
                  "C": "[[c, 1 - c], [0, 1]]", "D": "[[0, 0], [-h, -h]]", "E": "[[e, 1 - e]]"},
                 "[f, g]", "measure: distance\n")
    return Case(name, kappa, text, method, _fns(kappa, "l1", rng))


def random_case(seed: int) -> Case:
    """Seeded random method of one of KINDS at kappa in {2, 10, 100}."""
    rng = np.random.default_rng(1000 + seed)
    kind = KINDS[seed % len(KINDS)]
    kappa = float(rng.choice([2.0, 10.0, 100.0]))
    name = f"rand-{seed}-{kind}"
    if kind in ("pgm", "projm"):
        h = float(rng.uniform(0.05, 1.95)) / kappa
        beta = float(rng.uniform(0, 0.9))
        gamma = beta if rng.random() < 0.5 else float(rng.uniform(0, beta))
        g = "box" if kind == "projm" else str(rng.choice(["l1", "strong"]))
        measure = str(rng.choice(["distance", "function"]))
        return momentum_case(name, kappa, h, beta, gamma, g, measure, rng)
    if kind == "dr":
        t = float(np.exp(rng.uniform(-2, 2))) / math.sqrt(kappa)
        return dr_case(name, kappa, t, float(rng.uniform(0.2, 1.8)), rng)
    if kind == "pp":
        return pp_case(name, kappa, float(np.exp(rng.uniform(-3, 3))) / kappa, rng)
    a = (float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.8, 0.2)))
    b = (float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-1.5, -0.5)))
    return coupled_case(name, kappa, a, b, float(rng.uniform(-1, 2)), float(rng.uniform(0, 1)),
                        float(rng.uniform(0.3, 1.2)) / kappa, rng)


def adversarial_case(key: str) -> Case:
    """The named hard cases: step near 2/L, momentum near 1, kappa 1000, t -> 0, coupling."""
    rng = np.random.default_rng(len(key))
    if key == "pg-h-2/L":
        return momentum_case("adv-pg-h2L", 10.0, 1.999 / 10, 0.0, 0.0, "l1", "distance", rng)
    if key == "pgm-beta-0.99":
        return momentum_case("adv-beta", 10.0, 0.1 / 10, 0.99, 0.99, "l1", "distance", rng)
    if key in ("vfista-k1000", "projm-k1000"):
        beta = (math.sqrt(1000) - 1) / (math.sqrt(1000) + 1)
        g, meas = ("l1", "function") if key == "vfista-k1000" else ("box", "distance")
        return momentum_case(f"adv-{key}", 1000.0, 1 / 1000, beta, beta, g, meas, rng)
    if key == "dr-t-1e-6":
        return dr_case("adv-dr-t0", 10.0, 1e-6, 1.0, rng)
    if key == "dr-t-large":
        return dr_case("adv-dr-tbig", 100.0, 1e3, 1.9, rng)
    if key == "pp-t-1e-6":
        return pp_case("adv-pp-t0", 10.0, 1e-6, rng)
    if key == "tm-prox-coupled":  # triple momentum's (h, beta, gamma) with a prox step
        rho = 1 - 1 / math.sqrt(10)
        h, beta, gamma = (1 + rho) / 10, rho**2 / (2 - rho), rho**2 / ((1 + rho) * (2 - rho))
        return momentum_case("adv-tm-prox", 10.0, h, beta, gamma, "strong", "distance", rng)
    return coupled_case("adv-coupled", 10.0, (0.3, -0.2), (0.2, -1.0), 1.5, 0.5, 0.9 / 10, rng)


def make_case(key: int | str) -> Case:
    return random_case(key) if isinstance(key, int) else adversarial_case(key)


@cache
def judged(key: int | str) -> tuple[Case, float, object]:
    """The case, the judge's quadratic lower bound and sosalgo's analysis (once each)."""
    import sosalgo

    case = make_case(key)
    spec = sosalgo.spec_from_text(case.yaml)
    return case, quadratic_bound(case.method), sosalgo.analyze(spec, kappa=case.kappa)


# ---------------------------------------------------------------- the judge itself


def _pg(h: float, m: float, L: float, g: Fn) -> Method:
    return Method(np.eye(1), np.array([[-h, -h]]), np.ones((2, 1)),
                  np.array([[0, 0], [-h, -h]]), np.eye(1), (0, 1),
                  (Fn("smooth_strongly_convex", m, L), g))


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
@pytest.mark.parametrize("g", [Fn("convex"), Fn("indicator"), Fn("strongly_convex", 0.5)])
def test_judge_proximal_gradient_is_thg(kappa, g):
    """Prox-grad on F(m, L) + g: max(|1 - hm|, |1 - hL|) (THG 2018, tight with g = 0),
    divided by 1 + h mu for a mu-strongly convex g (the gradient step is that Lipschitz,
    the prox 1/(1 + h mu); g = mu|x|^2/2 attains the product)."""
    m = 0.7
    for hL in (0.3, 1.0, 1.5, 1.9):
        h = hL / (kappa * m)
        ref = max(abs(1 - h * m), abs(1 - h * kappa * m)) / (1 + h * g.m)
        assert quadratic_bound(_pg(h, m, kappa * m, g)) == pytest.approx(ref, abs=1e-9)


@pytest.mark.parametrize("m", [0.5, 2.0])
@pytest.mark.parametrize("t", [1e-3, 0.1, 1.0, 10.0])
def test_judge_proximal_point_is_one_over_one_plus_tm(t, m):
    method = Method(np.eye(1), np.array([[-t]]), np.eye(1), np.array([[-t]]), np.eye(1),
                    (0,), (Fn("strongly_convex", m),))
    assert quadratic_bound(method) == pytest.approx(1 / (1 + t * m), rel=1e-12)


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
def test_judge_nesterov_on_quadratics(kappa):
    """V-FISTA, function measure at the prox point: 1 - 1/sqrt(kappa) on quadratics."""
    beta = (math.sqrt(kappa) - 1) / (math.sqrt(kappa) + 1)
    case = momentum_case("n", kappa, 1 / kappa, beta, beta, "l1", "function",
                         np.random.default_rng(0))
    assert quadratic_bound(case.method) == pytest.approx(1 - 1 / math.sqrt(kappa), abs=1e-7)


@pytest.mark.parametrize("kappa", [2.0, 10.0, 100.0])
@pytest.mark.parametrize("relax", [0.5, 1.0, 1.7])
def test_judge_douglas_rachford_between_closed_forms(kappa, relax):
    """Below: g = 0 gives |1 - r + r/(1 + tq)| over q in [m, L]. Above: the reflected
    resolvent of t f contracts by c = max(|1 - tq|/(1 + tq)), so z contracts by
    |1 - r/2| + r c/2 and y1 = prox_{t f}(z) too (Giselsson, Boyd 2017)."""
    for tL in (0.1, 1.0, math.sqrt(kappa), 10.0):
        t = tL / kappa
        q = np.linspace(1.0, kappa, 2001)
        low = np.max(np.abs(1 - relax + relax / (1 + t * q)))
        c = np.max(np.abs(1 - t * q) / (1 + t * q))
        up = abs(1 - relax / 2) + relax * c / 2
        bound = quadratic_bound(dr_case("d", kappa, t, relax, np.random.default_rng(0)).method)
        assert low - 1e-9 <= bound <= up + 1e-9


def test_judge_minimizer_is_optimal():
    """0 in the subdifferential of the sum at the judge's minimizer, coordinate by coordinate."""
    rng = np.random.default_rng(3)
    for g in ("l1", "strong", "box"):
        f, gg = _fns(10.0, g, rng)
        x = minimizer([f, gg])
        r = f.grad(x) + (gg.mu * (x - gg.a) if gg.kind == "l1" else 0.0)
        if gg.kind == "l1":
            free = np.abs(x) > 1e-12
            assert np.allclose(r[free] + gg.lam * np.sign(x[free]), 0, atol=1e-9)
            assert np.all(np.abs(r[~free]) <= gg.lam + 1e-9)
        else:
            inside = (x > gg.lo + 1e-12) & (x < gg.hi - 1e-12)
            assert np.allclose(r[inside], 0, atol=1e-9)
            assert np.all(r[x >= gg.hi - 1e-12] <= 1e-9) and np.all(r[x <= gg.lo + 1e-12] >= -1e-9)


@pytest.mark.parametrize("measure", ["distance", "function"])
@pytest.mark.parametrize("hL", [0.5, 1.0, 1.5])
def test_judge_tail_decay_is_the_local_rate(hL, measure):
    """Huber f with x* in its linear region (curvature m) + l1: prox-grad's tail decays by
    (1 - hm)^2 per step, distance or function gap at the prox point (the l1-zero
    coordinates are identified, F is quadratic along the others)."""
    kappa = 10.0
    case = momentum_case("s", kappa, hL / kappa, 0.0, 0.0, "l1", measure,
                         np.random.default_rng(5))
    decay = simulate_decay(case.method, list(case.instance))
    assert decay == pytest.approx((1 - hL / kappa) ** 2, abs=1e-4)


# ---------------------------------------------------------------- sosalgo against it


def _judge(key: int | str) -> None:
    import sosalgo

    case, low, res = judged(key)
    alg = sosalgo.bind(sosalgo.spec_from_text(case.yaml), case.kappa)
    for ours, theirs in ((case.method.A, alg.A), (case.method.B, alg.B),
                         (case.method.C, alg.C), (case.method.D, alg.D)):
        np.testing.assert_allclose(np.asarray(theirs, dtype=float), ours, rtol=1e-12,
                                   atol=1e-15, err_msg=case.yaml)
    if not res.certified:
        return
    rho = res.rho
    assert rho >= low - SLACK, (
        f"certified rho {rho!r} below the judge's quadratic lower bound {low!r}\n{case.yaml}")
    check = sosalgo.verify(sosalgo.spec_from_text(case.yaml), res, simulate=False)
    assert check is not None and check["verified"] == "exact", f"{check}\n{case.yaml}"
    decay = simulate_decay(case.method, list(case.instance), steps=3000)
    if decay is not None:
        assert math.sqrt(decay) <= rho + SIM_SLACK, (
            f"observed tail decay {decay!r} above rho^2 = {rho**2!r}\n{case.yaml}")


@pytest.mark.parametrize("seed", range(CASES))
def test_random_composite_method(seed):
    _judge(seed)


@pytest.mark.parametrize("key", ADVERSARIAL)
def test_adversarial_composite_method(key):
    _judge(key)


def test_the_random_cases_are_not_vacuous():
    """Most random cases are certified, so the comparisons above are made."""
    certified = [judged(s)[2].certified for s in range(min(CASES, 20))]
    assert sum(certified) >= len(certified) // 2, certified
