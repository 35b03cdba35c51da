"""Conformance against PEPit's examples: ``python -m bench.conformance`` (or ``python -m bench
--only conformance``).

Every PEPit example has one case file (:mod:`bench.conformance.cases`). For each expressed
case and argument set, PEPit runs the example's own ``wc_`` function in its interpreter (a
subprocess, one at a time, niced, with a timeout; found as :mod:`bench.pepit` finds it) with
Clarabel, and sosalgo runs the case's command as a user types it (``sosalgo pep ... --json``,
the whole command timed: start-up, SDP, exact proof and witness). A CSV row is written as each
pair finishes (``results.csv`` here, resumed unless ``--restart``); ``--table`` rewrites the
docs table (``docs/conformance.md``) from the case files and that CSV without running
anything.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

from bench.conformance.cases import HERE, Case, arguments_text, load_all

ROOT = HERE.parents[1]
RESULTS = HERE / "results.csv"
COLUMNS = ("example", "set", "arguments", "command", "pepit_tau", "theoretical_tau",
           "pepit_seconds", "pepit_process_seconds", "pepit_error", "scale", "tau", "tau_proven",
           "check_kind", "witness_verified", "tau_lower", "sosalgo_seconds", "sosalgo_error",
           "agree", "not_below", "above_theoretical", "time_ratio")
AGREE_REL = 1e-6     # sosalgo's tau and PEPit's agree within this (relative)
BELOW_REL = 1e-7     # a proven bound may be below PEPit's float value by its solver's accuracy
ZERO_ABS = 1e-6     # where the worst case is exactly 0: agreement within this (absolute)
TIGHT_REL = 1e-12    # a proven bound is never below a tight theoretical value (float rounding)
SECONDS = float(os.environ.get("SOSALGO_CONFORMANCE_SECONDS", "600"))

# Runs in PEPit's interpreter: one example at one argument set, one JSON line out.
PEPIT_WORKER = r'''
import importlib, inspect, json, sys, time, warnings
warnings.simplefilter("ignore")
path, function, args, solver = json.loads(sys.argv[1])
fn = getattr(importlib.import_module("PEPit.examples." + path.replace("/", ".")), function)
accepted = inspect.signature(fn).parameters  # one example takes neither wrapper nor solver
extra = {"wrapper": "cvxpy", "solver": solver, "verbose": -1}
t0 = time.perf_counter()
tau, theoretical = fn(**args, **{k: v for k, v in extra.items() if k in accepted})
print(json.dumps({"tau": tau, "theoretical": theoretical, "seconds": time.perf_counter() - t0}))
'''


def run_pepit(python: str, case: Case, index: int) -> dict:
    job = [case.example, case.function, case.arguments[index], "CLARABEL"]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    t0 = time.perf_counter()
    try:
        out = subprocess.run(["nice", python, "-c", PEPIT_WORKER, json.dumps(job)],
                             capture_output=True, text=True, timeout=SECONDS, env=env)
    except subprocess.TimeoutExpired:
        return {"error": f"over {SECONDS:g} s"}
    lines = out.stdout.strip().splitlines()
    if out.returncode or not lines:
        return {"error": ((out.stderr.strip().splitlines() or ["no output"])[-1])[:100]}
    return {**json.loads(lines[-1]), "process_seconds": time.perf_counter() - t0}


def sosalgo_command() -> list[str]:
    entry = Path(sys.executable).with_name("sosalgo")
    return [str(entry)] if entry.exists() else [sys.executable, "-c",
                                                 "from sosalgo.cli import main; main()"]


def run_sosalgo(case: Case, index: int, out_dir: Path) -> dict:
    argv = sosalgo_command() + case.command(index) + [
        "--json", "--out", str(out_dir), "--no-plot", "--quiet", "--restart"]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    t0 = time.perf_counter()
    try:
        out = subprocess.run(["nice"] + argv, capture_output=True, text=True,
                             timeout=SECONDS, cwd=ROOT, env=env)
    except subprocess.TimeoutExpired:
        return {"error": f"over {SECONDS:g} s"}
    seconds = time.perf_counter() - t0
    if out.returncode:
        return {"error": ((out.stderr.strip().splitlines() or ["exit code"])[-1])[:100]}
    doc = json.loads(out.stdout)
    row = doc["rows"][-1] if "rows" in doc else doc
    return {"seconds": seconds, **pep_values(row)}


def pep_values(row: dict) -> dict:
    """tau, tau_proven (float), check kind, witness verified and lower bound of a pep row."""
    from fractions import Fraction

    cert, witness = row.get("certificate") or {}, row.get("witness") or {}
    proven = cert.get("tau_proven")
    check = witness.get("check") or {}
    return {"tau": row.get("tau"), "tau_proven": float(Fraction(proven)) if proven else None,
            "check_kind": cert.get("check_kind", ""),
            "witness_verified": bool(check.get("verified")),
            "tau_lower": check.get("tau_lower_float")}


def verdicts(case: Case, index: int, pepit: dict, ours: dict) -> dict:
    """agree, not_below, above_theoretical ("yes", "no", or "" when not applicable).

    Where the theoretical value is tight it is the true worst case and PEPit's float is
    an approximation of it: our tau agrees when it is within AGREE_REL of either, and a
    proven bound is not below when it is not below the lower of the two (beyond
    BELOW_REL; above_theoretical still asks for the tight value itself)."""
    if not case.expressed:
        return {"agree": "", "not_below": "", "above_theoretical": ""}
    scale = case.scale_at(index)
    p, tau, proven = pepit.get("tau"), ours.get("tau"), ours.get("tau_proven")
    theo = pepit.get("theoretical")
    tight = theo if case.tight[index] and theo is not None else None
    refs = [r for r in (p, tight) if r is not None]
    out = {"agree": "", "not_below": "", "above_theoretical": ""}
    # a worst case of exactly 0 (case.zero): PEPit's float is its solver's accuracy
    floor = ZERO_ABS if case.zero else 1e-300
    if p is not None and tau is not None:
        out["agree"] = _yes(any(abs(scale * tau - r) <= max(AGREE_REL * abs(r), floor)
                                for r in refs))
    if p is not None and proven is not None:
        low = min(refs)
        out["not_below"] = _yes(scale * proven >= low - max(BELOW_REL * abs(low), floor))
    if tight is not None and proven is not None:
        out["above_theoretical"] = _yes(scale * proven >= tight - TIGHT_REL * abs(tight))
    return out


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def result_row(case: Case, index: int, pepit: dict, ours: dict) -> dict:
    ratio = (ours["seconds"] / pepit["seconds"]
             if ours.get("seconds") and pepit.get("seconds") else None)
    return {"example": case.example, "set": index,
            "arguments": arguments_text(case.arguments[index]),
            "command": _command_text(case, index),
            "pepit_tau": pepit.get("tau"), "theoretical_tau": pepit.get("theoretical"),
            "pepit_seconds": pepit.get("seconds"),
            "pepit_process_seconds": pepit.get("process_seconds"),
            "pepit_error": pepit.get("error", ""),
            "scale": case.scale_at(index) if case.expressed else None, "tau": ours.get("tau"),
            "tau_proven": ours.get("tau_proven"), "check_kind": ours.get("check_kind", ""),
            "witness_verified": ours.get("witness_verified", ""),
            "tau_lower": ours.get("tau_lower"),
            "sosalgo_seconds": ours.get("seconds"), "sosalgo_error": ours.get("error", ""),
            **verdicts(case, index, pepit, ours), "time_ratio": ratio}


def _command_text(case: Case, index: int) -> str:
    if not case.expressed:
        return ""
    return "sosalgo " + " ".join(_quote(a) for a in case.command(index))


def _quote(arg: str) -> str:
    return f'"{arg}"' if any(c in arg for c in " *()[]") else arg


def read_results(path: Path = RESULTS) -> dict[tuple[str, int], dict]:
    if not path.exists():
        return {}
    with path.open(newline="") as fh:
        return {(r["example"], int(r["set"])): r for r in csv.DictReader(fh)}


def run_cases(cases: list[Case], python: str, path: Path, restart: bool, quick: bool) -> None:
    """Each case at each argument set (``quick``: the defaults), sosalgo only on expressed
    ones; a row already in ``path`` for the same arguments is kept (unless ``restart``)."""
    done = {} if restart else read_results(path)
    out_dir = Path(os.environ.get("SOSALGO_CONFORMANCE_OUT", "/tmp/sosalgo-conformance"))
    rows = dict(done)
    for case in cases:
        for index in range(1 if quick else len(case.arguments)):
            key = (case.example, index)
            old = done.get(key)
            if old and old["arguments"] == arguments_text(case.arguments[index]) \
                    and old["command"] == _command_text(case, index) \
                    and not old["pepit_error"] and not old["sosalgo_error"]:
                continue
            pepit = run_pepit(python, case, index)
            ours = (run_sosalgo(case, index, out_dir / case.example.replace("/", "-") / str(index))
                    if case.expressed else {})
            rows[key] = result_row(case, index, pepit, ours)
            write_results(rows, path)
            print(summary(rows[key]), flush=True)


def write_results(rows: dict, path: Path) -> None:
    tmp = path.with_suffix(".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for key in sorted(rows):
            writer.writerow({k: _cell(rows[key].get(k)) for k in COLUMNS})
    tmp.replace(path)


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def summary(row: dict) -> str:
    """One line per finished pair: PEPit's tau, ours proven (times the scale), verdicts."""
    if not row["command"]:
        return f"{row['example']} [{row['set']}] PEPit {row['pepit_tau'] or row['pepit_error']}"
    proven = row["tau_proven"]
    ours = f"{proven * row['scale']:.9g}" if proven is not None else row["sosalgo_error"]
    pepit = f"{row['pepit_tau']:.9g}" if row["pepit_tau"] is not None else row["pepit_error"]
    ratio = f"{row['time_ratio']:.1f}" if row["time_ratio"] else "-"
    return (f"{row['example']} [{row['set']}] PEPit {pepit} ours proven {ours} "
            f"agree={row['agree']} not_below={row['not_below']} time ratio {ratio}")


def run(quick: bool = False, restart: bool = False, only: str | None = None,
        path: Path = RESULTS, every: bool = False) -> None:
    """The bench suite: every expressed case (``quick``: the defaults only; ``every``: PEPit
    alone on the examples not expressed too, so that their values are on record)."""
    from bench.pepit import pepit_python

    python, origin = pepit_python()
    if python is None:
        print(f"skipped: {origin}")
        return
    cases = [c for c in load_all()
             if (c.expressed or every) and (not only or only in c.example)]
    expressed = sum(c.expressed for c in cases)
    print(f"PEPit from {origin}; {len(cases)} cases ({expressed} expressed); results in {path}",
          flush=True)
    run_cases(cases, python, path, restart, quick)
    from bench.conformance.table import write_docs

    write_docs()


def rejudge(path: Path = RESULTS) -> None:
    """The verdicts of every committed row again, from its stored values, by the current
    :func:`verdicts` (nothing is run)."""
    cases = {c.example: c for c in load_all()}
    rows = read_results(path)
    for (example, index), row in rows.items():
        case = cases.get(example)
        if case is None or index >= len(case.arguments):
            continue
        pepit = {"tau": _number(row["pepit_tau"]), "theoretical": _number(row["theoretical_tau"])}
        ours = {"tau": _number(row["tau"]), "tau_proven": _number(row["tau_proven"])}
        row.update(verdicts(case, index, pepit, ours))
    write_results(rows, path)


def _number(cell: str) -> float | None:
    return float(cell) if cell not in ("", None) else None


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.conformance")
    parser.add_argument("--quick", action="store_true", help="the examples' defaults only")
    parser.add_argument("--restart", action="store_true", help="run again every row")
    parser.add_argument("--only", default=None, help="the examples whose path contains this")
    parser.add_argument("--all", action="store_true", dest="every",
                        help="also run PEPit alone on the examples not expressed")
    parser.add_argument("--table", action="store_true",
                        help="only rewrite the docs table from the case files and results")
    parser.add_argument("--rejudge", action="store_true",
                        help="only recompute the verdicts of the committed rows")
    args = parser.parse_args()
    if args.rejudge:
        rejudge()
    if args.table or args.rejudge:
        from bench.conformance.table import write_docs

        write_docs()
        return
    run(quick=args.quick, restart=args.restart, only=args.only, every=args.every)
