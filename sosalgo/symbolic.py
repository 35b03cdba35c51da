"""Symbolic form of the certificate inequality, as in Section IV of the paper.

The entries of M(theta, rho, lambda, P) are derived by sympy from the spec's templates
through the same code that assembles the numeric LMI (:func:`theorem1_terms`), so what is
printed is what the solver sees.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sympy as sp

from sosalgo.certificates import get_family, spec_family
from sosalgo.certificates.listing import latex_block
from sosalgo.spec import BASE_SYMBOLS, Spec

__all__ = ["symbolic_matrix", "symbolic_lmi"]


def symbolic_matrix(spec: Spec, free: Sequence[str] | None = None,
                    family: Any = None) -> tuple[sp.Matrix, dict]:
    """M of the spec's certificate family (or ``family``), with kappa written as L/m."""
    m, L, kappa = BASE_SYMBOLS["m"], BASE_SYMBOLS["L"], BASE_SYMBOLS["kappa"]
    mats = spec.templates(free)
    mats = {k: v.xreplace({kappa: L / m}) for k, v in mats.items()}
    fam = family or get_family(spec.certificate, spec.certificate_options)
    return fam.symbolic(mats["A"], mats["B"], mats["C"], mats["E"], m, L)


def symbolic_lmi(spec: Spec, free: Sequence[str] | None = None, latex: bool = False,
                 family: Any = None) -> str:
    """Human-readable (or LaTeX) listing of M's entries and the certificate's unknowns; a
    family with its own listing (``listing``) gives its text."""
    selected = spec_family(spec)
    if selected is not None:  # m: 0: the family's own text (no kappa to bind the method at)
        return selected.listing(spec, {}, latex)
    fam = family or get_family(spec.certificate, spec.certificate_options)
    if not spec.has_seed_form:
        return _composite(spec, free, latex, fam)
    M, syms = symbolic_matrix(spec, free, fam)
    own = fam.listing(spec, syms, latex)
    if own is not None:
        return own
    entries = [(f"M_{{{i + 1}{j + 1}}}", M[i, j]) for i in range(M.shape[0])
               for j in range(i, M.shape[0])]
    if latex:
        head = [f"% sosalgo lmi {spec.name}: Theorem 1 (eq. 15), M = M^0 + rho^2 M^1"
                " + (1 - rho^2) M^2 + lambda M^3 <= 0"]
        first = (r"P &= " + sp.latex(syms["P"], mat_delim="", mat_str="bmatrix")
                 + r" \succeq 0, \qquad \lambda \ge 0")
        return latex_block(head, [first] + [f"{k} &= {sp.latex(v)}" for k, v in entries])
    size = M.shape[0]
    lines = [f"{spec.name}: M = M0 + rho^2 M1 + (1 - rho^2) M2 + lambda M3 <= 0  "
             f"({size}x{size}, Theorem 1, eq. 15)",
             f"P = {_plain(syms['P'])} >= 0, lambda >= 0"]
    lines += [f"{k.replace('_{', '').replace('}', '')} = {_plain(v)}" for k, v in entries]
    return "\n".join(lines)


def _plain(expr: Any) -> str:
    return sp.sstr(expr)


def _composite(spec: Spec, free: Sequence[str] | None, latex: bool, fam: Any) -> str:
    """The listing of a composite spec (:func:`sosalgo.certificates.listing.composite_listing`);
    the pair lists and sizes come from the numeric structure at the spec's first kappa
    (they do not depend on kappa or the parameters)."""
    from sosalgo.certificates.composite import composite_structure
    from sosalgo.certificates.listing import composite_listing
    from sosalgo.model import bind

    lag = fam.lag_for(spec.n)
    om = bind(spec, spec.kappa[0])
    return composite_listing(spec, free, lag, om, composite_structure(om, lag), latex)
