"""A gallery page's Markdown and figure, from a spec and its computed rows
(:mod:`sosalgo_gallery`).

The update rule is rendered from the spec's own matrices and oracles: each oracle call
``y_i = C_i xi + sum_j D_ij u_j`` in order, as an explicit point when ``D_ii = 0`` and as a
proximal step ``y_i = prox_{t g}(v)``, ``t = -D_ii``, when not; then ``xi+ = A xi + B u`` row
by row and the output ``x = E xi`` (or the oracle point the spec names).
"""

from __future__ import annotations

import re
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp


def md_text(text: str) -> str:
    """Plain text made safe for Markdown (its active characters escaped)."""
    return re.sub(r"([\\`*_\[\]<>$|{}~#!&])", r"\\\1", text)


def tex(expr: Any) -> str:
    """LaTeX of a sympy expression (parameter names as Greek letters where they are)."""
    return sp.latex(expr)


def function_class(spec: Any, name: str) -> str:
    """The class of function ``name`` as the spec declares it (the seed's default: F(m, L))."""
    decl = spec.functions.get(name)
    return "smooth_strongly_convex" if decl is None else decl.cls


def linear_tex(terms: list[tuple[Any, str]]) -> str:
    """sum c_i v_i in LaTeX, in the order given (state before oracle answers), zero terms
    left out: ``x_k - h u_k`` rather than sympy's ``- h u_k + x_k``."""
    out = ""
    for coef, var in terms:
        c = sp.sympify(coef)
        if c == 0:
            continue
        sign = "-" if c.could_extract_minus_sign() else "+"
        c = -c if sign == "-" else c
        body = var if c == 1 else (rf"\left({tex(c)}\right) {var}" if c.is_Add
                                   else f"{tex(c)} {var}")
        out += (f"- {body}" if sign == "-" else body) if not out else f" {sign} {body}"
    return out or "0"


def function_words(spec: Any, name: str) -> str:
    """The class of function ``name`` in words (the class's own description, m = 0 said
    where it applies) and how the iteration calls it (from the diagonal of D)."""
    from sosalgo.classes import get_class

    cls = function_class(spec, name)
    try:
        found = get_class(cls)
        words = md_text(found.description) or f"class `{cls}`"
    except KeyError:
        found, words = None, f"class `{cls}`"
    D = spec.sympy_matrices().get("D", sp.zeros(spec.p, spec.p))
    calls = set()
    for i, fname in enumerate(spec.oracles):
        if fname == name:
            calls.add("the projection onto $K$" if cls == "indicator" else
                      "its proximal operator" if D[i, i] != 0 else
                      "its gradient" if found is not None and "gradient" in found.oracles
                      else "a subgradient")
    how = f"; called through {' and '.join(sorted(calls))}" if calls else ""
    m0 = (" ($m = 0$ here)" if spec.sublinear and "m = 0" not in words
          and (found is None or found.convex) else "")
    return f"{words}{m0}{how} (class `{cls}`)"


def is_shift(spec: Any) -> bool:
    """Two states whose first is the second one step late (A's first row [0, 1], no
    input): the state is (z_{k-1}, z_k), and only the second row is an update."""
    mats = spec.sympy_matrices()
    A, B = mats["A"], mats["B"]
    return spec.n == 2 and list(A.row(0)) == [0, 1] and all(b == 0 for b in B.row(0))


def _names(spec: Any) -> tuple[list[str], list[str], list[str]]:
    """The LaTeX names of the state's coordinates, the oracle answers and the oracle
    points at iteration k: x when the state (or its second half, for a shift) is the
    output point, z when it is not, xi^{(i)} for a general state."""
    n, p, mats = spec.n, spec.p, spec.sympy_matrices()
    last = sp.Matrix([[0] * (n - 1) + [1]])
    base = "x" if spec.output is None and mats["E"] == last else "z"
    if is_shift(spec):
        xs = [f"{base}_{{k-1}}", f"{base}_k"]
    elif n == 1:
        xs = [f"{base}_k"]
    else:
        xs = [rf"\xi^{{({i + 1})}}_k" for i in range(n)]
    us = ["u_k" if p == 1 else f"u^{{({i + 1})}}_k" for i in range(p)]
    ys = ["y_k" if p == 1 else f"y^{{({i + 1})}}_k" for i in range(p)]
    return xs, us, ys


def combination(spec: Any, state: list[Any], answers: list[Any]) -> str:
    """state . xi_k + answers . u_k in LaTeX; on a shift state with weights summing to 1,
    in momentum form: ``z_k + c (z_k - z_{k-1})``."""
    xs, us, _ = _names(spec)
    a = [sp.sympify(c) for c in state]
    rest = linear_tex(list(zip(answers, us, strict=False)))
    if is_shift(spec) and a[0] != 0 and sp.simplify(a[0] + a[1] - 1) == 0:
        c = sp.simplify(-a[0])
        sign, c = ("-", -c) if c.could_extract_minus_sign() else ("+", c)
        coef = "" if c == 1 else (rf"\left({tex(c)}\right) " if c.is_Add else f"{tex(c)} ")
        head = rf"{xs[1]} {sign} {coef}\left({xs[1]} - {xs[0]}\right)"
    else:
        head = linear_tex(list(zip(a, xs, strict=True)))
    if rest == "0":
        return head
    if head == "0":
        return rest
    return f"{head} {rest}" if rest.startswith("- ") else f"{head} + {rest}"


def oracle_lines(spec: Any) -> list[str] | None:
    """The oracle calls of one iteration in order (None when a call depends on a later one:
    then only the matrix form is shown)."""
    mats = spec.sympy_matrices()
    _, us, ys = _names(spec)
    C, D = mats["C"], mats.get("D", sp.zeros(spec.p, spec.p))
    lines = []
    for i, fname in enumerate(spec.oracles):
        if any(D[i, j] != 0 for j in range(i + 1, spec.p)):
            return None
        v = combination(spec, list(C.row(i)), [D[i, j] for j in range(i)])
        cls, t, u, y = function_class(spec, fname), -D[i, i], us[i], ys[i]
        if t == 0:
            lines.append(f"{y} &= {v}")
        elif cls == "indicator":
            lines.append(rf"{y} &= \Pi_K\left({v}\right)")
        else:
            lines.append(rf"{y} &= \operatorname{{prox}}_{{{tex(t)} {fname}}}\left({v}\right)")
        if cls == "smooth_strongly_convex":
            lines.append(rf"{u} &= \nabla {fname}({y})")
        else:
            part = rf"N_K({y})" if cls == "indicator" else rf"\partial {fname}({y})"
            pre = "" if t == 0 else rf"= \frac{{1}}{{{tex(t)}}}\left({v} - {y}\right) "
            lines.append(rf"{u} &{pre}\in {part}")
    return lines


def state_lines(spec: Any) -> list[str]:
    """xi_{k+1} = A xi_k + B u_k row by row (a shift's copy row left out), and the output
    point x_k."""
    mats = spec.sympy_matrices()
    xs, _, ys = _names(spec)
    A, B, E = mats["A"], mats["B"], mats.get("E")
    lines = []
    for r in range(1 if is_shift(spec) else 0, spec.n):
        rhs = combination(spec, list(A.row(r)), list(B.row(r)))
        lines.append(f"{xs[r].replace('_k', '_{k+1}')} &= {rhs}")
    if spec.output is not None:
        lines.append(f"x_k &= {ys[spec.output]}")
    else:
        out = combination(spec, list(E.row(0)), [])
        if out != "x_k":
            lines.append(f"x_k &= {out}")
    return lines


def matrix_form(spec: Any) -> str:
    """A, B, C, (D,) E of the spec, in LaTeX."""
    mats = spec.sympy_matrices()
    parts = [f"{k} = {tex(mats[k])}" for k in ("A", "B", "C", "D", "E") if k in mats]
    return r",\quad ".join(parts)


def parameter_table(spec: Any) -> list[str]:
    """A list-table of the parameters: value (or tie) and the design range."""
    from sosalgo_gallery import to_sympy

    if not spec.parameters:
        return []
    rows = ["```{list-table}", ":header-rows: 1", "", "* - parameter", "  - value",
            "  - range (the box `design` searches)"]
    for name, par in spec.parameters.items():
        sym = tex(sp.Symbol(name))
        value = (f"${sym} = {tex(to_sympy(par.tied))}$ (tied)" if par.is_tied
                 else f"${sym} = {tex(to_sympy(par.value))}$")
        if par.schedule is not None:  # one value per step
            value = "$" + ", ".join(tex(to_sympy(e)) for e in par.schedule) + "$ (per step)"
        elif par.per_step:
            value += " (free per step)" if par.range is not None else ""
        rng = "" if par.range is None else (
            f"$[{tex(to_sympy(par.range[0]))}, {tex(to_sympy(par.range[1]))}]$")
        rows += [f"* - ${sym}$", f"  - {value}", f"  - {rng}"]
    return rows + ["```"]


def update_rule(spec: Any) -> list[str]:
    """The 'Update rule' section: the functions, the iteration written out, the matrices."""
    lines = ["## Update rule", ""]
    names = list(spec.functions) or list(dict.fromkeys(spec.oracles))
    for fname in names:
        lines.append(f"- ${fname}$: {function_words(spec, fname)}")
    if spec.finite_sum is not None:  # a program, one function (or block) drawn per step
        return lines + finite_sum_lines(spec) + parameter_table(spec) + [""]
    objective = " + ".join(names)
    lines += ["", f"Iteration $k$ of the method on ${objective}$, "
              "as the spec's matrices and oracles define it:", ""]
    calls = oracle_lines(spec)
    body = (calls or []) + state_lines(spec)
    lines += ["$$", " \\\\\n".join(body), "$$", ""]
    lines += ["In the spec's linear-system form "
              r"$\xi_{k+1} = A\xi_k + B u_k$, $y_k = C\xi_k + D u_k$, $x_k = E\xi_k$ "
              "(each block acts on $\\mathbb{R}^d$ as $\\otimes I_d$):", "",
              "$$", matrix_form(spec), "$$", ""]
    lines += parameter_table(spec)
    return lines + [""]


def finite_sum_lines(spec: Any) -> list[str]:
    """A finite sum's step as its spec writes it (docs/oracles.md, stochastic finite
    sums): the state, the assignments, the constraints."""
    fs = spec.finite_sum
    drawn = ("one of the blocks of coordinates" if fs.blocks
             else f"one of the functions ${fs.function}_1, \\dots, {fs.function}_n$")
    state = ", ".join(f"{name}[j]" if per else name for name, per in fs.state)
    body = [f"state: [{state}]", "step:"]
    body += [f"  - {target}{'[i]' if ix else ''} = {expr}" for target, ix, expr in fs.step]
    body += ["constraints:"] + [f"  - {c}" for c in fs.constraints] if fs.constraints else []
    return ["", f"Every step draws {drawn} uniformly (index $i$) and runs the spec's "
            "`finite_sum:` program:", "", "```yaml", *body, "```", ""]


def measure_sentence(spec: Any) -> str:
    """What the certified number bounds, in the spec's measure."""
    names = list(spec.functions) or ["f"]
    if spec.measure == "distance":
        err = r"\|x_k - x_\star\|^2"
    elif len(names) == 1:
        err = rf"{names[0]}(x_k) - {names[0]}_\star"
    else:
        err = r"F(x_k) - F_\star"
    total = "" if len(names) == 1 or spec.measure == "distance" else (
        f" with $F = {' + '.join(names)}$")
    if spec.sublinear:
        return (rf"The certified constant $c$ bounds ${err} \le c\,\|x_0 - x_\star\|^2 / k$ "
                rf"for every $k \ge 1${total} and every function of the class.")
    return (rf"The certified rate $\rho$ bounds ${err} \le \rho^{{2k}} V_0$ for every $k$"
            rf"{total} and every function of the class, where $V_0$ is the value of the "
            r"certificate's Lyapunov function at the start: the bound shrinks by $\rho^2$ "
            "per iteration.")


def rate_cell(row: dict[str, Any], key: str) -> str:
    """A certified number: the exact proof rounded up, or why there is none."""
    from sosalgo_gallery import round_up

    if row["proven"] is not None:
        return round_up(Fraction(row["proven"]))
    if row[key] is not None:
        return f"{row[key]:.{6}f} (not proven exactly)"
    return "none certified"


def rates_table(spec: Any, rows: list[dict[str, Any]]) -> list[str]:
    """A list-table: kappa (or L), the certified number, each reference."""
    refs = list(spec.references)
    first, key, label = (("$L$", "constant", "certified $c$") if spec.sublinear
                         else (r"$\kappa$", "rho", r"certified $\rho$"))
    lines = ["```{list-table}", ":header-rows: 1", "", f"* - {first}", f"  - {label}"]
    lines += [f"  - reference: {md_text(r)}" for r in refs]
    for row in rows:
        lines.append(f"* - {row['L' if spec.sublinear else 'kappa']:g}")
        lines.append(f"  - {rate_cell(row, key)}")
        for r in refs:
            v = row["references"].get(r)
            lines.append("  - " + ("-" if v is None else f"{v:.6f}"))
    return lines + ["```"]


def rates_section(spec: Any, rows: list[dict[str, Any]], image: str) -> list[str]:
    """The 'Certified rates' section: what the number bounds, the table, the figure."""
    family = md_text(rows[0]["family"])
    scale = (f"$m = 0$, $L = {spec.L:g}$" if spec.sublinear
             else f"$m = {spec.m:g}$ and $L = \\kappa m$")
    lines = ["## Certified " + ("constant" if spec.sublinear else "rates"), "",
             measure_sentence(spec), "",
             f"Computed when this page was built ({scale}) by the {family} certificate "
             "family; each certificate is then proven in exact rational arithmetic "
             "(as `sosalgo verify` does) and the proven value is shown rounded up. "
             "The references are the spec's closed forms (`references:`), rounded.", ""]
    lines += rates_table(spec, rows)
    what = ("the bound $c/k$ against $k$ (with $\\|x_0 - x_\\star\\| = 1$), the references "
            "as $c/k$ curves" if spec.sublinear else
            "the certified rate against $\\kappa$ (points), the references as curves")
    lines += ["", f"```{{figure}} {image}", f":alt: {spec.name}: {what}", "",
              f"{spec.name}: {what}.", "```", ""]
    return lines


def nonconvex(spec: Any) -> list[str]:
    """The spec's nonconvex functions (no rate is certified; ``sosalgo pep`` answers)."""
    from sosalgo.certificates import nonconvex_functions

    return nonconvex_functions(spec)


def operators_without_rate(spec: Any) -> list[str]:
    """The spec's operators when no family certifies a rate for it (m: 0)."""
    from sosalgo.spec.loading import operator_functions

    return operator_functions(spec) if spec.sublinear else []


def operator_section(spec: Any) -> list[str]:
    """An m: 0 operator spec: sosalgo pep answers its question; its references."""
    from sosalgo.certificates.sublinear import operator_refusal

    rate = ("no sublinear rate family applies" if operator_refusal(spec) else
            "`sosalgo analyze SPEC` certifies the O(1/k) constant of its squared residual")
    text = (f"{', '.join(operators_without_rate(spec))}: operator classes "
            f"(the operators page of the documentation), {rate}. Its "
            "question, as the spec's `pep:` field asks it, is answered after $N$ steps "
            "by `sosalgo pep SPEC --steps N`.")
    return ["## Operators", "", text, ""]


def sublinear_refused(spec: Any) -> str:
    """Why no sublinear family takes an m: 0 spec whose classes it would ("" when it
    does): indicators alone, or a state at the optimum that moves with the optimal
    subgradients (Douglas-Rachford); ``sosalgo pep`` answers."""
    from sosalgo.errors import ModelError
    from sosalgo.model import bind_sublinear
    from sosalgo.spec.loading import set_functions
    from sosalgo.steps import changes_with_k

    if not spec.sublinear or changes_with_k(spec):  # (those: pep answers in any case)
        return ""
    if set_functions(spec):
        return (f"{', '.join(set_functions(spec))}: indicators alone (a feasibility "
                "problem), with m: 0 no sublinear family bounds a distance")
    try:
        bind_sublinear(spec)
    except ModelError:
        return ("its state at the optimum moves with the optimal subgradients (as "
                "Douglas-Rachford's), which the sublinear families, started at rest at "
                "x_0, do not take")
    return ""


def inhomogeneous(spec: Any) -> list[str]:
    """The spec's functions whose class has conditions no Lyapunov family takes (a
    constant, a condition about x* alone; ``sosalgo pep`` answers)."""
    from sosalgo.certificates import inhomogeneous_functions

    return inhomogeneous_functions(spec)


def steps_section(spec: Any, rows: list[dict[str, Any]]) -> list[str]:
    """A method that changes with k, or on a nonconvex class: what its matrices use, and
    its references against the horizon N (its worst case is the finite-horizon PEP,
    ``sosalgo pep --steps N``)."""
    from sosalgo.steps import changes_with_k

    if operators_without_rate(spec) and not changes_with_k(spec):
        return operator_section(spec)
    if not changes_with_k(spec):  # time-invariant on a class no Lyapunov family takes
        what = (f"{', '.join(nonconvex(spec))} is nonconvex" if nonconvex(spec) else
                f"{', '.join(inhomogeneous(spec))}: its class's conditions are not "
                "pairwise homogeneous inequalities" if inhomogeneous(spec) else
                sublinear_refused(spec))
        text = (f"{what}: no rate is certified (no "
                "Lyapunov family applies). Its worst case after $N$ steps is a performance "
                "estimation problem: `sosalgo pep SPEC --steps N` (the pep command's "
                "page: minimum over iterates and nonconvex classes).")
        head = "## A nonconvex class" if nonconvex(spec) else "## A class only pep answers"
        return [head, "", text, ""]
    text = (r"Its coefficients depend on the iteration $k = 0, \dots, N - 1$ (and the "
            "horizon $N$): the matrices above are those of step $k$")
    seqs = [f"${tex(sp.Symbol(s))}$" for s in spec.sequences]
    if seqs:
        text += (", written with the sequence " + ", ".join(seqs) + " at $k$ (its value "
                 "at $k + 1$ carries the subscript next)")
    text += (". Its worst case after $N$ steps is a performance estimation problem: "
             "`sosalgo pep SPEC --steps N` "
             "({ref}`methods that change with k <methods-that-change-with-k>`).")
    lines = ["## A method that changes with k", "", text, ""]
    for name, decl in spec.sequences.items():
        from sosalgo_gallery import to_sympy

        sym = tex(sp.Symbol(name))
        rules = [f"${sym}_0 = {tex(to_sympy(decl.first))}$",
                 f"${sym}_{{k+1}} = {tex(to_sympy(decl.next))}$"]
        if decl.last is not None:
            rules.append(f"${sym}_N = {tex(to_sympy(decl.last))}$")
        lines.append(f"- {', '.join(rules)} (on the right, ${sym}$ is ${sym}_k$)")
    return lines + [""]


def pep_section(spec: Any, rows: list[dict[str, Any]], image: str) -> list[str]:
    """The 'Certified worst case' section of a method that changes with k or of one on a
    nonconvex class: tau_N and its
    exact proof at each N, the references, the figure."""
    kappa = rows[0]["kappa"]
    scale = (f"$m = 0$, $L = {spec.L:g}$" if kappa is None
             else f"$\\kappa = {kappa:g}$")
    lines = ["## Certified worst case", "",
             f"The worst case $\\tau_N$ is the largest value of the measure "
             f"`{rows[0]['measure']}` after $N$ steps over every function of the class, "
             f"with the initial condition `{rows[0]['initial']}` at most 1 (the pep "
             "command's `--measure` and `--initial`).", "",
             f"Computed when this page was built ({scale}) by `sosalgo pep SPEC --steps N`: "
             "$\\tau_N$ is the performance estimation problem's value (floating point), "
             "its dual certificate is then proven in exact rational arithmetic and the "
             "proven bound is shown rounded up. The references are the spec's closed "
             "forms (`references:`), rounded.", "",
             "```{list-table}", ":header-rows: 1", "", "* - $N$",
             "  - proven $\\tau_N$", "  - PEP $\\tau_N$"]
    refs = list(rows[0]["references"])  # pep's question's (pep.references when named)
    lines += [f"  - reference: {md_text(r)}" for r in refs]
    for row in rows:
        lines += [f"* - {row['steps']}", f"  - {rate_cell(row, 'tau')}",
                  "  - " + ("-" if row["tau"] is None else f"{row['tau']:.6g}")]
        for r in refs:
            v = row["references"].get(r)
            lines.append("  - " + ("-" if v is None else f"{v:.6f}"))
    what = "the proven worst case against the horizon N (points), the references"
    return lines + ["```", "", f"```{{figure}} {image}", f":alt: {spec.name}: {what}", "",
                    f"{spec.name}: {what}.", "```", ""]


def page_markdown(spec: Any, rows: list[dict[str, Any]], yaml_path: str, image: str) -> str:
    """The whole gallery page of one spec."""
    lines = [f"({'gallery-' + spec.name})=", f"# {md_text(spec.name)}", "",
             md_text(spec.description), ""]
    lines += update_rule(spec)
    command = f"sosalgo analyze {spec.name}.yaml"
    if "steps" in rows[0]:  # changes with k, nonconvex or operators: sosalgo pep answers
        lines += steps_section(spec, rows)
        if "tau" in rows[0]:
            lines += pep_section(spec, rows, image)
        command = f"sosalgo pep {spec.name}.yaml --steps {rows[-1]['steps']}"
    else:
        lines += rates_section(spec, rows, image)
    lines += ["## The spec", "",
              f"Copy it with `sosalgo examples {spec.name} --copy .`, then run "
              f"`{command}`.", "",
              f"```{{literalinclude}} {yaml_path}", ":language: yaml", "```", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- figure
def figure_style() -> Any:
    """sosalgo's shared figure style (:mod:`sosalgo.report.style`)."""
    from sosalgo.report import style

    return style


def _grid(values: list[float], points: int = 300) -> np.ndarray:
    """A fine grid spanning ``values`` (log-spaced), the values themselves included."""
    lo, hi = min(values), max(values)
    return np.array([lo]) if lo == hi else np.union1d(np.geomspace(lo, hi, points), values)


def _linear_axes(ax: Any, style: Any, spec: Any, rows: list[dict[str, Any]]) -> None:
    from sosalgo_gallery import reference_values

    kappas = [r["kappa"] for r in rows]
    grid = _grid(kappas)
    curves = [reference_values(spec, float(k)) for k in grid]
    for i, name in enumerate(spec.references):
        ys = [np.nan if c.get(name) is None else c[name] for c in curves]
        ax.plot(grid, ys, "--", color=style.color(i), label=f"reference: {name}", zorder=4)
    done = [(r["kappa"], float(Fraction(r["proven"]))) for r in rows if r["proven"] is not None]
    if done:
        ax.plot(*zip(*done, strict=True), "o-", color="black", label="certified rate", zorder=3)
    ax.set_xscale("log")
    style.log_ticks(ax.xaxis, min(kappas), max(kappas))
    ax.set_xlabel(r"condition number $\kappa = L/m$")
    ax.set_ylabel(r"rate $\rho$")


def _sublinear_axes(ax: Any, style: Any, spec: Any, rows: list[dict[str, Any]]) -> None:
    from sosalgo_gallery import round_up

    ks = np.arange(1, 101)
    drawn = []
    for i, (name, value) in enumerate(rows[0]["references"].items()):
        if value is not None:
            ax.plot(ks, value / ks, "--", color=style.color(i), label=f"reference: {name}",
                    zorder=4)
            drawn.append(value)
    if rows[0]["proven"] is not None:
        c = Fraction(rows[0]["proven"])
        ax.plot(ks, float(c) / ks, "-", color="black", label=f"certified c = {round_up(c)}",
                zorder=3)
        drawn.append(float(c))
    ax.set_xscale("log")
    ax.set_yscale("log")
    style.log_ticks(ax.xaxis, 1, 100)
    if drawn:
        style.log_ticks(ax.yaxis, min(drawn) / 100, max(drawn))
    ax.set_xlabel("iteration $k$")
    ax.set_ylabel(r"bound on $(f(x_k) - f_\star) / \|x_0 - x_\star\|^2$")


def _steps_axes(ax: Any, style: Any, spec: Any, rows: list[dict[str, Any]]) -> None:
    ns = [r["steps"] for r in rows]
    for i, name in enumerate(rows[0]["references"]):  # pep's question's
        ys = [np.nan if r["references"].get(name) is None else r["references"][name]
              for r in rows]
        ax.plot(ns, ys, "s--", color=style.color(i), label=f"reference: {name}", zorder=4,
                markerfacecolor="none")
    done = [(r["steps"], float(Fraction(r["proven"]))) for r in rows if r["proven"] is not None]
    if done:
        ax.plot(*zip(*done, strict=True), "o-", color="black", label="proven worst case",
                zorder=3)
    ax.set_xticks(ns)
    ax.set_yscale("log")
    ax.set_xlabel("horizon $N$ (steps)")
    ax.set_ylabel(r"worst case $\tau_N$")


def draw_figure(spec: Any, rows: list[dict[str, Any]], target: Path) -> None:
    """The page's figure in sosalgo's shared style, written as PNG."""
    from sosalgo.report import pyplot

    style = figure_style()
    fig, ax = style.new_figure()
    try:
        axes = (_steps_axes if "steps" in rows[0] else
                _sublinear_axes if spec.sublinear else _linear_axes)
        axes(ax, style, spec, rows)
        ax.set_title(spec.name)
        style.finish(ax)
        fig.tight_layout()
        fig.savefig(target, format="png", dpi=110)
    finally:
        pyplot().close(fig)
