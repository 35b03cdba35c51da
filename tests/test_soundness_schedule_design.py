"""Soundness of the N-step design's box-wide lower bound (sosalgo.design_search.steps_bound).

Every proven bound of a box must be at most the worst case at every θ of the box. The
worst case is computed here independently: a small cvxpy PEP on the Gram matrix of
(x_0 - x*, g_0, ..., g_N), written from the interpolation conditions of L-smooth
(strongly) convex functions (Taylor, Hendrickx, Glineur 2017), and, for gradient descent
with a constant step h in (0, 2) on L-smooth convex f, the closed form
L max(1/(2(2Nh + 1)), (1 - h)^(2N) / 2) (Drori-Teboulle; Teboulle-Vaisbourd). Boxes are
random, tiny, touching h = 0 and touching h = 2 (where the method stops converging).
"""

from __future__ import annotations

import json
import math
import random
import warnings
from fractions import Fraction

import numpy as np
import pytest

from sosalgo.design_search.steps_bound import (
    LADDER,
    TIGHT,
    BoxSolver,
    huber_bound,
    prove_box,
    quadratic_bound,
)
from sosalgo.design_search.steps_model import parametric_pep
from sosalgo.spec import load_spec
from tests.conftest import spec_path


def independent_pep(A, B, C, E, steps: int, m: float, L: float) -> float:
    """max f(x_N) - f* over F(m, L) with |x_0 - x*| <= 1 for xi+ = A xi + B g(C xi),
    x = E xi, xi_0 = 1 x_0 (numeric matrices), by cvxpy on the Gram matrix."""
    import cvxpy as cp

    A, B, C, E = (np.atleast_2d(np.asarray(M, float)) for M in (A, B, C, E))
    n, d = A.shape[0], steps + 2
    xi = np.zeros((n, d))
    xi[:, 0] = 1.0
    pts = []  # (x row, g row) of y_0..y_{N-1}, x_N, x*
    for k in range(steps):
        g = np.eye(d)[1 + k]
        pts.append(((C @ xi)[0], g))
        xi = A @ xi + np.outer(B[:, 0], g)
    pts.append(((E @ xi)[0], np.eye(d)[steps + 1]))
    pts.append((np.zeros(d), np.zeros(d)))
    G = cp.Variable((d, d), PSD=True)
    F = cp.Variable(len(pts))
    cons = [F[-1] == 0, G[0, 0] <= 1]
    for i, (xa, ga) in enumerate(pts):
        for j, (xb, gb) in enumerate(pts):
            if i == j:
                continue
            dx, dg = xa - xb, ga - gb
            # f_i >= f_j + <g_j, x_i - x_j> + (|dg|^2/L + m|dx|^2 - 2 m/L <dg, dx>)/(2(1-m/L))
            quad = (np.outer(gb, dx) + (np.outer(dg, dg) / L + m * np.outer(dx, dx)
                                        - 2 * m / L * np.outer(dg, dx)) / (2 * (1 - m / L)))
            quad = (quad + quad.T) / 2
            cons.append(F[i] >= F[j] + cp.trace(quad @ G))
    prob = cp.Problem(cp.Maximize(F[steps]), cons)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "may be inaccurate": compared with a margin
        prob.solve(solver="CLARABEL")
    return float(prob.value)


def gd_closed_form(h: float, steps: int) -> float:
    return max(1 / (2 * (2 * steps * h + 1)), (1 - h) ** (2 * steps) / 2)


@pytest.fixture(scope="module")
def gd_models():
    spec = load_spec(str(spec_path("gradient-convex")))
    return {n: parametric_pep(spec, None, n, ["h"]) for n in (1, 2, 3)}


def _boxes(rng: random.Random) -> list[tuple[Fraction, Fraction]]:
    out = []
    for _ in range(4):  # random sub-boxes of [0, 2]
        a, b = sorted(Fraction(rng.randint(0, 2000), 1000) for _ in range(2))
        out.append((a, b))
    c = Fraction(rng.randint(1, 1999), 1000)
    out += [(c, c + Fraction(1, 10 ** 9)),  # tiny
            (Fraction(0), Fraction(1, 50)), (Fraction(0), Fraction(0)),  # touching 0
            (Fraction(199, 100), Fraction(2)), (Fraction(2), Fraction(2))]  # the edge
    return out


@pytest.mark.parametrize("steps", [1, 2, 3])
def test_gd_box_bounds_below_worst_case(gd_models, steps):
    pp = gd_models[steps]
    solver = BoxSolver(pp)
    rng = random.Random(steps)
    for lo, hi in _boxes(rng):
        b = prove_box(pp, solver, (lo,), (hi,))
        hs = {float(lo), float(hi)} | {float(lo) + rng.random() * float(hi - lo)
                                         for _ in range(2)}
        for h in hs:
            indep = independent_pep([[1]], [[-h]], [[1]], [[1]], steps, 0.0, 1.0)
            assert float(b.bound) <= indep * (1 + 1e-6) + 1e-9, (lo, hi, h, b)
            if 0 < h < 2:
                assert float(b.bound) <= gd_closed_form(h, steps) * (1 + 1e-9), (lo, hi, h)


def test_gd_bounds_are_tight_on_small_boxes(gd_models):
    """A bound that cannot fail the test above by being 0 is no test: on small boxes the
    proven bound is close to the closed form at the box's worst end."""
    pp = gd_models[2]
    solver = BoxSolver(pp)
    for c in (Fraction(1, 2), Fraction(1), Fraction(3, 2), Fraction(19, 10)):
        lo, hi = c - Fraction(1, 10 ** 4), c + Fraction(1, 10 ** 4)
        b = prove_box(pp, solver, (lo,), (hi,))
        low = min(gd_closed_form(float(lo), 2), gd_closed_form(float(hi), 2))
        assert float(b.bound) >= low * (1 - 2e-3), (c, b)


def test_witness_bounds_match_their_closed_forms(gd_models):
    """On a point h, the Huber witness gives exactly 1/(2(2Nh+1)) (its slope
    1/(2Nh+1)) and the quadratic one at q = L at least (1-h)^(2N)/2."""
    for steps, pp in gd_models.items():
        for h in (Fraction(1, 2), Fraction(1), Fraction(7, 4)):
            hub = huber_bound(pp, (h,), (h,))
            assert hub == 1 / (2 * (2 * steps * h + 1))
            quad = quadratic_bound(pp, (h,), (h,), [Fraction(1)])
            assert quad == (1 - h) ** (2 * steps) / 2


def independent_schedule_pep(hs: list[float]) -> float:
    """Gradient descent with steps h_0..h_{N-1} (a per-step A, B): the independent PEP
    step by step (the same Gram formulation, one step's matrices at a time)."""
    import cvxpy as cp

    steps, d = len(hs), len(hs) + 2
    x = np.eye(d)[0]
    pts = []
    for k, h in enumerate(hs):
        g = np.eye(d)[1 + k]
        pts.append((x.copy(), g))
        x = x - h * g
    pts += [(x, np.eye(d)[steps + 1]), (np.zeros(d), np.zeros(d))]
    G = cp.Variable((d, d), PSD=True)
    F = cp.Variable(len(pts))
    cons = [F[-1] == 0, G[0, 0] <= 1]
    for i, (xa, ga) in enumerate(pts):
        for j, (xb, gb) in enumerate(pts):
            if i != j:
                quad = np.outer(gb, xa - xb) + np.outer(ga - gb, ga - gb) / 2
                cons.append(F[i] >= F[j] + cp.trace((quad + quad.T) / 2 @ G))
    prob = cp.Problem(cp.Maximize(F[steps]), cons)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prob.solve(solver="CLARABEL")
    return float(prob.value)


def test_per_step_schedule_boxes():
    """Per-step steps (h_0, h_1) free in [0, 3]^2: random boxes, boxes touching h = 0
    and h = 3, a point box; the bound stays below the worst case at random θ inside,
    and the point box's bound is close to it (so the comparison can fail)."""
    import sympy as sp

    from sosalgo.spec import read_spec_text
    from sosalgo.worstcase.evaluate import worst_case_evaluator

    spec = load_spec(str(spec_path("gradient-convex")))
    hs = [sp.Symbol("h_0"), sp.Symbol("h_1")]

    def mats(k):
        return {"A": sp.Matrix([[1]]), "B": sp.Matrix([[-hs[k]]]), "C": sp.Matrix([[1]]),
                "E": sp.Matrix([[1]])}

    pp = parametric_pep(spec, None, 2, ["h_0", "h_1"], mats)
    solver = BoxSolver(pp)
    rng = random.Random(11)
    boxes = [((Fraction(0), Fraction(14, 10)), (Fraction(1, 10), Fraction(15, 10))),
             ((Fraction(29, 10), Fraction(1)), (Fraction(3), Fraction(12, 10))),
             ((Fraction(7, 5), Fraction(15, 8)), (Fraction(7, 5), Fraction(15, 8)))]
    for _ in range(2):
        a = [Fraction(rng.randint(0, 280), 100) for _ in range(2)]
        boxes.append((tuple(a), tuple(x + Fraction(rng.randint(1, 20), 100) for x in a)))
    for lo, hi in boxes:
        bound = float(prove_box(pp, solver, lo, hi).bound)
        for _ in range(2):
            h = [float(a) + rng.random() * float(b - a) for a, b in zip(lo, hi, strict=True)]
            assert bound <= independent_schedule_pep(h) * (1 + 1e-6) + 1e-9, (lo, hi, h)
    point = independent_schedule_pep([1.4, 1.875])
    assert bound >= 0 and float(prove_box(pp, solver, *boxes[2]).bound) >= point * (1 - 1e-4)
    path = str(spec_path("gradient-schedule"))  # the same class, per-step h (pep's proof)
    _, proven_at = worst_case_evaluator(load_spec(path), read_spec_text(path), None, 2)
    proven, _ = proven_at({"h": ["1.4", "1.875"]})
    assert proven is not None and point * (1 - 1e-6) <= float(proven) <= point * (1 + 1e-5)


def test_strongly_convex_two_parameter_boxes():
    """Nesterov's method (h, beta) at kappa 10: random sub-boxes, random θ inside."""
    spec = load_spec(str(spec_path("nesterov")))
    pp = parametric_pep(spec, 10.0, 2, ["h", "beta"])
    solver = BoxSolver(pp)
    rng = random.Random(7)
    m, L = 1.0, 10.0
    for _ in range(3):
        h0 = Fraction(rng.randint(1, 19), 100)
        b0 = Fraction(rng.randint(0, 90), 100)
        lo, hi = (h0, b0), (h0 + Fraction(1, 100), b0 + Fraction(1, 10))
        bound = prove_box(pp, solver, lo, hi).bound
        for _ in range(2):
            h = float(lo[0]) + rng.random() * float(hi[0] - lo[0])
            beta = float(lo[1]) + rng.random() * float(hi[1] - lo[1])
            A = [[0, 1], [-beta, 1 + beta]]
            indep = independent_pep(A, [[0], [-h]], [[-beta, 1 + beta]], [[0, 1]], 2, m, L)
            assert float(bound) <= indep * (1 + 1e-6) + 1e-9, (lo, hi, h, beta)


def test_design_reaches_the_optimal_constant_step():
    """N = 1: the best constant step is h = 3/2 with worst case 1/8 (the closed form's
    two branches meet), which is also Drori's floor L/(2 theta_1^2) = 1/8. Its progress
    phases leave N to the task's label (a phase repeating it read "N 1: searching N = 1")."""
    from sosalgo.design_search.steps import design_steps, exact_box
    from sosalgo.kernel.phases import set_sink
    from sosalgo.spec import read_spec_text
    from sosalgo.worstcase.evaluate import worst_case_evaluator

    path = str(spec_path("gradient-convex"))
    spec, text = load_spec(path), read_spec_text(path)
    phases: list[tuple[str | None, str]] = []
    previous = set_sink(lambda task, name, detail: phases.append((name, detail)))
    try:
        res = design_steps(spec, text, None, 1, [("h", None)], exact_box(spec, None, ["h"]),
                           worst_case_evaluator(spec, text, None, 1), time_limit=60)
    finally:
        set_sink(previous)
    assert ("searching", "") in phases and not any("N =" in d for _, d in phases)
    d = res.to_dict()
    assert d["lower_bound"] <= 0.125 <= d["tau_certified"]
    assert d["gap"] <= 1e-6
    assert abs(d["schedule"]["h"] - 1.5) < 1e-3
    assert d["floor"] == pytest.approx(0.125, rel=1e-12)


def test_ogm_theta_and_floor():
    from sosalgo.design_search.steps import ogm_theta

    th = [1.0]
    for _ in range(3):
        th.append((1 + math.sqrt(1 + 4 * th[-1] ** 2)) / 2)
    last = (1 + math.sqrt(1 + 8 * th[3] ** 2)) / 2
    assert ogm_theta(4) == pytest.approx(last, rel=1e-15)
    assert ogm_theta(1) == 2.0


def test_cli_design_steps_and_verify(tmp_path):
    """The user's path: design --steps --json, the contract fields, verify (exit 0), a
    lower bound raised past the truth (exit 3), bad --steps (exit 2, one line)."""
    from click.testing import CliRunner

    from sosalgo.cli import cli

    runner = CliRunner()
    out = tmp_path / "o"
    res = runner.invoke(cli, ["design", str(spec_path("gradient-convex")), "--steps", "1",
                              "--time-limit", "60", "--out", str(out), "--json",
                              "--quiet", "--workers", "1"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    for key in ("schedule", "tau_certified", "lower_bound", "gap", "floor"):
        assert key in doc
    assert (out / "gradient-convex-design-steps.csv").exists()
    again = runner.invoke(cli, ["design", str(spec_path("gradient-convex")), "--steps", "1",
                                "--time-limit", "60", "--out", str(out), "--json",
                                "--quiet", "--workers", "1"])
    assert json.loads(again.stdout)["seconds"] == doc["seconds"]  # resumed, not re-run
    good = tmp_path / "good.json"
    good.write_text(json.dumps(doc))
    assert runner.invoke(cli, ["verify", str(good)]).exit_code == 0
    doc["lower_bound"] = 0.126  # above the true minimum 1/8
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    assert runner.invoke(cli, ["verify", str(bad)]).exit_code == 3
    res = runner.invoke(cli, ["design", str(spec_path("gradient-convex")), "--steps", "0",
                              "--out", str(out)])
    assert res.exit_code == 2 and "--steps" in res.output and "Traceback" not in res.output


@pytest.mark.deep
@pytest.mark.parametrize("steps", [2, 3, 4])
def test_gd_constant_step_gap_target(steps):
    """design gradient-convex --steps N: proven relative gap <= 1e-3 for N <= 4, and the
    designed worst case within 1e-3 of the closed form's minimum over h."""
    from scipy.optimize import minimize_scalar

    from sosalgo.design_search.steps import design_steps, exact_box
    from sosalgo.spec import read_spec_text
    from sosalgo.worstcase.evaluate import worst_case_evaluator

    path = str(spec_path("gradient-convex"))
    spec, text = load_spec(path), read_spec_text(path)
    res = design_steps(spec, text, None, steps, [("h", None)], exact_box(spec, None, ["h"]),
                       worst_case_evaluator(spec, text, None, steps), time_limit=120)
    d = res.to_dict()
    best = minimize_scalar(lambda h: gd_closed_form(h, steps), bounds=(1, 2),
                           method="bounded", options={"xatol": 1e-10}).fun
    assert d["lower_bound"] <= best * (1 + 1e-7)
    assert d["gap_relative"] <= 1e-3
    assert d["tau_certified"] <= best * (1 + 1e-3)


def _design_rows(tmp_path, spec: str, steps: str, limit: float) -> list[dict]:
    from sosalgo.runs.steps_design import steps_design_run

    doc = steps_design_run(str(spec_path(spec)), None, steps, tmp_path, time_limit=limit,
                           workers=1, progress=False, plot=False)
    return doc["rows"]


def test_momentum_schedule_one_step_reaches_the_floor(tmp_path):
    """momentum-schedule, N = 1: (beta_0, gamma_0) free per step; the design reaches
    L/(2 theta_1^2) = 1/8 (OGM, Drori's floor) within 1e-5, never below it, and its
    lower bound stays below it."""
    (row,) = _design_rows(tmp_path, "momentum-schedule", "1", 12)
    assert len(row["schedule"]["beta"]) == 1 and len(row["schedule"]["gamma"]) == 1
    assert 0.125 <= row["tau_certified"] <= 0.125 * (1 + 1e-5)
    assert row["lower_bound"] is not None and row["lower_bound"] <= 0.125
    assert row["floor"] == pytest.approx(0.125, rel=1e-12)


@pytest.mark.deep
@pytest.mark.parametrize("steps", [2, 3, 4])
def test_momentum_schedule_rediscovers_ogm(tmp_path, steps):
    from sosalgo.design_search.steps import ogm_theta

    (row,) = _design_rows(tmp_path, "momentum-schedule", str(steps), 180)
    ogm = 1 / (2 * ogm_theta(steps) ** 2)
    assert ogm * (1 - 1e-9) <= row["tau_certified"] <= ogm * (1 + 1e-5)
    assert row["lower_bound"] <= ogm


@pytest.mark.deep
@pytest.mark.parametrize("steps", [2, 3])
def test_gradient_schedule_gap(tmp_path, steps):
    """gradient-schedule: proven relative gap <= 1e-3 (N = 2, 3), the schedule's worst
    case checked by the independent PEP."""
    (row,) = _design_rows(tmp_path, "gradient-schedule", str(steps), 600)
    indep = independent_schedule_pep(row["schedule"]["h"])
    assert indep * (1 - 1e-6) <= row["tau_certified"] <= indep * (1 + 1e-5)
    assert row["gap_relative"] <= 1e-3


@pytest.mark.deep
def test_gradient_schedule_four_steps_gap_on_two_workers(tmp_path):
    """gradient-schedule, N = 4, --workers 2 (the bound's boxes on both cores): proven
    relative gap <= 1e-3 within its 600 s limit, the schedule's worst case checked by the
    independent PEP, and the lower bound at most the worst case of the best known schedule
    with its third step clipped to the box's 3/L (OBS-F's is 3.005), by the same PEP."""
    from sosalgo.design_search.steps import obs_f
    from sosalgo.runs.steps_design import steps_design_run

    doc = steps_design_run(str(spec_path("gradient-schedule")), None, "4", tmp_path,
                           time_limit=600, workers=2, progress=False, plot=False)
    (row,) = doc["rows"]
    indep = independent_schedule_pep(row["schedule"]["h"])
    assert indep * (1 - 1e-6) <= row["tau_certified"] <= indep * (1 + 1e-5)
    assert row["gap_relative"] <= 1e-3
    clipped = [min(h, 3.0) for h in obs_f(4)[0]]
    assert row["lower_bound"] <= independent_schedule_pep(clipped) * (1 + 1e-6)


def _closed_form_minimum(steps: int) -> float:
    from scipy.optimize import minimize_scalar

    return minimize_scalar(lambda h: gd_closed_form(h, steps), bounds=(1, 2),
                           method="bounded", options={"xatol": 1e-10}).fun


def test_design_steps_with_workers_and_dask(tmp_path):
    """design gradient-convex --steps 1..2 with --workers 2, then on a local Dask
    scheduler (when distributed is installed): each row brackets the closed form's minimum
    over h (lower_bound <= min <= tau_certified, within the gap), and the two runs agree."""
    from click.testing import CliRunner

    from sosalgo.cli import cli
    from sosalgo.runs.steps_design import steps_design_run

    res = CliRunner().invoke(cli, ["design", str(spec_path("gradient-convex")), "--steps",
                                   "1..2", "--time-limit", "60", "--workers", "2",
                                   "--out", str(tmp_path / "w"), "--json", "--quiet"])
    assert res.exit_code == 0, res.output
    local = json.loads(res.stdout)["rows"]
    for row in local:
        best = _closed_form_minimum(row["steps"])
        assert row["lower_bound"] <= best * (1 + 1e-9) <= row["tau_certified"] * (1 + 2e-9)
        assert row["gap_relative"] <= 1e-3
    distributed = pytest.importorskip("distributed")
    import gc

    gc.collect()  # a Client left by an earlier test must not close inside this loop's start
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        doc = steps_design_run(str(spec_path("gradient-convex")), None, "1..2",
                               tmp_path / "d", time_limit=60, progress=False, plot=False,
                               scheduler=cluster.scheduler_address)
    dask_rows = doc["rows"]
    assert [r["steps"] for r in dask_rows] == [r["steps"] for r in local] == [1, 2]
    for a, b in zip(local, dask_rows, strict=True):
        assert b["tau_certified"] == pytest.approx(a["tau_certified"], rel=1e-6)
        assert b["lower_bound"] <= a["tau_certified"] and a["lower_bound"] <= b["tau_certified"]


def test_schedule_outside_the_parametric_model_is_proven_by_pep(tmp_path):
    """A per-step step size times a sequence (c_k = 1 for every k) is outside the
    parametric model (not polynomial in the free values): the design still searches the
    schedule on sosalgo pep's values and proves it with pep's certificate, without a
    box-wide bound. N = 1: the best step's worst case is the closed form's 1/8."""
    from sosalgo.runs.steps_design import steps_design_run

    text = spec_path("gradient-schedule").read_text()
    text = text.replace("parameters:", "sequences:\n  c: {first: 1, next: c}\nparameters:")
    text = text.replace("B: [[-h]]", "B: [[-h*c]]")
    path = tmp_path / "gs-seq.yaml"
    path.write_text(text)
    (row,) = steps_design_run(str(path), None, 1, tmp_path / "o", time_limit=90, workers=1,
                              progress=False, plot=False)["rows"]
    assert 0.125 <= row["tau_certified"] <= 0.125 * (1 + 1e-5)
    assert row["lower_bound"] is None and "not a polynomial" in row["log"][0]


def test_a_model_that_disagrees_with_pep_is_set_aside():
    """The box-wide bound is about the parametric model: when the model is not the
    method pep proves (here steps 2 h_k instead of h_k), steps_evaluator drops it, with
    the reason, before any bound is computed."""
    import sympy as sp

    from sosalgo.design_search.steps import steps_problem
    from sosalgo.spec import read_spec_text
    from sosalgo.worstcase.evaluate import steps_evaluator

    path = str(spec_path("gradient-schedule"))
    spec, text = load_spec(path), read_spec_text(path)
    prob = steps_problem(spec, None, 2, ["h"])
    kept = steps_evaluator(spec, text, None, 2, prob)
    assert prob.model is not None and prob.reason is None and kept
    hs = [sp.Symbol("h_0"), sp.Symbol("h_1")]
    prob.model = parametric_pep(spec, None, 2, ["h_0", "h_1"], lambda k: {
        "A": sp.Matrix([[1]]), "B": sp.Matrix([[-2 * hs[k]]]), "C": sp.Matrix([[1]]),
        "E": sp.Matrix([[1]])})
    steps_evaluator(spec, text, None, 2, prob)
    assert prob.model is None and "differs from sosalgo pep" in prob.reason


def test_set_range_replaces_the_design_box(tmp_path):
    """--set h.range=[LO, HI] replaces the box a design searches: one step of gradient
    descent on L-smooth convex f has the worst case max(L/(2(2h + 1)), L(1 - h)^2/2)
    (h in units of 1/L), decreasing on [0, 1], so with the box [0, 1/L] the optimum is
    h = 1, 1/6: certified above it, proven below it; verify re-applies the range (exit 0).
    A malformed range or an unknown parameter: exit 2, one line naming the option."""
    from click.testing import CliRunner

    from sosalgo.cli import cli

    runner = CliRunner()
    out = tmp_path / "o"
    res = runner.invoke(cli, ["design", str(spec_path("gradient-schedule")), "--steps", "1",
                              "--set", "h.range=[0, 1/L]", "--time-limit", "60", "--out",
                              str(out), "--json", "--quiet", "--workers", "1"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["set"] == {"h.range": "[0, 1/L]"}
    assert float(doc["schedule"]["h"][0]) == pytest.approx(1.0, abs=1e-4)
    assert doc["lower_bound"] <= 1 / 6 <= doc["tau_certified"] <= (1 / 6) * (1 + 1e-4)
    good = tmp_path / "good.json"
    good.write_text(json.dumps(doc))
    assert runner.invoke(cli, ["verify", str(good)]).exit_code == 0
    for bad, word in (("h.range=[0]", "[LO, HI]"), ("q.range=[0, 1]", "unknown parameter")):
        res = runner.invoke(cli, ["design", str(spec_path("gradient-schedule")), "--steps",
                                  "1", "--set", bad, "--out", str(out)])
        lines = res.output.strip().splitlines()
        assert res.exit_code == 2 and len(lines) == 1, res.output
        assert "--set" in lines[0] and word in lines[0]


def test_long_step_start_is_the_silver_pattern():
    """The design's long-step start: Altschuler and Parrilo's silver steps 1 + rho^(nu(i)
    - 1), rho = 1 + sqrt 2, nu(i) the 2-adic valuation of i = k + 1."""
    import math

    from sosalgo.design_search.steps import long_step

    rho = 1 + math.sqrt(2)
    for i in range(1, 33):
        nu = 0
        while i % 2 ** (nu + 1) == 0:
            nu += 1
        assert long_step(i - 1) == pytest.approx(1 + rho ** (nu - 1), rel=1e-14)


def _schedule_model(steps: int):
    import sympy as sp

    spec = load_spec(str(spec_path("gradient-convex")))
    hs = [sp.Symbol(f"h_{k}") for k in range(steps)]
    return parametric_pep(spec, None, steps, [str(h) for h in hs], lambda k: {
        "A": sp.Matrix([[1]]), "B": sp.Matrix([[-hs[k]]]), "C": sp.Matrix([[1]]),
        "E": sp.Matrix([[1]])})


def test_affine_point_random_boxes():
    """The affine robust point (G and F affine in θ over the box) on random boxes of
    per-step gradient descent, N = 3 in [0, 3]^3, wide and narrow, touching 0 and 3:
    every proven bound is below the independent PEP at the box's corners and at random
    θ inside; on a narrow box around the optimized schedule (sqrt 2, 1 + sqrt 2, 3/2)
    (worst case (3 - 2 sqrt 2)/4, Grimmer-Shu-Wang) it is within 1e-3 of it, so the
    comparison can fail."""
    from sosalgo.design_search.steps_affine import AffineSolver

    pp = _schedule_model(3)
    solver = AffineSolver(pp, LADDER, TIGHT)
    rng = random.Random(5)
    boxes = []
    for width in (Fraction(1, 2), Fraction(1, 20), Fraction(1, 500)):
        for _ in range(2):
            a = [Fraction(rng.randint(0, 3000), 1000) for _ in range(3)]
            boxes.append((tuple(min(x, 3 - width) for x in a),
                          tuple(min(x, 3 - width) + width for x in a)))
    boxes += [((Fraction(0),) * 3, (Fraction(1, 10),) * 3),
              ((Fraction(29, 10),) * 3, (Fraction(3),) * 3)]
    proven = 0
    for lo, hi in boxes:
        _, got = solver.proven(lo, hi)
        if got is None:
            continue
        proven += 1
        pts = [[float(lo[0]), float(hi[1]), float(lo[2])], [float(x) for x in hi]]
        pts += [[float(a) + rng.random() * float(b - a) for a, b in zip(lo, hi, strict=True)]
                for _ in range(2)]
        for h in pts:
            assert float(got[0]) <= independent_schedule_pep(h) * (1 + 1e-6) + 1e-9, (lo, hi)
    assert proven >= 4
    r2 = math.sqrt(2)
    opt = [Fraction(r2).limit_denominator(10 ** 6), Fraction(1 + r2).limit_denominator(10 ** 6),
           Fraction(3, 2)]
    w = Fraction(1, 1000)
    _, got = solver.proven([x - w for x in opt], [x + w for x in opt])
    best = (3 - 2 * r2) / 4
    assert got is not None and best * (1 - 1e-3) <= float(got[0]) <= best


def test_affine_point_refused_when_not_positive_on_the_box():
    """The exact check of a recorded affine point: G(u) must be positive definite at
    every vertex (a G_1 larger than G_0 is refused), G_i[0][0] = 0 for i >= 1, and a
    bound re-proven from a tampered F slope never exceeds the worst case."""
    from sosalgo.design_search.steps_affine import AffineSolver, affine_bound

    pp = _schedule_model(2)
    lo, hi = (Fraction(13, 10), Fraction(17, 10)), (Fraction(14, 10), Fraction(19, 10))
    _, got = AffineSolver(pp, LADDER, TIGHT).proven(lo, hi)
    assert got is not None
    bound, (gram, slopes) = got
    assert affine_bound(pp, lo, hi, gram, slopes) == bound
    big = [[2 * v for v in row] for row in gram[0]]
    big[0][0] = Fraction(0)
    assert affine_bound(pp, lo, hi, [gram[0], big, gram[2]], slopes) is None
    off = [row[:] for row in gram[1]]
    off[0][0] = Fraction(1, 10 ** 9)
    assert affine_bound(pp, lo, hi, [gram[0], off, gram[2]], slopes) is None
    tampered = [[v + Fraction(1, 7) for v in row] for row in slopes]
    low = affine_bound(pp, lo, hi, gram, tampered)
    truth = min(independent_schedule_pep([a, b]) for a in (1.3, 1.4) for b in (1.7, 1.9))
    assert low is None or float(low) <= truth * (1 + 1e-6)


def test_obs_f_schedule_against_the_independent_pep():
    """OBS-F (Grimmer, Shu, Wang), the design's long-step start: its rate r gives the
    worst case r/2 of its schedule, checked by the independent PEP for N = 1..5, and the
    closed forms N = 1: h = 3/2, 1/8; N = 3: (sqrt 2, 1 + sqrt 2, 3/2), (3 - 2 sqrt 2)/4."""
    from sosalgo.design_search.steps import obs_f

    for steps in range(1, 6):
        sched, rate = obs_f(steps)
        assert len(sched) == steps
        assert independent_schedule_pep(sched) == pytest.approx(rate / 2, rel=1e-6)
    assert obs_f(1) == (pytest.approx([1.5]), pytest.approx(0.25))
    sched, rate = obs_f(3)
    assert sched == pytest.approx([math.sqrt(2), 1 + math.sqrt(2), 1.5], rel=1e-12)
    assert rate / 2 == pytest.approx((3 - 2 * math.sqrt(2)) / 4, rel=1e-12)


def test_may_coincide_only_where_a_step_may_be_zero():
    """Two queries of gradient descent are equal exactly where a step is 0 (y_{k+1} =
    y_k - h_k g_k): boxes touching h_k = 0 may coincide, boxes away from 0 do not; a
    box where the witnesses alone are tried still gets the exact vertex range of
    x_N = Π (1 - q h_k), here the quadratic q = L on [9/4, 3]^3 x [0, 3/4]:
    (5/4)^6 (1/4)^2 / 2 at least (|1 - h| >= 5/4, and 1/4 at h = 3/4)."""
    from sosalgo.design_search.steps_bound import may_coincide

    pp = _schedule_model(4)
    one = Fraction(1)
    assert may_coincide(pp, (Fraction(0), one, one, one), (one,) * 4)
    assert not may_coincide(pp, (Fraction(1, 10),) * 4, (one,) * 4)
    lo, hi = (Fraction(9, 4),) * 3 + (Fraction(0),), (Fraction(3),) * 3 + (Fraction(3, 4),)
    assert quadratic_bound(pp, lo, hi, [one]) == Fraction(5, 4) ** 6 * Fraction(1, 4) ** 2 / 2
    truth = independent_schedule_pep([2.25, 2.25, 2.25, 0.75])
    assert float(prove_box(pp, BoxSolver(pp), lo, hi).bound) <= truth * (1 + 1e-6)


def test_affine_leaf_round_trip_through_the_document():
    """A box near the optimized two-step schedule is proven by the affine point; its
    leaf document (gram, slopes as exact texts) is re-proven to the same bound by what
    verify runs, and a changed matrix entry is not re-proven to it (or at all)."""
    from sosalgo.design_search.steps import _leaf_doc
    from sosalgo.design_search.steps_bound import reprove
    from sosalgo.proofs.steps_design import _gram, _slopes

    pp = _schedule_model(2)
    lo, hi = (Fraction(141, 100), Fraction(187, 100)), (Fraction(142, 100), Fraction(188, 100))
    leaf = prove_box(pp, BoxSolver(pp), lo, hi)
    assert leaf.how == "affine-pep"
    doc = json.loads(json.dumps(_leaf_doc(leaf)))
    assert reprove(pp, lo, hi, doc["how"], None, _slopes(doc), _gram(doc)) == leaf.bound
    assert float(leaf.bound) <= independent_schedule_pep([1.415, 1.875]) * (1 + 1e-6)
    doc["gram"][1][1][1] = str(Fraction(doc["gram"][1][1][1]) + 1)
    assert reprove(pp, lo, hi, doc["how"], None, _slopes(doc), _gram(doc)) != leaf.bound


@pytest.mark.deep
def test_gradient_schedule_ten_steps_reaches_obs_f(tmp_path):
    """gradient-schedule at N = 10 with h in [0, 7/L]: the certified worst case reaches
    Grimmer, Shu and Wang's OBS-F, 0.0106222530682 at L = 1 (their published value),
    within 1e-4 relative and never below it; the schedule's worst case is checked by
    the independent PEP."""
    from sosalgo.runs.steps_design import steps_design_run

    (row,) = steps_design_run(str(spec_path("gradient-schedule")), None, 10, tmp_path,
                              time_limit=300, workers=1, progress=False, plot=False,
                              overrides={"h.range": "[0, 7/L]"})["rows"]
    obs = 0.0106222530682
    assert obs * (1 - 1e-9) <= row["tau_certified"] <= obs * (1 + 1e-4)
    indep = independent_schedule_pep(row["schedule"]["h"])
    assert indep * (1 - 1e-6) <= row["tau_certified"] <= indep * (1 + 1e-5)


def test_quadratic_witness_on_random_schedule_boxes():
    """Gradient descent's schedule on f = q x^2 / 2 from x_0 = 1: x_N = prod (1 - q h_k),
    each factor with its own h_k, so min |x_N| over a box is the product of each factor's
    least |1 - q h_k| over its interval, and the witness is max over q of q/2 times its
    square (exact, computed here apart from the code's vertex ranges and the float order
    it uses to skip curvatures)."""
    from sosalgo.design_search.steps import steps_problem
    from sosalgo.design_search.steps_bound import witness_curvatures

    spec = load_spec(str(spec_path("gradient-schedule")))
    rng = random.Random(7)
    for steps in (2, 3, 4):
        pp = steps_problem(spec, None, steps, ["h"]).model
        qs = witness_curvatures(pp)
        for _ in range(12):
            lo, hi = [], []
            for _ in range(steps):
                w = Fraction(3, 2 ** rng.randint(0, 9))
                a = rng.randint(0, int(3 / w) - 1) * w
                lo.append(a)
                hi.append(a + w)
            best = Fraction(0)
            for q in qs:
                low = Fraction(1)
                for a, b in zip(lo, hi, strict=True):
                    f0, f1 = 1 - q * a, 1 - q * b  # decreasing in h
                    low *= 0 if f1 <= 0 <= f0 else min(abs(f0), abs(f1))
                best = max(best, q * low * low / 2)
            assert quadratic_bound(pp, lo, hi, qs) == best, (lo, hi)


def test_bound_on_two_processes_covers_the_box_below_the_closed_form(gd_models):
    """branch_and_bound with workers = 2 (children proven on a worker process and here):
    its leaves tile [0, 2] (sorted, end to end), each re-proven exactly at its bound or
    above by the recorded argument alone, and the bound over the box is at most the
    closed form's minimum over h of gradient descent's worst case (Drori-Teboulle) and
    within 1e-2 of it."""
    import time as _time

    from sosalgo.design_search.steps_bound import branch_and_bound, reprove

    pp = gd_models[2]
    best = _closed_form_minimum(2)
    res = branch_and_bound(pp, [Fraction(0)], [Fraction(2)], lambda: best,
                           _time.time() + 300, 1e-2, workers=2, max_boxes=400)
    leaves = sorted(res.leaves, key=lambda b: b.lo)
    assert leaves[0].lo == (0,) and leaves[-1].hi == (2,)
    assert all(a.hi == b.lo for a, b in zip(leaves[:-1], leaves[1:], strict=True))
    assert res.finished and float(res.lower_bound) <= best
    assert float(res.lower_bound) >= best * (1 - 1e-2)
    for leaf in leaves:
        lo, hi = leaf.proof_box()
        got = reprove(pp, lo, hi, leaf.how, leaf.point, leaf.slopes, leaf.gram)
        assert got >= leaf.bound, leaf
