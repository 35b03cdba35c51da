"""What a run may consume: its peak memory and wall time estimated before it starts, the
memory budget it must fit in (``--max-memory``) and the worker processes the machine allows.

A run whose estimate exceeds the budget is refused before anything is written (one line
naming the option that makes it large and ``--max-memory``); a large run says its estimate
in one line on stderr; ``--json`` documents carry it as ``estimate``. Local workers are
never more than the cores this process may use, nor more than the budget holds.

The estimates are models whose constants were measured on this code (peak RSS of a child
process by ``resource.getrusage``, wall seconds on a 2-core machine; rerun ``python -m
bench --only budget`` to measure them again and update the constants below). Memory aims at
a factor of two, enough to refuse a run that cannot fit; time is an indication of how
long a large run takes. Nothing is enforced while the run goes.
"""

from __future__ import annotations

import math
import os
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sosalgo.errors import InputError

__all__ = ["Estimate", "analysis_seconds", "announce_workers", "check", "cores",
           "default_max_memory", "design_estimate", "grid_estimate", "max_memory",
           "parse_memory", "pep_estimate", "pep_task", "plan_workers", "set_max_memory",
           "size_text", "sweep_estimate", "usable_workers"]

MiB = 2**20
GiB = 2**30

# -- measured constants (bench/budget.py) ----------------------------------------------
# One process with sosalgo, numpy, scipy, clarabel and matplotlib imported, after its
# first solves (a serial grid of 100 to 400 points peaks at 126 MiB).
BASE_BYTES = 130 * MiB
# A worker process of an analysis, grid or design sweep at its peak (fork-server child).
WORKER_BYTES = 160 * MiB
# One PEP process before its problem is built: Python, NumPy, SciPy, sympy, flint and
# Clarabel imported: a whole small PEP (the composite accelerated method at N = 4, with
# its witness) peaks at 112-118 MiB in a long-lived environment and at 132 MiB in a
# freshly installed one with the same package versions (CI's new virtualenv).
PEP_BASE_BYTES = 140 * MiB
# PEP with K interpolation pairs (all pairs the class allows: every ordered pair of the
# points a function is called at, with x*) and a Gram matrix of size d; for one function
# K = d (d - 1). Its memory above PEP_BASE_BYTES has two parts:
# - the data of every pair, built before the first solve: its rows on the basis (K x 4 x
#   d floats) and their products with G when violated pairs are searched: about 110 B
#   per K * d whatever the method (gradient descent, |x_N - x*|^2, peak RSS of a child
#   process: N = 50, 100, 150, 200: 122, 220, 470, 949 MiB, 93-113 B per K * d);
# - Clarabel's factorization on the pairs that become active. Which ones is decided
#   during the run (constraint generation), so it is not known before it: gradient
#   descent keeps a band of neighbouring pairs (the part above is all), Nesterov's worst
#   case needs far-apart pairs and its chordal pattern turns dense past N = 40, where its
#   cost grows like d^4 (N = 30, 50, 70: 127, 203, 441 MiB, 563, 704, 944 B per K * d;
#   N = 100 reached 1.0 GB before it was stopped after 27 minutes).
# The estimate takes the dense case (every pair may become active): PEP_BYTES_PER_KD is
# the measured 944 B per K * d at N = 70 grown like d up to N = 100 (d = 102; Nesterov
# takes more than 10 minutes there). It over-states a banded run
# (gradient descent N = 200 without witness: 10.3 GiB estimated, 0.93 GiB measured),
# which still starts under half of a 24 GiB machine.
PEP_BYTES_PER_KD = 1350.0
# The witness (on by default; --no-witness skips it) solves the PEP again in the primal
# form, whose PSD cone on the whole Gram matrix makes a dense KKT block of (d (d+1)/2)^2
# entries: about 13 B per d^4 above the rest (gradient descent, |x_N - x*|^2, N = 100:
# 1.49 GiB with the witness, 0.21 GiB without; N = 200 passed 9 GB and was stopped).
PEP_WITNESS_BYTES_PER_D4 = 16.0
# PEP wall seconds (SDP rounds and the exact proof) = PEP_SECONDS * (K d) ** PEP_EXPONENT,
# an indication between the banded and the dense case (gradient descent N = 200 30 s,
# Nesterov N = 70 66 s, N = 100 more than 10 minutes; accelerated proximal gradient
# N = 10 35 s, at load 9 on 2 cores). The witness (on by default) comes on top.
PEP_SECONDS = 1e-4
PEP_EXPONENT = 1.0
# A grid point held by the parent: its task, its CSV row and its JSON entry (a grid of
# 8000 and of 64000 points on three parameters: 3270 and 3173 bytes per point).
GRID_BYTES_PER_POINT = 3300.0
# Wall seconds of one certified rate (a grid point or an analyzed kappa) on one worker,
# for a method with n states: ANALYSIS_SECONDS * n ** ANALYSIS_EXPONENT (mean of the CSV's
# seconds: 0.009-0.011 for gradient descent, 0.015 for two-state methods).
ANALYSIS_SECONDS = 0.01
ANALYSIS_EXPONENT = 1.0
# Wall seconds of one certified constant of a sublinear spec (m = 0: a grid point, or the
# analysis, which adds its simulation): gradient descent on smooth convex f, 1.0-3.0 s
# per point at load 9 on 2 cores (about 0.5 s idle).
SUBLINEAR_SECONDS = 0.5
# -------------------------------------------------------------------------------------

LARGE_SECONDS = 60.0  # a run estimated longer than this says so in one line
LARGE_BYTES = 1 * GiB  # ... or one needing more memory than this

_BUDGET: int | None = None  # this process's --max-memory (None: the machine's default)


def _meminfo() -> dict[str, int]:
    """/proc/meminfo in bytes (empty where there is none)."""
    out: dict[str, int] = {}
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                key, _, rest = line.partition(":")
                parts = rest.split()
                if parts and parts[0].isdigit():
                    out[key] = int(parts[0]) * 1024
    except OSError:
        pass
    return out


def _cgroup_limit() -> int | None:
    """The memory limit of this process's cgroup (v2), when one is set."""
    try:
        with open("/sys/fs/cgroup/memory.max", encoding="ascii") as fh:
            text = fh.read().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def default_max_memory() -> int:
    """Half the machine's memory (or of its cgroup's limit): a run leaves room for
    everything else. Fixed for the machine, so that the same command behaves the same
    whatever else runs beside it."""
    total = _meminfo().get("MemTotal")
    if total is None:
        try:
            total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
            total = 8 * GiB
    limit = _cgroup_limit()
    total = min(total, limit) if limit else total
    return max(256 * MiB, total // 2)


_UNITS = {"": 1, "k": 2**10, "m": MiB, "g": GiB, "t": 2**40}
_SIZE = re.compile(r"([0-9]*\.?[0-9]+(?:e[+-]?[0-9]+)?)\s*([kmgt]?)(i?b)?")


def parse_memory(value: Any, label: str = "--max-memory") -> int:
    """Bytes of a size: a text such as ``8G``, ``512M``, ``1.5GiB``, ``4096B`` or ``8``
    (a bare number is GiB; units are powers of 1024), or a number of bytes."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        num, scale = float(value), 1
    else:
        hit = _SIZE.fullmatch(str(value).strip().lower())
        if hit is None:
            raise InputError(f"{label} {value}: expected a size such as 8G or 512M")
        unit, suffix = hit.group(2), hit.group(3)
        num, scale = float(hit.group(1)), _UNITS[unit] if unit or suffix else GiB
    if not math.isfinite(num) or num <= 0 or num * scale < 1:
        raise InputError(f"{label} {value}: must be a positive size such as 8G or 512M")
    return int(num * scale)


def set_max_memory(value: Any | None, label: str = "--max-memory") -> int:
    """Set this process's memory budget (None: the machine's default); returns it."""
    global _BUDGET
    _BUDGET = None if value is None else parse_memory(value, label)
    return max_memory()


def max_memory() -> int:
    """This process's memory budget in bytes."""
    return _BUDGET if _BUDGET is not None else default_max_memory()


def size_text(nbytes: float) -> str:
    """``1.5 GiB``, ``300 MiB``."""
    return f"{nbytes / GiB:.3g} GiB" if nbytes >= GiB else f"{nbytes / MiB:.0f} MiB"


def _time_text(sec: float) -> str:
    if sec < 90:
        return f"{sec:.0f} s"
    if sec < 5400:
        return f"{sec / 60:.0f} min"
    return f"{sec / 3600:.1f} h"


def cores() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def usable_workers(requested: int | None, per_worker: float = WORKER_BYTES) -> int:
    """Local worker processes: as requested (default: all cores), but never more than the
    cores, nor more than the memory budget holds beside this process."""
    return plan_workers(requested, per_worker)[0]


def plan_workers(requested: int | None, per_worker: float = WORKER_BYTES
                 ) -> tuple[int, str | None]:
    """(workers, a one-line note when fewer than requested were allowed, else None)."""
    n = cores()
    want = n if requested is None else max(1, int(requested))
    room = max(1, int((max_memory() - BASE_BYTES) // max(per_worker, 1.0)))
    got = min(want, n, room)
    if requested is None or got >= want:
        return got, None
    why = (f"the {n} cores this process may use" if got == n else
           f"--max-memory {size_text(max_memory())} at about {size_text(per_worker)} each")
    return got, f"note: --workers {want} capped to {got} ({why})"


@dataclass(frozen=True)
class Estimate:
    """A run's estimated peak memory (bytes, all its processes) and wall seconds."""

    what: str  # e.g. "pep nesterov N=1..100"
    option: str  # the option that makes the run large, e.g. "--steps 100"
    peak_bytes: float
    seconds: float
    workers: int = 1

    @property
    def large(self) -> bool:
        return self.seconds > LARGE_SECONDS or self.peak_bytes > LARGE_BYTES

    def line(self) -> str:
        """One line for stderr."""
        on = f" on {self.workers} workers" if self.workers > 1 else ""
        return (f"note: {self.what}: estimated {size_text(self.peak_bytes)} of memory "
                f"(--max-memory {size_text(max_memory())}) and {_time_text(self.seconds)}{on}")

    def to_dict(self) -> dict[str, Any]:
        """The ``estimate`` entry of a ``--json`` document."""
        return {"peak_memory_bytes": int(self.peak_bytes), "seconds": round(self.seconds, 1),
                "workers": self.workers, "max_memory_bytes": max_memory(),
                "model": "sosalgo.kernel.budget (measured constants; about a factor of two)"}


def check(est: Estimate, announce: bool = True) -> Estimate:
    """Refuse ``est`` (InputError naming its option and --max-memory) when it exceeds the
    budget; otherwise say it in one line on stderr when it is large."""
    budget = max_memory()
    if est.peak_bytes > budget:
        head, lower = "", ""  # a run no option makes large (one sublinear analysis)
        if est.option:
            head, lower = f"{est.option}: ", f"lower {est.option.split()[0]} or "
        raise InputError(f"{head}{est.what} needs about {size_text(est.peak_bytes)} "
                         f"of memory (estimate), over --max-memory {size_text(budget)}; "
                         f"{lower}raise --max-memory")
    if announce and est.large:
        sys.stderr.write(est.line() + "\n")
        sys.stderr.flush()
    return est


# -- the models --------------------------------------------------------------------------

def pep_task(pairs: int, d: int, witness: bool = True) -> tuple[float, float]:
    """(peak bytes of the worker, seconds) of one PEP with ``pairs`` interpolation pairs
    (all the class allows: an upper bound of those that become active) and a Gram matrix
    of size ``d``, with its witness unless ``witness`` is False."""
    units = float(pairs) * d
    peak = PEP_BASE_BYTES + PEP_BYTES_PER_KD * units
    if witness:
        peak += PEP_WITNESS_BYTES_PER_D4 * float(d) ** 4
    return peak, PEP_SECONDS * units**PEP_EXPONENT


def pep_estimate(what: str, option: str, sizes: Sequence[tuple[int, int]],
                 workers: int | None, witness: bool = True) -> tuple[Estimate, int]:
    """The estimate of a PEP run whose tasks have these (pairs, d) sizes (with their
    witnesses unless ``witness`` is False), and the workers it may use (each holds the
    largest task at once)."""
    tasks = sorted((pep_task(k, d, witness) for k, d in sizes), reverse=True)
    biggest = tasks[0][0] if tasks else BASE_BYTES
    w = min(announce_workers(workers, biggest), max(1, len(tasks)))
    peak = BASE_BYTES + sum(b for b, _ in tasks[:w])
    total = sum(s for _, s in tasks)
    seconds = max(total / w, max((s for _, s in tasks), default=0.0))
    return Estimate(what, option, peak, seconds, w), w


def analysis_seconds(states: int) -> float:
    """Seconds of one certified rate of a method with ``states`` states."""
    return ANALYSIS_SECONDS * max(1, states) ** ANALYSIS_EXPONENT


def grid_estimate(what: str, option: str, points: int, states: int,
                  workers: int | None, seconds_each: float | None = None) -> Estimate:
    """A grid of ``points`` points in all (every kappa); ``seconds_each``: a point's
    seconds when not a certified rate's (a sublinear spec's constant)."""
    w = usable_workers(workers) if points >= 8 else 1
    peak = BASE_BYTES + GRID_BYTES_PER_POINT * points + (w * WORKER_BYTES if w > 1 else 0)
    each = analysis_seconds(states) if seconds_each is None else seconds_each
    return Estimate(what, option, peak, points * each / w, w)


def sweep_estimate(what: str, option: str, kappas: int, states: int, families: int,
                   workers: int | None, seconds_each: float | None = None) -> Estimate:
    """An analysis over ``kappas`` condition numbers for each of ``families``
    (``seconds_each``: one analysis's seconds when not a certified rate's)."""
    w = usable_workers(workers) if kappas >= 8 else 1
    peak = BASE_BYTES + (w * WORKER_BYTES if w > 1 else 0)
    per = (10 * analysis_seconds(states) if seconds_each is None  # witnesses, checks, ...
           else seconds_each)
    return Estimate(what, option, peak, kappas * families * per / w, w)


def design_estimate(what: str, option: str, kappas: int, seconds_each: float,
                    workers: int | None) -> Estimate:
    """A design (or front) over ``kappas`` condition numbers of at most ``seconds_each``
    (its time limit) each: one kappa uses the workers inside its phases."""
    w = usable_workers(workers)
    peak = BASE_BYTES + (w * WORKER_BYTES if w > 1 else 0)
    per = seconds_each if kappas == 1 else seconds_each * kappas / w
    return Estimate(what, option, peak, per, w)


def announce_workers(requested: int | None, per_worker: float = WORKER_BYTES) -> int:
    """The workers a run uses; a cap of an explicit ``--workers`` is said in one line."""
    n, msg = plan_workers(requested, per_worker)
    if msg:
        sys.stderr.write(msg + "\n")
    return n
