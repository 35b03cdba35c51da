"""Checks of user input shared by the Python API and the command line.

Each check raises :class:`~sosalgo.errors.InputError` (a ValueError) with one line naming
the option or field, before anything is computed or written; the CLI prints it (exit 2),
the API raises it. ``label`` is how the caller names the option (``--gap`` on the command
line, ``gap`` in Python).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sosalgo.errors import InputError
from sosalgo.spec import Spec

__all__ = [
    "MAX_GRID_POINTS", "MAX_POINTS_PER_AXIS", "check_gap", "check_grid_points",
    "check_kappa_points", "check_method", "check_time_limit", "check_tol",
    "free_names", "kappa_option", "out_dir", "parameter_boxes", "select_families", "writable",
]


MAX_POINTS_PER_AXIS = 2000
# All the points of a grid are listed before the first is computed, and each is a bisection
# of SDPs: a million points is many CPU hours, and their task list alone ~0.7 GB (two free
# parameters).
MAX_GRID_POINTS = 1_000_000


def check_grid_points(points: Any, n_free: int, label: str = "--points") -> int:
    """Grid points per free parameter, in 2..MAX_POINTS_PER_AXIS, with ``points ** n_free``
    at most :data:`MAX_GRID_POINTS` (checked before anything is allocated); the total."""
    if isinstance(points, bool) or not isinstance(points, int) or \
            not 2 <= points <= MAX_POINTS_PER_AXIS:
        raise InputError(f"{label} {points}: must be an integer in 2..{MAX_POINTS_PER_AXIS}")
    total = points ** max(n_free, 1)
    if total > MAX_GRID_POINTS:
        raise InputError(f"{label} {points}: {points}^{n_free} = {total:,} grid points exceed "
                         f"{MAX_GRID_POINTS:,}; use fewer points per axis or fewer free "
                         "parameters (--free)")
    return total


def refuse_nonconvex(spec: Any, linear_rates: bool = False) -> None:
    """InputError (one line) for a spec with a nonconvex function, an operator, an inexact
    oracle call or an exact line search: no
    certificate family certifies a rate for it (``sosalgo pep`` bounds its N-step worst
    case). ``linear_rates`` (``analyze``, ``design``): an operator spec with m > 0 passes
    (the interpolation family certifies its linear rates), and one with m: 0 whose
    functions are all operator classes given by pairwise conditions (the sublinear family
    bounds its squared residual)."""
    from sosalgo.certificates import inhomogeneous_functions, nonconvex_functions
    from sosalgo.spec.loading import operator_functions, set_functions

    refuse_oracle_options(spec)
    bad = nonconvex_functions(spec)
    if bad:
        raise InputError(f"{spec.source}: functions: {', '.join(bad)} is nonconvex: no "
                         "linear or sublinear rate is certified for it (no Lyapunov family "
                         "applies); sosalgo pep bounds its worst case after N steps")
    ops = operator_functions(spec)
    if ops and not linear_rates:
        raise InputError(f"{spec.source}: functions: {', '.join(ops)} is an operator class: "
                         "analyze certifies its linear rates (m > 0) and its O(1/k) "
                         "residual (m: 0, one operator; several maximally monotone: "
                         "the state change); grid and pareto do not take it "
                         "yet; sosalgo pep bounds its worst case after N steps")
    if ops and not spec.has_condition_number:
        from sosalgo.certificates.sublinear import operator_refusal

        why = operator_refusal(spec)
        if why is not None:
            raise InputError(f"{spec.source}: functions: {why}; sosalgo pep bounds its "
                             "worst case after N steps")
    sets = set_functions(spec)
    if sets and not spec.has_condition_number:
        raise InputError(f"{spec.source}: functions: {', '.join(sets)}: indicators alone with "
                         "m: 0 (a feasibility problem): no sublinear family bounds a "
                         "distance; sosalgo pep bounds its worst case after N steps")
    other = inhomogeneous_functions(spec)
    if other:
        raise InputError(f"{spec.source}: functions: {', '.join(other)}: its conditions are "
                         "not pairwise homogeneous inequalities: no linear or sublinear rate "
                         "is certified for it (no Lyapunov family applies); sosalgo pep "
                         "bounds its worst case after N steps")


def refuse_free_class_parameters(spec: Any, free: Sequence[str]) -> None:
    """InputError (one line) for a class parameter that names a free parameter (or one
    whose value is an expression of a free one): a class is one set of functions for the
    whole search, so its parameters are fixed (``--set NAME=VALUE`` fixes one)."""
    from sosalgo.spec.types import BASE_NAMES

    free_set = set(free)
    for fname, decl in spec.functions.items():
        for key, expr in decl.params.items():
            seen, todo = set(), list(expr.names() - set(BASE_NAMES))
            while todo:
                name = todo.pop()
                if name in seen or name not in spec.parameters:
                    continue
                seen.add(name)
                if name in free_set:
                    raise InputError(
                        f"{spec.source}: functions.{fname}.{key}: depends on the free "
                        f"parameter {name}: a class parameter is fixed for the whole run "
                        f"(fix it with --set {name}=VALUE, or leave it out of --free)")
                par = spec.parameters[name]
                todo += [n for e in (par.value, par.tied) if e is not None
                         for n in e.names()]


def refuse_oracle_options(spec: Any) -> None:
    """InputError (one line) for a spec with a finite sum, Bregman steps, an exact line
    search, a linear minimization call or an inexact call: no Lyapunov family models them
    (``sosalgo pep`` bounds their N-step worst case); the API's ``analyze`` refuses them
    as the command does."""
    if getattr(spec, "finite_sum", None) is not None:
        raise InputError(f"{spec.source}: finite_sum: one of n functions drawn per step: no "
                         "Lyapunov family models it (no rate is certified); sosalgo pep "
                         "bounds the expectation of its measure")
    if getattr(spec, "mirror", None):
        raise InputError(f"{spec.source}: mirror: Bregman steps: no Lyapunov family models "
                         "them (no rate is certified); sosalgo pep bounds their worst case "
                         "after N steps")
    if getattr(spec, "line_search", None):
        raise InputError(f"{spec.source}: line_search: a step chosen by exact line search: "
                         "no Lyapunov family models it (no rate is certified); sosalgo pep "
                         "bounds its worst case after N steps")
    lmo = sorted(getattr(spec, "lmo", None) or ())
    if lmo:
        raise InputError(f"{spec.source}: oracles[{lmo[0]}].lmo: a linear minimization "
                         "oracle: no Lyapunov family models it (no rate is certified); "
                         "sosalgo pep bounds its worst case after N steps")
    eps = sorted(getattr(spec, "epsilon", None) or ())
    if eps:
        raise InputError(f"{spec.source}: oracles[{eps[0]}].epsilon: an epsilon-subgradient "
                         "call: no Lyapunov family models it (no rate is certified); "
                         "sosalgo pep bounds its worst case after N steps")
    inexact = sorted(getattr(spec, "inexact", None) or ())
    if inexact:
        raise InputError(f"{spec.source}: oracles[{inexact[0]}].relative_error: an inexact "
                         "call: no Lyapunov family models it (no rate is certified); "
                         "sosalgo pep bounds its worst case after N steps")


def check_tol(tol: Any, label: str = "tol") -> float:
    """The bisection tolerance, in (0, 0.5)."""
    if isinstance(tol, bool) or not isinstance(tol, int | float) or not 0 < tol < 0.5:
        raise InputError(f"{label} {tol}: must be in (0, 0.5)")
    return float(tol)


def check_gap(gap: Any, label: str = "gap") -> float:
    """The target gap of a design: positive."""
    if isinstance(gap, bool) or not isinstance(gap, int | float) or not gap > 0:
        raise InputError(f"{label} {gap}: must be positive")
    return float(gap)


def check_time_limit(seconds: Any, label: str = "time_limit") -> float:
    """A wall-clock limit: positive and finite."""
    if isinstance(seconds, bool) or not isinstance(seconds, int | float) or not seconds > 0:
        raise InputError(f"{label} {seconds}: must be positive")
    if not math.isfinite(seconds):
        raise InputError(f"{label} {seconds}: must be finite")
    return float(seconds)


def check_method(method: str, scalarize: str, family: Any, label: str = "method") -> None:
    """The design's lower-bound method and scalarization, and that the family supports it."""
    if method not in ("dual", "moment"):
        raise InputError(f"{label} {method}: must be dual or moment")
    if scalarize not in ("pmi", "minors"):
        raise InputError(f"scalarize {scalarize}: must be pmi or minors")
    if method == "moment" and not family.supports_moment:
        raise InputError(f"{label} moment: the moment relaxation is built on Theorem 1, "
                         f"not {family.name} (use {label} dual)")


def kappa_option(value: str, label: str = "--kappa") -> tuple[float, ...]:
    """One --kappa value: a number, or a YAML list/range like '{from: 2, to: 100, points: 9}'."""
    import yaml

    from sosalgo.spec import parse_kappa

    raw: object = value
    if "," in value and value.strip()[:1] not in "[{":
        raise InputError(f"{label} {value}: one value per {label}; write {label} "
                         + f" {label} ".join(v.strip() for v in value.split(","))
                         + f" or a list {label} '[{value}]'")
    if value.strip()[:1] in "[{":
        try:
            raw = yaml.safe_load(value)
        except yaml.YAMLError:
            raise InputError(f"{label} {value}: not a number, list or range") from None
    return parse_kappa(raw, label, "value")


def free_names(spec: Spec, free: str | Sequence[str] | None,
               need_range: bool = True) -> list[str]:
    """The free parameters (a comma-separated string or a list; default: those with a
    range), checked against the spec."""
    if free is None:
        names = list(spec.ranged)
    elif isinstance(free, str):
        names = [p.strip() for p in free.split(",") if p.strip()]
    else:
        names = list(free)
    if free is not None and not names:
        raise InputError(f"--free {free!s:.40}: no parameter names given")
    twice = sorted({p for p in names if names.count(p) > 1})
    if twice:
        raise InputError(f"--free: {', '.join(twice)[:80]} given more than once")
    if not names and need_range:
        raise InputError(f"{spec.source}: parameters: no parameter has a range (use --free; "
                         "a parameter fixed by --set has none)")
    spec.check_free(names, need_range=need_range)
    refuse_free_class_parameters(spec, names)
    return names


def check_kappa_points(spec: Spec, kappas: Sequence[float],
                       theta: Mapping[str, float] | None = None) -> None:
    """Evaluate the spec at every kappa (a value outside its range, a pole) up front."""
    from sosalgo.model import ModelError, bind

    for k in kappas:
        try:
            bind(spec, k, theta)
        except ModelError as exc:
            raise InputError(f"{spec.source}: {exc.field}: at kappa={k:g}: {exc.message}") from None


def parameter_boxes(spec: Spec, kappas: Sequence[float], names: Sequence[str],
                    design: bool = False) -> dict[float, list[tuple[float, float]]]:
    """The box of the free parameters at every kappa; with ``design``, a range too large
    for design is refused too (:func:`sosalgo.model.design_box`)."""
    from sosalgo.model import ModelError, design_box, parameter_box

    check = design_box if design else parameter_box
    boxes = {}
    for k in kappas:
        try:
            boxes[k] = check(spec, k, list(names))
        except ModelError as exc:
            raise InputError(f"{spec.source}: {exc.field}: at kappa={k:g}: {exc.message}") from None
    return boxes


def _probe(path: Path) -> Path:
    """The nearest existing folder at or above ``path`` (where new files would go)."""
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    return probe


def writable(out: str | Path) -> bool:
    """Whether files can be written into ``out`` (created if missing)."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        return False
    probe = _probe(path)
    return probe.is_dir() and os.access(probe, os.W_OK | os.X_OK)


def out_dir(out: str | Path, label: str = "--out") -> Path:
    """The output folder, checked writable (nothing is created yet)."""
    path = Path(out)
    try:
        if path.exists() and not path.is_dir():
            raise InputError(f"{label} {out}: exists and is not a directory")
        if not writable(path):
            raise InputError(f"{label} {out}: not writable ({_probe(path)} does not accept "
                             "new files)")
    except (OSError, ValueError) as exc:  # a name too long, a NUL byte, ...
        reason = getattr(exc, "strerror", None) or str(exc)
        raise InputError(f"{label} {str(out)[:80]}: {reason}") from None
    return path


def select_families(spec: Spec, certificate: str | Sequence[str] | None = None,
                    options: Mapping[str, Any] | None = None, single: bool = False,
                    label: str = "--certificate", applicable_only: bool = False,
                    command: str | None = None) -> list[Any]:
    """The certificate families asked for (default: ``command``'s default for the spec,
    :func:`sosalgo.certificates.default_family_name`), with the spec's options when it is
    the spec's family; ``options`` (e.g. ``{"lag": 0}``; None values are unset) go to
    every family that has them, and at least one family must have each. A family that
    does not apply to the spec is refused, or with ``applicable_only`` (a table over many
    specs) left out as long as one applies."""
    from sosalgo.certificates import (
        FAMILIES,
        FAMILY_OPTIONS,
        default_family_name,
        family_applies,
        get_family,
    )

    if certificate is None:
        names = [default_family_name(spec, command)]
    else:
        names = ([v.strip() for v in certificate.split(",") if v.strip()]
                 if isinstance(certificate, str) else list(certificate))
        if not names or len(set(names)) != len(names):
            raise InputError(f"{label} {certificate}: expected distinct family names")
        for nm in names:
            if nm not in FAMILIES:
                raise InputError(f"{label} {nm}: unknown family (known: {', '.join(FAMILIES)})")
    if single and len(names) > 1:
        raise InputError(f"{label} {certificate}: this command takes one family")
    opts = {k: v for k, v in (options or {}).items() if v is not None}
    for key in opts:
        if not any(key in FAMILY_OPTIONS[nm] for nm in names):
            raise InputError(f"--{key}: no family asked for has this option "
                             f"({', '.join(names)})")
    from sosalgo.analysis import for_spec

    if applicable_only and any(not family_applies(spec, nm) for nm in names):
        names = [nm for nm in names if not family_applies(spec, nm)]
    fams = []
    for nm in names:
        problem = family_applies(spec, nm)
        if problem:
            raise InputError(f"{label} {nm}: {spec.source}: {problem}")
        own = spec.certificate_options if nm == spec.certificate else {}
        mine = {**own, **{k: v for k, v in opts.items() if k in FAMILY_OPTIONS[nm]}}
        try:
            fams.append(for_spec(get_family(nm, mine), spec))
        except ValueError as exc:
            raise InputError(f"--{exc}") from None
    return fams
