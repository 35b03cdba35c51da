"""The witness search is bounded: a source (one float answer of the PEP) whose candidates
keep failing the exact check is left after a few of them, not run to its last mix, and
the search's own solves start only within its share of the run. Simulated at a short
horizon (Nesterov, N = 6) by making every exact fit fail, and by a share of zero."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import sosalgo
import sosalgo.worstcase.witness as wit

SPEC = Path(__file__).resolve().parent.parent / "specs" / "nesterov.yaml"
KAPPA, STEPS = 10, 6


def test_a_source_whose_candidates_all_fail_is_left_early(monkeypatch):
    fitted: list[tuple[float, float]] = []  # (slack, objective floor) of each exact fit
    available: list[tuple[float, int]] = []  # (slack, candidates) of each source
    real = wit._candidates

    def spy_fit(doc, ex):
        fitted.append((doc["slack"], doc["objective_floor"]))
        return False  # no candidate has exact values

    def counting(mt, st, G, slack, interior):
        available.append((slack, sum(1 for _ in real(mt, st, G, slack, interior))))
        return real(mt, st, G, slack, interior)

    monkeypatch.setattr(wit, "fit_values", spy_fit)
    monkeypatch.setattr(wit, "plausible", lambda *a, **k: True)  # all reach the exact fit
    monkeypatch.setattr(wit, "_candidates", counting)
    res = sosalgo.pep(str(SPEC), KAPPA, steps=STEPS, measure="dist")
    w = res.witness
    assert w is not None and "quadratic" not in w["search"]
    sdp = [key for key in fitted if key[1] > 0]  # the quadratics have objective floor 0
    assert len(available) >= 2  # several sources were tried, each left early
    for slack, total in available:
        tried = sum(1 for s, _ in sdp if s == slack)
        assert total > wit.SOURCE_FAILS and tried == wit.SOURCE_FAILS, (slack, total, tried)
    assert len(sdp) < sum(total for _, total in available)
    assert w["search"]["sources_left"] == len(available)
    assert w["search"]["no_exact_values"] == len(fitted)


def test_no_solve_of_the_search_starts_past_its_share(monkeypatch):
    """A share of zero: no rank reduction and no interior point is solved; the PEP's own
    answer and the quadratics still give a witness proven exactly, below tau."""
    trace_solves = []
    real = wit.solve_pep

    def spy_solve(data, *a, **k):
        trace_solves.append(k.get("objective"))
        return real(data, *a, **k)

    monkeypatch.setattr(wit, "solve_pep", spy_solve)
    monkeypatch.setattr(wit, "SHARE", 0.0)
    monkeypatch.setattr(wit, "FLOOR", 0.0)
    res = sosalgo.pep(str(SPEC), KAPPA, steps=STEPS, measure="dist")
    w = res.witness
    assert trace_solves == []
    assert w["search"]["out_of_time"] is True and w["check"]["verified"] is True
    assert float(Fraction(w["check"]["tau_lower"])) <= res.tau
