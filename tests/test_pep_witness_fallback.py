"""The witness when the SDP's worst case cannot be made exact (Nesterov past N = 50: the
late iterates sit below the solver's accuracy). Simulated at a short horizon by giving the
search no geometry of the SDP's answer: the last resort is a quadratic f = q/2 x^2 with q
strictly inside [m, L], whose lower bound is proven whatever the solver's accuracy; it is
judged against the worst case over the same quadratics computed here by plain
recursion, and it is never taken for a proof that tau is tight: the output says so, and
verify leaves tau unsupported from below. And a witness is a run of the method on its
functions: every call must be its function's gradient at that call's point."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import sosalgo
import sosalgo.worstcase.witness as wit
from sosalgo.runs.pep import pep_summary
from sosalgo.spec import load_spec
from sosalgo.worstcase.claims import passed, verify_pep_document, verify_witness_file

SPEC = Path(__file__).resolve().parent.parent / "specs" / "nesterov.yaml"
KAPPA, STEPS = 10, 6


def _nesterov_quadratic_worst(positions, kappa: float, steps: int) -> float:
    """max over q = m + t (L - m) of x_N^2 / x_0^2 for Nesterov's method (h = 1/L,
    beta = (sqrt(kappa) - 1)/(sqrt(kappa) + 1), x_{-1} = x_0) on f = q/2 x^2, L = 1."""
    m, L = 1 / kappa, 1.0
    beta = (np.sqrt(kappa) - 1) / (np.sqrt(kappa) + 1)
    best = 0.0
    for t in positions:
        q = m + t * (L - m)
        prev = x = 1.0
        for _ in range(steps):
            y = x + beta * (x - prev)
            prev, x = x, y - q / L * y
        best = max(best, x * x)
    return best


@pytest.fixture(scope="module")
def fallback():
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(wit, "_sources", lambda *a, **k: iter(()))  # no SDP geometry at all
        return sosalgo.pep(str(SPEC), KAPPA, steps=STEPS, measure="dist")


def test_quadratic_witness_is_proven_and_is_the_quadratic_worst_case(fallback):
    w = fallback.witness
    assert w["check"]["verified"] is True and w["search"]["quadratic"] is True
    assert w["dimension"] == 1
    lower = Fraction(w["check"]["tau_lower"])
    closed = _nesterov_quadratic_worst(wit.QUADRATIC_AT, KAPPA, STEPS)
    assert float(lower) == pytest.approx(closed, rel=1e-9)
    assert float(lower) < fallback.tau  # a real gap: this is not the worst case
    spec = load_spec(SPEC)
    chk = verify_witness_file(w, spec)
    assert chk["tau_lower"] == w["check"]["tau_lower"]


def test_a_quadratic_witness_does_not_make_tau_backed(fallback):
    """tau sits far above the quadratic's bound: verify leaves it unsupported from
    below (exit 3), as with no witness; the printed output says what the witness is."""
    doc = fallback.to_dict()
    spec = load_spec(SPEC)
    (chk,) = verify_pep_document(doc, spec)
    assert not passed(chk)
    assert "witness proves only" in chk["reason"]
    text = pep_summary(doc)
    assert "the witness is a quadratic, proving only tau_N >=" in text


def test_an_unverified_witness_is_said_plainly(monkeypatch):
    """No candidate passes the exact check: the row says witness_verified false, no
    tau_lower, and the printed output says that tau has no proven lower bound."""
    real = wit.check_witness

    def failing(doc, spec, mt=None):
        return real(doc, spec, mt) | {"verified": False, "tau_lower": None,
                                      "tau_lower_float": None,
                                      "detail": "1 interpolation inequalities not proven"}

    monkeypatch.setattr(wit, "check_witness", failing)
    res = sosalgo.pep(str(SPEC), KAPPA, steps=2, measure="dist")
    from sosalgo.runs.pep import pep_row

    row = pep_row(res)
    assert row["witness_verified"] is False and row["tau_lower"] is None
    text = pep_summary(res.to_dict())
    assert "no witness verified" in text and "no proven lower bound" in text
    assert "proving only" not in text


def test_a_call_that_is_not_the_functions_gradient_is_refused():
    """Gradient descent, h = 1/L, kappa 10, N = 3: tau_3 = (1 - 1/kappa)^6 exactly. A
    witness whose last call is scaled (the method run with a gradient its function does
    not have there) would 'prove' more than that; the check refuses it, and the honest
    witness proves at most the closed form."""
    import copy

    from sosalgo.worstcase.check import check_witness

    gspec = load_spec(SPEC.with_name("gradient.yaml"))
    res = sosalgo.pep(gspec, 10, steps=3, measure="dist")
    closed = Fraction(9, 10) ** 6
    honest = res.witness
    assert honest["check"]["verified"] and Fraction(honest["check"]["tau_lower"]) <= closed
    for k, factor in ((2, Fraction(9, 10)), (2, Fraction(1001, 1000)), (1, Fraction(11, 10))):
        bad = copy.deepcopy(honest)
        bad["calls"][k] = [[str(Fraction(v) * factor) for v in u] for u in bad["calls"][k]]
        chk = check_witness(bad, gspec)
        assert chk["verified"] is False and "not the gradient" in chk["detail"], chk
