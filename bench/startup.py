"""Start-up and per-rate cost of the command line, as a user runs it.

- one-kappa ``sosalgo analyze specs/nesterov.yaml --kappa 10`` wall time, median of a few
  runs in fresh processes (target: <= 0.5 s), and a two-kappa run that draws the figure;
- marginal cost per rate in a CLI sweep: (time for N kappas - time for 1 kappa) / (N - 1),
  serial (``--workers 1``) and with the default workers (target: <= 4 ms);
- parsing 241 ``--kappa`` values.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "specs" / "nesterov.yaml"
TARGET_ONE = 0.5
TARGET_MARGINAL = 0.004
# what a numeric analysis cannot avoid: arrays, the solver (which loads scipy's BLAS), YAML, CLI
FLOOR = "import numpy, scipy.sparse, scipy.linalg.cython_blas, clarabel, yaml, click"


def _wall(args: list[str], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as out:
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "sosalgo.cli", *args]
                           + ([] if args == ["--version"] else ["--out", out]),
                           check=True, capture_output=True)
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _python(code: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True)
    return time.perf_counter() - t0


def _kappa_args(n: int) -> list[str]:
    return ["--kappa", f"{{from: 1.5, to: 1000, points: {n}, scale: log}}"]


def run(quick: bool = False) -> None:
    reps = 3 if quick else 5
    base = ["analyze", str(SPEC), "--quiet"]
    imp = _wall(["--version"], reps)
    floor = statistics.median(_python(FLOOR) for _ in range(reps))
    sympy = statistics.median(_python("import sympy") for _ in range(reps))
    one = _wall([*base, "--kappa", "10"], reps)
    two_plot = _wall([*base, "--kappa", "10", "--kappa", "100"], reps)
    n = 61 if quick else 241
    rows = [("`sosalgo --version` (imports of the CLI)", imp, None),
            ("floor: `import numpy, scipy.sparse, clarabel, yaml, click`", floor, None),
            ("for comparison: `import sympy` (not loaded by analysis)", sympy, None),
            ("one-kappa analyze (no figure for one kappa)", one, TARGET_ONE),
            ("two-kappa analyze with figure (PNG + PDF)", two_plot, None)]
    for label, extra in (("--workers 1", ["--workers", "1"]), ("default workers", [])):
        t1 = _wall([*base, "--kappa", "10", "--no-plot", *extra], 1 if quick else 3)
        tn = _wall([*base, *_kappa_args(n), "--no-plot", *extra], 1)
        rows.append((f"marginal cost per rate, {n}-kappa sweep, {label}", (tn - t1) / (n - 1),
                     TARGET_MARGINAL))
    from sosalgo.spec import parse_kappa

    many = [f"{1.5 + i * 0.5:g}" for i in range(241)]
    t0 = time.perf_counter()
    parse_kappa(many, "bench", "kappa")
    rows.append(("parse 241 `--kappa` strings (in process)", time.perf_counter() - t0, None))
    print("| measurement | seconds | target | met |")
    print("|---|---:|---:|:-:|")
    for label, t, target in rows:
        met = "" if target is None else ("yes" if t <= target else "no")
        tgt = "" if target is None else f"{target:g}"
        print(f"| {label} | {t:.4f} | {tgt} | {met} |", flush=True)


if __name__ == "__main__":
    run(quick="--quick" in sys.argv)
