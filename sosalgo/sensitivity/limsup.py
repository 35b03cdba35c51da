"""A certified bound on the limsup itself: ``noise_limsup`` (docs/noise.md, "The limsup itself").

``noise`` (:mod:`sosalgo.sensitivity.sdp`) bounds the long-run *average* of
E|x_k - x*|^2 / d. Here, on the same windows, a discounted dissipation inequality

    V_{k+1} - rho^2 V_k <= s |w_k|^2 + 2 w_k' (c . v_known)                  (D_rho)

for every f in F(m, L) and every noise value, and V_k >= |x_k - x*|^2 (positivity with the
output), both through the interpolation inequalities with multipliers (S-procedure), give
E V_{k+1} <= rho^2 E V_k + s sigma^2 d, hence limsup_k E|x_k - x*|^2 / d <= s sigma^2 /
(1 - rho^2) and gamma <= sqrt(s / (1 - rho^2)). For fixed rho < 1 this is an SDP in
(P, p, s, c, multipliers) (:func:`sosalgo.sensitivity.sdp.attempt` with ``rho2``); rho is
chosen by a golden-section search on log(1 - rho^2) over (rho_q, 1), rho_q the largest
spectral radius on the quadratics of the class (no smaller rho can hold on them), after
one solve just above rho_q (where gradient descent's optimum lies). Every rho tried that
passes yields a valid bound; the smallest is kept.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from sosalgo.sensitivity.sdp import (
    MARGINS,
    NoiseCertificate,
    attempt,
    original_units,
    scaled_problem,
    supply_scale,
)

__all__ = ["LimsupCertificate", "limsup_bound", "noise_limsup_certificate", "quadratic_radius",
           "SEARCH"]

GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
SEARCH = {"span": 4.0, "steps": 8, "edge": 1e-6}  # log-width, golden steps, first gap
SEARCH_MARGINS = (1e-8, 1e-6)  # strictness tried at each rho of the search


@dataclass
class LimsupCertificate(NoiseCertificate):
    """A certified upper bound ``gamma`` on the limsup sensitivity (None: none found), the
    ``rho`` of its certificate and how many SDPs the search solved."""

    rho: float | None = None
    solves: int = 0

    def to_dict(self) -> dict[str, Any]:
        return super().to_dict() | {"rho": self.rho, "solves": self.solves}


def quadratic_radius(alg: Any, points: int = 41) -> float:
    """max over a grid of q in [m, L] of the spectral radius of A + qBC (the quadratics'
    rate; a float lower end for the search, nothing is claimed from it)."""
    A, B, C = (np.asarray(M, dtype=float) for M in (alg.A, alg.B, alg.C))
    qs = np.linspace(float(alg.m), float(alg.L), points)
    return float(max(np.max(np.abs(np.linalg.eigvals(A + q * B @ C))) for q in qs))


def limsup_bound(cert: dict[str, Any], tau: Any) -> Any:
    """gamma^2 <= (s + sum sd) / (1 - rho^2) + sum r, tau = 1 - rho^2 (docs/noise.md, "The limsup
    itself"); exact when the entries and tau are rationals."""
    return (cert["s"] + sum(cert.get("sd", ()))) / tau + sum(cert.get("r", ()))


class _Search:
    """The SDPs at fixed rho for one method and lag; remembers the best bound found."""

    def __init__(self, alg: Any, lag: int, scale: float):
        self.alg, self.lag, self.scale = alg, lag, scale
        self.dec, self.pos, self.N, self.lay = scaled_problem(alg, lag, limsup=True)
        self.best: tuple[float, float, dict[str, Any], dict[str, float], str] | None = None
        self.solves, self.last, self.margins = 0, "", SEARCH_MARGINS

    def bound(self, rho: float) -> float:
        """gamma^2 <= s / (1 - rho^2) at ``rho`` (inf when nothing passes)."""
        rho2 = rho * rho
        tau = 1.0 - rho2
        for margin in self.margins:  # the supply weighted so that s is of order one
            self.solves += 1
            status, parts, checks, detail = attempt(self.dec, self.pos, self.lay, self.N,
                                                    margin, 1.0 / (self.scale * tau), rho2)
            self.last = detail
            if parts is not None:
                L = float(self.alg.L)
                cert = {"rho": rho} | original_units(parts, self.alg.n, self.lag, L,
                                                     self.dec, self.pos)
                g2 = limsup_bound(cert, tau)
                if self.best is None or g2 < self.best[0]:
                    self.best = (g2, rho, cert, checks, detail)
                return g2
            if status == "infeasible":
                break
        return math.inf


def _golden(search: _Search, lo: float, hi: float, steps: int) -> None:
    """Golden-section search of u = log(1 - rho^2) on [lo, hi]; when both probes fail the
    interval moves toward larger rho (smaller u), where the feasible set lies."""

    def at(u: float) -> float:
        return search.bound(math.sqrt(1.0 - math.exp(u)))

    a, b = lo, hi
    c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
    fc, fd = at(c), at(d)
    for _ in range(steps):
        if fc <= fd:  # also when both are inf (inf <= inf)
            b, d, fd = d, c, fc
            c = b - GOLDEN * (b - a)
            fc = at(c)
        else:
            a, c, fc = c, d, fd
            d = a + GOLDEN * (b - a)
            fd = at(d)


def noise_limsup_certificate(alg: Any, lag: int = 1, rho: float | None = None,
                             ) -> LimsupCertificate:
    """Certified upper bound on sqrt(limsup_k E|x_k - x*|^2 / d) / sigma over F(m, L) for
    ``alg`` (one gradient call on F(m, L)), lag ``lag``: at the given ``rho`` (one SDP)
    or the best rho of the search (module docstring), floating-point checked."""
    start = time.perf_counter()
    scale = supply_scale(alg)
    if not math.isfinite(scale) or scale <= 0:
        return LimsupCertificate(None, lag, "infeasible", "none",
                                 detail="unstable on a quadratic of the class",
                                 seconds=time.perf_counter() - start)
    search = _Search(alg, lag, scale)
    if rho is not None:
        if not 0.0 <= rho < 1.0:
            raise ValueError("rho: must be in [0, 1)")
        search.margins = MARGINS
        search.bound(float(rho))
    else:
        top = math.log((1.0 - quadratic_radius(alg) ** 2) * (1.0 - SEARCH["edge"]))
        search.bound(math.sqrt(1.0 - math.exp(top)))
        _golden(search, top - SEARCH["span"], top, int(SEARCH["steps"]))
    seconds = time.perf_counter() - start
    if search.best is None:
        return LimsupCertificate(None, lag, "failed", "none", seconds=seconds,
                                 solves=search.solves, detail=search.last)
    g2, r, cert, checks, detail = search.best
    return LimsupCertificate(math.sqrt(g2), lag, "certified", "float", cert, checks,
                             seconds, detail, rho=r, solves=search.solves)
