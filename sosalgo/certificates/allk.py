"""Bounds for every k: potentials whose weights are polynomials in k (docs/all-k.md).

A spec whose matrices are rational functions of the iteration index k (Nesterov's
momentum ``beta: k/(k + 3)``) on one L-smooth convex f (``m: 0``, one gradient call,
x = E xi) is certified for every N >= 1 at once:

    f(x_N) - f* <= C |x_0 - x*|^2 / a(N),   a(N) = N^2 + a1 N + a0   (degree 2)

by a potential phi_k = z_k' P(k) z_k + p(k) (f(q_k) - f*), z_k = (xi_k - xi*, g_k),
q_k = C(k) xi_k the gradient's point, P(k), p(k) polynomials in k, such that for every
real k >= 0

    (D)  phi_{k+1} <= phi_k,
    (B)  a(k + 1) (f(q_k) - f* + g_k'(x_{k+1} - q_k) + L/2 |x_{k+1} - q_k|^2) <= phi_k,
    (I)  phi_0 <= C |x_0 - x*|^2   (the method started at rest, xi_0 = u x_0),

each written as a quadratic form in the window plus linear terms in the function values
minus nonnegative combinations (multipliers polynomials in k with nonnegative
coefficients) of the interpolation inequalities of L-smooth convex functions, with the
linear terms identically 0. The bracket in (B) bounds f(x_{k+1}) - f* (L-smoothness), so
a(N) (f(x_N) - f*) <= phi_{N-1} <= phi_0 <= C |x_0 - x*|^2 (when the output is the
gradient's point, (B) is a(k) (f(x_k) - f*) <= phi_k for k >= 1 instead; everything is
written for f/L, 1-smooth, and C scaled back by L). (D) and (B), multiplied by a
denominator of the method's matrices that has no root on k >= 0, are matrix polynomials
that must be negative semidefinite for every k >= 0: the search asks -M(k) =
Z(k)' G0 Z(k) + k Z(k)' G1 Z(k), G0, G1 >= 0 (Z(k) = [I; kI; k^2 I; ...]), one SDP
minimizing C; the proof (:mod:`sosalgo.certificates.exact_allk`) is exact and does not
use the Gram matrices.

This module holds the method as closed forms in k (:func:`closed_form_system`, which
refuses every other spec in one line), the conditions in symbols (:func:`conditions`,
shared by the search and the proof) and the search (:func:`search`, then
:func:`margin_point`): at the SDP's optimum it reads how each block grows with k
(:func:`block_growth`: coefficients forced to 0, leading terms that cancel along a
direction polynomial in k) and asks for a margin of that shape, so that the point
rounded to fractions keeps every inequality.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass, field
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from sosalgo.classes import SEED_CLASS
from sosalgo.spec.types import NEXT_SUFFIX, SpecError, value_order
from sosalgo.steps import changes_with_k

if TYPE_CHECKING:
    from sosalgo.certificates.allk_recurrence import Recurrence
    from sosalgo.spec.types import Spec

__all__ = ["ALLK", "AllKFamily", "AllKSystem", "Conditions", "Growth", "Search",
           "block_growth", "bound_argument", "closed_form_system", "conditions", "margin_point",
           "offset_bounds", "pinned_point", "search", "why_not_closed_form"]

SMOOTH_CONVEX = SEED_CLASS.name  # F(m, L), with m = 0: L-smooth convex
MAX_STATES = 4  # the proof checks every principal minor of windows of n + 2 rows
MAX_K_DEGREE = 3  # of the numerators and denominators of the matrices' entries in k
DEGREE_TOL = 1e-5  # a diagonal coefficient below this (relative) is the solver's noise
CANCEL_TOL = 1e-3  # leading terms cancel when their 2 x 2 determinant is below this


@dataclass
class AllKSystem:
    """The method as closed forms in k: A(k), B(k), C(k) (rational functions of the
    symbol ``k`` with rational coefficients), E constant, L rational, and the state at
    rest u (A(k) u = u, C(k) u = E u = 1 for every k). :func:`closed_form_system` gives
    it in units L = 1 (f/L, whose gradient is g/L: B times the spec's L, ``scale``)."""

    k: Any
    A: Any
    B: Any
    C: Any
    E: Any
    L: Any
    u: Any
    source: str = ""
    scale: Any = 1  # the spec's L: the system is f/L's (1-smooth), C scales back by it
    recurrence: Recurrence | None = None  # the sequence the method runs on, if any

    def weight_at(self) -> Any:
        """The weights' argument at step k, as an expression of ``k`` (k itself, or the
        sequence's value theta_k)."""
        return self.k if self.recurrence is None else self.recurrence.at

    def weight_next(self) -> Any:
        """The weights' argument at step k + 1 (k + 1, or theta_{k+1})."""
        return self.k + 1 if self.recurrence is None else self.recurrence.next

    def weight_first(self) -> Any:
        """The weights' argument at step 0 (0, or theta_0 = 1)."""
        return 0 if self.recurrence is None else 1

    def offset(self) -> Fraction:
        """c of a >= (argument + c)^degree: 1 (a(N) >= (N + 1)^2), or 0 for a sequence
        (a(t) >= t^2, and theta_{N-1} >= (N + 1)/2)."""
        return Fraction(1) if self.recurrence is None else Fraction(0)

    @property
    def n(self) -> int:
        return int(self.A.shape[0])


# --------------------------------------------------------------------------- the spec
def _setting_problem(spec: Spec) -> tuple[str, str] | None:
    """(field, why) when the spec is outside the setting of the all-k potentials."""
    if spec.has_condition_number:
        return "m", "the all-k bound is for m: 0 (smooth convex f; give L)"
    decl = spec.functions.get("f")
    if (len(spec.functions) != 1 or decl is None or decl.cls != SMOOTH_CONVEX
            or decl.given or spec.oracles != ("f",)):
        return "functions", ("the all-k bound takes one L-smooth convex f "
                             "(smooth_strongly_convex, m: 0) queried by its gradient")
    if "D" in spec.matrices or spec.output is not None or spec.measure != "function":
        return "matrices", "the all-k bound takes no D, x = E xi and measure: function"
    return None


def _sequence_names(spec: Spec) -> dict[Any, str]:
    from sosalgo.kernel.expr.parse import sympy_symbol

    out = {}
    for s in spec.sequences:
        out[sympy_symbol(s)] = s
        out[sympy_symbol(s + NEXT_SUFFIX)] = s
    return out


def _recurrence_error(spec: Spec, s: str) -> SpecError:
    return SpecError(spec.source, f"sequences.{s}",
                     f"{s} is given by a recurrence, not as a closed form in k (the all-k "
                     "bound needs parameters that are rational functions of k)")


def _used_sequences(spec: Spec) -> list[str]:
    """The sequences the method's parameters or matrices use (in the spec's order)."""
    from sosalgo.kernel.expr.parse import to_sympy

    seqs = _sequence_names(spec)
    exprs = [par.tied if par.is_tied else par.value for par in spec.parameters.values()
             if par.schedule is None]
    exprs += [e for rows in spec.matrices.values() for row in rows for e in row]
    used = set()
    for expr in exprs:
        if expr is None:
            continue
        used |= {seqs[sym] for sym in to_sympy(expr).free_symbols if sym in seqs}
    return [s for s in spec.sequences if s in used]


def _closed_form(value: Any, where: str, spec: Spec, k: Any) -> Any:
    """``value`` as a rational function of k with rational coefficients, or SpecError."""
    import sympy as sp

    seqs = _sequence_names(spec)
    for sym in sorted(value.free_symbols, key=str):
        if sym in seqs:
            raise _recurrence_error(spec, seqs[sym])
        if str(sym) == "N":
            raise SpecError(spec.source, where, "depends on the horizon N: the all-k bound "
                            "needs the same method for every N")
        if str(sym) == "k" and sym != k:
            raise SpecError(spec.source, where, "uses k beside a sequence (the all-k bound "
                            "takes one or the other)")
        if sym != k:
            raise SpecError(spec.source, where, f"{sym} has no value")
    value = sp.cancel(sp.together(value))
    num, den = sp.fraction(value)
    try:
        degree = max(sp.Poly(num, k, domain="QQ").degree(),
                     sp.Poly(den, k, domain="QQ").degree())
    except (sp.PolynomialError, sp.CoercionFailed, sp.GeneratorsNeeded):
        if not value.free_symbols and value.is_rational:
            return value
        raise SpecError(spec.source, where, f"{value} is not a rational function of k "
                        "with rational coefficients") from None
    if degree > MAX_K_DEGREE:
        raise SpecError(spec.source, where, f"{value}: degree {degree} in k (the all-k bound "
                        f"takes numerators and denominators of degree <= {MAX_K_DEGREE})")
    return value


def _parameter_values(spec: Spec, env: dict[Any, Any], k: Any) -> None:
    from sosalgo.kernel.expr.parse import sympy_symbol, to_sympy

    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        if par.schedule is not None:
            raise SpecError(spec.source, f"parameters.{p}", "a schedule (one value per "
                            "step) is not a closed form in k: write the value as an "
                            "expression of k")
        expr, where = ((par.tied, f"parameters.{p}") if par.is_tied
                       else (par.value, f"parameters.{p}.value"))
        value = to_sympy(expr).xreplace(env)
        env[sympy_symbol(p)] = _closed_form(value, where, spec, k)


def closed_form_system(spec: Spec) -> AllKSystem:
    """The spec's method as closed forms in k (:class:`AllKSystem`); SpecError (one line
    naming the field, then where a bound after N steps is: ``sosalgo pep``) when the
    spec is not of that form."""
    from sosalgo.spec.types import VARIES

    try:
        return _closed_form_system(spec)
    except SpecError as exc:
        if not changes_with_k(spec):
            raise
        raise SpecError(spec.source, exc.field, f"{exc.message}; it "
                        + VARIES.format(source=spec.source)) from None


def _closed_form_system(spec: Spec) -> AllKSystem:
    import sympy as sp

    from sosalgo.certificates.allk_recurrence import check_lemma, recognize
    from sosalgo.kernel.expr.parse import sympy_symbol, to_sympy

    problem = _setting_problem(spec)
    if problem is not None:
        raise SpecError(spec.source, problem[0], problem[1])
    rec = recognize(spec, _used_sequences(spec), sp.Symbol("s", real=True))
    k = sympy_symbol("k") if rec is None else rec.var
    L = (sp.nsimplify(to_sympy(spec.L_expr)) if spec.L_expr is not None
         else sp.Rational(Fraction(repr(float(spec.L)))))
    if not (L.is_rational and L > 0):
        raise SpecError(spec.source, "L", f"{L} is not a positive rational number")
    env: dict[Any, Any] = {sympy_symbol("m"): sp.Integer(0), sympy_symbol("L"): L}
    if rec is not None:
        env |= {sympy_symbol(rec.name): rec.at, sympy_symbol(rec.name + NEXT_SUFFIX): rec.next}
    _parameter_values(spec, env, k)
    mats = {}
    for key, M in spec.sympy_matrices().items():
        mats[key] = M.applyfunc(lambda e, key=key: _closed_form(
            sp.sympify(e).xreplace(env), f"matrices.{key}", spec, k))
    if "E" not in mats:
        raise SpecError(spec.source, "matrices.E", "required (x = E xi)")
    if mats["E"].has(k):
        raise SpecError(spec.source, "matrices.E", "the all-k bound needs E constant in k")
    # in units L = 1 (f/L is 1-smooth, its gradient g/L): B L; the bound scales back by L
    if rec is not None and mats["C"].has(k):
        raise SpecError(spec.source, "matrices.C", f"uses {rec.name}: the gradient's point "
                        "must not depend on the sequence (the all-k bound with a sequence)")
    system = AllKSystem(k, mats["A"], (mats["B"] * L).applyfunc(sp.cancel), mats["C"],
                        mats["E"], sp.Integer(1), None, spec.source, L, rec)
    why = None if rec is None else check_lemma(rec)
    if why is not None:
        raise SpecError(spec.source, f"sequences.{rec.name}", why)
    if system.n > MAX_STATES:
        raise SpecError(spec.source, "matrices.A", f"{system.n} states: the all-k bound "
                        f"takes at most {MAX_STATES}")
    den = sp.Poly(denominator(system), k, domain="QQ")
    if den.count_roots(0, None):
        raise SpecError(spec.source, "matrices", f"the denominator {den.as_expr()} vanishes "
                        "at some real k >= 0: the all-k bound needs one that does not")
    system.u = _rest_state(system, spec)
    return system


def _rest_state(system: AllKSystem, spec: Spec) -> Any:
    """u with A(k) u = u and C(k) u = E u = 1 for every k (one for all k), else SpecError."""
    import sympy as sp

    n, k = system.n, system.k
    lhs = sp.Matrix.vstack(sp.eye(n) - system.A.subs(k, 0), system.C.subs(k, 0), system.E)
    rhs = sp.Matrix([0] * n + [1, 1])
    try:
        sol, params = lhs.gauss_jordan_solve(rhs)
    except ValueError:
        sol, params = None, None
    if sol is None or params.shape[0]:
        raise SpecError(spec.source, "matrices", "the state at the optimum is not unique "
                        "or does not exist (A u = u, C u = E u = 1)")
    res = sp.Matrix.vstack(system.A * sol - sol, system.C * sol - sp.ones(1, 1))
    if any(sp.cancel(e) != 0 for e in res):
        raise SpecError(spec.source, "matrices", "the state at the optimum changes with k: "
                        "every step must keep x* fixed")
    return sol


def why_not_closed_form(spec: Spec) -> str | None:
    """Why the all-k family refuses ``spec`` (the one-line message), None when it takes it."""
    try:
        closed_form_system(spec)
    except SpecError as exc:
        return str(exc)
    return None


class AllKFamily:
    """The all-k potentials in the certificate registry: the family that answers a spec
    whose coefficients change with k (``sosalgo analyze``: one bound for every N)."""

    name = "all-k"
    label = "all-k potential"
    description = ("f(x_N) - f* <= C |x_0 - x*|^2 / a(N) for every N, by a potential whose "
                   "weights are polynomials in k (docs/all-k.md)")

    def applies_to(self, spec: Spec) -> str | None:
        """Why the family refuses ``spec`` (one line), None when it takes it."""
        if not changes_with_k(spec):
            return (f"{spec.source}: does not change with k (the all-k bound is for "
                    "methods whose coefficients do)")
        return why_not_closed_form(spec)


ALLK = AllKFamily()


# --------------------------------------------------------------------------- conditions
@dataclass
class Conditions:
    """The conditions (D), (B), (I) in symbols: ``variables`` (sympy symbols, the
    certificate's unknowns), ``blocks`` name -> (matrix polynomial in k, linear in the
    variables, that must be <= 0 for every k >= 0; or constant), ``identities`` (linear
    in the variables, polynomials in k that must vanish), ``nonnegative`` (variables >= 0),
    ``kernels`` (v with M_D(k) v = 0 for every certificate; the bound block's v = (u, 0),
    in its kernel when the potential has no weight on the minimizer's direction),
    ``denominator``
    (positive on k >= 0: (D) and (B) were multiplied by its square)."""

    degree: int
    variables: list[Any]
    names: dict[str, Any]
    blocks: dict[str, Any]
    identities: list[Any]
    nonnegative: list[Any]
    kernels: dict[str, Any]
    denominator: Any
    extra: dict[str, Any] = field(default_factory=dict)
    # kernels imposed only when the search's point has them (then the proof is told)
    optional_kernels: tuple[str, ...] = ("bound",)

    def all_identities(self, kernels: tuple[str, ...] = ("decrease",)) -> list[Any]:
        """The identities, with M_b(k) v_b = 0 for each block b of ``kernels``."""
        import sympy as sp

        out = list(self.identities)
        for name in kernels:
            out += [sp.expand(e) for e in self.blocks[name] * self.kernels[name]]
        return out


def _poly_var(name: str, degree: int, k: Any, out: list[Any]) -> Any:
    import sympy as sp

    coeffs = [sp.Symbol(f"{name}_{j}", real=True) for j in range(degree + 1)]
    out.extend(coeffs)
    return sum((c * k**j for j, c in enumerate(coeffs)), sp.Integer(0))


def _sym_poly_matrix(name: str, size: int, degree: int, k: Any, out: list[Any]) -> Any:
    import sympy as sp

    M = sp.zeros(size, size)
    for i, j in itertools.combinations_with_replacement(range(size), 2):
        M[i, j] = M[j, i] = _poly_var(f"{name}{i}{j}", degree, k, out)
    return M


def _interpolation(points: list[tuple[Any, Any, Any]], L: Any) -> list[tuple[str, Any]]:
    """(label ij, I_ij) for ordered pairs of points (x, g, f) (scalars: the window's
    Gram form): I_ij = f_i - f_j - g_j (x_i - x_j) - (g_i - g_j)^2/(2L) >= 0, the
    interpolation inequalities of L-smooth convex functions."""
    out = []
    for (i, (xi, gi, fi)), (j, (xj, gj, fj)) in itertools.permutations(enumerate(points), 2):
        out.append((f"{i}{j}", fi - fj - gj * (xi - xj) - (gi - gj) ** 2 / (2 * L)))
    return out


def _quadratic_and_linear(expr: Any, w: list[Any], fs: list[Any]) -> tuple[Any, list[Any]]:
    """(symmetric matrix Q, [coefficient of each f]) of expr = w'Qw + sum c_f f."""
    import sympy as sp

    expr = sp.expand(expr)
    Q = sp.zeros(len(w), len(w))
    for i, a in enumerate(w):
        for j, b in enumerate(w):
            c = expr.coeff(a, 2) if i == j else expr.coeff(a, 1).coeff(b, 1) / 2
            Q[i, j] = sp.expand(c)
    lin = [sp.expand(expr.coeff(f, 1)) for f in fs]
    return Q, lin


def output_at_query(system: AllKSystem) -> bool:
    """Whether the output is the gradient's point at every step (E = C(k) for all k):
    then (B) reads a(k) (f(x_k) - f*) <= phi_k, without the smoothness step."""
    import sympy as sp

    return all(sp.cancel(e) == 0 for e in system.E - system.C)


def bound_argument(system: AllKSystem) -> dict[str, str]:
    """How the bound reads: a's ``argument`` (N, or the sequence's theta_{N-1}; theta_N
    when the output is the gradient's point), the ``floor`` it is at least (N, or
    (N + 1)/2, (N + 2)/2 by theta_k >= 1 + k/2) and the weights' ``variable``."""
    rec = system.recurrence
    if rec is None:
        return {"argument": "N", "floor": "N", "variable": "k"}
    if output_at_query(system):
        return {"argument": f"{rec.name}_N", "floor": "(N + 2)/2", "variable": f"{rec.name}_k"}
    return {"argument": f"{rec.name}_{{N-1}}", "floor": "(N + 1)/2",
            "variable": f"{rec.name}_k"}


def denominator(system: AllKSystem) -> Any:
    """A common denominator of A(k), B(k), C(k), C(k+1) (a polynomial in k; the proof
    checks it has no root on k >= 0 and a positive value there)."""
    import sympy as sp

    k = system.k
    entries = [*system.A, *system.B, *system.C, *system.C.subs(k, k + 1)]
    den = sp.Integer(1)
    for e in entries:
        den = sp.lcm(den, sp.fraction(sp.cancel(e))[1])
    if system.recurrence is not None:  # the weights' denominators: powers of w
        den = den * system.recurrence.w
    den = sp.expand(den)
    return -den if den.subs(k, 0) < 0 else den


def _window(system: AllKSystem) -> dict[str, Any]:
    import sympy as sp

    n, k = system.n, system.k
    xs = [sp.Symbol(f"w_x{i}", real=True) for i in range(n)]
    g0, g1, f0, f1 = sp.symbols("w_g0 w_g1 w_f0 w_f1", real=True)
    xi = sp.Matrix(xs)
    xi1 = system.A * xi + system.B * g0
    return {"xs": xs, "g0": g0, "g1": g1, "f0": f0, "f1": f1, "xi": xi, "xi1": xi1,
            "q0": (system.C * xi)[0], "q1": (system.C.subs(k, k + 1) * xi1)[0],
            "o1": (system.E * xi1)[0]}


def _scaled(Q: Any, den: Any) -> Any:
    """den^2 Q as a polynomial matrix in k (entries expanded)."""
    import sympy as sp

    return Q.applyfunc(lambda e: sp.expand(sp.cancel(e * den**2)))


def conditions(system: AllKSystem, degree: int = 2) -> Conditions:
    """(D), (B), (I) of the module's docstring for potentials of ``degree`` (2: P, p,
    multipliers of degree 2 and a(k) = k^2 + a1 k + a0; 1: degree 1, a(k) = k + a0); (B)
    as a(k) (f(q_k) - f*) <= phi_k for k >= 1 when the output is the gradient's point
    (:func:`output_at_query`)."""
    import sympy as sp

    k, L, n = system.k, system.L, system.n
    var: list[Any] = []
    P = _sym_poly_matrix("P", n + 1, degree, k, var)
    p = _poly_var("p", degree, k, var)
    a_low = [sp.Symbol(f"a_{j}", real=True) for j in range(degree)]
    var += a_low
    a = k**degree + sum((c * k**j for j, c in enumerate(a_low)), sp.Integer(0))
    C0 = sp.Symbol("C", real=True)
    var.append(C0)
    nonneg = list(a_low)
    w = _window(system)
    star = (sp.Integer(0), sp.Integer(0), sp.Integer(0))

    at, nxt = system.weight_at(), system.weight_next()

    def mult(name: str) -> Any:  # with a sequence: + terms in theta_{k+1} (>= 0 too)
        before = len(var)
        poly = _poly_var(name, degree, k, var).xreplace({k: at})
        if system.recurrence is not None:
            poly += _poly_var(f"{name}n", degree, k, var).xreplace({k: nxt})
            var.remove(sp.Symbol(f"{name}n_0", real=True))
            poly = poly.xreplace({sp.Symbol(f"{name}n_0", real=True): 0})
        nonneg.extend(var[before:])
        return poly

    z0 = sp.Matrix([*w["xs"], w["g0"]])
    z1 = sp.Matrix([*w["xi1"], w["g1"]])
    phi0 = (z0.T * P.xreplace({k: at}) * z0)[0] + p.xreplace({k: at}) * w["f0"]
    phi1 = (z1.T * P.xreplace({k: nxt}) * z1)[0] + p.xreplace({k: nxt}) * w["f1"]
    pts = [(w["q0"], w["g0"], w["f0"]), (w["q1"], w["g1"], w["f1"]), star]
    dec = phi1 - phi0 + sum(mult(f"lam{ij}") * ineq for ij, ineq in _interpolation(pts, L))
    pts_b = [(w["q0"], w["g0"], w["f0"]), star]
    mus = sum(mult(f"mu{ij}") * ineq for ij, ineq in _interpolation(pts_b, L))
    if output_at_query(system) and system.recurrence is not None:
        bnd = a.xreplace({k: at}) * w["f0"] - phi0 + mus  # a(theta_k) f(q_k) <= phi_k
    elif output_at_query(system):  # a(k) (f(q_k) - f*) <= phi_k at k + 1 >= 1
        bnd = (a * w["f0"] - phi0 + mus).xreplace({k: k + 1})
    else:  # a(k + 1), or a(theta_k) with a sequence, times f(x_{k+1})'s upper bound
        gap = w["o1"] - w["q0"]
        a_at = a.subs(k, k + 1) if system.recurrence is None else a.xreplace({k: at})
        bnd = a_at * (w["f0"] + w["g0"] * gap + L / 2 * gap**2) - phi0 + mus
    den = denominator(system)
    QD, linD = _quadratic_and_linear(dec, [*w["xs"], w["g0"], w["g1"]], [w["f0"], w["f1"]])
    QB, linB = _quadratic_and_linear(bnd, [*w["xs"], w["g0"]], [w["f0"]])
    QI, linI = _initial(system, P, p, C0, var, nonneg)
    kernels = {"decrease": sp.Matrix([*system.u, 0, 0]), "bound": sp.Matrix([*system.u, 0])}
    blocks = {"decrease": _scaled(QD, den), "bound": _scaled(QB, den), "initial": QI}
    identities = [*linD, *linB, *linI]
    if system.recurrence is not None:  # polynomials in k once multiplied by w^2
        identities = [sp.cancel(e * system.recurrence.w**2) for e in identities]
    return Conditions(degree, var, {str(s): s for s in var}, blocks,
                      [sp.expand(e) for e in identities], nonneg, kernels, den,
                      {"a": a, "P": P, "p": p, "k": k, "scale": system.scale})


def _initial(system: AllKSystem, P: Any, p: Any, C0: Any, var: list[Any],
             nonneg: list[Any]) -> tuple[Any, list[Any]]:
    """(I): phi_0 at xi_0 = u x_0 minus C x_0^2, with the interpolation of (x_0, g_0, f_0)
    and the optimum (multipliers nu >= 0)."""
    import sympy as sp

    k = system.k
    x0, g0, f0 = sp.symbols("w_x0s w_g0s w_f0s", real=True)
    nus = [sp.Symbol(f"nu_{j}", real=True) for j in range(2)]
    var += nus
    nonneg += nus
    z = sp.Matrix([*(system.u * x0), g0])
    first = system.weight_first()
    phi = (z.T * P.subs(k, first) * z)[0] + p.subs(k, first) * f0
    zero = sp.Integer(0)
    ineqs = _interpolation([(x0, g0, f0), (zero, zero, zero)], system.L)
    expr = phi - C0 * x0**2 + sum(nu * ineq for nu, (_, ineq) in zip(nus, ineqs, strict=True))
    return _quadratic_and_linear(expr, [x0, g0], [f0])


# --------------------------------------------------------------------------- the search
def _linear_rows(expr: Any, k: Any, index: dict[Any, int]) -> dict[int, tuple[np.ndarray, float]]:
    """power of k -> (coefficients over the variables, constant) of a polynomial in k
    that is affine in the variables."""
    import sympy as sp

    out: dict[int, tuple[np.ndarray, float]] = {}
    if expr == 0:
        return out
    gens = [k, *index]
    for monom, coeff in sp.Poly(expr, *gens).terms():
        t, rest = monom[0], monom[1:]
        vec, const = out.get(t, (np.zeros(len(index)), 0.0))
        hit = [i for i, e in enumerate(rest) if e]
        if hit:
            vec[hit[0]] += float(coeff)
        else:
            const += float(coeff)
        out[t] = (vec, const)
    return out


def _block_arrays(M: Any, k: Any, index: dict[Any, int]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per power t of k: (F_t with shape (s*s, nv), f_t with shape (s*s,)), M_t = F_t y + f_t
    (row-major vec)."""
    s = M.shape[0]
    per: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for i in range(s):
        for j in range(s):
            for t, (vec, const) in _linear_rows(M[i, j], k, index).items():
                F, f = per.setdefault(t, (np.zeros((s * s, len(index))), np.zeros(s * s)))
                F[i * s + j] += vec
                f[i * s + j] += const
    top = max(per, default=0)
    nv = len(index)
    return [per.get(t, (np.zeros((s * s, nv)), np.zeros(s * s))) for t in range(top + 1)]


def _sos_constraints(arrays: list[tuple[np.ndarray, np.ndarray]], s: int, y: Any, margin: Any,
                     weight: list[np.ndarray] | None) -> list[Any]:
    """-M(k) - margin W(k) = Z' G0 Z + k Z' G1 Z with G0, G1 >= 0 (W(k) = sum_t k^t W_t,
    ``weight``: the margin's shape, PSD for k >= 0; None: no margin)."""
    import cvxpy as cp

    D = max(len(arrays), len(weight or ())) - 1
    zero = (np.zeros_like(arrays[0][0]), np.zeros_like(arrays[0][1]))
    Ms = [cp.reshape(F @ y + f, (s, s), order="C")
          for F, f in arrays + [zero] * (D + 1 - len(arrays))]
    if weight is not None:
        Ms = [Ms[t] + margin * (weight[t] if t < len(weight) else 0) for t in range(D + 1)]
    if D == 0:
        return [-(Ms[0] + Ms[0].T) / 2 >> 0]
    cons = []
    grams = []
    for shift, d in ((0, D // 2), (1, (D - 1) // 2)):
        if d < 0:
            continue
        G = cp.Variable(((d + 1) * s, (d + 1) * s), PSD=True)
        grams.append((shift, d, G))
    for t in range(D + 1):
        rhs = 0
        for shift, d, G in grams:
            for i in range(d + 1):
                j = t - shift - i
                if 0 <= j <= d:
                    rhs = rhs + G[i * s:(i + 1) * s, j * s:(j + 1) * s]
        cons.append(-(Ms[t] + Ms[t].T) / 2 == rhs)
    return cons


# --------------------------------------------------------------------------- growth in k
@dataclass
class Growth:
    """How a block grows with k at the search's point: a basis T(k) (polynomial columns,
    det constant: v first, then directions along which the leading terms cancel, found
    and snapped to small fractions), the degree of each diagonal entry of T' M T (-1: an
    entry at 0), ``zeros`` (coefficients the point must have at exactly 0 to keep that
    growth) and ``weight`` (W(k) = T^-T diag((1 + k)^d_i) T^-1: the margin's shape)."""

    T: Any
    degrees: list[int]
    zeros: list[Any]
    weight: Any


def _numeric_polys(M: Any, k: Any, sub: dict[Any, float]) -> list[list[list[float]]]:
    import sympy as sp

    s = M.shape[0]
    return [[[float(c.xreplace(sub)) for c in reversed(sp.Poly(M[i, j], k).all_coeffs())]
             for j in range(s)] for i in range(s)]


def _degrees(num: list[list[list[float]]]) -> list[int]:
    """The degree of each diagonal entry of M (<= 0): its last clearly negative
    coefficient (a positive one above it is the solver's noise: M <= 0 forbids it)."""
    scale = max(1e-300, max(abs(c) for row in num for cs in row for c in cs))
    return [max([t for t, c in enumerate(num[i][i]) if c < -DEGREE_TOL * scale], default=-1)
            for i in range(len(num))]


def _cancelling_direction(num: list[list[list[float]]], deg: list[int]
                          ) -> tuple[int, int, Fraction, int] | None:
    """Two directions i, j (d_i <= d_j, same parity) whose leading terms in -M (PSD) form
    a singular 2 x 2 block: (i, j, q, e) with e_j + q k^e e_i the direction along which
    they cancel (q snapped to a small fraction); None when there is none."""
    act = [i for i in range(len(deg)) if deg[i] >= 0]
    for i, j in itertools.permutations(act, 2):
        if deg[i] > deg[j] or (deg[i] == deg[j] and i > j) or (deg[i] + deg[j]) % 2:
            continue
        mid = (deg[i] + deg[j]) // 2
        a, c = -num[i][i][deg[i]], -num[j][j][deg[j]]
        b = -num[i][j][mid] if mid < len(num[i][j]) else 0.0
        if a <= 0 or c <= 0 or abs(b) < 1e-9 * np.sqrt(a * c):
            continue
        if abs(a * c - b * b) > CANCEL_TOL * a * c:
            continue
        q = Fraction(-b / a).limit_denominator(64)
        if abs(float(q) + b / a) <= CANCEL_TOL * abs(b / a):
            return i, j, q, (deg[j] - deg[i]) // 2
    return None


def block_growth(cond: Conditions, name: str, y: np.ndarray) -> Growth:
    """The :class:`Growth` of block ``name`` at the point ``y``."""
    import sympy as sp

    k, M = cond.extra["k"], cond.blocks[name]
    s = M.shape[0]
    sub = dict(zip(cond.variables, (float(x) for x in y), strict=True))
    T = sp.eye(s)
    if name in cond.kernels:
        T[:, 0] = cond.kernels[name]
    for _ in range(s):
        num = _numeric_polys((T.T * M * T).applyfunc(sp.expand), k, sub)
        deg = _degrees(num)
        found = _cancelling_direction(num, deg)
        if found is None:
            break
        i, j, q, e = found
        T[:, j] = T[:, j] + q * k**e * T[:, i]
    Mt = (T.T * M * T).applyfunc(sp.expand)
    deg = _degrees(_numeric_polys(Mt, k, sub))
    zeros = []
    for i, j in itertools.combinations_with_replacement(range(s), 2):
        limit = deg[i] if i == j else (deg[i] + deg[j]) // 2
        coeffs = list(reversed(sp.Poly(Mt[i, j], k).all_coeffs()))
        zeros += [c for c in coeffs[max(limit + 1, 0):] if c != 0]
    Tinv = T.inv().applyfunc(sp.expand)
    D = sp.diag(*[(1 + k) ** max(d, 0) if d >= 0 else 0 for d in deg])
    return Growth(T, deg, zeros, (Tinv.T * D * Tinv).applyfunc(sp.expand))


def _weight_arrays(W: Any, k: Any) -> list[np.ndarray]:
    import sympy as sp

    s = W.shape[0]
    polys = [[list(reversed(sp.Poly(W[i, j], k).all_coeffs())) for j in range(s)]
             for i in range(s)]
    top = max(len(p) for row in polys for p in row)
    return [np.array([[float(polys[i][j][t]) if t < len(polys[i][j]) else 0.0
                       for j in range(s)] for i in range(s)]) for t in range(top)]


@dataclass
class Search:
    """The SDP's point (floats over ``conditions.variables``), its status and constant,
    the blocks whose kernel it imposed and the coefficients it set to 0 (the proof's
    rounding imposes them too)."""

    values: np.ndarray | None
    constant: float | None
    status: str
    solves: int = 0
    kernels: tuple[str, ...] = ("decrease",)
    zeros: list[Any] = field(default_factory=list)
    context: dict[str, Any] = field(default_factory=dict)


def _problem_data(cond: Conditions) -> dict[str, Any]:
    index = {v: i for i, v in enumerate(cond.variables)}
    k = cond.extra["k"]
    blocks = {name: (M.shape[0], _block_arrays(M, k, index)) for name, M in cond.blocks.items()}
    return {"index": index, "blocks": blocks}


def _equalities(cond: Conditions, index: dict[Any, int], kernels: tuple[str, ...],
                zeros: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    k = cond.extra["k"]
    rows, rhs = [], []
    for e in [*cond.all_identities(kernels), *zeros]:
        for vec, const in _linear_rows(e, k, index).values():
            rows.append(vec)
            rhs.append(-const)
    return np.array(rows), np.array(rhs)


def _solve(data: dict[str, Any], cond: Conditions, cap: float | None, offset: Fraction,
           growth: dict[str, Growth] | None = None, kernels: tuple[str, ...] = ("decrease",),
           pinned: Fraction | None = None) -> tuple[str, Any, Any]:
    import cvxpy as cp

    index = data["index"]
    y = cp.Variable(len(index))
    margin = cp.Variable() if cap is not None else 0.0
    zeros = [z for g in (growth or {}).values() for z in g.zeros]
    Aeq, beq = _equalities(cond, index, kernels, zeros)
    cons = [Aeq @ y == beq]
    cons += [y[index[cond.names[name]]] >= float(low)
             for name, low in offset_bounds(cond.degree, offset).items()]
    cons += [y[index[v]] >= 0 for v in cond.nonnegative]
    for name, (s, arrays) in data["blocks"].items():
        weight = (None if growth is None
                  else _weight_arrays(growth[name].weight, cond.extra["k"]))
        cons += _sos_constraints(arrays, s, y, margin, weight)
    C = y[index[cond.names["C"]]]
    if pinned is not None:  # C fixed, the multipliers as small as they go (sparse)
        cons.append(C == float(pinned))
        mults = [index[v] for v in cond.nonnegative if not str(v).startswith("a_")]
        prob = cp.Problem(cp.Minimize(cp.sum(y[mults])), cons)
    elif cap is None:
        prob = cp.Problem(cp.Minimize(C), cons)
    else:
        cons += [C <= cap, margin <= 1]
        prob = cp.Problem(cp.Maximize(margin), cons)
    try:
        with warnings.catch_warnings():  # "inaccurate": the proof decides
            warnings.simplefilter("ignore", UserWarning)
            prob.solve(solver="CLARABEL", tol_gap_abs=1e-11, tol_gap_rel=1e-11,
                       tol_feas=1e-11, max_iter=400)
    except cp.error.SolverError as exc:
        return f"the solver failed ({type(exc).__name__})", None, None
    return prob.status, y.value, (margin.value if cap is not None else None)


def offset_bounds(degree: int, offset: Fraction) -> dict[str, Fraction]:
    """The lower bounds on a(k)'s coefficients under which a(N) >= (N + offset)^degree."""
    if degree == 2:
        return {"a_1": 2 * offset, "a_0": offset**2}
    return {"a_0": offset}


def search(cond: Conditions, offset: Fraction = Fraction(1)) -> Search:
    """Minimize C over the conditions with a(N) >= (N + offset)^degree (one SDP) and read
    the growth in k of each block at the optimum (:func:`block_growth`). Floating point:
    certifies nothing by itself (its constant is where :func:`margin_point` starts)."""
    data = _problem_data(cond)
    status, y, _ = _solve(data, cond, None, offset)
    if status not in ("optimal", "optimal_inaccurate") or y is None:
        return Search(None, None, status, 1)
    y = np.asarray(y)
    kernels = ("decrease", *_kernels_at(cond, y))
    growth = {name: block_growth(cond, name, y) for name in cond.blocks}
    return Search(y, float(y[data["index"][cond.names["C"]]]), status, 1, kernels,
                  [z for g in growth.values() for z in g.zeros],
                  {"data": data, "growth": growth, "offset": offset})


def margin_point(cond: Conditions, found: Search, slack: float) -> np.ndarray | None:
    """At C <= C* (1 + slack), the point with the largest margin on every block (in the
    shape of its growth): the point the proof rounds; None when no positive margin."""
    if found.values is None or found.constant is None:
        return None
    ctx = found.context
    status, y, margin = _solve(ctx["data"], cond, found.constant * (1 + slack) + 1e-12,
                               ctx["offset"], ctx["growth"], found.kernels)
    found.solves += 1
    if status in ("optimal", "optimal_inaccurate") and y is not None and margin > 0:
        return np.asarray(y)
    return None


def pinned_point(cond: Conditions, found: Search, rel: float = 1e-2, den: int = 16
                 ) -> tuple[Fraction, np.ndarray] | None:
    """For a potential that is tight (no margin: OGM's decrease is an identity): C* snapped
    to a fraction of denominator <= ``den`` (None unless within ``rel`` of it), and the
    point at that C with the multipliers as small as they go (a sparse face, whose
    values the rounding snaps to small fractions)."""
    if found.values is None or found.constant is None:
        return None
    pinned = Fraction(found.constant).limit_denominator(den)
    if abs(float(pinned) - found.constant) > rel * abs(found.constant):
        return None
    ctx = found.context
    status, y, _ = _solve(ctx["data"], cond, None, ctx["offset"], None, found.kernels,
                          pinned=pinned)
    found.solves += 1
    if status in ("optimal", "optimal_inaccurate") and y is not None:
        return pinned, np.asarray(y)
    return None


def _kernels_at(cond: Conditions, y: np.ndarray) -> list[str]:
    """The optional kernels (the bound block's v) the search's point has: v' M v ~ 0."""
    out = []
    sub = dict(zip(cond.variables, (float(x) for x in y), strict=True))
    for name in cond.optional_kernels:
        v = cond.kernels[name]
        M = cond.blocks[name]
        val = float(((v.T * M * v)[0]).subs(sub).subs(cond.extra["k"], 1))
        scale = max(1.0, float(np.max(np.abs(y))))
        if abs(val) <= 1e-6 * scale:
            out.append(name)
    return out
