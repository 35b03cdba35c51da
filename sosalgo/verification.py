"""Glue between results (analysis rows, design documents) and :mod:`sosalgo.verify`:
exact proof and simulation for each certificate, rational certificates written to files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.model import bind
from sosalgo.spec import Spec
from sosalgo.verify import simulate_check, verify_exact, write_certificate

__all__ = ["verify_certificate", "verify_document_rows", "verify_interpolation_certificate"]


def verify_certificate(
    spec: Spec,
    kappa: float,
    rho: float,
    P: Sequence[Sequence[float]],
    lam: float,
    theta: Mapping[str, float] | None = None,
    out_dir: Path | None = None,
    simulate: bool = True,
) -> dict[str, Any]:
    """Exact check (and simulation) of one certificate; writes the rational certificate."""
    ex = verify_exact(spec, kappa, rho, np.asarray(P, dtype=float), lam, theta)
    out: dict[str, Any] = {
        "kappa": kappa,
        "rho": rho,
        "verified": ex.verified,
        "rho_proven": ex.rho_proven,
        "rho_proven_float": ex.rho_proven_float,
        "delta": ex.delta,
        "reason": ex.reason,
    }
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{spec.name}-k{kappa:g}-certificate.json"
        write_certificate(ex, path)
        out["certificate_file"] = str(path)
    if simulate:
        sim = simulate_check(bind(spec, kappa, theta), rho, np.asarray(P, dtype=float), lam)
        out["simulation"] = {
            "ok": sim.ok,
            "worst_ratio": sim.worst_ratio,
            "trajectories": sim.trajectories,
            "violations": sim.n_violations,
        }
    return out


def verify_interpolation_certificate(
    spec: Spec,
    kappa: float,
    rho: float,
    cert: Mapping[str, Any],
    theta: Mapping[str, float] | None = None,
    out_dir: Path | None = None,
    simulate: bool = True,
) -> dict[str, Any]:
    """Exact check and simulation of an interpolation-family certificate (P, p, c,
    multipliers); the simulation follows its Lyapunov function with function values."""
    import json

    from sosalgo.verify.exact_interpolation import verify_exact_interpolation

    ex = verify_exact_interpolation(spec, kappa, rho, cert, theta)
    out: dict[str, Any] = {
        "kappa": kappa, "rho": rho, "family": "interpolation", "verified": ex.verified,
        "rho_proven": ex.rho_proven, "rho_proven_float": ex.rho_proven_float,
        "delta": ex.delta, "reason": ex.reason,
    }
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{spec.name}-k{kappa:g}-interpolation-certificate.json"
        path.write_text(json.dumps(ex.to_dict(), indent=2) + "\n", encoding="utf-8")
        out["certificate_file"] = str(path)
    if simulate:
        lyap = {"lag": int(cert["lag"]), "p": [float(v) for v in cert["p"]],
                "c": None if cert.get("c") is None else float(cert["c"])}
        sim = simulate_check(bind(spec, kappa, theta), rho, np.asarray(cert["P"], dtype=float),
                             lyapunov=lyap)
        out["simulation"] = {
            "ok": sim.ok,
            "worst_ratio": sim.worst_ratio,
            "trajectories": sim.trajectories,
            "violations": sim.n_violations,
        }
    return out


def verify_document_rows(
    spec: Spec, rows: Sequence[Mapping[str, Any]], out_dir: Path | None, simulate: bool = True,
    family: Any = None,
) -> list[dict[str, Any] | None]:
    """Verify analysis rows (``rho``, ``P``, ``lambda``) or design documents
    (``rho_certified``, ``certificate``, ``theta``); None for uncertified rows.

    Rows of the interpolation family (``family: interpolation`` and ``certificate`` with
    P, p, c, multipliers; or every row when ``family`` is that family) are checked by
    :func:`verify_interpolation_certificate`."""
    results: list[dict[str, Any] | None] = []
    for row in rows:
        name = row.get("family") or (None if family is None else family.name)
        if name == "interpolation" and "rho_certified" not in row:
            rho, cert = row.get("rho"), row.get("certificate")
            if rho is None or not isinstance(cert, Mapping):
                results.append(None)
                continue
            results.append(verify_interpolation_certificate(
                spec, float(row["kappa"]), float(rho), cert, None, out_dir, simulate))
            continue
        if "rho_certified" in row:
            rho, cert = row.get("rho_certified"), row.get("certificate") or {}
            P, lam, theta = cert.get("P"), cert.get("lambda"), row.get("theta") or None
        else:
            rho, P, lam, theta = row.get("rho"), row.get("P"), row.get("lambda"), None
        if rho is None or P is None or lam is None:
            results.append(None)
            continue
        results.append(verify_certificate(spec, float(row["kappa"]), float(rho), P, float(lam),
                                          theta, out_dir, simulate))
    return results
