"""The worst case itself: a low-dimensional trajectory and functions that attain tau_N,
written as JSON and checked exactly (a theorem: tau_N >= its value).

Construction: the PEP again, minimizing tr G (a rank heuristic) with the measure at least
(1 - eta) tau_N and every interpolation inequality at least ``SLACK`` (scaled rows), so
that rounding cannot break them; G = V V' keeps the fewest eigenvalues whose dropped sum
is below SLACK / 10. Row c of V is basis vector c in R^r: x_0 - x* (x* = 0), the optimal
subgradients and every oracle answer, all exact binary rationals.

Document (``kind: pep-witness``): ``x0``; ``calls`` (the gradient u_{k,i} of every call,
actual, not tilted); per function its class, optimal subgradient s_j* (summing to 0) and
points: ``at`` (where: ``y<i>_<k>``, ``x_0``, ``x_N``), the subgradient g there and the
tilted value h = f_j(x) - f_j(x*) - <s_j*, x - x*>; ``evaluations``: which point of each
function a term reads. Numbers are exact rationals as strings ("p/q").

The check (:func:`check_witness`) trusts nothing but the spec: it recomputes the
trajectory from xi_0 = u x_0 with the exact method (balls, :mod:`sosalgo.pep.exact`),
checks every class inequality of every ordered pair of each function's points (x* with
g = s_j*, h = 0) on the tilted data (g - s_j*, h) with ball arithmetic (lower end >= 0),
sum_j s_j* = 0, and evaluates measure and initial exactly: tau_N >= measure / initial.
"""

from __future__ import annotations

import time
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.pep.sdp import PEPData, SDPAnswer, solve_pep
from sosalgo.pep.structure import Method
from sosalgo.pep.terms import Term
from sosalgo.spec import Spec

__all__ = ["WITNESS_KIND", "check_witness", "make_witness"]

WITNESS_KIND = "pep-witness"
SLACKS = (1e-7, 1e-8, 1e-9)  # inequality slack of the reduced solve (scaled rows)
ETAS = (1e-6, 1e-5)  # the measure kept at (1 - eta) tau_N
MAX_TRIES = 3  # dimensions tried per reduced solve


def _q(x: float | Fraction) -> str:
    f = Fraction(x)
    return f"{f.numerator}/{f.denominator}" if f.denominator != 1 else str(f.numerator)


def _vec(v: np.ndarray) -> list[str]:
    return [_q(float(t)) for t in v]


def _factors(G: np.ndarray, slack: float) -> list[np.ndarray]:
    """V (d x r) with G ~ V V' for r = 1, 2, ... up to the r whose dropped eigenvalues sum
    below slack / 10 (at most MAX_TRIES of them)."""
    e, V = np.linalg.eigh(0.5 * (G + G.T))
    e, V = e[::-1].clip(min=0.0), V[:, ::-1]
    out = []
    for r in range(1, len(e) + 1):
        out.append(V[:, :r] * np.sqrt(e[:r]))
        if e[r:].sum() <= slack / 10 or len(out) == MAX_TRIES:
            break
    return out


def make_witness(spec: Spec, kappa: float | None, mt: Method, data: PEPData,
                 ans: SDPAnswer, mterms: list[Term], iterms: list[Term],
                 res: Any) -> dict[str, Any] | None:
    """The witness document in the smallest dimension that passes the exact check (its
    ``check``), else the last one tried (not verified), or None when no reduction solves."""
    tau = float(ans.primal)  # type: ignore[arg-type]
    last = None
    for slack in SLACKS:
        for eta in ETAS:
            red = solve_pep(data, objective="trace", floor=(1 - eta) * tau, slack=slack,
                            unit=tau if tau > 1e-200 else 1.0)
            if red.status != "solved":
                continue
            for V in _factors(red.G, slack):  # type: ignore[arg-type]
                doc = _document(spec, mt, data.st, V, red.F, res)  # type: ignore[arg-type]
                doc.update(tau_float=tau, objective_floor=1 - eta, slack=slack)
                doc["check"] = check_witness(doc, spec)
                last = doc
                if doc["check"]["verified"]:
                    return _finish(doc)
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
            u = [s * Fraction(float(v)) for v in _ucol(st, k, i, p) @ V]
            row.append([_q(a + b) for a, b in zip(u, sstar[j], strict=True)])
        calls.append(row)
    return {"kind": WITNESS_KIND, "spec": spec.name, "kappa": res.kappa, "steps": st.steps,
            "calls_per_step": p, "call_steps": st.calls, "measure": res.measure,
            "initial": res.initial, "dimension": int(V.shape[1]), "x0": _vec(V[0]),
            "calls": calls, "functions": funcs,
            "evaluations": {f"{key}|{mt.functions[j][0]}": st.points[j][a].label
                            for (key, j), a in st.at.items()},
            "iterates": [[float(v) for v in _out(mt, st, k) @ V]
                         for k in range(st.steps + 1)]}


def _ucol(st: Any, k: int, i: int, p: int) -> np.ndarray:
    lab = f"u_{'y' + str(k) if p == 1 else f'y{i + 1}_{k}'}/s"
    c = st.basis.index(lab)
    out = np.zeros(st.d)
    out[c] = 1.0
    return out


def _out(mt: Method, st: Any, k: int) -> np.ndarray:
    """The output row at step k (x_k = E xi_k, or the output call's point)."""
    if mt.output is None:
        return (mt.E @ st.rows["xi"][k])[0]
    return st.rows["y"][k][mt.output] if k < len(st.rows["y"]) else st.rows["x"]


def _dot(a: list[Any], b: list[Any]) -> Any:
    from sosalgo.verify.exact import Ball

    return sum((Ball.of(x) * y for x, y in zip(a, b, strict=True)), Ball(0))


def _positions(doc: dict[str, Any], mt: Method) -> dict[str, list[Any]]:
    """Every point of the trajectory, recomputed exactly from x_0 and the calls."""
    x0 = [Fraction(v) for v in doc["x0"]]
    r, p, N = len(x0), mt.p, int(doc["steps"])
    xi = [[mt.X0[a] * x0[c] for c in range(r)] for a in range(mt.n)]
    pos: dict[str, list[Any]] = {"x0": x0}
    for k in range(int(doc["call_steps"])):
        u = [[Fraction(v) for v in doc["calls"][k][i]] for i in range(p)]
        if len(u[0]) != r:
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
    if mt.output is None:
        pos[f"x{N}"] = [_dot(list(mt.E[0]), [xi[a][c] for a in range(mt.n)])
                        for c in range(r)]
    else:
        o = mt.output
        pos[f"x{N}"] = pos[f"y{N}" if p == 1 else f"y{o + 1}_{N}"]
    for i in range(p):
        pos.setdefault(f"y{i + 1}_{N}", pos.get(f"y{N}" if p == 1 else f"y{i + 1}_{N}"))
    return pos


def _pairs_ok(mt: Method, doc: dict[str, Any], pos: dict[str, list[Any]]) -> tuple[int, int]:
    """(pairs checked, pairs violated): every tilted class inequality, ball lower ends."""
    checked = bad = 0
    for j, (name, _, _) in enumerate(mt.functions):
        fd = doc["functions"][name]
        sj = [Fraction(v) for v in fd["optimal_subgradient"]]
        pts = [(pos[pt["label"]], [Fraction(g) - s for g, s in zip(pt["g"], sj, strict=True)],
                Fraction(pt["h"])) for pt in fd["points"]]
        zero = [Fraction(0)] * len(sj)
        pts.append((zero, zero, Fraction(0)))
        for a, (xa, ga, ha) in enumerate(pts):
            for b, (xb, gb, hb) in enumerate(pts):
                if a == b:
                    continue
                X = [xa, xb, ga, gb]
                for alpha, Q in mt.ineqs[j]:
                    val = alpha * (ha - hb)
                    for u in range(4):
                        for v in range(4):
                            if Q[u, v].c != 0 or Q[u, v].r != 0:
                                val = val + Q[u, v] * _dot(X[u], X[v])
                    checked += 1
                    bad += val.lo < 0
    return checked, bad


def _terms_value(terms: list[Term], mt: Method, doc: dict[str, Any],
                 pos: dict[str, list[Any]]) -> Any:
    from sosalgo.verify.exact import Ball

    N = int(doc["steps"])
    total = Ball(0)
    for t in terms:
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


def check_witness(doc: dict[str, Any], spec: Spec) -> dict[str, Any]:
    """Check a witness exactly against ``spec`` (see the module); never raises on a bad
    witness: ``verified`` False with the reason."""
    from sosalgo.pep.bind import bound_method
    from sosalgo.pep.exact import exact_method
    from sosalgo.pep.terms import parse_terms

    t0 = time.perf_counter()
    out: dict[str, Any] = {"verified": False, "check_kind": "exact (rational and ball "
                           "arithmetic)", "tau_lower": None, "tau_lower_float": None}
    try:
        kappa = doc.get("kappa")
        om, _ = bound_method(spec, None if spec.sublinear else kappa)
        mt = exact_method(spec, kappa, om)
        mterms = parse_terms(doc["measure"], "measure", False, om.p)
        iterms = parse_terms(doc["initial"], "initial", True, om.p)
        pos = _positions(doc, mt)
        checked, bad = _pairs_ok(mt, doc, pos)
        ssum = [sum(Fraction(v[c]) for v in (f["optimal_subgradient"] for f in
                                              doc["functions"].values()))
                for c in range(len(doc["x0"]))]
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
                            "x_0 and the calls", "seconds": time.perf_counter() - t0}


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
