"""The exact check of a PEP witness (:func:`check_witness`) and the exact fit of its
function values (:func:`fit_values`), in ball arithmetic: python-flint's ``arb``
(outward rounded, :data:`PREC` bits) around the exact rationals of the document and the
exact method of :func:`sosalgo.worstcase.exact.exact_method` (its rational balls enclosed
outward). A claim holds only when every ball says so (``x >= 0`` of an ``arb`` is true
only for the whole ball).

The check trusts nothing but the spec: it recomputes the trajectory from xi_0 = u x_0
(or ``xi0``) and the calls (xi_{k+1} = A xi_k + B u_k, y_k = C xi_k + D u_k), checks
every class inequality of every ordered pair of each function's points (x* = 0 with
g = s_j*, h = 0) on the tilted data (g - s_j*, h), sum_j s_j* = 0, and evaluates measure
and initial: tau_N >= measure / initial (the lower end over the upper end).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from flint import arb, arb_mat, fmpq

from sosalgo.kernel.arb import arb_fraction, precision
from sosalgo.kernel.exact import Ball
from sosalgo.oracles import BoundFunction, Method
from sosalgo.spec import Spec
from sosalgo.steps import changes_with_k
from sosalgo.worstcase.exact import ball, exact_method, exact_steps_or_none
from sosalgo.worstcase.structure import PEPFrame, anchor_label, last_calls, method_field
from sosalgo.worstcase.terms import OUT0, Term, free_start

__all__ = ["PREC", "ArbView", "arb_view", "check_witness", "fit_values", "member_interval",
           "member_measure", "pair_forms", "positions", "q_str"]

PREC = 384  # bits: far below every slack a witness keeps, and cheap


def q_str(x: float | Fraction) -> str:
    """An exact rational as ``p/q`` (an integer alone)."""
    f = Fraction(x)
    return f"{f.numerator}/{f.denominator}" if f.denominator != 1 else str(f.numerator)


def _mat(rows: Any) -> arb_mat:
    rows = [[ball(v) for v in row] for row in rows]
    return arb_mat(len(rows), len(rows[0]) if rows else 0, [v for r in rows for v in r])


@dataclass
class ArbView:
    """An exact :class:`PEPFrame` ``mt`` in arb balls: its method as the one
    :class:`sosalgo.oracles.Method` over arb (``method``; ``A``, ``B``, ``C``, ``D``,
    ``E`` read from it), the frame's X0 (n x 1), Xs (n x J-1) and class inequalities
    (alpha, 4 x 4 Q) per function. Not a method type: the PEP's data in another number
    type."""

    A = method_field("A")
    B = method_field("B")
    C = method_field("C")
    D = method_field("D")
    E = method_field("E")

    mt: PEPFrame
    method: Method
    X0: arb_mat
    Xs: list[list[arb]]
    ineqs: list[list[tuple[arb, list[list[arb]]]]]
    G0: arb_mat | None = None  # ``initial_state``: xi_0 = X0 x_0 + G0 g0
    per_step: list[tuple[arb_mat, arb_mat, arb_mat, arb_mat]] | None = None  # changes with k

    def coef(self, t: Term) -> arb:
        return ball(self.mt.coef(t))

    def step(self, k: int) -> tuple[arb_mat, arb_mat, arb_mat, arb_mat]:
        """(A, B, C, D) of step k (:meth:`sosalgo.worstcase.structure.PEPFrame.step`)."""
        if self.per_step is None:
            return self.A, self.B, self.C, self.D
        if k >= len(self.per_step):
            raise ValueError(f"the method's matrices stop before step {k}")
        return self.per_step[k]


def arb_view(mt: PEPFrame) -> ArbView:
    """The arb form of an exact frame (at :data:`PREC` bits)."""
    with precision(PREC):
        ineqs = [[(ball(a), [[ball(v) for v in row] for row in Q]) for a, Q in fi]
                 for fi in mt.ineqs]
        per = None if mt.per_step is None else [tuple(_mat(M) for M in mats)
                                                 for mats in mt.per_step]
        return ArbView(mt, _arb_method(mt.method), _mat([[v] for v in mt.X0]),
                       [[ball(v) for v in row] for row in mt.Xs], ineqs,
                       None if mt.G0 is None else _mat([[v] for v in mt.G0]),
                       per)  # type: ignore[arg-type]


def _arb_method(method: Method) -> Method:
    """The exact ``method`` (balls) over arb: matrices, m, L and class parameters."""
    return Method(_mat(method.A), _mat(method.B), _mat(method.C), _mat(method.D),
                  None if method.E is None else _mat(method.E), ball(method.m),
                  ball(method.L), tuple(BoundFunction(fn.name, fn.cls, {
                      k: ball(v) for k, v in fn.params.items()}) for fn in method.functions),
                  method.oracles, method.output, method.measure, numbers="arb")


def _label(i: int, k: int, p: int) -> str:
    return f"y{k}" if p == 1 else f"y{i + 1}_{k}"


def _start(doc: dict[str, Any], av: ArbView, r: int) -> arb_mat:
    n = av.mt.n
    if doc.get("xi0") is not None:
        xi = doc["xi0"]
        if len(xi) != n or any(len(row) != r for row in xi):
            raise ValueError(f"xi0: expected {n} states of {r} coordinates")
        return _mat(xi)
    if len(doc["x0"]) != r:
        raise ValueError(f"x0: expected {r} coordinates")
    xi = av.X0 * _mat([doc["x0"]])
    if av.G0 is None:
        return xi
    name = av.mt.functions[av.mt.smooth][0]  # initial_state: + G0 g0, g0 its gradient at x0
    g0 = next(pt["g"] for pt in doc["functions"][name]["points"] if pt["label"] == "x0")
    if len(g0) != r:
        raise ValueError(f"{name} at x0: expected {r} coordinates")
    return xi + av.G0 * _mat([g0])


def _previous_call(mt: PEPFrame, av: ArbView) -> int | None:
    """The call whose point at step k - 1 is x_k exactly (:attr:`PEPFrame.prev_call`), for
    a method with the same matrices at every step and no line search."""
    if av.per_step is not None or mt.line_search:
        return None
    return mt.prev_call


def positions(doc: dict[str, Any], av: ArbView) -> dict[str, Any]:
    """Every point of the trajectory (a list of r balls), recomputed from the start and
    the calls; ``xi0``, ``xiN``: the states (arb_mat, n x r) at steps 0 and N."""
    mt = av.mt
    r, p, N = int(doc["dimension"]), mt.p, int(doc["steps"])
    xi = _start(doc, av, r)
    pos: dict[str, Any] = {"xi0": xi}
    start = None  # the call at x_0 exactly (:attr:`PEPFrame.x0_call`): the very same balls
    if doc.get("xi0") is None and av.G0 is None and mt.x0_call is not None:
        start = mt.x0_call
        pos["x0"] = [ball(v) for v in doc["x0"]]
    states = [xi]
    for k in range(int(doc["call_steps"])):
        rows = doc["calls"][k]
        if len(rows) != p or any(len(ui) != r for ui in rows):
            raise ValueError(f"calls[{k}]: expected {p} gradients of {r} coordinates")
        u = _mat(rows)
        A, B, C, D = av.step(k)
        y = C * xi + D * u
        for i in range(p):
            pos[_label(i, k, p)] = (pos["x0"] if k == 0 and i == start
                                    else [y[i, c] for c in range(r)])
        if k < N:
            xi = A * xi + B * u if not mt.line_search else xi + _ls_step(doc, k) * u
            states.append(xi)
    pos["xiN"] = xi
    call = mt.output if mt.output is not None else mt.out_call  # x_k is that call's point
    for k in [N, 0, *range(1, N)]:
        key = f"x{k}"
        if k >= 1 and mt.output is not None and last_calls(mt):  # step k - 1's call
            pos[key] = pos[_label(mt.output, k - 1, p)]
        elif key == "x0" and doc.get("xi0") is None:
            pos.setdefault("x0", [ball(v) for v in doc["x0"]])
        elif call is not None and _label(call, k, p) in pos:
            pos[key] = pos[_label(call, k, p)]
        elif k >= 1 and _previous_call(mt, av) is not None:  # the same point, proven
            pos[key] = pos[_label(_previous_call(mt, av), k - 1, p)]
        elif mt.output is None:
            row = av.E * states[k]  # type: ignore[operator]
            pos[key] = [row[0, c] for c in range(r)]
        elif _label(mt.output, k, p) in pos:
            pos[key] = pos[_label(mt.output, k, p)]
    # the output at step 0 (x_N-j at N = j): the start, or the output call's point there
    if last_calls(mt):  # x_0, the start
        pos[OUT0] = pos.get("x0")
    elif call is not None:
        pos[OUT0] = pos.get(_label(call, 0, p))
    else:  # E xi_0 (x_0 at rest; an initial_state may move it)
        row0 = av.E * states[0]  # type: ignore[operator]
        pos[OUT0] = [row0[0, c] for c in range(r)]
    for i in range(p):
        pos.setdefault(f"y{i + 1}_{N}", pos.get(_label(i, N, p)))
    for name, cls, _ in mt.functions:  # each origin o: where the witness puts it
        if cls.anchored:
            pt = next(q for q in doc["functions"][name]["points"]
                      if q["label"] == anchor_label(name))
            pos[pt["label"]] = _anchor_position(pt)
    if last_calls(mt):  # the y terms after N steps: the calls of step N - 1
        for i in range(p):
            pos[f"y{i + 1}_{N}"] = pos[_label(i, N - 1, p)]
            if p == 1:
                pos.setdefault(f"y{N}", pos[_label(i, N - 1, p)])
    return pos


def _ls_step(doc: dict[str, Any], k: int) -> arb:
    """The step t_k of a line search witness (x_{k+1} = x_k + t_k d_k), exactly: the
    line search is proven by <g_{k+1}, d_k> = 0
    (:func:`sosalgo.worstcase.call_checks.call_checks`)."""
    steps = doc["line_search_steps"]
    if not isinstance(steps, list) or len(steps) != int(doc["steps"]):
        raise ValueError("line_search_steps: expected one step per iteration")
    return ball(steps[k])


def _q_mat(rows: Any) -> np.ndarray:
    return np.array([[Fraction(v) for v in row] for row in rows], dtype=object)


def exact_points(doc: dict[str, Any], mt: PEPFrame) -> tuple[dict[str, list[Any]],
                                                            list[list[Any]]]:
    """(every point by label, the iterates x_0..x_N) as exact rationals (Fraction) or
    rational balls (:class:`~sosalgo.kernel.exact.Ball`, when the method has irrational
    entries), recomputed from the start and the calls as :func:`positions` does, in
    exact arithmetic instead of arb."""
    from sosalgo.worstcase.structure import coarsen

    def shorter(v: Any) -> Any:  # a ball's long centre rounded outward; rationals stay
        return coarsen(v, mt.bits) if getattr(v, "r", 0) else v

    p, N = mt.p, int(doc["steps"])
    if doc.get("xi0") is not None:
        xi = _q_mat(doc["xi0"])
    else:
        xi = np.outer(mt.X0, [Fraction(v) for v in doc["x0"]])
        if mt.G0 is not None:
            name = mt.functions[mt.smooth][0]
            g0 = next(pt["g"] for pt in doc["functions"][name]["points"]
                      if pt["label"] == "x0")
            xi = xi + np.outer(mt.G0, [Fraction(v) for v in g0])
    start = (mt.x0_call if doc.get("xi0") is None and mt.G0 is None else None)
    pts: dict[str, list[Any]] = {}
    states = [xi]
    for k in range(int(doc["call_steps"])):
        u = _q_mat(doc["calls"][k])
        A, B, C, D = mt.step(k)
        y = C.dot(xi) + D.dot(u)
        for i in range(p):
            pts[_label(i, k, p)] = ([Fraction(v) for v in doc["x0"]] if k == 0 and i == start
                                    else list(y[i]))
        if k < N:
            nxt = (A.dot(xi) + B.dot(u) if not mt.line_search
                   else xi + Fraction(doc["line_search_steps"][k]) * u)
            xi = np.vectorize(shorter, otypes=[object])(nxt)
            states.append(xi)
    x0 = [Fraction(v) for v in doc["x0"]] if doc.get("xi0") is None else None
    its = []  # x_k as the float ``iterates``: the output call's point, else E xi_k
    for k in range(N + 1):
        if mt.output is not None and last_calls(mt):  # step k - 1's call (x_0: the start)
            its.append(pts[_label(mt.output, k - 1, p)] if k else
                       (x0 if x0 is not None else list(mt.E.dot(states[0])[0])))
        elif mt.output is not None:
            its.append(pts[_label(mt.output, k, p)])
        elif k == 0 and x0 is not None and mt.G0 is None:
            its.append(x0)  # E X0 = 1, E Xs = 0 exactly
        elif mt.out_call is not None and _label(mt.out_call, k, p) in pts:
            its.append(pts[_label(mt.out_call, k, p)])
        else:
            its.append(list(mt.E.dot(states[k])[0]))
    pts["x0"] = x0 if x0 is not None else its[0]
    pts[f"x{N}"] = its[N]
    for i in range(p):
        if _label(i, N, p) in pts:
            pts.setdefault(f"y{i + 1}_{N}", pts[_label(i, N, p)])
        elif last_calls(mt):
            pts.setdefault(f"y{i + 1}_{N}", pts[_label(i, N - 1, p)])
    return pts, its


def exact_str(v: Any) -> str | list[str]:
    """An exact coordinate: ``p/q``, or ``[lo, hi]`` (rational strings) for a ball."""
    if hasattr(v, "c"):
        if not v.r:
            return q_str(v.c)
        return [q_str(v.c - v.r), q_str(v.c + v.r)]
    return q_str(v)


def pair_forms(doc: dict[str, Any], av: ArbView, pos: dict[str, Any]
               ) -> list[tuple[list[str], list[tuple[int, int, arb, arb]]]]:
    """Per function: (labels, [(a, b, alpha, q)]) with q = X' Q X the quadratic part of
    each tilted class inequality alpha (h_a - h_b) + q >= 0 of each ordered pair (x*
    last, g = s_j*, h = 0; not for a nonconvex class, whose PEP has no x*)."""
    out = []
    for j, (name, cls, _) in enumerate(av.mt.functions):
        fd = doc["functions"][name]
        if cls.anchored:  # an equality: in rationals
            out.append(_anchored_forms(doc, av, j, pos))
            continue
        sj = [ball(v) for v in fd["optimal_subgradient"]]
        r = len(sj)
        vecs = []
        for pt in fd["points"]:
            x = pos[pt["label"]]
            if len(x) != r or len(pt["g"]) != r:
                raise ValueError(f"{name} at {pt['label']}: expected {r} coordinates")
            vecs += [x, [ball(g) - s for g, s in zip(pt["g"], sj, strict=True)]]
        vecs += [[arb(0)] * r, [arb(0)] * r]  # x*: point 0, tilted subgradient 0
        Vm = arb_mat(len(vecs), r, [v for row in vecs for v in row])
        gram = Vm * Vm.transpose()
        npts = len(vecs) // 2
        rows = []
        # a nonconvex class: no x* in its PEP (unless the class assumes a minimizer)
        ends = npts if cls.convex or cls.minimizer else npts - 1
        for a in range(ends):
            for b in range(ends):
                if a == b:
                    continue
                idx = (2 * a, 2 * b, 2 * a + 1, 2 * b + 1)  # x_a, x_b, g_a, g_b
                for r, (alpha, Q) in enumerate(av.ineqs[j]):
                    if av.mt.scope(j, r) == "optimum" and b != npts - 1:
                        continue  # a condition between a point and x* only
                    q = ball(av.mt.constant(j, r))
                    for u in range(4):
                        for v in range(4):
                            if not Q[u][v].is_zero():
                                q += Q[u][v] * gram[idx[u], idx[v]]
                    rows.append((a, b, alpha, q))
        out.append(([pt["label"] for pt in fd["points"]] + ["x*"], rows))
    return out


def _anchored_forms(doc: dict[str, Any], av: ArbView, j: int, pos: dict[str, Any]
                    ) -> tuple[list[str], list[tuple[int, int, Fraction, Fraction]]]:
    """:func:`pair_forms` of an anchored class's function, in rationals (its conditions
    with the origin o are equalities, which balls cannot prove): the rows of every
    inequality, "anchor" ones with b = o only, and h_o - h* >= 0, h* - h_o >= 0 (o has
    the value of x*, 0)."""
    name = av.mt.functions[j][0]
    fd = doc["functions"][name]
    labels = [pt["label"] for pt in fd["points"]]
    if anchor_label(name) not in labels:
        raise ValueError(f"{name}: no point {anchor_label(name)} (its origin)")
    exact = _exact_anchor_positions(doc, av, name, pos)
    sj = [Fraction(v) for v in fd["optimal_subgradient"]]
    zero = [Fraction(0)] * len(sj)
    vecs = [(exact[pt["label"]], [Fraction(g) - s for g, s in zip(pt["g"], sj, strict=True)])
            for pt in fd["points"]] + [(zero, zero)]  # x*: point 0, tilted subgradient 0
    o, star = labels.index(anchor_label(name)), len(vecs) - 1
    rows = [(o, star, Fraction(1), Fraction(0)), (star, o, Fraction(1), Fraction(0))]
    forms = []
    for r, (alpha, Q) in enumerate(av.mt.ineqs[j]):
        Qr, c = _rationals(Q), Ball.of(av.mt.constant(j, r))
        if Qr is None or Ball.of(alpha).r != 0 or c.c != 0 or c.r != 0:
            raise ValueError(f"{name}: inexact class data or a constant")
        forms.append((Fraction(Ball.of(alpha).c), Qr))
    for a, (xa, ga) in enumerate(vecs):
        for b, (xb, gb) in enumerate(vecs):
            if a == b:
                continue
            X = (xa, xb, ga, gb)
            for r, (alpha, Q) in enumerate(forms):
                if av.mt.scope(j, r) == "optimum" and b != star or \
                        av.mt.scope(j, r) == "anchor" and (a == star or b != o):
                    continue  # conditions with x* only, with the origin o only
                q = sum((Q[u][v] * sum((s * t for s, t in zip(X[u], X[v], strict=True)),
                                        Fraction(0))
                         for u in range(4) for v in range(4) if Q[u][v]), Fraction(0))
                rows.append((a, b, alpha, q))  # an anchored class has no constants
    return [*labels, "x*"], rows


def _anchor_values(fd: dict[str, Any], name: str, exact: dict[str, list[Fraction]]
                   ) -> list[Fraction]:
    """The tilted values of a support function about its origin o, in rationals: h_a =
    <g_a - s*, x_a - o> at each point (``exact``: the rational positions), 0 at x*."""
    sj = [Fraction(v) for v in fd["optimal_subgradient"]]
    o = exact[anchor_label(name)]
    out = []
    for pt in fd["points"]:
        out.append(sum(((Fraction(g) - s) * (a - b) for g, s, a, b
                        in zip(pt["g"], sj, exact[pt["label"]], o, strict=True)),
                       Fraction(0)))
    return [*out, Fraction(0)]


def _rationals(M: Any) -> list[list[Fraction]] | None:
    """The exact method's matrix as rationals (None: some entry is a ball of radius > 0)."""
    out = []
    for row in np.atleast_2d(np.asarray(M, dtype=object)):
        balls = [Ball.of(v) for v in row]
        if any(b.r != 0 for b in balls):
            return None
        out.append([Fraction(b.c) for b in balls])
    return out


def _matvec(M: list[list[Fraction]], xs: list[list[Fraction]]) -> list[list[Fraction]]:
    """M X for X given by rows (each a point's coordinates)."""
    r = len(xs[0]) if xs else 0
    return [[sum((m * x[c] for m, x in zip(row, xs, strict=True)), Fraction(0))
             for c in range(r)] for row in M]


def rational_positions(doc: dict[str, Any], av: ArbView) -> dict[str, list[Fraction]] | None:
    """The start, the call points and each origin o in exact rationals, recomputed from the
    start and the calls (as :func:`positions` does in balls) when every entry of the method
    is rational; None otherwise (a line search, an ``initial_state``, a free start, an
    irrational entry)."""
    mt = av.mt
    if mt.line_search or av.G0 is not None or doc.get("xi0") is not None:
        return None
    X0 = _rationals(np.asarray(mt.X0, dtype=object).reshape(-1, 1))
    if X0 is None:
        return None
    x0 = [Fraction(v) for v in doc["x0"]]
    xi = [[row[0] * v for v in x0] for row in X0]
    out = {"x0": x0}
    for k in range(int(doc["call_steps"])):
        mats = [_rationals(M) for M in mt.step(k)]
        if any(M is None for M in mats):
            return None
        A, B, C, D = mats
        u = [[Fraction(v) for v in ui] for ui in doc["calls"][k]]
        y = [[a + b for a, b in zip(cy, dy, strict=True)]
             for cy, dy in zip(_matvec(C, xi), _matvec(D, u), strict=True)]
        for i in range(mt.p):
            out[_label(i, k, mt.p)] = y[i]
        if k < int(doc["steps"]):
            xi = [[a + b for a, b in zip(ax, bu, strict=True)]
                  for ax, bu in zip(_matvec(A, xi), _matvec(B, u), strict=True)]
    for name, cls, _ in mt.functions:
        if cls.anchored:
            pt = next(q for q in doc["functions"][name]["points"]
                      if q["label"] == anchor_label(name))
            out[pt["label"]] = [Fraction(float(v)) for v in pt["x"]]
    return out


def _exact_anchor_positions(doc: dict[str, Any], av: ArbView, name: str,
                            pos: dict[str, Any]) -> dict[str, list[Fraction]]:
    """Rational positions of every point of the anchored function ``name``, each inside
    its ball of :func:`positions` (ValueError when there are none)."""
    exact = rational_positions(doc, av)
    out = {}
    for pt in doc["functions"][name]["points"]:
        label = pt["label"]
        if exact is None or label not in exact:  # points as balls: exact when radius 0
            if any(not v.rad() == 0 for v in pos[label]):
                raise ValueError(f"{name} at {label}: not an exact point")
            out[label] = [arb_fraction(v.mid()) for v in pos[label]]
            continue
        if not all(v.overlaps(ball(q)) for v, q in zip(pos[label], exact[label],
                                                       strict=True)):
            raise ValueError(f"{name} at {label}: the rational point is not the point")
        out[label] = exact[label]
    return out


def _anchor_position(pt: dict[str, Any]) -> list[arb]:
    """The stated position of an origin o (a free point: the witness gives it), its exact
    coordinates the float ones (``x_exact``, when present, must say the same)."""
    x = [Fraction(float(v)) for v in pt["x"]]
    if "x_exact" in pt and [Fraction(v) for v in pt["x_exact"]] != x:
        raise ValueError(f"{pt['label']}: x_exact differs from x")
    return [ball(v) for v in x]


def _round_down(w: Fraction, bits: int = 64) -> Fraction:
    """A binary rational <= w with about ``bits`` significant bits."""
    if w == 0:
        return w
    e = w.numerator.bit_length() - w.denominator.bit_length() - bits
    return Fraction(math.floor(w / Fraction(2) ** e)) * Fraction(2) ** e


def _edges(rows: list[tuple[int, int, arb, arb]]) -> list[tuple[int, int, Fraction]] | None:
    """Each inequality alpha (h_a - h_b) + q >= 0 (for every alpha, q of the balls) as a
    difference constraint h_b <= h_a + w (alpha > 0: w <= q / alpha) or h_a <= h_b + w
    (alpha < 0); None when some alpha may vanish and its q >= 0 is not proven."""
    edges = []
    for a, b, alpha, q in rows:
        if alpha > 0:
            edges.append((a, b, _round_down(arb_fraction((q / alpha).lower()))))
        elif alpha < 0:
            edges.append((b, a, _round_down(arb_fraction((q / -alpha).lower()))))
        elif not q >= 0:
            return None
    return edges


def _shortest(n: int, src: int, edges: list[tuple[int, int, Fraction]]
              ) -> list[Fraction | None] | None:
    """Bellman-Ford from ``src`` (exact); None on a negative cycle."""
    dist: list[Fraction | None] = [None] * n
    dist[src] = Fraction(0)
    for _ in range(n + 1):
        changed = False
        for u, v, w in edges:
            du = dist[u]
            if du is not None and (dist[v] is None or du + w < dist[v]):  # type: ignore[operator]
                dist[v] = du + w
                changed = True
        if not changed:
            return dist if dist[src] == 0 else None
    return None


def fit_values(doc: dict[str, Any], mt: PEPFrame | ArbView) -> bool:
    """Replace the values h of every function by exact ones that satisfy every class
    inequality at the exactly recomputed points: the largest solution of the difference
    constraints (:func:`_edges`), shortest paths from x* (h = 0). False (doc unchanged)
    when none exists (a negative cycle: no function of the class has that geometry)."""
    av = mt if isinstance(mt, ArbView) else arb_view(mt)
    try:
        with precision(PREC):
            pos = positions(doc, av)
            forms = pair_forms(doc, av, pos)
            new = []
            for (labels, rows), (name, cls, _) in zip(forms, av.mt.functions, strict=True):
                if cls.anchored:  # its values are determined: h_a = <g_a, x_a - o>
                    new.append(_anchor_values(doc["functions"][name], name,
                                              _exact_anchor_positions(doc, av, name, pos)))
                    continue
                edges = _edges(rows)
                if edges == [] and rows:  # no value enters (an indicator's own
                    new.append([Fraction(0)] * len(labels))  # conditions): its values 0
                    continue
                dist = None if edges is None else _shortest(len(labels), len(labels) - 1,
                                                            edges)
                if dist is None:
                    return False
                new.append(dist)
    except (KeyError, ValueError, TypeError, IndexError, ArithmeticError, StopIteration):
        return False
    for (name, _, _), dist in zip(av.mt.functions, new, strict=True):
        for pt, h in zip(doc["functions"][name]["points"], dist, strict=False):
            if h is not None:
                pt["h"] = q_str(h)
    return True


def _pairs_ok(doc: dict[str, Any], av: ArbView, pos: dict[str, Any]) -> tuple[int, int]:
    """(pairs checked, pairs not proven): every tilted class inequality."""
    checked = bad = 0
    for (name, cls, _), (_, rows) in zip(av.mt.functions, pair_forms(doc, av, pos),
                                       strict=True):
        h = [(Fraction if cls.anchored else ball)(pt["h"])  # anchored: rational rows
             for pt in doc["functions"][name]["points"]]
        h.append(Fraction(0) if cls.anchored else arb(0))
        for a, b, alpha, q in rows:
            checked += 1
            bad += not (alpha * (h[a] - h[b]) + q >= 0)
    return checked, bad


def _dot(a: list[arb], b: list[arb]) -> arb:
    return sum((x * y for x, y in zip(a, b, strict=True)), arb(0))


def _sdist(doc: dict[str, Any], av: ArbView, xi: arb_mat) -> arb:
    """|xi - xi*|^2 over every state block, xi* = X_s s~ (x* = 0)."""
    sst = [[ball(v) for v in doc["functions"][name]["optimal_subgradient"]]
           for name, _, _ in av.mt.functions[:-1]]
    total = arb(0)
    for a in range(av.mt.n):
        for c in range(xi.ncols()):
            d = xi[a, c] - sum((av.Xs[a][j] * s[c] for j, s in enumerate(sst)), arb(0))
            total += d * d
    return total


def pos_key(point: str, N: int, p: int) -> str:
    """The position key of a term point y<i> at step N."""
    return f"y{N}" if p == 1 else f"{point}_{N}"


def _terms_value(terms: list[Term], doc: dict[str, Any], av: ArbView,
                 pos: dict[str, Any]) -> arb:
    from sosalgo.worstcase.terms import DIFF_KIND, MIN_OF, STEP_POINT, at_steps

    mt, N = av.mt, int(doc["steps"])
    total = arb(0)
    for t in at_steps(terms, N, "measure"):
        c = av.coef(t)
        if t.kind == DIFF_KIND:  # |P - Q|^2
            P, Q = (pos[{"x": f"x{N}"}.get(q) or (q if STEP_POINT.match(q) or q == OUT0
                                                  else pos_key(q, N, mt.p))]
                    for q in t.point.split("__"))
            v = [a - b for a, b in zip(P, Q, strict=True)]
            total += c * _dot(v, v)
            continue
        if t.kind in MIN_OF:  # min over the iterates x_0 .. x_N (x_N: point "x")
            each = [_terms_value([Term(MIN_OF[t.kind], f"x{k}" if k < N else "x", t.coef)],
                                 doc, av, pos) for k in range(N + 1)]
            total += arb_min(each)
            continue
        if t.kind == "sdist":
            total += c * _sdist(doc, av, pos["xiN" if t.point == "x" else "xi0"])
            continue
        key = {"x": f"x{N}"}.get(t.point) or (t.point if STEP_POINT.match(t.point)
                                               or t.point == OUT0
                                               else pos_key(t.point, N, mt.p))
        P = pos[key]
        if t.kind == "dist":
            total += c * _dot(P, P)
            continue
        funcs = (range(len(mt.functions)) if t.kind == "f" else
                 [j for j, f in enumerate(mt.functions) if "gradient" in f[1].oracles])
        acc: Any = arb(0) if t.kind == "f" else [arb(0)] * len(P)
        for j in funcs:
            name = mt.functions[j][0]
            label = doc["evaluations"][f"{t.point}|{name}"]
            pt = next(q for q in doc["functions"][name]["points"] if q["label"] == label)
            if pos[label] is not P and not all((a - b).is_zero()
                                               for a, b in zip(pos[label], P, strict=True)):
                raise ValueError(f"{name} at {label} is not provably the point {key}")
            if t.kind == "f":
                acc = acc + ball(pt["h"])
            else:
                acc = [a + ball(g) for a, g in zip(acc, pt["g"], strict=True)]
        total += c * (acc if t.kind == "f" else _dot(acc, acc))
    return total


def arb_min(values: list[arb]) -> arb:
    """A ball that holds the minimum of ``values``: from the least lower end to the least
    upper end (exact comparisons of exact endpoints)."""
    lo, hi = values[0].lower(), values[0].upper()
    for v in values[1:]:
        if v.lower() < lo:
            lo = v.lower()
        if v.upper() < hi:
            hi = v.upper()
    return lo.union(hi)


def _differences_only(terms: list[Term], av: ArbView) -> None:
    """A nonconvex class's PEP has no x* and no f*: its values are known up to a shift
    and its origin is arbitrary, so a witness proves a ratio only of terms free of x*
    (no dist, sdist) whose f coefficients sum to exactly 0 (ValueError otherwise)."""
    if any(t.kind in ("dist", "sdist") for t in terms):
        raise ValueError("dist about a nonconvex class (its PEP has no x*)")
    total = sum((av.coef(t) for t in terms if t.kind == "f"), arb(0))
    if not total.is_zero():
        raise ValueError("f - f* about a nonconvex class: the f coefficients do not cancel")


def set_quadratic_calls(doc: dict[str, Any], av: ArbView, q: list[Fraction],
                        bits: int = 2 * PREC) -> None:
    """Make the one-dimensional ``doc`` the run of the method on f_j = q_j/2 x^2 (each
    least at x* = 0) from its x_0: each call u_{k,i} = q_j y_{k,i} (j its oracle), with
    y_k = C xi_k + D u_k solved in ball arithmetic at ``bits`` bits and rounded to a
    rational, and every point's gradient q_j x (a call's point: the call itself). The
    exactly recomputed trajectory is then the quadratic's up to about 2^-bits, not up to
    the rounding of the floats (about 1e-16 absolute, more than the late iterates of a
    long horizon)."""
    mt, p = av.mt, av.mt.p
    funcs = doc["functions"]
    with precision(bits):
        if av.G0 is not None:  # initial_state: g0 = q_j x_0, j the smooth function
            j = mt.smooth
            for pt in funcs[mt.functions[j][0]]["points"]:
                if pt["label"] == "x0":
                    pt["g"] = [q_str(q[j] * Fraction(doc["x0"][0]))]
        xi = _start(doc, av, 1)
        qs = arb_mat(p, p)
        for i, j in enumerate(mt.oracles):
            qs[i, i] = arb(fmpq(q[j].numerator, q[j].denominator))
        eye = arb_mat(p, p)
        for i in range(p):
            eye[i, i] = arb(1)
        for k in range(int(doc["call_steps"])):
            A, B, C, D = av.step(k)
            y = (eye - D * qs).solve(C * xi)
            u = [arb_fraction((qs[i, i] * y[i, 0]).mid()) for i in range(p)]
            doc["calls"][k] = [[q_str(v)] for v in u]
            if k < int(doc["steps"]):
                xi = A * xi + B * _mat(doc["calls"][k])
    calls = {(mt.functions[j][0], _label(i, k, p)): doc["calls"][k][i]
             for k in range(int(doc["call_steps"])) for i, j in enumerate(mt.oracles)}
    pos = positions(doc, av)
    with precision(bits):
        for j, (name, _, _) in enumerate(mt.functions):
            qj = arb(fmpq(q[j].numerator, q[j].denominator))
            for pt in funcs[name]["points"]:
                pt["g"] = list(calls.get((name, pt["label"])) or
                               [q_str(arb_fraction((qj * pos[pt["label"]][0]).mid()))])


def _measure_initial(doc: dict[str, Any], spec: Spec, av: ArbView
                     ) -> tuple[int, int, bool, arb, arb]:
    """(pairs checked, not proven, optimal subgradients sum to 0, measure, initial)."""
    from sosalgo.worstcase.terms import parse_terms

    p = av.mt.p
    mterms = parse_terms(doc["measure"], "measure", False, p, spec.parameters)
    iterms = parse_terms(doc["initial"], "initial", True, p, spec.parameters)
    if free_start(iterms) != (doc.get("xi0") is not None):
        raise ValueError("an initial sdist needs the free start xi0, and only it")
    if not all(cls.convex or cls.minimizer for _, cls, _ in av.mt.functions):
        _differences_only(mterms, av)
        _differences_only(iterms, av)
    pos = positions(doc, av)
    checked, bad = _pairs_ok(doc, av, pos)
    from sosalgo.worstcase.call_checks import call_checks

    calls, wrong = call_checks(doc, av)  # each answer is its point's gradient (or near it)
    if wrong:
        raise ValueError(f"{wrong} of {calls} calls: the answer is not the gradient of its "
                         "function at its point in the witness (nor within its relative "
                         "error)")
    checked += calls
    ssum = [sum(Fraction(v[c]) for v in (f["optimal_subgradient"] for f in
                                          doc["functions"].values()))
            for c in range(int(doc["dimension"]))]
    return (checked, bad, not any(ssum), _terms_value(mterms, doc, av, pos),
            _terms_value(iterms, doc, av, pos))


def _inhomogeneous_lower(meas: arb, init: arb) -> Fraction:
    """The lower bound a witness gives on a PEP with constants (every one >= 0): its
    measure when initial <= 1; else the witness scaled by r = initial^-1/2 < 1 (points,
    subgradients by r, values by r^2) still satisfies every inequality (its homogeneous
    part times r^2, plus a constant >= 0) and has initial 1: measure / initial."""
    return arb_fraction(meas.lower()) / max(Fraction(1), arb_fraction(init.upper()))


def check_witness(doc: dict[str, Any], spec: Spec, mt: PEPFrame | ArbView | None = None
                  ) -> dict[str, Any]:
    """Check a witness against ``spec`` (see the module; ``mt``: its exact method, built
    here when not given); never raises on a bad witness: ``verified`` False with the
    reason."""
    from sosalgo.worstcase.bind import bound_method, class_kappa
    from sosalgo.worstcase.exact import document_kappa

    t0 = time.perf_counter()
    out: dict[str, Any] = {"verified": False, "check_kind": "exact (rational and ball "
                           "arithmetic)", "tau_lower": None, "tau_lower_float": None}
    try:
        if (getattr(spec, "pep", None) or {}).get("constraints"):
            raise ValueError("a witness of a PEP with constraints on the instance "
                             "(pep.constraints) is not checked: no lower bound")
        if mt is None and changes_with_k(spec):  # the per-step methods, exactly
            kappa = document_kappa(doc.get("kappa"), doc.get("kappa_exact"), "witness")
            mt = exact_steps_or_none(spec, kappa, int(doc["steps"]))
            if mt is None:
                raise ValueError("the exact per-step methods cannot be built")
        if mt is None:
            kappa = document_kappa(doc.get("kappa"), doc.get("kappa_exact"), "witness")
            om, _ = bound_method(spec, class_kappa(spec, kappa))
            mt = exact_method(spec, kappa, om, int(doc["steps"]))
        av = mt if isinstance(mt, ArbView) else arb_view(mt)
        if "xi0_second" in doc:  # two runs (:mod:`sosalgo.worstcase.contraction_witness`)
            from sosalgo.worstcase.contraction_witness import check_contraction_witness

            if str(doc.get("measure")).strip() != "contraction":
                raise ValueError("a second run is a witness of the contraction measure")
            with precision(PREC):
                return check_contraction_witness(doc, spec, av)
        with precision(PREC):
            if doc.get("members") is not None:  # explicit quadratics, not points
                from sosalgo.worstcase.terms import parse_terms

                meas, init = member_measure(
                    doc, av, parse_terms(doc["measure"], "measure", False, av.mt.p),
                    parse_terms(doc["initial"], "initial", True, av.mt.p))
                checked, bad, zero_sum = len(doc["members"]), 0, True
            else:
                checked, bad, zero_sum, meas, init = _measure_initial(doc, spec, av)
    except (KeyError, ValueError, TypeError, IndexError, ZeroDivisionError, StopIteration,
            ArithmeticError) as exc:
        return out | {"detail": f"malformed or inconsistent witness: {type(exc).__name__}: "
                                f"{exc}", "seconds": time.perf_counter() - t0}
    out["pairs_checked"] = checked
    if bad or not zero_sum or not init > 0 or not meas >= 0:
        why = (f"{bad} interpolation inequalities not proven" if bad else
               "the optimal subgradients do not sum to 0" if not zero_sum else
               "the initial condition is not positive" if not init > 0 else "measure < 0")
        return out | {"detail": why, "seconds": time.perf_counter() - t0}
    lower = arb_fraction(meas.lower()) / arb_fraction(init.upper())
    if av.mt.constants is not None and any(  # not scale invariant: _inhomogeneous_lower
            not ball(c).is_zero() for fc in av.mt.constants for c in fc):
        lower = _inhomogeneous_lower(meas, init)
    detail = (f"{checked} inequalities proven; the trajectory recomputed from the start "
              "and the calls" if doc.get("members") is None else
              f"{checked} explicit quadratics q/2 |x|^2 inside their classes; their run "
              "recomputed from the start")
    return out | {"verified": True, "tau_lower": q_str(lower), "tau_lower_float": float(lower),
                  "detail": detail, "seconds": time.perf_counter() - t0}


# ------------------------------------------------------------ explicit members
# Witnesses that are explicit members of the classes: one quadratic f_j = q_j/2 |x|^2
# per function (for an operator class, the linear operator q_j I), each least at x* = 0.
#
# A class with Gram-level conditions (:mod:`sosalgo.worstcase.blocks`) has equalities among its
# pairwise conditions (symmetry, the values of a quadratic), which no rounded trajectory
# meets exactly. Its witness is therefore not a list of points checked against the
# pairwise inequalities but the functions themselves: the document's ``members`` gives each
# q_j (a rational), and the check (:func:`member_measure`) trusts nothing else than the
# spec and x_0:
#
# - every q_j lies in its class's exact curvature interval
#   (:meth:`~sosalgo.classes.base.FunctionClass.exact_curvatures`, from rational bounds of
#   the exact parameters): q_j/2 |x|^2 is a member;
# - x* = 0 solves the problem (every f_j is least there: the optimal subgradients are 0);
# - the run of the method on those functions is recomputed from x_0 in ball arithmetic
#   (each call's answer q_j y, a proximal call solved from (I - D q) y = C xi), and the
#   measure and the initial condition evaluated on it.
#
# So the measure over the initial condition is a proven lower bound of the worst case.
# The candidates scan each class's interval (its ends included: no inequality is checked
# with a slack) and keep the largest proven ratio.


def member_interval(cls: Any, params: dict[str, Any]) -> tuple[Fraction, Fraction] | None:
    """The class's exact curvature interval at exact parameters (balls or rationals)."""
    from sosalgo.kernel.exact import Ball

    def lower(name: str) -> Fraction:
        b = Ball.of(params[name])
        return b.c - b.r

    def upper(name: str) -> Fraction:
        b = Ball.of(params[name])
        return b.c + b.r

    return cls.exact_curvatures(lower, upper)


def member_measure(doc: dict[str, Any], av: Any, mterms: list[Any], iterms: list[Any]
                   ) -> tuple[arb, arb]:
    """(measure, initial) of the explicit members' run (see the module); ValueError when
    a member is not in its class or the document is not such a witness."""
    mt = av.mt
    if av.G0 is not None or mt.line_search or doc.get("xi0") is not None:
        raise ValueError("members: a run from x_0 without an initial gradient or line "
                         "search")
    q = []
    for name, cls, params in mt.functions:
        qj = Fraction(doc["members"][name])
        iv = member_interval(cls, params)
        if iv is None or not iv[0] <= qj <= iv[1]:
            raise ValueError(f"members: {name}: {qj} is outside the curvatures of "
                             f"{cls.name} at these parameters")
        if any(Fraction(v) != 0 for v in doc["functions"][name]["optimal_subgradient"]):
            raise ValueError(f"members: {name}: its optimal subgradient must be 0")
        q.append(qj)
    r, p, N = int(doc["dimension"]), mt.p, int(doc["steps"])
    Qs, eye = arb_mat(p, p), arb_mat(p, p)
    for i, j in enumerate(mt.oracles):
        Qs[i, i], eye[i, i] = ball(q[j]), arb(1)
    xi, calls = _start(doc, av, r), []
    for k in range(int(doc["call_steps"])):
        A, B, C, D = av.step(k)
        y = (eye - D * Qs).solve(C * xi)
        u = Qs * y
        calls.append([[u[i, c] for c in range(r)] for i in range(p)])
        if k < N:
            xi = A * xi + B * u
    run = dict(doc, calls=calls)
    pos = positions(run, av)
    funcs = {}
    for j, (name, _, _) in enumerate(mt.functions):
        qb = ball(q[j])
        pts = []
        for pt in doc["functions"][name]["points"]:
            x = pos[pt["label"]]
            pts.append({"label": pt["label"], "g": [qb * v for v in x],
                        "h": qb * sum((v * v for v in x), arb(0)) / 2})
        funcs[name] = {"points": pts}
    run["functions"] = funcs
    return _terms_value(mterms, run, av, pos), _terms_value(iterms, run, av, pos)
