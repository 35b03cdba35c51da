"""Exact (rational) proof of a noise-sensitivity certificate.

The certificate (P, p, s, c and the multipliers, original units) of
:func:`sosalgo.sensitivity.sdp.noise_certificate` is checked without floating point in the
proof path, as the interpolation family's certificates are
(:mod:`sosalgo.certificates.exact_interpolation`):

1. the method is made exact (:func:`sosalgo.proofs.exact.exact_algorithm`: rational kappa,
   m, L, rational balls around irrational entries) and its fixed point proven;
2. every number of the certificate is read as the exact rational value of its float;
   negative multipliers become 0;
3. the windows (:mod:`sosalgo.sensitivity.window`) and the four parts are computed in
   midpoint-radius arithmetic; the function-value rows are checked exactly (<= 0, >= 0)
   and -D ⪰ delta I, Pq ⪰ delta I proven by rational LDL^T with delta above the radius
   of the enclosure (:func:`sosalgo.certificates.exact_interpolation.prove_definite`);
4. the proven bound is gamma <= sqrt(s), a rational rounded upward.

With ``limsup`` the certificate of ``noise_limsup`` (:mod:`sosalgo.sensitivity.limsup`):
rho is read as the exact rational of its float (0 <= rho < 1), the discounted parts are
proven the same way, and the bound is sqrt((s + sum sd) / (1 - rho^2) + sum r), s >= 0.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

from sosalgo.certificates.exact_interpolation import Refused, symmetric_matrix
from sosalgo.exact_method import exact_algorithm, exact_fixed_point
from sosalgo.kernel.exact import DEFAULT_DIGITS, Ball, Verdict, fraction_str, rational
from sosalgo.sensitivity.limsup import limsup_bound
from sosalgo.sensitivity.sdp import noise_windows
from sosalgo.sensitivity.window import noise_parts, past_noise, state_size
from sosalgo.spec.types import Spec

__all__ = ["NoiseProof", "verify_composite_noise", "verify_noise", "sqrt_upper"]


@dataclass
class NoiseProof:
    """Outcome of :func:`verify_noise`; ``gamma_proven`` is a float >= the proven bound."""

    spec: str
    verified: Verdict = Verdict.FAILED
    gamma_proven: float | None = None
    gamma_fraction: str | None = None  # a rational >= sqrt(s)
    reason: str | None = None
    proofs: dict[str, str] = field(default_factory=dict)
    certificate: dict[str, Any] = field(default_factory=dict)  # the rationals proven
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.verified == Verdict.EXACT

    def to_dict(self) -> dict[str, Any]:
        return {"spec": self.spec, "verified": str(self.verified),
                "gamma_proven": self.gamma_proven, "gamma_fraction": self.gamma_fraction,
                "reason": self.reason, "proofs": dict(self.proofs),
                "certificate": self.certificate, "seconds": self.seconds}


def sqrt_upper(s: Fraction, digits: int = 10) -> Fraction:
    """A rational t >= sqrt(s) with about ``digits`` significant digits (s >= 0)."""
    if s <= 0:
        return Fraction(0)
    mag = (len(str(s.numerator)) - len(str(s.denominator))) // 2  # ~ log10 sqrt(s)
    scale = Fraction(10) ** (digits - mag)
    x = s * scale * scale  # t = ceil(sqrt(x)) / scale
    r = math.isqrt(x.numerator // x.denominator)
    return Fraction(r if r * r == x else r + 1) / scale


def _exact_windows(spec: Spec, kappa: float, theta: Mapping[str, float] | None, lag: int,
                   digits: int) -> tuple[Any, Any, int]:
    """(decrease, positivity) windows of the exact method, and its number of states."""
    from sosalgo.certificates.exact_composite import exact_class_inequalities
    from sosalgo.classes import SEED_CLASS
    from sosalgo.model import bind, fixed_point

    try:
        ex = exact_algorithm(spec, kappa, theta, digits)
        alg = bind(spec, float(kappa), theta)
    except ValueError as exc:
        raise Refused(f"the exact method cannot be built: {exc}") from None
    if exact_fixed_point(ex, fixed_point(alg)) is None:
        raise Refused("fixed point (u with (I - A)u = 0, Cu = 1, Eu = 1) not proven")
    ineqs, _ = exact_class_inequalities(SEED_CLASS, {"m": Ball(ex.m), "L": Ball(ex.L)})
    alpha, Q = ineqs[0]
    from sosalgo.kernel.exact import object_matrix

    mats = [object_matrix(ex.balls[k]) for k in ("A", "B", "C", "E")]
    dec, pos = noise_windows(*mats, alpha, Q, lag, obj=True)
    return dec, pos, len(ex.balls["A"])


def _read(cert: Mapping[str, Any], dec: Any, pos: Any, n: int) -> dict[str, Any]:
    """The certificate's numbers as exact rationals (negative multipliers as 0)."""
    try:
        lag = int(cert["lag"])
        N = state_size(n, lag)
        P = symmetric_matrix(cert["P"], N, lambda a, b: (rational(a) + rational(b)) / 2)
        p, c = [rational(v) for v in cert["p"]], [rational(v) for v in cert["c"]]
        if len(p) != lag + 1 or len(c) != len(dec.measurable):
            raise Refused("p or c has the wrong length")
        mult = cert["multipliers"]
        zero = Fraction(0)
        eta = [max(zero, rational(mult["decrease"][k])) for k in dec.labels]
        lam = [max(zero, rational(mult["positivity"][k])) for k in pos.labels]
        return {"P": P, "p": p, "s": rational(cert["s"]), "c": c, "eta": eta, "lam": lam}
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise Refused(f"malformed certificate: {type(exc).__name__}: {exc}") from None


def _read_limsup(cert: Mapping[str, Any], dec: Any, pos: Any, num: dict[str, Any]) -> None:
    """The rational rho (0 <= rho < 1) and past-noise terms of a ``noise_limsup``
    certificate into ``num`` (negative r, sd as 0, like multipliers)."""
    try:
        rho = rational(cert["rho"])
        sizes = {"r": pos.lag, "sd": dec.lag,
                 "cp": sum(len(k) for _, k in past_noise(pos)),
                 "cd": sum(len(k) for _, k in past_noise(dec))}
        for k, size in sizes.items():
            vals = [rational(v) for v in cert.get(k, [0] * size)]
            if len(vals) != size:
                raise Refused(f"{k} has the wrong length")
            num[k] = [max(Fraction(0), v) for v in vals] if k in ("r", "sd") else vals
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise Refused(f"malformed certificate: {type(exc).__name__}: {exc}") from None
    if not 0 <= rho < 1:
        raise Refused(f"rho = {fraction_str(rho)} is not in [0, 1)")
    num["rho2"] = rho * rho


def _prove(res: NoiseProof, dec: Any, pos: Any, num: dict[str, Any]) -> None:
    """The four parts in exact arithmetic; ``res`` becomes verified when all hold (with
    ``rho2`` in ``num``: the discounted parts and bound of ``noise_limsup``)."""
    from sosalgo.kernel.exact import prove_definite, symmetrize_balls

    rho2 = num.get("rho2")
    parts = noise_parts(dec, pos, num["P"], num["p"], num["s"], num["c"], num["eta"],
                        num["lam"], obj=True, rho2=rho2, past=num if rho2 is not None else None)
    bad_df = [i for i, v in enumerate(parts["Df"]) if Ball.of(v).hi > 0]
    bad_pf = [i for i, v in enumerate(parts["Pf"]) if Ball.of(v).lo < 0]
    ok_d, delta_d, det_d = prove_definite(symmetrize_balls(parts["D"]), -1)
    ok_p, delta_p, det_p = prove_definite(symmetrize_balls(parts["Pq"]), +1)
    bad_s = num["s"] <= 0 if rho2 is None else num["s"] < 0  # limsup: s >= 0 is enough
    if bad_df or bad_pf or not (ok_d and ok_p) or bad_s:
        res.reason = "; ".join(
            ([f"decrease function-value rows {bad_df} > 0"] if bad_df else [])
            + ([f"positivity function-value rows {bad_pf} < 0"] if bad_pf else [])
            + ([f"decrease matrix: {det_d}"] if not ok_d else [])
            + ([f"positivity matrix: {det_p}"] if not ok_p else [])
            + ([f"s = {fraction_str(num['s'])} out of range"] if bad_s else []))
        return
    bound = num["s"] if rho2 is None else limsup_bound(num, 1 - rho2)
    t = sqrt_upper(bound)
    res.verified = Verdict.EXACT
    res.gamma_fraction = fraction_str(t)
    res.gamma_proven = math.nextafter(float(t), math.inf)
    res.proofs = {"decrease": f"-D ⪰ {fraction_str(delta_d)} I: {det_d}",
                  "positivity": f"Pq ⪰ {fraction_str(delta_p)} I: {det_p}",
                  "function values": "all rows exact (<= 0 / >= 0)",
                  "bound": f"gamma^2 <= s = {fraction_str(num['s'])}" if rho2 is None else
                  f"gamma^2 <= (s + sum sd) / (1 - rho^2) + sum r = {fraction_str(bound)}, "
                  f"rho^2 = {fraction_str(rho2)}"}


def _composite_numbers(cert: Mapping[str, Any], st: Any, nz: int,
                       ncols: tuple[int, int]) -> dict[str, Any]:
    """The certificate's numbers as exact rationals (negative multipliers as 0)."""
    P = symmetric_matrix(cert["P"], nz, lambda a, b: (rational(a) + rational(b)) / 2)
    p, c = [rational(v) for v in cert["p"]], [rational(v) for v in cert["c"]]
    if (len(p), len(c)) != ncols:
        raise ValueError("p or c has the wrong length")
    mult, zero = cert["multipliers"], Fraction(0)
    return {"P": P, "p": p, "s": rational(cert["s"]), "c": c,
            "eta": [max(zero, rational(mult["decrease"][k])) for k in st.dec.labels],
            "lam": [max(zero, rational(mult["positivity"][k])) for k in st.pos.labels]}


def verify_composite_noise(spec: Spec, kappa: float, cert: Mapping[str, Any],
                           theta: Mapping[str, float] | None = None,
                           digits: int | None = None) -> NoiseProof:
    """Exact proof of a composite noise certificate
    (:func:`sosalgo.sensitivity.composite.composite_noise_certificate`): its parts on the
    exact method, -D ⪰ delta I and Pq ⪰ delta I by rational LDL^T, the value rows exactly;
    gamma <= sqrt(s) rounded up; the fixed points proven exactly as for the rates
    (:func:`sosalgo.certificates.exact_composite.fixed_point_failure`)."""
    from sosalgo.kernel.exact import prove_definite, symmetrize_balls
    from sosalgo.sensitivity.composite import (
        composite_noise_parts,
        exact_noise_structure,
        real_calls,
    )
    from sosalgo.sensitivity.sdp import check_lag

    start = time.perf_counter()
    res = NoiseProof(spec=spec.name)
    try:
        lag = int(cert["lag"])
        check_lag(lag)
        nm, st, known = exact_noise_structure(spec, kappa, theta, lag, digits or DEFAULT_DIGITS)
        num = _composite_numbers(cert, st, st.dec.Z[lag].shape[0],
                                 ((lag + 1) * real_calls(nm),
                                  (nm.p - real_calls(nm)) * len(known)))
        res.certificate = {"lag": lag, "s": fraction_str(num["s"])}
        parts = composite_noise_parts(nm, st, num, known)
        bad = [i for i, v in enumerate(parts["Df"]) if Ball.of(v).hi > 0] + \
              [i for i, v in enumerate(parts["Pf"]) if Ball.of(v).lo < 0]
        ok_d, dd, det_d = prove_definite(symmetrize_balls(parts["D"]), -1)
        ok_p, dp, det_p = prove_definite(symmetrize_balls(parts["Pq"]), +1)
        if bad or not (ok_d and ok_p) or num["s"] <= 0:
            res.reason = "; ".join(([f"function-value rows {bad}"] if bad else [])
                                   + ([f"decrease matrix: {det_d}"] if not ok_d else [])
                                   + ([f"positivity matrix: {det_p}"] if not ok_p else [])
                                   + (["s <= 0"] if num["s"] <= 0 else []))
        else:
            t = sqrt_upper(num["s"])
            res.verified, res.gamma_fraction = Verdict.EXACT, fraction_str(t)
            res.gamma_proven = math.nextafter(float(t), math.inf)
            res.proofs = {"decrease": f"-D ⪰ {fraction_str(dd)} I: {det_d}",
                          "positivity": f"Pq ⪰ {fraction_str(dp)} I: {det_p}",
                          "function values": "all rows exact (<= 0 / >= 0)",
                          "bound": f"gamma^2 <= s = {fraction_str(num['s'])}",
                          "fixed point": "proven exactly (sympy, x* = 1 and each free "
                                         "optimal subgradient)"}
    except (KeyError, TypeError, ValueError, AttributeError, Refused) as exc:
        res.reason = f"malformed certificate or method: {type(exc).__name__}: {exc}"
    res.seconds = time.perf_counter() - start
    return res


def verify_noise(spec: Spec, kappa: float, cert: Mapping[str, Any],
                 theta: Mapping[str, float] | None = None,
                 digits: int = DEFAULT_DIGITS, limsup: bool = False) -> NoiseProof:
    """Prove in exact arithmetic that ``cert`` (a :class:`NoiseCertificate`'s
    ``certificate``, or with ``limsup`` a
    :class:`~sosalgo.sensitivity.limsup.LimsupCertificate`'s) bounds the sensitivity
    (the long-run average, or with ``limsup`` the limsup) of the spec's method at ``kappa``."""
    start = time.perf_counter()
    res = NoiseProof(spec=spec.name)
    if not spec.has_seed_form and spec.has_condition_number and not limsup:
        return verify_composite_noise(spec, kappa, cert, theta, digits)
    try:
        if not spec.has_seed_form:  # m: 0 is not the seed's form either
            raise Refused("noise sensitivity needs one gradient call on F(m, L)")
        dec, pos, n = _exact_windows(spec, kappa, theta, int(cert["lag"]), digits)
        num = _read(cert, dec, pos, n)
        if limsup:
            _read_limsup(cert, dec, pos, num)
        res.certificate = {"lag": int(cert["lag"]), "s": fraction_str(num["s"])} | (
            {"rho": fraction_str(rational(cert["rho"]))} if limsup else {})
        _prove(res, dec, pos, num)
    except Refused as exc:
        res.reason = str(exc)
    except (KeyError, TypeError, ValueError) as exc:
        res.reason = f"malformed certificate: {type(exc).__name__}: {exc}"
    res.seconds = time.perf_counter() - start
    return res
