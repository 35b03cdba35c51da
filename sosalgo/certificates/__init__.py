"""Certificate families: each turns a numeric algorithm into an LMI feasibility problem.

A family (see :class:`sosalgo.certificates.base.CertificateFamily`) assembles, once per
algorithm, the data of ``G_b(x; rho^2) ⪯ 0`` for every block b, affine in the decision
vector x for fixed rho. Analysis, design and verification only see that data, so a new
family (e.g. Lyapunov functions with interpolation conditions) plugs in beside
Theorem 1 by adding a module and an entry in :data:`FAMILIES`.
"""

from sosalgo.certificates.base import AffineBlock, CertificateFamily, LMIProblem
from sosalgo.certificates.theorem1 import THEOREM1

FAMILIES: dict[str, CertificateFamily] = {THEOREM1.name: THEOREM1}


def get_family(name: str) -> CertificateFamily:
    """The certificate family registered under ``name``."""
    try:
        return FAMILIES[name]
    except KeyError:
        raise ValueError(f"unknown certificate family {name!r}") from None


__all__ = ["AffineBlock", "CertificateFamily", "LMIProblem", "FAMILIES", "get_family"]
