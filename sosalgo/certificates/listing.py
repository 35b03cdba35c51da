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


# --------------------------------------------------------------------------- composite specs


def _rows(mats: dict[str, Any], p: int, steps: int, output: int | None) -> dict[str, Any]:
    """Symbolic row maps of the window w = (xi_0 - xi*, u~[0], ..., u~[steps-1]): the
    state Xi_t, the call points Y_t and the output x_t (all minus their fixed point)."""
    A, B, C, D = mats["A"], mats["B"], mats["C"], mats["D"]
    n = A.shape[0]
    width = n + p * steps
    eye = sp.eye(width)
    U = [eye[n + p * t: n + p * (t + 1), :] for t in range(steps)]
    Xi = [eye[:n, :]]
    for t in range(steps - 1):
        Xi.append((A * Xi[t] + B * U[t]).applyfunc(sp.simplify))
    Y = [(C * Xi[t] + D * U[t]).applyfunc(sp.simplify) for t in range(steps)]
    out = [Y[t][output, :] if output is not None else (mats["E"] * Xi[t]).applyfunc(sp.simplify)
           for t in range(steps)]
    return {"Xi": Xi, "Y": Y, "out": out, "width": width}


def _entries(n: int, p: int, steps: int) -> list[str]:
    return ([f"xi{i + 1}" for i in range(n)] if n > 1 else ["xi"]) + [
        f"u{i + 1}[{t}]" for t in range(steps) for i in range(p)]


def _dot(row: Any, names: list[str]) -> str:
    """A row map as a sum over the named entries of w (plain text)."""
    terms = [sp.sstr(sp.factor(c) * sp.Symbol(nm)) for c, nm in zip(list(row), names,
                                                                      strict=False) if c != 0]
    return " + ".join(terms).replace("+ -", "- ") or "0"


def _functions(spec: Any, om: Any, latex: bool) -> list[str]:
    """One line per function: its class, parameters, calls (gradient or proximal step)."""
    lines = []
    D = spec.templates()["D"] if "D" in spec.matrices else sp.zeros(spec.p, spec.p)
    for j, fn in enumerate(om.functions):
        decl = spec.functions[fn.name]
        params = ", ".join(f"{k} = {decl.params[k]}" for k in fn.cls.parameters)
        calls = ", ".join(f"y{i + 1} ({'gradient' if D[i, i] == 0 else f'prox, t = {-D[i, i]}'})"
                          for i, o in enumerate(om.oracles) if o == j)
        head = f"{fn.name}: {fn.cls.name}" + (f" ({params})" if params else "")
        lines.append(f"{head}; calls {calls}; for every ordered pair (a, b) of its points: "
                     f"{fn.cls.listing_text(fn.params, latex)}")
    return lines


def composite_listing(spec: Any, free: Sequence[str] | None, lag: int, om: Any, st: Any,
                      latex: bool) -> str:
    """``sosalgo lmi`` on a composite spec: functions and their inequalities, the lifted
    vector and its row maps, the Lyapunov function and the blocks; ``om``/``st``: the
    numeric method and its structure at one kappa (the pair lists, sizes the solver sees)."""
    m, L, kappa = sp.Symbol("m", positive=True), sp.Symbol("L", positive=True), sp.Symbol(
        "kappa", positive=True)
    mats = {k: v.xreplace({kappa: L / m}) for k, v in spec.templates(free).items()}
    mats.setdefault("D", sp.zeros(spec.p, spec.p))
    steps = lag + 2
    rows = _rows(mats, spec.p, steps, spec.output)
    Z = {t: sp.Matrix.vstack(rows["Xi"][t], *[sp.eye(rows["width"])[
        spec.n + spec.p * (t - tau): spec.n + spec.p * (t - tau + 1), :]
        for tau in range(lag + 1)]) for t in (lag, lag + 1)}
    if latex:
        return _composite_latex(spec, om, st, lag, rows, Z)
    names = _entries(spec.n, spec.p, steps)
    out = f"y{spec.output + 1}" if spec.output is not None else "E xi"
    lines = [f"{spec.name}: interpolation certificate (composite), lag l = {lag}, "
             f"measure {spec.measure}, output x = {out}",
             f"problem: minimize {' + '.join(fn.name for fn in om.functions)}; each f_j tilted: "
             "h_j = f_j - f_j(x*) - <s_j*, . - x*> >= 0, h_j(x*) = 0, u~_i = u_i - s*_j(i) in "
             "dh_j(i)(y_i), sum_j s_j* = 0", *_functions(spec, om, False),
             f"lifted vector w = ({', '.join(names)}), deviations from the fixed point "
             f"(xi - xi*, u~ = u - u*)  [{rows['width']} entries"
             + (f"; + {st.dec.width - rows['width']} free subgradients at the output points]"
                if st.dec.width > rows["width"] else "]")]
    for t in range(steps):
        pts = [f"y{i + 1}[{t}] = {_dot(rows['Y'][t][i, :], names)}" for i in range(spec.p)]
        lines.append(f"  step {t}: " + ";  ".join(pts)
                     + f";  x[{t}] = {_dot(rows['out'][t], names)}")
    lines += _blocks_text(spec, st, lag, Z)
    return "\n".join(lines)


def _blocks_text(spec: Any, st: Any, lag: int, Z: dict[int, Any]) -> list[str]:
    """The Lyapunov function and the blocks (D), (P) with their sizes and pair lists."""
    d, p = st.dec, st.pos
    c = " + c sum_j h_j(x_k)" if st.has_c else ""
    past = "" if lag == 0 else f", ..., u~[k-{lag}]"
    meas = ("|x_l - x*|^2 (in (P))" if spec.measure == "distance"
            else "sum_j h_j(x_l) (in the function-value rows of (P))")
    return [
        f"V_k = z_k' P z_k + sum_(tau=0..{lag}) sum_i p_(tau,i) h_j(i)(y_i[k-tau]){c},  "
        f"z_k = (xi_k - xi*, u~[k]{past}) = Z_t w  [{st.nz} entries; P symmetric, "
        f"not required PSD; {st.npi} weights p{', c' if st.has_c else ''}]",
        *(f"  Z_{t} = {sp.sstr(Z[t].tolist())}" for t in (lag, lag + 1)),
        f"(D)  Z_{lag + 1}' P Z_{lag + 1} - rho^2 Z_{lag}' P Z_{lag} + sum eta_ab M_ab <= 0 "
        f"({d.width}x{d.width}) and {d.nphi} function-value rows <= 0; eta >= 0 on "
        f"{len(d.labels)} pairs: {' '.join(d.labels)}",
        f"(P)  V_{lag} - sum lambda_ab q_ab >= measure = {meas}: a {p.width}x{p.width} "
        f"block and {p.nphi} function-value rows; lambda >= 0 on {len(p.labels)} pairs: "
        f"{' '.join(p.labels)}",
        "each pair's M_ab, q_ab: the class inequality above at its two points (h, g, x rows "
        "of w); rho is certified when (D) and (P) hold",
    ]


def _composite_latex(spec: Any, om: Any, st: Any, lag: int, rows: dict[str, Any],
                     Z: dict[int, Any]) -> str:
    """:func:`composite_listing` as a LaTeX snippet: classes, row maps, Z matrices."""
    def mat(x: Any) -> str:
        return sp.latex(sp.Matrix(x), mat_delim="", mat_str="bmatrix")

    d, p = st.dec, st.pos
    comments = [f"% sosalgo lmi {spec.name}: interpolation certificate (composite), lag "
                f"l = {lag}, measure {spec.measure}; h_j tilted, u~ = u - s*;",
                f"% (D) Z_{{l+1}}' P Z_{{l+1}} - rho^2 Z_l' P Z_l + sum eta_ab M_ab <= 0 "
                f"({d.width}x{d.width}), {len(d.labels)} pairs;",
                f"% (P) V_l - sum lambda_ab q_ab >= measure ({p.width}x{p.width}), "
                f"{len(p.labels)} pairs; w = (xi_0 - xi*, u~[0], ..., u~[{lag + 1}])"]
    rows_tex = [f"\\text{{{fn.name} ({fn.cls.name.replace('_', chr(92) + '_')})}} &: "
                f"{fn.cls.listing_text(fn.params, True)}"
                for fn in om.functions]
    for t in range(lag + 2):
        rows_tex.append(f"Y_{{{t}}} &= " + mat(rows["Y"][t]))
    rows_tex += [f"x_{{{t}}} &= " + mat(r) for t, r in enumerate(rows["out"])]
    rows_tex += [f"Z_{{{t}}} &= " + mat(Z[t]) for t in (lag, lag + 1)]
    return latex_block(comments, rows_tex)
