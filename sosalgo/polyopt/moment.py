"""Moment and localizing matrices as sparse linear maps of the moment vector ``y``.

For a truncated moment sequence ``y = (y_alpha)_{|alpha| <= 2k}`` (Lasserre 2001):

* the moment matrix ``M_t(y)`` has entry ``y_{beta + gamma}`` at row ``beta``, column
  ``gamma`` (monomials of degree <= t, graded order);
* the localizing matrix of a polynomial ``g = sum_delta g_delta x^delta`` is
  ``M_t(g y)[beta, gamma] = sum_delta g_delta y_{beta + gamma + delta}``;
* for a symmetric polynomial matrix ``G = (G_ab)`` of size p, the localizing matrix
  ``M_t(G y)`` is the ``p N_t`` square block matrix with blocks ``M_t(G_ab y)``
  (Henrion-Lasserre 2006, "Convergent relaxations of polynomial matrix inequalities");
* an equality ``h = 0`` gives the linear moment equations ``L_y(h x^alpha) = 0``.

Each matrix is returned as a sparse matrix ``S`` with ``vec(M) = S @ y`` (column-major
vec); the maps are symmetric by construction.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from .polynomial import Exponent, PolyDict, monomials_up_to

__all__ = ["MomentIndex"]


class MomentIndex:
    """Index of the monomials of degree <= ``2 * order`` in ``n`` variables.

    ``monomials[i]`` is the exponent of ``y[i]``; the first ``C(n + t, t)`` entries are
    the basis of degree <= t used for ``M_t``.
    """

    def __init__(self, n: int, order: int) -> None:
        self.n = n
        self.order = order
        self.monomials: list[Exponent] = monomials_up_to(n, 2 * order)
        self.exponents = np.array(self.monomials, dtype=np.int64).reshape(-1, n)
        self.degrees = self.exponents.sum(axis=1)
        self._base = 2 * order + 1
        self._weights = self._base ** np.arange(n, dtype=np.int64)
        keys = self.exponents @ self._weights
        self._order_keys = np.argsort(keys)
        self._sorted_keys = keys[self._order_keys]

    @property
    def size(self) -> int:
        """Number of moments ``C(n + 2k, 2k)``."""
        return len(self.monomials)

    def basis_size(self, t: int) -> int:
        """Number of monomials of degree <= t."""
        return int(np.count_nonzero(self.degrees <= t)) if t >= 0 else 0

    def lookup(self, exps: np.ndarray) -> np.ndarray:
        """Indices of the exponent rows ``exps`` (shape ``(..., n)``) in ``y``."""
        keys = exps @ self._weights
        pos = np.searchsorted(self._sorted_keys, keys)
        return self._order_keys[pos]

    def index_of(self, e: Exponent) -> int:
        """Index of a single exponent tuple."""
        return int(self.lookup(np.asarray(e, dtype=np.int64)[None, :])[0])

    def linear_functional(self, p: PolyDict) -> np.ndarray:
        """Dense vector ``c`` with ``c @ y = L_y(p)``."""
        c = np.zeros(self.size)
        for e, coef in p.items():
            c[self.index_of(e)] += coef
        return c

    def _block_entries(self, g: PolyDict, t: int) -> tuple[np.ndarray, np.ndarray]:
        """Moment indices and coefficients of the entries of ``M_t(g y)``.

        Returns arrays of shape ``(terms, N_t, N_t)``: entry ``(beta, gamma)`` of the
        localizing matrix is ``sum over terms of coef * y[index]``.
        """
        N = self.basis_size(t)
        B = self.exponents[:N]
        pair = B[:, None, :] + B[None, :, :]
        idx, val = [], []
        for e, coef in g.items():
            shifted = pair + np.asarray(e, dtype=np.int64)
            idx.append(self.lookup(shifted))
            val.append(np.full((N, N), coef))
        if not idx:
            return np.zeros((0, N, N), dtype=np.int64), np.zeros((0, N, N))
        return np.stack(idx), np.stack(val)

    def localizing_map(self, g: PolyDict, t: int) -> sps.csr_array:
        """Sparse ``S`` (``N_t^2 x size``) with ``vec(M_t(g y)) = S @ y``."""
        return self.matrix_localizing_map([[g]], t)

    def moment_map(self, t: int) -> sps.csr_array:
        """Sparse ``S`` with ``vec(M_t(y)) = S @ y``."""
        return self.localizing_map({(0,) * self.n: 1.0}, t)

    def matrix_localizing_map(self, G: list[list[PolyDict]], t: int) -> sps.csr_array:
        """Sparse ``S`` (``(p N_t)^2 x size``) with ``vec(M_t(G y)) = S @ y``."""
        p = len(G)
        N = self.basis_size(t)
        dim = p * N
        rows, cols, vals = [], [], []
        local = np.arange(N)
        for a in range(p):
            for b in range(p):
                idx, val = self._block_entries(G[a][b], t)
                if idx.shape[0] == 0:
                    continue
                r = a * N + local[:, None]
                c = b * N + local[None, :]
                flat = np.broadcast_to(r + c * dim, (N, N))  # column-major position
                rows.append(np.broadcast_to(flat, idx.shape).ravel())
                cols.append(idx.ravel())
                vals.append(val.ravel())
        if not rows:
            return sps.csr_array((dim * dim, self.size))
        S = sps.coo_array(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(dim * dim, self.size),
        )
        return S.tocsr()  # duplicates are summed

    def equality_map(self, h: PolyDict) -> sps.csr_array:
        """Rows ``L_y(h x^alpha)`` for all ``|alpha| <= 2k - deg h``."""
        dh = max(sum(e) for e in h)
        count = self.basis_size(2 * self.order - dh)
        A = self.exponents[:count]
        rows, cols, vals = [], [], []
        for e, coef in h.items():
            rows.append(np.arange(count))
            cols.append(self.lookup(A + np.asarray(e, dtype=np.int64)))
            vals.append(np.full(count, coef))
        S = sps.coo_array(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(count, self.size),
        )
        return S.tocsr()

    def moment_matrix(self, y: np.ndarray, t: int) -> np.ndarray:
        """Dense ``M_t(y)`` for a numeric moment vector ``y``."""
        N = self.basis_size(t)
        B = self.exponents[:N]
        return np.asarray(y)[self.lookup(B[:, None, :] + B[None, :, :])]
