"""Sublinear rates (no strong convexity): a potential whose weights grow with k.

For a method of the oracle model (:mod:`sosalgo.oracles`) on functions with m = 0, the
certificate bounds ``measure(x_k) <= c |x_0 - x*|^2 / k`` for every k >= 1 (``measure:
function``: sum_j f_j(x_k) - f_j*; for one operator class, ``residual``: sum_i |u_i|^2 of
the calls at step k, :func:`sosalgo.certificates.composite.residual_measured`). As in
Taylor and Bach (COLT 2019), the potential is

    phi_k = z_k' (P + k Q) z_k + (p + k q)' psi_k,      z_k = (xi_k - xi*, u_k),

psi_k the tilted function values h_j >= 0 of the window at time k (the calls' points and
the output point), the same window and interpolation inequalities as the interpolation
family at lag 0 (:mod:`sosalgo.certificates.composite`). Everything is affine in k, so
"for all k >= 0" splits into the constant and the k-coefficient parts (an affine function
of k is <= 0 on k >= 0 iff both parts are, multipliers eta0 + k eta1 >= 0):

    (D0)  z1'(P + Q) z1 - z0' P z0 + (p + q)'psi1 - p'psi0 + sum eta0 q_ab <= 0
    (D1)  z1' Q z1 - z0' Q z0 + q'(psi1 - psi0) + sum eta1 q_ab <= 0
    (P0)  z0' P z0 + p'psi0 - b measure_0 - sum lam0 q_ab >= 0
    (P1)  z0' Q z0 + q'psi0 - measure_0 - sum lam1 q_ab >= 0
    (I)   C |x_0|^2 - phi_0 - sum nu q_ab >= 0   with xi_0 - xi* = u (x_0 - x*),

u the fixed point of x* = 1 (the method started at rest at x_0). Then (D0)+(D1):
phi_{k+1} <= phi_k, (P0)+(P1): phi_k >= (k + b) measure(x_k), (I): phi_0 <= C |x_0|^2, so
measure(x_k) <= C |x_0|^2 / (k + b) <= C |x_0|^2 / k (b >= 0): c = C, minimized.

Each inequality holds as a quadratic form (matrix) plus coefficient-wise on psi >= 0. The
direction v of a minimizer moving with zero gradients (xi = u t, every u = 0) makes
(D0), (D1) and (P1) exactly singular for every certificate (with m = 0 nothing pins x*),
so they are imposed as ``G v = 0`` (solved for exactly: the variables live in the null
space of these linear equations) and ``R' G R`` negative definite on the complement R of
v; the solver then has a strictly feasible problem and the returned point passes the
floating-point check of :func:`sosalgo.kernel.solvers.check_point` (the equations hold to
rounding, reported as ``residual``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.linalg as sla

from sosalgo.certificates.base import CertificateFamily, snap_basis
from sosalgo.certificates.composite import CWindow, composite_structure, residual_measured
from sosalgo.kernel.conic import AffineBlock, LMIProblem, unit_quads

if TYPE_CHECKING:  # only for annotations
    from sosalgo.spec.types import Spec

__all__ = ["SUBLINEAR", "SublinearFamily", "SublinearProblem", "block_kernels",
           "full_violation", "moving_optimum", "operator_refusal", "original_kernels", "snap_basis",
           "sublinear_data",
           "sublinear_parts", "sublinear_problem"]

@dataclass
class SublinearProblem:
    """The LMI in y (x = N y) with r = C/s the constant in solver units (rho^2 = r)."""

    problem: LMIProblem  # blocks in y, r = rho^2
    N: np.ndarray  # x = x0 + N y
    x0: np.ndarray
    lay: dict[str, slice]
    s: float  # units: u = s u~, h = s psi~ (c = s r)
    equalities: np.ndarray  # E x = e: the kernels (known and found) and the tight rows
    rhs: np.ndarray
    # the kernels imposed, in original units (:func:`original_kernels`; exact verification)
    kernels: dict[str, list] = field(default_factory=dict)


def _fixed_direction(om: Any, width: int) -> np.ndarray:
    """v on a window: the state at the fixed point of x* = 1, every input 0."""
    from sosalgo.oracles import fixed_point_basis

    basis = fixed_point_basis(om)
    assert basis is not None  # the loader checked it
    v = np.zeros(width)
    v[: om.n] = basis[:, 0]
    return v / np.linalg.norm(v)


DEGREE = 2  # weights polynomial in k of this degree (1: affine, Taylor and Bach's form)
WEIGHTS = ("P", "Q", "R")  # z' (P + k Q + k^2 R) z
VALUES = ("p", "q", "r")  # (p + k q + k^2 r)' psi


def _tri(n: int) -> int:
    return n * (n + 1) // 2


def _layout(sizes: dict[str, int]) -> dict[str, slice]:
    out, k = {}, 0
    for name, size in sizes.items():
        out[name] = slice(k, k + size)
        k += size
    return out


def _sizes(st: Any, deg: int) -> dict[str, int]:
    """Variables: the weights, b, the multipliers' coefficients (eta: decrease, lam:
    positivity, nu: initial) and, for degree 2, the auxiliaries of each "<= 0 on k >= 0"
    (S psd and K skew of the matrix blocks). The t variables are in no constraint (the
    scalar parts are constrained coefficient-wise); they stay because the solver's path,
    and so every constant it gives, depends on the number of variables."""
    d, p = st.dec, st.pos
    nd, npos = len(d.labels), len(p.labels)
    sizes = {WEIGHTS[j]: _tri(st.nz) for j in range(deg + 1)}
    sizes |= {VALUES[j]: st.npi for j in range(deg + 1)}
    sizes["b"] = 1
    sizes |= {f"eta{j}": nd for j in range(deg + 1)} | {f"lam{j}": npos for j in range(deg + 1)}
    sizes["nu"] = npos
    if deg == 2:
        for tag, w, nphi in (("D", d.width, d.nphi), ("P", p.width, p.nphi)):
            sizes |= {f"S{tag}": _tri(w), f"K{tag}": w * (w - 1) // 2, f"t{tag}": nphi}
        sizes |= {"teta": nd, "tlam": npos}
    return sizes


def _skew_units(n: int) -> np.ndarray:
    """E_ab - E_ba for a < b."""
    ia, ib = np.triu_indices(n, 1)
    out = np.zeros((len(ia), n, n))
    out[np.arange(len(ia)), ia, ib] = 1.0
    out[np.arange(len(ia)), ib, ia] = -1.0
    return out


@dataclass
class _Poly:
    """A constraint ``sum_j k^j (c_j + sum_i x_i q_j[i]) <= 0`` (matrix part) and
    ``sum_j k^j (cl_j + lin_j x) <= 0`` coefficient-wise (the part on psi >= 0), k >= 0."""

    q: list[np.ndarray]  # (nvar, w, w) per power of k
    c: list[np.ndarray]  # (w, w)
    lin: list[np.ndarray]  # (nphi, nvar)
    cl: list[np.ndarray]  # (nphi,)


def _polys(st: Any, lay: dict[str, slice], nvar: int, deg: int) -> dict[str, _Poly]:
    """(D) phi_{k+1} - phi_k + sum eta(k) q_ab <= 0 and (P) (k + b) measure + sum lam(k)
    q_ab - phi_k <= 0, as polynomials in k (phi_{k+1}: (k+1)^i = sum_j C(i, j) k^j)."""
    from math import comb

    d, p = st.dec, st.pos
    U0, U1, Up = unit_quads(d.Z[0]), unit_quads(d.Z[1]), unit_quads(p.Z[0])
    F0, F1, Fp = d.F[0].T, d.F[1].T, p.F[0].T  # (nphi, npi)
    D = _Poly([np.zeros((nvar, d.width, d.width)) for _ in range(deg + 1)],
              [np.zeros((d.width, d.width))] * (deg + 1),
              [np.zeros((d.nphi, nvar)) for _ in range(deg + 1)], [np.zeros(d.nphi)] * (deg + 1))
    P = _Poly([np.zeros((nvar, p.width, p.width)) for _ in range(deg + 1)],
              [np.zeros((p.width, p.width))] * (deg + 1),
              [np.zeros((p.nphi, nvar)) for _ in range(deg + 1)], [np.zeros(p.nphi)] * (deg + 1))
    for j in range(deg + 1):
        D.q[j][lay[WEIGHTS[j]]] -= U0
        D.lin[j][:, lay[VALUES[j]]] -= F0
        for i in range(j, deg + 1):
            D.q[j][lay[WEIGHTS[i]]] += comb(i, j) * U1
            D.lin[j][:, lay[VALUES[i]]] += comb(i, j) * F1
        D.q[j][lay[f"eta{j}"]] = d.Mq
        D.lin[j][:, lay[f"eta{j}"]] = d.mq.T
        P.q[j][lay[WEIGHTS[j]]] = -Up
        P.lin[j][:, lay[VALUES[j]]] = -Fp
        P.q[j][lay[f"lam{j}"]] = p.Mq
        P.lin[j][:, lay[f"lam{j}"]] = p.mq.T
    P.q[0][lay["b"]] = p.meas_quad
    P.lin[0][:, lay["b"].start] = p.meas_lin
    P.c[1], P.cl[1] = p.meas_quad, p.meas_lin
    return {"D": D, "P": P}


def moving_optimum(om: Any) -> bool:
    """Whether the fixed point moves with the optimal answers (several operators, measured
    by the state change): then the start is free, |xi_0 - xi*|^2 bounds phi_0."""
    from sosalgo.certificates.composite import STATE_CHANGE

    return om.measure == STATE_CHANGE


def _moving_directions(om: Any, st: Any) -> tuple[np.ndarray, np.ndarray]:
    """(decrease, positivity) window directions (columns) of a stationary point that has
    moved with the optimal answers: (A - I) xi + B u = 0, every call at x* (C xi + D u =
    0), the same answers at every time, on whose span every class inequality's form
    vanishes (Douglas-Rachford: xi = alpha d, u = (d, -d)); none unless
    :func:`moving_optimum`."""
    n = om.n
    if not moving_optimum(om):
        return np.zeros((st.dec.width, 0)), np.zeros((st.pos.width, 0))
    s = float(om.L)
    M = np.block([[om.A - np.eye(n), s * om.B], [om.C, s * om.D]])
    base = sla.null_space(M)

    def lift(steps: int) -> np.ndarray:
        return np.vstack([base[:n]] + [base[n:]] * steps)

    Wd = lift(2)
    forms = [Wd.T @ Mq @ Wd for Mq in st.dec.Mq]  # zero on the span kept: every form 0
    keep = _null_abs(np.vstack(forms)) if forms else np.eye(Wd.shape[1])
    return snap_basis(Wd @ keep), snap_basis(lift(1) @ keep)


def _null_abs(F: np.ndarray, tol: float = 1e-10) -> np.ndarray:
    """Null space of F with an absolute tolerance (forms of unit-scaled inequalities)."""
    _, sv, Vt = np.linalg.svd(F)
    rank = int(np.sum(sv > tol))
    return Vt[rank:].T


def _initial_map(om: Any, pos: CWindow) -> tuple[np.ndarray, np.ndarray]:
    """T (w x w'): the positivity window with xi_0 = u x_0 (w' = (x_0, the rest)), and the
    form |x_0|^2 on w'; a free start (:func:`moving_optimum`): T = I and |xi_0 - xi*|^2."""
    from sosalgo.oracles import fixed_point_basis

    if moving_optimum(om):
        w = pos.width
        return np.eye(w), np.diag(np.r_[np.ones(om.n), np.zeros(w - om.n)])
    basis = fixed_point_basis(om)
    assert basis is not None
    w = pos.width
    T = np.zeros((w, w - om.n + 1))
    T[: om.n, 0] = basis[:, 0]
    T[om.n:, 1:] = np.eye(w - om.n)
    e = np.zeros((w - om.n + 1, w - om.n + 1))
    e[0, 0] = 1.0
    return T, e


@dataclass
class _XData:
    """The inequalities on x: matrix blocks (name, c0, c1, l (nvar, s, s)) with
    G = c0 + r c1 + sum x_i l_i <= 0, scalar rows (name, constant, row) <= 0, and the
    directions every certificate's block is singular along (``known``: the minimizer
    moving with zero gradients)."""

    mats: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]
    rows: list[tuple[str, float, np.ndarray]]
    known: dict[str, np.ndarray]
    lay: dict[str, slice]
    st: Any
    s: float
    deg: int
    om: Any = None  # the method measured (its measure says whether the start is free)


def _halfline(name: str, poly: _Poly, lay: dict[str, slice], tag: str,
              nvar: int) -> tuple[list, list]:
    """``poly(k) <= 0`` for all k >= 0 as LMIs. Degree 1: both coefficients <= 0. Degree 2:
    [[A0, Y], [Y', A2]] <= 0 with Y = (A1 + S)/2 + K, S >= 0, K skew (then -A(k) =
    [I; kI]' M [I; kI] + k S with M >= 0); the scalar parts coefficient-wise (each
    coefficient <= 0)."""
    deg = len(poly.q) - 1
    if deg == 1:
        mats = [(f"{name}{j}", poly.c[j], np.zeros_like(poly.c[j]), poly.q[j]) for j in (0, 1)]
        rows = [(f"{name}{j}-f[{i}]", float(poly.cl[j][i]), poly.lin[j][i])
                for j in (0, 1) for i in range(len(poly.cl[j]))]
        return mats, rows
    w = poly.c[0].shape[0]
    Su, Ku = np.zeros((nvar, w, w)), np.zeros((nvar, w, w))
    Su[lay[f"S{tag}"]], Ku[lay[f"K{tag}"]] = unit_quads(np.eye(w)), _skew_units(w)
    mats = [(name, *_stack2(poly.q, poly.c, Su, Ku)), (f"{name}-S", np.zeros((w, w)),
                                                          np.zeros((w, w)), -Su)]
    rows = [(f"{name}{j}-f[{i}]", float(poly.cl[j][i]), poly.lin[j][i])
            for j in range(3) for i in range(len(poly.cl[j]))]
    return mats, rows


def _stack2(q: list, c: list, Su: np.ndarray, Ku: np.ndarray) -> tuple:
    """(c0, c1 = 0, l) of [[A0, Y], [Y', A2]], Y = (A1 + S)/2 + K."""
    w = c[0].shape[0]
    nvar = q[0].shape[0]
    L = np.zeros((nvar, 2 * w, 2 * w))
    Y = 0.5 * (q[1] + Su) + Ku
    L[:, :w, :w], L[:, w:, w:] = q[0], q[2]
    L[:, :w, w:], L[:, w:, :w] = Y, Y.transpose(0, 2, 1)
    C = np.zeros((2 * w, 2 * w))
    C[:w, :w], C[w:, w:] = c[0], c[2]
    C[:w, w:] = C[w:, :w] = 0.5 * c[1]
    return C, np.zeros_like(C), L


def _nonneg(names: tuple[str, ...], lay: dict[str, slice], nvar: int) -> list:
    """Multiplier polynomials sum_j k^j x[names[j]] >= 0 on k >= 0, coefficient-wise
    (every coefficient >= 0): one row each."""
    eye = np.eye(nvar)
    return [(f"{nm}[{i - lay[nm].start}]", 0.0, -eye[i]) for nm in names
            for i in range(lay[nm].start, lay[nm].stop)]


def operator_refusal(spec: Spec) -> str | None:
    """Why the family does not answer an ``m: 0`` spec with an operator class (None: one
    function, an operator class that is exactly its pairwise conditions: its zero has
    u* = 0, so the squared residual sum_i |u_i|^2 of the calls is the measure; or several
    maximally monotone operators (Douglas-Rachford), measured by the state change
    |xi_{k+1} - xi_k|^2 from a free start, the fixed point moving with the optimal answers)."""
    from sosalgo.classes import CLASSES
    from sosalgo.steps import changes_with_k

    classes = {name: CLASSES[d.cls] for name, d in spec.functions.items()}
    if all(c.has_values for c in classes.values()):
        return None
    named = ", ".join(f"{n} ({c.name})" for n, c in classes.items())
    if len(classes) > 1 and not all(c.state_change_rates for c in classes.values()):
        return (f"{named}: an operator class among several functions: the sublinear "
                "family bounds the squared residual of one operator only, or the state "
                "change of several maximally monotone ones (m: 0)")
    if not next(iter(classes.values())).pairwise_defined:
        return (f"{named} is an operator class not given by pairwise conditions: no "
                "sublinear family applies to it (m: 0)")
    if changes_with_k(spec):
        return (f"{named} is an operator class and the method changes with k: the "
                "sublinear family takes one method for every step (m: 0)")
    return None


def sublinear_data(om: Any, deg: int = DEGREE) -> _XData:
    """The potential LMI of a method (module docstring) in units s = L, on x."""
    om = residual_measured(om)
    s = float(om.L)
    st = composite_structure(om, 0, s, rescale=True)
    p = st.pos
    sizes = _sizes(st, deg)
    lay = _layout(sizes)
    nvar = sum(sizes.values())
    polys = _polys(st, lay, nvar, deg)
    mats, rows = [], []
    for name, tag in (("D", "D"), ("P", "P")):
        m_, r_ = _halfline(name, polys[name], lay, tag, nvar)
        mats, rows = mats + m_, rows + r_
    T, e0 = _initial_map(om, p)
    Iq = np.zeros((nvar, p.width, p.width))
    Iq[lay["P"]], Iq[lay["nu"]] = unit_quads(p.Z[0]), p.Mq
    mats.append(("I", np.zeros((T.shape[1],) * 2), -e0, np.einsum("ia,kij,jb->kab", T, Iq, T)))
    Il = np.zeros((p.nphi, nvar))
    Il[:, lay["p"]], Il[:, lay["nu"]] = p.F[0].T, p.mq.T
    rows += [(f"I-f[{i}]", 0.0, Il[i]) for i in range(p.nphi)]
    rows.append(("b[0]", 0.0, -np.eye(nvar)[lay["b"].start]))
    for group in ("eta", "lam"):
        rows += _nonneg(tuple(f"{group}{j}" for j in range(deg + 1)), lay, nvar)
    rows += _nonneg(("nu",), lay, nvar)
    return _XData(mats, rows, _known(om, st, deg), lay, st, s, deg, om)


def _known(om: Any, st: Any, deg: int) -> dict[str, np.ndarray]:
    """Block directions singular for every certificate: v = the minimizer moving with zero
    gradients (xi = u t, every input 0) in every coefficient of (D) and in the growing
    coefficients of (P)."""
    md, mp = _moving_directions(om, st)
    vd = np.column_stack([_fixed_direction(om, st.dec.width), md])
    vp = np.column_stack([_fixed_direction(om, st.pos.width), mp])
    if deg == 1:
        return {"D0": vd, "D1": vd, "P1": vp}
    zd, zp = np.zeros_like(vd), np.zeros_like(vp)
    return {"D": np.hstack([np.vstack([vd, zd]), np.vstack([zd, vd])]),
            "D-S": vd, "P": np.vstack([zp, vp]), "P-S": vp}


def sublinear_problem(data: _XData, tight: frozenset[int] = frozenset(),
                      kernels: dict[str, np.ndarray] | None = None,
                      r: float = 0.0) -> SublinearProblem:
    """The LMI in y, x = x0 + N y solving as equalities the known kernels, the scalar rows
    ``tight`` (indices into ``data.rows``) and G K = 0 for each matrix block's ``kernels``
    K (at r = C/s); each such block is reduced to the complement of K; all strict."""
    kernels = data.known | (kernels or {})
    Erows, rhs = [np.zeros((0, data.mats[0][3].shape[0]))], [np.zeros(0)]
    for name, c0, c1, lq in data.mats:
        K = kernels.get(name)
        if K is not None and K.shape[1]:
            Erows.append(np.einsum("kij,jm->imk", lq, K).reshape(-1, lq.shape[0]))
            rhs.append(-((c0 + r * c1) @ K).reshape(-1))
    for i in sorted(tight):
        Erows.append(data.rows[i][2][None, :])
        rhs.append(np.array([-data.rows[i][1]]))
    Eall, e = np.vstack(Erows), np.concatenate(rhs)
    x0 = np.linalg.lstsq(Eall, e, rcond=None)[0]
    N = sla.null_space(Eall, rcond=1e-10)
    ny = N.shape[1]
    blocks = []
    for name, c0, c1, lq in data.mats:
        K = kernels.get(name)
        R = np.eye(c0.shape[0]) if K is None or not K.shape[1] else sla.null_space(K.T)
        if not R.shape[1]:  # singular everywhere: the equalities say it all
            continue
        lr = np.einsum("ia,kij,jb->kab", R, lq, R)
        blocks.append(AffineBlock(name, R.T @ c0 @ R + np.tensordot(x0, lr, axes=1),
                                  R.T @ c1 @ R, np.einsum("kab,ky->yab", lr, N),
                                  np.zeros((ny,) + lr.shape[1:])))
    one, zero = np.zeros((1, 1)), np.zeros((ny, 1, 1))
    for i, (name, c, row) in enumerate(data.rows):
        if i not in tight:
            blocks.append(AffineBlock(name, np.full((1, 1), c + row @ x0), one,
                                      (row @ N)[:, None, None], zero))
    st, lay, s, deg = data.st, data.lay, data.s, data.deg
    problem = LMIProblem(ny, tuple(blocks), lambda y: _unpack(st, lay, s, deg, x0 + N @ y))
    return SublinearProblem(problem, N, x0, lay, s, Eall, e)


def block_kernels(data: _XData, x: np.ndarray, r: float,
                  tol: float = 1e-7) -> dict[str, np.ndarray]:
    """The known kernels of each matrix block and, on their complement, the eigenvectors at
    (x, r) with eigenvalue >= -tol (relative): at an interior point of the solutions, the
    directions where every certificate's block is singular."""
    out = {}
    for name, c0, c1, lq in data.mats:
        G = c0 + r * c1 + np.tensordot(x, lq, axes=1)
        known = data.known.get(name, np.zeros((G.shape[0], 0)))
        R = sla.null_space(known.T) if known.shape[1] else np.eye(G.shape[0])
        w, V = np.linalg.eigh(R.T @ G @ R)
        scale = max(1.0, float(np.abs(w).max(initial=0.0)))
        out[name] = np.hstack([known, snap_basis(R @ V[:, w >= -tol * scale])])
    return out


def full_violation(data: _XData, x: np.ndarray, r: float) -> float:
    """The largest eigenvalue of every block and the largest row at (x, r), before any
    equality is used (each must be <= 0): the reduced check assumes the equalities hold,
    which rounding can break when x is large."""
    worst = max(float(c + row @ x) for _, c, row in data.rows) if data.rows else -np.inf
    for _, c0, c1, lq in data.mats:
        G = c0 + r * c1 + np.tensordot(x, lq, axes=1)
        worst = max(worst, float(np.linalg.eigvalsh(G)[-1]))
    return worst


def original_kernels(data: _XData, kernels: dict[str, np.ndarray]) -> dict[str, list]:
    """The kernels imposed on each block (columns; known ones first) in original units: a
    block is s Dw M~ Dw with Dw = 1/s on the input columns (u = s u~), so G~ K~ = 0 gives
    G (Dw^-1 K~) = 0: rows on input columns are multiplied by s. The initial block "I" is
    on (x_0, the window's input columns)."""
    n, s = data.st.n, data.s
    out = {}
    for name, K in kernels.items():
        if not K.shape[1]:
            continue
        if name == "I":
            head = n if moving_optimum(data.om) else 1  # the state (free start) or x_0
            scale = np.concatenate([np.ones(head), np.full(K.shape[0] - head, s)])
        else:
            w = (data.st.dec if name.startswith("D") else data.st.pos).width
            scale = np.tile(np.concatenate([np.ones(n), np.full(w - n, s)]), K.shape[0] // w)
        out[name] = (scale[:, None] * K).tolist()
    return out


def _sym(vec: np.ndarray, n: int) -> np.ndarray:
    M = np.zeros((n, n))
    M[np.triu_indices(n)] = vec
    return M + np.triu(M, 1).T


def _unpack(st: Any, lay: dict[str, slice], s: float, deg: int,
            x: np.ndarray) -> dict[str, Any]:
    """Original units (as :func:`sosalgo.certificates.composite._unpack`, v = s): P, Q (and
    R for degree 2) on z = (xi - xi*, u), p, q (r) on the function values, b, multipliers
    divided by their inequality's scale."""
    dz = np.concatenate([np.ones(st.n), np.full(st.nz - st.n, 1.0 / s)])

    def mat(name: str) -> list[list[float]]:
        return (s * dz[:, None] * _sym(x[lay[name]], st.nz) * dz[None, :]).tolist()

    def mult(name: str, win: CWindow) -> dict[str, float]:
        return {lab: float(t) * s / g for lab, t, g in zip(win.labels, x[lay[name]],
                                                            win.sigma, strict=True)}

    out: dict[str, Any] = {"family": "sublinear", "lag": 0, "degree": deg,
                           "b": float(x[lay["b"]][0])}
    mults = {"nu": mult("nu", st.pos)}
    for j in range(deg + 1):
        out[WEIGHTS[j]] = mat(WEIGHTS[j])
        out[VALUES[j]] = [float(t) for t in x[lay[VALUES[j]]]]
        mults[f"eta{j}"] = mult(f"eta{j}", st.dec)
        mults[f"lam{j}"] = mult(f"lam{j}", st.pos)
    out["multipliers"] = mults
    if deg == 2:  # the S-procedure auxiliaries of each "<= 0 on k >= 0" (exact verification)
        for tag, win in (("D", st.dec), ("P", st.pos)):
            out[f"S_{tag}"], out[f"K_{tag}"] = _halfline_aux(x, lay, tag, win.width, st.n, s)
    return out


def _halfline_aux(x: np.ndarray, lay: dict[str, slice], tag: str, w: int, n: int,
                  s: float) -> tuple[list, list]:
    """S (psd) and K (skew) of block ``tag`` in original units: the window's input columns
    carry u = s u~, and the block is s times the solver's, so M = s Dw M~ Dw with
    Dw = diag(1 (the n state columns), 1/s (the rest))."""
    dw = np.concatenate([np.ones(n), np.full(w - n, 1.0 / s)])
    K = np.zeros((w, w))
    K[np.triu_indices(w, 1)] = x[lay[f"K{tag}"]]
    K = K - K.T
    return [(s * dw[:, None] * M * dw[None, :]).tolist()
            for M in (_sym(x[lay[f"S{tag}"]], w), K)]


def sublinear_parts(sp: SublinearProblem, y: np.ndarray, r: float) -> dict[str, float]:
    """Largest eigenvalue of every reduced block at (y, r) (each must be <= 0), the
    largest residual of the equalities and the size of x."""
    x = sp.x0 + sp.N @ y
    out = {b.name: float(np.linalg.eigvalsh(b.value(y, np.sqrt(r)))[-1])
           for b in sp.problem.blocks if b.size > 1}
    res = sp.equalities @ x - sp.rhs
    out["residual"] = float(np.abs(res).max())  # absolute: what the blocks see
    out["size"] = float(np.abs(x).max())
    return out


# --------------------------------------------------------------------------- the family in runs
def _cell(v: Any) -> Any:
    """A CSV cell as these files have always written it (``True``/``False`` for flags)."""
    return str(v) if isinstance(v, bool) else v


def _num(v: str | None) -> float | None:
    return None if v in (None, "") else float(v)


def _flag(v: str | None) -> bool:
    return v in ("True", "true")


def _json_cell(v: str | None) -> Any:
    import json

    return None if v in (None, "") else json.loads(v)


class SublinearFamily(CertificateFamily):
    """The family of ``m: 0`` specs: a constant c in measure(x_k) <= c |x_0 - x*|^2 / k
    instead of a rate. It implements :class:`CertificateFamily` with the constant in the
    place of rho and no kappa: the float build :meth:`problem` (its data at the spec's L,
    what :func:`sosalgo.analysis.analyze_sublinear` solves for each degree), the exact check
    :meth:`exact_check` (:mod:`sosalgo.certificates.exact_sublinear`), :meth:`listing` and
    :meth:`applies_to`, which selects it for a spec (:func:`sosalgo.certificates.spec_family`;
    it is not a ``--certificate`` choice). It owns what an analysis, design and grid row
    holds, keyed by ``L`` (one row, no kappa), how its CSV cells are written and read back,
    and the columns its printed table shows."""

    name = "sublinear"
    description = ("sublinear: potential z'(P + k Q + k^2 R) z + (p + k q + k^2 r)' psi, "
                   "measure(x_k) <= c |x_0 - x*|^2 / k")
    label = "sublinear"
    rate_type = "sublinear"
    is_default = False
    supports_moment = False
    certificate_parts = ("P", "Q", "p", "q")  # R and r too at degree 2
    # the columns of its printed table (before ``verified`` and the spec's references)
    PRINTED_COLUMNS = ("L", "rate_type", "constant", "certified", "solves", "seconds")

    def applies_to(self, spec: Spec) -> str | None:
        """Why the family does not answer ``spec`` (None for an ``m: 0`` spec, L given)."""
        if not spec.has_condition_number:  # operators: inputs.refuse_nonconvex's operator_refusal
            return None
        return "the sublinear family answers m: 0 specs (L given, no kappa) only"

    def problem(self, alg: Any) -> LMIProblem:
        """The feasibility data of the potential of degree :data:`DEGREE` for a method
        bound without kappa (:func:`sosalgo.model.bind_sublinear`), in y and r = c / s."""
        return sublinear_problem(sublinear_data(alg)).problem

    def exact_problem(self, A: Any, B: Any, C: Any, E: Any, m: Any, L: Any) -> None:
        """None: design proves no box-wide lower bound for a constant."""
        return None

    def parse_certificate(self, parts: Mapping[str, Any], n: int) -> dict[str, Any]:
        """The parts as given (a mapping): the exact check itself fails a malformed one."""
        if not isinstance(parts, Mapping):
            raise ValueError("certificate: expected an object")
        return dict(parts)

    def exact_check(self, spec: Spec, kappa: float | None, rho: float | None,
                    cert: Mapping[str, Any], theta: Mapping[str, float] | None = None) -> Any:
        """Proof in exact arithmetic that ``cert`` certifies the constant ``rho`` (there is
        no kappa): :func:`sosalgo.certificates.exact_sublinear.verify_exact_sublinear`, its
        result carrying ``constant_proven`` where a rate family's carries ``rho_proven``."""
        from sosalgo.certificates.exact_sublinear import verify_exact_sublinear

        if kappa is not None:
            raise ValueError("kappa: an m: 0 spec has no kappa")
        return verify_exact_sublinear(spec, cert, theta, constant=rho)

    def lyapunov(self, cert: Mapping[str, Any]) -> dict[str, Any]:
        """The potential's weights at k = 0 (P, p): the simulation of a constant follows the
        bound itself (:mod:`sosalgo.proofs.simulate_sublinear`), not a decrease."""
        return {"P": np.asarray(cert["P"], dtype=float),
                "lyapunov": {"p": [float(v) for v in cert["p"]]}}

    def listing(self, spec: Spec, symbols: dict[str, Any], latex: bool) -> str:
        """Its text for ``sosalgo lmi``: the bound, the potential and what its conditions
        say (the module's docstring, eqs. (D0) to (I), each coefficient of k a matrix
        inequality with interpolation multipliers); a LaTeX snippet with ``latex``."""
        if latex:
            return "\n".join([
                "\\begin{equation*}", "\\begin{aligned}",
                "&\\mathrm{measure}(x_k) \\le c\\,\\|x_0 - x_\\star\\|^2 / k,"
                "\\quad k \\ge 1\\\\",
                "&\\phi_k = z_k^\\top (P + kQ + k^2 R)\\, z_k + (p + kq + k^2 r)^\\top "
                "\\psi_k,\\quad z_k = (\\xi_k - \\xi_\\star, u_k)\\\\",
                "&\\phi_{k+1} \\le \\phi_k,\\quad \\phi_k \\ge (k + b)\\,"
                "\\mathrm{measure}(x_k),\\quad \\phi_0 \\le c\\,\\|x_0 - x_\\star\\|^2",
                "\\end{aligned}", "\\end{equation*}"])
        return "\n".join([
            f"{spec.name}: measure(x_k) <= c |x_0 - x*|^2 / k for k >= 1 (m: 0)",
            "phi_k = z_k' (P + k Q + k^2 R) z_k + (p + k q + k^2 r)' psi_k,",
            "  z_k = (xi_k - xi*, u_k), psi_k the function values of the window",
            "phi_{k+1} <= phi_k, phi_k >= (k + b) measure(x_k), phi_0 <= c |x_0 - x*|^2,",
            "  each coefficient of k a matrix inequality with interpolation multipliers"])

    def printed_columns(self, columns: list[str]) -> list[str]:
        """The columns of its printed table: :data:`PRINTED_COLUMNS`, then ``verified``
        when ``columns`` (what a rate family would print) has it."""
        return list(self.PRINTED_COLUMNS) + (["verified"] if "verified" in columns else [])
    key = ("L",)
    COLUMNS = ("L", "rate_type", "constant", "certified", "constant_estimate", "measure",
               "solves", "seconds", "solver", "check_kind", "check", "error", "certificate")

    def analysis_columns(self, spec: Any) -> list[str]:
        """CSV columns of ``sosalgo analyze``: the constant and how it was checked, the
        parameters' values, the spec's references, the certificate (one JSON object)."""
        return (list(self.COLUMNS) + [f"param_{p}" for p in spec.parameters]
                + list(spec.references))

    def analysis_tasks(self, spec: Any) -> list[dict[str, Any]]:
        """The sweep's tasks: the one row at the spec's L."""
        return [{"L": float(spec.L)}]

    def analysis_cells(self, spec: Any, row: dict[str, Any]) -> dict[str, Any]:
        """The CSV cells of an analysis row (its JSON form, references included)."""
        import json

        cells = {k: row.get(k) for k in ("L", "rate_type", "constant", "certified",
                                          "constant_estimate", "measure", "solves",
                                          "seconds", "solver", "check_kind")}
        cells["check"] = None if row["check"] is None else json.dumps(row["check"])
        cells["certificate"] = (None if row["certificate"] is None
                                else json.dumps(row["certificate"], separators=(",", ":")))
        cells.update({f"param_{p}": v for p, v in row["params"].items()})
        cells.update(row["references"])
        return {k: _cell(v) for k, v in cells.items()}

    def analysis_json(self, spec: Any, cells: dict[str, str]) -> dict[str, Any]:
        """The JSON row read back from its CSV cells (the references computed again; the
        simulation of the constant is evidence added by the run)."""
        from sosalgo.spec.references import reference_values

        return {"rate_type": cells["rate_type"], "constant": _num(cells["constant"]),
                "certified": _flag(cells["certified"]), "L": float(cells["L"]),
                "measure": cells["measure"],
                "constant_estimate": _num(cells["constant_estimate"]),
                "solves": int(cells["solves"]), "seconds": float(cells["seconds"]),
                "solver": cells["solver"] or None,
                "params": {p: float(cells[f"param_{p}"]) for p in spec.parameters
                           if cells.get(f"param_{p}", "") != ""},
                "check_kind": cells["check_kind"] or None,
                "check": _json_cell(cells["check"]),
                "certificate": _json_cell(cells["certificate"]), "family": self.name,
                "references": reference_values(spec, float("nan"))}

    # -- design: the constant minimized over the free parameters' box (one row at L)
    DESIGN_COLUMNS = ("L", "rate_type", "free", "constant", "certified", "lower_bound",
                      "bound_status", "evaluations", "seconds", "time_limit", "timed_out",
                      "check_kind", "simulation_ok", "simulation_worst_ratio")

    def design_columns(self, spec: Any) -> list[str]:
        """CSV columns of ``sosalgo design``."""
        return (list(self.DESIGN_COLUMNS) + [f"param_{p}" for p in spec.parameters]
                + ["certificate"])

    def design_cells(self, names: list[str], row: dict[str, Any]) -> dict[str, Any]:
        """The CSV cells of a design row (its JSON form, the simulation included)."""
        import json

        sim = row["simulation"]
        cells = {k: row.get(k) for k in self.DESIGN_COLUMNS} | {
            "free": ",".join(names), "certificate": json.dumps(row["certificate"]),
            "simulation_ok": None if sim is None else sim["ok"],
            "simulation_worst_ratio": None if sim is None else sim["worst_ratio"]}
        cells |= {f"param_{p}": v for p, v in row["params"].items()}
        return {k: _cell(v) for k, v in cells.items()}

    def design_json(self, spec: Any, names: list[str], cells: dict[str, str]) -> dict[str, Any]:
        """The design row read back from its CSV cells (the simulation is evidence the run
        adds again)."""
        from sosalgo.model import parameter_box

        params = {p: float(cells[f"param_{p}"]) for p in spec.parameters
                  if cells.get(f"param_{p}", "") != ""}
        constant = _num(cells["constant"])
        box = parameter_box(spec, float("nan"), names)
        return {"rate_type": cells["rate_type"], "L": float(cells["L"]), "free": names,
                "box": [list(b) for b in box], "constant": constant,
                "certified": _flag(cells["certified"]),
                "theta": None if constant is None else {p: params[p] for p in names},
                "params": params, "lower_bound": _num(cells["lower_bound"]),
                "bound_status": cells["bound_status"],
                "evaluations": int(cells["evaluations"]), "seconds": float(cells["seconds"]),
                "time_limit": float(cells["time_limit"]),
                "timed_out": _flag(cells["timed_out"]),
                "check_kind": cells["check_kind"] or None,
                "certificate": _json_cell(cells["certificate"]), "family": self.name}

    # -- grid: the constant at each point of a grid over the free parameters
    GRID_COLUMNS = ("constant", "certified", "solves", "seconds")

    def grid_columns(self, names: list[str]) -> list[str]:
        """CSV columns of ``sosalgo grid``: the free parameters, then the constant."""
        return list(names) + list(self.GRID_COLUMNS)

    def grid_cells(self, theta: dict[str, float], res: Any) -> dict[str, Any]:
        """The CSV cells of a grid point (``res``: its analysis; None where the model has
        no fixed point or leaves a function's domain)."""
        cells = {"certified": False} if res is None else {
            "constant": res.constant, "certified": res.certified, "solves": res.solves,
            "seconds": res.seconds}
        return {k: _cell(v) for k, v in (theta | cells).items()}


SUBLINEAR = SublinearFamily()
