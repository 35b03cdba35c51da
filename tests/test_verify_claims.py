"""Verification never passes what it cannot check: missing or malformed
certificates, non-symmetric P, NaN checks, large errors in the test functions, results
that moved or whose spec changed."""

from __future__ import annotations

import copy
import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from sosalgo.analysis import analyze_spec
from sosalgo.cli import cli
from sosalgo.proofs.functions import _lse_excess, _softmax_minus_p, logsumexp
from sosalgo.spec import spec_from_text

from .conftest import SPECS

GRADIENT = SPECS / "gradient-optimal.yaml"


def run(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("res")
    res = run(["analyze", GRADIENT, "--kappa", "10", "--out", out, "--json", "--quiet",
               "--no-plot", "--certificate", "theorem1"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def verify_doc(tmp_path, doc, *extra):
    path = tmp_path / "r.json"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return run(["verify", path, "--out", tmp_path, "--no-simulate", *extra])


@pytest.mark.parametrize("field", ["P", "lambda"])
@pytest.mark.parametrize("how", ["null", "removed"])
def test_certified_row_without_p_or_lambda_fails(tmp_path, result, field, how):
    doc = copy.deepcopy(result)
    if how == "null":
        doc["rows"][0][field] = None
    else:
        del doc["rows"][0][field]
    res = verify_doc(tmp_path, doc)
    assert res.exit_code == 3, res.output
    assert "missing" in res.stdout


def test_non_symmetric_p_is_refused_not_symmetrized(tmp_path):
    spec_text = (SPECS / "nesterov.yaml").read_text()
    res = run(["analyze", SPECS / "nesterov.yaml", "--kappa", "10", "--out", tmp_path,
               "--json", "--quiet", "--no-plot", "--certificate", "theorem1"])
    doc = json.loads(res.stdout)
    P = np.array(doc["rows"][0]["P"])
    P[0, 1] += 1e-3 * abs(P[0, 1]) + 1e-6  # P12 != P21
    doc["rows"][0]["P"] = P.tolist()
    res = verify_doc(tmp_path, doc)
    assert res.exit_code == 3 and "not symmetric" in res.stdout
    assert spec_text  # the embedded spec was used, not re-read


@pytest.mark.parametrize("mutate", [
    lambda r: r.__setitem__("P", "[[1]]"),
    lambda r: r.__setitem__("P", [[1.0, 2.0]]),
    lambda r: r.__setitem__("lambda", "0.5"),
    lambda r: r.__setitem__("rho", [0.5]),
    lambda r: r.__setitem__("kappa", "10"),
    lambda r: r.__setitem__("certified", "yes"),
])
def test_malformed_rows_are_exit_2_with_one_line(tmp_path, result, mutate):
    doc = copy.deepcopy(result)
    mutate(doc["rows"][0])
    res = verify_doc(tmp_path, doc)
    assert res.exit_code == 2, res.output
    assert res.stderr.count("\n") == 1 and "rows[0]" in res.stderr
    assert not (tmp_path / "certificates").exists()


def test_deeply_nested_json_is_exit_2(tmp_path):
    res = verify_doc(tmp_path, "[" * 100_000 + "]" * 100_000)
    assert res.exit_code == 2 and res.stderr.count("\n") == 1


def test_nan_check_never_certifies():
    text = GRADIENT.read_text().replace("name: gradient-optimal", "name: g\nm: 1e300")
    spec = spec_from_text(text)
    res = analyze_spec(spec, 4.0)
    # either a finite, checked certificate or none at all: never max_eig_M = nan
    assert (not res.certified) or (np.isfinite(res.max_eig_M) and res.max_eig_M <= 0)


def test_logsumexp_pieces_are_finite_at_large_errors():
    p = np.array([1.0, 0.0, 0.0])  # an underflowed softmax
    w = np.array([[-800.0, 10.0, 5.0], [3e3, -1e3, 0.0]])
    g = _softmax_minus_p(w, p)
    assert np.all(np.isfinite(g))
    # exact: p = e_1, so softmax(a + w) - p = e_1 - e_1 = 0 (the other weights stay 0)
    assert np.allclose(g, 0.0)
    D = _lse_excess(w, p)
    assert np.all(np.isfinite(D)) and np.allclose(D, 0.0)
    rng = np.random.default_rng(0)
    f = logsumexp(3, rng, 1.0, 1e6)
    z = rng.standard_normal((4, 3)) * 1e4
    assert np.all(np.isfinite(f.grad_z(z))) and np.all(np.isfinite(f.gap(z)))


def test_large_kappa_certificate_passes_both_commands_alike(tmp_path):
    res = run(["analyze", SPECS / "nesterov.yaml", "--kappa", "1e6", "--out", tmp_path,
               "--json", "--quiet", "--no-plot", "--verify"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["rows"][0]["verification"]["simulation"]["ok"]
    path = tmp_path / "r.json"
    path.write_text(res.stdout)
    again = run(["verify", path, "--out", tmp_path])
    assert again.exit_code == 0, again.output


def test_analyze_verify_exits_3_like_verify_on_a_failing_check(tmp_path, monkeypatch):
    import sosalgo.proofs.results as verification

    def fake(*a, **k):
        return {"kappa": 10.0, "rho": 0.5, "verified": "failed", "rho_proven": None,
                "rho_proven_float": None, "delta": None, "reason": "test"}

    monkeypatch.setattr(verification, "verify_family_certificate", fake)
    res = run(["analyze", GRADIENT, "--kappa", "10", "--out", tmp_path, "--quiet",
               "--no-plot", "--verify"])
    assert res.exit_code == 3


def test_verify_after_moving_the_result_and_editing_the_spec(tmp_path):
    spec = tmp_path / "spec.yaml"
    shutil.copy(GRADIENT, spec)
    res = run(["analyze", spec, "--kappa", "10", "--out", tmp_path, "--json", "--quiet",
               "--no-plot"])
    assert res.exit_code == 0
    elsewhere = tmp_path / "moved"
    elsewhere.mkdir()
    (elsewhere / "r.json").write_text(res.stdout)
    spec.write_text(spec.read_text().replace("value:", "value: 0.5 *"))  # a later edit
    res = run(["verify", elsewhere / "r.json", "--out", elsewhere, "--no-simulate"])
    assert res.exit_code == 0, res.output
    spec.unlink()
    res = run(["verify", elsewhere / "r.json", "--out", elsewhere, "--no-simulate"])
    assert res.exit_code == 0, res.output


def test_certificate_files_never_collide(tmp_path):
    for k in ("100", "100.00001"):
        res = run(["analyze", GRADIENT, "--kappa", k, "--out", tmp_path / k, "--json",
                   "--quiet", "--no-plot", "--certificate", "theorem1"])
        (tmp_path / f"{k}.json").write_text(res.stdout)
        assert run(["verify", tmp_path / f"{k}.json", "--out", tmp_path,
                    "--no-simulate"]).exit_code == 0
    files = sorted(p.name for p in (tmp_path / "certificates").iterdir())
    assert files == ["gradient-optimal-k100-certificate.json",
                     "gradient-optimal-k100.00001-certificate.json"]
    # another certificate at the same kappa (an edited copy with the same name) gets its own
    edited = tmp_path / "e.yaml"
    edited.write_text(GRADIENT.read_text().replace("kappa: [", "kappa: [3, "))
    res = run(["analyze", edited, "--kappa", "100", "--out", tmp_path / "e", "--json",
               "--quiet", "--no-plot", "--tol", "1e-4", "--certificate", "theorem1"])
    (tmp_path / "e.json").write_text(res.stdout)
    assert run(["verify", tmp_path / "e.json", "--out", tmp_path, "--no-simulate"]).exit_code == 0
    assert len(list((tmp_path / "certificates").iterdir())) == 3
