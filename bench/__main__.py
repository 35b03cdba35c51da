"""Run every benchmark and print the tables: ``python -m bench [--quick] [--only NAME]``."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# Every suite is a module of this package with ``run(quick)``; AutoLyap and PEPit run in a
# subprocess (their suites skip with one line when they are not installed).
SUITES = ("startup", "analysis", "design", "design_steps", "grid", "interpolation", "fallback",
          "noise", "pep", "pep_scaling", "pep_time_varying", "pep_accuracy", "autolyap",
          "autolyap_operators", "pepit", "conformance", "budget")


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench")
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--only", default=None, help="run only this benchmark")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    for name in SUITES:
        if args.only and name != args.only:
            continue
        run = importlib.import_module(f"bench.{name}").run
        print(f"\n## {name}\n", flush=True)
        run(quick=args.quick)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
