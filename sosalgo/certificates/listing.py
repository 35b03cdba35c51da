"""Text of a certificate family for ``sosalgo lmi``: plain listings and LaTeX snippets.

Families call these from their ``listing`` member; the module needs only sympy (no spec
or model), so families can use it without an import cycle.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sympy as sp

__all__ = ["interpolation_listing", "latex_block"]


def latex_block(comments: Sequence[str], rows: Sequence[str]) -> str:
    """A LaTeX snippet ready to paste: ``comments`` as % lines (with the package it needs),
    then ``rows`` (each ``lhs &= rhs``) in an ``aligned`` inside ``equation*``."""
    body = ",\\\\\n".join(f"  {r}" for r in rows)
    return "\n".join([*comments, r"% needs \usepackage{amsmath} (equation*, aligned, bmatrix)",
                      r"\begin{equation*}", r"\begin{aligned}", body + ".",
                      r"\end{aligned}", r"\end{equation*}"])


def _plain(expr: Any) -> str:
    return sp.sstr(expr)


def interpolation_listing(spec: Any, syms: dict, latex: bool) -> str:
    """The interpolation family in symbols: row maps of the windows, the Lyapunov function
    and the interpolation pairs (the blocks themselves are sums of these pieces)."""
    st = syms["structure"]
    lag = st.lag
    d, p = st.dec, st.pos
    ex = d.Mq[d.labels.index("y0>*")] if "y0>*" in d.labels else None
    if latex:
        return _interpolation_latex(spec, syms, ex)
    fmt = _plain
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
    if ex is not None:
        lines.append(f"example M_(y0>*) = {fmt(sp.Matrix(ex).applyfunc(sp.factor))}")
    return "\n".join(lines)


def _interpolation_latex(spec: Any, syms: dict, ex: Any) -> str:
    """:func:`interpolation_listing` as a LaTeX snippet: the row maps and matrices."""
    st = syms["structure"]
    lag, d, p = st.lag, st.dec, st.pos

    def mat(m: Any) -> str:
        return sp.latex(sp.Matrix(m), mat_delim="", mat_str="bmatrix")

    comments = [f"% sosalgo lmi {spec.name}: interpolation certificate, lag l = {lag};",
                f"% (D) Z_{{l+1}}' P Z_{{l+1}} - rho^2 Z_l' P Z_l + sum eta_ij M_ij <= 0 "
                f"({d.width}x{d.width}), pairs: {' '.join(d.labels)}",
                f"% (P) Z_+' P Z_+ - sum lambda_ij M^+_ij >= 0 ({p.width}x{p.width}), "
                f"pairs: {' '.join(p.labels)}"]
    rows = [r"P &= " + mat(syms["P"]),
            f"Z_{{{lag}}} &= " + mat(d.Z[lag]),
            f"Z_{{{lag + 1}}} &= " + mat(d.Z[lag + 1]),
            r"Z_{+} &= " + mat(p.Z[lag])]
    if ex is not None:
        rows.append(r"M_{y_0 > \star} &= " + mat(sp.Matrix(ex).applyfunc(sp.factor)))
    return latex_block(comments, rows)
