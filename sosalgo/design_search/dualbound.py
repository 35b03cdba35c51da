"""Lower bounds for design (eq. 17) by dual certificates that hold over whole boxes.

For fixed θ and r = ρ², a family's inequalities ``G_b(x; r) ⪯ 0`` (Theorem 1: M ⪯ 0 of
eq. 15, -P ⪯ 0, -λ ≤ 0) have no solution x when there are Z_b ⪰ 0 with

    Σ_b <Z_b, L_{b,i}(θ, r)> = 0 for every variable x_i,   Σ_b <Z_b, C_b(θ, r)> > 0     (F)

(Farkas: Σ_b <Z_b, G_b(x)> would be both <= 0 and > 0). Blocks that are plain cones on the
variables and do not depend on θ or r ("cone blocks": P ⪰ 0 and λ >= 0) absorb the first
condition: their Z is *determined* by the others, Z_c(θ, r) = -Φ_c^{-1}(g(θ, r)), and only
has to stay ⪰ 0. So one dual point Z of the remaining blocks, affine in θ and computed by a
small SDP for a box of (θ, r), proves (F) on the whole box when

    h(θ, r) = Σ <Z_b, C_b(θ, r)> > 0   and   Z_c(θ, r) ⪰ 0   for all (θ, r) in the box.

What is floating point and what is proven:

* floating point (it proposes or rejects, it never makes a box proven): the SDP that finds
  Z (Clarabel), the repair of Z and of its covers S, the screening of (F) with a safety
  margin (``_holds``) and the bisection on r that picks the r to prove;
* proven in ball arithmetic (python-flint ``arb``, outward rounding) on the exact
  polynomial data (:mod:`sosalgo.design_search.polymodel`): every box counted as proven, by
  :mod:`sosalgo.design_search.boxproof` (the data shifted to the box, both ends of the r-interval
  since the conditions are affine in r, the θ-variation bounded by the box's Taylor
  coefficients) or, near degenerate faces, by the mode argument of
  :mod:`sosalgo.design_search.modes` (a visible mode slower than T on a quadratic);
* the reported bound is the square root of the smallest proven r, rounded down.

A proven box contains no θ that the family certifies at any ρ² in the box's r-range.

Branch and bound covers Θ × [0, T²] by proven boxes, which proves that no θ ∈ Θ is
certified below T. Unlike the homogenized moment relaxation, the f - f* term keeps its
coefficient 1, so degenerate "certificates" with c = 0 and singular P are excluded by
construction.
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
import scipy.sparse as sps

from sosalgo.design_search.boxproof import BoxProver
from sosalgo.design_search.modes import ModeTest
from sosalgo.design_search.polymodel import PolyLMI
from sosalgo.kernel.solvers import (
    SolverStatus,
    clarabel_solve,
    finite_data,
    quiet_settings,
    solver_status,
    svec,
)

__all__ = ["BoundStatus", "DualStructure", "BoundSearch", "dual_structure"]

MIN_HALF_WIDTH = 1e-10  # boxes narrower than this (in scaled units) are not split further
SAFETY = 1e-9  # relative margin of the float screening (the proofs need none)
ARITHMETIC = "ball arithmetic (python-flint arb, outward rounded) on exact polynomial data"


class BoundStatus(StrEnum):
    """What a bound search proved (a str: compares and serializes as one)."""

    PROVED = "proved"  # Θ × [0, T²] covered by proven boxes: nothing in Θ certified below T
    PARTIAL = "partial"  # boxes left open (time, or no proof near them): what was covered
    UNSUPPORTED = "unsupported"  # the family's variables are not all in θ-free cones


@dataclass
class DualStructure:
    """Which blocks get a dual matrix from the SDP (``dep``) and which are cone blocks
    reconstructed from it (``cone``: block index, variables, map R with
    Z_c = -Σ_i R[..., i] g_i)."""

    dep: list[int]
    cone: list[tuple[int, list[int], np.ndarray]]


def dual_structure(model: PolyLMI) -> DualStructure | None:
    """Split the blocks as above; None when some variable is in no cone block (then a
    box-wide dual certificate would need an exact polynomial identity: not supported)."""
    k = model.k
    dep, cone = [], []
    owner: dict[int, int] = {}
    nvar = model.template.nvar
    for b in range(len(model.names)):
        co = model.coef[b]
        const_free = not (np.any(co["c0"]) or np.any(co["c1"]) or np.any(co["l1"]))
        if const_free and not model.depends_on_theta(b):
            l0 = co["l0"][(0,) * k]  # (nvar, s, s)
            vars_ = [i for i in range(nvar) if np.any(l0[i])]
            s = l0.shape[-1]
            pairs = [(a, c) for a in range(s) for c in range(a, s)]
            if len(vars_) == len(pairs) and not any(i in owner for i in vars_):
                Phi = np.array([[l0[i, a, c] * (1.0 if a == c else 2.0) for a, c in pairs]
                                for i in vars_])
                if np.linalg.matrix_rank(Phi) == len(pairs):
                    inv = np.linalg.inv(Phi)  # entries of Z_c from (<Z_c, l0_i>)_i
                    R = np.zeros((s, s, len(vars_)))
                    for q, (a, c) in enumerate(pairs):
                        R[a, c] = R[c, a] = inv[q]
                    cone.append((b, vars_, R))
                    for i in vars_:
                        owner[i] = b
                    continue
        dep.append(b)
    if len(owner) != nvar or not dep:
        return None
    return DualStructure(dep, cone)


@dataclass
class _Box:
    zc: np.ndarray  # center and half-widths in scaled coordinates z
    w: np.ndarray
    lb: float = 0.0  # r = ρ² below which the box is already proven empty

    def key(self) -> tuple[float, float]:
        return (self.lb, -float(self.w.max()) if self.w.size else 0.0)


@dataclass
class BoundState:
    """Progress of a bound search: counts and the boxes still open."""

    target: float  # r = ρ² up to which boxes are being proven empty
    proven: int = 0
    quadratic: int = 0  # of which proven by the mode argument
    dual: int = 0  # of which proven by a dual certificate
    refuted: int = 0  # float screening passed, the ball-arithmetic proof did not
    solves: int = 0
    stuck: list[_Box] = field(default_factory=list)
    heap: list[tuple[tuple[float, float], int, _Box]] = field(default_factory=list)
    record: list[tuple[np.ndarray, np.ndarray, float, str]] | None = None  # proven boxes
    proofs: list[dict] = field(default_factory=list)  # every proof made: the certificate

    def done(self, box: _Box, r: float, how: str) -> None:
        """Count a box proven empty for ρ² < r (``how``: dual / mode / inherited)."""
        self.proven += 1
        self.quadratic += how == "mode"
        self.dual += how == "dual"
        if self.record is not None:
            self.record.append((box.zc.copy(), box.w.copy(), r, how))

    def proved(self, box: _Box, r: float, how: str, Zs=None, bounds=None,
               covers=None) -> None:
        """Keep a proof that the box holds no certificate for ρ² in [0, r] (``how``:
        dual, with its dual matrices and covers, or mode): the bound's certificate
        (:func:`sosalgo.design_search.boundcheck.bound_certificate`)."""
        self.proofs.append({"z": box.zc.copy(), "w": box.w.copy(), "r": float(r),
                            "how": how, "Z": Zs, "bounds": bounds, "covers": covers})

    def lower_r(self) -> float:
        """Largest r proven: no θ of Θ is certified with ρ² below it."""
        opens = [b.lb for b in self.stuck] + [item[2].lb for item in self.heap]
        return min([self.target, *opens])

    def lower_bound(self) -> float:
        """The proven bound on ρ: a float <= sqrt(lower_r()) (rounded down)."""
        r = max(0.0, self.lower_r())
        return float(np.nextafter(math.sqrt(r), 0.0)) if r > 0 else 0.0

    @property
    def complete(self) -> bool:
        return not self.stuck and not self.heap


class BoundSearch:
    """Best-first branch and bound over Θ: each box needs one dual point Z valid on the
    whole box for every r in [0, T²] (found by a robust SDP, screened in floats, proven in
    ball arithmetic by :class:`~sosalgo.design_search.boxproof.BoxProver`), or the mode argument
    (``modes``)."""

    def __init__(self, model: PolyLMI, structure: DualStructure, target_r: float,
                 modes: ModeTest | None = None, record: bool = False):
        self.model, self.st, self.modes = model, structure, modes
        self.prover = BoxProver(model, structure.dep,
                                [(b, vars_) for b, vars_, _ in structure.cone])
        k = model.k
        self.state = BoundState(target=target_r, record=[] if record else None)
        self._count = 0
        self._push(_Box(np.zeros(k), np.ones(k) * (model.half > 0)))

    def _push(self, box: _Box) -> None:
        heapq.heappush(self.state.heap, (box.key(), self._count, box))
        self._count += 1

    def lower_target(self, r: float) -> None:
        """A better design was certified: only ρ² below ``r`` needs proving now."""
        self.state.target = min(self.state.target, r)

    # ------------------------------------------------------------------ data of a box
    def _box_data(self, box: _Box, w: np.ndarray) -> list[dict[str, np.ndarray]]:
        """Per dep block: coefficients in the box's local coordinates u (not flattened)."""
        m = self.model
        return [{key: m.shifted(b, key, box.zc, w) for key in ("c0", "c1", "l0", "l1")}
                for b in self.st.dep]

    def _place(self, arr: np.ndarray, j: int) -> np.ndarray:
        """Coefficients of u_j · p(u) (j = 0: p itself) on the extended monomial grid,
        flattened over monomials: shape (#monomials, *data shape)."""
        k = self.model.k
        ext = np.zeros(tuple(n + 1 for n in arr.shape[:k]) + arr.shape[k:])
        idx = tuple(slice(1, None) if i == j - 1 else slice(0, -1) for i in range(k))
        ext[idx] = arr
        return ext.reshape((-1,) + arr.shape[k:])

    def _even(self) -> np.ndarray:
        """Which extended monomials have only even exponents (so u^α ∈ [0, 1])."""
        k = self.model.k
        shape = tuple(d + 2 for d in self.model.degrees)
        grids = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
        even = np.ones(shape, dtype=bool)
        for g in grids[:k]:
            even &= g % 2 == 0
        return even.reshape(-1)

    def _sums(self, data, Zs, r: float) -> tuple[np.ndarray, np.ndarray]:
        """Coefficients of h(u) = Σ <Z_d(u), C_d(u, r)> and g_i(u) = Σ <Z_d(u), L_di(u, r)>
        for affine dual matrices Z_d(u) = Z_d0 + Σ_j u_j Z_dj."""
        h = 0.0
        g = 0.0
        for d, Zd in zip(data, Zs, strict=True):
            C = d["c0"] + r * d["c1"]
            Lm = d["l0"] + r * d["l1"]
            for j, Z in enumerate(Zd):
                h = h + self._place(np.tensordot(C, Z, axes=([-2, -1], [0, 1])), j)
                g = g + self._place(np.tensordot(Lm, Z, axes=([-2, -1], [0, 1])), j)
        return np.asarray(h), np.asarray(g)

    def _holds(self, data, Zs, r: float, bounds: dict | None = None) -> bool:
        """(F) on the whole box at this r, in floats with a safety margin. ``bounds``
        maps (cone, monomial) to the SDP's matrices S with -S ⪯ Z_c,α ⪯ S (repaired here
        before use); without them the matrix absolute value is used."""
        even = self._even()
        h, g = self._sums(data, Zs, r)
        if not _positive_lower(h, even):
            return False
        for c, (_, vars_, R) in enumerate(self.st.cone):
            Zc = -np.tensordot(g[:, vars_], R, axes=([1], [2]))  # (monomials, s, s)
            S = None if bounds is None else {a: v for (cc, a), v in bounds.items() if cc == c}
            if not _psd_lower(Zc, even, S):
                return False
        return True

    def _proven_up_to(self, box: _Box, data, Zs, r_hi: float, covers=None) -> float:
        """Largest r in [0, r_hi] with (F) proven on the box for all of [0, r] (0 if none):
        bisection on the float screening, then the proof at the r found."""
        if not self._holds(data, Zs, 0.0):
            return 0.0
        lo, hi = 0.0, r_hi  # the set of good r is an interval (concave conditions)
        if self._holds(data, Zs, r_hi):
            lo = r_hi
        else:
            for _ in range(12):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if self._holds(data, Zs, mid) else (lo, mid)
        if lo > 0 and self.prover.proves(box.zc, box.w, Zs, (None, None), (0.0, lo), covers):
            self.state.proved(box, lo, "dual", Zs, None, covers)
            return lo
        return 0.0

    # ------------------------------------------------------------------ robust dual SDP
    def _dual(self, data, r_ends: tuple[float, ...], affine: bool = True):
        """Affine dual matrices Z_d(u) = Z_d0 + Σ_j u_j Z_dj (⪰ 0 on the box) maximizing the
        worst margin of (F) over the box (|u^α| <= 1, u^α ∈ [0, 1] for even α) at each r
        in ``r_ends``; None unless the margin is > 0. ``affine=False``: constant Z.
        Returns (Zs, bounds per r of the cone matrices' coefficients, covers S_dj)."""
        lay = _Layout.build([d["c0"].shape[-1] for d in data], self.model.k, affine,
                            [R.shape[0] for _, _, R in self.st.cone], len(r_ends))
        maps = [self._r_map(data, r, lay) for r in r_ends]
        lay.live = [a for a in range(self._even().size) if a == 0 or any(
            np.any(H[a]) or np.any(Gm[a]) for H, Gm in maps)]
        rows = _Rows(lay.ny)
        _z_constraints(rows, lay)
        even = self._even()
        for e, (H, Gm) in enumerate(maps):
            _h_constraints(rows, lay, e, H, even)
            self._cone_constraints(rows, lay, e, Gm, even)
        y = self._solve_dual(rows, lay)
        return None if y is None else _read_dual(y, lay, self.model.k)

    def _r_map(self, data, r: float, lay: _Layout) -> tuple[np.ndarray, np.ndarray]:
        """The linear maps y -> h_α (H) and y -> g_α,i (Gm) at r, α over the monomials."""
        nmono = self._even().size
        H = np.zeros((nmono, lay.nzcols))
        Gm = np.zeros((nmono, self.model.template.nvar, lay.nzcols))
        for q, d in enumerate(data):
            sC = svec(d["c0"] + r * d["c1"], True)
            sL = svec(d["l0"] + r * d["l1"], True)
            for j in range(lay.nz_terms):
                c0 = lay.zoff[q][j]
                H[:, c0:c0 + lay.tri[q]] = self._place(sC, j)
                Gm[:, :, c0:c0 + lay.tri[q]] = self._place(sL, j)
        return H, Gm

    def _cone_constraints(self, rows: _Rows, lay: _Layout, e: int, Gm: np.ndarray,
                          even: np.ndarray) -> None:
        """Z_c,0 - Σ S_α - t I ⪰ 0 and S_α ∓ Z_c,α ⪰ 0 for each cone block at the e-th r
        (even α, u^α ∈ [0, 1]: S_α + Z_c,α ⪰ 0 and S_α ⪰ 0)."""
        off_c = 1
        for (_, vars_, R), ct in zip(self.st.cone, lay.ctri, strict=True):
            s = R.shape[0]
            Zmap = -np.tensordot(R, Gm[lay.live][:, vars_, :], axes=([2], [1]))  # s,s,α,y
            Mv = np.moveaxis(svec(np.moveaxis(Zmap, (2, 3), (0, 1)), True), 2, 1)
            A = np.zeros((ct, lay.ny))
            A[:, :lay.nzcols] = -Mv[0]
            A[:, lay.t_col] += svec(np.eye(s), True)
            for pos in range(1, len(lay.live)):
                c0 = lay.s_col(e, pos) + off_c
                A[:, c0:c0 + ct] += np.eye(ct)
            rows.add(A, _psd(s))
            for pos, a in enumerate(lay.live[1:], start=1):
                c0 = lay.s_col(e, pos) + off_c
                for sign in ((-1.0,) if even[a] else (1.0, -1.0)):
                    A = np.zeros((ct, lay.ny))
                    A[:, :lay.nzcols] = sign * Mv[pos]
                    A[:, c0:c0 + ct] -= np.eye(ct)
                    rows.add(A, _psd(s))
                if even[a]:
                    A = np.zeros((ct, lay.ny))
                    A[:, c0:c0 + ct] = -np.eye(ct)
                    rows.add(A, _psd(s))
            off_c += ct

    def _solve_dual(self, rows: _Rows, lay: _Layout) -> np.ndarray | None:
        """Clarabel on the assembled SDP (maximize t): y, or None unless t > 0 was found
        (solved, or almost solved: the float screening and the proof come after)."""
        q = np.zeros(lay.ny)
        q[lay.t_col] = -1.0
        A, b = np.vstack(rows.rows), np.array(rows.b)
        if not finite_data(A, b):
            return None
        settings = quiet_settings()
        settings.max_iter = 100
        try:
            sol = clarabel_solve(sps.csc_matrix((lay.ny, lay.ny)), q, sps.csc_matrix(A), b,
                                 rows.cones, settings)
        except Exception:  # noqa: BLE001 - a crash is just "no dual point"
            return None
        self.state.solves += 1
        if solver_status(sol.status) not in (SolverStatus.SOLVED, SolverStatus.ALMOST_SOLVED):
            return None
        y = np.array(sol.x)
        return y if y[lay.t_col] > 0 else None

    # ------------------------------------------------------------------ driver
    def run(
        self, deadline: float, on_open: Callable[[np.ndarray, float], float | None] | None,
        max_boxes: int = 1_000_000, on_box: Callable[[BoundState], None] | None = None,
    ) -> BoundState:
        """Prove boxes until none is left, time runs out or ``max_boxes`` were handled.

        ``on_open(z, r)`` is called when not even the box center has a dual certificate at
        r = T²: the point may be certifiable below the target. It returns a new (lower)
        target r when it certified a better design there, else None (``on_open=None``:
        the target stays, the box is split). ``on_box(state)`` is told before each box.
        """
        st = self.state
        handled = 0
        while st.heap and time.perf_counter() < deadline and handled < max_boxes:
            if on_box is not None:
                on_box(st)
            _, _, box = heapq.heappop(st.heap)
            handled += 1
            T2 = st.target
            if box.lb >= T2:
                st.done(box, box.lb, "inherited")
                continue
            if self.modes is not None and self.modes.proves(box.zc, box.w, T2):
                st.proved(box, T2, "mode")
                st.done(box, T2, "mode")
                continue
            data = self._box_data(box, box.w)
            out = self._dual(data, (0.0, T2))
            Zs = None
            cov = None
            if out is not None:
                Zs, bd, cov = out
                if self._holds(data, Zs, 0.0, bd[0]) and self._holds(data, Zs, T2, bd[1]):
                    if self.prover.proves(box.zc, box.w, Zs, bd, (0.0, T2), cov):
                        st.proved(box, T2, "dual", Zs, bd, cov)
                        st.done(box, T2, "dual")
                        continue
                    st.refuted += 1
            if Zs is None:  # is the center itself certifiable below T?
                center = self._box_data(box, np.zeros_like(box.w))
                outc = self._dual(center, (T2,), affine=False)
                Zc = None if outc is None else outc[0]
                cov = None if outc is None else outc[2]
                if Zc is None and on_open is not None:
                    new = on_open(box.zc, T2)
                    if new is not None and new < T2:
                        self.lower_target(new)
                        self._push(box)
                        continue
                else:
                    Zs = Zc
            if Zs is not None:
                box.lb = max(box.lb, self._proven_up_to(box, data, Zs, T2, cov))
            if box.lb < T2:
                box.lb = max(box.lb, self._prove_part(box, data, T2))
            self._split(box)
        return st

    def _prove_part(self, box: _Box, data, T2: float) -> float:
        """A box that resists at T²: prove it for ρ² up to halfway between what it inherited
        and T² (so a partial bound grows with every split); returns the r proven, or 0."""
        r = box.lb + 0.5 * (T2 - box.lb)
        out = self._dual(data, (0.0, r))
        if out is None:
            return 0.0
        Zs, bd, cov = out
        ok = self._holds(data, Zs, 0.0, bd[0]) and self._holds(data, Zs, r, bd[1])
        if ok and self.prover.proves(box.zc, box.w, Zs, bd, (0.0, r), cov):
            self.state.proved(box, r, "dual", Zs, bd, cov)
            return r
        return 0.0

    def _split(self, box: _Box) -> None:
        if box.w.size == 0 or box.w.max() < MIN_HALF_WIDTH:
            self.state.stuck.append(box)
            return
        i = int(np.argmax(box.w))
        w = box.w.copy()
        w[i] *= 0.5
        for sign in (-1.0, 1.0):
            zc = box.zc.copy()
            zc[i] += sign * w[i]
            self._push(_Box(zc, w, box.lb))


@dataclass
class _Layout:
    """Columns of the robust dual SDP: Z_dj (dep block d, term j), t, the S_dj bounding
    Z_dj, then for each r and each live monomial α ≠ 0 a scalar s_α and one matrix S_α per
    cone block (svec'd, Clarabel's upper-triangular order)."""

    sizes: list[int]  # dep block sizes
    tri: list[int]  # their svec lengths
    zoff: list[list[int]]  # column of Z_dj
    nz_terms: int  # k + 1 (affine Z) or 1 (constant Z)
    csizes: list[int]  # cone block sizes
    ctri: list[int]
    n_r: int  # number of r values
    live: list[int] = field(default_factory=list)  # monomials any map reaches (0 first)

    @classmethod
    def build(cls, sizes: list[int], k: int, affine: bool, csizes: list[int],
              n_r: int) -> _Layout:
        nz_terms = k + 1 if affine else 1
        tri = [s * (s + 1) // 2 for s in sizes]
        zoff, col = [], 0
        for t_ in tri:
            zoff.append([col + j * t_ for j in range(nz_terms)])
            col += nz_terms * t_
        return cls(sizes, tri, zoff, nz_terms, csizes, [s * (s + 1) // 2 for s in csizes], n_r)

    @property
    def nzcols(self) -> int:
        return self.zoff[-1][0] + self.nz_terms * self.tri[-1] if self.tri else 0

    @property
    def t_col(self) -> int:
        return self.nzcols

    @property
    def per_alpha(self) -> int:
        return 1 + sum(self.ctri)

    @property
    def s_base(self) -> int:
        return self.nzcols + 1 + sum(self.tri) * (self.nz_terms - 1)

    @property
    def ny(self) -> int:
        return self.s_base + self.n_r * (len(self.live) - 1) * self.per_alpha

    def s_col(self, e: int, pos: int) -> int:
        """Column of s_α (then the S_α) for the e-th r and the pos-th live monomial."""
        return self.s_base + (e * (len(self.live) - 1) + pos - 1) * self.per_alpha


class _Rows:
    """Constraint rows A y + s = b, s in the cones, collected for Clarabel."""

    def __init__(self, ny: int):
        self.ny = ny
        self.rows: list[np.ndarray] = []
        self.cones: list = []
        self.b: list[float] = []

    def add(self, A: np.ndarray, cone, rhs: list[float] | None = None) -> None:
        A = np.atleast_2d(A)
        self.rows.append(A)
        self.cones.append(cone)
        self.b.extend([0.0] * A.shape[0] if rhs is None else rhs)


def _psd(s: int) -> tuple[str, int]:
    return ("nonneg", 1) if s == 1 else ("psd", s)


def _z_constraints(rows: _Rows, lay: _Layout) -> None:
    """Z_d(u) ⪰ 0 on the box: Z_d0 - Σ_j S_dj ⪰ 0 and S_dj ∓ Z_dj ⪰ 0; Σ_d tr Z_d0 = 1."""
    tr = np.zeros(lay.ny)
    soff = lay.t_col + 1
    for q, s in enumerate(lay.sizes):
        t_, z0 = lay.tri[q], lay.zoff[q][0]
        tr[z0:z0 + t_] = svec(np.eye(s), True)
        A = np.zeros((t_, lay.ny))
        A[:, z0:z0 + t_] = -np.eye(t_)
        for j in range(1, lay.nz_terms):
            sc = soff + (j - 1) * t_
            A[:, sc:sc + t_] += np.eye(t_)
            for sign in (1.0, -1.0):
                B = np.zeros((t_, lay.ny))
                B[:, sc:sc + t_] = -np.eye(t_)
                B[:, lay.zoff[q][j]:lay.zoff[q][j] + t_] = sign * np.eye(t_)
                rows.add(B, _psd(s))
        soff += (lay.nz_terms - 1) * t_
        rows.add(A, _psd(s))
    rows.add(tr[None, :], ("zero", 1), [1.0])


def _h_constraints(rows: _Rows, lay: _Layout, e: int, H: np.ndarray,
                   even: np.ndarray) -> None:
    """h_0 - Σ s_α - t >= 0 with s_α >= |h_α| (even α, u^α ∈ [0, 1]: s_α >= -h_α, s_α >= 0)
    at the e-th r: the worst value of h over the box is at least t."""
    nonneg = ("nonneg", 1)
    A = np.zeros(lay.ny)
    A[:lay.nzcols] = -H[0]
    A[lay.t_col] += 1.0
    for pos in range(1, len(lay.live)):
        A[lay.s_col(e, pos)] += 1.0
    rows.add(A[None, :], nonneg)
    for pos, a in enumerate(lay.live[1:], start=1):
        for sign in ((-1.0,) if even[a] else (1.0, -1.0)):
            A = np.zeros(lay.ny)
            A[:lay.nzcols] = sign * H[a]
            A[lay.s_col(e, pos)] -= 1.0
            rows.add(A[None, :], nonneg)
        if even[a]:
            A = np.zeros(lay.ny)
            A[lay.s_col(e, pos)] = -1.0
            rows.add(A[None, :], nonneg)


def _read_dual(y: np.ndarray, lay: _Layout, k: int):
    """(Zs, bounds, covers) from the SDP's solution: the affine terms of each Z_d with
    their covers S_dj (repaired in floats), and per r the cone matrices' bounds S_α."""
    Zs, covers = [], []
    soff = lay.t_col + 1
    pad = k + 1 - lay.nz_terms
    for q, s in enumerate(lay.sizes):
        t_ = lay.tri[q]
        terms = [_unsvec(y[lay.zoff[q][j]:lay.zoff[q][j] + t_], s)
                 for j in range(lay.nz_terms)] + [np.zeros((s, s))] * pad
        Ss = [_unsvec(y[soff + j * t_:soff + (j + 1) * t_], s)
              for j in range(lay.nz_terms - 1)] + [np.zeros((s, s))] * pad
        soff += (lay.nz_terms - 1) * t_
        terms, Ss = _repair(terms, Ss)
        Zs.append(terms)
        covers.append(Ss)
    bounds: list[dict] = []
    for e in range(lay.n_r):
        bd: dict = {}
        off_c = 1
        for c, (s, ct) in enumerate(zip(lay.csizes, lay.ctri, strict=True)):
            for pos in range(1, len(lay.live)):
                c0 = lay.s_col(e, pos) + off_c
                bd[(c, lay.live[pos])] = _unsvec(y[c0:c0 + ct], s)
            off_c += ct
        bounds.append(bd)
    return Zs, bounds, covers


def _unsvec(v: np.ndarray, s: int) -> np.ndarray:
    """Inverse of Clarabel's scaled upper-triangular svec."""
    Z = np.zeros((s, s))
    q = 0
    for j in range(s):
        for i in range(j + 1):
            Z[i, j] = Z[j, i] = v[q] if i == j else v[q] / math.sqrt(2.0)
            q += 1
    return Z


def _repair(terms: list[np.ndarray], Ss: list[np.ndarray]
            ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Make Z(u) = Z_0 + Σ_j u_j Z_j ⪰ 0 on the box (in floats, with margins; the proof
    re-checks it): raise each S_j until S_j ± Z_j ⪰ 0, then raise Z_0 until
    Z_0 - Σ_j S_j ⪰ 0. Returns the terms and the S_j."""
    terms = [0.5 * (t + t.T) for t in terms]
    low = terms[0].copy()
    size = float(np.abs(low).max())
    covers = []
    for t, S in zip(terms[1:], Ss, strict=True):
        S = _cover(t, 0.5 * (S + S.T), even=False)
        covers.append(S)
        low -= S
        size += float(np.abs(S).max())
    deficiency = -float(np.linalg.eigvalsh(low)[0])
    bump = max(deficiency, 0.0) + 4 * SAFETY * (1.0 + size)
    terms[0] = terms[0] + bump * np.eye(terms[0].shape[0])
    return terms, covers


def _cover(A: np.ndarray, S: np.ndarray | None, even: bool) -> np.ndarray:
    """A matrix S with S ± A ⪰ 0 (even: S + A ⪰ 0 and S ⪰ 0), from a candidate S raised
    by its deficiency plus a margin; without a candidate, |A| (resp. the negative part)."""
    A = 0.5 * (A + A.T)
    if S is None:
        wv, V = np.linalg.eigh(A)
        part = np.maximum(-wv, 0.0) if even else np.abs(wv)
        S = (V * part) @ V.T
    n = A.shape[0]
    checks = (S + A, S) if even else (S + A, S - A)
    deficiency = max(-float(np.linalg.eigvalsh(M)[0]) for M in checks)
    scale = 1.0 + float(np.abs(A).max())
    return S + (max(deficiency, 0.0) + 2 * SAFETY * scale) * np.eye(n)


def _positive_lower(coef: np.ndarray, even: np.ndarray) -> bool:
    """p(u) > 0 on [-1, 1]^k for monomial coefficients ``coef`` (flattened; index 0 the
    constant): a_0 - Σ_odd |a_α| - Σ_even max(0, -a_α) > margin (u^α ∈ [0, 1] if even)."""
    flat = coef.reshape(-1)
    a0 = float(flat[0])
    ev = np.asarray(even, dtype=bool).reshape(-1)[1:] if np.ndim(even) else np.zeros(
        flat.size - 1, dtype=bool)
    rest = flat[1:]
    loss = float(np.abs(rest[~ev]).sum() + np.maximum(-rest[ev], 0.0).sum())
    return a0 - loss > SAFETY * (1.0 + abs(a0) + float(np.abs(rest).sum()))


def _psd_lower(coef: np.ndarray, even: np.ndarray, bounds: dict | None = None) -> bool:
    """Σ_α u^α A_α ⪰ 0 on [-1, 1]^k: A_0 - Σ_{α≠0} S_α ≻ 0 with S_α ± A_α ⪰ 0 (even α,
    u^α ∈ [0, 1]: S_α + A_α ⪰ 0, S_α ⪰ 0); S_α from ``bounds`` (repaired) or |A_α|."""
    s = coef.shape[-1]
    flat = coef.reshape(-1, s, s)
    ev = np.asarray(even, dtype=bool).reshape(-1) if np.ndim(even) else np.zeros(
        flat.shape[0], dtype=bool)
    total = 0.5 * (flat[0] + flat[0].T)
    size = float(np.abs(total).max())
    for a in range(1, flat.shape[0]):
        A = flat[a]
        if not np.any(A):
            continue
        S = _cover(A, None if bounds is None else bounds.get(a), bool(ev[a]))
        total = total - S
        size += float(np.abs(S).max())
    lam = float(np.linalg.eigvalsh(total)[0])
    return lam > SAFETY * (1.0 + size)
