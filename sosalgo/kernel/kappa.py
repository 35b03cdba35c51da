"""A condition number as written: :class:`Kappa` is the float every numerical step uses,
carrying the text the user wrote (``10/3``, ``3.3``, ``5*sqrt(2)``) so that the exact
proofs are about the class as written (:func:`exact_kappa`).

The convention, the same for the spec's ``kappa`` list, ``--kappa`` and the Python API:

- a value written as text (a spec entry, a ``--kappa`` option, a string given to the API)
  is the number the text denotes: ``10/3`` is 10/3, the decimal ``3.3`` is 33/10,
  ``5*sqrt(2)`` is the irrational 5 sqrt(2) (enclosed in outward-rounded balls where it
  enters a proof);
- a number that arrives as a float is the shortest decimal that reads back as that float
  (``3.3`` is 33/10, ``10/3`` computed in Python is 3.3333333333333335): a YAML number
  (``kappa: [3.3]``, which YAML reads as a float before sosalgo sees it), each point of a
  ``{from, to, points}`` range, a Python float given to the API;
- an int or a ``Fraction`` given to the API is itself (``Fraction(10, 3)`` is 10/3;
  ``Fraction(x)`` of a float x is x's binary value).
"""

from __future__ import annotations

import math
import re
from fractions import Fraction
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # sympy is loaded by the exact proofs only, not by numeric work
    import sympy as sp

__all__ = ["Kappa", "exact_kappa", "kappa_fields", "kappa_from_fields", "kappa_written",
           "plain_kappa"]

_PLAIN_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


class Kappa(float):
    """A condition number: the float (its numerical value) and ``written``, the text of
    its exact value (see :func:`exact_kappa`)."""

    __slots__ = ("written",)
    written: str

    def __new__(cls, value: float, written: str) -> Kappa:
        obj = super().__new__(cls, value)
        obj.written = written
        return obj

    def __reduce__(self) -> tuple[Any, ...]:
        return (Kappa, (float(self), self.written))


def kappa_written(value: float, text: object = None) -> Kappa:
    """``value`` with its exact text: ``text`` when given as a string, else the shortest
    decimal that reads back as the float (a YAML number, a range point)."""
    written = text.strip() if isinstance(text, str) else repr(float(value))
    return Kappa(float(value), written)


def exact_kappa(kappa: Any) -> sp.Expr:
    """kappa's exact value as a sympy number: a :class:`Kappa` (or a string) as written, a
    float the shortest decimal that reads back as it, an int or Fraction itself."""
    import sympy as sp

    q = plain_kappa(kappa)
    if q is not None:
        return sp.Rational(q.numerator, q.denominator)
    return _expression_value(kappa.written if isinstance(kappa, Kappa) else kappa)


def plain_kappa(kappa: Any) -> Fraction | None:
    """kappa's exact value when it is a plain number (a float, int, Fraction, or a decimal
    written as text), without sympy; None for an expression (``10/3``, ``sqrt(2)*5``)."""
    text = kappa.written if isinstance(kappa, Kappa) else kappa
    if isinstance(text, str):
        return Fraction(text.strip()) if _PLAIN_NUMBER.fullmatch(text.strip()) else None
    if isinstance(kappa, bool):
        raise ValueError(f"condition number must be a number, got {kappa!r}")
    if isinstance(kappa, int | Fraction):
        return Fraction(kappa)
    xf = float(kappa)
    if not math.isfinite(xf):
        raise ValueError(f"condition number must be finite, got {kappa}")
    return Fraction(repr(xf))


def _expression_value(text: str) -> sp.Expr:
    import sympy as sp

    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.kernel.expr.tree import parse_tree

    val = sp.sympify(to_sympy(parse_tree(text.strip(), ())))
    if val.free_symbols or not val.is_real:
        raise ValueError(f"condition number {text.strip()!r} is not a real constant")
    return val


def kappa_fields(kappa: Any, digits: int = 30) -> dict[str, Any]:
    """What a result document records about kappa besides its float: ``kappa_exact``, the
    exact value proven about (``10/3``, ``33/10``, ``5*sqrt(2)``), and for an irrational
    kappa ``kappa_enclosure``, an outward-rounded rational ball [lo, hi] holding it."""
    if kappa is None:
        return {}
    q = plain_kappa(kappa)
    if q is not None:  # no sympy for numeric runs of plain numbers
        return {"kappa_exact": str(q)}
    from sosalgo.kernel.exact import enclose, fraction_str

    val = exact_kappa(kappa)
    out: dict[str, Any] = {"kappa_exact": str(val)}
    if not val.is_Rational:
        try:
            b = enclose(val, digits)
        except ValueError:  # no ball arithmetic for it: its proofs fail and say why
            return out
        out["kappa_enclosure"] = [fraction_str(b.lo), fraction_str(b.hi)]
    return out


def kappa_from_fields(kappa: float, exact: object, where: str) -> Kappa | float:
    """A result row's kappa: its float ``kappa`` with the ``kappa_exact`` it records (an
    old row without one: the float). ValueError (naming ``where``) when ``kappa_exact`` is
    not a constant or is not the number ``kappa`` is the float of."""
    import sympy as sp

    from sosalgo.kernel.expr.tree import ExprError

    if exact is None:
        return kappa
    if not isinstance(exact, str) or not exact.strip() or len(exact) > 200:
        raise ValueError(f"{where}.kappa_exact: expected the exact kappa as text")
    try:
        val = exact_kappa(exact)
        close = abs(float(val) - float(kappa)) <= 4 * math.ulp(float(kappa))
    except (ExprError, ValueError, TypeError, ArithmeticError, sp.SympifyError) as exc:
        raise ValueError(f"{where}.kappa_exact: {exc}") from None
    if not close:
        raise ValueError(f"{where}.kappa_exact: {exact} is not the row's kappa {kappa!r}")
    return Kappa(float(kappa), exact.strip())
