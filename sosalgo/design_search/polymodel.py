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
from fractions import Fraction

import numpy as np
import sympy as sp
from flint import arb, arb_mat

import sosalgo.design_search.enclosure as enc
from sosalgo.certificates.base import CertificateFamily
from sosalgo.kernel.conic import ExactBlock, LMIProblem
from sosalgo.kernel.expr.parse import to_sympy
from sosalgo.model import ModelError, evaluate_algorithm
from sosalgo.spec import Spec

__all__ = ["ExactMethod", "ModelTimeout", "PolyLMI", "check_polynomial", "exact_method",
           "poly_lmi", "shift_tensor"]

MAX_DEGREE = 12  # per free parameter; templates of higher degree are refused
KEYS = ("c0", "c1", "l0", "l1")


class ModelTimeout(TimeoutError):
    """The expansion of the polynomial model passed its deadline (checked between
    entries: one entry's expansion is the step that may run past it)."""


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


# --------------------------------------------------------------------------- exact method
@dataclass
class ExactMethod:
    """The method with exact entries, polynomial in z ∈ [-1, 1]^k (θ = mid + half·z).

    ``mid``/``half`` are exact (dyadic) and the box mid ± half contains Θ; ``m``, ``L``
    are exact rationals; ``matrices`` maps A, B, C, E (and D, absent E, in the oracle
    model) to sympy matrices in ``zs``.
    """

    free: list[str]
    zs: list[sp.Symbol]
    mid: list[Fraction]
    half: list[Fraction]
    m: sp.Rational
    L: sp.Rational
    matrices: dict[str, sp.Matrix]

    @property
    def k(self) -> int:
        return len(self.free)

    def theta(self, z: Sequence[float]) -> dict[str, float]:
        return {p: float(mi + hi * Fraction(float(zi)))
                for p, mi, hi, zi in zip(self.free, self.mid, self.half, z, strict=True)}


def _rat(x: float | Fraction) -> sp.Rational:
    q = Fraction(x)
    return sp.Rational(q.numerator, q.denominator)


def _outward(lo: sp.Expr, hi: sp.Expr) -> tuple[Fraction, Fraction]:
    """Float ends lo_f <= lo and hi_f >= hi of an exact interval."""
    from sosalgo.kernel.exact import enclose

    a, b = enclose(lo), enclose(hi)
    lo_f, hi_f = float(a.lo), float(b.hi)
    if Fraction(lo_f) > a.lo:
        lo_f = float(np.nextafter(lo_f, -np.inf))
    if Fraction(hi_f) < b.hi:
        hi_f = float(np.nextafter(hi_f, np.inf))
    return Fraction(lo_f), Fraction(hi_f)


def _rational_kappa(kappa: float) -> Fraction:
    """kappa as written (:func:`sosalgo.kernel.kappa.exact_kappa`: ``10/3`` is 10/3, a
    float its shortest decimal); ValueError when it is irrational."""
    from sosalgo.kernel.kappa import exact_kappa

    val = exact_kappa(kappa)
    if not val.is_Rational:
        raise ValueError(f"kappa {val} is irrational: the lower bound takes a rational kappa")
    return Fraction(int(val.p), int(val.q))


def exact_method(spec: Spec, kappa: float, free: Sequence[str]) -> ExactMethod:
    """The spec at ``kappa`` with the free parameters as scaled symbols (see class)."""
    from sosalgo.spec.types import BASE_SYMBOLS, value_order

    check_polynomial(spec, free)
    free = list(free)
    kq = _rational_kappa(kappa)
    mq = Fraction(float(spec.m))
    base = {BASE_SYMBOLS["m"]: _rat(mq), BASE_SYMBOLS["L"]: _rat(kq * mq),
            BASE_SYMBOLS["kappa"]: _rat(kq)}
    sym = spec.symbols
    values: dict[sp.Symbol, sp.Expr] = dict(base)
    for p in value_order(spec.parameters, spec.source):
        par = spec.parameters[p]
        if p in free:
            values[sym[p]] = sym[p]
            continue
        values[sym[p]] = to_sympy(par.tied if par.is_tied else par.value).xreplace(values)
    zs = [sp.Symbol(f"z{i}", real=True) for i in range(len(free))]
    mid, half = [], []
    for p in free:
        lo_e, hi_e = (to_sympy(e).xreplace(values) for e in spec.parameters[p].range)
        lo, hi = _outward(lo_e, hi_e)
        mid.append((lo + hi) / 2)
        half.append((hi - lo) / 2)
    scaled = {sym[p]: _rat(mi) + _rat(hi) * z
              for p, mi, hi, z in zip(free, mid, half, zs, strict=True)}
    mats = {k: mat.xreplace(values).xreplace(scaled)
            for k, mat in spec.sympy_matrices().items()}  # D too in the oracle model
    return ExactMethod(free, zs, mid, half, _rat(mq), _rat(kq * mq), mats)


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
            return self.method.theta(z)
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
    degrees, cols = ball_coefficients(entries, method.zs, deadline)
    balls = arb_mat(cols)
    mids = np.array([[float(x.mid()) for x in row] for row in cols])
    shape = tuple(d + 1 for d in degrees)
    coef = [{key: mids[:, s:s + int(np.prod(sh))].reshape(shape + sh)
             for key, (s, sh) in pos.items()} for pos in layout]
    return PolyLMI(list(method.free), np.array([float(x) for x in method.mid]),
                   np.array([float(x) for x in method.half]), degrees,
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
    return family.problem(evaluate_algorithm(spec, kappa, method.theta(np.zeros(method.k))))
