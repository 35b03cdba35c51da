"""The interface between certificate families and the solvers that use them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:  # only for annotations: families do not depend on the model at run time
    import sympy as sp

    from sosalgo.model import Algorithm


__all__ = ["AffineBlock", "LMIProblem", "CertificateFamily"]


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

    def max_eigs(self, x: np.ndarray, rho: float) -> dict[str, float]:
        """Largest eigenvalue of each block at (x, rho): all must be <= 0."""
        out = {}
        for b in self.blocks:
            if b.size == 1:  # a scalar row: its value is its eigenvalue
                out[b.name] = float(b.value(x, rho)[0, 0])
            else:
                out[b.name] = float(np.linalg.eigvalsh(b.value(x, rho))[-1])
        return out


class CertificateFamily(Protocol):
    """A family of Lyapunov certificates for linear rates on F(m, L)."""

    name: str
    description: str

    def problem(self, alg: Algorithm) -> LMIProblem:
        """Assemble the feasibility data for a numeric algorithm."""
        ...

    def symbolic(
        self, A: sp.Matrix, B: sp.Matrix, C: sp.Matrix, E: sp.Matrix, m: sp.Expr, L: sp.Expr
    ) -> tuple[sp.Matrix, dict[str, Any]]:
        """The main matrix inequality M ⪯ 0 in symbols, and the symbols it uses."""
        ...

    def matrix(self, alg: Algorithm, rho: float, cert: dict[str, Any]) -> np.ndarray:
        """The main matrix M at a numeric certificate (for reporting and checks)."""
        ...
