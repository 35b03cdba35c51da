"""The performance estimation problem (PEP) of a method of the oracle model, as data.

Drori and Teboulle (2014); Taylor, Hendrickx and Glineur (2017). The worst case of
``measure(x_N) / initial(x_0)`` over every f_j in its class and every start is an SDP in

    G = Gram matrix of (x_0 - x*, s~, b_{k,i}, extra subgradients),   F = function values,

with x* = 0 and every function tilted as in :mod:`sosalgo.certificates.composite`:
h_j = f_j - f_j* - <s_j*, . - x*> >= 0 (value 0 and subgradient 0 at x*), u~ = u - s_j*,
s~ = (s_1*, ..., s_{J-1}*) the free optimal subgradients (s_J* = -sum). The deviations
follow the method exactly: xi~_0 = u (x_0 - x*) - X_s s~ (xi_0 = u ⊗ x_0; X_s the fixed
points of the optimal subgradients, :func:`sosalgo.oracles.fixed_point_basis`),
xi~_{k+1} = A xi~_k + B u~_k, y~_k = C xi~_k + D u~_k.

Free start: an initial term ``sdist`` (|xi_0 - xi*|^2, every state block) makes xi~_0
itself the first n basis vectors (xi_0 anywhere; x_0 is then the output at step 0).

Basis. The oracle answers are not basis vectors: u~_k/s = K xi~_k + b_k with b_k the new
basis vectors and K a deadbeat gain (A + s B K nilpotent, :func:`deadbeat_gain`): an
invertible, causal change of basis (the same PEP), in which every point and subgradient
combines the b of the last n steps only. With u~_k itself as basis vector a late iterate
would combine every earlier gradient: dense inequality rows, and a late iterate (tiny)
computed as the difference of large numbers.

Each function's tilted class inequalities hold between every ordered pair of its points:
its calls, x* and the extra points where a term evaluates it (an extra point that
coincides with one of its calls is that call). Then

    tau_N = max measure(G, F)  s.t.  initial(G, F) <= 1,  alpha (F_a - F_b) + <Q_ab, G> >= 0,
            F >= 0 (h_j >= 0),  G ⪰ 0.

Units: subgradients are divided by s = L and function values too (gradient rows are u~/s,
F = h/s), so that every entry is a distance squared. The builder is written once for
floats and for exact balls (:class:`sosalgo.kernel.exact.Ball`, object arrays): the
exact check rebuilds the same structure on exact numbers.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.base import ANCHOR
from sosalgo.errors import InputError
from sosalgo.oracles import CallShape, Method
from sosalgo.worstcase.terms import (
    CALL_AT,
    DIFF_KIND,
    FREE_KIND,
    GRAD_OF,
    INNER_KIND,
    MIN_OF,
    OUT0,
    REST,
    STEP_POINT,
    Term,
    at_steps,
    free_start,
)

__all__ = ["PEPFrame", "PEPPoint", "PEPStructure", "anchor_label", "build_structure",
           "enclosure_bits", "enclosure_digits", "last_calls", "method_field", "output_call",
           "pair_label", "radius_growth"]


def method_field(name: str) -> property:
    """The read of a method's field ``name`` by the PEP's data around it (``frame.A`` is
    ``frame.method.A``)."""
    return property(lambda frame: getattr(frame.method, name),
                    doc=f"The method's ``{name}`` (its ``method``).")


@dataclass
class PEPFrame(CallShape):
    """The PEP's own data around a method: not a method type, but the one
    :class:`sosalgo.oracles.Method` (``method``: over floats, or exact numbers: balls, or
    a quadratic field's numbers) with what the PEP builds on it. ``A``, ``B``, ``C``,
    ``D``, ``E``, ``output``, ``functions`` (name, class, params) and ``oracles`` are read
    from ``method`` (the PEP splitting a transpose part off replaces ``method``).

    ``coef(term)`` the number of a term's c; ``X0``, ``Xs``: the fixed-point direction and
    the fixed points of the free optimal subgradients (columns); ``same(a, b)``: whether
    two rows are the same point; ``K``: the gain that defines the basis (the same binary
    numbers in both number types)."""

    A = method_field("A")
    B = method_field("B")
    C = method_field("C")
    D = method_field("D")
    E = method_field("E")
    output = method_field("output")
    functions = method_field("functions")
    oracles = method_field("oracles")

    method: Method
    X0: np.ndarray
    Xs: np.ndarray
    s: Any
    ineqs: list[list[tuple[Any, np.ndarray]]]  # per function: (alpha, Q) tilted
    coef: Callable[[Term], Any]
    same: Callable[[np.ndarray, np.ndarray], bool]
    K: np.ndarray  # (p x n) the deadbeat gain of the basis (:func:`deadbeat_gain`)
    exact: bool = False
    G0: np.ndarray | None = None  # ``initial_state``: xi_0 = X0 x_0 + G0 g0 (None: G0 = 0)
    smooth: int = 0  # the function whose gradient g0 is
    out_call: int | None = None  # output None, E = C_i and D_i = 0: x_k is call i's point
    # D_i = 0 and C_i [X0 Xs] = [1 0] proven exactly: from xi_0 = X0 x_0 - Xs s~ the first
    # call i is at x_0 (set on exact methods; floats find the coincidence by ``same``)
    x0_call: int | None = None
    # output None, E A = C_i and E B = D_i proven exactly: x_k (k >= 1) is the point of
    # call i at step k - 1 (a proximal output; set on exact methods for the witness check)
    prev_call: int | None = None
    # exact methods: the structures built on them (the proof of each margin's certificate
    # rebuilds the same one; built once, :func:`build_structure`)
    structures: dict[Any, Any] = field(default_factory=dict, repr=False, compare=False)
    # exact methods: significant bits kept when a long centre is rounded outward
    # (:func:`coarsen`), matched to the decimals of the enclosures (:func:`enclosure_digits`)
    bits: int = 160
    # a mingrad measure: the weighted sum that bounds it (:mod:`sosalgo.worstcase.minimum`)
    bound: str | None = None
    # a method that changes with k: (A_k, B_k, C_k, D_k) of step k (call k and the move
    # from xi_k to xi_{k+1}); None: A, B, C, D at every step (:meth:`step`)
    per_step: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] | None = None
    per_gain: list[np.ndarray] | None = None  # K_k of step k's basis (None: K at every step)
    # per function, per inequality: its constant (>= 0, in the units of f) and its scope
    # ("pairs" or "optimum", :class:`sosalgo.classes.base.Inequality`); None: 0, "pairs"
    constants: list[list[Any]] | None = None
    scopes: list[list[str]] | None = None

    def constant(self, j: int, r: int) -> Any:
        """The constant of function j's inequality r (0 when none)."""
        return 0 if self.constants is None else self.constants[j][r]

    def scope(self, j: int, r: int) -> str:
        """The pairs function j's inequality r holds for: "pairs", "optimum" or "anchor"."""
        return "pairs" if self.scopes is None else self.scopes[j][r]
    # inexact gradient calls: call index -> eps (|d - g| <= eps |g|,
    # :mod:`sosalgo.worstcase.inexact`)
    errors: dict[int, Any] = field(default_factory=dict)
    # epsilon-subgradient calls: call index -> eps (:mod:`sosalgo.worstcase.epsilon`)
    epsilons: dict[int, Any] = field(default_factory=dict)
    # an inexact call's reference vector (coefficients on the step's answers) and the
    # calls answering an inexact call's true subgradient (call -> that call; no point)
    error_refs: dict[int, tuple[Any, ...]] = field(default_factory=dict)
    twins: dict[int, int] = field(default_factory=dict)
    # x+ = x - gamma_k u with gamma_k by exact line search (:mod:`sosalgo.worstcase.linesearch`)
    line_search: bool = False
    span_search: bool = False  # the line search over the span of the past gradients
    # linear minimization calls: call index -> its direction's call (:mod:`sosalgo.worstcase.lmo`)
    lmo: dict[int, int] = field(default_factory=dict)
    # constraints on the instance: (relation, terms of left - right), relation ==, <= or >=
    # (:mod:`sosalgo.worstcase.constraints`)
    constraints: list[tuple[str, list[Term]]] = field(default_factory=list)
    # per function: the K (2 x 2) of each Gram-level condition of its class
    # (:meth:`sosalgo.classes.base.FunctionClass.blocks`; :mod:`sosalgo.worstcase.blocks`)
    blocks: list[list[np.ndarray]] = field(default_factory=list)
    # per function: its class's LMIs on tuples of points (:class:`TupleLMI`,
    # :mod:`sosalgo.worstcase.lmis`)
    lmis: list[list[Any]] = field(default_factory=list)
    # their cuts' rows, computed once per method (function, LMI, entries) -> (Qc, values)
    lmi_rows: dict[Any, Any] = field(default_factory=dict)
    # transpose calls of a linear operator (:mod:`sosalgo.worstcase.adjoint`); None: none
    adjoint: dict[str, Any] | None = None

    def gain(self, k: int) -> np.ndarray:
        """The gain K_k of step k's basis vectors (:func:`_trajectory`)."""
        return self.K if self.per_gain is None else self.per_gain[k]

    def step(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, D) of step k."""
        if self.per_step is None:
            return self.A, self.B, self.C, self.D
        if k >= len(self.per_step):
            raise InputError(f"--steps: the method's matrices are given for steps "
                             f"0..{len(self.per_step) - 1}, step {k} is needed")
        return self.per_step[k]


@dataclass
class PEPPoint:
    label: str
    x: np.ndarray  # row on the Gram basis
    g: np.ndarray  # row of the tilted subgradient / s
    f: int | None  # index in F (None: x*, value 0)
    t: int | None = None  # the step of a call (None: x* or a term's extra point)
    # the answer the method moved with when it is not this point's subgradient (an
    # epsilon-subgradient call: :mod:`sosalgo.worstcase.epsilon`); grad(P) reads it
    answer: np.ndarray | None = None


@dataclass
class PEPStructure:
    """Everything the SDP, its exact check and the witness need."""

    steps: int
    calls: int  # iterations whose calls are points (steps, or steps + 1)
    basis: list[str]
    points: list[list[PEPPoint]]  # per function
    nF: int
    pairs: list[tuple[int, int, int, int]]  # (function, a, b, inequality index)
    labels: list[str]
    meas_q: np.ndarray
    meas_f: np.ndarray
    init_q: np.ndarray
    init_f: np.ndarray
    rows: dict[str, Any] = field(default_factory=dict)  # xi, y, x rows by time
    at: dict[tuple[str, int], int] = field(default_factory=dict)  # (term point, j) -> point
    # no x* (a nonconvex class): values enter only as differences, the dual's c_F is 0
    # (no margin on it; proven exactly zero, :func:`sosalgo.worstcase.exact.prove_at`)
    free_values: bool = False
    # a mingrad measure: the forms c |grad f(x_k)|^2 + (linear terms), k = 0..N (the
    # witness keeps each at its floor, so that their minimum is; :mod:`sosalgo.worstcase.minimum`)
    floors: list[tuple[np.ndarray, np.ndarray]] | None = None
    # the constant of each pair's inequality (None: all 0, the homogeneous PEP); with
    # constants the worst case is the one under initial <= 1, and a dual certificate
    # (tau, lambda) bounds the measure by tau + sum_k lambda_k c_k (:mod:`sosalgo.worstcase.sdp`)
    constants: np.ndarray | None = None
    # the rows that are half of an equality (a support function's conditions with its
    # origin o: h_a = <g_a, x_a - o>), which an interior point cannot hold with a slack
    equalities: np.ndarray | None = None
    # constraints beyond the class inequalities, after the pairs (their multipliers follow
    # the pairs'): (label, X (4 x d), Qc (4 x 4)) with tr(Qc X G X') + a F >= 0
    extras: list[tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)
    # no initial condition (``--initial none``): the question is homogeneous, its worst
    # case 0 or unbounded; the solver normalizes it (:mod:`sosalgo.worstcase.sdp`), the proof is
    # at tau = 0 exactly
    bare: bool = False
    # the margin solves put no margin on the directions no form has a square of (their
    # rows of S are 0; the proof makes them exactly 0): free points a span search ties to
    # the run by equalities only
    margin_seen: bool = False
    # the value coefficients a (on F) of the extras that have some (index in extras -> a;
    # the others have none: :mod:`sosalgo.worstcase.constraints`)
    extra_values: dict[int, np.ndarray] = field(default_factory=dict)
    # Gram-level conditions (:mod:`sosalgo.worstcase.blocks`): (function, condition, its points)
    blocks: list[tuple[int, int, list[int]]] = field(default_factory=list)
    # the rank-one cuts of the blocks' multipliers, appended to the extras:
    # (function, condition, vector over the block's points)
    cuts: list[tuple[int, int, list[Any]]] = field(default_factory=list)
    # the class LMIs on tuples of points (:mod:`sosalgo.worstcase.lmis`): (function, LMI,
    # the tuple's points), and their cuts, appended to the extras: (function, LMI,
    # tuple, the cut's stored entries)
    lmis: list[tuple[int, int, tuple[int, ...]]] = field(default_factory=list)
    lmi_cuts: list[tuple[int, int, tuple[int, ...], list[Any]]] = field(
        default_factory=list)

    @property
    def d(self) -> int:
        return len(self.basis)

    def equality_rows(self, n: int) -> np.ndarray:
        """Which of the first n rows are half of an equality (False beyond ``equalities``:
        rows added later, such as cuts)."""
        out = np.zeros(n, dtype=bool)
        if self.equalities is not None:
            k = min(n, len(self.equalities))
            out[:k] = self.equalities[:k]
        return out

    @property
    def count(self) -> int:
        """The constraints with a multiplier: the pairs, then the extras."""
        return len(self.pairs) + len(self.extras)

    def pair_rows(self, method: PEPFrame, k: int) -> tuple[Any, np.ndarray, np.ndarray]:
        """(alpha, a on F, X (4 x d)) of pair k: alpha (F_a - F_b) + X' Q X >= 0."""
        j, a, b, r = self.pairs[k]
        pa, pb = self.points[j][a], self.points[j][b]
        alpha, _ = method.ineqs[j][r]
        av = np.zeros(self.nF, dtype=object if method.exact else float)
        if pa.f is not None:
            av[pa.f] = av[pa.f] + alpha * method.s
        if pb.f is not None:
            av[pb.f] = av[pb.f] - alpha * method.s
        s = method.s
        X = np.vstack([pa.x, pb.x, pa.g * s, pb.g * s])
        return alpha, av, X


def pair_label(fname: str, a: str, b: str, r: int, many: bool) -> str:
    return f"{fname}:{a},{b}" + (f"#{r}" if many else "")


def _call_label(i: int, k: int, p: int) -> str:
    return f"y{k}" if p == 1 else f"y{i + 1}_{k}"


def deadbeat_gain(A: np.ndarray, B: np.ndarray, s: float) -> np.ndarray:
    """K (p x n) with A + s B K nilpotent (deadbeat, Ackermann's formula with the desired
    polynomial z^n, on the input direction g = e_i or the sum of all that gives the best
    conditioned controllability matrix), or 0 when no direction controls the state."""
    n, p = B.shape
    Bt = s * np.asarray(B, float)
    A = np.asarray(A, float)
    best, K = np.inf, np.zeros((p, n))
    for g in [*np.eye(p), np.ones(p)]:
        b = Bt @ g
        Cm = np.column_stack([np.linalg.matrix_power(A, j) @ b for j in range(n)])
        cond = np.linalg.cond(Cm)
        if not np.isfinite(cond) or cond > 1e8 or cond >= best:
            continue
        k = -np.linalg.solve(Cm.T, np.eye(n)[-1]) @ np.linalg.matrix_power(A, n)
        cand = np.outer(g, k)
        M = np.linalg.matrix_power(A + Bt @ cand, n)
        if np.abs(M).max() <= 1e-10 * (1 + np.abs(A).max() ** n):
            best, K = cond, cand
    return K


ENCLOSURE_TARGET = 40  # decimals the trajectory's radii keep after the last step
MAX_DIGITS = 1000  # a hostile spec or document (huge growth or steps) stays bounded


def radius_growth(A: np.ndarray, B: np.ndarray, K: np.ndarray, s: float) -> float:
    """The factor by which ball arithmetic widens the radii of the exact trajectory per
    step, asymptotically: xi_{k+1} = A xi_k + s B (K xi_k + b_k) computed entrywise in
    balls widens a radius vector r to (|A| + s |B| |K|) r plus new rounding, so by the
    spectral radius of that nonnegative matrix (its Perron root; at least 1). This is far
    above the true sensitivity (A + s B K is nilpotent), but it is what interval
    arithmetic pays (Nesterov at kappa = 10: 3.35 per step, as measured)."""
    M = np.abs(np.asarray(A, float)) + abs(float(s)) * (np.abs(np.asarray(B, float))
                                                         @ np.abs(np.asarray(K, float)))
    if not M.size or not np.isfinite(M).all():
        return 1.0 if not M.size else math.inf
    return max(1.0, float(np.abs(np.linalg.eigvals(M)).max()))


def enclosure_digits(growth: float, steps: int, base: int = 50,
                     target: int = ENCLOSURE_TARGET) -> int:
    """Decimals of the rational enclosures of irrational entries for an exact
    trajectory of ``steps`` steps: radii 10^-digits widened by ``growth`` per step
    (:func:`radius_growth`) end below 10^-target; never fewer than ``base`` (the short
    horizons' precision), rounded up to a multiple of 10, at most :data:`MAX_DIGITS` (a
    coarser enclosure can only fail a proof, never pass a false one)."""
    if not math.isfinite(growth) or growth < 1.0:
        growth = 1.0 if math.isfinite(growth) else 10.0
    need = target + math.ceil(min(max(0, int(steps)), MAX_DIGITS) * math.log10(growth))
    return min(MAX_DIGITS, max(base, 10 * math.ceil(need / 10)))


def enclosure_bits(digits: int) -> int:
    """Significant bits :func:`coarsen` keeps for enclosures of ``digits`` decimals (a
    rounding step as fine as the enclosures: about 3.33 digits' worth of bits, never
    fewer than the default 160)."""
    return max(160, math.ceil(digits * math.log2(10)) + 8)


def coarsen(v: Any, bits: int = 160) -> Any:
    """An exact number whose denominators have grown past ``bits`` bits as a ball around
    a binary rational with about ``bits`` significant bits, the rounding error added to
    its radius (outward: the ball still holds the number)."""
    from sosalgo.kernel.exact import Ball
    from sosalgo.kernel.qfield import QSqrt

    if isinstance(v, QSqrt):  # an exact element of Q(sqrt d): kept as it is
        return v
    b = Ball.of(v)
    if max(b.c.denominator.bit_length(), b.r.denominator.bit_length()) <= 2 * bits:
        return v
    k = bits - (abs(b.c.numerator).bit_length() - b.c.denominator.bit_length())
    c = Fraction(round(b.c * 2 ** k), 2 ** k) if k >= 0 else Fraction(round(b.c / 2 ** -k)
                                                                        * 2 ** -k)
    err = abs(b.c - c) + b.r
    kr = max(k, 0) + 8
    return Ball(c, Fraction(math.ceil(err * 2 ** kr), 2 ** kr))


def _trajectory(mt: PEPFrame, xi0: np.ndarray, new: list[np.ndarray],
                calls: int) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """(xi, y, u/s) rows: u~_k/s = K xi~_k + b_k (b_k the new basis vectors ``new[k]``),
    y~_k = C xi~_k + s D u~_k/s, xi~_{k+1} = A xi~_k + s B u~_k/s. With K deadbeat, every
    row combines the last n steps' b only (float rows: round-off below 1e-13 dropped)."""
    if mt.exact:
        return _exact_trajectory(mt, xi0, new, calls)
    xi, Y, U = [xi0], [], []
    for k in range(calls):
        A, B, C, D = mt.step(k)
        u = mt.gain(k) @ xi[k] + new[k]
        U.append(u)
        Y.append(C @ xi[k] + mt.s * (D @ u))
        nxt = A @ xi[k] + mt.s * (B @ u)
        nxt[np.abs(nxt) < 1e-13 * (1.0 + np.abs(nxt).max())] = 0.0
        xi.append(nxt)
    return xi, Y, U


def _exact_trajectory(mt: PEPFrame, xi0: np.ndarray, new: list[np.ndarray],
                      calls: int) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """:func:`_trajectory` on exact numbers, computed on the columns in use only (the
    others are exact zeros, a product of exact zeros included: Ball(c, r) * 0 = 0), so
    that a step costs the band of the last n steps, not the whole basis."""
    zero = Fraction(0)
    xi, Y, U = [xi0], [], []
    for k in range(calls):
        cols = np.flatnonzero([any(_nonzero(v) for v in col) for col in
                               np.vstack([xi[k], new[k]]).T])
        x, b = xi[k][:, cols], new[k][:, cols]
        A, B, C, D = mt.step(k)
        u = mt.gain(k) @ x + b
        nxt = np.vectorize(lambda v: coarsen(v, mt.bits), otypes=[object])(
            A @ x + mt.s * (B @ u))
        parts = []
        for rows in (u, C @ x + mt.s * (D @ u), nxt):
            full = np.full((rows.shape[0], xi0.shape[1]), zero, dtype=object)
            full[:, cols] = rows
            parts.append(full)
        U.append(parts[0])
        Y.append(parts[1])
        xi.append(parts[2])
    return xi, Y, U


def build_structure(mt: PEPFrame, steps: int, measure: Sequence[Term],
                    initial: Sequence[Term], option: tuple[str, str] = ("--measure",
                                                                       "--initial")
                    ) -> PEPStructure:
    """The PEP of ``steps`` steps (see the module docstring); on an exact method, built
    once per (steps, terms) and kept on the method (nothing downstream changes it)."""
    from sosalgo.worstcase.contraction import is_contraction

    key = (steps, repr(list(measure)), repr(list(initial)), option)
    if mt.exact and key in mt.structures:
        return mt.structures[key]
    if is_contraction(measure, initial):  # two runs (:mod:`sosalgo.worstcase.contraction`)
        if mt.adjoint is not None:
            raise InputError(f"{option[0]}: contraction: not with transpose calls")
        st = _contraction_structure(mt, steps, measure, initial)
    else:
        st = _build_structure(mt, steps, measure, initial, option)
    if mt.exact:
        mt.structures[key] = st
    return st


def _contraction_structure(mt: PEPFrame, steps: int, measure: Sequence[Term],
                           initial: Sequence[Term]) -> PEPStructure:
    """The PEP of the contraction measure (:mod:`sosalgo.worstcase.contraction`): no points,
    no values, the two-point conditions as extra rows."""
    from sosalgo.worstcase.contraction import contraction_parts, contraction_size

    d = contraction_size(mt, steps)
    eye = np.eye(d) if not mt.exact else _obj_eye(d)
    c = contraction_parts(mt, steps, measure, initial, eye)
    dt = object if mt.exact else float
    return PEPStructure(steps, steps, c["basis"], [[] for _ in mt.functions], 0, [],
                        [lab for lab, _, _ in c["extras"]], c["meas"], np.zeros(0, dtype=dt),
                        c["init"], np.zeros(0, dtype=dt),
                        {k: c[k] for k in ("xi", "y", "u", "x")}, {}, True,
                        extras=c["extras"])


def _build_structure(mt: PEPFrame, steps: int, measure: Sequence[Term],
                     initial: Sequence[Term], option: tuple[str, str]) -> PEPStructure:
    p, J, n = mt.p, len(mt.functions), mt.n
    free = free_start(initial)
    _check_alone(mt)
    origin = _check_nonconvex(mt, measure, initial, option)
    n0 = n if free else 1
    needs_n = mt.output is not None or any(
        re.fullmatch(r"y\d+", q.removeprefix(GRAD_OF)) for t in [*measure, *initial]
        for q in t.point.split("__"))
    calls = steps + 1 if needs_n and mt.per_step is None else steps  # see last_calls
    if mt.line_search:  # a call at x_N: its gradient enters the last step's equalities
        calls = steps + 1
    extra_cap = J * (len(measure) + len(initial)) + J + 1
    g0 = mt.G0 is not None and not free
    dmax = n0 + (J - 1) + p * calls + extra_cap + (len(mt.errors) + mt.line_search
                                                     + 2 * len(mt.epsilons)) * calls
    dmax += sum(cls.anchored for _, cls, _ in mt.functions)  # each origin o: a column
    eye = np.eye(dmax) if not mt.exact else _obj_eye(dmax)
    cols = [f"xi0_{a + 1}-xi*" for a in range(n)] if free else ["x0-x*"]
    nfree = J - 1 if mt.adjoint is None else 0  # transpose calls: every s_j* = 0
    S = eye[n0:n0 + nfree]  # the free optimal subgradients / s
    cols += [f"s*_{mt.functions[j][0]}/s" for j in range(nfree)]
    sstar = [S[j] for j in range(nfree)] + ([-S.sum(axis=0)] if nfree else [])
    sstar += [eye[0] * 0] * (J - len(sstar))
    if mt.adjoint is not None:  # (:mod:`sosalgo.worstcase.adjoint`)
        from sosalgo.worstcase.adjoint import check_start

        check_start(mt, free, option[1])
    cols += [f"b_{_call_label(i, k, p)}" for k in range(calls) for i in range(p)]
    if g0:  # g_j(x0) / s: its own column
        cols.append(f"g_{mt.functions[mt.smooth][0]}(x0)/s")
    if free:
        xi0 = eye[:n]
    elif origin:  # no x*: the origin at x_0, the column x0-x* unused (dropped)
        xi0 = np.outer(mt.X0, eye[0] * 0)
    else:
        xi0 = np.outer(mt.X0, eye[0]) - (mt.s * (mt.Xs @ S) if nfree else 0)
        if g0:  # + G0 g0, g0 / s = its tilted column + s_j* / s
            xi0 = xi0 + np.outer(mt.G0, (eye[len(cols) - 1] + sstar[mt.smooth]) * mt.s)
    base = n0 + nfree
    new = [eye[base + p * k: base + p * (k + 1)] for k in range(calls)]
    if mt.line_search:
        from sosalgo.worstcase.linesearch import line_search_trajectory

        if g0 or free or origin:
            raise InputError(f"{option[1]}: a line search starts at x_0 (no initial_state "
                             "gradient, no sdist, a convex class)")
        xi, Y, U = line_search_trajectory(mt, xi0, new, calls, steps, cols, eye)
    else:
        xi, Y, U = _trajectory(mt, xi0, new, calls)
    Yr = [[Y[k][i] for i in range(p)] for k in range(calls)]  # one object per call point
    out = _output_row(mt, xi, Yr, steps)
    x0 = _output_row(mt, xi, Yr, 0) if free else eye[0] * 0 if origin else eye[0]
    if not free and not g0 and mt.x0_call is not None:  # the same point, proven exactly
        Yr[0][mt.x0_call] = x0
    where = {"x": out, "x0": x0, REST: x0}  # REST: sdist(x_0), at the start
    where.update({f"y{i + 1}": Yr[steps][i] for i in range(p)} if calls > steps else {})
    if last_calls(mt):  # the calls of the last step
        where.update({f"y{i + 1}": Yr[steps - 1][i] for i in range(p)})
    pts: list[list[PEPPoint]] = [[] for _ in range(J)]
    nF = 0
    valued = [cls.has_values for _, cls, _ in mt.functions]  # an operator: no F entries
    for k in range(calls):
        for i, j in enumerate(mt.oracles):
            if i in mt.twins:  # the true subgradient of another call's point: no point
                continue
            flip = mt.adjoint is not None and i in mt.adjoint["negated"]  # M' = -M
            pts[j].append(PEPPoint(_call_label(i, k, p), Yr[k][i], -U[k][i] if flip
                                   else U[k][i], nF if valued[j] else None, k))
            nF += valued[j]
    zero = eye[0] * 0
    at = {}
    if g0:  # the point x0 of the smooth function, with the gradient g0 of the start
        pts[mt.smooth].append(PEPPoint("x0", eye[0], eye[len(cols) - 1], nF))
        at[("x0", mt.smooth)] = len(pts[mt.smooth]) - 1
        nF += 1
    from sosalgo.worstcase.inexact import inexact_calls

    extras = inexact_calls(mt, pts, U, sstar, cols, eye)
    from sosalgo.worstcase.epsilon import epsilon_calls

    eps_rows, eps_values, eps_consts, nF = epsilon_calls(
        mt, pts, cols, eye, nF, lambda lab, x, g, f: PEPPoint(lab, x, g, f))
    extra_values = {len(extras) + e: v for e, v in eps_values.items()}
    extra_consts = {len(extras) + e: c for e, c in eps_consts.items()}
    extras += eps_rows
    if mt.line_search:
        from sosalgo.worstcase.linesearch import line_search_rows

        extras += line_search_rows(mt, pts, Y, U, steps)
    for j, (fname, cls, _) in enumerate(mt.functions):
        if cls.anchored:  # its origin o: a free point, tilted value 0 and subgradient 0
            pts[j].append(PEPPoint(anchor_label(fname), eye[len(cols)], zero, None))
            cols.append(f"{anchor_label(fname)}-x*")
    for j in range(J):
        pts[j].append(PEPPoint("x*", zero, zero, None))
    state = {"nF": nF, "next": len(cols), "cols": cols, "eye": eye, "at": at, "origin": origin,
             "xi": {"x": xi[steps], "x0": xi[0], REST: xi[0]}, "extras": extras,
             "extra_values": extra_values, "extra_consts": extra_consts}
    if mt.lmo:
        from sosalgo.worstcase.lmo import lmo_points

        lmo_points(mt, pts, Yr, U, sstar, state, where, steps)
    forms = {}
    for key, terms, opt in (("m", measure, option[0]), ("i", initial, option[1])):
        forms[key] = []
        for t in at_steps(list(terms), steps, opt):
            if t.kind in MIN_OF:
                raise InputError(f"{opt}: {t.kind}: expand it first (terms.expand_min)")
            rows = [_point_row(mt, xi, Yr, where, q.removeprefix(GRAD_OF), steps, opt)
                    for q in t.point.split("__")]
            if t.kind == DIFF_KIND:  # |P - Q|^2
                v = rows[0] - rows[1]
                forms[key].append((np.outer(v, v) * mt.coef(t), {}))
                continue
            if t.kind == INNER_KIND:  # <P, Q>, each a point or a (sub)gradient there
                a, b = (_inner_row(mt, q, r, pts, sstar, state, opt, steps)
                        for q, r in zip(t.point.split("__"), rows, strict=True))
                half = Fraction(1, 2) if mt.exact else 0.5
                forms[key].append(((np.outer(a, b) + np.outer(b, a)) * (mt.coef(t) * half),
                                   {}))
                continue
            if t.kind == FREE_KIND:  # frees the start only
                forms[key].append((0 * np.outer(rows[0], rows[0]), {}))
                continue
            forms[key].append(_term(mt, t, rows[0], pts, sstar, state, opt, steps))
    if mt.constraints:
        _constraints(mt, steps, xi, Yr, where, pts, sstar, state)
    if mt.adjoint is not None:
        from sosalgo.worstcase.adjoint import adjoint_rows

        state["extras"] += adjoint_rows(mt, pts)
    st = _finish(mt, steps, calls, state, pts, forms, {"xi": xi, "y": Y, "u": U, "x": out})
    st.bare = not initial
    st.margin_seen = mt.span_search
    return st


def _inner_row(mt: PEPFrame, key: str, row: np.ndarray, pts: list[list[PEPPoint]],
               sstar: list[np.ndarray], state: dict[str, Any], opt: str,
               steps: int) -> np.ndarray:
    """The vector of one side of an inner term: the point's row (x - x*), or for
    ``G<point>`` the sum of the functions' (sub)gradients there (the call's own at a
    call, else a new one where the function is finite everywhere)."""
    if not key.startswith(GRAD_OF):
        return row
    point = key[len(GRAD_OF):]
    label = {"x": f"x{steps}"}.get(point) or (
        point if STEP_POINT.match(point) else f"{point}_{steps}")
    v = 0 * row
    for j in range(len(mt.functions)):
        pt = _point_at(mt, j, row, pts, label, state, opt, point)
        v = v + (pt.g if pt.answer is None else pt.answer) + sstar[j]
    return v * mt.s


def _constraints(mt: PEPFrame, steps: int, xi: list[np.ndarray], Yr: list[list[np.ndarray]],
                 where: dict[str, np.ndarray], pts: list[list[PEPPoint]],
                 sstar: list[np.ndarray], state: dict[str, Any]) -> None:
    """The rows of the constraints on the instance (:mod:`sosalgo.worstcase.constraints`)."""
    from sosalgo.worstcase.constraints import constraint_rows

    def label(key: str) -> str:
        return {"x": f"x{steps}"}.get(key) or (key if STEP_POINT.match(key)
                                                else f"{key}_{steps}")

    def value_at(row: np.ndarray, key: str, opt: str) -> dict[int, Any]:
        out: dict[int, Any] = {}
        for j, (name, cls, _) in enumerate(mt.functions):
            if not cls.has_values:
                raise InputError(f"{opt}: f: {name} ({cls.name}) is an operator class, it "
                                 "has no function values")
            pt = _point_at(mt, j, row, pts, label(key), state, opt, key)
            out[pt.f] = out.get(pt.f, 0) + mt.s
        return out

    state.setdefault("extra_values", {})
    state.setdefault("extra_consts", {})
    constraint_rows(mt, steps, lambda q, opt: _point_row(mt, xi, Yr, where, q, steps, opt),
                    lambda row, key, opt: _grad_row(mt, row, pts, sstar, state, opt,
                                                    label(key), key),
                    value_at, state)


def _point_row(mt: PEPFrame, xi: list[np.ndarray], Yr: list[list[np.ndarray]],
               where: dict[str, np.ndarray], point: str, steps: int, opt: str) -> np.ndarray:
    """The row of a term's point (``where``: the points known so far, extended by the
    outputs x_k a term names)."""
    call = CALL_AT.match(point)
    if call and point not in where:  # call i at step k
        i, k = int(call.group(1)), int(call.group(2))
        if k >= len(Yr):
            raise InputError(f"{opt}: y{i}_{k}: the method makes its calls at steps "
                             f"0..{len(Yr) - 1} here (N = {steps})")
        where[point] = Yr[k][i - 1]
    if point == OUT0 and point not in where:  # the output at step 0 (x_N-j at N = j)
        where[point] = where["x0"] if last_calls(mt) else _output_row(mt, xi, Yr, 0)
    step = STEP_POINT.match(point)
    if step and point not in where:
        if int(step.group(1)) > steps:
            raise InputError(f"{opt}: x_{step.group(1)}: after the last step (N = {steps})")
        where[point] = _output_row(mt, xi, Yr, int(step.group(1)))
    if point not in where:
        raise InputError(f"{opt}: {point}_N: no such point")
    return where[point]


def _check_alone(mt: PEPFrame) -> None:
    """InputError unless a class whose conditions hold for the function itself (not the
    tilted one: ``alone``) is the only function, started at x_0 (its optimal subgradient
    is then 0, so its tilted data are its own)."""
    alone = [f"{name} ({cls.name})" for name, cls, _ in mt.functions if cls.alone]
    if alone and (len(mt.functions) > 1 or mt.G0 is not None):
        raise InputError(f"functions: {alone[0]}: its conditions bound the function itself "
                         "(not up to a linear term): its PEP takes it as the only function, "
                         "started at x_0 (no initial_state gradient)")


def _check_nonconvex(mt: PEPFrame, measure: Sequence[Term], initial: Sequence[Term],
                     option: tuple[str, str]) -> bool:
    """Whether the PEP has no x* (a nonconvex class: a stationary point below the points
    is not a minimizer, :mod:`sosalgo.classes.smooth`): then one function, no term about
    x* (dist, sdist), and f only in differences (the f terms' coefficients sum to 0, so
    that f* cancels; checked on floats). InputError naming the option otherwise."""
    bad = [f"{name} ({cls.name})" for name, cls, _ in mt.functions
           if not cls.convex and not cls.minimizer]
    if not bad:
        return False
    if len(mt.functions) > 1 or mt.G0 is not None:
        raise InputError(f"functions: {bad[0]} is nonconvex: its PEP takes one function "
                         "started at x_0 (no initial_state gradient)")
    for terms, opt in ((measure, option[0]), (initial, option[1])):
        near = [t.kind for t in terms if t.kind in ("dist", "sdist")]
        if near:
            raise InputError(f"{opt}: {near[0]}: {bad[0]} is nonconvex, its PEP has no "
                             "minimizer x* (use grad, mingrad or differences of f)")
        if not mt.exact and any(t.kind == "f" for t in terms):
            total = sum(float(mt.coef(t)) for t in terms if t.kind == "f")
            if abs(total) > 1e-12 * sum(abs(float(mt.coef(t))) for t in terms):
                raise InputError(f"{opt}: f - f*: {bad[0]} is nonconvex, its PEP has no "
                                 "minimum f*; use differences such as f(x_0) - f(x_N)")
    return True


def _output_row(mt: PEPFrame, xi: list[np.ndarray], Yr: list[list[np.ndarray]],
                k: int) -> np.ndarray:
    """The output's row at step k: the very row object of the output call when the
    output is a call (``output: y<i>``, or E = C_i with D_i = 0: :attr:`PEPFrame.out_call`)
    and that call is made at step k — the same point by construction, so a term there
    reads the call's subgradient and value, in floats and in exact numbers alike (a
    numerical comparison of ball rows cannot prove them equal) — else E xi_k."""
    if last_calls(mt) and mt.output is not None and k >= 1:
        return Yr[k - 1][mt.output]
    call = mt.output if mt.output is not None else mt.out_call
    if call is not None and k < len(Yr):
        return Yr[k][call]
    return (mt.E @ xi[k])[0]


def anchor_label(fname: str) -> str:
    """The label of function ``fname``'s origin o (an ``anchored`` class)."""
    return f"{ANCHOR}_{fname}"


def last_calls(mt: PEPFrame) -> bool:
    """Whether the output call and the ``y`` terms after N steps are the calls of step
    N - 1 (a method that changes with k: its N per-step methods make N calls, the N-th
    one's prox point is x_N, as PEPit counts FISTA), not those of a step N."""
    return mt.per_step is not None


def output_call(E: Any, C: Any, D: Any, same: Callable[[Any, Any], bool]) -> int | None:
    """The first call i whose point is the output x = E xi for every state and answer
    (E = C_i, D_i = 0), by ``same`` on the rows; None when there is none."""
    if E is None:
        return None
    for i in range(C.shape[0]):
        if same(E[0], C[i]) and same(D[i], 0 * D[i]):
            return i
    return None


def _finish(mt: PEPFrame, steps: int, calls: int, state: dict[str, Any],
            pts: list[list[PEPPoint]], forms: dict[str, list[Any]],
            rows: dict[str, Any]) -> PEPStructure:
    """Drop the unused columns, sum the terms' forms, list the pairs."""
    J = len(mt.functions)
    d = state["next"]
    n0 = sum(1 for c in state["cols"] if c.startswith(("xi0_", "x0-")))
    cons = [X.T @ X for k, (_, X, _) in enumerate(state["extras"])
            if k in state.get("extra_values", {})]  # a constraint's squared terms
    used = _used_columns(pts, [q for q, _ in forms["m"] + forms["i"]] + cons, n0,
                         J if mt.adjoint is None else 1, d)
    keep = [c for c in range(d) if used[c]]
    nF = state["nF"]
    dt = object if mt.exact else float
    for fp in pts:
        for pt in fp:
            pt.x, pt.g = pt.x[keep], pt.g[keep]
            if pt.answer is not None:
                pt.answer = pt.answer[keep]
    meas_q, meas_f = _sum_forms([q for q, _ in forms["m"]], [f for _, f in forms["m"]],
                                keep, nF, dt)
    init_q, init_f = _sum_forms([q for q, _ in forms["i"]], [f for _, f in forms["i"]],
                                keep, nF, dt)
    pairs, labels, consts = [], [], []
    for j, (fname, cls, _) in enumerate(mt.functions):
        many = len(mt.ineqs[j]) > 1
        # a nonconvex class has no minimizer in its PEP (unless it assumes one): no x* pairs
        star = cls.convex or cls.minimizer
        for a, pa in enumerate(pts[j]):
            for b, pb in enumerate(pts[j]):
                if a != b and (star or "x*" not in (pa.label, pb.label)):
                    for r in range(len(mt.ineqs[j])):
                        if mt.scope(j, r) == "optimum" and pb.label != "x*":
                            continue  # a condition between a point and x* only
                        if mt.scope(j, r) == "anchor" and (pa.label == "x*" or pb.label
                                                           != anchor_label(fname)):
                            continue  # a condition between a point and the origin o
                        if _vanishes(mt, j, r, pa, pb):
                            continue  # 0 >= 0 (an indicator's own condition at x*)
                        pairs.append((j, a, b, r))
                        labels.append(pair_label(fname, pa.label, pb.label, r, many))
                        consts.append(mt.constant(j, r))
    extras = [(lab, X[:, keep], Qc) for lab, X, Qc in state["extras"]]
    anchors = {anchor_label(f) for f, cls, _ in mt.functions if cls.anchored}
    # two calls at one point (an indicator's normal vectors at x_0 taken twice): their
    # conditions both ways pin the values equal, no slack to give either
    equal = [bool(anchors & {pts[j][a].label, pts[j][b].label})
             or _same_point(pts[j][a], pts[j][b]) for j, a, b, _ in pairs]
    values = {}
    for k, fs in state.get("extra_values", {}).items():  # constraints' values, on F
        values[k] = np.zeros(nF, dtype=dt)
        for f, v in fs.items():
            values[k][f] = values[k][f] + v
    labels += [lab for lab, _, _ in extras]
    cut = {"xi": [x[:, keep] for x in rows["xi"]], "y": [y[:, keep] for y in rows["y"]],
           "u": [u[:, keep] for u in rows["u"]], "x": rows["x"][keep]}
    st = PEPStructure(steps, calls, [state["cols"][c] for c in keep], pts, nF, pairs,
                      labels, meas_q, meas_f, init_q, init_f, cut, state["at"],
                      state["origin"], extras=extras, extra_values=values)
    if any(equal):
        st.equalities = np.array(equal + [False] * len(extras))
    st.blocks = [(j, r, [a for a, pt in enumerate(pts[j]) if pt.label != "x*"])
                 for j, fb in enumerate(mt.blocks) for r in range(len(fb))]
    st.lmis = _lmi_tuples(mt, pts)
    zero = Fraction(0) if mt.exact else 0.0
    rest = [state.get("extra_consts", {}).get(e, zero) for e in range(len(extras))]
    if any(_nonzero(c) for c in consts + rest):  # one constant per row: pairs, then extras
        st.constants = np.array(consts + rest, dtype=dt)
    return st


def _same_point(pa: PEPPoint, pb: PEPPoint) -> bool:
    """Whether two points of a function have the same x (as rows on the basis)."""
    return pa.label != pb.label and all(u == v for u, v in zip(pa.x, pb.x, strict=True))


def _lmi_tuples(mt: PEPFrame, pts: list[list[PEPPoint]]
                ) -> list[tuple[int, int, tuple[int, ...]]]:
    """(function, LMI, tuple) of every class LMI: each ordered tuple of the function's
    points (x* among them when the PEP keeps it for the class) that are not all the
    same point, x* appended when the LMI asks for it."""
    from itertools import product

    out = []
    for j, fl in enumerate(mt.lmis):
        cls = mt.functions[j][1]
        star = [a for a, pt in enumerate(pts[j]) if pt.label == "x*"]
        keep = [a for a, pt in enumerate(pts[j])
                if pt.label != "x*" or cls.convex or cls.minimizer]
        for r, lmi in enumerate(fl):
            if lmi.optimum and not star:
                continue
            for idx in product(keep, repeat=lmi.arity):
                if len(set(idx)) > 1:
                    out.append((j, r, idx + ((star[0],) if lmi.optimum else ())))
    return out


def _vanishes(mt: PEPFrame, j: int, r: int, pa: PEPPoint, pb: PEPPoint) -> bool:
    """Whether function j's inequality r between points a and b is 0 >= 0 whatever G
    and F: no value (alpha 0), no constant, and each entry of its Q meets a zero row of
    (x_a, x_b, g_a, g_b) (a subgradient pinned at 0 at x*: indicators alone)."""
    alpha, Q = mt.ineqs[j][r]
    if _nonzero(alpha) or _nonzero(mt.constant(j, r)):
        return False
    live = [any(_nonzero(v) for v in row) for row in (pa.x, pb.x, pa.g, pb.g)]
    return not any(_nonzero(Q[u][v]) and live[u] and live[v]
                   for u in range(4) for v in range(4))


def _obj_eye(k: int) -> np.ndarray:
    out = np.full((k, k), Fraction(0), dtype=object)
    for i in range(k):
        out[i, i] = Fraction(1)
    return out


def _point_at(mt: PEPFrame, j: int, row: np.ndarray, pts: list[list[PEPPoint]], label: str,
              state: dict[str, Any], opt: str, key: str) -> PEPPoint:
    """Function j's point at ``row``: one of its points there, or a new one (a new
    subgradient column and value) when the function is finite everywhere."""
    for a, pt in enumerate(pts[j]):
        if pt.label != "x*" and (pt.x is row or mt.same(pt.x, row)):
            state["at"][(key, j)] = a
            return pt
    name, cls, _ = mt.functions[j]
    if not cls.finite_everywhere and j not in {mt.oracles[i] for i in mt.epsilons}:
        raise InputError(f"{opt}: {name} ({cls.name}) is not evaluated at {label}: it may "
                         "be infinite there; use a point where the method queries it or "
                         "dist")
    k = state["next"]
    state["next"] += 1
    state["cols"].append(f"g_{name}({label})/s")
    pt = PEPPoint(label, row, state["eye"][k], state["nF"] if cls.has_values else None)
    state["nF"] += cls.has_values
    pts[j].insert(len(pts[j]) - 1, pt)  # x* stays last
    state["at"][(key, j)] = len(pts[j]) - 2
    return pt


def _term(mt: PEPFrame, t: Term, row: np.ndarray, pts: list[list[PEPPoint]],
          sstar: list[np.ndarray], state: dict[str, Any], opt: str,
          steps: int) -> tuple[np.ndarray, dict[int, Any]]:
    """(quadratic form on the basis, {F index: coefficient}) of one term."""
    c = mt.coef(t)
    label = {"x": f"x{steps}"}.get(t.point) or (
        t.point if STEP_POINT.match(t.point) or t.point == OUT0 else f"{t.point}_{steps}")
    if t.kind == "dist":
        return np.outer(row, row) * c, {}
    if t.kind == "sdist":
        X = state["xi"][t.point]
        return sum(np.outer(r, r) for r in X) * c, {}
    if t.kind == "f":
        valueless = [f"{n} ({cls.name})" for n, cls, _ in mt.functions if not cls.has_values]
        valued = [j for j, (_, cls, _) in enumerate(mt.functions) if cls.has_values]
        if mt.adjoint is not None and (len(valued) != 1 or mt.adjoint["plain"]):
            raise InputError(f"{opt}: f: with transpose calls f(P) is the value of the one "
                             "function with values, with optimality: [M.T(g)] alone (use "
                             "dist or sdist)")
        if mt.adjoint is not None:  # g is composed with M: at its calls' points only
            hit = [pt for pt in pts[valued[0]] if pt.label != "x*" and
                   (pt.x is row or mt.same(pt.x, row))]
            if not hit:
                raise InputError(f"{opt}: f({t.point}): {mt.functions[valued[0]][0]} is "
                                 "composed with the operator: its value is asked at the "
                                 "points of its calls (y<i>_N)")
            state["at"][(t.point, valued[0])] = pts[valued[0]].index(hit[0])
            return 0 * np.outer(row, row), {hit[0].f: c * mt.s}
        if valueless:
            raise InputError(f"{opt}: f: {valueless[0]} is an operator class, it has no "
                             "function values (use dist, grad or dist(P, Q))")
        fs: dict[int, Any] = {}
        for j in range(len(mt.functions)):
            pt = _point_at(mt, j, row, pts, label, state, opt, t.point)
            fs[pt.f] = fs.get(pt.f, 0) + c * mt.s
        return 0 * np.outer(row, row), fs
    v = _grad_row(mt, row, pts, sstar, state, opt, label, t.point)
    return np.outer(v, v) * c, {}


def _grad_row(mt: PEPFrame, row: np.ndarray, pts: list[list[PEPPoint]],
              sstar: list[np.ndarray], state: dict[str, Any], opt: str, label: str,
              key: str) -> np.ndarray:
    """The row of the gradient of the smooth part (the functions with a gradient oracle)
    at the point ``row``."""
    smooth = ([j for j, (_, cls, _) in enumerate(mt.functions) if "gradient" in cls.oracles]
              or [j for j in {mt.oracles[i] for i in mt.epsilons}])  # else the eps calls'
    if mt.adjoint is not None:
        raise InputError(f"{opt}: grad: not with transpose calls (the gradient of g(Mx) is "
                         "M^T grad g(Mx); use dist, sdist or f)")
    if not smooth:
        raise InputError(f"{opt}: grad: no smooth function (a class with a gradient "
                         "oracle) in this spec")
    v = 0 * row
    for j in smooth:
        pt = _point_at(mt, j, row, pts, label, state, opt, key)
        v = v + (pt.g if pt.answer is None else pt.answer) + sstar[j]
    return v * mt.s


def _used_columns(pts: list[list[PEPPoint]], forms: list[np.ndarray], n0: int, J: int,
                  d: int) -> list[bool]:
    """Columns some point or term uses: the first d, minus optimal subgradients that appear
    nowhere (they would be free directions of G)."""
    used = [c < d for c in range(len(pts[0][0].x))]
    if n0 == 1:  # x0-x*: unused when the PEP has no x* (its origin at x_0)
        used[0] = (any(_nonzero(pt.x[0]) or _nonzero(pt.g[0]) for fp in pts for pt in fp)
                   or any(_nonzero(v) for q in forms for v in q[0]))
    for c in range(n0, n0 + J - 1):  # (floats: a rounding residue of a column that
        # cancels exactly, e.g. -X_s s* + G0 s* of a start x0 + t g0, is no use)
        used[c] = (any(_live(pt.x[c]) or _live(pt.g[c]) for fp in pts for pt in fp)
                   or any(_live(v) for q in forms for v in q[c]))
    return used


def _live(v: Any) -> bool:
    """A nonzero entry (exact), or a float entry above rounding residue (1e-13)."""
    return _nonzero(v) if not isinstance(v, float | np.floating) else bool(abs(v) > 1e-13)


def _nonzero(v: Any) -> bool:
    if hasattr(v, "c"):
        return bool(v.c != 0 or v.r != 0)
    return bool(v != 0)


def _sum_forms(qs: Sequence[np.ndarray], fs: Sequence[dict[int, Any]], keep: list[int],
               nF: int, dt: Any) -> tuple[np.ndarray, np.ndarray]:
    d = len(keep)
    Q = np.zeros((d, d), dtype=dt)
    f = np.zeros(nF, dtype=dt)
    for q in qs:
        Q = Q + q[np.ix_(keep, keep)]
    for fd in fs:
        for k, v in fd.items():
            f[k] = f[k] + v
    return Q, f
