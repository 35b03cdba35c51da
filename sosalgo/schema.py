"""The result schema, in one place: CSV columns, printed columns and output file names.

Every name here is a contract (scripts read these files): extend, never rename or remove.
A certificate family contributes its own parts through its interface (``p_size`` for the
``P11, P12, ...`` columns, ``csv_columns`` for its extra columns, ``options`` for the file
suffix); the columns common to every family are listed here once.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    from sosalgo.certificates.base import CertificateFamily
    from sosalgo.spec import Spec

__all__ = [
    "ANALYSIS_COLUMNS", "CHECK_COLUMNS", "FAMILY_COLUMNS", "GRID_COLUMNS", "TABLE1_COLUMNS",
    "TABLE1_FILE", "analysis_columns", "analysis_csv", "certificate_name", "design_columns",
    "design_stem", "family_suffix", "grid_columns", "grid_fixed", "grid_stem", "kappa_label",
    "p_columns", "rate_stem", "SUBLINEAR_COLUMNS", "sublinear_columns", "NOISE_COLUMNS",
    "PEP_COLUMNS", "pep_csv", "OBJECTIVE_COLUMNS", "PARETO_COLUMNS", "pareto_stem",
    "STEPS_DESIGN_COLUMNS", "steps_design_csv",
    "SOLVER_COLUMNS", "printed_columns",
]

# ---------------------------------------------------------------------------- printed tables
# analyze's printed table (the CSV has more); the default family's shows lambda as well
ANALYSIS_COLUMNS = ["kappa", "rho", "certified", "lambda", "max_eig_M", "min_eig_P", "solves",
                    "seconds"]
FAMILY_COLUMNS = ["kappa", "rho", "certified", "max_eig_M", "min_eig_P", "solves", "seconds"]
# the solver's internals: printed only with ``--details`` (the CSV and JSON always hold them)
SOLVER_COLUMNS = frozenset({"lambda", "max_eig_M", "min_eig_P", "solves", "seconds",
                            "witness_dim", "noise_lag", "noise_check", "noise_limsup_rho"})
CHECK_COLUMNS = ["kappa", "rho", "verified", "rho_proven", "simulation", "reason"]
TABLE1_COLUMNS = ["spec", "kappa", "rho_certified", "certified", "closed_form",
                  "closed_form_rate", "difference"]
TABLE1_FILE = "table1.csv"
# a sublinear spec's (m: 0) printed table and CSV: measure(x_k) <= constant |x_0 - x*|^2 / k
SUBLINEAR_COLUMNS = ["L", "rate_type", "constant", "certified", "solves", "seconds"]

# ---------------------------------------------------------------------------- CSV columns
_ANALYSIS_HEAD = ["kappa", "rho", "certified", "lambda"]
_ANALYSIS_TAIL = ["max_eig_M", "min_eig_P", "solves", "seconds", "solver", "rho_infeasible",
                  "error", "warning", "rate_type", "rho_lower", "rho_lower_kind",
                  "cycle_length", "cycle", "rho_lower_witness"]  # sosalgo.witnesses
# ``analyze --noise``: certified noise sensitivity, its value on quadratics, the lag of its
# certificate, how it was checked (exact / float / none), the certificate (one JSON object);
# then the bound on the limsup itself, the rho of its certificate, its check, its certificate
NOISE_COLUMNS = ["noise", "noise_quadratic", "noise_lag", "noise_check", "noise_certificate",
                 "noise_limsup", "noise_limsup_rho", "noise_limsup_check",
                 "noise_limsup_certificate"]
# ``sosalgo pep``: one row per (kappa, N); ``document`` is the row's --json document
PEP_COLUMNS = ["kappa", "steps", "tau", "status", "gap", "tau_proven", "check_kind",
               "witness_verified", "tau_lower", "witness_dimension", "measure", "initial",
               "seconds", "document"]
# ``design --steps N``: one row per (kappa, N); ``document`` the whole design document
STEPS_DESIGN_COLUMNS = ["kappa", "steps", "schedule", "tau_certified", "lower_bound", "gap",
                        "gap_relative", "floor", "time_limited", "seconds", "document"]
# ``design --objective noise --max-rate R`` / ``--objective rate --max-noise G``: appended to
# the design columns (only then: a rate design's file keeps its columns)
OBJECTIVE_COLUMNS = ["objective", "max_rate", "max_noise", "noise", "noise_quadratic",
                     "noise_lag", "noise_check", "objective_status", "bound_status",
                     "rho_check", "rho_proven", "noise_certificate"]
# ``sosalgo pareto``: one row per front point (kind "front", index 0 = the rate design),
# known tuning ("tuning") and robust momentum member ("robust momentum"); theta as JSON
PARETO_COLUMNS = ["index", "kind", "name", "cap", "rho", "noise", "noise_quadratic",
                  "noise_lag", "noise_check", "rho_check", "theta", "seconds", "error",
                  "rho_proven", "certificate", "noise_certificate"]
_GRID_HEAD = ["rho", "certified", "lambda"]
_GRID_TAIL = ["max_eig_M", "min_eig_P", "solves", "seconds", "solver", "error"]
_DESIGN_HEAD = ["kappa", "lower_bound", "rho_certified", "gap", "gap_met"]
_DESIGN_TAIL = ["scalarize", "order", "status", "flat", "ranks", "seconds", "steps", "error",
                "method", "floor", "time_limited"]
# a grid's parameter columns may not take these names
GRID_COLUMNS = frozenset(["kappa", *_GRID_HEAD, *_GRID_TAIL])


def printed_columns(columns: Sequence[str], details: bool) -> list[str]:
    """The printed table's columns: without ``--details``, the solver's internals
    (:data:`SOLVER_COLUMNS`) are left out."""
    return [c for c in columns if details or c not in SOLVER_COLUMNS]


def p_columns(n: int) -> list[str]:
    """Column names of P's upper triangle: P11, P12, ..., Pnn (1-based)."""
    return [f"P{i + 1}{j + 1}" for i in range(n) for j in range(i, n)]


def _family_parts(spec: Spec, family: CertificateFamily | None) -> tuple[list[str], list[str]]:
    """(P's columns, the family's own columns): Theorem 1's when ``family`` is None."""
    if family is None:
        return p_columns(spec.n), []
    return p_columns(family.p_size(spec.n)), list(family.csv_columns(spec.n))


def analysis_columns(spec: Spec, family: CertificateFamily | None = None,
                     noise: bool = False) -> list[str]:
    """CSV columns of ``sosalgo analyze``: the common ones, P's entries (of the family's
    size), the spec's references, then the family's own columns (and with ``noise``, those
    of ``--noise``: NOISE_COLUMNS)."""
    ps, own = _family_parts(spec, family)
    named = [] if "family" in own else ["family"]  # every analysis row names its family
    return (_ANALYSIS_HEAD + ps + _ANALYSIS_TAIL + list(spec.references) + own + named
            + (NOISE_COLUMNS if noise else []))


def sublinear_columns(spec: Spec) -> list[str]:
    """CSV columns of ``sosalgo analyze`` on a sublinear spec: the constant and how it was
    checked, the spec's references, the certificate (one JSON object): the sublinear
    family's columns."""
    from sosalgo.certificates.sublinear import SUBLINEAR

    return SUBLINEAR.analysis_columns(spec)


def design_columns(spec: Spec, free: Sequence[str],
                   family: CertificateFamily | None = None,
                   objective: bool = False) -> list[str]:
    """CSV columns of ``sosalgo design`` over kappa (with ``objective``: a design with a
    noise objective or cap, OBJECTIVE_COLUMNS at the end)."""
    ps, own = _family_parts(spec, family)
    return (_DESIGN_HEAD + [f"theta_{p}" for p in free] + ["rho_at_values", "lambda"] + ps
            + _DESIGN_TAIL + list(spec.references) + own
            + (OBJECTIVE_COLUMNS if objective else []))


def grid_fixed(spec: Spec, free: Sequence[str]) -> list[str]:
    """The grid's parameters that are not free (nor tied): one column each, their value."""
    return [p for p in spec.inputs if p not in free]


def grid_columns(spec: Spec, free: Sequence[str],
                 family: CertificateFamily | None = None) -> list[str]:
    """CSV columns of ``sosalgo grid``: kappa, the free parameters, the rate and its
    certificate, the family's own columns, then the fixed parameters' values."""
    ps, own = _family_parts(spec, family)
    return ["kappa", *free, *_GRID_HEAD, *ps, *_GRID_TAIL, *own, *grid_fixed(spec, free)]


# ---------------------------------------------------------------------------- file names
def kappa_label(kappa: float) -> str:
    """Exact file-name text of a condition number: ``10`` for 10.0, else the shortest
    round-trip repr (``10.000001``, ``1e+20``), so distinct kappas never share a name."""
    k = float(kappa)
    if math.isfinite(k) and k.is_integer() and abs(k) < 1e16:
        return str(int(k))
    return repr(k)


def _option_label(key: str, value: object) -> str:
    """'-lag0' for lag 0; '-uniform' / '-nouniform' for a flag."""
    if isinstance(value, bool):
        return f"-{key}" if value else f"-no{key}"
    return f"-{key}{value}"


def family_suffix(family: CertificateFamily | None) -> str:
    """'' for the default family, '-<family>' otherwise, then one label per option set
    (e.g. '-interpolation-lag0')."""
    if family is None or family.is_default:
        return ""
    opts = "".join(_option_label(k, v) for k, v in family.options().items() if v is not None)
    return f"-{family.name}{opts}"


def analysis_csv(out_dir: Path, spec_name: str, family: CertificateFamily | None) -> Path:
    """``<name>-analysis[-<family>...].csv``."""
    return Path(out_dir) / f"{spec_name}-analysis{family_suffix(family)}.csv"


def steps_design_csv(out_dir: Path, spec_name: str) -> Path:
    """``<name>-design-steps.csv``: ``sosalgo design --steps``'s rows."""
    return Path(out_dir) / f"{spec_name}-design-steps.csv"


def pep_csv(out_dir: Path, spec_name: str) -> Path:
    """``<name>-pep.csv``: ``sosalgo pep``'s rows."""
    return Path(out_dir) / f"{spec_name}-pep.csv"


def pareto_stem(out_dir: Path, spec_name: str, kappa: float) -> Path:
    """``<name>-pareto-k<kappa>`` (.csv, .png, .pdf): ``sosalgo pareto``'s front."""
    return Path(out_dir) / f"{spec_name}-pareto-k{kappa_label(kappa)}"


def rate_stem(out_dir: Path, spec_name: str,
              families: Sequence[CertificateFamily] | None = None) -> Path:
    """``<name>-rate[-<family>...]`` (.png, .pdf): analyze's figure, every family on one;
    the families drawn are named unless ``families`` is None (the command's default
    family), so that a run with other families does not overwrite it."""
    if families is None:
        return Path(out_dir) / f"{spec_name}-rate"
    tags = "".join(family_suffix(f) or f"-{f.name}" for f in families)
    return Path(out_dir) / f"{spec_name}-rate{tags}"


def design_stem(out_dir: Path, spec_name: str, family: CertificateFamily | None) -> Path:
    """``<name>-design[-<family>...]`` (.csv, .png, .pdf)."""
    return Path(out_dir) / f"{spec_name}-design{family_suffix(family)}"


def grid_stem(out_dir: Path, spec_name: str, kappa: float,
              family: CertificateFamily | None) -> Path:
    """``<name>-grid-k<kappa>[-<family>...]`` (.csv, .png, .pdf)."""
    return Path(out_dir) / f"{spec_name}-grid-k{kappa_label(kappa)}{family_suffix(family)}"


def certificate_name(spec_name: str, kappa: float, family: CertificateFamily,
                     digest: str | None = None) -> str:
    """``<name>-k<kappa>[-<family>][-<digest>]-certificate.json`` (the family named unless
    it is the default; the digest when that name holds another certificate)."""
    fam = "" if family.is_default else f"-{family.name}"
    tag = "" if digest is None else f"-{digest}"
    return f"{spec_name}-k{kappa_label(kappa)}{fam}{tag}-certificate.json"
