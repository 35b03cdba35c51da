"""Certificate families: each turns a numeric algorithm into an LMI feasibility problem.

A family (see :class:`sosalgo.certificates.base.CertificateFamily`) assembles, once per
algorithm, the data of ``G_b(x; rho^2) ⪯ 0`` for every block b, affine in the decision
vector x for fixed rho. Analysis, design and verification only see that data, so a new
family (e.g. Lyapunov functions with interpolation conditions) plugs in beside
Theorem 1 by adding a module and an entry in :data:`FAMILIES`.
"""

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from sosalgo.certificates.allk import ALLK
from sosalgo.certificates.base import CertificateFamily
from sosalgo.certificates.interpolation import INTERPOLATION
from sosalgo.certificates.sublinear import SUBLINEAR
from sosalgo.certificates.theorem1 import THEOREM1

if TYPE_CHECKING:  # only for annotations
    from sosalgo.spec.types import Spec

FAMILIES: dict[str, CertificateFamily] = {
    THEOREM1.name: THEOREM1, INTERPOLATION.name: INTERPOLATION,
}
# families a spec selects by itself (:func:`spec_family`), not choices of
# ``--certificate``: their question is not a linear rate (the sublinear family's constant)
SPEC_FAMILIES: tuple[CertificateFamily, ...] = (SUBLINEAR,)
# families that answer a spec whose coefficients change with k (one bound for every N)
K_FAMILIES = (ALLK,)
# the option names of each family (its ``option_names``; kept as a table for old callers)
FAMILY_OPTIONS: dict[str, tuple[str, ...]] = {n: tuple(f.option_names)
                                               for n, f in FAMILIES.items()}


def register_family(family: CertificateFamily, options: tuple[str, ...] | None = None) -> None:
    """Make ``family`` available under ``family.name`` (specs' ``certificate:`` field,
    ``--certificate``); its options are its ``option_names`` (or ``options``)."""
    FAMILIES[family.name] = family
    names = getattr(family, "option_names", ()) if options is None else options
    FAMILY_OPTIONS[family.name] = tuple(names)


def default_family() -> CertificateFamily:
    """The family of result rows and files that name none (``is_default``: Theorem 1, the
    family of every document written before rows named their family)."""
    return next(f for f in FAMILIES.values() if f.is_default)


# the families from the tightest: each certifies every rate a later one certifies (the
# interpolation family contains Theorem 1 as a special case)
TIGHTEST_FIRST: tuple[str, ...] = ("interpolation", "theorem1")
# commands whose default is the family with a box-wide lower bound (design over a box)
LOWER_BOUND_COMMANDS = frozenset({"design"})
# commands that keep the spec's declared family (Theorem 1 for a seed spec naming none):
# the paper's table and figures, symbolic listings, grids
DECLARED_COMMANDS = frozenset({"table1", "lmi", "grid"})


def family_applies(spec: "Spec", family: str) -> str | None:
    """Why certificate family ``family`` does not apply to ``spec`` (None when it does):
    the family's ``applies_to`` (Theorem 1 holds only in the seed's setting; a family
    registered without one applies to every spec)."""
    from sosalgo.spec.loading import operator_functions

    operators = operator_functions(spec)
    if operators and (family != "interpolation" or not spec.has_condition_number):
        return (f"{', '.join(operators)} is an operator class: only the interpolation "
                "family certifies its rates, linear ones (m > 0; use sosalgo pep for a "
                "worst case after N steps)")
    nonconvex = nonconvex_functions(spec)
    if nonconvex:
        return (f"{', '.join(nonconvex)} is nonconvex: no Lyapunov family certifies a "
                "linear or sublinear rate for it (use sosalgo pep)")
    other = inhomogeneous_functions(spec)
    if other:
        return (f"{', '.join(other)}: its conditions are not pairwise homogeneous "
                "inequalities: no Lyapunov family certifies a rate for it (use sosalgo pep)")
    applies_to = getattr(FAMILIES.get(family), "applies_to", None)
    return None if applies_to is None else applies_to(spec)


def nonconvex_functions(spec: "Spec") -> list[str]:
    """``name (class)`` of each function of ``spec`` whose class is not convex (no family
    of this package certifies a rate for it)."""
    from sosalgo.classes import get_class

    return [f"{name} ({decl.cls})" for name, decl in spec.functions.items()
            if not get_class(decl.cls).convex]


def inhomogeneous_functions(spec: "Spec") -> list[str]:
    """``name (class)`` of each function of ``spec`` whose class has conditions other than
    pairwise homogeneous inequalities (a constant, a condition about x* alone: no family
    of this package takes them)."""
    from sosalgo.classes import get_class

    return [f"{name} ({decl.cls})" for name, decl in spec.functions.items()
            if not get_class(decl.cls).homogeneous]


def spec_family(spec: "Spec") -> CertificateFamily | None:
    """The family a spec selects by itself, whatever ``--certificate`` says: the first of
    :data:`SPEC_FAMILIES` that applies to it (the sublinear family for an ``m: 0`` spec),
    None for a spec whose rate a family of :data:`FAMILIES` certifies."""
    return next((f for f in SPEC_FAMILIES if f.applies_to(spec) is None), None)


def default_family_name(spec: "Spec", command: str | None = "analyze") -> str:
    """The family ``command`` uses when neither the command line nor the spec's
    ``certificate:`` field names one: the one place that default is decided.

    - ``analyze``, ``pareto``, ``noise`` (design with a noise objective or cap) and any
      other command: the tightest family that applies to the spec (:data:`TIGHTEST_FIRST`);
    - ``design``: the tightest family with a box-wide lower bound (``box_lower_bound``:
      Theorem 1) when one applies, else the tightest;
    - :data:`DECLARED_COMMANDS` (``table1``, ``lmi``, ``grid``) and ``None`` (library
      functions given no family): the spec's declared family (Theorem 1 for a seed spec,
      interpolation for a composite one).

    (``verify`` takes no default: a row names its family, and a row that names none is
    Theorem 1's, :func:`default_family`.)
    """
    if spec.certificate_given or command is None or command in DECLARED_COMMANDS:
        return spec.certificate
    applicable = [n for n in TIGHTEST_FIRST
                  if n in FAMILIES and family_applies(spec, n) is None]
    if not applicable:
        return spec.certificate
    if command in LOWER_BOUND_COMMANDS:
        bounded = [n for n in applicable if getattr(FAMILIES[n], "box_lower_bound", False)]
        return (bounded or applicable)[0]
    return applicable[0]


def get_family(name: str, options: Mapping[str, Any] | None = None) -> CertificateFamily:
    """The certificate family registered under ``name``, with its options (e.g. lag): the
    one place options are checked (ValueError '<option>: what is wrong')."""
    try:
        fam = FAMILIES[name]
    except KeyError:
        raise ValueError(f"unknown certificate family {name!r} "
                         f"(known: {', '.join(FAMILIES)})") from None
    opts = {k: v for k, v in (options or {}).items() if v is not None}
    unknown = sorted(set(opts) - set(FAMILY_OPTIONS[name]), key=str)
    if unknown:
        raise ValueError(f"{str(unknown[0])[:40]}: unknown option of family {name}")
    return fam.with_options(**opts) if opts else fam


def describe_family(fam: CertificateFamily) -> dict[str, Any]:
    """A family as plain data (workers, settings files): its name and set options."""
    return {"family": fam.name,
            **{k: v for k, v in fam.options().items() if v is not None}}


def family_from_description(desc: Mapping[str, Any] | None) -> CertificateFamily | None:
    """Inverse of :func:`describe_family` (None for None or an empty description)."""
    if not desc:
        return None
    return get_family(desc["family"], {k: v for k, v in desc.items() if k != "family"})


__all__ = [
    "CertificateFamily", "FAMILIES", "FAMILY_OPTIONS",
    "DECLARED_COMMANDS", "K_FAMILIES", "LOWER_BOUND_COMMANDS", "SPEC_FAMILIES",
    "TIGHTEST_FIRST",
    "default_family",
    "default_family_name", "describe_family", "family_applies", "family_from_description",
    "inhomogeneous_functions",
    "nonconvex_functions",
    "get_family",
    "register_family", "spec_family",
]
