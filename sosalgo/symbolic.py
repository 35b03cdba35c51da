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
    """Human-readable (or LaTeX) listing of M's entries and the certificate's unknowns."""
    M, syms = symbolic_matrix(spec, free, family)
    if "structure" in syms:
        return _interpolation_listing(spec, syms, latex)
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


def _interpolation_listing(spec: Spec, syms: dict, latex: bool) -> str:
    """The interpolation family in symbols: row maps of the windows, the Lyapunov function
    and the interpolation pairs (the blocks themselves are sums of these pieces)."""
    st = syms["structure"]
    lag = st.lag
    fmt = sp.latex if latex else _plain
    d, p = st.dec, st.pos
    zs = ", ".join(["xi_0"] + [f"u_{t}" for t in range(lag + 2)]
                   + ([f"v_{lag}", f"v_{lag + 1}"] if st.has_x else []))
    xterm = " + c (f(x_k) - f*)" if st.has_x else ""
    lines = [
        f"{spec.name}: interpolation certificate, lag l = {lag}",
        f"V_k = z_k' P z_k + sum_(j=0..{lag}) p_j (f(y_(k-j)) - f*){xterm},  "
        f"z_k = (xi_k - xi*, u_k, ..., u_(k-{lag})),  P = {fmt(syms['P'])}",
        f"decrease window w = ({zs})  [{d.width} entries]",
        f"  Z_{lag} = {fmt(sp.Matrix(d.Z[lag]))}",
        f"  Z_{lag + 1} = {fmt(sp.Matrix(d.Z[lag + 1]))}",
        f"  (D)  Z_{lag + 1}' P Z_{lag + 1} - rho^2 Z_{lag}' P Z_{lag} + sum eta_ij M_ij <= 0"
        f"  ({d.width}x{d.width}), and the function-value rows ({d.nphi}) <= 0",
        f"  pairs ({len(d.labels)}): {' '.join(d.labels)}",
        f"positivity window [{p.width} entries]: Z+ = {fmt(sp.Matrix(p.Z[lag]))}",
        f"  (P)  Z+' P Z+ - sum lambda_ij M+_ij >= 0 ({p.width}x{p.width}), "
        f"function-value rows ({p.nphi}) >= 0 with V >= f(x) - f*",
        f"  pairs ({len(p.labels)}): {' '.join(p.labels)}",
        "q_ij = (L - m)(f_i - f_j) + 1/2 [x_i; x_j; g_i; g_j]' MM [x_i; x_j; g_i; g_j] >= 0,"
        " MM = [[-mL, mL, m, -L], [mL, -mL, -m, L], [m, -m, -1, 1], [-L, L, 1, -1]]",
    ]
    ex = d.Mq[d.labels.index("y0>*")] if "y0>*" in d.labels else None
    if ex is not None:
        lines.append(f"example M_(y0>*) = {fmt(sp.Matrix(ex).applyfunc(sp.factor))}")
    return "\n".join(lines)
