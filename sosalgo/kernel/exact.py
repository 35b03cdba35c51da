"""Exact arithmetic that proofs are made of: rationals, rational balls, enclosures, PSD proofs.

- Rational symmetric matrices are decided PSD exactly (:func:`prove_psd`): an LDL^T
  factorization with rational pivots; a zero pivot (semidefinite case) falls back to
  principal minors (n <= 8) or to LDL^T with diagonal pivoting.
- :class:`Ball`: a real number known to lie in c ± r (exact rationals), closed under
  +, -, *; :func:`enclose` puts a constant sympy expression (sqrt, exp, log, pi, ...) in
  a rational ball by mpmath's outward-rounding interval arithmetic;
  :func:`prove_definite` proves sign * M ⪰ delta I for every matrix of a ball matrix M.
- :func:`rational` (the exact binary value of a float), :func:`rational_at_least`,
  :func:`rho_candidates`, :func:`round_down`: roundings that never go the unsafe way.
- :class:`Verdict`: what an exact check concludes.
"""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from fractions import Fraction
from typing import Any

import mpmath
import numpy as np
import sympy as sp
from mpmath import libmp

__all__ = [
    "Ball", "BallMatrix", "DEFAULT_DIGITS", "DEFAULT_MAX_DEN", "DEFAULT_RHO_STEPS", "Matrix",
    "PSDProof", "Verdict", "enclose", "float_str", "fraction_str", "frobenius_bound",
    "is_exact", "is_zero", "object_matrix", "prove_definite", "prove_psd", "psd_by_minors",
    "rational", "rational_at_least", "rho_candidates", "round_down", "symmetrize_balls",
]


DEFAULT_MAX_DEN = 10**12
DEFAULT_RHO_STEPS = (0.0, 1e-12, 1e-10, 1e-9, 1e-8, 1e-7)  # relative increases tried
DEFAULT_DIGITS = 50  # decimals of the rational enclosures of irrational entries
MINORS_MAX_N = 8  # principal-minor fallback up to this size, pivoted LDL^T beyond

Matrix = list[list[Fraction]]


def fraction_str(x: Fraction) -> str:
    return f"{x.numerator}/{x.denominator}" if x.denominator != 1 else str(x.numerator)


def float_str(x: Fraction) -> str:
    """Six digits of ``x``; beyond the float range its order of magnitude (~1e+400)."""
    try:
        return f"{float(x):.6g}"
    except OverflowError:
        q = abs(Fraction(x))
        digits = len(str(q.numerator)) - len(str(q.denominator))
        return f"{'-' if x < 0 else ''}~1e{digits:+d}"


# --------------------------------------------------------------------------- PSD proofs


@dataclass(frozen=True)
class PSDProof:
    """Outcome of an exact PSD test of a rational symmetric matrix.

    ``kind`` is "definite", "semidefinite" or "indefinite"; ``method`` says which test
    decided ("ldl", "minors" or "pivoted-ldl"); ``pivots`` are the LDL^T pivots computed.
    """

    psd: bool
    kind: str
    method: str
    pivots: tuple[Fraction, ...]
    detail: str


def _as_fractions(S: Sequence[Sequence[Any]]) -> Matrix:
    out = [[Fraction(v) for v in row] for row in S]
    n = len(out)
    if any(len(row) != n for row in out):
        raise ValueError("matrix must be square")
    for i in range(n):
        for j in range(i):
            if out[i][j] != out[j][i]:
                raise ValueError(f"matrix is not symmetric at ({i}, {j})")
    return out


def _det(S: Matrix) -> Fraction:
    """Exact determinant by Gaussian elimination with row exchanges."""
    a = [row[:] for row in S]
    n = len(a)
    det = Fraction(1)
    for k in range(n):
        piv = next((i for i in range(k, n) if a[i][k] != 0), None)
        if piv is None:
            return Fraction(0)
        if piv != k:
            a[k], a[piv] = a[piv], a[k]
            det = -det
        det *= a[k][k]
        for i in range(k + 1, n):
            f = a[i][k] / a[k][k]
            if f:
                for j in range(k + 1, n):
                    a[i][j] -= f * a[k][j]
    return det


def psd_by_minors(S: Sequence[Sequence[Any]]) -> bool:
    """PSD iff every principal minor (all 2^n - 1 of them) is >= 0, exactly."""
    a = _as_fractions(S)
    n = len(a)
    for size in range(1, n + 1):
        for idx in itertools.combinations(range(n), size):
            if _det([[a[i][j] for j in idx] for i in idx]) < 0:
                return False
    return True


def _pivoted_ldl(a: Matrix) -> tuple[bool, list[Fraction], str]:
    """Schur complements on the largest diagonal entry.

    A diagonal < 0 proves indefiniteness; if every remaining diagonal is 0 the matrix is
    PSD iff the remaining block is 0 (a PSD matrix with a zero diagonal entry has a zero
    row); with a pivot > 0, S ⪰ 0 iff its Schur complement ⪰ 0.
    """
    a = [row[:] for row in a]
    pivots: list[Fraction] = []
    while a:
        diag = [a[i][i] for i in range(len(a))]
        neg = [i for i, v in enumerate(diag) if v < 0]
        if neg:
            msg = f"negative diagonal {float_str(diag[neg[0]])} in a Schur complement"
            return False, pivots, msg
        k = max(range(len(a)), key=lambda i: diag[i])
        if diag[k] == 0:
            nz = any(v != 0 for row in a for v in row)
            msg = "zero-diagonal block with a nonzero entry" if nz else "zero remaining block"
            return not nz, pivots, msg
        p = a[k][k]
        pivots.append(p)
        rest = [i for i in range(len(a)) if i != k]
        a = [[a[i][j] - a[i][k] * a[k][j] / p for j in rest] for i in rest]
    return True, pivots, "all pivots > 0 or zero block"


def solve_affine(eqs: Sequence[Sequence[Any] | Mapping[int, Any]], rhs: Sequence[Any],
                 n: int, free_value: Any) -> list[Fraction] | None:
    """A solution x of ``eqs`` x = ``rhs`` (n unknowns, rational entries; a row is a
    sequence, or a mapping column -> entry whose missing columns are 0) in exact
    rationals: the reduced row echelon form of the augmented system (python-flint's
    ``fmpq_mat``), each free coordinate c at ``free_value(c)`` (a Fraction), the pivots
    solved from them; None when the system is inconsistent."""
    from flint import fmpq, fmpq_mat

    zero = fmpq(0)

    def q(v: Any) -> Any:
        if not v:
            return zero
        f = v if isinstance(v, Fraction) else Fraction(v)
        return fmpq(f.numerator, f.denominator)

    if not eqs:
        return [Fraction(free_value(c)) for c in range(n)]
    aug = fmpq_mat(len(eqs), n + 1)  # zeros: only the nonzero entries are set
    for i, (row, b) in enumerate(zip(eqs, rhs, strict=True)):
        for c, v in (row.items() if isinstance(row, Mapping) else enumerate(row)):
            if v:
                aug[i, c] = q(v)
        if b:
            aug[i, n] = q(b)
    R, rank = aug.rref()
    pivots: list[int] = []
    for i in range(rank):  # each row's pivot right of the one above (echelon form)
        c = next(c for c in range(pivots[-1] + 1 if pivots else 0, n + 1) if R[i, c] != 0)
        if c == n:  # a row 0 = 1
            return None
        pivots.append(c)
    x = [Fraction(0)] * n
    z = fmpq_mat(n + 1, 1)  # the free values, -1 on the right-hand side, 0 on the pivots
    z[n, 0] = -1
    for c in sorted(set(range(n)) - set(pivots)):
        x[c] = Fraction(free_value(c))
        if x[c]:
            z[c, 0] = q(x[c])
    Rz = R * z  # row i: sum over free f of R[i, f] x_f - R[i, n] = -x[pivot i]
    for i, c in enumerate(pivots):
        v = Rz[i, 0]
        x[c] = -Fraction(int(v.p), int(v.q))
    return x


def prove_psd(S: Sequence[Sequence[Any]]) -> PSDProof:
    """Decide S ⪰ 0 exactly for a rational symmetric S.

    LDL^T without pivoting: all pivots > 0 means positive definite (Sylvester). A negative
    pivot after positive ones is a negative leading principal minor: not PSD. A zero pivot
    (semidefinite or indefinite) falls back to principal minors (n <= 8) or to LDL^T with
    diagonal pivoting.
    """
    a = _as_fractions(S)
    n = len(a)
    if n == 0:
        return PSDProof(True, "definite", "ldl", (), "empty matrix")
    w = [row[:] for row in a]
    pivots: list[Fraction] = []
    for k in range(n):
        p = w[k][k]
        if p < 0:
            pivots.append(p)
            return PSDProof(
                False, "indefinite", "ldl", tuple(pivots),
                f"pivot {k + 1} is negative ({float_str(p)}): a leading principal minor < 0",
            )
        if p == 0:
            break
        pivots.append(p)
        for i in range(k + 1, n):
            f = w[i][k] / p
            if f:
                row_k = w[k]
                row_i = w[i]
                for j in range(k + 1, n):
                    row_i[j] -= f * row_k[j]
    else:
        return PSDProof(True, "definite", "ldl", tuple(pivots), "all LDL^T pivots > 0")
    if n <= MINORS_MAX_N:
        ok = psd_by_minors(a)
        detail = "all principal minors >= 0" if ok else "a principal minor is negative"
        return PSDProof(ok, "semidefinite" if ok else "indefinite", "minors", tuple(pivots), detail)
    ok, piv, detail = _pivoted_ldl(a)
    return PSDProof(ok, "semidefinite" if ok else "indefinite", "pivoted-ldl", tuple(piv), detail)


# --------------------------------------------------------------------------- ball arithmetic


class Ball:
    """A real number known to lie in [c - r, c + r] (exact rationals c, r >= 0)."""

    __slots__ = ("c", "r")

    def __init__(self, c: Fraction | int, r: Fraction | int = 0):
        self.c = Fraction(c)
        self.r = Fraction(r)

    @staticmethod
    def of(x: Ball | Fraction | int) -> Ball:
        return x if isinstance(x, Ball) else Ball(x)

    def __add__(self, o: Ball | Fraction | int) -> Ball:
        o = Ball.of(o)
        return Ball(self.c + o.c, self.r + o.r)

    __radd__ = __add__

    def __neg__(self) -> Ball:
        return Ball(-self.c, self.r)

    def __sub__(self, o: Ball | Fraction | int) -> Ball:
        o = Ball.of(o)
        return Ball(self.c - o.c, self.r + o.r)

    def __rsub__(self, o: Ball | Fraction | int) -> Ball:
        return Ball.of(o) - self

    def __mul__(self, o: Ball | Fraction | int) -> Ball:
        o = Ball.of(o)
        if not self.r and not o.r:
            return Ball(self.c * o.c)
        return Ball(self.c * o.c, abs(self.c) * o.r + abs(o.c) * self.r + self.r * o.r)

    __rmul__ = __mul__

    @property
    def lo(self) -> Fraction:
        return self.c - self.r

    @property
    def hi(self) -> Fraction:
        return self.c + self.r

    def __repr__(self) -> str:
        return f"Ball({float(self.c)!r} ± {float(self.r):.3g})"


BallMatrix = list[list[Ball]]


def object_matrix(mat: list[list[Ball]]) -> np.ndarray:
    """Rows of balls as an object array (kept exact: numpy never converts them)."""
    out = np.empty((len(mat), len(mat[0]) if mat else 0), dtype=object)
    for i, row in enumerate(mat):
        for j, b in enumerate(row):
            out[i, j] = b
    return out


def symmetrize_balls(M: np.ndarray) -> list[list[Ball]]:
    """A square matrix of numbers or balls as a symmetric ball matrix: the centres must
    agree across the diagonal, each pair of entries gets the larger radius."""
    s = M.shape[0]
    out = [[Ball.of(M[i, j]) for j in range(s)] for i in range(s)]
    for i in range(s):
        for j in range(i):
            if out[i][j].c != out[j][i].c:
                raise AssertionError("matrix centre is not symmetric")
            r = max(out[i][j].r, out[j][i].r)
            out[i][j] = out[j][i] = Ball(out[i][j].c, r)
    return out


def prove_definite(M: list[list[Ball]], sign: int) -> tuple[bool, Fraction, str]:
    """Prove sign * M ⪰ delta I for every matrix in the ball matrix M; (ok, delta, detail)."""
    eta = frobenius_bound(M)
    S = [[sign * b.c for b in row] for row in M]
    s = len(S)
    try:
        est = float(np.linalg.eigvalsh(np.array([[float(v) for v in row] for row in S]))[0])
    except (OverflowError, np.linalg.LinAlgError):
        est = math.nan
    targets = []
    if math.isfinite(est) and est > 0 and Fraction(f"{est / 2:.3g}") > eta:
        targets.append(Fraction(f"{est / 2:.3g}"))
    targets.append(eta)
    detail = ""
    for t in targets:
        proof = prove_psd([[S[i][j] - (t if i == j else 0) for j in range(s)] for i in range(s)])
        if proof.psd:
            return True, round_down(t - eta), f"{proof.kind} ({proof.method})"
        detail = proof.detail
    return False, Fraction(0), f"not proven (min eig estimate {est:.3g}): {detail}"


# --------------------------------------------------------------------------- enclosures


def _mpf_fraction(raw: tuple) -> Fraction:
    if raw in (libmp.finf, libmp.fninf, libmp.fnan):
        raise ValueError("interval enclosure is unbounded")
    sign, man, exp, _ = raw
    val = Fraction(man) * (Fraction(2) ** exp)
    return -val if sign else val


def _iv(expr: sp.Expr) -> Any:
    """Rigorous mpmath interval of a constant sympy expression (outward rounding)."""
    iv = mpmath.iv
    if expr.is_Rational:
        return iv.mpf(int(expr.p)) / iv.mpf(int(expr.q))
    if expr.is_Float:
        q = Fraction(*sp.Rational(expr).as_numer_denom())
        return iv.mpf(q.numerator) / iv.mpf(q.denominator)
    if expr is sp.pi:
        return iv.pi
    if expr is sp.E:
        return iv.e
    if isinstance(expr, sp.Add):
        out = iv.mpf(0)
        for a in expr.args:
            out = out + _iv(a)
        return out
    if isinstance(expr, sp.Mul):
        out = iv.mpf(1)
        for a in expr.args:
            out = out * _iv(a)
        return out
    if isinstance(expr, sp.Pow):
        base, ex = expr.args
        if ex.is_Integer:
            b = _iv(base)
            k = int(ex)
            return b ** k if k >= 0 else iv.mpf(1) / (b ** (-k))
        if ex == sp.Rational(1, 2):
            return iv.sqrt(_iv(base))
        if ex == sp.Rational(-1, 2):
            return iv.mpf(1) / iv.sqrt(_iv(base))
        return iv.exp(_iv(ex) * iv.log(_iv(base)))
    if isinstance(expr, sp.exp):
        return iv.exp(_iv(expr.args[0]))
    if isinstance(expr, sp.log):
        return iv.log(_iv(expr.args[0]))
    if isinstance(expr, sp.Abs):
        return abs(_iv(expr.args[0]))
    if isinstance(expr, sp.Min | sp.Max):
        parts = [_iv(a)._mpi_ for a in expr.args]
        pick = min if isinstance(expr, sp.Min) else max
        lo = pick(mpmath.mp.make_mpf(p[0]) for p in parts)
        hi = pick(mpmath.mp.make_mpf(p[1]) for p in parts)
        return iv.mpf([lo, hi])
    raise ValueError(f"cannot enclose {type(expr).__name__} in {expr}")


def enclose(expr: sp.Expr, digits: int = DEFAULT_DIGITS) -> Ball:
    """A rational ball containing the real constant ``expr`` (exact when it is rational)."""
    expr = sp.sympify(expr)
    if expr.free_symbols:
        names = sorted(map(str, expr.free_symbols))
        raise ValueError(f"expression {expr} still has symbols {names}")
    if expr.is_Rational:
        return Ball(Fraction(int(expr.p), int(expr.q)))
    old = mpmath.iv.prec
    try:
        mpmath.iv.prec = int(digits * 3.33) + 64
        val = _iv(expr)
    finally:
        mpmath.iv.prec = old
    if not isinstance(val, mpmath.iv.mpf):
        raise ValueError(f"{expr} is not a real number")
    lo, hi = (_mpf_fraction(r) for r in val._mpi_)
    scale = 10**digits
    lo_r = Fraction(math.floor(lo * scale), scale)
    hi_r = Fraction(math.ceil(hi * scale), scale)
    return Ball((lo_r + hi_r) / 2, (hi_r - lo_r) / 2)


def rational(x: Any) -> Fraction:
    """Exact rational value of a float (its binary value) / int / Fraction / "p/q" string."""
    if is_exact(x):
        return Fraction(x if not isinstance(x, numbers.Integral) else int(x))
    xf = float(x)
    if not math.isfinite(xf):
        raise ValueError(f"{x} is not finite")
    return Fraction(xf)


def is_exact(x: Any) -> bool:
    """Exact inputs (int, Fraction, "p/q" strings) are used as given, without rounding."""
    return isinstance(x, numbers.Rational | str) and not isinstance(x, bool)


def is_zero(expr: sp.Expr) -> bool:
    """True only when ``expr == 0`` is proven (automatic or exact algebraic simplification)."""
    expr = sp.sympify(expr)
    if expr == 0 or expr.is_zero is True:
        return True
    if sp.simplify(expr) == 0:
        return True
    try:
        x = sp.Dummy("x")
        return sp.minimal_polynomial(expr, x) == x
    except (NotImplementedError, ValueError, sp.polys.polyerrors.PolynomialError):
        return False


# --------------------------------------------------------------------------- rationals


def rational_at_least(x: float | Fraction, max_den: int = DEFAULT_MAX_DEN) -> Fraction:
    """A rational >= x with denominator <= max_den (x itself when its denominator fits).

    The best approximation is used when it is >= x, else ceil(x max_den) / max_den.
    """
    f = Fraction(x)
    if f.denominator <= max_den:
        return f
    g = f.limit_denominator(max_den)
    return g if g >= f else Fraction(math.ceil(f * max_den), max_den)


def rho_candidates(rho: Fraction, steps: Sequence[float], max_den: int) -> list[Fraction]:
    r = rho
    out: list[Fraction] = []
    for s in steps:
        c = rational_at_least(r * (1 + rational(s)), max_den)
        if c > 1 >= r:
            c = Fraction(1)
        if c not in out:
            out.append(c)
    return out


def _upper_sqrt(s: Fraction, sig: int = 8) -> Fraction:
    """A rational t >= sqrt(s) (s >= 0) with about ``sig`` significant digits."""
    if s <= 0:
        return Fraction(0)
    p, q = s.numerator, s.denominator
    t = Fraction(math.isqrt(p * q) + 1, q)  # (isqrt(pq) + 1)^2 > pq, so t^2 > s
    mag = len(str(t.numerator)) - len(str(t.denominator))  # ~ log10(t)
    scale = Fraction(10) ** (sig - mag)
    return Fraction(math.ceil(t * scale)) / scale


def round_down(x: Fraction, sig: int = 8) -> Fraction:
    """A rational <= x with about ``sig`` significant digits (x itself if x <= 0)."""
    if x <= 0:
        return x
    mag = len(str(x.numerator)) - len(str(x.denominator))
    scale = Fraction(10) ** (sig - mag)
    return Fraction(math.floor(x * scale)) / scale


def frobenius_bound(M: BallMatrix) -> Fraction:
    return _upper_sqrt(sum((b.r * b.r for row in M for b in row), Fraction(0)))


# --------------------------------------------------------------------------- verdicts


class Verdict(StrEnum):
    """Verdict of a verification (a str: compares and serializes as one)."""

    EXACT = "exact"  # proven in exact arithmetic (rational numbers and enclosures)
    FAILED = "failed"  # not proven, or nothing to prove it with (``reason`` says why)
