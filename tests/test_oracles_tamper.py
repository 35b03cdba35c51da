"""``sosalgo verify`` on the witnesses of inexact calls, exact line search and the
contraction measure: every claim field tampered is refused (the harness of
``test_pep_tamper``), honest ones verify."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from .test_pep_tamper import is_claim, leaves, put, run, tampered, verify

SPECS = Path(__file__).resolve().parents[1] / "specs"
CASES = {  # spec: (steps, extra options)
    "inexact-gradient": (1, ()),
    "gradient-line-search": (1, ()),
    "douglas-rachford-contraction": (1, ()),
}


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    out = {}
    for name, (steps, extra) in CASES.items():
        where = tmp_path_factory.mktemp(name)
        res = run(["pep", SPECS / f"{name}.yaml", "--kappa", "10", "--steps", steps, "--out",
                   where, "--json", "--no-plot", *extra])
        assert res.exit_code == 0, res.output
        wit = json.loads((where / f"{name}-pep-k10-N{steps}-witness.json").read_text())
        out[name] = (SPECS / f"{name}.yaml", json.loads(res.stdout), wit)
    return out


@pytest.mark.parametrize("name", list(CASES))
def test_honest_documents_verify(tmp_path, made, name):
    spec, doc, wit = made[name]
    for d in (doc, wit):
        res = verify(tmp_path, spec, d)
        assert res.exit_code == 0, res.output


@pytest.mark.parametrize("name", list(CASES))
def test_every_witness_claim_tampered_is_refused(tmp_path, made, name):
    spec, _, wit = made[name]
    fields = [(p, v) for p, v in leaves(wit) if is_claim(p)]
    assert len(fields) > 10
    passed = []
    for path, value in fields:
        doc = copy.deepcopy(wit)
        put(doc, path, tampered(value))
        if verify(tmp_path, spec, doc).exit_code not in (2, 3):
            passed.append(path)
    assert not passed


@pytest.mark.parametrize("name", list(CASES))
def test_every_row_claim_tampered_is_refused(tmp_path, made, name):
    spec, doc, _ = made[name]
    fields = [(p, v) for p, v in leaves(doc) if is_claim(p)  # the witness: walked above;
              and p[0] not in ("witness", "estimate")]  # the run's memory estimate
    assert len(fields) > 5
    passed = []
    for path, value in fields:
        d = copy.deepcopy(doc)
        put(d, path, tampered(value))
        if verify(tmp_path, spec, d).exit_code not in (2, 3):
            passed.append(path)
    assert not passed
