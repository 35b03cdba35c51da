"""The exact proof of an all-k certificate (:mod:`sosalgo.certificates.allk`).

The certificate is a rational value for every unknown of the conditions (the weights of
P(k), p(k), the coefficients of a(k), C, the multipliers). With those values:

1. every identity (the terms in the function values, M_D(k) v) is the zero polynomial;
2. every multiplier coefficient and a(k)'s lower coefficients are >= 0, and a(k) >=
   (k + offset)^degree coefficient by coefficient;
3. the denominator the conditions were multiplied by has no root on [0, oo);
4. each block -M(k) is positive semidefinite for every real k >= 0: every principal minor
   of -M(k) (a polynomial in k with rational coefficients) is >= 0 on [0, oo), decided
   exactly: the product r of its square-free factors of odd multiplicity must have no root
   in (0, oo) (Sturm's count, sympy) and a positive leading coefficient. A symmetric
   matrix is PSD exactly when all its principal minors are >= 0, so this decides (D) and
   (B) for every k at once; the initial block is a constant matrix, decided the same way.

No floating point is in the proof. :func:`round_certificate` turns the search's floats
into such a certificate: multipliers found at 0 are set to 0, the others rounded to
fractions, and the point moved onto the identities by an exact minimal-norm correction
(python-flint).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.certificates.allk import Conditions, offset_bounds

__all__ = ["SLACKS", "AllKProof", "AllKResult", "check_certificate", "prove_all_k",
           "verify_allk_document",
           "nonnegative_on_halfline",
           "principal_minors", "round_certificate"]

ZERO_TOL = 1e-7  # a nonnegative unknown below this (relative) is taken as 0
MAX_DEN = 2**40


@dataclass
class AllKProof:
    """The outcome: ``verified`` ("exact" or "failed"), the proven constant C (in the
    spec's units: the certificate's C times L) and a(k)'s
    coefficients (Fractions), the offset c (a(N) >= (N + c)^degree), ``reason`` when not
    proven, and per block the number of principal minors decided."""

    verified: str
    constant: Fraction | None = None
    a: list[Fraction] = field(default_factory=list)
    offset: Fraction | None = None
    reason: str | None = None
    minors: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"verified": self.verified,
                "constant_proven": None if self.constant is None else str(self.constant),
                "a": [str(c) for c in self.a],
                "offset": None if self.offset is None else str(self.offset),
                "reason": self.reason, "minors": dict(self.minors)}


# --------------------------------------------------------------------------- polynomials
def _poly(expr: Any, k: Any) -> Any:
    """A sympy polynomial in k over QQ (expr has no other symbol)."""
    import sympy as sp

    return sp.Poly(expr, k, domain="QQ")


def nonnegative_on_halfline(poly: Any) -> bool:
    """Whether the polynomial (sympy Poly over QQ in one variable) is >= 0 on [0, oo),
    decided exactly (square-free factors of odd multiplicity, Sturm's count)."""
    if poly.is_zero:
        return True
    lead, factors = poly.sqf_list()
    r = poly.one * lead
    for f, mult in factors:
        if mult % 2:
            r = r * f
    if r.degree() <= 0:
        return bool(r.LC() > 0)
    roots = r.count_roots(0, None)
    at_zero = 1 if r.eval(0) == 0 else 0
    return roots - at_zero == 0 and bool(r.LC() > 0)


def _det(M: list[list[Any]]) -> Any:
    """Determinant of a small square matrix of polynomials (Laplace along the first row)."""
    n = len(M)
    if n == 1:
        return M[0][0]
    total = None
    for j in range(n):
        if M[0][j].is_zero:
            continue
        minor = [row[:j] + row[j + 1:] for row in M[1:]]
        term = M[0][j] * _det(minor)
        term = term if j % 2 == 0 else -term
        total = term if total is None else total + term
    return M[0][0] * 0 if total is None else total


def principal_minors(M: list[list[Any]]) -> list[tuple[tuple[int, ...], Any]]:
    """Every principal minor (index set, determinant) of a square matrix of polynomials."""
    n = len(M)
    out = []
    for size in range(1, n + 1):
        for idx in itertools.combinations(range(n), size):
            out.append((idx, _det([[M[i][j] for j in idx] for i in idx])))
    return out


def _psd_for_all_k(M: Any, k: Any) -> tuple[bool, int, str]:
    """Whether -M(k) is PSD for every k >= 0 (M a sympy matrix of polynomials in k)."""
    s = M.shape[0]
    neg = [[_poly(-M[i, j], k) for j in range(s)] for i in range(s)]
    minors = principal_minors(neg)
    for idx, d in minors:
        if not nonnegative_on_halfline(d):
            return False, len(minors), f"principal minor {list(idx)} is negative at some k >= 0"
    return True, len(minors), ""


# --------------------------------------------------------------------------- the proof
def _substitute(cond: Conditions, cert: dict[str, Fraction]) -> dict[Any, Any]:
    import sympy as sp

    missing = [str(v) for v in cond.variables if str(v) not in cert]
    if missing:
        raise ValueError(f"certificate: {missing[0]} is missing")
    return {v: sp.Rational(cert[str(v)].numerator, cert[str(v)].denominator)
            for v in cond.variables}


def check_certificate(cond: Conditions, cert: dict[str, Fraction], offset: Fraction,
                      k: Any) -> AllKProof:
    """The exact proof of the module's docstring for the rational values ``cert``."""
    try:
        sub = _substitute(cond, cert)
    except ValueError as exc:
        return AllKProof("failed", reason=str(exc))
    fail = _signs_and_identities(cond, cert, sub, offset, k)
    if fail:
        return AllKProof("failed", reason=fail)
    den = _poly(cond.denominator, k)
    if den.eval(0) <= 0 or den.count_roots(0, None) != 0:
        return AllKProof("failed", reason=f"the denominator {den.as_expr()} vanishes on k >= 0")
    minors = {}
    for name, M in cond.blocks.items():
        ok, count, why = _psd_for_all_k(M.xreplace(sub), k)
        minors[name] = count
        if not ok:
            return AllKProof("failed", reason=f"{name}: {why}", minors=minors)
    a = [cert[f"a_{j}"] for j in range(cond.degree)] + [Fraction(1)]
    return AllKProof("exact", cert["C"] * Fraction(str(cond.extra["scale"])), a, offset,
                     None, minors)


def _signs_and_identities(cond: Conditions, cert: dict[str, Fraction], sub: dict[Any, Any],
                          offset: Fraction, k: Any) -> str | None:
    """Why the signs or identities fail (None when they hold)."""
    for v in cond.nonnegative:
        if cert[str(v)] < 0:
            return f"{v} = {cert[str(v)]} is negative"
    if offset < 0:
        return f"offset {offset} is negative"
    for name, low in offset_bounds(cond.degree, offset).items():
        if cert[name] < low:
            return f"{name} = {cert[name]} is below {low} (a(N) >= (N + {offset})^d fails)"
    for e in cond.identities:
        if not _poly(e.xreplace(sub), k).is_zero:
            return "an identity (the terms in the function values, or M_D v) is not 0"
    return None


# --------------------------------------------------------------------------- rounding
def _fraction(x: float, snap: float = 1e-6, small_den: int = 64) -> Fraction:
    """x as a fraction: a small-denominator one (<= ``small_den``) when within ``snap``
    of it (the structural values of an optimum: 1/2, -1, ...), else a close one."""
    small = Fraction(float(x)).limit_denominator(small_den)
    if abs(float(small) - float(x)) <= snap:
        return small
    return Fraction(float(x)).limit_denominator(MAX_DEN)


def round_certificate(cond: Conditions, values: np.ndarray, k: Any,
                      kernels: tuple[str, ...] = ("decrease",), zeros: list[Any] | None = None,
                      pivots: bool = True, snap: tuple[float, int] = (1e-6, 64)
                      ) -> dict[str, Fraction]:
    """Rational values near the search's ``values`` that satisfy the identities exactly
    (the nonnegative unknowns found at 0 set to 0): with ``pivots``, the free unknowns of
    the identities' echelon form keep their rounded values and the others are solved
    (small fractions); else (or when that fails) a minimal-norm exact correction."""
    import flint

    index = {v: i for i, v in enumerate(cond.variables)}
    scale = max(1.0, float(np.max(np.abs(values))))
    y = [_fraction(x, *snap) for x in values]
    rows: list[list[Fraction]] = []
    rhs: list[Fraction] = []
    for v in cond.nonnegative:
        if values[index[v]] <= ZERO_TOL * scale:
            rows.append([Fraction(int(i == index[v])) for i in range(len(y))])
            rhs.append(Fraction(0))
    for e in [*cond.all_identities(kernels), *(zeros or [])]:
        for vec, const in _exact_rows(e, k, index):
            rows.append(vec)
            rhs.append(-const)
    if not rows:
        return {str(v): y[i] for v, i in index.items()}
    A = flint.fmpq_mat(len(rows), len(y), [flint.fmpq(c.numerator, c.denominator)
                                          for r in rows for c in r])
    if pivots:
        solved = _solve_on_pivots(A, rhs, y)
        if solved is not None:
            return {str(v): solved[i] for v, i in index.items()}
    keep = _independent_rows(A)
    A = flint.fmpq_mat([[A[i, j] for j in range(len(y))] for i in keep])
    b = flint.fmpq_mat([[flint.fmpq(rhs[i].numerator, rhs[i].denominator)] for i in keep])
    yv = flint.fmpq_mat([[flint.fmpq(c.numerator, c.denominator)] for c in y])
    z = (A * A.transpose()).solve(A * yv - b)
    y_new = yv - A.transpose() * z
    out = {}
    for v, i in index.items():
        q = y_new[i, 0]
        out[str(v)] = Fraction(int(q.p), int(q.q))
    return out


def _solve_on_pivots(A: Any, rhs: list[Fraction], y: list[Fraction]) -> list[Fraction] | None:
    """y with its pivot unknowns (reduced echelon form of A y = rhs) solved exactly from
    the others; None when the system has no solution."""
    import flint

    n = len(y)
    aug = flint.fmpq_mat(A.nrows(), n + 1, [
        (A[i, j] if j < n else flint.fmpq(rhs[i].numerator, rhs[i].denominator))
        for i in range(A.nrows()) for j in range(n + 1)])
    R, rank = aug.rref()
    out = list(y)
    pivots = []
    for i in range(rank):
        col = next(j for j in range(n + 1) if R[i, j] != 0)
        if col == n:
            return None
        pivots.append((i, col))
    cols = {c for _, c in pivots}
    for i, col in pivots:
        value = R[i, n] - sum((R[i, j] * flint.fmpq(out[j].numerator, out[j].denominator)
                               for j in range(n) if j not in cols and R[i, j] != 0),
                              flint.fmpq(0))
        out[col] = Fraction(int(value.p), int(value.q))
    return out


def _exact_rows(expr: Any, k: Any, index: dict[Any, int]) -> list[tuple[list[Fraction], Fraction]]:
    """Per power of k: (exact coefficients over the unknowns, exact constant)."""
    import sympy as sp

    per: dict[int, tuple[list[Fraction], Fraction]] = {}
    if expr == 0:
        return []
    for monom, coeff in sp.Poly(expr, k, *index).terms():
        vec, const = per.get(monom[0], ([Fraction(0)] * len(index), Fraction(0)))
        c = Fraction(int(coeff.p), int(coeff.q))
        hit = [i for i, e in enumerate(monom[1:]) if e]
        if hit:
            vec[hit[0]] += c
        else:
            const += c
        per[monom[0]] = (vec, const)
    return list(per.values())


def _independent_rows(A: Any) -> list[int]:
    """Indices of a maximal set of linearly independent rows of A (flint fmpq_mat)."""
    R, rank = A.transpose().rref()
    keep = []
    for i in range(rank):
        for j in range(R.ncols()):
            if R[i, j] != 0:
                keep.append(j)
                break
    return keep


# --------------------------------------------------------------------------- the driver
SLACKS = (5e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1)  # C <= C* (1 + slack) tried in turn


@dataclass
class AllKResult:
    """A search and its proof: the proof (``proof.verified == "exact"`` when proven), the
    rational certificate (unknown name -> Fraction), the SDP's constant C* (unchecked),
    the slack of the proven point, the degree and the solves."""

    proof: AllKProof
    certificate: dict[str, Fraction] | None
    estimate: float | None
    slack: float | None
    degree: int
    solves: int


def prove_all_k(system: Any, degree: int = 2, offset: Fraction | None = None) -> AllKResult:
    """Search a potential of ``degree`` with a(N) >= (N + offset)^degree and prove it
    exactly: the SDP's optimum, then points with a margin at C <= C* (1 + slack) for
    each slack of :data:`SLACKS`, rounded and checked until one is proven. ``offset``:
    the system's own (1; 0 for a sequence, a(t) >= t^degree) unless given."""
    from sosalgo.certificates.allk import conditions, margin_point, search

    offset = system.offset() if offset is None else offset
    cond = conditions(system, degree)
    found = search(cond, offset)
    if found.values is None:
        return AllKResult(AllKProof("failed", reason=f"the search found no potential of "
                                    f"degree {degree} ({found.status})"),
                          None, None, None, degree, found.solves)
    last = AllKProof("failed", reason="no point with a margin")
    estimate = found.constant * float(system.scale)
    # a sequence's potentials are often tight (OGM's): the snapped C is tried first
    tight = _tight(cond, found, system, offset) if system.recurrence is not None else None
    if tight is not None:
        return AllKResult(tight[0], tight[1], estimate, 0.0, degree, found.solves)
    for slack in SLACKS:
        y = margin_point(cond, found, slack)
        if y is None:
            continue
        for pivots in (True, False):
            cert = round_certificate(cond, y, system.k, found.kernels, found.zeros, pivots)
            last = check_certificate(cond, cert, offset, system.k)
            if last.verified == "exact":
                return AllKResult(last, cert, estimate, slack, degree, found.solves)
    tight = _tight(cond, found, system, offset) if system.recurrence is None else None
    if tight is not None:
        return AllKResult(tight[0], tight[1], estimate, 0.0, degree, found.solves)
    return AllKResult(last, None, estimate, None, degree, found.solves)


TIGHT_SNAPS = ((1e-2, 8), (1e-2, 16), (1e-6, 64))  # (distance, denominator) of the snap


def _tight(cond: Conditions, found: Any, system: Any, offset: Fraction
           ) -> tuple[AllKProof, dict[str, Fraction]] | None:
    """A potential with no margin (every condition tight somewhere, as OGM's): at C*
    snapped to a small fraction, the sparse point rounded to small fractions."""
    from sosalgo.certificates.allk import pinned_point

    point = pinned_point(cond, found)
    if point is None:
        return None
    _, y = point
    for snap in TIGHT_SNAPS:
        for pivots in (True, False):
            cert = round_certificate(cond, y, system.k, found.kernels, None, pivots, snap)
            proof = check_certificate(cond, cert, offset, system.k)
            if proof.verified == "exact":
                return proof, cert
    return None


# --------------------------------------------------------------------------- verify
def _fractions(cert: Any, where: str) -> dict[str, Fraction]:
    if not isinstance(cert, dict) or not cert:
        raise ValueError(f"{where}.certificate: expected an object of fractions")
    out = {}
    for name, text in cert.items():
        try:
            out[str(name)] = Fraction(str(text))
        except (ValueError, ZeroDivisionError):
            raise ValueError(f"{where}.certificate.{name}: {str(text)[:40]!r} is not a "
                             "fraction") from None
    return out


def _claims_differ(doc: dict[str, Any], proof: AllKProof) -> str | None:
    """Why the document's claims are not what the proof proves (None when they are)."""
    assert proof.constant is not None
    if str(doc.get("constant_proven")) != str(proof.constant):
        return f"constant_proven {doc.get('constant_proven')} is not the certificate's C"
    const = doc.get("constant")
    if not isinstance(const, int | float) or Fraction(const) < proof.constant:
        return f"constant {const} is below the proven {float(proof.constant):.10g}"
    if [str(c) for c in proof.a] != [str(c) for c in doc.get("a", [])]:
        return "a: not the certificate's a(N)"
    if doc.get("verified") != "exact" or doc.get("certified") is not True:
        return "the document does not claim the bound it carries"
    return None


def verify_allk_document(doc: dict[str, Any], spec: Any, where: str) -> list[dict[str, Any]]:
    """Re-prove an ``all-k`` document's bound from its certificate, about ``spec``: one
    check (``verified`` "exact" when its every claim is proven, else "failed" and
    ``reason``). A document claiming nothing (no proven bound) fails; a malformed
    certificate raises InputError naming the field."""
    from sosalgo.certificates.allk import closed_form_system, conditions

    head = {"spec": doc.get("spec"), "kappa": None, "steps": None}
    if not doc.get("certified"):
        return [head | {"verified": "failed", "reason": f"{where}: no bound is claimed"}]
    try:
        cert = _fractions(doc.get("certificate"), where)
        degree, offset = int(doc.get("degree", 0)), Fraction(str(doc.get("offset")))
        if degree not in (1, 2):
            raise ValueError(f"{where}.degree: {degree!r} is not 1 or 2")
    except (ValueError, TypeError) as exc:  # malformed: exit code 2, naming the field
        from sosalgo.errors import InputError

        raise InputError(str(exc)) from None
    system = closed_form_system(spec)
    proof = check_certificate(conditions(system, degree), cert, offset, system.k)
    why = proof.reason if proof.verified != "exact" else _claims_differ(doc, proof)
    if why is not None:
        return [head | {"verified": "failed", "reason": f"{where}: {why}"}]
    return [head | proof.to_dict() | {"verified": "exact"}]
