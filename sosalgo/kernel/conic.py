"""Conic data: LMI blocks affine in the decision vector and in rho^2, their exact twins, and
the scaled half-vectorization (svec) of symmetric matrices that the conic solvers read."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["AffineBlock", "ExactBlock", "LMIProblem", "svec", "svec_index", "sym_basis",
           "unit_quads", "unsvec"]

SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class AffineBlock:
    """``G(x; r) = c0 + r c1 + sum_i x_i (l0[i] + r l1[i])`` with r = rho^2; we need G ⪯ 0.

    ``c0, c1`` have shape (s, s); ``l0, l1`` have shape (nvar, s, s); all symmetric.
    """

    name: str
    c0: np.ndarray
    c1: np.ndarray
    l0: np.ndarray
    l1: np.ndarray
    strict: bool = True  # solve with G ⪯ -margin I (False for plain cones such as P ⪰ 0)

    @property
    def size(self) -> int:
        return int(self.c0.shape[0])

    def constant(self, rho: float) -> np.ndarray:
        return self.c0 + rho**2 * self.c1

    def linear(self, rho: float) -> np.ndarray:
        return self.l0 + rho**2 * self.l1

    def value(self, x: np.ndarray, rho: float) -> np.ndarray:
        """G(x; rho^2) as a dense symmetric matrix."""
        s = self.size
        lin = (x @ self.l0.reshape(len(x), -1) + rho**2 * (x @ self.l1.reshape(len(x), -1)))
        return self.constant(rho) + lin.reshape(s, s)


@dataclass(frozen=True)
class ExactBlock:
    """An :class:`AffineBlock` in exact arithmetic: sympy matrices (entries may be
    polynomials in the design parameters), ``l0``/``l1`` one matrix per variable."""

    name: str
    c0: Any
    c1: Any
    l0: list[Any]
    l1: list[Any]
    strict: bool = True


@dataclass(frozen=True, eq=False)
class LMIProblem:
    """Find x with every block ⪯ 0 at a given rho; ``unpack`` names the parts of x.

    ``project`` moves a solver's x onto the non-strict cones exactly (e.g. clips tiny
    negative eigenvalues of P), so that the floating-point check is meaningful.
    """

    nvar: int
    blocks: tuple[AffineBlock, ...]
    unpack: Callable[[np.ndarray], dict[str, Any]]
    project: Callable[[np.ndarray], np.ndarray] = lambda x: x


@functools.cache
def _tri_indices(s: int, upper_colmajor: bool) -> tuple[np.ndarray, np.ndarray]:
    if upper_colmajor:  # Clarabel: (0,0),(0,1),(1,1),(0,2),...
        pairs = [(i, j) for j in range(s) for i in range(j + 1)]
    else:  # SCS: lower triangle column-major: (0,0),(1,0),(2,0),(1,1),...
        pairs = [(i, j) for j in range(s) for i in range(j, s)]
    rows = np.array([p[0] for p in pairs])
    cols = np.array([p[1] for p in pairs])
    return rows, cols


def svec(mats: np.ndarray, upper_colmajor: bool = True) -> np.ndarray:
    """Scaled half-vectorization of symmetric matrix/matrices (last two axes): Clarabel's
    upper triangle column by column, or SCS's lower triangle (``upper_colmajor=False``)."""
    s = mats.shape[-1]
    if s == 1:
        return mats[..., 0, :1]
    r, c = _tri_indices(s, upper_colmajor)
    scale = np.where(r == c, 1.0, SQRT2)
    return mats[..., r, c] * scale


@functools.cache
def svec_index(d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, scale) of Clarabel's svec: upper triangle column by column."""
    r = np.array([i for j in range(d) for i in range(j + 1)], dtype=int)
    c = np.array([j for j in range(d) for i in range(j + 1)], dtype=int)
    return r, c, np.where(r == c, 1.0, SQRT2)


def unsvec(v: np.ndarray, d: int) -> np.ndarray:
    """The symmetric d x d matrix of Clarabel's svec ``v`` (inverse of :func:`svec`)."""
    r, c, s = svec_index(d)
    out = np.zeros((d, d))
    out[r, c] = v / s
    out[c, r] = v / s
    return out


def sym_basis(n: int) -> list[tuple[int, int]]:
    """The pairs (i, j), i <= j, of an n x n symmetric matrix, row by row: the coordinates
    of a symmetric matrix variable in the families' decision vectors."""
    return [(i, j) for i in range(n) for j in range(i, n)]


def unit_quads(Z: np.ndarray, pairs: list[tuple[int, int]] | None = None) -> np.ndarray:
    """Z' E_ab Z for every pair (a, b) (default: every a <= b, row by row, as
    :func:`sym_basis`), E_ab the symmetric unit matrix (1 at (a, b) and (b, a))."""
    ia, ib = np.triu_indices(Z.shape[0]) if pairs is None else np.array(pairs).T
    out = Z[ia][:, :, None] * Z[ib][:, None, :]
    off = ia != ib
    out[off] = out[off] + out[off].transpose(0, 2, 1)
    return out
