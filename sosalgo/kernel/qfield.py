"""Exact arithmetic in a real quadratic field Q(sqrt d) (d > 1 squarefree).

A proof whose data are irrational only through one square root (sqrt(mu), sqrt(kappa)
with rational mu, kappa) can be decided exactly in Q(sqrt d) where ball arithmetic
cannot: a singular certificate whose null direction has irrational entries is PSD with
an exact zero there, which no ball proves.

- :class:`QSqrt`: a + b sqrt(d) with Fraction parts, closed under +, -, *, /; its sign is
  exact (``a + b sqrt d > 0`` decided through squares), so comparisons are exact.
- :func:`radicand`: the one squarefree d of a set of sympy numbers (None when they need
  more than one square root or another irrational); :func:`to_field`: a sympy number as
  an element of Q(sqrt d) (ValueError when it is not one).
- :func:`recognize`: a float as a short element of Q(sqrt d) (an integer relation found
  by PSLQ; a guess that the caller's exact proof must confirm).
- :func:`solve_linear`: Gauss-Jordan elimination over the field (free variables
  reported); :func:`field_psd`: S ⪰ 0 decided exactly (LDL^T with diagonal pivoting).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction
from typing import Any

import mpmath
import sympy as sp

__all__ = ["QSqrt", "field_psd", "parse_element", "radicand", "recognize", "solve_linear",
           "to_field"]


Number = Any  # a QSqrt, a Fraction or an int


class QSqrt:
    """The number a + b sqrt(d) (a, b rational; d > 1 a squarefree integer)."""

    __slots__ = ("a", "b", "d")

    def __init__(self, a: Fraction | int, b: Fraction | int, d: int):
        self.a, self.b, self.d = Fraction(a), Fraction(b), int(d)

    def _other(self, o: Any) -> QSqrt:
        if isinstance(o, QSqrt):
            if o.d != self.d:
                raise ArithmeticError(f"sqrt({self.d}) and sqrt({o.d}) in one field")
            return o
        if isinstance(o, int | Fraction) and not isinstance(o, bool):
            return QSqrt(o, 0, self.d)
        return NotImplemented  # type: ignore[return-value]

    def __add__(self, o: Any) -> QSqrt:
        o = self._other(o)
        return NotImplemented if o is NotImplemented else QSqrt(self.a + o.a, self.b + o.b,
                                                                self.d)

    __radd__ = __add__

    def __neg__(self) -> QSqrt:
        return QSqrt(-self.a, -self.b, self.d)

    def __sub__(self, o: Any) -> QSqrt:
        o = self._other(o)
        return NotImplemented if o is NotImplemented else QSqrt(self.a - o.a, self.b - o.b,
                                                                self.d)

    def __rsub__(self, o: Any) -> QSqrt:
        return (-self) + o

    def __mul__(self, o: Any) -> QSqrt:
        o = self._other(o)
        if o is NotImplemented:
            return o
        return QSqrt(self.a * o.a + self.d * self.b * o.b, self.a * o.b + self.b * o.a,
                     self.d)

    __rmul__ = __mul__

    def norm(self) -> Fraction:
        """a^2 - d b^2: zero only for 0 (d is not a square)."""
        return self.a * self.a - self.d * self.b * self.b

    def inverse(self) -> QSqrt:
        n = self.norm()
        if n == 0:
            raise ZeroDivisionError("division by zero in Q(sqrt d)")
        return QSqrt(self.a / n, -self.b / n, self.d)

    def __truediv__(self, o: Any) -> QSqrt:
        o = self._other(o)
        return NotImplemented if o is NotImplemented else self * o.inverse()

    def __rtruediv__(self, o: Any) -> QSqrt:
        return self.inverse() * o

    def sign(self) -> int:
        """The exact sign of a + b sqrt(d)."""
        sa, sb = (self.a > 0) - (self.a < 0), (self.b > 0) - (self.b < 0)
        if sa == sb or sb == 0:
            return sa
        if sa == 0:
            return sb
        return sa if self.a * self.a > self.d * self.b * self.b else sb

    def _cmp(self, o: Any) -> int:
        o = self._other(o)
        if o is NotImplemented:
            raise TypeError(f"cannot compare QSqrt with {type(o).__name__}")
        return (self - o).sign()

    def __eq__(self, o: object) -> bool:
        try:
            return self._cmp(o) == 0
        except TypeError:
            return False

    def __ne__(self, o: object) -> bool:
        return not self == o

    def __lt__(self, o: Any) -> bool:
        return self._cmp(o) < 0

    def __le__(self, o: Any) -> bool:
        return self._cmp(o) <= 0

    def __gt__(self, o: Any) -> bool:
        return self._cmp(o) > 0

    def __ge__(self, o: Any) -> bool:
        return self._cmp(o) >= 0

    def __bool__(self) -> bool:
        return bool(self.a or self.b)

    def __abs__(self) -> QSqrt:
        return -self if self.sign() < 0 else self

    def __hash__(self) -> int:
        return hash((self.a, self.b, self.d)) if self.b else hash(self.a)

    def __float__(self) -> float:
        if (self.a > 0) != (self.b > 0) and self.a and self.b:  # cancellation: the norm
            return float(self.norm() / (self.a - self.b * Fraction(math.sqrt(self.d))))
        return float(self.a) + float(self.b) * math.sqrt(self.d)

    def upper(self) -> Fraction:
        """A rational >= the number within about 1e-30 of it (outward)."""
        if not self.b:
            return self.a
        scale = 10 ** 30
        t = self.b * self.b * self.d * scale * scale  # (b sqrt d * scale)^2
        r = math.isqrt(math.floor(t))  # floor of |b| sqrt(d) scale, up to one unit
        s = Fraction(r + 1, scale) if self.b > 0 else -Fraction(r, scale)
        return self.a + s

    def parts(self) -> list[str]:
        """[a, b] as exact strings (p/q)."""
        return [_fs(self.a), _fs(self.b)]

    def text(self) -> str:
        """The closed form, e.g. ``-1/10 + 3/7*sqrt(10)``."""
        if not self.b:
            return _fs(self.a)
        root = f"{_fs(abs(self.b))}*sqrt({self.d})" if abs(self.b) != 1 else f"sqrt({self.d})"
        if not self.a:
            return root if self.b > 0 else f"-{root}"
        return f"{_fs(self.a)} {'+' if self.b > 0 else '-'} {root}"

    def __repr__(self) -> str:
        return f"QSqrt({self.text()})"


def _fs(x: Fraction) -> str:
    return f"{x.numerator}/{x.denominator}" if x.denominator != 1 else str(x.numerator)


def parse_element(v: Any, d: int) -> QSqrt:
    """[a, b] (exact strings or integers) as a + b sqrt(d); ValueError when malformed."""
    if not isinstance(v, list | tuple) or len(v) != 2 or any(
            isinstance(x, bool) or not isinstance(x, str | int) for x in v):
        raise ValueError(f"expected [a, b] (exact p/q strings), got {v!r}")
    return QSqrt(Fraction(v[0]), Fraction(v[1]), d)


def _squarefree(n: int) -> int:
    out, k = 1, 2
    while k * k <= n:
        while n % (k * k) == 0:
            n //= k * k
        if n % k == 0:
            out *= k
            n //= k
        k += 1
    return out * n


def radicand(exprs: Sequence[Any]) -> int | None:
    """The squarefree d > 1 of the only square root the sympy numbers ``exprs`` use
    (sqrt(p/q) counts as sqrt(p q) / q); None when they use none, several, or another
    irrational (a cube root, pi, a nested radical)."""
    found: set[int] = set()
    for e in exprs:
        e = sp.sympify(e)
        if e.is_Rational:
            continue
        for atom in e.atoms(sp.Pow):
            if atom.exp == sp.Rational(1, 2) or atom.exp == sp.Rational(-1, 2):
                if not atom.base.is_Rational or atom.base <= 0:
                    return None
                base = sp.Rational(atom.base)
                found.add(_squarefree(int(base.p) * int(base.q)))
            elif not atom.exp.is_Integer:
                return None
        if e.atoms(sp.NumberSymbol) or e.has(sp.exp, sp.log, sp.sin, sp.cos):
            return None
    found.discard(1)
    return found.pop() if len(found) == 1 else None


def to_field(expr: Any, d: int) -> QSqrt:
    """The sympy number ``expr`` as a + b sqrt(d), exactly; ValueError when it is not in
    Q(sqrt d)."""
    e = sp.sympify(expr)
    if e.is_Rational:
        return QSqrt(Fraction(int(e.p), int(e.q)), 0, d)
    r = sp.sqrt(d)
    e = sp.expand(sp.radsimp(e))
    try:
        poly = sp.Poly(e, r)
    except sp.PolynomialError as exc:
        raise ValueError(f"{expr} is not in Q(sqrt({d}))") from exc
    a, b = Fraction(0), Fraction(0)
    for (k,), c in poly.terms():
        c = sp.nsimplify(c) if not c.is_Rational else c
        if not c.is_Rational:
            raise ValueError(f"{expr} is not in Q(sqrt({d}))")
        q = Fraction(int(c.p), int(c.q)) * Fraction(d) ** (k // 2)
        if k % 2:
            b += q
        else:
            a += q
    out = QSqrt(a, b, d)
    val = float(sp.N(expr, 30))
    if not math.isclose(float(out), val, rel_tol=1e-12, abs_tol=1e-300):
        raise ValueError(f"{expr} is not in Q(sqrt({d})) (conversion check)")
    return out


def recognize(x: float, d: int, maxcoeff: int = 10 ** 5, tol: float = 1e-9
              ) -> QSqrt | None:
    """A short a + b sqrt(d) equal to ``x`` within ``tol`` (relative), found as an
    integer relation c0 x + c1 + c2 sqrt(d) = 0 (PSLQ, coefficients up to ``maxcoeff``);
    None when there is none. A guess: only an exact check downstream decides."""
    if x == 0:
        return QSqrt(0, 0, d)
    short = Fraction(x).limit_denominator(1000)
    if abs(float(short) - x) <= tol * max(1.0, abs(x)):
        return QSqrt(short, 0, d)
    with mpmath.workdps(30):
        rel = mpmath.pslq([mpmath.mpf(x), 1, mpmath.sqrt(d)], tol=tol * max(1.0, abs(x)),
                          maxcoeff=maxcoeff, maxsteps=10 ** 4)
    if not rel or rel[0] == 0:
        return None
    out = QSqrt(Fraction(-rel[1], rel[0]), Fraction(-rel[2], rel[0]), d)
    return out if abs(float(out) - x) <= 10 * tol * max(1.0, abs(x)) else None


def solve_linear(A: list[list[Number]], b: list[Number]
                 ) -> tuple[list[list[Number]], list[Number], list[int]] | None:
    """Gauss-Jordan on A x = b over the field: (rows of the reduced system as
    (coefficients on the free variables), constants, free columns) so that
    x[pivot_i] = const_i - sum_f coef_i[f] x[f]; None when inconsistent. Use
    :func:`back_substitute` with the free values."""
    m = len(A)
    n = len(A[0]) if m else 0
    R = [list(row) + [rhs] for row, rhs in zip(A, b, strict=True)]
    pivots: list[int] = []
    r = 0
    for c in range(n):
        p = next((i for i in range(r, m) if R[i][c] != 0), None)
        if p is None:
            continue
        R[r], R[p] = R[p], R[r]
        inv = 1 / R[r][c]
        R[r] = [v * inv for v in R[r]]
        for i in range(m):
            if i != r and R[i][c] != 0:
                f = R[i][c]
                R[i] = [vi - f * vr for vi, vr in zip(R[i], R[r], strict=True)]
        pivots.append(c)
        r += 1
        if r == m:
            break
    if any(R[i][n] != 0 for i in range(r, m)):
        return None
    free = [c for c in range(n) if c not in pivots]
    coefs = [[R[i][f] for f in free] for i in range(r)]
    consts = [R[i][n] for i in range(r)]
    return coefs, consts, free + [-1] + pivots  # free columns, separator, pivot columns


def back_substitute(system: tuple[list[list[Number]], list[Number], list[int]],
                    values: list[Number], n: int) -> list[Number]:
    """The solution of :func:`solve_linear`'s ``system`` with its free variables at
    ``values`` (in the order of its free columns); ``n`` unknowns."""
    coefs, consts, cols = system
    cut = cols.index(-1)
    free, pivots = cols[:cut], cols[cut + 1:]
    x: list[Number] = [Fraction(0)] * n
    for f, v in zip(free, values, strict=True):
        x[f] = v
    for i, p in enumerate(pivots):
        x[p] = consts[i] - sum((c * v for c, v in zip(coefs[i], values, strict=True)),
                               Fraction(0))
    return x


def field_psd(S: list[list[Number]]) -> tuple[bool, str]:
    """S ⪰ 0 decided exactly over the field: symmetric, then Schur complements on the
    largest diagonal entry (a negative diagonal proves indefiniteness; a zero diagonal
    needs a zero row). (psd, detail)."""
    n = len(S)
    for i in range(n):
        for j in range(i):
            if S[i][j] != S[j][i]:
                return False, f"not symmetric at ({i}, {j})"
    a = [list(row) for row in S]
    rank = 0
    while a:
        diag = [a[i][i] for i in range(len(a))]
        neg = [i for i, v in enumerate(diag) if v < 0]
        if neg:
            return False, f"negative diagonal {float(diag[neg[0]]):.6g} in a Schur complement"
        k = max(range(len(a)), key=lambda i: diag[i])
        if diag[k] == 0:
            if any(v != 0 for row in a for v in row):
                return False, "a zero diagonal with a nonzero entry in its row"
            break
        p = a[k][k]
        rank += 1
        rest = [i for i in range(len(a)) if i != k]
        a = [[a[i][j] - a[i][k] * a[k][j] / p for j in rest] for i in rest]
    return True, f"LDL^T in Q(sqrt d): {rank} positive pivots, the rest exactly 0"
