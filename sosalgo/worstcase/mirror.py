"""Bregman (mirror) steps in the PEP: a spec with ``mirror: {kernel: {class: ...}}``.

The method's one state is the mirror variable z = grad h(x) of the kernel h, the call
is made at the point x whose mirror variable is C z + D u, and z+ = A z + B u
(A = C = E = 1, B = -gamma): a point is defined implicitly by the kernel's gradient,
as a proximal step's point is by its subgradient. Two steps:

* gradient step (D = 0; NoLips, mirror descent): with g_k = grad f(x_k),
  grad h(x_{k+1}) + s_{k+1} = grad h(x_k) - gamma g_k;
* proximal step (D = B; Bregman proximal point): with g_{k+1} a subgradient of f at
  x_{k+1}, grad h(x_{k+1}) + s_{k+1} = grad h(x_k) - gamma g_{k+1};

s_{k+1} a normal vector of the set C at x_{k+1} when ``set: true`` (the problem is then
min f + i_C, the step over h + i_C), else 0. This is PEPit's ``bregman_gradient_step``
and ``bregman_proximal_step``.

The PEP (Dragomir, Taylor, d'Aspremont and Bolte 2021): the points x* (when f is convex:
the minimizer, grad f(x*) + s* = 0), x_0, ..., x_N are free vectors; f and h get a value
and a subgradient at each, those fixed by the step equations combined from the others.
Conditions between every ordered pair of points: the convex blocks cf f + ch h of a
class relative to the kernel (:mod:`sosalgo.classes.relatively_smooth`), or the
classes of f and of h; the kernel's own class; the set's normal vectors
<s_b, x_a - x_b> <= 0. Values are free (no tilt): the dual's value coefficients must
vanish exactly. A minimum over iterates (``min D_h(...)``) is bounded by a weighted sum,
the weights w >= 0 (sum 1) chosen by the SDP:

    min_k m_k <= sum_k w_k m_k <= tau initial     when
    S = tau I0 - sum_k w_k M_k - sum_p lam_p Q_p ⪰ 0,
    tau i_F - sum_k w_k m_F,k - sum_p lam_p a_p = 0,   lam >= 0.

The proof: the SDP is solved with a margin (S ⪰ eps I), the multipliers and weights made
rationals, the value equations solved exactly on the multipliers' support (a square
system of independent rows), then S ⪰ 0 is decided in exact rationals
(:func:`sosalgo.kernel.exact.prove_psd`). Every datum is an exact rational of the spec
as written (parameters, classes); an irrational one leaves the bound unproven.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.errors import InputError

__all__ = ["MEASURES", "INITIALS", "MirrorPEP", "build_mirror", "mirror_pep",
           "prove_mirror", "solve_mirror"]

# the terms a mirror spec's PEP takes (whitespace ignored; x_(k-1) is x_{k-1})
MEASURES = ("f", "D_h(x_*, x_N)", "min D_h(x_{k-1}, x_k)", "min D_h(x_k, x_{k-1})")
INITIALS = ("D_h(x_*, x_0)", "f(x_0) - f(x_N)")


def _key(text: str) -> str:
    """A term without whitespace, x_(k-1) written x_{k-1}."""
    return "".join(text.split()).replace("x_(k-1)", "x_{k-1}")


@dataclass
class MirrorPEP:
    """The PEP as data: Gram forms on ``basis`` (d x d), value forms on ``values``;
    ``pairs``: (label, a on F, Q on G) with a.F + <Q, G> >= 0; ``measures``: the forms
    whose minimum is bounded; ``initial``: the form bounded by 1."""

    basis: list[str]
    values: list[str]
    pairs: list[tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)
    measures: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    initial: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def d(self) -> int:
        return len(self.basis)


class _Builder:
    """Rows (on the basis) and value indices, built on Fractions or floats."""

    def __init__(self, one: Any) -> None:
        self.one = one
        self.cols: list[str] = []
        self.vals: list[str] = []
        self.rows: list[np.ndarray] = []  # pending rows are padded at the end

    def vector(self, label: str) -> dict[int, Any]:
        self.cols.append(label)
        return {len(self.cols) - 1: self.one}

    def value(self, label: str) -> int:
        self.vals.append(label)
        return len(self.vals) - 1


def _lin(*terms: tuple[Any, dict[int, Any]]) -> dict[int, Any]:
    """sum c v over (c, v) of sparse rows."""
    out: dict[int, Any] = {}
    for c, v in terms:
        for k, x in v.items():
            out[k] = out.get(k, 0) + c * x
    return out


@dataclass
class _Point:
    label: str
    x: dict[int, Any]
    gf: dict[int, Any] | None = None
    gh: dict[int, Any] | None = None
    s: dict[int, Any] | None = None  # a normal vector of the set (None: not in the set)
    f: int | None = None
    h: int | None = None


def build_mirror(data: dict[str, Any], steps: int, measure: str, initial: str) -> MirrorPEP:
    """The PEP of a mirror spec's method (``data``: :func:`_method_data`) after ``steps``
    steps; exact when its numbers are Fractions."""
    one = data["one"]
    zero = one * 0
    b = _Builder(one)
    convex = data["minimizer"]
    use_set = data["set"]
    x0_in_set = use_set and "f(x_0)" in _key(initial)
    pts: list[_Point] = []
    if convex:  # x* = 0; grad f(x*) + s* = 0
        star = _Point("x*", {}, f=b.value("f(x*)"), h=b.value("h(x*)"))
        star.gh = {}  # h - <grad h(x*), .> is as good a kernel: the same steps and D_h
        star.gf = b.vector("gf(x*)") if use_set else {}
        star.s = _lin((-one, star.gf)) if use_set else None
        pts.append(star)
    # without x*, the origin at x_0 and grad h(x_0) = 0 (a translation, a linear tilt of h)
    x0 = _Point("x0", b.vector("x0-x*") if convex else {}, f=b.value("f(x0)"),
                h=b.value("h(x0)"))
    x0.gf, x0.gh = b.vector("gf(x0)"), b.vector("gh(x0)") if convex else {}
    if x0_in_set:
        x0.s = b.vector("s(x0)")
    pts.append(x0)
    gamma, prox = data["gamma"], data["prox"]
    for k in range(1, steps + 1):
        prev = pts[-1]
        p = _Point(f"x{k}", b.vector(f"x{k}"), f=b.value(f"f(x{k})"), h=b.value(f"h(x{k})"))
        p.gf = b.vector(f"gf(x{k})")
        z = _lin((one, prev.gh), (-gamma, p.gf if prox else prev.gf))
        if use_set:  # grad h(x+) + s+ = z
            p.gh = b.vector(f"gh(x{k})")
            p.s = _lin((one, z), (-one, p.gh))
        else:
            p.gh = z
        pts.append(p)
    pep = MirrorPEP(list(b.cols), list(b.vals))
    dense = [(p, {key: getattr(p, key) for key in ("x", "gf", "gh", "s")}) for p in pts]
    _pairs(pep, data, dense, zero)
    nF = len(b.vals)
    rows = {p.label: r for p, r in dense}
    vals = {p.label: p for p, _ in dense}
    pep.measures = _measure_forms(measure, steps, rows, vals, nF, zero, convex)
    init = _measure_forms(initial, steps, rows, vals, nF, zero, convex, True)
    pep.initial = init[0]
    return pep


Form = dict  # a symmetric Gram form: {(i, j): v} with i <= j (S[i][j] = S[j][i] = v)


def _outer(u: dict[int, Any], v: dict[int, Any]) -> Form:
    """The symmetric Gram form of <u, v> (sparse rows)."""
    out: Form = {}
    for i, a in u.items():
        for j, b in v.items():
            key = (i, j) if i <= j else (j, i)
            out[key] = out.get(key, 0) + (a * b if i == j else a * b / 2)
    return out


def _add(*terms: tuple[Any, Form]) -> Form:
    """sum c F over (c, F)."""
    out: Form = {}
    for c, F in terms:
        for k, v in F.items():
            out[k] = out.get(k, 0) + c * v
    return {k: v for k, v in out.items() if v != 0}


def _sub(u: dict[int, Any], v: dict[int, Any]) -> dict[int, Any]:
    return _lin((1, u), (-1, v))


def _convex_pair(xa, xb, ga, gb) -> Form:  # noqa: ANN001
    """Gram part of f_a - f_b - <g_b, x_a - x_b> (>= 0 for a convex f)."""
    return _add((-1, _outer(gb, _sub(xa, xb))))


def dense_form(F: Form, d: int, zero: Any = 0.0) -> np.ndarray:
    """The d x d matrix of a form (floats by default)."""
    out = np.full((d, d), zero, dtype=object if not isinstance(zero, float) else float)
    for (i, j), v in F.items():
        out[i, j] = v
        out[j, i] = v
    return out


def _pairs(pep: MirrorPEP, data: dict[str, Any], dense: list[Any], zero: Any) -> None:
    """Every ordered pair's conditions: f's blocks (or class), the kernel's class, the set."""
    nF = len(pep.values)

    def fvec(entries: dict[int, Any]) -> np.ndarray:
        out = np.array([zero] * nF, dtype=object)
        for k, v in entries.items():
            if k is not None:
                out[k] = out[k] + v
        return out

    for pa, ra in dense:
        for pb, rb in dense:
            if pa is pb:
                continue
            lab = f"{pa.label},{pb.label}"
            for r, (cf, ch) in enumerate(data["blocks"]):
                ga = _lin((cf, ra["gf"]), (ch, ra["gh"]))
                gb = _lin((cf, rb["gf"]), (ch, rb["gh"]))
                a = fvec({pa.f: cf}) + fvec({pa.h: ch}) - fvec({pb.f: cf}) - fvec({pb.h: ch})
                pep.pairs.append((f"block{r}:{lab}", a, _convex_pair(ra["x"], rb["x"], ga, gb)))
            for name, g, key, ineqs in (("f", "gf", "f", data["f_ineqs"]),
                                        ("h", "gh", "h", data["h_ineqs"])):
                for r, (alpha, Q) in enumerate(ineqs):
                    X = [ra["x"], rb["x"], ra[g], rb[g]]
                    G = _add(*((Q[u][v], _outer(X[u], X[v])) for u in range(4)
                               for v in range(4) if Q[u][v] != 0))
                    a = fvec({getattr(pa, key): alpha}) - fvec({getattr(pb, key): alpha})
                    pep.pairs.append((f"{name}#{r}:{lab}", a, G))
            if ra["s"] is not None and rb["s"] is not None:  # <s_b, x_a - x_b> <= 0
                pep.pairs.append((f"set:{lab}", fvec({}),
                                  _convex_pair(ra["x"], rb["x"], ra["s"], rb["s"])))


def _bregman(rows: dict[str, Any], vals: dict[str, Any], a: str, b: str, nF: int,
             zero: Any) -> tuple[np.ndarray, np.ndarray]:
    """D_h(a, b) = h(a) - h(b) - <grad h(b), a - b> as (Gram form, value form)."""
    f = np.array([zero] * nF, dtype=object)
    f[vals[a].h] = f[vals[a].h] + 1
    f[vals[b].h] = f[vals[b].h] - 1
    return _add((-1, _outer(rows[b]["gh"], _sub(rows[a]["x"], rows[b]["x"])))), f


def _fdiff(rows: dict[str, Any], vals: dict[str, Any], a: str, b: str, nF: int,
           zero: Any) -> tuple[np.ndarray, np.ndarray]:
    """f(a) - f(b) as (Gram form, value form)."""
    f = np.array([zero] * nF, dtype=object)
    f[vals[a].f] = f[vals[a].f] + 1
    f[vals[b].f] = f[vals[b].f] - 1
    return {}, f


def _measure_forms(text: str, steps: int, rows: dict[str, Any], vals: dict[str, Any],
                   nF: int, zero: Any, convex: bool, initial: bool = False) -> list[Any]:
    """The forms of a measure (several: their minimum) or of the initial condition."""
    key = _key(text)
    N = f"x{steps}"
    forms = {"f": lambda: [_fdiff(rows, vals, N, "x*", nF, zero)],
             "D_h(x_*,x_N)": lambda: [_bregman(rows, vals, "x*", N, nF, zero)],
             "minD_h(x_{k-1},x_k)": lambda: [_bregman(rows, vals, f"x{k - 1}", f"x{k}", nF,
                                                      zero) for k in range(1, steps + 1)],
             "minD_h(x_k,x_{k-1})": lambda: [_bregman(rows, vals, f"x{k}", f"x{k - 1}", nF,
                                                      zero) for k in range(1, steps + 1)],
             "D_h(x_*,x_0)": lambda: [_bregman(rows, vals, "x*", "x0", nF, zero)],
             "f(x_0)-f(x_N)": lambda: [_fdiff(rows, vals, "x0", N, nF, zero)]}
    return forms[key]()


def check_terms(spec: Any, measure: str, initial: str, mopt: str, iopt: str,
                convex: bool) -> None:
    """InputError naming the option unless the terms are ones a mirror PEP takes (no x*
    when f is nonconvex)."""
    for text, opt, known in ((measure, mopt, MEASURES), (initial, iopt, INITIALS)):
        key = _key(text)
        if key not in {_key(k) for k in known}:
            raise InputError(f"{spec.source}: {opt}: {text!r}: a Bregman step's PEP takes "
                             + ", ".join(repr(k) for k in known))
        if not convex and ("x_*" in key or key == "f"):
            raise InputError(f"{spec.source}: {opt}: {text!r}: f is nonconvex, its PEP has "
                             "no minimizer x* (use min D_h(...) and f(x_0) - f(x_N))")


# --------------------------------------------------------------------------- the method


def _fraction(v: Any) -> Fraction | None:
    """A sympy number as a Fraction (None when irrational)."""
    return Fraction(int(v.p), int(v.q)) if getattr(v, "is_Rational", False) else None


def method_data(spec: Any, exact: bool) -> dict[str, Any] | None:
    """gamma, the step kind, the classes' data of a mirror spec, in floats, or exact
    rationals (``exact``; None when a number is irrational). InputError naming the field
    for a method that is not a Bregman step."""
    import sympy as sp

    from sosalgo.classes import CLASSES
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.worstcase.exact import exact_values

    env, mats = exact_values(spec)
    A, B, C, E = (mats[k][0, 0] for k in "ABCE")
    D = mats["D"][0, 0] if "D" in mats else sp.Integer(0)
    if not (A == 1 and C == 1 and E == 1 and sp.simplify(B) < 0
            and (D == 0 or sp.simplify(D - B) == 0)):
        raise InputError(f"{spec.source}: matrices: a Bregman step is z+ = z - gamma u with "
                         "A = C = E = [[1]], B = [[-gamma]] (gamma > 0) and D = [[0]] (gradient "
                         "step) or D = B (proximal step)")
    (fname, fdecl), = spec.functions.items()
    fcls, kdecl = CLASSES[fdecl.cls], spec.mirror["kernel"]
    kcls = CLASSES[kdecl.cls]
    prox = D != 0
    relative = bool(getattr(fcls, "relative", False))
    if prox == relative:
        raise InputError(f"{spec.source}: functions.{fname}.class: " + (
            f"{fdecl.cls} is relative to the kernel: its step is a Bregman gradient step "
            "(D = [[0]])" if relative else "a Bregman gradient step needs f smooth relative "
            f"to the kernel (a class with L h - f convex), not {fdecl.cls}"))
    if prox and "proximal" not in fcls.oracles:
        raise InputError(f"{spec.source}: functions.{fname}.class: {fdecl.cls} has no "
                         "proximal oracle")

    def number(v: Any) -> Any:
        return _fraction(sp.nsimplify(v) if not v.is_Rational else v) if exact else float(v)

    def params(decl: Any) -> dict[str, Any]:
        return {k: number(to_sympy(e).xreplace(env)) for k, e in decl.params.items()}

    fp, kp = params(fdecl), params(kdecl)
    gamma = number(-B)
    if exact and (gamma is None or None in fp.values() or None in kp.values()):
        return None
    fl = {k: float(v) for k, v in fp.items()}
    try:
        fcls.check(fl)
        kcls.check({k: float(v) for k, v in kp.items()})
    except ValueError as exc:
        raise InputError(f"{spec.source}: functions.{fname}.{exc}") from None
    return {"one": Fraction(1) if exact else 1.0, "gamma": gamma, "prox": bool(prox),
            "set": spec.mirror["set"], "minimizer": fcls.convex,
            "blocks": fcls.blocks(fp) if relative else [],
            "f_ineqs": [] if relative else _ineqs(fcls, fp, exact),
            "h_ineqs": _ineqs(kcls, kp, exact)}


def _ineqs(cls: Any, params: dict[str, Any], exact: bool) -> list[tuple[Any, Any]]:
    """(alpha, Q 4 x 4) of a class's inequalities (exact ones from its exact data)."""
    if exact:
        return [(Fraction(a), [[Fraction(v) for v in row] for row in Q])
                for a, Q in cls.exact_tilted(params)]
    return [(float(i.alpha), np.asarray(i.Q, float).tolist())
            for i in cls.inequalities(params)]


# --------------------------------------------------------------------------- solve


def _floats(M: np.ndarray) -> np.ndarray:
    return np.array(M, dtype=float)


def linear_directions(pep: MirrorPEP) -> list[int]:
    """The basis directions no form has a square of (a zero diagonal everywhere): a
    slack S ⪰ 0 is zero on their rows."""
    forms = [Q for _, _, Q in pep.pairs] + [M for M, _ in pep.measures]
    forms.append(pep.initial[0])  # type: ignore[index]
    squared = {i for Q in forms for (i, j), v in Q.items() if i == j and v}
    return [i for i in range(pep.d) if i not in squared]


def solve_mirror(pep: MirrorPEP, margin: float = 0.0) -> dict[str, Any] | None:
    """The dual SDP (see the module): min tau over (tau, w, lam) with S zero on the
    :func:`linear_directions` and S ⪰ margin I on the others; None when the solver
    fails."""
    import cvxpy as cp

    d, nF, P, K = pep.d, len(pep.values), len(pep.pairs), len(pep.measures)
    Qs = np.array([dense_form(Q, d).ravel() for _, _, Q in pep.pairs]).reshape(P, d * d)
    As = np.array([_floats(a) for _, a, _ in pep.pairs]).reshape(P, nF)
    Ms = np.array([dense_form(M, d).ravel() for M, _ in pep.measures]).reshape(K, d * d)
    mF = np.array([_floats(f) for _, f in pep.measures]).reshape(K, nF)
    assert pep.initial is not None
    I0, iF = dense_form(pep.initial[0], d).ravel(), _floats(pep.initial[1])
    zero = linear_directions(pep)
    rest = [i for i in range(d) if i not in zero]
    tau, w, lam = cp.Variable(), cp.Variable(K, nonneg=True), cp.Variable(P, nonneg=True)
    S = cp.Variable((len(rest), len(rest)), PSD=True)
    expr = cp.reshape(tau * I0 - Ms.T @ w - Qs.T @ lam, (d, d), order="C")
    cons = [cp.sum(w) == 1, tau * iF - mF.T @ w - As.T @ lam == 0,
            expr[rest, :][:, rest] == S]
    if zero:
        cons.append(expr[zero, :] == 0)
    if margin > 0:
        cons.append(S >> margin * np.eye(len(rest)))
    prob = cp.Problem(cp.Minimize(tau), cons)
    try:
        prob.solve(solver=cp.CLARABEL)
    except cp.SolverError:
        return None
    if prob.status not in ("optimal", "optimal_inaccurate") or tau.value is None:
        return None
    full = np.zeros((d, d))
    full[np.ix_(rest, rest)] = np.asarray(S.value, float)
    return {"tau": float(tau.value), "w": np.maximum(np.asarray(w.value, float), 0),
            "lam": np.maximum(np.asarray(lam.value, float), 0), "S": full,
            "status": prob.status}


# --------------------------------------------------------------------------- exact proof


def prove_mirror(pep: MirrorPEP, tau: float, w: np.ndarray, lam: np.ndarray
                 ) -> tuple[bool, dict[str, Any]]:
    """Prove min_k m_k <= tau' (a decimal just above ``tau``) on the exact PEP from the
    float weights and multipliers (see the module): the value coefficients and the rows
    of S on the :func:`linear_directions` made exactly zero by a correction of the
    multipliers on their support, then S ⪰ 0 in exact rationals. (proven, detail)."""
    from sosalgo.kernel.exact import fraction_str, prove_psd, rational
    from sosalgo.worstcase.exact import decimal_up

    t0 = time.perf_counter()
    wq = [rational(float(v)) if v > 1e-12 * max(w.max(), 1e-300) else Fraction(0) for v in w]
    total = sum(wq, Fraction(0))
    if total <= 0:
        return False, {"detail": "no positive weight"}
    wq = [v / total for v in wq]
    top = float(lam.max(initial=0.0))
    support = [p for p, v in enumerate(lam) if v > 1e-9 * top]
    keep = set(support)
    lq = [rational(float(v)) if p in keep else Fraction(0) for p, v in enumerate(lam)]
    zero = linear_directions(pep)
    rest = [i for i in range(pep.d) if i not in zero]
    why = "no margin"
    for rel in (Fraction(1, 10 ** 9), Fraction(1, 10 ** 7), Fraction(1, 10 ** 5)):
        tq = decimal_up(rational(tau) * (1 + rel))
        lam2 = _balance(pep, tq, wq, lq, support, zero)
        if lam2 is None:
            why = "the equations have no nonnegative exact solution on the support"
            continue
        S = _slack(pep, tq, wq, lam2)
        if any(S[i][j] for i in zero for j in range(pep.d)):
            why = "a row of S on a linear direction is not zero"
            continue
        proof = prove_psd([[S[i][j] for j in rest] for i in rest])
        if proof.psd:
            return True, {"tau_proven": fraction_str(tq), "tau_proven_float": float(tq),
                          "detail": "value coefficients and the linear directions' rows of "
                                    f"S exactly 0; S ⪰ 0 in exact rationals ({proof.kind})",
                          "multipliers_exact": {pep.pairs[p][0]: fraction_str(v)
                                                for p, v in enumerate(lam2) if v},
                          "weights_exact": [fraction_str(v) for v in wq],
                          "seconds": time.perf_counter() - t0}
        why = f"S is not proven PSD: {proof.detail}"
    return False, {"detail": why, "seconds": time.perf_counter() - t0}


def _value_residual(pep: MirrorPEP, tq: Fraction, wq: list[Fraction],
                    lq: list[Fraction]) -> list[Fraction]:
    """tau i_F - sum_k w_k m_F,k - sum_p lam_p a_p, exactly."""
    assert pep.initial is not None
    r = [tq * Fraction(v) for v in pep.initial[1]]
    for wk, (_, f) in zip(wq, pep.measures, strict=True):
        if wk:
            r = [a - wk * Fraction(b) for a, b in zip(r, f, strict=True)]
    for lp, (_, a, _) in zip(lq, pep.pairs, strict=True):
        if lp:
            r = [x - lp * Fraction(y) for x, y in zip(r, a, strict=True)]
    return r


def _balance(pep: MirrorPEP, tq: Fraction, wq: list[Fraction], lq: list[Fraction],
             support: list[int], zero: list[int]) -> list[Fraction] | None:
    """The multipliers with the value equations and the rows of S on the directions
    ``zero`` exact (tau fixed at ``tq``, the weights ``wq`` kept): a correction on
    independent columns, the largest multipliers first (every pair may enter, a small
    one last), solving independent rows exactly (flint), then checked on every row;
    None when it fails or makes a multiplier negative."""
    P, K = len(pep.pairs), len(wq)
    cols = ["tau"] + [("w", k) for k in range(K)] + [("lam", p) for p in range(P)]
    A = _linear_system(pep, cols, zero)
    u = [tq] + list(wq) + list(lq)
    r = A.residual(u)
    if not any(r):
        return lq
    lamcols = list(range(1 + K, len(cols)))
    top = float(max(lq, default=Fraction(0)))
    size = np.array([max(float(u[c]), 1e-6 * top) for c in lamcols])
    rows, sub = _independent(A.dense(lamcols) * size)
    if not rows:
        return None
    delta = _exact_solve(A, r, rows, [lamcols[c] for c in sub])
    if delta is None:
        return None
    new = list(u)
    for c, dx in delta.items():
        new[c] += dx
    if any(v < 0 for v in new[1:]) or any(A.residual(new)):
        return None
    return new[1 + K:]


def _independent(A: np.ndarray) -> tuple[list[int], list[int]]:
    """Rows and as many columns of A forming a well-conditioned square submatrix (QR with
    column pivoting, on the rows first, then on the columns of those rows)."""
    from scipy.linalg import qr

    live = np.flatnonzero(np.abs(A).max(axis=1) > 0) if A.size else np.zeros(0, int)
    if live.size == 0:
        return [], []
    _, R, prow = qr(A[live].T, pivoting=True, mode="economic")
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > 1e-9 * diag.max())) if diag.size else 0
    rows = sorted(live[prow[:rank]].tolist())
    _, R2, pcol = qr(A[rows], pivoting=True, mode="economic")
    return rows, sorted(pcol[:rank].tolist())


def _slack(pep: MirrorPEP, tq: Fraction, wq: list[Fraction], lq: list[Fraction]
           ) -> list[list[Fraction]]:
    """S = tau I0 - sum_k w_k M_k - sum_p lam_p Q_p in exact rationals."""
    assert pep.initial is not None
    S = _add((tq, pep.initial[0]), *((-wk, M) for wk, (M, _) in zip(wq, pep.measures,
                                                                       strict=True) if wk),
             *((-lp, Q) for lp, (_, _, Q) in zip(lq, pep.pairs, strict=True) if lp))
    S = dense_form({k: Fraction(v) for k, v in S.items()}, pep.d, Fraction(0))
    return [list(row) for row in S]


# --------------------------------------------------------------------------- the run

MARGINS = (1e-8, 1e-7, 1e-6, 1e-5)  # relative margins of the certificate solves, in order


def _problem(spec: Any, kappa: float | None, steps: int, measure: str | None,
             initial: str | None) -> tuple[MirrorPEP, dict[str, Any], bool, str, str]:
    """(PEP, data, whether the data are exact, measure, initial): every input error
    first, naming its option."""
    if kappa is not None:
        raise InputError(f"{spec.source}: --kappa: a mirror spec (m: 0) has no condition "
                         "number")
    mopt = "--measure" if measure or "measure" not in spec.pep else "pep.measure"
    iopt = "--initial" if initial or "initial" not in spec.pep else "pep.initial"
    measure = measure or spec.pep.get("measure") or "f"
    initial = initial or spec.pep.get("initial") or "D_h(x_*, x_0)"
    data = method_data(spec, exact=True)
    exact_data = data is not None
    if data is None:
        data = method_data(spec, exact=False)
    assert data is not None
    check_terms(spec, measure, initial, mopt, iopt, data["minimizer"])
    return build_mirror(data, steps, measure, initial), data, exact_data, measure, initial


def mirror_problem(spec: Any, kappas: list[float | None], steps: int, measure: str | None,
                   initial: str | None) -> tuple[int, int]:
    """(pairs, basis size) of the PEP after ``steps`` steps, every input error raised
    first (InputError naming the option)."""
    for k in kappas:
        pep, *_ = _problem(spec, k, steps, measure, initial)
    return len(pep.pairs), pep.d


def mirror_pep(spec: Any, kappa: float | None, steps: int, measure: str | None,
               initial: str | None, exact: bool, result: Any) -> Any:
    """``sosalgo pep`` of a mirror spec (``steps`` checked by the caller): a ``result``
    (:class:`~sosalgo.worstcase.core.PEPResult`) whose certificate is proven in exact
    rationals (no witness: said in ``note``)."""
    PEPResult = result
    t0 = time.perf_counter()
    pep, data, exact_data, measure, initial = _problem(spec, kappa, steps, measure, initial)
    ans = solve_linear(pep) if no_squares(pep) else solve_mirror(pep)
    status = "failed" if ans is None else ans["status"]
    status = "solved" if status.startswith("optimal") else status
    res = PEPResult(spec.name, None, steps, measure, initial, status,
                    ans["tau"] if status == "solved" else None)
    res.extra["note"] = ("no worst-case witness for a Bregman step (tau_proven is the "
                         "proven upper bound)")
    if status == "unbounded":
        res.tau = float("inf")
        res.extra["note"] = "the measure is unbounded for this initial condition"
    if status != "solved":
        res.seconds = time.perf_counter() - t0
        return res
    res.gap = 0.0
    res.certificate = _certificate(pep, ans, exact and exact_data)
    if not exact_data and exact:
        res.certificate["proof"] = {"proven": False, "detail": "a parameter is irrational: "
                                    "no exact data"}
    res.seconds = time.perf_counter() - t0
    return res


def _certificate(pep: MirrorPEP, ans: dict[str, Any], exact: bool) -> dict[str, Any]:
    """The certificate of the solve ``ans``: proven at the first margin that works."""
    tau = ans["tau"]
    cert: dict[str, Any] = {"tau": tau, "check_kind": "floating-point check",
                            "tau_proven": None, "proof": None, "bregman": True}
    best = ans
    if "system" in ans:  # S = 0: a vertex of the linear program, proven as it is
        if exact:
            ans["labels"] = [lab for lab, _, _ in pep.pairs]
            ok, proof = prove_linear(ans)
            cert["proof"] = {"proven": ok, **proof}
            if ok:
                cert.update(check_kind="exact (rational arithmetic)",
                            tau_proven=proof["tau_proven"], margin=0.0)
        exact = False  # no margin helps: S = 0 is the only PSD slack
    scale = max([1.0] + [abs(float(v)) for v in pep.initial[0].values()])  # type: ignore[index]
    for rel in MARGINS if exact else ():
        cand = solve_mirror(pep, margin=rel * max(abs(tau), 1e-12) / scale)
        if cand is None:
            continue
        best = cand
        ok, proof = prove_mirror(pep, max(cand["tau"], tau), cand["w"], cand["lam"])
        cert["proof"] = {"proven": ok, **proof}
        if ok:
            cert.update(check_kind="exact (rational arithmetic)",
                        tau_proven=proof["tau_proven"], margin=rel)
            break
    top = float(best["lam"].max(initial=0.0))
    cert["multipliers"] = {lab: float(v) for (lab, _, _), v in zip(pep.pairs, best["lam"],
                                                                   strict=True)
                           if v > 1e-12 * top}
    cert["weights"] = [float(v) for v in best["w"]]
    cert["basis"] = pep.basis
    cert["values"] = pep.values
    cert["slack"] = best["S"].tolist()
    cert["min_eig_slack"] = float(np.linalg.eigvalsh(best["S"])[0])
    return cert


def no_squares(pep: MirrorPEP) -> bool:
    """Whether no form has a diagonal entry (only products <g, x>: convex classes, no
    modulus): S ⪰ 0 with a zero diagonal is S = 0, and the certificate is linear
    (:func:`prove_linear`)."""
    forms = [Q for _, _, Q in pep.pairs] + [M for M, _ in pep.measures]
    forms.append(pep.initial[0])  # type: ignore[index]
    return all(not any(v for (i, j), v in Q.items() if i == j) for Q in forms)


def solve_linear(pep: MirrorPEP) -> dict[str, Any] | None:
    """The dual with S = 0 (:func:`no_squares`) as a linear program (HiGHS): a vertex,
    whose support is a basis; None when it fails."""
    from sosalgo.kernel.solvers import linear_program

    K, P = len(pep.measures), len(pep.pairs)
    cols = ["tau"] + [("w", k) for k in range(K)] + [("lam", p) for p in range(P)]
    A = _linear_system(pep, cols)
    c = np.zeros(len(cols))
    c[0] = 1.0
    res = linear_program(c, A.sparse(), np.array([float(v) for v in A.rhs]),
                         [(None, None)] + [(0, None)] * (K + P), method="highs-ds")
    if res.status == 2:  # the dual is infeasible: no bound, the worst case is unbounded
        return {"status": "unbounded"}
    if res.status != 0:
        return None
    u = np.asarray(res.x, float)
    d = pep.d
    return {"tau": float(u[0]), "w": np.maximum(u[1:K + 1], 0),
            "lam": np.maximum(u[K + 1:], 0), "S": np.zeros((d, d)), "status": "optimal",
            "system": (A, cols)}


def prove_linear(ans: dict[str, Any]) -> tuple[bool, dict[str, Any]]:
    """The certificate with S = 0 exactly from the vertex ``ans`` of
    :func:`solve_linear`: tau and the weights and multipliers of its support solve the
    equations (S = 0, the value coefficients 0, sum w = 1) in exact rationals
    (independent rows chosen in floating point), then every equation is checked exactly
    and every multiplier and weight is >= 0. (proven, detail)."""
    from sosalgo.kernel.exact import fraction_str

    t0 = time.perf_counter()
    A, cols = ans["system"]
    u = np.concatenate([[ans["tau"]], ans["w"], ans["lam"]])
    top = float(np.abs(u).max())
    piv = [0] + [c for c in range(1, len(cols)) if u[c] > 1e-10 * top]
    rows, sub = _independent(A.dense(piv))
    if len(sub) != len(piv):
        return False, {"detail": "the vertex's columns are dependent",
                       "seconds": time.perf_counter() - t0}
    found = _exact_solve(A, A.rhs, rows, piv)
    if found is None:
        return False, {"detail": "the vertex's equations are singular",
                       "seconds": time.perf_counter() - t0}
    sol = [found.get(c, Fraction(0)) for c in range(len(cols))]
    if any(sol[c] < 0 for c in range(1, len(cols))) or any(A.residual(sol)):
        return False, {"detail": "exact solve: a negative multiplier or an equation off",
                       "seconds": time.perf_counter() - t0}
    tq = sol[0]
    return True, {"tau_proven": fraction_str(tq), "tau_proven_float": float(tq),
                  "detail": "S = 0 and the value coefficients 0 in exact rationals "
                            "(multipliers and weights >= 0)",
                  "multipliers_exact": {pep_label: fraction_str(v) for (kind, pep_label), v
                                        in _labelled(ans, sol) if kind == "lam" and v},
                  "weights_exact": [fraction_str(v) for (kind, _), v in _labelled(ans, sol)
                                    if kind == "w"],
                  "seconds": time.perf_counter() - t0}


def _labelled(ans: dict[str, Any], sol: list[Fraction]) -> list[tuple[tuple[str, Any],
                                                                       Fraction]]:
    """((kind, label), value) of every unknown but tau."""
    labels = ans["labels"]
    return [((c[0], labels[c[1]] if c[0] == "lam" else c[1]), v)
            for c, v in zip(ans["system"][1][1:], sol[1:], strict=True)]


@dataclass
class _System:
    """Sparse linear equations sum_c A[r][c] u_c = rhs[r]: ``cols`` one {row: value}
    per unknown (exact rationals)."""

    cols: list[dict[int, Fraction]]
    rhs: list[Fraction]

    def dense(self, which: list[int]) -> np.ndarray:
        """The float submatrix of the columns ``which`` (every row)."""
        out = np.zeros((len(self.rhs), len(which)))
        for k, c in enumerate(which):
            for r, v in self.cols[c].items():
                out[r, k] = float(v)
        return out

    def apply(self, u: list[Fraction]) -> list[Fraction]:
        """A u, exactly."""
        out = [Fraction(0)] * len(self.rhs)
        for c, x in enumerate(u):
            if x:
                for r, v in self.cols[c].items():
                    out[r] += v * x
        return out

    def sparse(self) -> Any:
        """The float matrix (scipy CSR)."""
        import scipy.sparse as sps

        rows, cols, vals = [], [], []
        for c, col in enumerate(self.cols):
            for r, v in col.items():
                rows.append(r)
                cols.append(c)
                vals.append(float(v))
        return sps.csr_matrix((vals, (rows, cols)), shape=(len(self.rhs), len(self.cols)))

    def residual(self, u: list[Fraction]) -> list[Fraction]:
        return [b - a for a, b in zip(self.apply(u), self.rhs, strict=True)]


def _linear_system(pep: MirrorPEP, cols: list[Any], only: list[int] | None = None
                   ) -> _System:
    """Rows: S[i][j] = 0 (i <= j; with ``only``, the entries with i or j in it), the
    value coefficients = 0, sum w = 1; columns ``cols`` (tau, weights, multipliers)."""
    assert pep.initial is not None
    d, nF = pep.d, len(pep.values)
    entries = [(i, j) for i in range(d) for j in range(i, d)
               if only is None or i in only or j in only]
    index = {e: k for k, e in enumerate(entries)}
    n = len(entries) + nF + 1

    def column(c: Any) -> dict[int, Fraction]:
        if c == "tau":
            Q, f, sign = pep.initial[0], pep.initial[1], 1  # type: ignore[index]
        elif c[0] == "w":
            (Q, f), sign = pep.measures[c[1]], -1
        else:
            _, f, Q = pep.pairs[c[1]]
            sign = -1
        out = {index[e]: sign * Fraction(v) for e, v in Q.items() if v and e in index}
        out.update({len(entries) + k: sign * Fraction(v) for k, v in enumerate(f) if v})
        if c != "tau" and c[0] == "w":
            out[n - 1] = Fraction(1)
        return out

    rhs = [Fraction(0)] * (n - 1) + [Fraction(1)]
    return _System([column(c) for c in cols], rhs)


def _exact_solve(A: _System, rhs: list[Fraction], rows: list[int], piv: list[int]
                 ) -> dict[int, Fraction] | None:
    """Solve the rows ``rows`` of A x = rhs for the columns ``piv`` exactly (flint), the
    other unknowns 0: {column: value}; None when singular."""
    from flint import fmpq, fmpq_mat

    if len(rows) != len(piv) or not rows:
        return None
    at = {r: k for k, r in enumerate(rows)}
    sub = [[Fraction(0)] * len(piv) for _ in rows]
    for k, c in enumerate(piv):
        for r, v in A.cols[c].items():
            if r in at:
                sub[at[r]][k] = v
    M = fmpq_mat(len(rows), len(piv), [fmpq(v.numerator, v.denominator)
                                        for row in sub for v in row])
    b = fmpq_mat(len(rows), 1, [fmpq(rhs[r].numerator, rhs[r].denominator) for r in rows])
    try:
        x = M.solve(b)
    except ZeroDivisionError:
        return None
    return {c: Fraction(int(x[k, 0].p), int(x[k, 0].q)) for k, c in enumerate(piv)}


def reprove_mirror(spec: Any, steps: int, measure: str, initial: str,
                   proof: dict[str, Any]) -> tuple[bool, str]:
    """(proven, detail): the claim min measure <= ``proof["tau_proven"]`` proven again
    from the proof's own exact multipliers (by pair label) and weights, on the exact PEP
    of ``spec`` rebuilt here: multipliers and weights >= 0, sum w = 1, the value
    coefficients exactly 0 and S ⪰ 0 in exact rationals; nothing is solved."""
    from sosalgo.kernel.exact import prove_psd

    lab, wts = proof.get("multipliers_exact"), proof.get("weights_exact")
    if not isinstance(lab, dict) or not isinstance(wts, list) \
            or not isinstance(proof.get("tau_proven"), str):
        return False, "the proof carries no exact multipliers and weights"
    try:
        tq = Fraction(proof["tau_proven"])
        data = method_data(spec, exact=True)
        if data is None:
            return False, "the exact data cannot be built (an irrational parameter)"
        check_terms(spec, measure, initial, "measure", "initial", data["minimizer"])
        pep = build_mirror(data, int(steps), measure, initial)
        index = {name: k for k, (name, _, _) in enumerate(pep.pairs)}
        unknown = [k for k in lab if k not in index]
        if unknown:
            return False, f"multiplier {unknown[0]!r} is not a pair of this PEP"
        lam = [Fraction(0)] * len(pep.pairs)
        for name, v in lab.items():
            lam[index[name]] = Fraction(v)
        w = [Fraction(v) for v in wts]
    except (ValueError, TypeError, ZeroDivisionError, ArithmeticError, InputError) as exc:
        return False, f"malformed proof: {type(exc).__name__}: {exc}"
    if len(w) != len(pep.measures) or any(v < 0 for v in w) or sum(w) != 1:
        return False, f"weights: expected {len(pep.measures)} numbers >= 0 summing to 1"
    if any(v < 0 for v in lam):
        return False, "a negative multiplier"
    if any(_value_residual(pep, tq, w, lam)):
        return False, "a value coefficient is not 0"
    psd = prove_psd(_slack(pep, tq, w, lam))
    if not psd.psd:
        return False, f"S is not PSD: {psd.detail}"
    return True, f"S ⪰ 0 ({psd.kind}) and the value coefficients 0, in exact rationals"
