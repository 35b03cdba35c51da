"""``sosalgo verify`` on the documents of ``sosalgo pep``: an honest ``pep --json``
document and witness file verify (exit 0); every claim field tampered is refused (exit 3,
or 2 when the document no longer parses); the fields that claim nothing (solver
diagnostics, timings, texts) leave the verdict alone. A witness for ``m: 1/10`` is
checked here, in fractions, against F(1/10, 1) as written."""

from __future__ import annotations

import copy
import json
from fractions import Fraction
from itertools import combinations

import pytest
from click.testing import CliRunner

from sosalgo.cli import cli

SPEC = """name: gradient-tenth
description: gradient descent with step 1/L on F(1/10, 1)
m: 1/10
parameters:
  h: {value: 1/L}
matrices:
  A: [[1]]
  B: [[-h]]
  C: [[1]]
  E: [[1]]
kappa: [10]
"""

# fields that claim nothing: solver diagnostics, timings, texts, the drawing, file names
DIAGNOSTIC = {"gap", "status", "seconds", "detail", "slack", "min_eig_slack",
              "min_value_slack", "multipliers", "basis", "margin", "objective_floor",
              "mixed", "interpolant", "pairs_checked", "delta", "search",
              "multipliers_nonzero", "repaired", "files", "source", "note", "spec_text"}
# proof data: any values that still prove the claim are a proof (tampered below by
# breaking them: a negative multiplier, a zero scale)
PROOF_DATA = {"multipliers_exact", "scale"}


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """(spec path, pep --json document of N = 1..2, the N = 2 witness file)."""
    out = tmp_path_factory.mktemp("pep")
    spec = out / "tenth.yaml"
    spec.write_text(SPEC)
    res = run(["pep", spec, "--kappa", "10", "--steps", "1..2", "--out", out, "--json",
               "--no-plot"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    wit = json.loads((out / "gradient-tenth-pep-k10-N2-witness.json").read_text())
    return spec, doc, wit


def verify(tmp_path, spec, doc):
    path = tmp_path / "doc.json"
    path.write_text(json.dumps(doc))
    return run(["verify", path, "--spec", spec])


def leaves(node, path=()):
    """Every (path, value) of the JSON tree below ``node``."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from leaves(v, (*path, k))
    elif isinstance(node, list) and node:
        for i, v in enumerate(node):
            yield from leaves(v, (*path, i))
    else:
        yield path, node


def tampered(value):
    """A different value of the same kind: numbers doubled (and moved off 0), exact
    strings likewise, flags flipped, term strings scaled, other text replaced."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, int | float):
        return value * 2 + (1 if value == 0 else 0)
    if isinstance(value, str):
        try:
            q = Fraction(value)
        except (ValueError, ZeroDivisionError):
            return f"2*{value}" if value in ("f", "dist", "grad") else value + "x"
        return str(q * 2 + (1 if q == 0 else 0))
    return 1 if value is None else None


def put(doc, path, value):
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value


def is_claim(path):
    names = {p for p in path if isinstance(p, str)}
    if path[-2:] == ("check", "check_kind"):  # a witness check's label (the row's is a claim)
        return False
    return not names & (DIAGNOSTIC | PROOF_DATA)


def test_honest_documents_verify(tmp_path, made):
    spec, doc, wit = made
    for d in (doc, wit, doc["rows"][1]):
        res = verify(tmp_path, spec, d | ({"source": str(spec)} if "rows" not in d else {}))
        assert res.exit_code == 0, res.output
        assert "NOT verified" not in res.output


def test_every_witness_claim_tampered_is_refused(tmp_path, made):
    spec, _, wit = made
    fields = [(p, v) for p, v in leaves(wit) if is_claim(p)]
    assert len(fields) > 40  # the walk reaches the points, calls, class and bounds
    passed = []
    for path, value in fields:
        doc = copy.deepcopy(wit)
        put(doc, path, tampered(value))
        res = verify(tmp_path, spec, doc)
        if res.exit_code not in (2, 3):
            passed.append(path)
    assert not passed


def test_every_row_claim_tampered_is_refused(tmp_path, made):
    spec, doc, _ = made
    fields = [(p, v) for p, v in leaves(doc["rows"][0]) if is_claim(p)
              and p[0] != "witness"]  # the witness is walked above
    assert len(fields) > 8
    passed = []
    for path, value in fields:
        d = copy.deepcopy(doc)
        put(d["rows"][0], path, tampered(value))
        res = verify(tmp_path, spec, d)
        if res.exit_code not in (2, 3):
            passed.append(path)
    assert not passed


def test_diagnostics_do_not_change_the_verdict(tmp_path, made):
    """One leaf of every diagnostic field (by name) tampered: still verified."""
    spec, doc, wit = made
    seen = set()
    for base in (wit, doc):
        for path, value in leaves(base):
            key = next(p for p in reversed(path) if isinstance(p, str))
            if (is_claim(path) or key in seen | {"spec_text", "source"}
                    or set(path) & PROOF_DATA):
                continue
            seen.add(key)
            d = copy.deepcopy(base)
            put(d, path, tampered(value))
            res = verify(tmp_path, spec, d)
            assert res.exit_code == 0, (path, res.output)
    assert {"gap", "slack", "seconds", "objective_floor"} <= seen


@pytest.mark.parametrize("where", ["witness", "row"])
def test_broken_proof_data_is_refused(tmp_path, made, where):
    spec, doc, wit = made
    base = wit if where == "witness" else doc
    proof = (lambda d: d["upper"]) if where == "witness" else (
        lambda d: d["rows"][0]["certificate"]["proof"])
    for label in proof(base)["multipliers_exact"]:
        d = copy.deepcopy(base)
        proof(d)["multipliers_exact"][label] = "-1"
        assert verify(tmp_path, spec, d).exit_code == 3, label
    d = copy.deepcopy(base)
    proof(d)["scale"][0] = "0"
    assert verify(tmp_path, spec, d).exit_code == 3


def test_tau_halved_without_certificates_is_refused(tmp_path, made):
    spec, doc, _ = made
    d = copy.deepcopy(doc)
    for row in d["rows"]:
        row["certificate"] = row["witness"] = None
    res = verify(tmp_path, spec, d)
    assert res.exit_code == 3 and "unsupported" in res.output  # claimed, never proven
    for row in d["rows"]:
        row["tau"] /= 2
    assert verify(tmp_path, spec, d).exit_code == 3
    d = copy.deepcopy(doc)
    for row in d["rows"]:
        row["tau"] /= 2
    res = verify(tmp_path, spec, d)
    assert res.exit_code == 3 and "below the proven lower bound" in res.output


@pytest.mark.parametrize("change", [
    ("params", "L", 100), ("params", "m", 0), ("measure", None, "2*f"),
    ("measure", None, "f + dist"), ("initial", None, "dist + f"), ("kappa", None, 20.0)])
def test_witness_about_another_class_or_measure_is_refused(tmp_path, made, change):
    spec, _, wit = made
    d = copy.deepcopy(wit)
    key, sub, value = change
    if key == "params":
        d["functions"]["f"]["params"][sub] = value
    else:
        d[key] = value
    res = verify(tmp_path, spec, d)
    assert res.exit_code in (2, 3), res.output


def test_witness_class_is_as_written_and_checks_in_fractions(made):
    """Test-side check, in fractions only, of the stored exact witness against the
    interpolation conditions of F(m, L) with m = 1/10, L = kappa m = 1 as written
    (Taylor, Hendrickx, Glineur 2017, Theorem 4), and of its claimed lower bound."""
    _, _, wit = made
    m, L = Fraction(1, 10), Fraction(1)
    assert wit["class"]["m"] == "1/10" and wit["class"]["L"] == "1"
    fd = wit["functions"]["f"]
    assert all(Fraction(v) == 0 for v in fd["optimal_subgradient"])  # one function
    pts = [([Fraction(v) for v in p["x_exact"]], [Fraction(v) for v in p["g"]],
            Fraction(p["h"])) for p in fd["points"]]
    r = len(pts[0][0])
    pts.append(([Fraction(0)] * r, [Fraction(0)] * r, Fraction(0)))  # x* = 0, f* = 0

    def dot(a, b):
        return sum((x * y for x, y in zip(a, b, strict=True)), Fraction(0))

    def sub(a, b):
        return [x - y for x, y in zip(a, b, strict=True)]

    violations = 0
    for (xi, gi, fi), (xj, gj, fj) in ((a, b) for p, q in combinations(pts, 2)
                                       for a, b in ((p, q), (q, p))):
        dx, dg = sub(xi, xj), sub(gi, gj)
        rhs = fj + dot(gj, dx) + (dot(dg, dg) / L + m * dot(dx, dx)
                                  - 2 * m / L * dot(dg, dx)) / (2 * (1 - m / L))
        violations += fi < rhs
    assert violations == 0
    # the measure f(x_N) - f* over the initial |x_0 - x*|^2, both from the stored data
    x0 = [Fraction(v) for v in wit["iterates_exact"][0]]
    xN = [Fraction(v) for v in wit["iterates_exact"][-1]]
    assert [Fraction(v) for v in wit["x0"]] == x0
    fN = next(p for p in fd["points"] if [Fraction(v) for v in p["x_exact"]] == xN)
    assert Fraction(fN["h"]) / dot(x0, x0) >= Fraction(wit["check"]["tau_lower"])
    # the iterates are gradient steps x+ = x - g/L on the stored gradients, exactly
    ys = [p for p in fd["points"] if p["label"].startswith("y")]
    for k, p in enumerate(ys):
        nxt = [Fraction(a) - Fraction(g) / L for a, g in zip(p["x_exact"], p["g"],
                                                              strict=True)]
        assert nxt == [Fraction(v) for v in wit["iterates_exact"][k + 1]]


def test_csv_tau_proven_against_the_closed_form(tmp_path):
    """Gradient descent with h = 1/L on smooth convex f: the worst case of
    f(x_N) - f* is L/(4N + 2) |x_0 - x*|^2 (Drori and Teboulle 2014); the CSV's
    tau_proven is a proven upper bound just above it."""
    import csv

    from .conftest import spec_path

    res = run(["pep", spec_path("gradient-convex"), "--steps", "1..3", "--out", tmp_path,
               "--no-plot", "--no-witness"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(tmp_path / "gradient-convex-pep.csv")))
    assert [int(r["steps"]) for r in rows] == [1, 2, 3]
    for r in rows:
        exact = 1 / (4 * int(r["steps"]) + 2)  # L = 1
        proven = float(r["tau_proven"])
        assert exact <= proven <= exact * (1 + 1e-5)
        doc = json.loads((tmp_path / r["document"]).read_text())  # the row's own file
        assert float(Fraction(doc["certificate"]["tau_proven"])) == proven


def test_pepit_nesterov_example_gets_a_proof_and_a_witness(tmp_path):
    """PEPit's accelerated-gradient example (x_0 = y_0, initial f(x_0) - f* + m/2
    |x_0 - x*|^2): y_0 = x_0 holds only symbolically (beta is irrational), and is carried
    exactly, so the worst case gets its exact proof and a verified witness; the witness
    reads f at x_0 from the call y_0, and verify vouches for the document."""
    from .conftest import spec_path

    res = run(["pep", spec_path("nesterov"), "--kappa", "10", "--steps", "2", "--initial",
               "f + m/2*dist", "--out", tmp_path, "--json", "--no-plot"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    proven = Fraction(doc["certificate"]["tau_proven"])
    wit = doc["witness"]
    assert wit["check"]["verified"] and wit["evaluations"]["x0|f"] == "y0"
    lower = Fraction(wit["check"]["tau_lower"])
    assert lower <= proven <= lower * Fraction(1001, 1000)
    assert doc["class"]["m"] == "1" and doc["class"]["L"] == "10"
    path = tmp_path / "doc.json"
    path.write_text(json.dumps(doc))
    assert run(["verify", path]).exit_code == 0  # its own source, no --spec
    assert run(["verify", tmp_path / "nesterov-pep-k10-N2-witness.json"]).exit_code == 0


def test_kappa_is_the_decimal_it_was_given_as(tmp_path):
    """--kappa 10.1 proves about kappa = 101/10 (not the binary float), L = kappa m."""
    import sosalgo
    from sosalgo.spec import spec_from_text

    spec = spec_from_text(SPEC, str(tmp_path / "tenth.yaml"))
    res = sosalgo.pep(spec, 10.1, 1, witness=False)
    cls = res.certificate["proof"]["class"]
    assert (cls["kappa"], cls["m"], cls["L"]) == ("101/10", "1/10", "101/100")
    assert cls["functions"]["f"]["params"] == {"m": "1/10", "L": "101/100"}
