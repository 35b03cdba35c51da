"""A-posteriori validation of a moment relaxation's bound from the solver's dual.

The dual of the order-k moment relaxation (Lasserre 2001, Sec. 4) is the SOS program

    max gamma  s.t.  f - gamma = <Z_0, m m^T> + sum_i <Z_i, M_t(g_i) (x)> + sum_j h_j q_j,

with ``Z_i ⪰ 0`` (``m`` the monomials of degree <= k). A numerical dual ``(gamma, Z_i, q_j)``
satisfies this identity only up to a residual polynomial ``r``. This module turns it into
a *rigorous* lower bound on the POP's minimum, whatever the solver's accuracy:

1. ``Z_i`` is replaced by its PSD part ``Z_i^+`` and the residual ``r = f - gamma - ...`` is
   recomputed from the moment maps, so ``f(x) - gamma = (PSD terms >= 0 on K) + r(x)``.
2. ``r`` is bounded below on the feasible set K in two ways, and the better one is used:

   * *box*: when every variable is bounded, ``|z^alpha| <= rho^alpha`` on K, so
     ``r(z) >= r_0 - sum_{alpha != 0} |r_alpha| rho^alpha``;
   * *Gram*: ``r = m^T R m`` with ``R[b, c] = r_{b+c} / #{(b', c'): b' + c' = b + c}``; if
     ``A = Z_0^+ + R`` becomes PSD after adding ``delta`` to its constant entry,
     ``f - gamma + delta`` is a sum of squares plus PSD terms, so ``f >= gamma - delta`` on K
     (``delta = max(0, b^T C^{-1} b - a)`` for ``A = [[a, b^T], [b, C]]``, ``C ≻ 0``).
     This needs no box.

The floating-point rounding of the check itself is covered by a margin of a few ulps of
the magnitudes involved; everything else is exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sps

from sosalgo.kernel.solvers import cvxpy_solve

from .moment import MomentIndex

__all__ = ["DualData", "certified_bound", "interior_dual", "newton_keep"]

_EPS = np.finfo(float).eps


@dataclass
class DualData:
    """The relaxation's data and the solver's dual, in the relaxation's coordinates.

    ``c @ y`` is the objective; ``psd_maps[i] @ y = vec(M_i(y))`` (column-major) with dual
    ``psd_duals[i]`` (square, expected PSD), ``psd_maps[0]`` being the moment matrix
    ``M_k``; ``eq_map @ y = 0`` with dual ``eq_dual``; ``y_0 = 1`` with dual ``y0_dual``
    (cvxpy's sign: ``gamma = -y0_dual``). ``c_error``, ``psd_error_maps`` and
    ``eq_error_map`` are the same maps for the bounds on the coefficients' rounding errors
    (the stored problem vs the exact one); they are charged to the residual's margin.
    """

    c: np.ndarray
    psd_maps: list[sps.csr_array]
    psd_duals: list[np.ndarray]
    eq_map: sps.csr_array | None
    eq_dual: np.ndarray | None
    y0_dual: float
    c_error: np.ndarray | None = None
    psd_error_maps: list[sps.csr_array | None] | None = None
    eq_error_map: sps.csr_array | None = None


def _psd_part(Z: np.ndarray) -> np.ndarray:
    """``V max(w, 0) V^T`` computed as a Gram product (symmetric, PSD up to rounding)."""
    Z = np.atleast_2d(np.asarray(Z, dtype=float))
    w, V = np.linalg.eigh(0.5 * (Z + Z.T))
    F = V * np.sqrt(np.clip(w, 0.0, None))
    return F @ F.T


def residual(
    data: DualData, zplus: list[np.ndarray], keep: np.ndarray | None = None
) -> tuple[float, np.ndarray, np.ndarray]:
    """``(gamma, r, margin)``: residual coefficients of ``f - gamma - sum <Z_i^+, M_i>``.

    ``zplus`` are the PSD parts of the duals; ``keep`` (boolean over the basis of ``M_k``)
    zeroes the rows and columns of ``Z_0^+`` outside it first. ``margin`` bounds, per
    coefficient, the rounding error of the computed ``r_alpha`` and the difference between
    each computed ``Z^+ = F F^T`` and the exactly PSD ``F F^T``
    (``|E_ab| <= dim eps sqrt(Z_aa Z_bb)``), so the identity
    ``f - gamma = sum <F_i F_i^T, M_i> + r_true`` holds with ``|r_true - r| <= margin``.
    """
    gamma = -float(data.y0_dual)
    r = np.array(data.c, dtype=float)
    mag = np.abs(r)
    r[0] -= gamma
    mag[0] += abs(gamma)
    terms = 2  # summands per coefficient, for the rounding bound of a sum (n eps sum|.|)
    for i, (S, Zp) in enumerate(zip(data.psd_maps, zplus, strict=True)):
        if i == 0 and keep is not None:
            Zp = np.where(keep[:, None] & keep[None, :], Zp, 0.0)
        terms += int(np.diff(S.tocsc().indptr).max(initial=0))
        r -= S.T @ Zp.reshape(-1, order="F")
        d = np.sqrt(np.clip(np.diag(Zp), 0.0, None))
        env = (len(d) + 4) * np.outer(d, d)  # dominates |Zp| and the rounding of F F^T
        mag += abs(S).T @ env.reshape(-1, order="F")
    if data.eq_map is not None and data.eq_dual is not None:
        nu = np.asarray(data.eq_dual, dtype=float).ravel()
        r += data.eq_map.T @ nu
        mag += abs(data.eq_map).T @ np.abs(nu)
        terms += int(np.diff(data.eq_map.tocsc().indptr).max(initial=0))
    margin = 2.0 * terms * _EPS * mag
    margin += _data_error(data, zplus, keep)
    return gamma, r, margin


def _data_error(data: DualData, zplus: list[np.ndarray], keep: np.ndarray | None) -> np.ndarray:
    """Bound on the residual change if the exact (unrounded) problem data were used.

    ``|c_err| + sum_i |E_i|^T |Z_i| + |E_eq|^T |nu|`` with ``|Z_ab| <= sqrt(Z_aa Z_bb)``.
    """
    out = np.zeros(len(data.c))
    if data.c_error is not None:
        out += np.abs(data.c_error)
    for i, E in enumerate(data.psd_error_maps or []):
        if E is None:
            continue
        Zp = zplus[i]
        if i == 0 and keep is not None:
            Zp = np.where(keep[:, None] & keep[None, :], Zp, 0.0)
        d = np.sqrt(np.clip(np.diag(Zp), 0.0, None))
        out += abs(E).T @ np.outer(d, d).reshape(-1, order="F")
    if data.eq_error_map is not None and data.eq_dual is not None:
        out += abs(data.eq_error_map).T @ np.abs(np.asarray(data.eq_dual, dtype=float).ravel())
    return out * (1.0 + 1e-12)


def box_bound(
    index: MomentIndex, gamma: float, r: np.ndarray, margin: np.ndarray, radius: np.ndarray
) -> float:
    """``gamma + min_K r`` bounded through ``|z^alpha| <= radius^alpha`` (all variables boxed)."""
    mono = np.prod(np.asarray(radius, dtype=float)[None, :] ** index.exponents, axis=1)
    lower = r[0] - margin[0] - float(np.sum((np.abs(r[1:]) + margin[1:]) * mono[1:]))
    return gamma + lower


def gram_bound(
    index: MomentIndex,
    gamma: float,
    r: np.ndarray,
    margin: np.ndarray,
    Z0: np.ndarray,
    keep: np.ndarray | None = None,
) -> float:
    """``gamma - delta`` after absorbing ``r`` into the moment-matrix Gram matrix ``Z0``.

    ``keep`` (boolean, over the basis of ``M_k``; the constant monomial must be kept)
    restricts the Gram matrix to a subset of the basis; ``Z0``, ``r`` and ``margin`` must
    come from :func:`residual` with the same ``keep`` (``Z0`` unmasked). Each residual
    coefficient ``r_alpha`` is then spread evenly over the kept entries ``(b, c)`` with
    ``b + c = alpha``. Returns ``-inf`` when some nonzero
    ``r_alpha`` has no such entry or no finite ``delta`` works (the non-constant block is
    not positive definite with a safe margin).
    """
    N = index.basis_size(index.order)
    B = index.exponents[:N]
    pos = index.lookup(B[:, None, :] + B[None, :, :])  # moment index of entry (b, c)
    if keep is None:
        keep = np.ones(N, dtype=bool)
    if not keep[0]:
        raise ValueError("the constant monomial must be kept")
    sub = pos[np.ix_(keep, keep)]
    counts = np.bincount(sub.ravel(), minlength=index.size)
    covered = counts > 0
    if np.any((np.abs(r) + margin)[~covered] > 0.0):
        return -math.inf
    A = Z0[np.ix_(keep, keep)] + r[sub] / counts[sub]
    A = 0.5 * (A + A.T)
    # spectral norm of the error in R is at most the sum of the coefficient errors
    slack = float(np.sum(margin)) + 8.0 * _EPS * N * float(np.abs(A).max(initial=0.0))
    a, b, C = A[0, 0], A[0, 1:], A[1:, 1:]
    if A.shape[0] == 1:
        return gamma + min(0.0, a - slack)
    w, V = np.linalg.eigh(C)
    w = w - slack  # every eigenvalue made pessimistic by the rounding allowance
    if w[0] <= 0.0:
        return -math.inf
    proj = V.T @ b
    need = float(np.sum(proj**2 / w)) - (a - slack)
    return gamma - max(0.0, need)


def newton_keep(index: MomentIndex, support: list[tuple[int, ...]]) -> np.ndarray:
    """Basis monomials ``b`` of ``M_k`` with ``2b`` in the Newton polytope of ``f - gamma``.

    For an unconstrained problem every SOS decomposition of ``f - gamma`` uses only such
    monomials (Reznick 1978), so the others can be dropped from the Gram matrix.
    """
    from sosalgo.kernel.solvers import linear_program

    N = index.basis_size(index.order)
    P = np.array([*support, (0,) * index.n], dtype=float).T  # n x m vertices
    keep = np.zeros(N, dtype=bool)
    A_eq = np.vstack([P, np.ones((1, P.shape[1]))])
    for i, b in enumerate(index.exponents[:N]):
        rhs = np.concatenate([2.0 * b, [1.0]])
        res = linear_program(np.zeros(P.shape[1]), A_eq, rhs, (0, None))
        keep[i] = res.status == 0
    keep[0] = True
    return keep


def certified_bound(
    index: MomentIndex,
    data: DualData,
    radius: np.ndarray | None,
    target: float = -math.inf,
    newton_support: list[tuple[int, ...]] | None = None,
    keeps: list[np.ndarray] | None = None,
) -> tuple[float, float]:
    """``(certified lower bound, dual value gamma)`` in the relaxation's (scaled) units.

    ``radius`` (per variable, ``|z_i| <= radius_i`` on the feasible set) enables the box
    bound; None when some variable is unbounded. Gram absorption is tried on the full
    basis, on the Newton-polytope basis (``newton_support``: the objective's support, for
    unconstrained problems) and on the basis without rows whose diagonal in ``Z_0`` is
    negligible; the search stops once a bound reaches ``target``. Every candidate is a
    valid bound, so the best one is returned.
    """
    zplus = [_psd_part(Z) for Z in data.psd_duals]
    gamma, r, margin = residual(data, zplus)
    if not np.all(np.isfinite(r)) or not math.isfinite(gamma):
        return -math.inf, gamma
    best = -math.inf
    if radius is not None:
        best = box_bound(index, gamma, r, margin, radius)
        if best >= target:
            return best, gamma
    Z0 = zplus[0]
    candidates: list[np.ndarray | None] = [None, *(keeps or [])]
    if newton_support is not None:
        candidates.append(newton_keep(index, newton_support))
    diag = np.diag(Z0)
    top = float(diag.max(initial=0.0))
    for tau in (1e-10, 1e-8, 1e-6):
        keep = diag > tau * top
        keep[0] = True
        candidates.append(keep)
    seen: list[np.ndarray] = []
    for keep in candidates:
        if keep is not None:
            if any(np.array_equal(keep, k) for k in seen) or keep.all():
                continue
            seen.append(keep)
            _, r, margin = residual(data, zplus, keep)
        else:
            r, margin = r, margin
        best = max(best, gram_bound(index, gamma, r, margin, Z0, keep))
        if best >= target:
            break
    return best, gamma


def _cone_variable(dim: int, cons: list) -> Any:
    """A cvxpy multiplier of side ``dim`` in its cone (>= 0 for a scalar, ⪰ 0 otherwise),
    its constraint appended to ``cons``."""
    import cvxpy as cp

    if dim == 1:
        Zv = cp.Variable((1, 1))
        cons.append(Zv >= 0)
    else:
        Zv = cp.Variable((dim, dim), symmetric=True)
        cons.append(Zv >> 0)
    return Zv


def interior_dual(
    index: MomentIndex,
    data: DualData,
    gamma: float,
    keep: np.ndarray | None,
    solver: str,
    options: dict,
) -> DualData | None:
    """A dual for the backed-off level ``gamma`` whose Gram matrix is as interior as possible.

    Solves ``max eps`` s.t. ``f - gamma = <Z_0, m_B m_B^T> + sum_i <Z_i, M_i> + sum_j h_j q_j``,
    ``Z_0 ⪰ eps I`` (on the kept basis ``B``), ``Z_i ⪰ 0``, ``eps <= 1``. An interior
    point solver's own dual sits on the boundary of the PSD cone (``Z_0 m(x*) = 0`` at a
    minimizer), where no residual can be absorbed; with ``gamma`` a little below the
    relaxation's value, ``Z_0`` can be definite and :func:`gram_bound` then succeeds.
    Returns None if the solve fails. Only used for problems with unbounded variables.
    """
    import cvxpy as cp

    N = index.basis_size(index.order)
    if keep is None:
        keep = np.ones(N, dtype=bool)
    kept = np.flatnonzero(keep)
    nb = kept.size
    rows = (kept[:, None] + N * kept[None, :]).reshape(-1, order="F")
    S0 = data.psd_maps[0][rows]
    Q = cp.Variable((nb, nb), symmetric=True)
    eps = cp.Variable()
    expr = S0.T @ cp.vec(Q, order="F")
    cons = [Q - eps * np.eye(nb) >> 0, eps <= 1.0]
    zs = [_cone_variable(Z.shape[0], cons) for Z in data.psd_duals[1:]]
    for S, Zv in zip(data.psd_maps[1:], zs, strict=True):
        expr = expr + S.T @ cp.vec(Zv, order="F")
    w = None
    if data.eq_map is not None:
        w = cp.Variable(data.eq_map.shape[0])
        expr = expr + data.eq_map.T @ w
    rhs = np.array(data.c, dtype=float)
    rhs[0] -= gamma
    cons.append(expr == rhs)
    prob = cp.Problem(cp.Maximize(eps), cons)
    if cvxpy_solve(prob, solver, **options).error is not None:
        return None  # a failed refinement just leaves the bound as it was
    if Q.value is None or any(Zv.value is None for Zv in zs):
        return None
    Z0 = np.zeros((N, N))
    Z0[np.ix_(kept, kept)] = Q.value
    return DualData(
        c=data.c,
        psd_maps=data.psd_maps,
        psd_duals=[Z0, *[np.asarray(Zv.value, dtype=float) for Zv in zs]],
        eq_map=data.eq_map,
        eq_dual=None if w is None else -np.asarray(w.value, dtype=float),
        y0_dual=-gamma,
        c_error=data.c_error,
        psd_error_maps=data.psd_error_maps,
        eq_error_map=data.eq_error_map,
    )
