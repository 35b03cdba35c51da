"""The pieces of the speed–robustness front (``sosalgo pareto``; the run is
:mod:`sosalgo.runs.pareto`): the rate caps (:func:`front_caps`), the known tunings in the
form of eq. (9) (:func:`known_tunings`: gradient descent, Nesterov, heavy ball, the triple
momentum method, the robust momentum family), the front of certified points
(:func:`pareto_filter`), and the points of a pareto document for ``sosalgo verify``
(:func:`pareto_rows`). The search under each cap is
:func:`sosalgo.design_search.objectives.min_noise`, its proof
:func:`~sosalgo.design_search.objectives.certify_point`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from sosalgo.errors import InputError
from sosalgo.kinds import PARETO_KIND
from sosalgo.spec import Spec

__all__ = ["front_caps", "is_pareto_document", "known_tunings", "pareto_filter",
           "pareto_rows", "reference_spec", "robust_momentum", "tmm_parameters"]

RM_POINTS = 7  # members of the robust momentum family drawn
REFERENCE = "three-parameter"  # the spec whose form the known tunings are written in


def front_caps(rho_fast: float, points: int) -> list[float]:
    """R_i = 1 - (1 - rho_fast)^(1 + i/(points - 1)), i = 0 .. points - 1 (R_0 = rho_fast)."""
    return [1 - (1 - rho_fast) ** (1 + i / (points - 1)) for i in range(points)]


def robust_momentum(kappa: float, L: float, rho: float) -> dict[str, float]:
    """The robust momentum method (Cyrus, Hu, Van Scoy, Lessard 2018) with rate parameter
    rho in [1 - 1/sqrt(kappa), 1 - 1/kappa], as (h, beta, gamma) of eq. (9):
    h = kappa (1 - rho)^2 (1 + rho)/L, beta = kappa rho^3/(kappa - 1),
    gamma = rho^3/((kappa - 1)(1 - rho)^2 (1 + rho)). rho = 1 - 1/sqrt(kappa) is the triple
    momentum method; at rho = 1 - 1/kappa its rate is gradient descent's with h = 1/L (its
    noise sensitivity is not)."""
    return {"h": kappa * (1 - rho) ** 2 * (1 + rho) / L, "beta": kappa * rho**3 / (kappa - 1),
            "gamma": rho**3 / ((kappa - 1) * (1 - rho) ** 2 * (1 + rho))}


def tmm_parameters(kappa: float, L: float) -> dict[str, float]:
    """The triple momentum method in the paper's family (h, β, γ) at condition κ."""
    r = 1 - 1 / np.sqrt(kappa)
    return {"h": (1 + r) / L, "beta": r**2 / (2 - r), "gamma": r**2 / ((1 + r) * (2 - r))}


def known_tunings(kappa: float, m: float, L: float, rm_points: int = RM_POINTS
                  ) -> list[tuple[str, str, dict[str, float]]]:
    """(kind, name, θ of eq. (9)) of the known tunings and of ``rm_points`` members of the
    robust momentum family (rho evenly spaced from 1 - 1/sqrt(kappa) to 1 - 1/kappa)."""
    s = math.sqrt(kappa)
    c = (s - 1) / (s + 1)
    out = [("tuning", "gradient h=2/(m+L)", {"h": 2 / (m + L), "beta": 0.0, "gamma": 0.0}),
           ("tuning", "gradient h=1/L", {"h": 1 / L, "beta": 0.0, "gamma": 0.0}),
           ("tuning", "Nesterov", {"h": 1 / L, "beta": c, "gamma": c}),
           ("tuning", "heavy ball (Polyak)",
            {"h": 4 / (math.sqrt(L) + math.sqrt(m)) ** 2, "beta": c * c, "gamma": 0.0}),
           ("tuning", "triple momentum",
            {k: float(v) for k, v in tmm_parameters(kappa, L).items()})]
    lo, hi = 1 - 1 / s, 1 - 1 / kappa
    for j in range(rm_points):
        rho = lo + (hi - lo) * j / (rm_points - 1)
        out.append(("robust momentum", f"robust momentum rho={rho:.6f}",
                    robust_momentum(kappa, L, rho)))
    return out


def pareto_filter(points: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The points (dicts with ``rho`` and ``noise``, both certified) that no other point
    dominates (no other has rho and noise <= with one <), one per value pair, by rho. A
    point whose ``rho_check`` or ``noise_check`` is given and not "exact" (a value only
    checked in floating point) is left out: every point of the front is proven."""
    ok = [p for p in points if p.get("rho") is not None and p.get("noise") is not None
          and all(p.get(k, "exact") == "exact" for k in ("rho_check", "noise_check"))]
    out: list[dict[str, Any]] = []
    best = math.inf
    for p in sorted(ok, key=lambda p: (p["rho"], p["noise"])):
        if p["noise"] < best:
            out.append(dict(p))
            best = p["noise"]
    return out


@functools.cache
def reference_spec() -> Spec:
    """The spec the known tunings are written in (eq. (9), specs/three-parameter.yaml)."""
    from sosalgo.spec import spec_from_text
    from sosalgo.spec.loading import spec_text_and_path

    return spec_from_text(*spec_text_and_path(REFERENCE))


def is_pareto_document(doc: Mapping[str, Any]) -> bool:
    """Whether ``doc`` is a ``sosalgo pareto`` document (one kappa, or several)."""
    return doc.get("kind") == PARETO_KIND or "fronts" in doc or (
        "front" in doc and "points" in doc)


def pareto_rows(doc: Mapping[str, Any], where: str = "result") -> list[dict[str, Any]]:
    """Every computed point of a pareto document (``points``, then ``tunings``; each
    front of a multi-kappa document in turn) as a design-like row for ``sosalgo verify``:
    kappa, ``rho_certified`` and its ``certificate``, ``theta``, ``family``, ``noise`` and
    ``noise_certificate``; ``reference`` is true for the tunings (checked against
    :func:`reference_spec`). InputError naming the field when the document is malformed."""
    fronts = doc.get("fronts", [doc])
    if not isinstance(fronts, list) or not all(isinstance(f, Mapping) for f in fronts):
        raise InputError(f"{where}: fronts: expected a list of pareto documents")
    rows = []
    for i, f in enumerate(fronts):
        for key in ("points", "tunings"):
            pts = f.get(key)
            if not isinstance(pts, list) or not all(isinstance(p, Mapping) for p in pts):
                raise InputError(f"{where}: fronts[{i}].{key}: expected a list of points")
            rows += [{"kappa": f.get("kappa"), "kappa_exact": f.get("kappa_exact"),
                      "rho_certified": p.get("rho"),
                      "certificate": p.get("certificate"), "theta": p.get("theta"),
                      "family": f.get("family"), "noise": p.get("noise"),
                      "noise_check": p.get("noise_check"), "name": p.get("name"),
                      "noise_certificate": p.get("noise_certificate"),
                      "reference": key == "tunings"} for p in pts]
    return rows
