"""A certificate family's LMI data as exact polynomials in the free parameters θ.

For the design problem (eq. 17) every block ``G_b(x; r) = c0 + r c1 + Σ x_i (l0_i + r l1_i)``
of a family has entries that are polynomials in θ whenever A, B, C, E are (Theorem 1:
products such as A'PA, eq. 14). This module

* decides, symbolically, that the templates are polynomial in the free parameters (a
  parameter entering through ``min``, ``sqrt``, ... is refused with its expression);
* recovers the polynomial of every data entry by interpolation on a tensor Chebyshev grid
  in scaled coordinates z ∈ [-1, 1]^k (θ = mid + half·z), with the degree found along each
  axis and the fit verified at random points;
* re-expands the polynomial around any sub-box (a Taylor shift), so that ranges over the
  sub-box can be bounded: for u ∈ [-1, 1]^k, |p(u) - a_0| <= Σ_{α≠0} |a_α|.

Everything goes through the family's numeric ``problem``, so any family plugs in.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from math import comb

import numpy as np
import sympy as sp

from sosalgo.certificates.base import AffineBlock, CertificateFamily, LMIProblem
from sosalgo.expr.parse import to_sympy
from sosalgo.model import Algorithm, ModelError, evaluate_algorithm
from sosalgo.spec import Spec

__all__ = ["PolyLMI", "check_polynomial", "fit_poly_lmi", "shift_matrices"]

MAX_DEGREE = 12  # per free parameter; templates of higher degree are refused
FIT_RTOL = 1e-11  # relative to the data scale; measured errors are ~1e-15


def check_polynomial(spec: Spec, free: Sequence[str]) -> None:
    """Raise ModelError unless every template entry is a polynomial in the free parameters.

    Tied parameters are checked first (naming the parameter and its expression), then the
    matrix entries (other input parameters keep their ``value``).
    """
    syms = [spec.symbols[p] for p in free]
    symset = set(syms)
    for name, expr in spec.tied_closure().items():
        if expr.free_symbols & symset and not expr.is_polynomial(*syms):
            raise ModelError(
                f"parameters.{name}",
                f"{name} = {_show(to_sympy(spec.parameters[name].tied))} is not polynomial "
                f"in the free parameter(s) {_names(free, syms, expr)}; design needs "
                "polynomial dependence",
            )
    for key, mat in spec.templates(free).items():
        for (i, j), entry in np.ndenumerate(np.array(mat.tolist(), dtype=object)):
            entry = sp.sympify(entry)
            if entry.free_symbols & symset and not entry.is_polynomial(*syms):
                raise ModelError(
                    f"matrices.{key}[{i}][{j}]",
                    f"{_show(entry)} is not polynomial in the free parameter(s) "
                    f"{_names(free, syms, entry)}; design needs polynomial dependence",
                )


def _names(free: Sequence[str], syms: Sequence[sp.Symbol], expr: sp.Expr) -> str:
    return ", ".join(p for p, s in zip(free, syms, strict=True) if s in expr.free_symbols)


def _show(expr: sp.Basic, n: int = 80) -> str:
    """An expression as a spec would write it (min, max, abs in lower case)."""
    text = str(expr)
    for a, b in (("Min(", "min("), ("Max(", "max("), ("Abs(", "abs(")):
        text = text.replace(a, b)
    return text if len(text) <= n else text[: n - 3] + "..."


def _cheb_nodes(d: int) -> np.ndarray:
    j = np.arange(d + 1)
    return np.cos(np.pi * (j + 0.5) / (d + 1))


def shift_matrices(center: float, half: float, degree: int) -> np.ndarray:
    """S with p(center + half·u) = Σ_i u^i (S @ a)_i for p(z) = Σ_j a_j z^j."""
    S = np.zeros((degree + 1, degree + 1))
    for j in range(degree + 1):
        for i in range(j + 1):
            S[i, j] = comb(j, i) * center ** (j - i) * half**i
    return S


def _apply_axes(T: np.ndarray, mats: Sequence[np.ndarray]) -> np.ndarray:
    """Apply mats[i] along axis i of T (the leading k axes)."""
    for i, M in enumerate(mats):
        T = np.moveaxis(np.tensordot(M, T, axes=([1], [i])), 0, i)
    return T


@dataclass
class PolyLMI:
    """Block data of a family as polynomials in z ∈ [-1, 1]^k (θ = mid + half·z).

    ``coef[b][name]`` has shape (D_1+1, ..., D_k+1, *data shape) with monomial
    coefficients; ``name`` is one of ``c0, c1, l0, l1``.
    """

    free: list[str]
    mid: np.ndarray
    half: np.ndarray
    degrees: tuple[int, ...]
    names: list[str]
    strict: list[bool]
    coef: list[dict[str, np.ndarray]]
    template: LMIProblem  # a problem at some θ: unpack/project do not depend on θ

    @property
    def k(self) -> int:
        return len(self.free)

    def theta(self, z: Sequence[float]) -> dict[str, float]:
        th = self.mid + self.half * np.asarray(z, dtype=float)
        return dict(zip(self.free, map(float, th), strict=True))

    def depends_on_theta(self, b: int) -> bool:
        for arr in self.coef[b].values():
            flat = arr.reshape(int(np.prod(arr.shape[: self.k])), -1)
            if np.any(flat[1:] != 0):
                return True
        return False

    def shifted(self, b: int, name: str, center: np.ndarray, half: np.ndarray) -> np.ndarray:
        """Coefficients of block ``b``'s ``name`` in local coordinates u of a sub-box."""
        return shift_tensor(self.coef[b][name], self.degrees, center, half)

    def at(self, z: Sequence[float]) -> LMIProblem:
        """The numeric problem at scaled point z (evaluated from the polynomials)."""
        blocks = []
        for b, name in enumerate(self.names):
            data = {key: evaluate_tensor(arr, self.degrees, z)
                    for key, arr in self.coef[b].items()}
            blocks.append(AffineBlock(name, data["c0"], data["c1"], data["l0"], data["l1"],
                                      self.strict[b]))
        return LMIProblem(self.template.nvar, tuple(blocks), self.template.unpack,
                          self.template.project)


def fit_tensor(
    fn: Callable[[np.ndarray], np.ndarray], half: np.ndarray
) -> tuple[tuple[int, ...], np.ndarray, float]:
    """Monomial coefficients (in z ∈ [-1, 1]^k) of a vector-valued polynomial ``fn(z)``.

    The degree along each axis comes from a high-degree 1-D fit through the center
    (trailing coefficients below 1e-9 of the data scale dropped), then one tensor
    Chebyshev grid of those degrees is interpolated. Returns (degrees, coef, scale) with
    coef of shape (D_1+1, ..., D_k+1, len(fn(z))).
    """
    k = len(half)
    base = np.asarray(fn(np.zeros(k)), dtype=float)
    scale = max(1.0, float(np.abs(base).max()))
    degrees = []
    for i in range(k):
        if half[i] == 0:
            degrees.append(0)
            continue
        nodes = _cheb_nodes(MAX_DEGREE)
        vals = []
        for t in nodes:
            z = np.zeros(k)
            z[i] = t
            vals.append(fn(z))
        V = np.vander(nodes, MAX_DEGREE + 1, increasing=True)
        c = np.linalg.solve(V, np.array(vals))
        mags = np.abs(c).max(axis=1)
        nz = np.nonzero(mags > 1e-9 * scale)[0]
        degrees.append(int(nz[-1]) if nz.size else 0)
    grids = [_cheb_nodes(d) for d in degrees]
    shape = tuple(d + 1 for d in degrees)
    data = np.empty(shape + base.shape)
    for idx in np.ndindex(*shape):
        data[idx] = fn(np.array([grids[i][j] for i, j in enumerate(idx)]))
    inv = [np.linalg.inv(np.vander(g, len(g), increasing=True)) for g in grids]
    coef = _apply_axes(data, inv)
    coef[np.abs(coef) < 1e-13 * scale] = 0.0
    return tuple(degrees), coef, scale


def evaluate_tensor(coef: np.ndarray, degrees: Sequence[int], z: Sequence[float]) -> np.ndarray:
    """Value at z of the polynomial with monomial coefficient tensor ``coef``."""
    pows = [np.asarray(zi) ** np.arange(d + 1)
            for zi, d in zip(np.asarray(z, dtype=float), degrees, strict=True)]
    k = len(pows)
    return _apply_axes(coef, [p[None, :] for p in pows]).reshape(coef.shape[k:])


def shift_tensor(coef: np.ndarray, degrees: Sequence[int], center: np.ndarray,
                 half: np.ndarray) -> np.ndarray:
    """Coefficients in local coordinates u of the sub-box center + half·u."""
    mats = [shift_matrices(c, h, d) for c, h, d in zip(center, half, degrees, strict=True)]
    return _apply_axes(coef, mats)


def _flatten(problem: LMIProblem) -> np.ndarray:
    return np.concatenate([np.concatenate([b.c0.ravel(), b.c1.ravel(), b.l0.ravel(),
                                           b.l1.ravel()]) for b in problem.blocks])


def fit_poly_lmi(
    spec: Spec, kappa: float, free: Sequence[str], box: Sequence[tuple[float, float]],
    family: CertificateFamily, seed: int = 0,
) -> PolyLMI:
    """Interpolate the family's data over ``box`` (see module docstring)."""
    check_polynomial(spec, free)
    free = list(free)
    lo = np.array([b[0] for b in box], dtype=float)
    hi = np.array([b[1] for b in box], dtype=float)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)

    def problem_at(z: np.ndarray) -> LMIProblem:
        th = dict(zip(free, map(float, mid + half * z), strict=True))
        alg: Algorithm = evaluate_algorithm(spec, kappa, th)
        return family.problem(alg)

    k = len(free)
    template = problem_at(np.zeros(k))
    degrees, coef, scale = fit_tensor(lambda z: _flatten(problem_at(z)), half)
    shape = tuple(d + 1 for d in degrees)
    # unflatten into blocks
    out: list[dict[str, np.ndarray]] = []
    pos = 0
    for blk in template.blocks:
        entry = {}
        for key, arr in (("c0", blk.c0), ("c1", blk.c1), ("l0", blk.l0), ("l1", blk.l1)):
            size = arr.size
            entry[key] = coef[..., pos:pos + size].reshape(shape + arr.shape)
            pos += size
        out.append(entry)
    model = PolyLMI(free, mid, half, tuple(degrees), [b.name for b in template.blocks],
                    [b.strict for b in template.blocks], out, template)
    rng = np.random.default_rng(seed)
    for _ in range(3):  # the fit must reproduce the family at points off the grid
        z = rng.uniform(-1, 1, size=k)
        direct, fitted = _flatten(problem_at(z)), _flatten(model.at(z))
        if np.abs(direct - fitted).max() > FIT_RTOL * scale:
            raise ModelError(
                "parameters",
                f"the certificate data are not polynomial in {', '.join(free)} of degree "
                f"<= {MAX_DEGREE}; design needs polynomial dependence",
            )
    return model
