"""python-flint (Arb) helpers shared by the ball-arithmetic proofs: the working precision,
exact rationals as balls and back."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from fractions import Fraction

from flint import arb, ctx, fmpq

__all__ = ["PREC", "arb_fraction", "arb_of", "precision"]

PREC = 256  # bits of the enclosures


@contextmanager
def precision(bits: int = PREC) -> Iterator[None]:
    """Run flint's ball arithmetic at ``bits`` of working precision."""
    old = ctx.prec
    ctx.prec = bits
    try:
        yield
    finally:
        ctx.prec = old


def arb_of(x: Fraction | int | float) -> arb:
    """The ball of an exact rational (exact when it is dyadic)."""
    q = Fraction(x)
    return arb(fmpq(q.numerator, q.denominator))


def arb_fraction(x: arb) -> Fraction:
    """The exact rational value of an exact (radius 0) ball's midpoint."""
    man, exp = x.mid().man_exp()
    man, exp = int(man), int(exp)
    return Fraction(man) * (Fraction(2) ** exp)
