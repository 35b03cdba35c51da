"""N-step schedule designs (``python -m bench --only design_steps``): ``sosalgo design SPEC
--steps N`` on the shipped schedule specs, wall time, certified worst case, proven lower
bound and relative gap, beside the references: gradient descent's best known schedule
(OBS-F, Grimmer, Shu and Wang; its worst case from their rate, computed by
:func:`sosalgo.design_search.steps.obs_f`, inside the box only up to N = 3 with h <= 3/L)
and OGM's L/(2 theta_N^2) for the momentum family. One process per case, one worker
unless the case's options say ``--workers`` (gradient descent's per-step steps at
N = 1..4 also on ``--workers 2``: both cores prove the bound's boxes).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# (spec, N, extra options, time limit)
CASES = [("gradient-schedule", n, [], 600.0) for n in (1, 2, 3, 4)] + [
    ("gradient-schedule", n, ["--workers", "2"], 600.0) for n in (1, 2, 3, 4)] + [
    ("gradient-schedule", 10, ["--set", "h.range=[0, 7/L]"], 600.0)] + [
    ("momentum-schedule", n, [], 600.0) for n in (1, 2, 3, 4)]
QUICK = [("gradient-schedule", 2, [], 120.0), ("momentum-schedule", 1, [], 60.0)]


def _reference(spec: str, steps: int) -> str:
    from sosalgo.design_search.steps import obs_f, ogm_theta

    if spec == "momentum-schedule":
        return f"OGM {1 / (2 * ogm_theta(steps) ** 2):.10g}"
    return f"OBS-F {obs_f(steps)[1] / 2:.10g}"


def run(quick: bool = False) -> None:
    print("| spec | N | options | tau_certified | lower_bound | gap (rel.) | reference "
          "| seconds |")
    print("|---|---|---|---|---|---|---|---|")
    for spec, steps, extra, limit in QUICK if quick else CASES:
        with tempfile.TemporaryDirectory() as out:
            t0 = time.perf_counter()
            cli = str(Path(sys.executable).with_name("sosalgo"))
            res = subprocess.run(
                [cli, "design", f"specs/{spec}.yaml", "--steps", str(steps), *extra,
                 "--time-limit", str(limit), "--out", out, "--json", "--quiet",
                 *([] if "--workers" in extra else ["--workers", "1"])],
                capture_output=True, text=True)
            wall = time.perf_counter() - t0
        if res.returncode != 0:
            print(f"| {spec} | {steps} | {' '.join(extra)} | failed: "
                  f"{res.stderr.strip().splitlines()[-1:]} | | | | {wall:.0f} |")
            continue
        doc = json.loads(res.stdout)
        low, gap = doc.get("lower_bound"), doc.get("gap_relative")
        print(f"| {spec} | {steps} | {' '.join(extra)} | {doc['tau_certified']:.10g} | "
              f"{'—' if low is None else f'{low:.10g}'} | "
              f"{'—' if gap is None else f'{gap:.2g}'} | {_reference(spec, steps)} | "
              f"{wall:.0f} |", flush=True)
