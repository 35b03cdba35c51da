"""The N-step PEP of a method with free parameters θ, in a basis that does not depend on θ.

Basis: x_0 - x*, then the oracle answers g_0, ..., g_{N-1} at the queries y_k and g_N at
the output x_N (x* = 0, g* = 0, f* = 0). The queries and the output are polynomials in θ
times this basis (``xi_{k+1} = A xi_k + B g_k`` from ``xi_0 = u x_0``), so every
interpolation inequality of an L-smooth, m-strongly convex f is

    F_i - F_j + sum_alpha theta^alpha <Q_alpha, G> >= 0

with exact rational matrices Q_alpha (:class:`ParametricPEP`). The measure is
f(x_N) - f* = F_N, the initial condition |x_0 - x*|^2 = G_00. Everything here is exact
(fractions); :mod:`sosalgo.design_search.steps_bound` solves and proves boxes of θ with it.

Supported: one ``smooth_strongly_convex`` function queried by its gradient, no D, x = E xi,
the start at rest (no ``initial_state``), xi* = 1 x* (every row of A sums to 1 and
C 1 = E 1 = 1), the measure f(x_N) - f* from |x_0 - x*|^2, and polynomial matrices with
rational coefficients. :func:`parametric_pep` raises :class:`Unsupported` otherwise (the
design then reports no box-wide lower bound, with the reason).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
import sympy as sp

from sosalgo.classes import SEED_CLASS, get_class
from sosalgo.spec import Spec

__all__ = ["ParametricPEP", "PointSearch", "Poly", "Unsupported", "check_setting",
           "exact_forms", "largest_values", "parametric_pep", "poly_matvec",
           "poly_range",
           "smooth_convex_q", "step_symbol", "varying_matrices"]

Poly = dict[tuple[int, ...], Fraction]  # monomial exponents -> coefficient


class Unsupported(ValueError):
    """The spec is outside what the parametric PEP covers (the message says why)."""


def _padd(a: Poly, b: Poly, s: Fraction = Fraction(1)) -> Poly:
    out = dict(a)
    for e, c in b.items():
        v = out.get(e, Fraction(0)) + s * c
        if v:
            out[e] = v
        else:
            out.pop(e, None)
    return out


def _pmul(a: Poly, b: Poly) -> Poly:
    out: Poly = {}
    for ea, ca in a.items():
        for eb, cb in b.items():
            e = tuple(x + y for x, y in zip(ea, eb, strict=True))
            out[e] = out.get(e, Fraction(0)) + ca * cb
    return {e: c for e, c in out.items() if c}


def _to_poly(expr: sp.Expr, syms: Sequence[sp.Symbol], where: str) -> Poly:
    expr = sp.sympify(expr)
    try:
        p = sp.Poly(sp.expand(expr), *syms, domain="QQ") if syms else None
    except (sp.PolynomialError, sp.CoercionFailed, sp.GeneratorsNeeded):
        p = None
    if p is None:
        if syms or not expr.is_Rational:
            raise Unsupported(f"{where} = {expr} is not a polynomial with rational "
                              "coefficients in the free parameters")
        return {(): Fraction(int(expr.p), int(expr.q))} if expr != 0 else {}
    return {tuple(int(x) for x in e): Fraction(int(c.p), int(c.q))
            for e, c in p.terms() if c != 0}


def smooth_convex_q(m: Fraction, L: Fraction) -> list[list[Fraction]]:
    """The 4x4 form on (x_i, x_j, g_i, g_j) of f_i - f_j + <that> >= 0 for F(m, L):
    f_i >= f_j + <g_j, x_i - x_j> + (|g_i - g_j|^2 / L + m |x_i - x_j|^2
    - 2 (m/L) <g_j - g_i, x_j - x_i>) / (2 (1 - m/L))."""
    c = 1 / (2 * (1 - m / L))
    k = 2 * c * m / L
    Q = [[Fraction(0)] * 4 for _ in range(4)]
    terms = (  # (a, b, v): v <r_a, r_b>, rows r = (x_i, x_j, g_i, g_j)
        (3, 0, Fraction(-1)), (3, 1, Fraction(1)),  # -<g_j, x_i - x_j>
        (2, 2, -c / L), (3, 3, -c / L), (2, 3, 2 * c / L),  # -c/L |g_i - g_j|^2
        (0, 0, -c * m), (1, 1, -c * m), (0, 1, 2 * c * m),  # -c m |x_i - x_j|^2
        (3, 1, k), (3, 0, -k), (2, 1, -k), (2, 0, k))  # +k <g_j - g_i, x_j - x_i>
    for a, b, v in terms:
        Q[a][b] += v / 2
        Q[b][a] += v / 2
    return Q


@dataclass
class ParametricPEP:
    """The exact data (see the module): ``rows[i]`` the coordinates of point i on the
    basis (polynomial per basis vector; point ``npts`` is x* = 0), ``grad[i]`` the basis
    index of g_i; ``pairs`` (i, j) ordered pairs of distinct points (the star included);
    ``forms[k]``: monomial -> d x d rational matrix (object array) of pair k's G-part."""

    free: list[str]
    steps: int
    m: Fraction
    L: Fraction
    d: int
    npts: int
    pairs: list[tuple[int, int]]
    forms: list[dict[tuple[int, ...], np.ndarray]]
    monomials: list[tuple[int, ...]]

    @property
    def measure_point(self) -> int:
        return self.npts - 1  # x_N

    def float_forms(self, shrink: Fraction = Fraction(0)) -> np.ndarray:
        """(K, A, d, d) floats: pair k's matrix of monomial a (``monomials`` order) for the
        class F(m + s (L - m), L (1 - s)), s = ``shrink`` (a subclass of F(m, L) whose
        inequalities have slack wherever two points or two gradients differ)."""
        if not shrink:
            src = self.forms
        else:
            m2 = self.m + shrink * (self.L - self.m)
            src = _pair_forms(self._rows, self.d, self.npts, self.pairs,
                              smooth_convex_q(m2, self.L * (1 - shrink)))
        out = np.zeros((len(self.pairs), len(self.monomials), self.d, self.d))
        idx = {e: a for a, e in enumerate(self.monomials)}
        for k, form in enumerate(src):
            for e, M in form.items():
                out[k, idx[e]] = np.asarray(M, dtype=float)
        return out

    def value_differences(self) -> np.ndarray:
        """(K, npts): row k picks F_i - F_j of pair k = (i, j) (x* has value 0, no column)."""
        diff = np.zeros((len(self.pairs), self.npts))
        for k, (i, j) in enumerate(self.pairs):
            if i < self.npts:
                diff[k, i] += 1.0
            if j < self.npts:
                diff[k, j] -= 1.0
        return diff

    _rows: list[list[list[Poly]]] | None = None
    step_polys: list[dict[str, list[list[Poly]]]] | None = None  # A, B, C, E of step k


def _basis_row(d: int, j: int, zero: tuple[int, ...]) -> list[Poly]:
    return [{zero: Fraction(1)} if i == j else {} for i in range(d)]


def _matvec(M: list[list[Poly]], rows: list[list[Poly]], d: int) -> list[list[Poly]]:
    """M (r x n polys) times a stack of n coordinate rows (each d polys)."""
    out = []
    for Mi in M:
        acc: list[Poly] = [{} for _ in range(d)]
        for Mij, row in zip(Mi, rows, strict=True):
            if not Mij:
                continue
            for c in range(d):
                if row[c]:
                    acc[c] = _padd(acc[c], _pmul(Mij, row[c]))
        out.append(acc)
    return out


def poly_matvec(M: list[list[Poly]], v: list[Poly]) -> list[Poly]:
    """M (polynomial entries) times the vector v of polynomials, exactly."""
    out = []
    for row in M:
        acc: Poly = {}
        for a, b in zip(row, v, strict=True):
            if a and b:
                acc = _padd(acc, _pmul(a, b))
        out.append(acc)
    return out


def trajectory_rows(step_mats: Callable[[int], dict[str, list[list[Poly]]]], n: int,
                    steps: int, nvar: int) -> list[list[list[Poly]]]:
    """Point i's (x_i, g_i) coordinate rows: [x-row, g-row] per point, queries
    y_0..y_{N-1}, then x_N, then x* (all zero)."""
    d = steps + 2
    zero = (0,) * nvar
    xi = [_basis_row(d, 0, zero) for _ in range(n)]  # xi_0 = 1 x_0
    pts = []
    for k in range(steps):
        mats = step_mats(k)
        y = _matvec(mats["C"], xi, d)[0]
        g = _basis_row(d, 1 + k, zero)
        pts.append([y, g])
        Ax = _matvec(mats["A"], xi, d)
        Bg = _matvec(mats["B"], [g], d)
        xi = [[_padd(a, b) for a, b in zip(ra, rb, strict=True)]
              for ra, rb in zip(Ax, Bg, strict=True)]
    xN = _matvec(step_mats(steps - 1)["E"], xi, d)[0]
    pts.append([xN, _basis_row(d, steps + 1, zero)])
    pts.append([[{} for _ in range(d)], [{} for _ in range(d)]])  # x*, g* = 0
    return pts


def _pair_forms(pts: list[list[list[Poly]]], d: int, npts: int,
                pairs: list[tuple[int, int]], Q: list[list[Fraction]]
                ) -> list[dict[tuple[int, ...], np.ndarray]]:
    forms = []
    for i, j in pairs:
        rows = [pts[i][0], pts[j][0], pts[i][1], pts[j][1]]
        form: dict[tuple[int, ...], np.ndarray] = {}
        for a in range(4):
            for b in range(4):
                if not Q[a][b]:
                    continue
                for ca, pa in enumerate(rows[a]):
                    for cb, pb in enumerate(rows[b]):
                        if not pa or not pb:
                            continue
                        for e, v in _pmul(pa, pb).items():
                            M = form.get(e)
                            if M is None:
                                M = form[e] = np.full((d, d), Fraction(0), dtype=object)
                            M[ca, cb] += Q[a][b] * v
        for e in list(form):
            M = form[e]
            form[e] = (M + M.T) / 2
            if not any(form[e].ravel()):
                del form[e]
        forms.append(form)
    return forms


def exact_class(spec: Spec, kappa: float | None) -> tuple[Fraction, Fraction]:
    """(m, L) as exact rationals: m: 0 specs their L as written, others m and kappa m."""
    from sosalgo.kernel.expr.parse import to_sympy

    if not spec.has_condition_number:
        Le = sp.nsimplify(to_sympy(spec.L_expr)) if spec.L_expr is not None else None
        L = (Fraction(int(Le.p), int(Le.q)) if Le is not None and Le.is_Rational
             else Fraction(float(spec.L)))  # type: ignore[arg-type]
        return Fraction(0), L
    from sosalgo.kernel.kappa import exact_kappa

    kq = exact_kappa(kappa)  # type: ignore[arg-type]
    if not kq.is_Rational:
        raise Unsupported(f"kappa {kq} is irrational")
    mq = Fraction(float(spec.m))
    return mq, mq * Fraction(int(kq.p), int(kq.q))


def check_setting(spec: Spec) -> None:
    """Unsupported unless the spec is in the setting of the module."""
    fns = list(spec.functions.values())
    if (len(fns) > 1 or (fns and get_class(fns[0].cls) is not SEED_CLASS)
            or spec.oracles != ("f",) or spec.output is not None
            or "D" in spec.matrices or spec.initial_state is not None
            or spec.measure != "function" or (fns and fns[0].given - {"m", "L"})):
        raise Unsupported("the box-wide bound covers one smooth strongly convex f queried "
                          "by its gradient (no D, no output, no initial_state, the "
                          "measure f(x_N) - f*)")


def parametric_pep(spec: Spec, kappa: float | None, steps: int, free: Sequence[str],
                   step_matrices: Callable[[int], dict[str, sp.Matrix]] | None = None
                   ) -> ParametricPEP:
    """The exact parametric PEP (see the module). ``step_matrices(k)``: the sympy
    matrices of step k in the free symbols (default: the spec's, the same every step)."""
    check_setting(spec)
    m, L = exact_class(spec, kappa)
    syms = [spec.symbols[p] for p in free] if step_matrices is None else \
        [sp.Symbol(p) for p in free]
    mats_of = step_matrices or _constant_matrices(spec, free, m, L)
    cache: dict[int, dict[str, list[list[Poly]]]] = {}

    def polys(k: int) -> dict[str, list[list[Poly]]]:
        if k not in cache:
            cache[k] = {name: [[_to_poly(M[i, j], syms, f"matrices.{name}[{i}][{j}]")
                                for j in range(M.shape[1])] for i in range(M.shape[0])]
                        for name, M in mats_of(k).items()}
            _check_rest(cache[k], len(free))
        return cache[k]

    n = len(polys(0)["A"])
    pts = trajectory_rows(polys, n, steps, len(free))
    npts = len(pts) - 1  # the last is x*
    d = steps + 2
    pairs = [(i, j) for i in range(npts + 1) for j in range(npts + 1) if i != j]
    forms = _pair_forms(pts, d, npts, pairs, smooth_convex_q(m, L))
    # every monomial of the class and of its shrunk subclasses (m + s (L - m) > 0: the
    # squared distances of points, degree twice the points')
    wide = _pair_forms(pts, d, npts, pairs, smooth_convex_q((m + L) / 2, L))
    monos = sorted({e for f in forms + wide for e in f} | {(0,) * len(free)})
    pp = ParametricPEP(list(free), steps, m, L, d, npts, pairs, forms, monos)
    pp._rows = pts
    pp.step_polys = [polys(k) for k in range(steps)]
    return pp


def _constant_matrices(spec: Spec, free: Sequence[str], m: Fraction, L: Fraction
                       ) -> Callable[[int], dict[str, sp.Matrix]]:
    """The spec's A, B, C, E with the free parameters as symbols, the others at their
    exact values (m, L, kappa exact)."""
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.spec.types import BASE_SYMBOLS, value_order

    values: dict[sp.Symbol, Any] = {
        BASE_SYMBOLS["m"]: sp.Rational(m.numerator, m.denominator),
        BASE_SYMBOLS["L"]: sp.Rational(L.numerator, L.denominator)}
    if m:
        kq = L / m
        values[BASE_SYMBOLS["kappa"]] = sp.Rational(kq.numerator, kq.denominator)
    sym = spec.symbols
    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        values[sym[p]] = sym[p] if p in free else \
            to_sympy(par.tied if par.is_tied else par.value).xreplace(values)
    mats = {k: spec.sympy_matrices()[k].xreplace(values) for k in ("A", "B", "C", "E")}
    return lambda k: mats


def _check_rest(mats: dict[str, list[list[Poly]]], nvar: int) -> None:
    """xi* = 1 x*: the rows of A sum to 1, C 1 = E 1 = 1 (identically in θ)."""
    one = {(0,) * nvar: Fraction(1)}
    for name in ("A", "C", "E"):
        for row in mats[name]:
            s: Poly = {}
            for p in row:
                s = _padd(s, p)
            if s != one:
                raise Unsupported(f"matrices.{name}: the state at the optimum is not "
                                  "1 x* for every θ (a row does not sum to 1)")


def exact_forms(pp: ParametricPEP) -> Any:
    """All pair forms as one fmpq matrix: row k * A + a is vec of pair k's monomial a."""
    from flint import fmpq, fmpq_mat

    if getattr(pp, "_exact", None) is None:
        K, A, d = len(pp.pairs), len(pp.monomials), pp.d
        idx = {e: a for a, e in enumerate(pp.monomials)}
        entries = [fmpq(0)] * (K * A * d * d)
        for k, form in enumerate(pp.forms):
            for e, M in form.items():
                base = (k * A + idx[e]) * d * d
                for r in range(d):
                    for c in range(d):
                        if M[r, c]:
                            entries[base + r * d + c] = fmpq(M[r, c].numerator,
                                                             M[r, c].denominator)
        pp._exact = fmpq_mat(K * A, d * d, entries)  # type: ignore[attr-defined]
    return pp._exact  # type: ignore[attr-defined]


def largest_values(pp: ParametricPEP, weights: list[Fraction]) -> Fraction | None:
    """max F_N with F_* = 0 and F_j <= F_i + w_ij for every pair: the shortest distance
    from x* to x_N (Bellman-Ford); None when a cycle is negative (no feasible F)."""
    n = pp.npts + 1
    star = pp.npts
    dist: list[Fraction | None] = [None] * n
    dist[star] = Fraction(0)
    for _ in range(n):
        changed = False
        for (i, j), w in zip(pp.pairs, weights, strict=True):
            di = dist[i]
            if di is not None and (dist[j] is None or di + w < dist[j]):
                dist[j] = di + w
                changed = True
        if not changed:
            break
    else:
        return None
    if dist[star] != 0:
        return None
    return dist[pp.measure_point]


def poly_range(e: tuple[int, ...], lo: Sequence[Fraction], hi: Sequence[Fraction]
               ) -> tuple[Fraction, Fraction]:
    """The exact range of theta^e over the box [lo, hi]."""
    a, b = Fraction(1), Fraction(1)
    for k, lk, hk in zip(e, lo, hi, strict=True):
        if k == 0:
            continue
        vals = [lk ** k, hk ** k]
        plo = Fraction(0) if (k % 2 == 0 and lk <= 0 <= hk) else min(vals)
        phi = max(vals)
        cands = [a * plo, a * phi, b * plo, b * phi]
        a, b = min(cands), max(cands)
    return a, b


def step_symbol(p: str, k: int | None) -> str:
    """The name of a free value: ``p`` (one value), ``p_k`` (the value at step k)."""
    return p if k is None else f"{p}_{k}"


def varying_matrices(spec: Spec, kappa: float | None, steps: int,
                     per_step: Sequence[tuple[str, bool]]
                     ) -> tuple[Callable[[int], dict[str, sp.Matrix]], list[list[float]]]:
    """(step k -> the spec's A, B, C, E at step k with the free values as symbols
    (``step_symbol``), the free values' own per-step values as seeds): m, L, kappa, k, N
    exact, fixed parameters (values, ties, listed schedules) substituted. Entries that
    still use a sequence are left to :func:`parametric_pep` to refuse (not polynomial
    with rational coefficients)."""
    from sosalgo.kernel.expr.parse import sympy_symbol, to_sympy
    from sosalgo.spec.types import value_order

    m, L = exact_class(spec, kappa)
    base: dict[str, Any] = {"m": sp.Rational(m.numerator, m.denominator),
                            "L": sp.Rational(L.numerator, L.denominator),
                            "N": sp.Integer(steps)}
    if m:
        kq = L / m
        base["kappa"] = sp.Rational(kq.numerator, kq.denominator)
    free = dict(per_step)
    envs, seeds = [], []
    for k in range(steps):
        env = dict(base, k=sp.Integer(k))
        own: dict[str, float] = {}
        for p in value_order(spec.parameters, spec.source):
            par = spec.parameters[p]
            sub = {sympy_symbol(n): v for n, v in env.items()}
            sched = getattr(par, "schedule", None)
            if sched is not None and k >= len(sched):  # a free list of another length
                sched = sched[-1:] * (k + 1) if p in free else None
                if sched is None:
                    raise Unsupported(f"parameters.{p}: a schedule of "
                                      f"{len(par.schedule)} values for N = {steps} steps")
            expr = (to_sympy(sched[k]) if sched is not None else
                    to_sympy(par.tied if par.is_tied else par.value)).xreplace(sub)
            if p in free:
                own[p] = _seed(expr)
                env[p] = sp.Symbol(step_symbol(p, k if free[p] else None))
            else:
                env[p] = expr
        envs.append({sympy_symbol(n): v for n, v in env.items()})
        seeds.append([own[p] for p, _ in per_step])
    mats = spec.sympy_matrices()

    def at(k: int) -> dict[str, sp.Matrix]:
        return {key: mats[key].xreplace(envs[k]) for key in ("A", "B", "C", "E")}

    return at, seeds


class PointSearch:
    """The float PEP of ``pp`` at one θ (cvxpy, Clarabel): its value and its gradient in θ,
    which steer the schedule search (:mod:`sosalgo.design_search.steps`). It proves nothing: the
    worst case of a schedule and its proof are ``sosalgo pep``'s
    (:func:`sosalgo.worstcase.evaluate.worst_case_evaluator`).

    Primal: max F_N subject to G_00 <= 1, G ⪰ 0 and, for every pair k = (i, j),
    F_i - F_j + <P_k(θ), G> >= 0 with P_k(θ) = sum_alpha θ^alpha Q_{k,alpha}. The gradient
    of the value in θ is sum_k lambda_k <dP_k/dθ, G> at the optimum, lambda the pairs'
    multipliers (the envelope theorem; a subgradient where the optimum is not unique)."""

    def __init__(self, pp: ParametricPEP):
        import cvxpy as cp

        self.pp = pp
        K, A, d = len(pp.pairs), len(pp.monomials), pp.d
        self.forms = pp.float_forms().reshape(K, A, d * d)
        self.G = cp.Variable((d, d), PSD=True)
        self.F = cp.Variable(pp.npts)
        self.P = cp.Parameter((K, d * d))
        self.pairs_con = (pp.value_differences() @ self.F
                          + self.P @ cp.vec(self.G, order="C") >= 0)
        self.problem = cp.Problem(cp.Maximize(self.F[pp.measure_point]),
                                  [self.pairs_con, self.G[0, 0] <= 1])
        self.exps = np.array(pp.monomials, dtype=float)  # (A, p)

    def _monomials(self, theta: np.ndarray) -> np.ndarray:
        return np.prod(np.power(theta[None, :], self.exps), axis=1)

    def _dmonomials(self, theta: np.ndarray) -> np.ndarray:
        """(A, p): the derivative of each monomial in each θ_i."""
        out = np.zeros_like(self.exps)
        for i in range(self.exps.shape[1]):
            e = self.exps.copy()
            c = e[:, i].copy()
            e[:, i] = np.maximum(e[:, i] - 1, 0)
            out[:, i] = c * np.prod(np.power(theta[None, :], e), axis=1)
        return out

    def value_grad(self, theta: Sequence[float]) -> tuple[float, np.ndarray]:
        """The PEP value at θ and its gradient (inf and zeros when the solve fails)."""
        from sosalgo.kernel.solvers import SolverStatus, cvxpy_solve

        th = np.asarray(theta, float)
        self.P.value = np.einsum("a,kaj->kj", self._monomials(th), self.forms)
        end = cvxpy_solve(self.problem, "CLARABEL")
        if end.status not in (SolverStatus.SOLVED, SolverStatus.ALMOST_SOLVED) \
                or self.G.value is None:
            return float("inf"), np.zeros(len(th))
        lam = np.maximum(np.asarray(self.pairs_con.dual_value, float), 0.0)
        inner = np.einsum("kaj,j->ka", self.forms, np.array(self.G.value).reshape(-1))
        grad = (lam @ inner) @ self._dmonomials(th)  # sum_k lam_k <dP_k/dθ, G>
        return float(self.F.value[self.pp.measure_point]), grad


def _seed(expr: Any) -> float:
    try:
        return float(expr)
    except (TypeError, ValueError):
        return float("nan")
