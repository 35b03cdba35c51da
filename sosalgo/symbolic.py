"""Symbolic form of the certificate inequality, as in Section IV of the paper.

The entries of M(theta, rho, lambda, P) are derived by sympy from the spec's templates
through the same code that assembles the numeric LMI (:func:`theorem1_terms`), so what is
printed is what the solver sees.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sympy as sp

from sosalgo.certificates import get_family
from sosalgo.spec import BASE_SYMBOLS, Spec

__all__ = ["symbolic_matrix", "symbolic_lmi"]


def symbolic_matrix(spec: Spec, free: Sequence[str] | None = None) -> tuple[sp.Matrix, dict]:
    """M of the spec's certificate family, with kappa written as L/m."""
    m, L, kappa = BASE_SYMBOLS["m"], BASE_SYMBOLS["L"], BASE_SYMBOLS["kappa"]
    mats = spec.templates(free)
    mats = {k: v.xreplace({kappa: L / m}) for k, v in mats.items()}
    fam = get_family(spec.certificate)
    return fam.symbolic(mats["A"], mats["B"], mats["C"], mats["E"], m, L)


def symbolic_lmi(spec: Spec, free: Sequence[str] | None = None, latex: bool = False) -> str:
    """Human-readable (or LaTeX) listing of M's entries and the certificate's unknowns."""
    M, syms = symbolic_matrix(spec, free)
    P = syms["P"]
    size = M.shape[0]
    lines: list[str] = []
    if latex:
        lines.append(f"% {spec.name}: M = M^0 + rho^2 M^1 + (1-rho^2) M^2 + lambda M^3 <= 0")
        lines.append(r"P = " + sp.latex(P) + r", \quad P \succeq 0,\ \lambda \ge 0")
        lines.append(r"\begin{aligned}")
        for i in range(size):
            for j in range(i, size):
                lines.append(f"M_{{{i + 1}{j + 1}}} &= {sp.latex(M[i, j])} \\\\")
        lines.append(r"\end{aligned}")
        return "\n".join(lines)
    lines.append(
        f"{spec.name}: M = M0 + rho^2 M1 + (1 - rho^2) M2 + lambda M3 <= 0  "
        f"({size}x{size}, Theorem 1, eq. 15)"
    )
    lines.append(f"P = {_plain(P)} >= 0, lambda >= 0")
    for i in range(size):
        for j in range(i, size):
            lines.append(f"M{i + 1}{j + 1} = {_plain(M[i, j])}")
    return "\n".join(lines)


def _plain(expr: Any) -> str:
    return sp.sstr(expr)
