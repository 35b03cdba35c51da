"""Calibration of the run-budget model (:mod:`sosalgo.kernel.budget`): peak resident memory and
wall seconds of PEPs at several N (the exact proof, with or without the witness), and the
parent's memory per grid point, each measured in a fresh process, beside what the model
says (``python -m bench --only budget``).

When the code changes how much a PEP or a grid point costs, rerun this and update the
constants at the top of ``sosalgo/kernel/budget.py`` (the fitted values are printed). Seconds
depend on the machine's load: calibrate on an idle machine."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile

# (spec, measure or None for the spec's default, steps, witness): gradient descent keeps
# a band of neighbouring pairs (small solver memory), Nesterov's pattern turns dense past
# N = 40 (the largest memory per pair), accelerated proximal gradient is the composite
# case; the witness's primal solve grows like d^4.
PEP_CASES = (("gradient", "dist", (50, 100, 150, 200), False),
             ("nesterov", None, (10, 30, 50, 70), False),
             ("accelerated-proximal-gradient", None, (5, 10, 20), False),
             ("gradient", "dist", (50, 100), True), ("nesterov", None, (30,), True))
QUICK_PEP = (("gradient", "dist", (10, 50), False), ("nesterov", None, (20,), False),
             ("gradient", "dist", (30,), True))

PEP_CHILD = """
import json, sys, time
from sosalgo.worstcase.core import pep, pep_problem
from sosalgo.spec import load_spec
spec, N = load_spec(f"specs/{sys.argv[1]}.yaml"), int(sys.argv[2])
measure, witness = sys.argv[3] or None, sys.argv[4] == "1"
kappa = None if spec.sublinear else 10.0
_, st, *_ = pep_problem(spec, kappa, N, measure)
t0 = time.perf_counter()
pep(spec, kappa, N, measure, witness=witness)
hwm = [int(x.split()[1]) for x in open('/proc/self/status') if x.startswith('VmHWM:')][0]
print(json.dumps({"pairs": len(st.pairs), "d": st.d, "seconds": time.perf_counter() - t0,
                  "bytes": hwm * 1024}))
"""

GRID_CHILD = """
import json, sys
import sosalgo.batch.sweeps as sw

def fake(spec_text, source, options, chunk):  # the row of a real point, no solve
    return [{"kappa": t["kappa"], **t["theta"], "rho": 0.99798004799, "certified": True,
             "lambda": 72.727369121, "max_eig_M": -0.0036478382, "min_eig_P": 14750.23001,
             "solves": 4, "seconds": 0.001528, "solver": "clarabel-margin", "error": "",
             **{f"P{i}{j}": 14750.230013886605 for i in (1, 2) for j in (1, 2) if i <= j}}
            for t in chunk]

sw.grid_chunk = fake
from sosalgo.runs import grid_run
doc = grid_run("specs/three-parameter.yaml", [10.0], sys.argv[2], points=int(sys.argv[1]),
               workers=1, progress=False)
hwm = [int(x.split()[1]) for x in open('/proc/self/status') if x.startswith('VmHWM:')][0]
print(json.dumps({"bytes": hwm * 1024}))
"""


def _child(code: str, *args: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _pep_rows(cases) -> list[dict]:
    from sosalgo.kernel import budget

    rows = []
    for spec, measure, steps, witness in cases:
        for n in steps:
            got = _child(PEP_CHILD, spec, str(n), measure or "", "1" if witness else "0")
            units = got["pairs"] * got["d"]
            model_bytes, model_s = budget.pep_task(got["pairs"], got["d"], witness)
            above = got["bytes"] - budget.PEP_BASE_BYTES
            rows.append({"spec": spec, "N": n, "witness": witness, "d": got["d"], "K*d": units,
                         "MiB": got["bytes"] / 2**20,
                         "model MiB": model_bytes / 2**20, "B/Kd": above / units,
                         "s": got["seconds"], "model s": model_s,
                         "model/measured": model_bytes / got["bytes"]})
    return rows


def _fit(rows: list[dict]) -> tuple[float, float]:
    """Least squares of log seconds against log units: (coefficient, exponent)."""
    xs = [math.log(r["K*d"]) for r in rows]
    ys = [math.log(r["s"]) for r in rows]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sxx if sxx else 1.0
    return math.exp(my - b * mx), b


def run(quick: bool = False) -> None:
    from sosalgo.kernel import budget
    from sosalgo.report import format_table

    rows = _pep_rows(QUICK_PEP if quick else PEP_CASES)
    print(format_table([{k: (f"{v:.3g}" if isinstance(v, float) else v) for k, v in r.items()}
                        for r in rows], list(rows[0])))
    big = [r for r in rows if r["K*d"] >= 1e5 and not r["witness"]]
    if len(big) >= 2:
        coef, expo = _fit(big)
        print(f"fitted: PEP_SECONDS = {coef:.2g}, PEP_EXPONENT = {expo:.2f} "
              f"(now {budget.PEP_SECONDS:g}, {budget.PEP_EXPONENT:g})")
    per_kd = [r["B/Kd"] for r in rows if not r["witness"] and r["K*d"] >= 1e5]
    print(f"memory: largest B/Kd {max(per_kd, default=float('nan')):.0f} at K*d >= 1e5 "
          f"(PEP_BYTES_PER_KD now {budget.PEP_BYTES_PER_KD:g}); model/measured must stay "
          "at least 1 (a safe over-estimate) on every row")
    seen = [(r["B/Kd"] - budget.PEP_BYTES_PER_KD) * r["K*d"] / r["d"] ** 4 for r in rows
            if r["witness"] and r["d"] >= 30]
    if seen:
        print(f"witness: at most {max(seen):.1f} B per d^4 above the proof's model "
              f"(PEP_WITNESS_BYTES_PER_D4 now {budget.PEP_WITNESS_BYTES_PER_D4:g})")
    sizes = (10, 20) if quick else (20, 40)
    peaks = []
    for p in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            peaks.append(_child(GRID_CHILD, str(p), tmp)["bytes"])
    per = (peaks[1] - peaks[0]) / (sizes[1] ** 3 - sizes[0] ** 3)
    print(f"grid: {per:.0f} bytes per point in the parent (GRID_BYTES_PER_POINT now "
          f"{budget.GRID_BYTES_PER_POINT:g}); peak {peaks[0] / 2**20:.0f} MiB at "
          f"{sizes[0] ** 3} points (BASE_BYTES now {budget.BASE_BYTES / 2**20:.0f} MiB)")
