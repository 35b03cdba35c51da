"""Glue between results (analysis rows, design documents) and :mod:`sosalgo.verify`:
exact proof and simulation for each certificate, rational certificates written to files.

A result is checked only for what it claims: a row that claims a certificate (``certified:
true`` or a ``rho_certified``) must carry ``rho``, a symmetric ``P`` of the spec's size and
``lambda``; one without them *fails* (never "nothing to verify"). Malformed values (strings
where numbers belong, wrong shapes, booleans) raise :class:`ResultError` (exit code 2).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.batch.store import kappa_label
from sosalgo.errors import InputError
from sosalgo.model import bind
from sosalgo.spec import Spec
from sosalgo.verify import simulate_check, verify_exact

__all__ = [
    "ResultError", "check_failed", "verify_certificate", "verify_document_rows",
    "verify_interpolation_certificate",
]


class ResultError(InputError):
    """A result document is malformed (names the row and field): exit code 2."""


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
    P_arr = np.asarray(P, dtype=float)
    ex = verify_exact(spec, kappa, rho, P_arr, lam, theta)
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
        path, digest = _certificate_path(out_dir, spec, kappa, rho, P_arr, lam, theta)
        doc = ex.to_dict()
        doc["inputs_hash"] = digest
        path.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
        out["certificate_file"] = str(path)
    if simulate:
        out["simulation"] = _summary(simulate_check(bind(spec, kappa, theta), rho, P_arr, lam))
    return out


def _summary(sim: Any) -> dict[str, Any]:
    """The JSON summary of a simulation check."""
    return {"ok": sim.ok, "worst_ratio": sim.worst_ratio, "trajectories": sim.trajectories,
            "violations": sim.n_violations}


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
    from sosalgo.verify.exact_interpolation import verify_exact_interpolation

    ex = verify_exact_interpolation(spec, kappa, rho, cert, theta)
    out: dict[str, Any] = {
        "kappa": kappa, "rho": rho, "family": "interpolation", "verified": ex.verified,
        "rho_proven": ex.rho_proven, "rho_proven_float": ex.rho_proven_float,
        "delta": ex.delta, "reason": ex.reason,
    }
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{spec.name}-k{kappa_label(kappa)}-interpolation-certificate.json"
        path.write_text(json.dumps(ex.to_dict(), indent=2) + "\n", encoding="utf-8")
        out["certificate_file"] = str(path)
    if simulate:
        lyap = {"lag": int(cert["lag"]), "p": [float(v) for v in cert["p"]],
                "c": None if cert.get("c") is None else float(cert["c"])}
        out["simulation"] = _summary(simulate_check(
            bind(spec, kappa, theta), rho, np.asarray(cert["P"], dtype=float), lyapunov=lyap))
    return out


def _certificate_path(out_dir: Path, spec: Spec, kappa: float, rho: float, P: np.ndarray,
                      lam: float, theta: Mapping[str, float] | None) -> tuple[Path, str]:
    """``<name>-k<kappa>-certificate.json`` (exact kappa); when that file already holds
    another certificate (other spec text, theta, rho, P or lambda), a short hash of the
    certificate is added so two different certificates never share a file."""
    inputs = json.dumps({"name": spec.name, "m": spec.m, "family": spec.certificate,
                         "matrices": {k: str(v) for k, v in spec.matrices.items()},
                         "params": {k: str(v) for k, v in spec.parameters.items()},
                         "kappa": kappa, "rho": rho, "P": P.tolist(), "lambda": lam,
                         "theta": dict(theta or {})}, sort_keys=True)
    digest = hashlib.sha256(inputs.encode()).hexdigest()[:8]
    plain = out_dir / f"{spec.name}-k{kappa_label(kappa)}-certificate.json"
    try:
        old = json.loads(plain.read_text(encoding="utf-8")).get("inputs_hash")
    except (OSError, ValueError, AttributeError):
        old = None
    if not plain.exists() or old == digest:
        path = plain
    else:
        path = out_dir / f"{spec.name}-k{kappa_label(kappa)}-{digest}-certificate.json"
    return path, digest


def _number(value: Any, where: str, allow_none: bool = True) -> float | None:
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ResultError(f"{where}: expected a number, got {type(value).__name__}")
    return float(value)


def _matrix(value: Any, n: int, where: str) -> list[list[float]] | None:
    if value is None:
        return None
    if not (isinstance(value, list) and len(value) == n
            and all(isinstance(r, list) and len(r) == n for r in value)):
        raise ResultError(f"{where}: expected a {n}x{n} list of lists of numbers")
    return [[_number(v, where, allow_none=False) for v in row] for row in value]


def _claim(spec: Spec, row: Any, i: int) -> dict[str, Any] | None:
    """What row ``i`` claims: None when it claims no certificate; else its numbers (P or
    lambda may be None: the check then fails)."""
    where = f"rows[{i}]"
    if not isinstance(row, Mapping):
        raise ResultError(f"{where}: expected an object")
    kappa = _number(row.get("kappa"), f"{where}.kappa", allow_none=False)
    if not (math.isfinite(kappa) and kappa > 1):
        raise ResultError(f"{where}.kappa: must be a finite number > 1")
    if "rho_certified" in row:
        rho = _number(row.get("rho_certified"), f"{where}.rho_certified")
        cert = row.get("certificate")
        if cert is None:
            cert = {}
        if not isinstance(cert, Mapping):
            raise ResultError(f"{where}.certificate: expected an object")
        P, lam = cert.get("P"), cert.get("lambda")
        theta = row.get("theta") or None
        claimed = rho is not None
        field = f"{where}.certificate"
    else:
        rho = _number(row.get("rho"), f"{where}.rho")
        P, lam, theta = row.get("P"), row.get("lambda"), None
        certified = row.get("certified", rho is not None)
        if not isinstance(certified, bool):
            raise ResultError(f"{where}.certified: expected true or false")
        claimed = certified or rho is not None
        field = where
    if theta is not None:
        if not isinstance(theta, Mapping) or not all(isinstance(k, str) for k in theta):
            raise ResultError(f"{where}.theta: expected an object of numbers")
        theta = {k: _number(v, f"{where}.theta.{k}", allow_none=False) for k, v in theta.items()}
    P = _matrix(P, spec.n, f"{field}.P")
    lam = _number(lam, f"{field}.lambda")
    if not claimed:
        return None
    return {"kappa": kappa, "rho": rho, "P": P, "lambda": lam, "theta": theta}


def _unverifiable(c: dict[str, Any], reason: str) -> dict[str, Any]:
    return {"kappa": c["kappa"], "rho": c["rho"], "verified": "failed", "rho_proven": None,
            "rho_proven_float": None, "delta": None, "reason": reason}


def verify_document_rows(
    spec: Spec, rows: Sequence[Mapping[str, Any]], out_dir: Path | None, simulate: bool = True,
    family: Any = None,
) -> list[dict[str, Any] | None]:
    """Verify analysis rows (``rho``, ``P``, ``lambda``) or design documents
    (``rho_certified``, ``certificate``, ``theta``); None for rows claiming no certificate.
    A claimed certificate without rho, P or lambda fails; malformed rows raise ResultError.

    Rows of the interpolation family (``family: interpolation`` with a ``certificate`` of
    P, p, c, multipliers; or every row when ``family`` is that family) are checked by
    :func:`verify_interpolation_certificate`."""
    results: list[dict[str, Any] | None] = []
    plain = []
    for i, row in enumerate(rows):
        name = (row.get("family") if isinstance(row, Mapping) else None) or (
            None if family is None else family.name)
        plain.append(None if name == "interpolation" else _claim(spec, row, i))
    for i, (row, c) in enumerate(zip(rows, plain, strict=True)):
        name = row.get("family") or (None if family is None else family.name)
        if name == "interpolation":
            results.append(_interpolation_row(spec, row, i, out_dir, simulate))
            continue
        if c is None:
            results.append(None)
            continue
        missing = [k for k in ("rho", "P", "lambda") if c[k] is None]
        if missing:
            results.append(_unverifiable(
                c, f"claims a certificate but {', '.join(missing)} missing or null"))
            continue
        try:
            bind(spec, c["kappa"], c["theta"])
        except ValueError as exc:
            results.append(_unverifiable(c, f"the method cannot be evaluated: {exc}"))
            continue
        results.append(verify_certificate(spec, c["kappa"], c["rho"], c["P"], c["lambda"],
                                          c["theta"], out_dir, simulate))
    return results


def _interpolation_row(spec: Spec, row: Mapping[str, Any], i: int, out_dir: Path | None,
                       simulate: bool) -> dict[str, Any] | None:
    """One interpolation-family row (analysis row or design document)."""
    where = f"rows[{i}]"
    kappa = _number(row.get("kappa"), f"{where}.kappa", allow_none=False)
    design_doc = "rho_certified" in row
    rho = _number(row.get("rho_certified" if design_doc else "rho"), f"{where}.rho")
    cert = row.get("certificate")
    theta = row.get("theta") or None if design_doc else None
    if theta is not None:
        if not isinstance(theta, Mapping):
            raise ResultError(f"{where}.theta: expected an object of numbers")
        theta = {str(k): _number(v, f"{where}.theta.{k}", allow_none=False)
                 for k, v in theta.items()}
    claimed = rho is not None or row.get("certified") is True
    if not claimed:
        return None
    c = {"kappa": kappa, "rho": rho}
    if rho is None or not isinstance(cert, Mapping) or any(
            cert.get(k) is None for k in ("P", "p", "lag")):
        return _unverifiable(c, "claims a certificate but rho or its parts (P, p, lag) are "
                                "missing or null")
    try:
        return verify_interpolation_certificate(spec, kappa, rho, cert, theta, out_dir,
                                                simulate)
    except (KeyError, TypeError, ValueError) as exc:
        raise ResultError(f"{where}.certificate: malformed ({exc})") from None


def check_failed(check: Mapping[str, Any] | None) -> bool:
    """True when a verification result does not prove its certificate (exit code 3)."""
    if check is None:
        return False
    sim = check.get("simulation")
    return check.get("verified") != "exact" or (sim is not None and not sim.get("ok", False))
