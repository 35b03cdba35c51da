"""Exact (rational) verification of an interpolation-family certificate.

The certificate (rho, P, p, c, multipliers eta, lambda) is checked in original units
(F(m, L), no normalization) without floating point in the proof path:

1. The method is made exact as for Theorem 1 (:func:`sosalgo.exact_method.exact_algorithm`):
   rational kappa, m, L and rational balls enclosing irrational entries of A, B, C, E.
2. P, p, c, eta, lambda are rounded to rationals; negative multipliers are set to 0, and
   p_j (or c) is raised where needed so that the function-value rows of the positivity
   condition hold exactly (raising a weight only increases V). The rows of both
   conditions involve only m, L and 0/1 selections, so they are exact rationals.
3. The decrease matrix (D) and the positivity matrix are computed in midpoint-radius
   arithmetic; with eta >= ||R||_F for the radius matrix R, exact LDL^T proofs of
   -D(centre) - t I ⪰ 0 and Pq(centre) - t I ⪰ 0 for rationals t >= eta prove
   D ⪯ 0 and Pq ⪰ 0 for every method inside the enclosures.

The window algebra (row maps, interpolation pairs) is the family's own builder run on
exact numbers (the family's ``exact_structure``/``exact_parts``); the simulation check
(:mod:`sosalgo.proofs.simulate`) evaluates the Lyapunov function independently along
trajectories of actual functions.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.certificates.exact_theorem1 import SCALED_UNITS, ProofResult
from sosalgo.exact_method import (
    exact_algorithm,
    exact_fixed_point,
    scaled_method,
    units_far_from_one,
)
from sosalgo.kernel.exact import (
    DEFAULT_DIGITS,
    DEFAULT_MAX_DEN,
    DEFAULT_RHO_STEPS,
    Ball,
    Verdict,
    fraction_str,
    is_zero,
    object_matrix,
    prove_definite,
    rational,
    rho_candidates,
    symmetrize_balls,
)
from sosalgo.model import bind, fixed_point
from sosalgo.spec.types import MATRIX_NAMES, Spec

__all__ = ["InterpolationExactResult", "float_entry", "scaled_certificate", "symmetric_matrix",
           "verify_exact_interpolation"]


@dataclass
class InterpolationExactResult(ProofResult):
    """Outcome of :func:`verify_exact_interpolation` (``to_dict`` has what a re-check needs)."""

    delta: str | None = None  # D ⪯ -delta I and Pq ⪰ delta I (delta may be 0 for exact data)
    certificate: dict[str, Any] = field(default_factory=dict)  # rational parts
    enclosures: dict[str, Any] = field(default_factory=dict)
    proofs: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "certificate_family": "interpolation (Lyapunov function with function values, "
                                  "F(m, L) interpolation inequalities)",
            "spec": self.spec, "verified": str(self.verified), "rho_requested": self.rho_requested,
            "rho_proven": self.rho_proven, "rho_proven_float": self.rho_proven_float,
            "delta": self.delta, "certificate": self.certificate, "proofs": self.proofs,
            "reason": self.reason, "attempts": self.attempts, "seconds": self.seconds,
            "kappa": self.kappa, "m": self.m, "L": self.L, "params": dict(self.params),
            "enclosures": self.enclosures,
        } | ({"units": self.units} if self.units else {})


def rational_near(x: Any, max_den: int) -> Fraction:
    f = rational(x)
    return f.limit_denominator(max_den) if not isinstance(x, Fraction | str) else f


class Refused(Exception):
    """Why the certificate cannot be proven (it becomes the result's ``reason``)."""


def symmetric_matrix(raw: Any, n: int, entry: Callable[[Any, Any], Any]) -> np.ndarray:
    """P (n x n, object) from a certificate's nested list: P[i, j] = P[j, i] =
    entry(raw[i][j], raw[j][i]); :class:`Refused` on a wrong shape."""
    P_raw = np.asarray(raw, dtype=object)
    if P_raw.shape != (n, n):
        raise Refused(f"P has shape {P_raw.shape}, expected {(n, n)}")
    P = np.empty((n, n), dtype=object)
    for i in range(n):
        for j in range(i, n):
            P[i, j] = P[j, i] = entry(P_raw[i, j], P_raw[j, i])
    return P


def float_entry(max_den: int) -> Callable[[Any, Any], Fraction]:
    """A symmetric entry from floats (their average, then a nearby rational with
    denominator <= ``max_den``) or kept as given when already exact (Fraction, "p/q")."""
    def entry(a: Any, b: Any) -> Fraction:
        v = a if isinstance(a, Fraction | str) else 0.5 * (float(a) + float(b))
        return rational_near(v, max_den)
    return entry


@dataclass
class _Cert:
    """The certificate's parts read as rationals (before the multipliers)."""

    lag: int
    has_x: bool  # a c term (x_k != y_k)
    P: np.ndarray  # object array of Fractions
    pi: list[Fraction]  # the weights p_0..p_lag, then c when has_x
    m_dec: Mapping[str, Any]
    m_pos: Mapping[str, Any]


def verify_exact_interpolation(
    spec: Spec, kappa: float, rho: float, cert: Mapping[str, Any],
    theta: Mapping[str, float] | None = None, *, family: Any, max_den: int = DEFAULT_MAX_DEN,
    rho_steps: tuple[float, ...] = DEFAULT_RHO_STEPS, digits: int = DEFAULT_DIGITS,
) -> InterpolationExactResult:
    """Prove in exact arithmetic that ``cert`` certifies ``rho`` (or a rational rho slightly
    above it, from ``rho_steps``) for the exact method of ``spec`` at ``kappa``.

    ``family`` (the interpolation family, which calls this as its ``exact_check``) builds
    the windows and evaluates the inequality parts on exact numbers."""
    start = time.perf_counter()
    res = InterpolationExactResult(spec=spec.name, verified=Verdict.FAILED,
                                   rho_requested=float(rho))
    try:
        ex, n = _exact_method(spec, kappa, theta, digits, res)
        if not np.isfinite(float(rho)) or not 0 < rational(rho) <= 1:
            raise Refused(f"rho = {rho!r} is not in (0, 1]")
        res.reason = _prove_in_units(res, family, ex, n, cert, Fraction(1), rational(rho),
                                     rho_steps, max_den)
        if res.reason is not None and units_far_from_one(ex):
            _prove_scaled(res, family, ex, n, cert, rational(rho), rho_steps, max_den)
    except Refused as exc:
        res.reason = str(exc)
    res.seconds = time.perf_counter() - start
    return res


def _prove_in_units(res: InterpolationExactResult, family: Any, ex: Any, n: int,
                    cert: Mapping[str, Any], s: Fraction, rho: Fraction,
                    rho_steps: tuple[float, ...], max_den: int) -> str | None:
    """The proof for the class with f divided by ``s`` (1: as written): the method with
    B s on F(m/s, L/s), the certificate ``cert`` in those units; None when proven."""
    c = _read_certificate(cert, ex, n, max_den)
    if s != 1:
        ex = scaled_method(ex, s)
    st = family.exact_structure(*(object_matrix(ex.balls[k]) for k in MATRIX_NAMES), ex.m, ex.L,
                                c.lag, c.has_x)
    eta, lam = _multipliers(c, st, max_den)
    _raise_weights(st, c, lam)
    res.certificate = _rational_certificate(c, st, eta, lam)
    return _prove(res, family, st, c, eta, lam, rho, rho_steps, max_den)


def _prove_scaled(res: InterpolationExactResult, family: Any, ex: Any, n: int,
                  cert: Mapping[str, Any], rho: Fraction, rho_steps: tuple[float, ...],
                  max_den: int) -> None:
    """The proof in units where L = 1, after it failed as written in units far from 1
    (:func:`~sosalgo.exact_method.units_far_from_one`): f in F(m, L) exactly
    when f/L is in F(m/L, 1), and the method run on f/L with the step matrix B L has the
    same iterates, so a rate proven there is the rate on F(m, L) (the rate is
    scale-invariant). A certificate found in the normalized units (every float solve is)
    and written back in tiny or huge units (m = 1e-300) rounds to rationals there. The
    result says which units its rational certificate is in; a failure keeps the reason of
    the proof as written."""
    first, kept = res.reason, res.certificate
    try:
        scaled = scaled_certificate(cert, n, ex.L)
        reason = _prove_in_units(res, family, ex, n, scaled, ex.L, rho, rho_steps, max_den)
    except (Refused, ArithmeticError, TypeError, ValueError):
        reason = "not proven"
    if reason is None:
        res.reason, res.units = None, SCALED_UNITS
        res.proofs["units"] = res.units
    else:
        res.reason, res.certificate = first, kept


def scaled_certificate(cert: Mapping[str, Any], n: int, s: Fraction) -> dict[str, Any]:
    """``cert`` for f/s: V/s = z'(D P D / s)z on z = (xi, u/s) with D = diag(I_n, s I), the
    weights p and c as they are, the multipliers times s (each interpolation inequality
    scales by 1/s^2). Floats stay floats (a candidate to round), exact strings exact."""
    def times(v: Any, k: int) -> Any:  # v * s^k
        if isinstance(v, str | Fraction):
            return fraction_str(rational(v) * s**k)
        return float(v) / float(s) ** -k if k < 0 else float(v) * float(s) ** k

    lag = int(cert["lag"])
    side = n + lag + 1
    power = [0] * n + [1] * (lag + 1)
    P = [[times(cert["P"][i][j], power[i] + power[j] - 1) for j in range(side)]
         for i in range(side)]
    mult = {w: {k: times(v, 1) for k, v in cert["multipliers"][w].items()}
            for w in ("decrease", "positivity")}
    return {**cert, "P": P, "multipliers": mult}


def _exact_method(spec: Spec, kappa: float, theta: Mapping[str, float] | None, digits: int,
                  res: InterpolationExactResult) -> tuple[Any, int]:
    """The exact method (its numbers recorded in ``res``), checked against the float one
    and with a proven fixed point; returns it and its number of states."""
    try:
        ex = exact_algorithm(spec, kappa, theta, digits)
    except ValueError as exc:
        raise Refused(f"the exact method cannot be built: {exc}") from None
    res.kappa, res.m, res.L = fraction_str(ex.kappa), fraction_str(ex.m), fraction_str(ex.L)
    res.params = {k: str(v) for k, v in ex.params.items()}
    res.enclosures = ex.enclosures()
    try:
        alg = bind(spec, float(kappa), theta)
    except ValueError as exc:
        raise Refused(f"the method cannot be evaluated: {exc}") from None
    for k in MATRIX_NAMES:
        cen = np.array([[float(b.c) for b in row] for row in ex.balls[k]])
        if not np.allclose(cen, getattr(alg, k), rtol=1e-9, atol=1e-9):
            raise Refused(f"exact matrix {k} differs from sosalgo.model.bind")
    if exact_fixed_point(ex, fixed_point(alg)) is None:
        raise Refused("fixed point (u with (I - A)u = 0, Cu = 1, Eu = 1) not proven")
    return ex, alg.n


def _read_certificate(cert: Mapping[str, Any], ex: Any, n: int, max_den: int) -> _Cert:
    """lag, P (symmetrized, rational), the weights p (and c) and the multiplier tables."""
    try:
        lag = int(cert["lag"])
        has_x = cert.get("c") is not None
        if not has_x and not all(is_zero(v) for v in (ex.matrices["E"] - ex.matrices["C"])):
            raise Refused("certificate has no c term but x_k != y_k (E != C)")
        nz = n + lag + 1
        P = symmetric_matrix(cert["P"], nz, float_entry(max_den))
        pi = [rational_near(v, max_den) for v in list(cert["p"]) + ([cert["c"]] if has_x else [])]
        if len(pi) != lag + 1 + has_x:
            raise Refused(f"p has {len(cert['p'])} weights, expected {lag + 1}")
        mult = cert["multipliers"]
        return _Cert(lag, has_x, P, pi, mult["decrease"], mult["positivity"])
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise Refused(f"malformed certificate: {type(exc).__name__}: {exc}") from None


def _multipliers(c: _Cert, st: Any, max_den: int) -> tuple[list[Fraction], list[Fraction]]:
    """The decrease (eta) and positivity (lambda) multipliers, rational, negatives as 0."""
    try:
        eta = [max(Fraction(0), rational_near(c.m_dec[k], max_den)) for k in st.dec.labels]
        lam = [max(Fraction(0), rational_near(c.m_pos[k], max_den)) for k in st.pos.labels]
    except KeyError as exc:
        raise Refused(f"multiplier of pair {exc} missing") from None
    return eta, lam


def _raise_weights(st: Any, c: _Cert, lam: list[Fraction]) -> None:
    """Raise p_j (or c) so that the positivity function-value rows hold exactly (a larger
    weight only increases V)."""
    Fp = st.pos.F[c.lag]
    for q in range(st.pos.nphi):
        j = next(r for r in range(Fp.shape[0]) if Fp[r, q] == 1)
        need = Fraction(st.norm[q]) + sum(
            (lv * Fraction(mv[q]) for lv, mv in zip(lam, st.pos.mq, strict=True)), Fraction(0))
        c.pi[j] = max(c.pi[j], need)


def _rational_certificate(c: _Cert, st: Any, eta: list[Fraction],
                          lam: list[Fraction]) -> dict[str, Any]:
    """The certificate as it is proven (exact strings)."""
    nz = c.P.shape[0]
    return {
        "lag": c.lag, "P": [[fraction_str(c.P[i, j]) for j in range(nz)] for i in range(nz)],
        "p": [fraction_str(v) for v in c.pi[: c.lag + 1]],
        "c": fraction_str(c.pi[-1]) if c.has_x else None,
        "multipliers": {
            "decrease": dict(zip(st.dec.labels, map(fraction_str, eta), strict=True)),
            "positivity": dict(zip(st.pos.labels, map(fraction_str, lam), strict=True))},
    }


def _prove(res: InterpolationExactResult, family: Any, st: Any, c: _Cert,
           eta: list[Fraction], lam: list[Fraction], rho: Fraction,
           rho_steps: tuple[float, ...], max_den: int) -> str | None:
    """Try rho and the rationals slightly above it: the first proven one goes into ``res``
    (verified exact, reason None); else the reason the first attempt failed."""
    first_fail = None
    for rq in rho_candidates(rho, list(rho_steps), max_den):
        res.attempts += 1
        parts = family.exact_parts(st, rq * rq, c.P, np.array(c.pi, dtype=object), eta, lam)
        bad_df = [i for i, b in enumerate(Ball.of(v) for v in parts["Df"]) if b.hi > 0]
        bad_pf = [i for i, b in enumerate(Ball.of(v) for v in parts["Pf"]) if b.lo < 0]
        ok_d, delta_d, det_d = prove_definite(symmetrize_balls(parts["D"]), -1)
        ok_p, delta_p, det_p = prove_definite(symmetrize_balls(parts["Pq"]), +1)
        why = settle(res, rq, bad_df, bad_pf, (ok_d, delta_d, det_d), (ok_p, delta_p, det_p))
        if why is None:
            return None
        first_fail = first_fail or why
    return first_fail


def settle(res: Any, rq: Fraction, bad_df: list[int], bad_pf: list[int],
           dec: tuple[bool, Fraction, str], pos: tuple[bool, Fraction, str]) -> str | None:
    """One attempt at ``rq``: when the function-value rows and both matrices (decrease
    ``dec``, positivity ``pos``: proven, margin, detail) are proven, ``res`` becomes
    verified exact at ``rq`` and None is returned; else why the attempt failed."""
    (ok_d, delta_d, det_d), (ok_p, delta_p, det_p) = dec, pos
    if not bad_df and not bad_pf and ok_d and ok_p:
        res.verified = Verdict.EXACT
        res.rho_proven, res.rho_proven_float = fraction_str(rq), float(rq)
        res.delta = fraction_str(min(delta_d, delta_p))
        res.proofs = {"decrease": f"-D ⪰ {fraction_str(delta_d)} I: {det_d}",
                      "positivity": f"Pq ⪰ {fraction_str(delta_p)} I: {det_p}",
                      "function values": "all rows exact (<= 0 / >= 0)"}
        return None
    return "; ".join(
        ([f"decrease function-value rows {bad_df} > 0"] if bad_df else [])
        + ([f"positivity function-value rows {bad_pf} < 0"] if bad_pf else [])
        + ([f"decrease matrix: {det_d}"] if not ok_d else [])
        + ([f"positivity matrix: {det_p}"] if not ok_p else [])
    ) + f" at rho = {fraction_str(rq)}"
