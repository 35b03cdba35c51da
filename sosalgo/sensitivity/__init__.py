"""Certified sensitivity to additive gradient noise (docs/noise.md).

- :func:`noise_certificate`: for a bound method and a lag, the certified upper bound gamma
  on the sensitivity over F(m, L) with its certificate (one SDP, floating-point checked);
- :func:`noise_quadratic`: the exact sensitivity on the quadratics (q/2)|x|^2, q in [m, L]
  (a discrete Lyapunov equation per q, the largest over q);
- :func:`noise_limsup_certificate`: the certified bound on the limsup itself (a discounted
  dissipation inequality, rho searched; docs/noise.md, "The limsup itself");
- :func:`verify_noise`: the exact (rational) proof of a certificate (``limsup=True``: of a
  ``noise_limsup`` certificate);
- :func:`analyze_noise`: all three for a spec at one kappa (``sosalgo analyze --noise``).
"""

from __future__ import annotations

from typing import Any

__all__ = ["analyze_noise", "noise_certificate", "noise_limsup_certificate", "noise_quadratic",
           "verify_noise"]

_WHERE = {
    "noise_certificate": "sosalgo.sensitivity.sdp",
    "noise_limsup_certificate": "sosalgo.sensitivity.limsup",
    "noise_quadratic": "sosalgo.sensitivity.quadratic",
    "verify_noise": "sosalgo.sensitivity.exact",
    "analyze_noise": "sosalgo.sensitivity.run",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        from importlib import import_module

        return getattr(import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'sosalgo.sensitivity' has no attribute {name!r}")
