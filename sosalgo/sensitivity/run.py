"""Noise sensitivity of a spec at one kappa: certified bound, proof, quadratic value.

:func:`analyze_noise` is what ``sosalgo analyze --noise`` computes per kappa (and the
Python twin ``sosalgo.noise``): the certified bound of :func:`best_noise_certificate`
(the lag given, or the best of lags 0 .. n + 1), its exact proof, and the exact
sensitivity on quadratics beside it. Its CSV cells are
:data:`sosalgo.schema.NOISE_COLUMNS`.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from sosalgo.errors import InputError
from sosalgo.sensitivity.quadratic import QuadraticNoise, noise_quadratic
from sosalgo.sensitivity.sdp import MAX_LAG, NoiseCertificate, noise_certificate
from sosalgo.spec import Spec

__all__ = ["NoiseResult", "analyze_noise", "best_noise_certificate", "check_noise_spec",
           "limsup_fields", "noise_cells", "noise_json", "LAG_GAIN"]

LAG_GAIN = 1e-6  # relative improvement that counts as a gain when the lag is chosen


def check_noise_spec(spec: Spec) -> None:
    """InputError (one line naming the file) unless the spec has one gradient call on
    F(m, L) (a seed spec with m > 0), or is a composite spec with m > 0 and a gradient
    call on a smooth_strongly_convex function (the noisy calls)."""
    if not spec.has_condition_number or (not spec.has_seed_form
                                          and not _has_noisy_call(spec)):
        raise InputError(f"{spec.source}: --noise: noise sensitivity needs one gradient "
                         "call on F(m, L) (a seed spec with m > 0, or a composite spec with "
                         "m > 0 and a gradient call on a smooth_strongly_convex function)")


def _has_noisy_call(spec: Spec) -> bool:
    """Whether a composite spec has a gradient call on a smooth_strongly_convex function
    (decided on the method bound at the spec's first kappa)."""
    from sosalgo.model import bind
    from sosalgo.sensitivity.composite import noisy_calls

    try:
        return bool(noisy_calls(bind(spec, float(spec.kappa[0]) if spec.kappa else 10.0)))
    except (ValueError, ArithmeticError):
        return False


def best_noise_certificate(alg: Any, lags: Sequence[int] | None = None,
                           quadratic: float | None = None,
                           certify: Callable[[Any, int], NoiseCertificate] | None = None,
                           ) -> NoiseCertificate:
    """The smallest certified bound over ``lags`` (default 0 .. n + 1, at most MAX_LAG),
    tried in order; stops once the bound is within LAG_GAIN of ``quadratic`` (a lower
    bound for every lag) or two lags in a row gain nothing. A failed lag is skipped.
    ``certify(alg, lag)``: the certificate of one lag (default :func:`noise_certificate`)."""
    todo = list(lags) if lags is not None else list(range(min(alg.n + 1, MAX_LAG) + 1))
    best: NoiseCertificate | None = None
    idle = 0
    for lag in todo:
        cert = (certify or noise_certificate)(alg, lag)
        if cert.certified and (best is None or not best.certified
                               or cert.gamma < best.gamma * (1 - LAG_GAIN)):
            best, idle = cert, 0
        else:
            best, idle = best or cert, idle + 1
        if best.certified and quadratic is not None and \
                best.gamma <= quadratic * (1 + LAG_GAIN):
            break
        if idle >= 2 and best.certified:
            break
    assert best is not None
    return best


@dataclass
class NoiseResult:
    """The sensitivity of one method: ``noise`` is the certified upper bound (proven in
    exact arithmetic when ``check_kind`` is "exact", floating-point checked when "float",
    None when nothing is certified), ``noise_quadratic`` the exact value on quadratics."""

    kappa: float
    noise: float | None
    noise_float: float | None  # the bound at the solver's checked point
    noise_quadratic: float
    q_worst: float  # the curvature of the worst quadratic
    lag: int | None
    check_kind: str  # "exact", "float" or "none"
    certificate: dict[str, Any] | None
    proof: dict[str, Any] | None
    seconds: float
    detail: str = ""
    # noise_limsup: the certified bound on the limsup itself (docs/noise.md, "The limsup itself")
    noise_limsup: float | None = None
    noise_limsup_rho: float | None = None
    noise_limsup_check: str = "none"  # "exact", "float" or "none"
    noise_limsup_certificate: dict[str, Any] | None = None
    noise_limsup_proof: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"kappa": self.kappa, "noise": self.noise, "noise_float": self.noise_float,
                "noise_quadratic": self.noise_quadratic
                if math.isfinite(self.noise_quadratic) else None, "q_worst": self.q_worst,
                "noise_lag": self.lag, "noise_check": self.check_kind,
                "noise_certificate": self.certificate, "noise_proof": self.proof,
                "seconds": self.seconds, "detail": self.detail} | limsup_fields(self)


def _jsonable(cert: Mapping[str, Any] | None) -> dict[str, Any] | None:
    if cert is None:
        return None
    return {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in cert.items()}


def limsup_fields(res: NoiseResult) -> dict[str, Any]:
    """The ``noise_limsup*`` fields of a result (JSON)."""
    return {"noise_limsup": res.noise_limsup, "noise_limsup_rho": res.noise_limsup_rho,
            "noise_limsup_check": res.noise_limsup_check,
            "noise_limsup_certificate": res.noise_limsup_certificate,
            "noise_limsup_proof": res.noise_limsup_proof}


def _limsup(res: NoiseResult, spec: Spec, alg: Any, theta: Mapping[str, float] | None,
            lag: int, exact: bool) -> None:
    """``noise_limsup`` at ``lag`` (rho searched), proven exactly with ``exact``."""
    from sosalgo.sensitivity.limsup import noise_limsup_certificate

    cert = noise_limsup_certificate(alg, lag)
    if not cert.certified:
        return
    res.noise_limsup, res.noise_limsup_rho = cert.gamma, cert.rho
    res.noise_limsup_check = cert.check_kind
    res.noise_limsup_certificate = _jsonable(cert.certificate)
    if exact:
        from sosalgo.sensitivity.exact import verify_noise

        pr = verify_noise(spec, res.kappa, cert.certificate or {}, theta, limsup=True)
        res.noise_limsup_proof = pr.to_dict()
        if pr.ok:
            res.noise_limsup, res.noise_limsup_check = pr.gamma_proven, "exact"


def _quadratic(alg: Any) -> tuple[QuadraticNoise, Any]:
    """(value on quadratics, certify(alg, lag) or None for the seed's): a method outside
    the seed's form gets the composite quadratic value (q: the worst curvature of the first
    noisy call's function) and
    :func:`~sosalgo.sensitivity.composite.composite_noise_certificate`."""
    if alg.has_seed_form:
        return noise_quadratic(alg), None
    from sosalgo.sensitivity.composite import (
        composite_noise_certificate,
        composite_noise_quadratic,
        noisy_calls,
    )

    gamma, worst = composite_noise_quadratic(alg)
    quad = QuadraticNoise(gamma, worst[alg.oracles[noisy_calls(alg)[0]]])
    return quad, lambda om, lag: composite_noise_certificate(om, lag, gamma)


def analyze_noise(spec: Spec, kappa: float, theta: Mapping[str, float] | None = None,
                  lag: int | None = None, exact: bool = True,
                  limsup: bool = True) -> NoiseResult:
    """Certified sensitivity (lag ``lag``, or the best of 0 .. n + 1), its exact proof
    (``exact``) and the sensitivity on quadratics, for the spec's method at ``kappa``;
    with ``limsup`` also ``noise_limsup`` at lag ``lag`` (default: the lag chosen for
    ``noise``, at least 1)."""
    from sosalgo.model import bind

    check_noise_spec(spec)
    start = time.perf_counter()
    alg = bind(spec, kappa, theta)
    quad, certify = _quadratic(alg)
    cert = best_noise_certificate(alg, None if lag is None else [lag], quad.gamma, certify)
    noise, kind, proof = cert.gamma, cert.check_kind, None
    if cert.certified and exact:
        from sosalgo.sensitivity.exact import verify_noise

        pr = verify_noise(spec, kappa, cert.certificate or {}, theta)
        proof = pr.to_dict()
        if pr.ok:
            noise, kind = pr.gamma_proven, "exact"
    res = NoiseResult(float(kappa), noise, cert.gamma, quad.gamma, quad.q, cert.lag, kind,
                      _jsonable(cert.certificate), proof, 0.0, cert.detail)
    if limsup and math.isfinite(quad.gamma) and alg.has_seed_form:
        _limsup(res, spec, alg, theta, max(1, cert.lag) if lag is None else lag, exact)
    res.seconds = time.perf_counter() - start
    return res


def noise_cells(res: NoiseResult) -> dict[str, Any]:
    """The CSV cells of :data:`sosalgo.schema.NOISE_COLUMNS` (the certificate as one JSON
    object; an empty ``noise_quadratic`` means unstable on some quadratic of the class)."""
    q = res.noise_quadratic
    return {"noise": res.noise, "noise_quadratic": q if math.isfinite(q) else None,
            "noise_lag": res.lag if res.noise is not None else None,
            "noise_check": res.check_kind,
            "noise_certificate": None if res.certificate is None
            else json.dumps(res.certificate, separators=(",", ":")),
            "noise_limsup": res.noise_limsup, "noise_limsup_rho": res.noise_limsup_rho,
            "noise_limsup_check": res.noise_limsup_check,
            "noise_limsup_certificate": None if res.noise_limsup_certificate is None
            else json.dumps(res.noise_limsup_certificate, separators=(",", ":"))}


def noise_json(row: Mapping[str, str]) -> dict[str, Any]:
    """The JSON fields of a CSV row's noise cells (empty when the row has none)."""
    if "noise_check" not in row:
        return {}

    def num(v: str | None) -> float | None:
        return None if v in (None, "") else float(v)

    return {"noise": num(row.get("noise")), "noise_quadratic": num(row.get("noise_quadratic")),
            "noise_lag": int(row["noise_lag"]) if row.get("noise_lag") else None,
            "noise_check": row.get("noise_check") or "none",
            "noise_certificate": json.loads(row["noise_certificate"])
            if row.get("noise_certificate") else None} | ({} if "noise_limsup_check" not in row
                                                          else _limsup_json(row, num))


def _limsup_json(row: Mapping[str, str], num: Any) -> dict[str, Any]:
    """The ``noise_limsup*`` JSON fields of a CSV row."""
    return {"noise_limsup": num(row.get("noise_limsup")),
            "noise_limsup_rho": num(row.get("noise_limsup_rho")),
            "noise_limsup_check": row.get("noise_limsup_check") or "none",
            "noise_limsup_certificate": json.loads(row["noise_limsup_certificate"])
            if row.get("noise_limsup_certificate") else None}
