"""Sparse real polynomials as ``{exponent tuple: float coefficient}`` dictionaries.

All inner-loop algebra of the moment relaxation works on these dictionaries; sympy is
used only once, in :func:`from_sympy_with_error`, to expand the user's expressions.
"""

from __future__ import annotations

import itertools
import math
from collections import defaultdict
from collections.abc import Sequence
from fractions import Fraction

import numpy as np
import sympy as sp

_EPS = float(np.finfo(float).eps)

Exponent = tuple[int, ...]
PolyDict = dict[Exponent, float]

__all__ = [
    "Exponent",
    "PolyDict",
    "from_sympy_with_error",
    "exact_affine_substitute",
    "rational_affine_substitute",
    "degree",
    "evaluate",
    "abs_evaluate",
    "affine_substitute",
    "max_abs_coefficient",
    "scaled",
    "monomials_up_to",
]


def from_sympy_with_error(
    expr: object, variables: Sequence[sp.Symbol]
) -> tuple[PolyDict, PolyDict]:
    """Expand a sympy expression into a :data:`PolyDict` over ``variables``, with a bound
    on each coefficient's conversion error. Raises ``ValueError`` if ``expr`` is not a
    polynomial with real numeric coefficients in exactly these variables.

    The error is exactly ``|float(c) - c|`` (rounded up) for rational and floating-point
    sympy coefficients, and ``2 eps |float(c)|`` for others (``sqrt(2)`` ...).
    """
    try:
        expr = sp.sympify(expr, strict=True)  # strict: never parses (evaluates) a string
    except (sp.SympifyError, TypeError) as exc:
        raise ValueError(f"cannot interpret {expr!r} as a sympy expression") from exc
    extra = expr.free_symbols - set(variables)
    if extra:
        names = ", ".join(sorted(str(s) for s in extra))
        raise ValueError(f"expression {expr} contains symbols that are not variables: {names}")
    # Floats are replaced by their exact (binary) rational values first, so that sympy's
    # expansion is exact: expanding 1e9*(x - 1/3)**2 in Float arithmetic would round the
    # coefficients silently (and move the minimum) before any error could be accounted for.
    floats = expr.atoms(sp.Float)
    if floats:
        expr = expr.xreplace({f: sp.Rational(f) for f in floats})
    try:
        poly = sp.Poly(expr, *variables)
    except sp.PolynomialError as exc:
        raise ValueError(f"expression {expr} is not a polynomial in the variables") from exc
    out: PolyDict = {}
    err: PolyDict = {}
    for monom, coeff in poly.terms():
        try:
            value = float(coeff)
        except TypeError as exc:
            raise ValueError(f"coefficient {coeff} of {expr} is not a real number") from exc
        if not math.isfinite(value):
            raise ValueError(f"coefficient {coeff} of {expr} is not finite")
        e = tuple(int(a) for a in monom)
        if coeff.is_Rational or coeff.is_Float:
            q = sp.Rational(coeff)
            exact = Fraction(int(q.p), int(q.q))
            u = _round_up(abs(Fraction(value) - exact))
        else:
            u = 2.0 * _EPS * abs(value)
        if value != 0.0:
            out[e] = value
        if u > 0.0:
            err[e] = u
    return out, err


def _round_up(q: Fraction) -> float:
    """A float >= the nonnegative rational ``q``."""
    f = float(q)
    return f if Fraction(f) >= q else math.nextafter(f, math.inf)


def exact_affine_substitute(
    p: PolyDict, offset: Sequence[float], width: Sequence[float]
) -> tuple[PolyDict, PolyDict]:
    """:func:`affine_substitute` in exact rational arithmetic, then rounded once.

    Returns the rounded polynomial and the exact rounding error of each coefficient
    (rounded up), so the only error left is one rounding per coefficient (no cancellation
    error, which matters when a large-coefficient polynomial is re-centred near a root).
    """
    out = rational_affine_substitute(p, offset, width)
    poly: PolyDict = {}
    err: PolyDict = {}
    for e, q in out.items():
        v = float(q)
        if v != 0.0:
            poly[e] = v
        u = _round_up(abs(Fraction(v) - q))
        if u > 0.0:
            err[e] = u
    return poly, err


def rational_affine_substitute(
    p: PolyDict, offset: Sequence[float], width: Sequence[float]
) -> dict[Exponent, Fraction]:
    """:func:`affine_substitute` in exact rational arithmetic, not rounded."""
    out: defaultdict[Exponent, Fraction] = defaultdict(Fraction)
    offs = [Fraction(float(o)) for o in offset]
    wids = [Fraction(float(w)) for w in width]
    for e, c in p.items():
        factors = [
            [(j, math.comb(a, j) * o ** (a - j) * w**j) for j in range(a + 1)]
            for a, o, w in zip(e, offs, wids, strict=True)
        ]
        cf = Fraction(c)
        for combo in itertools.product(*factors):
            coef = cf
            for _, f in combo:
                coef *= f
            out[tuple(j for j, _ in combo)] += coef
    return {e: q for e, q in out.items() if q != 0}


def degree(p: PolyDict) -> int:
    """Total degree of ``p`` (0 for constants and for the zero polynomial)."""
    return max((sum(e) for e in p), default=0)


def evaluate(p: PolyDict, x: Sequence[float] | np.ndarray) -> float:
    """Value of ``p`` at the point ``x``."""
    xv = np.asarray(x, dtype=float)
    total = 0.0
    for e, c in p.items():
        total += c * float(np.prod(xv ** np.asarray(e)))
    return total


def abs_evaluate(p: PolyDict, x: Sequence[float] | np.ndarray) -> float:
    """``sum_alpha |c_alpha| |x^alpha|``: the magnitude scale of ``p``'s terms at ``x``."""
    xv = np.abs(np.asarray(x, dtype=float))
    return float(sum(abs(c) * np.prod(xv ** np.asarray(e)) for e, c in p.items()))


def affine_substitute(p: PolyDict, offset: Sequence[float], width: Sequence[float]) -> PolyDict:
    """Rewrite ``p(x)`` in the variables ``z`` where ``x_i = offset_i + width_i * z_i``."""
    out: defaultdict[Exponent, float] = defaultdict(float)
    for e, c in p.items():
        factors: list[list[tuple[int, float]]] = []
        for a, o, w in zip(e, offset, width, strict=True):
            if o == 0.0:
                factors.append([(a, w**a)])
            else:
                factors.append([(j, math.comb(a, j) * o ** (a - j) * w**j) for j in range(a + 1)])
        for combo in itertools.product(*factors):
            coef = c
            for _, f in combo:
                coef *= f
            out[tuple(j for j, _ in combo)] += coef
    return {e: c for e, c in out.items() if c != 0.0}


def max_abs_coefficient(p: PolyDict) -> float:
    """Largest absolute coefficient; 0 for the zero polynomial."""
    return max((abs(c) for c in p.values()), default=0.0)


def scaled(p: PolyDict, factor: float) -> PolyDict:
    """``factor * p``."""
    return {e: factor * c for e, c in p.items()}


def monomials_up_to(n: int, d: int) -> list[Exponent]:
    """Exponents of all monomials of degree <= ``d`` in ``n`` variables, graded order.

    Within a degree the order is ``x1^d, x1^(d-1) x2, ..., xn^d`` (GloptiPoly's order), so
    the basis of degree <= s is a prefix of the basis of degree <= t for s <= t.
    """
    out: list[Exponent] = []
    for t in range(d + 1):
        for combo in itertools.combinations_with_replacement(range(n), t):
            e = [0] * n
            for i in combo:
                e[i] += 1
            out.append(tuple(e))
    return out
