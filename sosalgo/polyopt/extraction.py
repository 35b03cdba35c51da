"""Flatness test and extraction of global minimizers from a moment matrix.

Implements the numerical linear algebra of Henrion & Lasserre (2005), "Detecting global
optimality and extracting solutions in GloptiPoly":

1. *Flat extension* (Curto-Fialkow): if ``rank M_s(y) = rank M_{s-d}(y) = r`` for some
   ``d <= s <= k`` (``d = max(1, max_i ceil(deg g_i / 2))``), then ``y`` is the moment
   vector of an r-atomic measure on the feasible set and the relaxation is exact.
2. *Extraction*: factor ``M_s = V V^T`` (V of rank r), bring V to column echelon form
   ``U`` (the pivots select r basis monomials ``w(x)``, chosen here by QR with column
   pivoting on the rows of degree <= s - d for numerical stability), read off the
   multiplication matrices ``N_i`` with ``N_i w(x) = x_i w(x)``, take a random
   combination ``N = sum_i lambda_i N_i`` and its Schur form ``N = Q T Q^*``; the atoms
   are ``x_i(j) = q_j^* N_i q_j`` (returned sorted, which plays the role of the paper's
   ordered Schur form).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from .moment import MomentIndex

__all__ = ["numerical_rank", "rank_gap", "flat_orders", "extract_atoms", "RANK_GAP"]

#: A numerical rank r counts for the flatness test only when the r-th largest eigenvalue
#: exceeds the (r+1)-th by at least this factor (a clear gap, not a threshold artefact).
RANK_GAP = 1e3


def numerical_rank(M: np.ndarray, tol: float) -> int:
    """Number of eigenvalues of the symmetric ``M`` above ``tol * max eigenvalue``."""
    w = np.linalg.eigvalsh(0.5 * (M + M.T))
    top = float(w[-1]) if w.size else 0.0
    if top <= 0.0:
        return 0
    return int(np.count_nonzero(w > tol * top))


def rank_gap(M: np.ndarray, rank: int) -> float:
    """Ratio of the ``rank``-th to the ``(rank+1)``-th largest eigenvalue (inf if none).

    Eigenvalues at or below zero count as zero; 0 when the ``rank``-th is not positive.
    """
    w = np.sort(np.linalg.eigvalsh(0.5 * (M + M.T)))[::-1]
    if rank < 1 or rank > w.size or w[rank - 1] <= 0.0:
        return 0.0
    if rank == w.size:
        return np.inf
    nxt = max(float(w[rank]), 0.0)
    return np.inf if nxt == 0.0 else float(w[rank - 1]) / nxt


def flat_orders(ranks: list[int], shift: int) -> list[int]:
    """Orders ``s`` with ``rank M_s == rank M_{s - shift}``; ``ranks[t]`` is rank ``M_t``.

    ``ranks[0]`` is the rank of ``M_0 = [y_0] = [1]``, i.e. 1.
    """
    k = len(ranks) - 1
    return [s for s in range(shift, k + 1) if ranks[s] == ranks[s - shift] and ranks[s] > 0]


def extract_atoms(
    index: MomentIndex,
    y: np.ndarray,
    s: int,
    shift: int,
    rank: int,
    rng: np.random.Generator,
    attempts: int = 3,
) -> np.ndarray | None:
    """Atoms (``rank x n`` array) of the flat moment matrix ``M_s(y)``, or None on failure.

    Follows the algorithm of Henrion-Lasserre (2005). Fails (returns None) when the pivot
    block is numerically singular, a needed monomial is missing, or the multiplication
    matrices do not have real, separated eigenvalues.
    """
    n = index.n
    M = index.moment_matrix(y, s)
    w, vecs = np.linalg.eigh(0.5 * (M + M.T))
    if rank < 1 or w[-rank] <= 0.0:
        return None
    V = vecs[:, -rank:] * np.sqrt(w[-rank:])  # M ~ V V^T
    n_cand = index.basis_size(s - shift)
    if n_cand < rank:
        return None
    _, R, piv = sla.qr(V[:n_cand].T, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    if diag.size < rank or diag[rank - 1] <= 1e-10 * diag[0]:
        return None
    pivots = np.sort(piv[:rank])
    W = V[pivots]  # rank x rank, rows = basis monomials w(x)
    try:
        U = np.linalg.solve(W.T, V.T).T  # V = U W, so v_s(x) = U w(x) on the atoms
    except np.linalg.LinAlgError:
        return None
    pivot_exps = index.exponents[pivots]
    n_rows = index.basis_size(s)
    mult = []
    for i in range(n):
        shifted = pivot_exps.copy()
        shifted[:, i] += 1
        rows = index.lookup(shifted)
        if np.any(rows >= n_rows):
            return None
        mult.append(U[rows])  # N_i: (N_i w)(x) = x_i w(x)
    return _joint_eigenvalues(mult, rank, rng, attempts)


def _joint_eigenvalues(mult: list[np.ndarray], rank: int, rng: np.random.Generator,
                       attempts: int) -> np.ndarray | None:
    """The atoms from the multiplication matrices ``mult`` (N_i w = x_i w on the atoms):
    Schur form of a random combination, its eigenvalues separated; None when they are not
    (after ``attempts`` combinations) or when the atoms are complex."""
    n = len(mult)
    scale = max(1.0, max(float(np.abs(Ni).max()) for Ni in mult))
    for _ in range(attempts):
        lam = rng.random(n) + 0.1
        lam /= lam.sum()
        N = sum(lam[i] * mult[i] for i in range(n))
        T, Q = sla.schur(N, output="complex")
        eig = np.diag(T)
        if rank > 1:
            gaps = np.abs(eig[:, None] - eig[None, :])
            np.fill_diagonal(gaps, np.inf)
            if gaps.min() < 1e-6 * scale:
                continue  # coincident eigenvalues: the atoms are not separated, retry
        # Q^* N_i Q is upper triangular with the i-th coordinates of the atoms on its
        # diagonal, since every N_i is a polynomial in N (distinct eigenvalues).
        atoms = np.array([np.einsum("ij,ik,kj->j", Q.conj(), Ni, Q) for Ni in mult]).T
        if np.abs(atoms.imag).max() > 1e-3 * scale:
            return None  # complex atoms: the moment matrix is not a real measure's
        atoms = atoms.real
        return atoms[np.lexsort(atoms.T[::-1])]  # ordered, lexicographically
    return None
