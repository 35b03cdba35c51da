"""A certificate family's LMI data as exact polynomials in the free parameters θ.

For the design problem (eq. 17) every block ``G_b(x; r) = c0 + r c1 + Σ x_i (l0_i + r l1_i)``
of a family has entries that are polynomials in θ whenever A, B, C, E are (Theorem 1:
products such as A'PA, eq. 14). This module

* decides, symbolically, that the templates are polynomial in the free parameters (a
  parameter entering through ``min``, ``sqrt``, ... is refused with its expression);
* writes the method exactly: κ and m are the rationals of their binary values, fixed
  parameters keep their exact values (e.g. (√κ − 1)/(√κ + 1)), and Θ is enclosed in a
  box with float (dyadic) ends, rounded outwards;
* builds the family's blocks from its exact form (``exact_problem``) in scaled
  coordinates z ∈ [-1, 1]^k (θ = mid + half·z) and expands every entry (sympy), so the
  degrees and coefficients are exact; each coefficient is then enclosed in a ball
  (:mod:`sosalgo.design_search.enclosure`). The SDPs use the balls' midpoints; proofs use the
  balls.
* re-expands the polynomial around any sub-box (a Taylor shift), in floats for the SDP
  and in ball arithmetic for proofs.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import sympy as sp
from flint import arb, arb_mat

import sosalgo.design_search.enclosure as enc
from sosalgo.certificates.base import CertificateFamily
from sosalgo.errors import ModelError
from sosalgo.exact_method import check_polynomial, polynomial_method
from sosalgo.kernel.conic import ExactBlock, LMIProblem
from sosalgo.model import evaluate_algorithm
from sosalgo.oracles import Method
from sosalgo.spec import Spec

__all__ = ["ExactMethod", "ModelTimeout", "PolyLMI", "check_polynomial", "exact_method",
           "poly_lmi", "shift_tensor"]

# the method with entries polynomial in the box coordinates: the one Method over ``poly``
# (:func:`sosalgo.exact_method.polynomial_method`; the names kept for the design code)
ExactMethod = Method
exact_method = polynomial_method

MAX_DEGREE = 12  # per free parameter; templates of higher degree are refused
KEYS = ("c0", "c1", "l0", "l1")


class ModelTimeout(TimeoutError):
    """The expansion of the polynomial model passed its deadline (checked between
    entries: one entry's expansion is the step that may run past it)."""


# --------------------------------------------------------------------------- LMI data
@dataclass
class PolyLMI:
    """Block data of a family as polynomials in z ∈ [-1, 1]^k (θ = mid + half·z).

    ``coef[b][name]`` (floats: the balls' midpoints) has shape (D_1+1, ..., D_k+1, *data
    shape) with monomial coefficients; ``name`` is one of ``c0, c1, l0, l1``.
    ``balls`` holds every coefficient as a ball: an arb matrix with one row per monomial
    (row-major over the degree grid) and the columns ``cols[b][name]`` (start, shape).
    """

    free: list[str]
    mid: np.ndarray
    half: np.ndarray
    degrees: tuple[int, ...]
    names: list[str]
    strict: list[bool]
    coef: list[dict[str, np.ndarray]]
    template: LMIProblem  # a problem at some θ: unpack/project do not depend on θ
    balls: arb_mat | None = None
    cols: list[dict[str, tuple[int, tuple[int, ...]]]] | None = None
    method: ExactMethod | None = None

    @property
    def k(self) -> int:
        return len(self.free)

    def theta(self, z: Sequence[float]) -> dict[str, float]:
        if self.method is not None:
            return self.method.box.theta(z)
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


def poly_lmi(method: ExactMethod, family: CertificateFamily, template: LMIProblem,
             deadline: float | None = None) -> PolyLMI | None:
    """The family's exact blocks at ``method`` as polynomial data (None: no exact form).
    ``deadline`` (``time.perf_counter``): :class:`ModelTimeout` once it has passed."""
    A, B, C, E = (method.matrices[k] for k in ("A", "B", "C", "E"))
    blocks = family.exact_problem(A, B, C, E, method.m, method.L)
    if blocks is None:
        return None
    entries: list[sp.Expr] = []
    layout = []
    for blk in blocks:
        pos = {}
        for key in KEYS:
            mats = _key_mats(blk, key)
            shape = (len(mats), *mats[0].shape) if key in ("l0", "l1") else mats[0].shape
            pos[key] = (len(entries), tuple(shape))
            for M in mats:
                entries.extend(M)  # row-major
        layout.append(pos)
    degrees, cols = ball_coefficients(entries, method.box.zs, deadline)
    balls = arb_mat(cols)
    mids = np.array([[float(x.mid()) for x in row] for row in cols])
    shape = tuple(d + 1 for d in degrees)
    coef = [{key: mids[:, s:s + int(np.prod(sh))].reshape(shape + sh)
             for key, (s, sh) in pos.items()} for pos in layout]
    box = method.box
    return PolyLMI(list(box.free), np.array([float(x) for x in box.mid]),
                   np.array([float(x) for x in box.half]), degrees,
                   [b.name for b in blocks], [b.strict for b in blocks], coef, template,
                   balls, layout, method)


def _expand(exprs: list[sp.Expr], zs: list[sp.Symbol], deadline: float | None
            ) -> list[sp.Poly | None]:
    """Each expression as a polynomial in ``zs`` (None: constant), refused at the first
    entry of too high a degree, stopped between entries once ``deadline`` has passed."""
    zset = set(zs)
    polys: list[sp.Poly | None] = []
    for e in exprs:
        if deadline is not None and time.perf_counter() > deadline:
            raise ModelTimeout(f"the polynomial model was expanded for {len(polys)} of "
                               f"{len(exprs)} entries")
        p = sp.Poly(e, *zs) if e.free_symbols & zset else None
        if p is not None and max(p.degree_list()) > MAX_DEGREE:
            raise ModelError("parameters", f"the certificate data have degree "
                             f"{max(p.degree_list())} > {MAX_DEGREE} in a free parameter; "
                             "design refuses it")
        polys.append(p)
    return polys


def ball_coefficients(exprs: list[sp.Expr], zs: list[sp.Symbol],
                      deadline: float | None = None
                      ) -> tuple[tuple[int, ...], list[list[arb]]]:
    """Monomial coefficients of polynomials in ``zs`` as balls, on a common degree grid:
    (degrees, rows), one row per monomial (row-major), one column per expression.
    ``deadline``: :class:`ModelTimeout` once it has passed (between entries)."""
    polys = _expand(exprs, zs, deadline)
    dlists = [p.degree_list() for p in polys if p is not None]
    degrees = tuple(max((d[i] for d in dlists), default=0) for i in range(len(zs)))
    dims = [d + 1 for d in degrees]
    zero = arb(0)
    rows = [[zero] * len(exprs) for _ in range(int(np.prod(dims)))]
    for j, (e, p) in enumerate(zip(exprs, polys, strict=True)):
        if p is None:
            if e != 0:
                rows[0][j] = enc.sympy_ball(e)
            continue
        for monom, c in p.terms():
            rows[int(np.ravel_multi_index(monom, dims))][j] = enc.sympy_ball(c)
    return degrees, rows


def _key_mats(blk: ExactBlock, key: str) -> list[sp.Matrix]:
    val = getattr(blk, key)
    return list(val) if key in ("l0", "l1") else [val]


# --------------------------------------------------------------------------- floats
def shift_matrices(center: float, half: float, degree: int) -> np.ndarray:
    """S with p(center + half·u) = Σ_i u^i (S @ a)_i for p(z) = Σ_j a_j z^j."""
    from math import comb

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


def numeric_template(spec: Spec, kappa: float, method: ExactMethod,
                     family: CertificateFamily) -> LMIProblem:
    """The family's numeric problem at the box center (its unpack/project, sizes)."""
    box = method.box
    return family.problem(evaluate_algorithm(spec, kappa, box.theta(np.zeros(box.k))))
