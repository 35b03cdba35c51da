"""The random and adversarial gradient methods with momentum of the soundness suites
(``tests/test_soundness_*.py`` judged by ``tests/independent_momentum.py``): x+ = x - h
grad f(x + eta (x - x_prev)) + beta (x - x_prev); random h, beta, eta, near-divergent and
degenerate ones, tuned ones, kappa in [1.5, 1e4]; every parameter an exact dyadic
rational, so that the judge's fractions and sosalgo's exact arithmetic read the same
method. Each case is written as a sosalgo spec (:meth:`Case.spec`).

SOSALGO_MOMENTUM_CASES sets the number of random cases per feature (default 2; ``make
soundness`` runs MOMENTUM_CASES; the slow features (long PEP horizons, objective designs,
pareto fronts) run a quarter or a tenth of it). SOSALGO_MOMENTUM_REPORT, a file path:
every comparison is appended to it as one JSON line (the margins reported in docs/validation.md).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from .independent_momentum import Momentum, Start

CASES = max(1, int(os.environ.get("SOSALGO_MOMENTUM_CASES", "2")))
REPORT = os.environ.get("SOSALGO_MOMENTUM_REPORT")
DEN = 4096  # parameters are multiples of 1/DEN (exact in binary and in decimal)
REL = 1e-9  # relative room for the judge's own float rounding (its bounds are floats)
CYCLE_SECONDS = 1.0
F = Fraction
SPECS = Path(__file__).resolve().parents[1] / "specs"


def record(feature: str, case: str, **numbers: object) -> None:
    """One comparison, appended to SOSALGO_MOMENTUM_REPORT (when set) as a JSON line."""
    if REPORT:
        with open(REPORT, "a") as fh:
            fh.write(json.dumps({"feature": feature, "case": case, **numbers}) + "\n")


# ---------------------------------------------------------------- the cases


@dataclass(frozen=True)
class Case:
    name: str
    meth: Momentum

    @property
    def kappa(self) -> float:
        return float(self.meth.L / self.meth.m) if self.meth.m else math.nan

    def spec(self):
        """The method as a sosalgo spec (seed spec on F(1, kappa), or m: 0, L = 1)."""
        from sosalgo.spec import spec_from_dict

        return spec_from_dict(self.spec_dict())

    def spec_dict(self, start: Start | None = None) -> dict:
        """The spec's fields; ``start`` (c_prev, c_cur) adds ``initial_state: [x0 +
        c_prev*g0, x0 + c_cur*g0]``, each c written as (c L)/L."""
        mt = self.meth
        d: dict = {"name": self.name,
                   "parameters": {"h": {"value": f"({mt.hL})/L"},
                                  "beta": {"value": str(mt.beta)},
                                  "eta": {"value": str(mt.eta)}},
                   "matrices": {"A": [[0, 1], ["-beta", "1 + beta"]], "B": [[0], ["-h"]],
                                "C": [["-eta", "1 + eta"]], "E": [[0, 1]]}}
        if mt.m == 0:
            d |= {"m": 0, "L": 1, "functions": {"f": {"class": "smooth_strongly_convex"}}}
        else:
            d["kappa"] = [self.kappa]
        if start is not None:
            d["initial_state"] = [f"x0 + ({c * mt.L})*g0/L" for c in start]
        return d


def dyadic(x: float, den: int = DEN) -> Fraction:
    return F(round(x * den), den)


def boundary(beta: Fraction, eta: Fraction) -> Fraction:
    """h L at which the loop at q = L has the root -1: 2 (1 + beta) / (1 + 2 eta)."""
    return 2 * (1 + beta) / (1 + 2 * eta)


def tuned(kappa: float, which: int) -> tuple[Fraction, Fraction, Fraction]:
    """(beta, eta, h L) of Nesterov (0), heavy ball (1), triple momentum (2) at kappa."""
    s = math.sqrt(kappa)
    if which == 0:
        b = dyadic((s - 1) / (s + 1))
        return b, b, F(1)
    if which == 1:
        return dyadic(((s - 1) / (s + 1)) ** 2), F(0), dyadic(4 * kappa / (1 + s) ** 2)
    r = 1 - 1 / s  # triple momentum: rho = 1 - 1/sqrt(kappa)
    return dyadic(r * r / (2 - r)), dyadic(r * r / ((1 + r) * (2 - r))), dyadic(1 + r)


def make_case(seed: int, sublinear: bool) -> Case:
    """Random (kind seed % 5): free, near-divergent, degenerate, tuned, extreme kappa."""
    rng = np.random.default_rng(10_000 + seed + (50_000 if sublinear else 0))
    kappa = dyadic(float(np.exp(rng.uniform(math.log(1.5), math.log(1e4)))), 64)
    kind = seed % 5
    beta, eta = dyadic(rng.uniform(0, 1)), dyadic(rng.uniform(0, 1.5))
    hL = dyadic(rng.uniform(0.01, 1.0) * float(boundary(beta, eta)))
    if kind == 1:  # just inside the boundary at q = L, or beta near 1
        if rng.uniform() < 0.5:
            hL = boundary(beta, eta) * (1 - F(1, int(rng.choice([64, 1024]))))
        else:
            beta = 1 - F(1, int(rng.choice([32, 256])))
    elif kind == 2:  # gradient descent, heavy ball, Nesterov form, tiny step
        beta, eta = [(F(0), F(0)), (beta, F(0)), (beta, beta), (beta, eta)][seed // 5 % 4]
        hL = hL if seed // 5 % 4 != 3 else F(1, DEN)
    elif kind == 3:  # Nesterov, heavy ball, triple momentum tunings, rounded to dyadics
        beta, eta, hL = tuned(float(kappa) if not sublinear else 1e6, seed // 5 % 3)
    elif kind == 4:
        kappa = F(10_000) if seed // 5 % 2 == 0 else F(3, 2)
    m, L = (F(0), F(1)) if sublinear else (F(1), kappa)
    return Case(f"mom-{'sub' if sublinear else 'lin'}-{seed}", Momentum(hL, beta, eta, m, L))


ADVERSARIAL = {
    "gd-1-over-L": (F(1), F(0), F(0)),
    "gd-near-2-over-L": (F(2) - F(1, 1024), F(0), F(0)),
    "heavy-ball-k25": (F(25, 9), F(4, 9), F(0)),  # cycles at kappa 25 (Lessard et al.)
    "triple-momentum-k16": (F(7, 4), F(9, 20), F(9, 35)),  # rho = 1 - 1/4 on F(1, 16)
    "beta-0.999": (F(1, 2), F(999, 1000), F(1, 2)),
    "eta-large": (F(1, 8), F(1, 2), F(4)),
}


def adversarial(name: str, sublinear: bool = False) -> Case:
    kappa = {"heavy-ball-k25": F(25), "triple-momentum-k16": F(16)}.get(name, F(100))
    m, L = (F(0), F(1)) if sublinear else (F(1), kappa)
    return Case(name, Momentum(*ADVERSARIAL[name], m, L))


def case_of(key: int | str, sublinear: bool) -> Case:
    return make_case(key, sublinear) if isinstance(key, int) else adversarial(key, sublinear)


def same_method(case: Case, spec) -> None:
    """sosalgo reads the judge's method (matrices, m, L) from the case's spec."""
    from sosalgo.model import bind, bind_sublinear

    mt = case.meth
    alg = bind_sublinear(spec) if mt.m == 0 else bind(spec, case.kappa)
    A, B, C, E = mt.matrices()
    for ours, theirs in zip((A, B, C, E), (alg.A, alg.B, alg.C, alg.E), strict=True):
        np.testing.assert_allclose(np.asarray(theirs, dtype=float), ours, rtol=1e-13,
                                   atol=1e-15, err_msg=case.name)
    assert float(alg.m) == float(mt.m) and float(alg.L) == pytest.approx(float(mt.L))
