"""The conformance suite against PEPit's examples (bench/conformance): one well-formed case
file per example, every expressed case's command accepted by sosalgo, and sosalgo's proven
value against PEPit's committed one (a peer's number, computed by PEPit 0.5.1 with Clarabel:
``python -m bench.conformance``)."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest
from click.testing import CliRunner

from bench.conformance import ZERO_ABS, read_results
from bench.conformance.cases import (
    CASES,
    CaseError,
    case_files,
    listed_examples,
    listed_parameters,
    load,
    load_all,
)
from bench.conformance.table import DOCS, END, START, table

ROOT = Path(__file__).resolve().parents[1]
EXPRESSED = [c for c in load_all() if c.expressed]


def test_every_pepit_example_has_exactly_one_case_file():
    listed = listed_examples()
    assert len(listed) == 96 and len({p for p, _ in listed}) == 96
    files = {str(p.relative_to(CASES).with_suffix("")) for p in case_files()}
    assert files == {p for p, _ in listed}
    functions = dict(listed)
    for case in load_all():
        assert case.function == functions[case.example], case.example


def test_every_case_is_well_formed():
    parameters = listed_parameters()
    for case in load_all():  # load refuses a malformed file
        assert len(case.arguments) >= 3
        required, optional = parameters[case.example]
        for args in case.arguments:  # PEPit's function accepts every argument set
            assert required <= set(args) <= required | optional, (case.example, args)
        if case.expressed:
            assert case.scale_reason and len(case.commands) == len(case.arguments)
        else:
            assert case.reason.strip() and case.needs


NOT_EXPRESSIBLE_CASE = """example: continuous_time_models/gradient_flow_convex
function: wc_gradient_flow_convex
question: "for a gradient flow."
arguments:  # PEPit's keyword arguments; the example's own first
  - {t: 2.5}
  - {t: 1.0}
  - {t: 5.0}
status: not expressible
needs: ["continuous time"]
reason: "a continuous-time flow"
"""


def test_a_malformed_case_names_its_file_and_field(tmp_path):
    text = NOT_EXPRESSIBLE_CASE  # a well-formed case file of a listed example
    path = tmp_path / "continuous_time_models" / "gradient_flow_convex.yaml"
    path.parent.mkdir()
    path.write_text(text)
    assert load(path, root=tmp_path).reason  # the copy itself is well-formed
    for old, new, field in [("status: not expressible", "status: maybe", "status"),
                            ("reason:", "because:", "because"),
                            ("example: continuous_time_models/", "example: other/", "example"),
                            ("  - {t: 5.0}\n", "", "arguments")]:
        assert old in text
        path.write_text(text.replace(old, new))
        with pytest.raises(CaseError, match=f"gradient_flow_convex.yaml: {field}"):
            load(path, root=tmp_path)


@pytest.mark.parametrize("case", EXPRESSED, ids=[c.example for c in EXPRESSED])
def test_every_expressed_command_is_accepted(case):
    from sosalgo.cli import pep
    from sosalgo.runs import spec_with_text
    from sosalgo.spec.overrides import parse_set_options

    for i in range(len(case.arguments)):
        argv = case.command(i)
        assert argv[0] == "pep"
        ctx = pep.make_context("pep", argv[1:])
        assert (ROOT / ctx.params["spec_path"]).is_file()
        spec, _ = spec_with_text(str(ROOT / ctx.params["spec_path"]),
                                 overrides=parse_set_options(ctx.params["overrides"]),
                                 varying=True)
        assert spec.m == 0 or ctx.params["kappa"], "an m > 0 spec needs --kappa"


def _proven(case, index, tmp_path) -> float:
    from sosalgo.cli import cli

    args = case.command(index) + ["--json", "--out", str(tmp_path), "--no-plot", "--quiet",
                                  "--no-witness"]
    out = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert out.exit_code == 0, out.output
    doc = json.loads(out.output)
    row = doc["rows"][-1] if "rows" in doc else doc
    proven = row["certificate"].get("tau_proven")
    assert proven, f"not proven ({row['certificate'].get('check_kind')})"
    return float(Fraction(proven)) * case.scale_at(index)


def _check_against_pepit(case, index, tmp_path):
    committed = read_results()[(case.example, index)]
    pepit = float(committed["pepit_tau"])
    proven = _proven(case, index, tmp_path)
    tight = (float(committed["theoretical_tau"])
             if case.tight[index] and committed["theoretical_tau"] else None)
    # where the theoretical value is tight it is the true worst case, and PEPit's float
    # an approximation of it (its solver's accuracy): either is a reference
    refs = [pepit] if tight is None else [pepit, tight]
    low = min(refs)
    assert proven >= low - 1e-7 * abs(low), (proven, refs)  # a rate may be < 0
    assert any(abs(proven - r) <= max(1e-6 * abs(r), ZERO_ABS if case.zero else 0)
               for r in refs), (proven, refs)
    if tight is not None:
        assert proven >= tight - 1e-12 * abs(tight)


FAST = [c for c in EXPRESSED if c.fast]
# Expressed and agreeing in floating point, where the proof misses the 1e-6 of the test: kept
# as strict expected failures, so that a fix shows up here.
_LOOSE = "the exact proof is {} above PEPit's value (the certificate's margin), more than 1e-6"
KNOWN_GAPS = {
    ("low_dimensional_worst_cases_scenarios/inexact_gradient", 0):
        "PEPit's logdet solves fail (Clarabel): no committed value to compare with (sosalgo "
        "proves the tight 0.1397311: test_inexact.py)",
    ("low_dimensional_worst_cases_scenarios/inexact_gradient", 1):
        "PEPit's logdet solves fail (Clarabel): no committed value to compare with",
    ("low_dimensional_worst_cases_scenarios/averaged_projections", 0):
        "PEPit's logdet solves fail (Clarabel): no committed value to compare with",
    ("monotone_inclusions_variational_inequalities/optimistic_gradient", 2):
        "the exact proof is 2.2e-6 above PEPit's value; PEPit's default solver is off by "
        "1e-5 to 1e-4 on these problems (which side is nearer the worst case is not shown)",
    ("composite_convex_minimization/frank_wolfe", 0): _LOOSE.format("2.3e-4"),
    ("composite_convex_minimization/frank_wolfe", 1): _LOOSE.format("5.2e-4"),
    ("low_dimensional_worst_cases_scenarios/frank_wolfe", 0): _LOOSE.format("2.3e-4"),
    ("low_dimensional_worst_cases_scenarios/frank_wolfe", 1): _LOOSE.format("5.2e-4"),
    ("monotone_inclusions_variational_inequalities/past_extragradient", 2):
        _LOOSE.format("1.6e-6"),
    **{("unconstrained_convex_minimization/inexact_accelerated_gradient", i):
       "PEPit's value (Clarabel, default tolerances) is above its own value at tolerance "
       "1e-12 by more than 1e-7: ours is proven between the two "
       "(test_proven_against_pepit_at_tight_tolerance)" for i in range(2)},
    **{("stochastic_and_randomized_convex_minimization/point_saga", i):
       "tau agrees, no exact proof: S is singular along the fixed-point family and the "
       "step gamma is irrational (no rational zero rows)" for i in range(3)},
    **{("inexact_proximal_methods/relatively_inexact_proximal_point_algorithm", i):
       "PEPit's value (Clarabel, default tolerances) is above its own value at tolerance "
       "1e-12 by 1.6e-7: ours is proven between the two "
       "(test_proven_against_pepit_at_tight_tolerance)" for i in range(2)},
    ("monotone_inclusions_variational_inequalities/optimistic_gradient_refined_cocoercive",
     1): "the proven 1.33333363 is 1.3e-6 above PEPit's Clarabel value 1.33333194 (its n = 1 "
         "values are up to 6e-7 below the proven ones): not judged without a closed form",
    ("monotone_inclusions_variational_inequalities/optimistic_gradient_refined", 2):
        "PEPit's Clarabel solve takes over 600 s here (no committed value; an earlier run "
        "gave 0.12351681, which tau 0.1235169 agrees with) and no exact proof: the margin "
        "solves of the cut PEP leave S indefinite (least eigenvalue about -1e-6, scaled)",
    **{("low_dimensional_worst_cases_scenarios/dykstra", i):
       "tau agrees with PEPit within 1e-6, but the proven bound is 1.2e-6 above PEPit's "
       "value (no closed form to judge which is nearer the worst case)" for i in range(2)},
}
REST = [pytest.param(c, i, id=f"{c.example}[{i}]", marks=(
            [pytest.mark.xfail(strict=True, reason=KNOWN_GAPS[(c.example, i)])]
            if (c.example, i) in KNOWN_GAPS else []))
        for c in EXPRESSED for i in range(len(c.arguments)) if not (c.fast and i == 0)]


@pytest.mark.parametrize("case", FAST, ids=[c.example for c in FAST])
def test_proven_value_against_pepit_fast(case, tmp_path):
    _check_against_pepit(case, 0, tmp_path)


@pytest.mark.deep
@pytest.mark.parametrize("case,index", REST)
def test_proven_value_against_pepit(case, index, tmp_path):
    _check_against_pepit(case, index, tmp_path)


def test_docs_table_is_generated_from_cases_and_results():
    text = DOCS.read_text()
    assert text.split(START, 1)[1].split(END, 1)[0].strip() == table().strip()


def _set_lists(argv: list[str]) -> dict[str, list[float]]:
    sets = [argv[i + 1] for i, a in enumerate(argv) if a == "--set"]
    out = {}
    for item in sets:
        name, value = item.split("=", 1)
        if value.startswith("["):
            out[name] = [float(v.strip().removesuffix("/L")) for v in value[1:-1].split(",")]
    return out


def test_per_step_coefficients_in_case_files_are_the_schedules():
    from bench.conformance.schedules import (
        accelerated_proximal_point,
        ogm_g,
        silver_strongly_convex,
    )

    cases = {c.example: c for c in load_all()}
    silver = cases["unconstrained_convex_minimization/"
                   "gradient_descent_silver_stepsize_strongly_convex"]
    for i, args in enumerate(silver.arguments):
        steps = _set_lists(silver.command(i))["h"]
        assert steps == pytest.approx(silver_strongly_convex(args["L"] / args["mu"], args["n"]),
                                      rel=1e-15)
    app = cases["unconstrained_convex_minimization/accelerated_proximal_point"]
    for i, args in enumerate(app.arguments):
        lists = _set_lists(app.command(i))
        assert lists["gamma"] == pytest.approx(args["gammas"], rel=1e-15)
        assert lists["alpha"] == pytest.approx(
            accelerated_proximal_point(args["A0"], args["gammas"]), rel=1e-15)
    ogmg = cases["unconstrained_convex_minimization/optimized_gradient_for_gradient"]
    for i, args in enumerate(ogmg.arguments):
        lists = _set_lists(ogmg.command(i))
        beta, gamma = ogm_g(args["n"])
        assert lists["beta"] == pytest.approx(beta, rel=1e-15)
        assert lists["gamma"] == pytest.approx(gamma, rel=1e-15)


def test_schedules_against_closed_forms():
    from bench.conformance.schedules import ogm_g, silver_strongly_convex

    # one silver step at kappa: psi(1/kappa) = (1 + 1)/(1 + 1/kappa) = 2 kappa/(kappa + 1)
    assert silver_strongly_convex(10, 1) == pytest.approx([20 / 11])
    # as kappa grows, a block of 8 steps begins with the convex schedule 1 + rho^(nu(i) - 1),
    # i = 1..7 (its last step grows with kappa)
    rho = 1 + 2 ** 0.5
    assert silver_strongly_convex(1e12, 8)[:7] == pytest.approx(
        [1 + rho ** (v - 1) for v in (0, 1, 0, 2, 0, 1, 0)], rel=1e-5)
    # OGM-G's last step: theta_n = 1, theta_{n-1} = (1 + sqrt 5)/2: beta = (t - 1)/(t (2t - 1))
    t = (1 + 5 ** 0.5) / 2
    beta, gamma = ogm_g(2)
    assert beta[-1] == pytest.approx((t - 1) / (t * (2 * t - 1)))
    assert gamma[-1] == pytest.approx(1 / (2 * t - 1))
    # accelerated proximal point: alpha_0 solves alpha^2 = (1 - alpha) A_0 gamma_0 (A0 g = 1:
    # the golden ratio's inverse), and the next A is (1 - alpha) A
    from bench.conformance.schedules import accelerated_proximal_point

    alphas = accelerated_proximal_point(1, [1, 2])
    assert alphas[0] == pytest.approx(1 / t)
    a1 = 1 - 1 / t
    assert alphas[1] ** 2 == pytest.approx((1 - alphas[1]) * a1 * 2)


def test_verdicts_flag_a_proof_below_pepit_or_below_a_tight_value():
    from bench.conformance import verdicts

    case = next(c for c in EXPRESSED if c.example.endswith("/proximal_gradient"))
    pepit = {"tau": 0.6561, "theoretical": 0.6561}  # 0.9^4, tight
    good = verdicts(case, 0, pepit, {"tau": 0.6561000001, "tau_proven": 0.6561000082})
    assert good == {"agree": "yes", "not_below": "yes", "above_theoretical": "yes"}
    low = verdicts(case, 0, pepit, {"tau": 0.6560999, "tau_proven": 0.6560999})
    assert low["not_below"] == "no" and low["above_theoretical"] == "no"
    far = verdicts(case, 0, pepit, {"tau": 0.6562, "tau_proven": 0.6562})
    assert far["agree"] == "no" and far["not_below"] == "yes"
    unproven = verdicts(case, 0, pepit, {"tau": 0.6561, "tau_proven": None})
    assert unproven["not_below"] == "" and unproven["above_theoretical"] == ""


def test_verdicts_take_a_tight_value_below_pepits_float_as_the_reference():
    # Halpern, n = 25: (2/26)^2 = 1/169 is the worst case (Lieder 2021); PEPit's float is
    # 2.9e-6 above it (its solver's accuracy), a proof between the two is neither wrong
    # nor below the true value; one below 1/169 still is
    from bench.conformance import verdicts

    case = next(c for c in EXPRESSED if c.example == "fixed_point_problems/halpern_iteration")
    pepit = {"tau": 0.005917176830520356, "theoretical": 1 / 169}
    between = verdicts(case, 0, pepit, {"tau": 0.0059171597833, "tau_proven": 0.0059171674182})
    assert between == {"agree": "yes", "not_below": "yes", "above_theoretical": "yes"}
    below = verdicts(case, 0, pepit, {"tau": 0.00591714, "tau_proven": 0.00591714})
    assert below["not_below"] == "no" and below["above_theoretical"] == "no"
    # where the theoretical value is not tight, PEPit's float stays the reference
    loose = next(c for c in EXPRESSED if not any(c.tight))
    far = verdicts(loose, 0, {"tau": 0.0059171768, "theoretical": 1 / 169},
                   {"tau": 0.0059171597833, "tau_proven": 0.0059171674182})
    assert far["agree"] == "no" and far["not_below"] == "no"


def test_command_placeholders_are_parsed_not_evaluated():
    from bench.conformance.cases import fill

    assert fill("--kappa {L/mu} --set h={gamma*L}/L", {"L": 1, "mu": 0.1, "gamma": 1.5}) \
        == "--kappa 10 --set h=1.5/L"
    with pytest.raises(ValueError):
        fill("{__import__('os').getcwd()}", {"L": 1})



# (example, arguments, the tight worst case): Halpern (2/(n + 1))^2 (Lieder 2021), the
# accelerated proximal point on a monotone operator 1/n^2 (Kim 2021), the optimal proximal
# point on a mu-strongly monotone one (2 mu/((1 + 2 mu)^n - 1))^2 (Park, Ryu 2022)
CLOSED_FORMS = [("fixed_point_problems/halpern_iteration", {"n": 3}, Fraction(1, 4)),
                ("fixed_point_problems/halpern_iteration", {"n": 5}, Fraction(1, 9)),
                ("monotone_inclusions_variational_inequalities/accelerated_proximal_point",
                 {"alpha": 2, "n": 10}, Fraction(1, 100)),
                ("monotone_inclusions_variational_inequalities/accelerated_proximal_point",
                 {"alpha": 1, "n": 3}, Fraction(1, 9)),
                ("monotone_inclusions_variational_inequalities/"
                 "optimal_strongly_monotone_proximal_point", {"n": 10, "mu": 0.05},
                 (Fraction(1, 10) / (Fraction(11, 10) ** 10 - 1)) ** 2),
                ("monotone_inclusions_variational_inequalities/"
                 "optimal_strongly_monotone_proximal_point", {"n": 3, "mu": 0.1},
                 (Fraction(1, 5) / (Fraction(6, 5) ** 3 - 1)) ** 2),
                # gradient descent on quadratics: max over q in [mu, L] of q/2 (1 - gamma
                # q)^(2n), at q = 1/(gamma (2n + 1)) when inside, else at mu; proximal
                # gradient on quadratics: max((1 - mu gamma)^2, (1 - L gamma)^2)^n
                *[("unconstrained_convex_minimization/gradient_descent_quadratics", a, v)
                  for a, v in [({"mu": 0.3, "L": 3, "gamma": 1 / 3, "n": 4},
                                Fraction(1, 6) * Fraction(8, 9) ** 8),
                               ({"mu": 0.1, "L": 1, "gamma": 1, "n": 2},
                                Fraction(1, 10) * Fraction(4, 5) ** 4),
                               ({"mu": 0.3, "L": 3, "gamma": 0.5, "n": 3},
                                Fraction(3, 20) * Fraction(17, 20) ** 6)]],
                ("composite_convex_minimization/proximal_gradient_quadratics",
                 {"L": 1, "mu": 0.1, "gamma": 1.5, "n": 3}, Fraction(289, 400) ** 3)]


@pytest.mark.parametrize("example,args,exact", CLOSED_FORMS,
                         ids=[f"{e.rsplit('/', 1)[1]}-{a}" for e, a, _ in CLOSED_FORMS])
def test_proven_against_tight_closed_form(example, args, exact, tmp_path):
    """Where PEPit's float is above the exact worst case by more than its tolerance (the rows
    of KNOWN_GAPS that say so), the closed form decides: proven, never below it, within
    1e-6 of it."""
    from dataclasses import replace

    case = next(c for c in EXPRESSED if c.example == example)
    proven = _proven(replace(case, arguments=(args,)), 0, tmp_path)
    assert proven >= float(exact) * (1 - 1e-12)
    assert proven <= float(exact) * (1 + 1e-6)


# (example, arguments, PEPit's value with Clarabel at tol_gap_abs = tol_gap_rel = tol_feas
# = 1e-12; SCS at eps = 1e-10 agrees within 1.2e-9 relative), where PEPit's value at its
# default tolerances is above it by more than 1e-7
PEPIT_TIGHT = [("unconstrained_convex_minimization/inexact_accelerated_gradient",
                {"L": 1, "epsilon": 0.1, "n": 5}, 0.039387813980435636),
               ("unconstrained_convex_minimization/inexact_accelerated_gradient",
                {"L": 1, "epsilon": 0.1, "n": 3}, 0.07299270074928768),
               ("inexact_proximal_methods/relatively_inexact_proximal_point_algorithm",
                {"n": 8, "gamma": 10, "sigma": 0.65}, 0.007678412477375481),
               ("inexact_proximal_methods/relatively_inexact_proximal_point_algorithm",
                {"n": 4, "gamma": 10, "sigma": 0.65}, 0.013025798738068152)]


@pytest.mark.parametrize("example,args,peer", PEPIT_TIGHT,
                         ids=[f"{e.rsplit('/', 1)[1]}-{a}" for e, a, _ in PEPIT_TIGHT])
def test_proven_against_pepit_at_tight_tolerance(example, args, peer, tmp_path):
    """Proven, not below PEPit's value at tight tolerances (beyond its 1e-8 accuracy),
    within 1e-6 of it."""
    from dataclasses import replace

    case = next(c for c in EXPRESSED if c.example == example)
    proven = _proven(replace(case, arguments=(args,)), 0, tmp_path)
    assert proven >= peer * (1 - 1e-8)
    assert proven <= peer * (1 + 1e-6)
