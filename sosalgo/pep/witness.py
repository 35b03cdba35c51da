"""The worst case itself: a low-dimensional trajectory and functions that attain tau_N,
written as JSON and checked exactly (a theorem: tau_N >= its value).

Construction (:func:`make_witness`): the PEP again, minimizing tr H with the measure at
least (1 - eta) tau_N and every interpolation inequality at least a slack (the
:data:`LADDER`); candidates G = V V' in 1, 2, 3 dimensions, the full rank, then G mixed
with a strictly feasible quadratic trajectory (:func:`quadratic_point`); each rounded to
binary rationals, the trajectory recomputed exactly and the values fitted exactly
(:func:`fit_values`: difference constraints, shortest paths); the first that passes the
check is kept.

Document (``kind: pep-witness``): ``x0``; ``xi0`` (a free start: the initial state,
every block); ``calls`` (the gradient u_{k,i} of every call,
actual, not tilted); per function its class, optimal subgradient s_j* (summing to 0) and
points: ``at`` (where: ``y<i>_<k>``, ``x_0``, ``x_N``), the subgradient g there and the
tilted value h = f_j(x) - f_j(x*) - <s_j*, x - x*>; ``evaluations``: which point of each
function a term reads. Numbers are exact rationals as strings ("p/q").

The check (:func:`check_witness`) trusts nothing but the spec: it recomputes the
trajectory from xi_0 = u x_0 (or ``xi0``) with the exact method (balls, :mod:`sosalgo.pep.exact`),
checks every class inequality of every ordered pair of each function's points (x* with
g = s_j*, h = 0) on the tilted data (g - s_j*, h) with ball arithmetic (lower end >= 0),
sum_j s_j* = 0, and evaluates measure and initial exactly (sdist with xi* = X_s s~ from
the exact fixed points): tau_N >= measure / initial.
"""

from __future__ import annotations

import math
import time
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.pep.sdp import PEPData, SDPAnswer, solve_pep
from sosalgo.pep.structure import Method
from sosalgo.pep.terms import Term
from sosalgo.spec import Spec
from sosalgo.verify.exact import Ball

__all__ = ["WITNESS_KIND", "check_witness", "make_witness"]

WITNESS_KIND = "pep-witness"
# (slack, eta) of the reduced solves, in order: every inequality >= slack (scaled rows),
# the measure kept at (1 - eta) tau_N; a larger eta leaves room for a larger slack
LADDER = ((1e-9, 1e-6), (1e-8, 1e-5), (1e-7, 1e-4), (1e-6, 1e-3))
MAX_TRIES = 3  # dimensions tried per reduced solve (then the full rank)


def _q(x: float | Fraction) -> str:
    f = Fraction(x)
    return f"{f.numerator}/{f.denominator}" if f.denominator != 1 else str(f.numerator)


def _vec(v: np.ndarray) -> list[str]:
    return [_q(float(t)) for t in v]


def _factors(G: np.ndarray, slack: float) -> list[np.ndarray]:
    """V (d x r) with G ~ V V' for r = 1, 2, ... (at most MAX_TRIES, and while the
    dropped eigenvalues are not negligible), then the factor of full numerical rank."""
    e, V = np.linalg.eigh(0.5 * (G + G.T))
    e, V = e[::-1].clip(min=0.0), V[:, ::-1]
    rank = max(1, int(np.sum(e > 1e-15 * e[0]))) if e[0] > 0 else 1
    out = [V[:, :r] * np.sqrt(e[:r]) for r in range(1, min(rank, MAX_TRIES) + 1)]
    if rank > MAX_TRIES:
        out.append(V[:, :rank] * np.sqrt(e[:rank]))
    return out


THETAS = (1e-6, 1e-4)  # weights of the strictly feasible quadratic mixed in


def _candidates(mt: Method, st: Any, G: np.ndarray, slack: float):
    """(V, theta): the factors of G (:func:`_factors`), then G mixed with a strictly
    feasible point: V_theta = [sqrt(1 - theta) V, sqrt(theta) v0] (one more dimension),
    v0 the trajectory on the quadratics of :func:`quadratic_point` (every interpolation
    inequality is linear in (G, F) and strict there, so the mix turns the solver's small
    violations into slack, for a measure (1 - theta) as large)."""
    fs = _factors(G, slack)
    for V in fs:
        yield V, 0.0
    v0 = quadratic_point(mt, st)
    if v0 is None:
        return
    for theta in THETAS:
        yield np.hstack([math.sqrt(1 - theta) * fs[-1], math.sqrt(theta) * v0[:, None]]), theta


def quadratic_point(mt: Method, st: Any) -> np.ndarray | None:
    """The basis coordinates (one dimension) of the method run from x_0 = 1 (xi_0 = u, or
    the fixed-point direction for a free start) on f_j = q_j/2 x^2, q_j strictly inside
    its class (the middle of [m, L], or lo + s/2); None when a prox step is singular."""
    p, s = mt.p, float(mt.s)
    q = []
    for _, cls, params in mt.functions:
        lo, hi = cls.curvatures({k: float(v) for k, v in params.items()}) or (0.0, 0.0)
        q.append((lo + hi) / 2 if hi > lo else lo + s / 2)
    qc = np.array([q[j] for j in mt.oracles])
    col = {name: c for c, name in enumerate(st.basis)}
    v = np.zeros(st.d)
    xi = np.asarray(mt.X0, float).copy()
    v[0] = 1.0
    C, D, A, B, K = (np.asarray(M, float) for M in (mt.C, mt.D, mt.A, mt.B, mt.K))
    for k in range(st.calls):
        try:
            y = np.linalg.solve(np.eye(p) - D * qc, C @ xi)
        except np.linalg.LinAlgError:
            return None
        u = qc * y / s
        for i in range(p):
            c = col.get(f"b_{'y' + str(k) if p == 1 else f'y{i + 1}_{k}'}")
            if c is not None:
                v[c] = u[i] - K[i] @ xi
        xi = A @ xi + s * (B @ u)
    for j, fp in enumerate(st.points):
        for pt in fp:
            if pt.t is None and pt.label != "x*":  # a term's extra point: its gradient
                c = int(np.argmax(np.abs(pt.g)))
                v[c] = q[j] * float(pt.x @ v) / s
    return v


def make_witness(spec: Spec, kappa: float | None, mt: Method, data: PEPData,
                 ans: SDPAnswer, mterms: list[Term], iterms: list[Term],
                 res: Any) -> dict[str, Any] | None:
    """The witness document in the smallest dimension that passes the exact check (its
    ``check``), else the last one tried (not verified), or None when no reduction solves.
    Each candidate: V rounded to binary rationals, the trajectory recomputed exactly,
    then the values fitted exactly (:func:`fit_values`)."""
    from sosalgo.pep.bind import bound_method
    from sosalgo.pep.exact import exact_method

    tau = float(ans.primal)  # type: ignore[arg-type]
    try:
        ex = exact_method(spec, kappa, bound_method(spec, None if spec.sublinear else kappa)[0])
    except (ValueError, ArithmeticError):
        ex = None
    last = None
    for slack, eta in LADDER:
        red = solve_pep(data, objective="trace", floor=(1 - eta) * tau, slack=slack,
                        unit=tau if tau > 1e-200 else 1.0)
        if red.status != "solved":
            continue
        for V, theta in _candidates(mt, data.st, red.G, slack):  # type: ignore[arg-type]
            doc = _document(spec, mt, data.st, V, red.F, res)  # type: ignore[arg-type]
            doc.update(tau_float=tau, objective_floor=1 - eta, slack=slack, mixed=theta)
            if ex is not None and not fit_values(doc, ex):
                last = last or doc
                continue  # no values fit this geometry: the check would fail
            doc["check"] = check_witness(doc, spec, ex)
            last = doc
            if doc["check"]["verified"]:
                return _finish(doc)
    if last is not None and "check" not in last:
        last["check"] = check_witness(last, spec, ex)
    return None if last is None else _finish(last)


def _finish(doc: dict[str, Any]) -> dict[str, Any]:
    if doc["dimension"] == 1:
        doc["interpolant"] = interpolant_1d(doc)
    return doc


def _document(spec: Spec, mt: Method, st: Any, V: np.ndarray, F: np.ndarray,
              res: Any) -> dict[str, Any]:
    """The witness JSON of the factor V (see the module docstring)."""
    s = Fraction(mt.s)
    col = {name: c for c, name in enumerate(st.basis)}
    J = len(mt.functions)
    sstar = []
    for j in range(J - 1):
        c = col.get(f"s*_{mt.functions[j][0]}/s")
        sstar.append([s * Fraction(float(v)) for v in V[c]] if c is not None
                     else [Fraction(0)] * V.shape[1])
    sstar.append([-sum(col_) for col_ in zip(*sstar, strict=True)] if sstar
                 else [Fraction(0)] * V.shape[1])
    funcs: dict[str, Any] = {}
    for j, (name, cls, params) in enumerate(mt.functions):
        pts = []
        for pt in st.points[j][:-1]:
            gt = [s * Fraction(float(v)) for v in pt.g @ V]
            g = [a + b for a, b in zip(gt, sstar[j], strict=True)]
            pts.append({"label": pt.label, "g": list(map(_q, g)),
                        "h": _q(s * Fraction(float(F[pt.f]))), "x": [float(v) for v in pt.x @ V]})
        funcs[name] = {"class": cls.name, "params": {k: float(v) for k, v in params.items()},
                       "optimal_subgradient": list(map(_q, sstar[j])), "points": pts}
    p = mt.p
    calls = []
    for k in range(st.calls):
        row = []
        for i, j in enumerate(mt.oracles):
            u = [s * Fraction(float(v)) for v in st.rows["u"][k][i] @ V]
            row.append([_q(a + b) for a, b in zip(u, sstar[j], strict=True)])
        calls.append(row)
    doc: dict[str, Any] = {}
    if st.basis[0].startswith("xi0_"):  # a free start: xi_0 = xi~_0 + X_s s~ (x* = 0)
        xs = np.asarray(mt.Xs, float) @ np.array([[float(v) for v in r] for r in sstar[:-1]]
                                                 ).reshape(len(sstar) - 1, V.shape[1])
        doc["xi0"] = [_vec(r) for r in st.rows["xi"][0] @ V + xs]
    return doc | {"kind": WITNESS_KIND, "spec": spec.name, "kappa": res.kappa,
            "steps": st.steps, "calls_per_step": p, "call_steps": st.calls,
            "measure": res.measure, "initial": res.initial, "dimension": int(V.shape[1]),
            "x0": _vec(V[0]), "calls": calls, "functions": funcs,
            "evaluations": {f"{key}|{mt.functions[j][0]}": st.points[j][a].label
                            for (key, j), a in st.at.items()},
            "iterates": [[float(v) for v in _out(mt, st, k) @ V]
                         for k in range(st.steps + 1)]}


def _out(mt: Method, st: Any, k: int) -> np.ndarray:
    """The output row at step k (x_k = E xi_k, or the output call's point)."""
    if mt.output is None:
        return (mt.E @ st.rows["xi"][k])[0]
    return st.rows["y"][k][mt.output] if k < len(st.rows["y"]) else st.rows["x"]


def _dot(a: list[Any], b: list[Any]) -> Any:
    return sum((Ball.of(x) * y for x, y in zip(a, b, strict=True)), Ball(0))


def _positions(doc: dict[str, Any], mt: Method) -> dict[str, Any]:
    """Every point of the trajectory, recomputed exactly from the start (xi_0 = u x_0, or
    ``xi0``: a free start, x_0 then the output at step 0) and the calls; ``xi0``, ``xiN``:
    the states at steps 0 and N."""
    r, p, N = int(doc["dimension"]), mt.p, int(doc["steps"])
    if doc.get("xi0") is not None:
        xi = [[Fraction(v) for v in row] for row in doc["xi0"]]
        if len(xi) != mt.n or any(len(row) != r for row in xi):
            raise ValueError(f"xi0: expected {mt.n} states of {r} coordinates")
    else:
        x0 = [Fraction(v) for v in doc["x0"]]
        if len(x0) != r:
            raise ValueError(f"x0: expected {r} coordinates")
        xi = [[mt.X0[a] * x0[c] for c in range(r)] for a in range(mt.n)]
    pos: dict[str, Any] = {"xi0": xi}
    for k in range(int(doc["call_steps"])):
        u = [[Fraction(v) for v in doc["calls"][k][i]] for i in range(p)]
        if any(len(ui) != r for ui in u):
            raise ValueError(f"calls[{k}]: expected {r} coordinates")
        for i in range(p):
            y = [_dot(list(mt.C[i]), [xi[a][c] for a in range(mt.n)])
                 + _dot(list(mt.D[i]), [u[b][c] for b in range(p)]) for c in range(r)]
            pos[f"y{k}" if p == 1 else f"y{i + 1}_{k}"] = y
        if k == N:
            continue
        xi = [[_dot(list(mt.A[a]), [xi[b][c] for b in range(mt.n)])
               + _dot(list(mt.B[a]), [u[b][c] for b in range(p)]) for c in range(r)]
              for a in range(mt.n)]
    pos["xiN"] = xi
    for k, key in ((N, f"x{N}"), (0, "x0")):
        if key == "x0" and doc.get("xi0") is None:
            pos["x0"] = [Fraction(v) for v in doc["x0"]]
        elif mt.output is None:
            st = pos["xiN"] if k == N else pos["xi0"]
            pos[key] = [_dot(list(mt.E[0]), [st[a][c] for a in range(mt.n)])
                        for c in range(r)]
        else:
            pos[key] = pos[f"y{k}" if p == 1 else f"y{mt.output + 1}_{k}"]
    for i in range(p):
        pos.setdefault(f"y{i + 1}_{N}", pos.get(f"y{N}" if p == 1 else f"y{i + 1}_{N}"))
    return pos


def _pair_forms(mt: Method, doc: dict[str, Any], pos: dict[str, Any]):
    """Per function j: (labels, [(a, b, alpha, q)]) with q = X' Q X the quadratic part of
    each tilted class inequality alpha (h_a - h_b) + q >= 0 of each ordered pair (x* last,
    g = s_j*, h = 0), in ball arithmetic."""
    out = []
    for j, (name, _, _) in enumerate(mt.functions):
        fd = doc["functions"][name]
        sj = [Fraction(v) for v in fd["optimal_subgradient"]]
        pts = [(pos[pt["label"]], [Fraction(g) - s for g, s in zip(pt["g"], sj, strict=True)])
               for pt in fd["points"]]
        zero = [Fraction(0)] * len(sj)
        pts.append((zero, zero))
        vecs = [v for pt in pts for v in pt]  # x_0, g_0, x_1, g_1, ...
        gram: dict[tuple[int, int], Any] = {}
        for u in range(len(vecs)):
            for v in range(u, len(vecs)):
                gram[u, v] = gram[v, u] = _dot(vecs[u], vecs[v])
        rows = []
        for a in range(len(pts)):
            for b in range(len(pts)):
                if a == b:
                    continue
                idx = [2 * a, 2 * b, 2 * a + 1, 2 * b + 1]  # x_a, x_b, g_a, g_b
                for alpha, Q in mt.ineqs[j]:
                    q = Ball(0)
                    for u in range(4):
                        for v in range(4):
                            if Q[u, v].c != 0 or Q[u, v].r != 0:
                                q = q + Q[u, v] * gram[idx[u], idx[v]]
                    rows.append((a, b, Ball.of(alpha), q))
        out.append(([pt["label"] for pt in fd["points"]] + ["x*"], rows))
    return out


def _pairs_ok(mt: Method, doc: dict[str, Any], pos: dict[str, Any]) -> tuple[int, int]:
    """(pairs checked, pairs violated): every tilted class inequality, ball lower ends."""
    checked = bad = 0
    for (name, _, _), (_, rows) in zip(mt.functions, _pair_forms(mt, doc, pos),
                                       strict=True):
        h = [Fraction(pt["h"]) for pt in doc["functions"][name]["points"]] + [Fraction(0)]
        for a, b, alpha, q in rows:
            checked += 1
            bad += (alpha * (h[a] - h[b]) + q).lo < 0
    return checked, bad


def _edge(alpha: Ball, q: Ball) -> tuple[bool, Fraction] | None:
    """alpha (h_a - h_b) + q >= 0 for every alpha, q in their balls as one difference
    constraint: (forward, w) meaning h_b <= h_a + w (forward) or h_a <= h_b + w; None
    when alpha may vanish (then q >= 0 is needed, not a constraint on h)."""
    if alpha.lo > 0:
        return True, q.lo / (alpha.hi if q.lo >= 0 else alpha.lo)
    if alpha.hi < 0:
        return False, q.lo / (-alpha.lo if q.lo >= 0 else -alpha.hi)
    return None


def _round_down(w: Fraction, bits: int = 64) -> Fraction:
    """A binary rational <= w with about ``bits`` significant bits."""
    if w == 0:
        return w
    e = w.numerator.bit_length() - w.denominator.bit_length() - bits
    return Fraction(math.floor(w / Fraction(2) ** e)) * Fraction(2) ** e


def fit_values(doc: dict[str, Any], mt: Method) -> bool:
    """Replace the rounded values h of every function by exact ones that satisfy every
    class inequality at the exactly recomputed points: the inequalities are difference
    constraints h_b <= h_a + w_ab (w rounded down), and the shortest paths from x*
    (h = 0) give the largest such values (Bellman-Ford). False (doc unchanged) when
    they have no solution (a negative cycle) or a pair needs q >= 0 that fails."""
    try:
        pos = _positions(doc, mt)
        forms = _pair_forms(mt, doc, pos)
    except (KeyError, ValueError, TypeError, IndexError, ArithmeticError):
        return False
    new = []
    for labels, rows in forms:
        V, src = len(labels), len(labels) - 1
        edges = []
        for a, b, alpha, q in rows:
            e = _edge(alpha, q)
            if e is None:
                if q.lo < 0:
                    return False
                continue
            fwd, w = e
            edges.append((a, b, _round_down(w)) if fwd else (b, a, _round_down(w)))
        dist: list[Fraction | None] = [None] * V
        dist[src] = Fraction(0)
        for _ in range(V):
            changed = False
            for u, v, w in edges:
                if dist[u] is not None and (dist[v] is None or dist[u] + w < dist[v]):
                    dist[v] = dist[u] + w
                    changed = True
            if not changed:
                break
        if changed or dist[src] != 0:
            return False
        new.append(dist)
    for (name, _, _), dist in zip(mt.functions, new, strict=True):
        for pt, h in zip(doc["functions"][name]["points"], dist, strict=False):
            if h is not None:
                pt["h"] = _q(h)
    return True


def _sdist(mt: Method, doc: dict[str, Any], xi: list[list[Any]]) -> Any:
    """|xi - xi*|^2 over every state block, xi* = u x* + X_s s~ (x* = 0)."""
    sst = [[Fraction(v) for v in doc["functions"][name]["optimal_subgradient"]]
           for name, _, _ in mt.functions[:-1]]
    total = Ball(0)
    for a in range(mt.n):
        star = [_dot([mt.Xs[a, j] for j in range(len(sst))], [s[c] for s in sst])
                for c in range(len(xi[a]))]
        diff = [x - y for x, y in zip(xi[a], star, strict=True)]
        total = total + _dot(diff, diff)
    return total


def _terms_value(terms: list[Term], mt: Method, doc: dict[str, Any],
                 pos: dict[str, Any]) -> Any:
    N = int(doc["steps"])
    total = Ball(0)
    for t in terms:
        if t.kind == "sdist":
            total = total + mt.coef(t) * _sdist(mt, doc, pos["xi0" if t.point == "x0"
                                                           else "xiN"])
            continue
        key = {"x": f"x{N}", "x0": "x0"}.get(t.point) or pos_key(t.point, N, mt.p)
        P = pos[key]
        if t.kind == "dist":
            total = total + mt.coef(t) * _dot(P, P)
            continue
        funcs = (range(len(mt.functions)) if t.kind == "f" else
                 [j for j, f in enumerate(mt.functions) if "gradient" in f[1].oracles])
        acc: Any = Ball(0) if t.kind == "f" else [Ball(0)] * len(P)
        for j in funcs:
            name = mt.functions[j][0]
            label = doc["evaluations"][f"{t.point}|{name}"]
            pt = next(q for q in doc["functions"][name]["points"] if q["label"] == label)
            if pos[label] is not P and any(Ball.of(a - b).c != 0 or Ball.of(a - b).r != 0
                                           for a, b in zip(pos[label], P, strict=True)):
                raise ValueError(f"{name} at {label} is not provably the point {key}")
            if t.kind == "f":
                acc = acc + Fraction(pt["h"])
            else:
                acc = [a + Fraction(g) for a, g in zip(acc, pt["g"], strict=True)]
        total = total + mt.coef(t) * (acc if t.kind == "f" else _dot(acc, acc))
    return total


def pos_key(point: str, N: int, p: int) -> str:
    """The position key of a term point y<i> at step N."""
    return f"y{N}" if p == 1 else f"{point}_{N}"


def check_witness(doc: dict[str, Any], spec: Spec, mt: Method | None = None) -> dict[str, Any]:
    """Check a witness exactly against ``spec`` (see the module; ``mt``: its exact method,
    built here when not given); never raises on a bad witness: ``verified`` False with
    the reason."""
    from sosalgo.pep.bind import bound_method
    from sosalgo.pep.exact import exact_method
    from sosalgo.pep.terms import parse_terms

    t0 = time.perf_counter()
    out: dict[str, Any] = {"verified": False, "check_kind": "exact (rational and ball "
                           "arithmetic)", "tau_lower": None, "tau_lower_float": None}
    try:
        kappa = doc.get("kappa")
        om, _ = bound_method(spec, None if spec.sublinear else kappa)
        mt = mt if mt is not None else exact_method(spec, kappa, om)
        mterms = parse_terms(doc["measure"], "measure", False, om.p)
        iterms = parse_terms(doc["initial"], "initial", True, om.p)
        if any(t.kind == "sdist" for t in iterms) != (doc.get("xi0") is not None):
            raise ValueError("an initial sdist needs the free start xi0, and only it")
        pos = _positions(doc, mt)
        checked, bad = _pairs_ok(mt, doc, pos)
        ssum = [sum(Fraction(v[c]) for v in (f["optimal_subgradient"] for f in
                                              doc["functions"].values()))
                for c in range(int(doc["dimension"]))]
        meas = _terms_value(mterms, mt, doc, pos)
        init = _terms_value(iterms, mt, doc, pos)
    except (KeyError, ValueError, TypeError, IndexError, ZeroDivisionError, StopIteration,
            ArithmeticError) as exc:
        return out | {"detail": f"malformed or inconsistent witness: {type(exc).__name__}: "
                                f"{exc}", "seconds": time.perf_counter() - t0}
    out["pairs_checked"] = checked
    if bad or any(ssum) or init.hi <= 0 or meas.lo < 0:
        why = (f"{bad} interpolation inequalities not proven" if bad else
               "the optimal subgradients do not sum to 0" if any(ssum) else
               "the initial condition is not positive" if init.hi <= 0 else "measure < 0")
        return out | {"detail": why, "seconds": time.perf_counter() - t0}
    lower = meas.lo / init.hi
    return out | {"verified": True, "tau_lower": _q(lower), "tau_lower_float": float(lower),
                  "detail": f"{checked} inequalities proven; the trajectory recomputed from "
                            "the start and the calls", "seconds": time.perf_counter() - t0}


def interpolant_1d(doc: dict[str, Any]) -> dict[str, Any]:
    """For r = 1: each function as the smallest convex piecewise quadratic through its
    points of its smooth class, max_a h_a + g_a (x - x_a) + (m/2)(x - x_a)^2 ... drawn
    on a grid; values are tilted (h_j, minimal 0 at x* = 0)."""
    out: dict[str, Any] = {}
    for name, fd in doc["functions"].items():
        s = float(Fraction(fd["optimal_subgradient"][0]))
        pts = [(float(np.mean(p["x"])), float(Fraction(p["g"][0])) - s,
                float(Fraction(p["h"]))) for p in fd["points"]] + [(0.0, 0.0, 0.0)]
        m = float(fd["params"].get("m", 0.0))
        L = fd["params"].get("L")
        xs = np.linspace(min(p[0] for p in pts) - 0.2, max(p[0] for p in pts) + 0.2, 201)
        lo = np.max([h + g * (xs - x) + 0.5 * m * (xs - x) ** 2 for x, g, h in pts], axis=0)
        if L is not None:  # smooth: the Moreau-type upper interpolant of the lower one
            from scipy.ndimage import minimum_filter1d  # noqa: F401  (cheap, always present)

            up = np.min([h + g * (xs - x) + 0.5 * float(L) * (xs - x) ** 2
                         for x, g, h in pts], axis=0)
            lo = np.minimum(np.maximum(lo, 0.0), np.maximum(up, lo))
        out[name] = {"x": xs.tolist(), "h": lo.tolist(),
                     "points": [[p[0], p[2]] for p in pts]}
    return out
