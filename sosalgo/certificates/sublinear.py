"""Sublinear rates (no strong convexity): a potential whose weights grow with k.

For a method of the oracle model (:mod:`sosalgo.oracles`) on functions with m = 0, the
certificate bounds ``measure(x_k) <= c |x_0 - x*|^2 / k`` for every k >= 1 (``measure:
function``: sum_j f_j(x_k) - f_j*). As in Taylor and Bach (COLT 2019), the potential is

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
floating-point check of :func:`sosalgo.solvers.check_point` (the equations hold to
rounding, reported as ``residual``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from sosalgo.certificates.base import AffineBlock, LMIProblem
from sosalgo.certificates.composite import CWindow, composite_structure

__all__ = ["SublinearProblem", "block_kernels", "sublinear_data", "sublinear_parts",
           "sublinear_problem"]

NAMES = ("P", "Q", "p", "q", "b", "eta0", "eta1", "lam0", "lam1", "nu")


@dataclass
class SublinearProblem:
    """The LMI in y (x = N y) with r = C/s the constant in solver units (rho^2 = r)."""

    problem: LMIProblem  # blocks in y, r = rho^2
    N: np.ndarray  # x = x0 + N y
    x0: np.ndarray
    lay: dict[str, slice]
    s: float  # units: u = s u~, h = s psi~ (c = s r)
    equalities: np.ndarray  # E x = e: the v-rows of (D0), (D1), (P1) and the tight rows
    rhs: np.ndarray


def _unit_quads(Z: np.ndarray) -> np.ndarray:
    """Z' E_ab Z for each symmetric unit E_ab, a <= b."""
    n = Z.shape[0]
    ia, ib = np.triu_indices(n)
    out = Z[ia][:, :, None] * Z[ib][:, None, :]
    off = ia != ib
    out[off] = out[off] + out[off].transpose(0, 2, 1)
    return out


def _layout(nz: int, npi: int, nd: int, npos: int) -> dict[str, slice]:
    sizes = dict(P=nz * (nz + 1) // 2, Q=nz * (nz + 1) // 2, p=npi, q=npi, b=1, eta0=nd,
                 eta1=nd, lam0=npos, lam1=npos, nu=npos)
    out, k = {}, 0
    for name in NAMES:
        out[name] = slice(k, k + sizes[name])
        k += sizes[name]
    return out


def _fixed_direction(om: Any, width: int) -> np.ndarray:
    """v on a window: the state at the fixed point of x* = 1, every input 0."""
    from sosalgo.oracles import fixed_point_basis

    basis = fixed_point_basis(om)
    assert basis is not None  # the loader checked it
    v = np.zeros(width)
    v[: om.n] = basis[:, 0]
    return v / np.linalg.norm(v)


def _pieces(om: Any, st: Any, lay: dict[str, slice], nvar: int) -> dict[str, tuple]:
    """Quadratic (nvar, w, w) and scalar (nphi, nvar) parts of each inequality, and their
    constants, on the full windows: G = c + sum x_i l_i (we need G <= 0)."""
    d, p = st.dec, st.pos
    U0, U1, Up = _unit_quads(d.Z[0]), _unit_quads(d.Z[1]), _unit_quads(p.Z[0])
    wd, wp = d.width, p.width

    def quad(w: int) -> np.ndarray:
        return np.zeros((nvar, w, w))

    def lin(k: int) -> np.ndarray:
        return np.zeros((k, nvar))

    D0q, D1q, P0q, P1q, Iq = quad(wd), quad(wd), quad(wp), quad(wp), quad(wp)
    D0l, D1l, P0l, P1l, Il = lin(d.nphi), lin(d.nphi), lin(p.nphi), lin(p.nphi), lin(p.nphi)
    D0q[lay["P"]], D0q[lay["Q"]], D0q[lay["eta0"]] = U1 - U0, U1, d.Mq
    D1q[lay["Q"]], D1q[lay["eta1"]] = U1 - U0, d.Mq
    P0q[lay["P"]], P0q[lay["lam0"]], P0q[lay["b"]] = -Up, p.Mq, p.meas_quad
    P1q[lay["Q"]], P1q[lay["lam1"]] = -Up, p.Mq
    Iq[lay["P"]], Iq[lay["nu"]] = Up, p.Mq
    F0, F1, Fp = d.F[0].T, d.F[1].T, p.F[0].T  # (nphi, npi)
    D0l[:, lay["p"]], D0l[:, lay["q"]], D0l[:, lay["eta0"]] = F1 - F0, F1, d.mq.T
    D1l[:, lay["q"]], D1l[:, lay["eta1"]] = F1 - F0, d.mq.T
    P0l[:, lay["p"]], P0l[:, lay["lam0"]] = -Fp, p.mq.T
    P0l[:, lay["b"].start] = p.meas_lin
    P1l[:, lay["q"]], P1l[:, lay["lam1"]] = -Fp, p.mq.T
    Il[:, lay["p"]], Il[:, lay["nu"]] = Fp, p.mq.T
    zq, zl = np.zeros((wp, wp)), np.zeros(p.nphi)
    return {"D0": (D0q, np.zeros((wd, wd)), D0l, np.zeros(d.nphi)),
            "D1": (D1q, np.zeros((wd, wd)), D1l, np.zeros(d.nphi)),
            "P0": (P0q, zq, P0l, zl), "P1": (P1q, p.meas_quad, P1l, p.meas_lin),
            "I": (Iq, zq, Il, zl)}


def _initial_map(om: Any, pos: CWindow) -> tuple[np.ndarray, np.ndarray]:
    """T (w x w'): the positivity window with xi_0 = u x_0 (w' = (x_0, the rest)), and the
    form |x_0|^2 on w'."""
    from sosalgo.oracles import fixed_point_basis

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
    """The inequalities on x (before the equalities are eliminated): matrix blocks
    (name, c0, c1, l (nvar, s, s)) reduced along v, scalar rows (name, constant, row)."""

    mats: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]
    rows: list[tuple[str, float, np.ndarray]]
    E: np.ndarray  # the v-equalities E x = 0
    lay: dict[str, slice]
    st: Any
    s: float


def sublinear_data(om: Any) -> _XData:
    """The potential LMI of a method (module docstring) in units s = L, on x."""
    s = float(om.L)
    st = composite_structure(om, 0, s, rescale=True)
    d, p = st.dec, st.pos
    lay = _layout(st.nz, st.npi, len(d.labels), len(p.labels))
    nvar = lay["nu"].stop
    pc = _pieces(om, st, lay, nvar)
    vd, vp = _fixed_direction(om, d.width), _fixed_direction(om, p.width)
    E = np.vstack([np.einsum("kij,j->ik", pc[k][0], v)
                   for k, v in (("D0", vd), ("D1", vd), ("P1", vp))])
    T, e0 = _initial_map(om, p)
    reduce = {"D0": sla.null_space(vd[None, :]), "D1": sla.null_space(vd[None, :]),
              "P0": np.eye(p.width), "P1": sla.null_space(vp[None, :]), "I": T}
    mats, rows = [], []
    for name, (q, c, lin, cl) in pc.items():
        R = reduce[name]
        c0 = R.T @ c @ R
        mats.append((name, c0, -e0 if name == "I" else np.zeros_like(c0),
                     np.einsum("ia,kij,jb->kab", R, q, R)))
        rows += [(f"{name}-f[{i}]", float(cl[i]), lin[i]) for i in range(lin.shape[0])]
    for name in ("b", "eta0", "eta1", "lam0", "lam1", "nu"):  # >= 0
        for i in range(lay[name].start, lay[name].stop):
            rows.append((f"{name}[{i - lay[name].start}]", 0.0, -np.eye(nvar)[i]))
    return _XData(mats, rows, E, lay, st, s)


def sublinear_problem(data: _XData, tight: frozenset[int] = frozenset(),
                      kernels: dict[str, np.ndarray] | None = None,
                      r: float = 0.0) -> SublinearProblem:
    """The LMI in y, x = x0 + N y solving as equalities the v-equalities, the scalar rows
    ``tight`` (indices into ``data.rows``) and G K = 0 for each matrix block's ``kernels``
    K (at r = C/s); each such block is reduced to the complement of K; all strict."""
    kernels = kernels or {}
    Erows, rhs = [data.E], [np.zeros(len(data.E))]
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
        lr = np.einsum("ia,kij,jb->kab", R, lq, R)
        blocks.append(AffineBlock(name, R.T @ c0 @ R + np.tensordot(x0, lr, axes=1),
                                  R.T @ c1 @ R, np.einsum("kab,ky->yab", lr, N),
                                  np.zeros((ny,) + lr.shape[1:])))
    one, zero = np.zeros((1, 1)), np.zeros((ny, 1, 1))
    for i, (name, c, row) in enumerate(data.rows):
        if i not in tight:
            blocks.append(AffineBlock(name, np.full((1, 1), c + row @ x0), one,
                                      (row @ N)[:, None, None], zero))
    st, lay, s = data.st, data.lay, data.s
    problem = LMIProblem(ny, tuple(blocks), lambda y: _unpack(st, lay, s, x0 + N @ y))
    return SublinearProblem(problem, N, x0, lay, s, Eall, e)


def block_kernels(data: _XData, x: np.ndarray, r: float,
                  tol: float = 1e-7) -> dict[str, np.ndarray]:
    """The eigenvectors of each matrix block at (x, r) with eigenvalue >= -tol (relative):
    at an interior point of the solutions, the directions where every certificate's
    block is singular."""
    out = {}
    for name, c0, c1, lq in data.mats:
        G = c0 + r * c1 + np.tensordot(x, lq, axes=1)
        w, V = np.linalg.eigh(G)
        scale = max(1.0, float(np.abs(w).max()))
        out[name] = V[:, w >= -tol * scale]
    return out


def _sym(vec: np.ndarray, n: int) -> np.ndarray:
    M = np.zeros((n, n))
    M[np.triu_indices(n)] = vec
    return M + np.triu(M, 1).T


def _unpack(st: Any, lay: dict[str, slice], s: float, x: np.ndarray) -> dict[str, Any]:
    """Original units (as :func:`sosalgo.certificates.composite._unpack`, v = s): P, Q on
    z = (xi - xi*, u), p, q on the function values, b, multipliers divided by their
    inequality's scale."""
    dz = np.concatenate([np.ones(st.n), np.full(st.nz - st.n, 1.0 / s)])

    def mat(name: str) -> list[list[float]]:
        return (s * dz[:, None] * _sym(x[lay[name]], st.nz) * dz[None, :]).tolist()

    def mult(name: str, win: CWindow) -> dict[str, float]:
        return {lab: float(t) * s / g for lab, t, g in zip(win.labels, x[lay[name]],
                                                            win.sigma, strict=True)}

    return {"family": "sublinear", "lag": 0, "P": mat("P"), "Q": mat("Q"),
            "p": [float(t) for t in x[lay["p"]]], "q": [float(t) for t in x[lay["q"]]],
            "b": float(x[lay["b"]][0]),
            "multipliers": {"eta0": mult("eta0", st.dec), "eta1": mult("eta1", st.dec),
                            "lam0": mult("lam0", st.pos), "lam1": mult("lam1", st.pos),
                            "nu": mult("nu", st.pos)}}


def sublinear_parts(sp: SublinearProblem, y: np.ndarray, r: float) -> dict[str, float]:
    """Largest eigenvalue of every block at (y, r) (each must be <= 0) and the residual of
    the equalities relative to the size of x."""
    x = sp.x0 + sp.N @ y
    out = {b.name: float(np.linalg.eigvalsh(b.value(y, np.sqrt(r)))[-1])
           for b in sp.problem.blocks if b.size > 1}
    res = sp.equalities @ x - sp.rhs
    out["residual"] = float(np.abs(res).max() / max(1.0, np.abs(x).max()))
    return out
