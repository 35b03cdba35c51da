"""Run every benchmark and print the tables: ``python -m bench [--quick] [--only NAME]``."""

from __future__ import annotations

import argparse
import os
import sys

from bench import analysis, startup


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench")
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--only", default=None, help="run only this benchmark")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    suites = {"startup": startup.run, "analysis": analysis.run}
    try:  # later issues add suites; absent modules are skipped, not faked
        from bench import design

        suites["design"] = design.run
    except ImportError:
        pass
    try:
        from bench import grid

        suites["grid"] = grid.run
    except ImportError:
        pass
    try:
        from bench import interpolation

        suites["interpolation"] = interpolation.run
    except ImportError:
        pass
    try:
        from bench import noise

        suites["noise"] = noise.run
    except ImportError:
        pass
    try:
        from bench import pep

        suites["pep"] = pep.run
    except ImportError:
        pass
    try:  # AutoLyap itself runs in a subprocess; the suite skips with one line without it
        from bench import autolyap

        suites["autolyap"] = autolyap.run
    except ImportError:
        pass
    for name, fn in suites.items():
        if args.only and name != args.only:
            continue
        print(f"\n## {name}\n", flush=True)
        fn(quick=args.quick)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
