"""Certificate families: each turns a numeric algorithm into an LMI feasibility problem.

A family (see :class:`sosalgo.certificates.base.CertificateFamily`) assembles, once per
algorithm, the data of ``G_b(x; rho^2) ⪯ 0`` for every block b, affine in the decision
vector x for fixed rho. Analysis, design and verification only see that data, so a new
family (e.g. Lyapunov functions with interpolation conditions) plugs in beside
Theorem 1 by adding a module and an entry in :data:`FAMILIES`.
"""

from sosalgo.certificates.base import AffineBlock, CertificateFamily, LMIProblem
from sosalgo.certificates.interpolation import INTERPOLATION
from sosalgo.certificates.theorem1 import THEOREM1

FAMILIES: dict[str, CertificateFamily] = {
    THEOREM1.name: THEOREM1, INTERPOLATION.name: INTERPOLATION,
}
FAMILY_OPTIONS: dict[str, tuple[str, ...]] = {THEOREM1.name: (), INTERPOLATION.name: ("lag",)}


def register_family(family: CertificateFamily, options: tuple[str, ...] = ()) -> None:
    """Make ``family`` available under ``family.name`` (specs' ``certificate:`` field,
    ``--certificate``); ``options`` are the keyword options its ``with_options`` takes."""
    FAMILIES[family.name] = family
    FAMILY_OPTIONS[family.name] = tuple(options)


def default_family() -> CertificateFamily:
    """The family of specs without a ``certificate:`` field (``is_default``)."""
    return next(f for f in FAMILIES.values() if f.is_default)


def get_family(name: str, options: dict | None = None) -> CertificateFamily:
    """The certificate family registered under ``name``, with its options (e.g. lag)."""
    try:
        fam = FAMILIES[name]
    except KeyError:
        raise ValueError(f"unknown certificate family {name!r}") from None
    opts = {k: v for k, v in (options or {}).items() if v is not None}
    unknown = set(opts) - set(FAMILY_OPTIONS[name])
    if unknown:
        raise ValueError(f"family {name!r} has no option {sorted(unknown)[0]!r}")
    return fam.with_options(**opts) if opts else fam  # type: ignore[attr-defined]


__all__ = [
    "AffineBlock", "CertificateFamily", "LMIProblem", "FAMILIES", "FAMILY_OPTIONS",
    "default_family", "get_family", "register_family",
]
