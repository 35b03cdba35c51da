"""Glue between results (analysis rows, design documents) and :mod:`sosalgo.proofs`:
exact proof and simulation for each certificate, rational certificates written to files.

A result is checked only for what it claims: a row that claims a certificate (``certified:
true`` or a ``rho_certified``) must carry ``rho``, a symmetric ``P`` of the spec's size and
``lambda``; one without them *fails* (never "nothing to verify"). Malformed values (strings
where numbers belong, wrong shapes, booleans) raise :class:`ResultError` (exit code 2).

A row with a noise bound (``noise`` certified, or a ``noise_certificate``: ``analyze
--noise``, ``design --objective noise|--max-noise``, the points of ``pareto``) has that
certificate proven again (:func:`sosalgo.sensitivity.exact.verify_noise`); its check gets
the ``noise_*`` fields of :func:`_noise_checks` and fails when the bound is not proven or
is above the claim.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.certificates import FAMILIES, default_family, get_family, spec_family
from sosalgo.certificates.base import CertificateFamily, check_number
from sosalgo.errors import InputError, ModelError
from sosalgo.kernel.exact import Verdict
from sosalgo.kernel.phases import show_phase
from sosalgo.kinds import CERTIFICATE_KIND
from sosalgo.model import bind
from sosalgo.proofs import simulate_check
from sosalgo.proofs.exact import write_certificate
from sosalgo.schema import certificate_name
from sosalgo.spec import Spec
from sosalgo.store import output_lock

__all__ = [
    "ResultError", "check_failed", "verify_document_rows", "verify_family_certificate",
    "verify_sublinear_rows",
]


class ResultError(InputError):
    """A result document is malformed (names the row and field): exit code 2."""


def verify_family_certificate(
    spec: Spec,
    family: CertificateFamily,
    kappa: float,
    rho: float,
    cert: Mapping[str, Any],
    theta: Mapping[str, float] | None = None,
    out_dir: Path | None = None,
    simulate: bool = True,
    file_stem: str | None = None,
) -> dict[str, Any]:
    """Exact check (``family.exact_check``) and simulation along the family's Lyapunov
    function (``family.lyapunov``) of one certificate; writes the rational certificate
    (its file named after ``file_stem``, by default the spec's name).
    The returned document holds plain values (the verdict as its string)."""
    ex = family.exact_check(spec, kappa, rho, cert, theta)
    out: dict[str, Any] = {"kappa": kappa, "rho": rho}
    if not family.is_default:
        out["family"] = family.name
    out.update({"verified": str(ex.verified), "rho_proven": ex.rho_proven,
                "rho_proven_float": ex.rho_proven_float, "delta": ex.delta,
                "reason": ex.reason})
    if getattr(ex, "units", None):  # proven for f/L (tiny or huge m, L): said so
        out["units"] = ex.units
    if out_dir is not None:
        out["certificate_file"] = str(_write_certificate_file(
            out_dir, spec, family, kappa, rho, cert, theta, ex.to_dict(),
            file_stem or spec.name))
    if simulate:
        out["simulation"] = _simulation(spec, family, kappa, rho, cert, theta)
    return out


def _simulation(spec: Spec, family: CertificateFamily, kappa: float, rho: float,
                cert: Mapping[str, Any], theta: Mapping[str, float] | None) -> dict[str, Any]:
    """The simulation check as plain values; ``skipped`` (with ``ok`` None) when its test
    functions cannot be built in floating point (e.g. m = 1e-300: m L underflows)."""
    check = simulate_check
    if not spec.has_seed_form:  # proximal steps on test functions with closed-form proxes
        from sosalgo.proofs.simulate_composite import simulate_composite as check
    try:
        sim = check(bind(spec, kappa, theta), rho, **family.lyapunov(cert))
    except (ValueError, FloatingPointError, OverflowError, np.linalg.LinAlgError) as exc:
        return {"ok": None, "skipped": f"not run: {exc}"}
    return {"ok": sim.ok, "worst_ratio": sim.worst_ratio, "trajectories": sim.trajectories,
            "violations": sim.n_violations}


def _certificate_inputs(spec: Spec, family: CertificateFamily, kappa: float, rho: float,
                        cert: Mapping[str, Any], theta: Mapping[str, float] | None) -> str:
    """What identifies a certificate: the spec, kappa, rho, the certificate's parts, theta
    (for Theorem 1 exactly as before, so that files written earlier keep their hash)."""
    inputs: dict[str, Any] = {
        "name": spec.name, "m": spec.m, "family": spec.certificate,
        "matrices": {k: str(v) for k, v in spec.matrices.items()},
        "params": {k: str(v) for k, v in spec.parameters.items()},
        "kappa": kappa, "rho": rho, "theta": dict(theta or {})}
    if family.is_default:
        inputs |= {"P": np.asarray(cert["P"], dtype=float).tolist(), "lambda": cert["lambda"]}
    else:
        inputs |= {"family": family.name, "certificate": dict(cert)}
    return json.dumps(inputs, sort_keys=True, default=_plain)


def _plain(value: Any) -> Any:
    """numpy values as JSON values (for hashing)."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


def _write_certificate_file(out_dir: Path, spec: Spec, family: CertificateFamily,
                            kappa: float, rho: float, cert: Mapping[str, Any],
                            theta: Mapping[str, float] | None, doc: dict[str, Any],
                            stem: str) -> Path:
    """Write a verification's certificate document, never over another certificate.

    ``<stem>-k<kappa>[-<family>]-certificate.json`` (exact kappa; the family named unless it
    is the default one) holds the first certificate written there; a different certificate
    (other spec text, theta, rho or parts, e.g. a tampered or a design's result) gets its
    own file with a short hash of its inputs added, and the same certificate rewrites its
    own file. So a verified certificate is never overwritten or lost, whatever is verified
    after it into the same folder. The choice and the write happen under the output lock
    (concurrent runs), and the write is atomic."""
    digest = hashlib.sha256(_certificate_inputs(spec, family, kappa, rho, cert, theta)
                            .encode()).hexdigest()[:8]
    return _write_once(out_dir, certificate_name(stem, kappa, family),
                       certificate_name(stem, kappa, family, digest), digest, doc)


def _write_once(out_dir: Path, name: str, hashed: str, digest: str,
                doc: dict[str, Any]) -> Path:
    """``name`` when it is free or holds the same inputs (``digest``), else ``hashed``:
    never over another certificate; under the folder's output lock, atomic."""
    out_dir.mkdir(parents=True, exist_ok=True)
    plain = out_dir / name
    with output_lock(out_dir):  # one lock for the folder (beside it: DIR/.certificates.lock)
        try:
            old = json.loads(plain.read_text(encoding="utf-8")).get("inputs_hash")
        except (OSError, ValueError, AttributeError):
            old = None
        exists = plain.exists() or plain.is_symlink()
        path = plain if not exists or old == digest else out_dir / hashed
        return write_certificate({"kind": CERTIFICATE_KIND, **doc, "inputs_hash": digest},
                                 path)


def _number(value: Any, where: str, allow_none: bool = True) -> float | None:
    try:
        return check_number(value, where, allow_none)
    except ValueError as exc:
        raise ResultError(str(exc)) from None


def _row_family(row: Mapping[str, Any], i: int, family: CertificateFamily | None,
                ) -> CertificateFamily:
    """The family a row names (``family``), else ``family``, else the default one."""
    name = row.get("family")
    if name is None:
        return family or default_family()
    if family is not None and name == family.name:
        return family
    if not isinstance(name, str) or name not in FAMILIES:
        raise ResultError(f"rows[{i}].family: unknown certificate family {name!r} "
                          f"(known: {', '.join(FAMILIES)})")
    return get_family(name)


def _theta(row: Mapping[str, Any], where: str) -> dict[str, float] | None:
    """A design document's theta (None when absent or empty)."""
    theta = row.get("theta") or None
    if theta is None:
        return None
    if not isinstance(theta, Mapping) or not all(isinstance(k, str) for k in theta):
        raise ResultError(f"{where}.theta: expected an object of numbers")
    return {k: _number(v, f"{where}.theta.{k}", allow_none=False) for k, v in theta.items()}


def row_kappa(row: Mapping[str, Any], where: str) -> float:
    """A row's kappa: its float ``kappa`` with the exact value it records in
    ``kappa_exact`` (:func:`sosalgo.kernel.kappa.kappa_from_fields`), which the proofs are
    about; a row without ``kappa_exact`` (written before rows recorded it): the float, read
    as its shortest decimal (:func:`sosalgo.kernel.kappa.exact_kappa`). ResultError when
    ``kappa_exact`` is not the float's number."""
    from sosalgo.kernel.kappa import kappa_from_fields

    kappa = _number(row.get("kappa"), f"{where}.kappa", allow_none=False)
    if not (math.isfinite(kappa) and kappa > 1):
        raise ResultError(f"{where}.kappa: must be a finite number > 1")
    try:
        return kappa_from_fields(kappa, row.get("kappa_exact"), where)
    except ValueError as exc:
        raise ResultError(str(exc)) from None


def _claim(spec: Spec, fam: CertificateFamily, row: Any, i: int) -> dict[str, Any] | None:
    """What row ``i`` claims: None when it claims no certificate; else its numbers and the
    certificate's parts (read by ``fam.parse_certificate``; a missing part is None and the
    check then fails). Analysis rows claim with ``rho``/``certified`` and carry the parts
    in ``certificate`` or, for the default family, beside ``rho``; design documents claim
    with ``rho_certified`` and carry them in ``certificate`` with their ``theta``."""
    where = f"rows[{i}]"
    kappa = row_kappa(row, where)
    if "rho_certified" in row:
        rho = _number(row.get("rho_certified"), f"{where}.rho_certified")
        parts, field, theta = row.get("certificate"), f"{where}.certificate", _theta(row, where)
        parts = {} if parts is None else parts
        claimed = rho is not None
    else:
        rho = _number(row.get("rho"), f"{where}.rho")
        parts, field, theta = row.get("certificate"), f"{where}.certificate", None
        if parts is None:
            parts, field = row, where
        certified = row.get("certified", rho is not None)
        if not isinstance(certified, bool):
            raise ResultError(f"{where}.certified: expected true or false")
        claimed = certified or rho is not None
    if not isinstance(parts, Mapping):
        raise ResultError(f"{field}: expected an object")
    try:
        cert = fam.parse_certificate(parts, spec.n)
    except ValueError as exc:
        raise ResultError(f"{field}.{exc}") from None
    if not claimed:
        return None
    return {"kappa": kappa, "rho": rho, "cert": cert, "theta": theta, "field": field}


def _unverifiable(c: dict[str, Any], reason: str) -> dict[str, Any]:
    return {"kappa": c["kappa"], "rho": c["rho"], "verified": str(Verdict.FAILED),
            "rho_proven": None, "rho_proven_float": None, "delta": None, "reason": reason}


def verify_document_rows(
    spec: Spec, rows: Sequence[Mapping[str, Any]], out_dir: Path | None, simulate: bool = True,
    family: CertificateFamily | None = None, file_stem: str | None = None,
) -> list[dict[str, Any] | None]:
    """Verify analysis rows (``rho`` and a certificate) or design documents
    (``rho_certified``, ``certificate``, ``theta``); None for rows claiming no certificate.
    Certificate files are named after ``file_stem`` (default: the spec's name); the
    progress bar, if any, says which row is being checked.
    A claimed certificate without rho or one of its family's ``certificate_parts`` fails;
    malformed rows raise ResultError, before anything is verified or written.

    Each row is checked by the family it names (``family``), else by ``family``, else by
    the default family, through the family's ``exact_check`` and ``lyapunov``; the rows of
    a spec that selects its family (:func:`sosalgo.certificates.spec_family`: a constant c
    and its potential certificate for ``m: 0``) by that family."""
    own = spec_family(spec)
    if own is not None:
        return verify_sublinear_rows(spec, rows, out_dir, simulate, family=own)
    claims = []
    for i, row in enumerate(rows):
        if not isinstance(row, Mapping):
            raise ResultError(f"rows[{i}]: expected an object")
        fam = _row_family(row, i, family)
        claims.append((fam, _claim(spec, fam, row, i)))
    noise = [_noise_claim(row, i) for i, row in enumerate(rows)]
    limsup = [_noise_claim(row, i, "noise_limsup") for i, row in enumerate(rows)]
    results: list[dict[str, Any] | None] = []
    for i, ((fam, c), nz, ls) in enumerate(zip(claims, noise, limsup, strict=True)):
        if len(rows) > 1:
            show_phase("checking", f"row {i + 1} of {len(rows)}")
        if c is None:
            results.append(None if nz is None and ls is None else _noise_only(nz or ls))
            continue
        missing = [k for k in ("rho", *fam.certificate_parts)
                   if (c["rho"] if k == "rho" else c["cert"].get(k)) is None]
        if missing:
            results.append(_unverifiable(
                c, f"claims a certificate but {', '.join(missing)} missing or null"))
            continue
        try:
            bind(spec, c["kappa"], c["theta"])
        except ValueError as exc:
            results.append(_unverifiable(c, f"the method cannot be evaluated: {exc}"))
            continue
        try:
            results.append(verify_family_certificate(spec, fam, c["kappa"], c["rho"],
                                                     c["cert"], c["theta"], out_dir, simulate,
                                                     file_stem))
        except (KeyError, TypeError, ValueError) as exc:
            raise ResultError(f"{c['field']}: malformed ({exc})") from None
    return [r if r is None else r | (nz or {}) | (ls or {})
            for r, nz, ls in zip(results, _noise_checks(spec, noise),
                                 _noise_checks(spec, limsup, "noise_limsup"), strict=True)]


def _noise_claim(row: Mapping[str, Any], i: int, key: str = "noise") -> dict[str, Any] | None:
    """What row ``i`` claims on the noise axis (``noise``, ``noise_check``,
    ``noise_certificate``, or with ``key`` "noise_limsup" the ``noise_limsup*`` fields; a
    design's ``theta``), None when it claims nothing. A row whose bound is certified
    ("exact" or "float") without its certificate is kept: its check then fails."""
    where = f"rows[{i}]"
    cert = row.get(f"{key}_certificate")
    noise = _number(row.get(key), f"{where}.{key}")
    claimed = noise is not None and row.get(f"{key}_check") in ("exact", "float")
    if cert is None and not claimed:
        return None
    if cert is not None and not isinstance(cert, Mapping):
        raise ResultError(f"{where}.{key}_certificate: expected an object")
    kappa = row_kappa(row, where)
    return {"kappa": kappa, "noise": noise, "cert": cert,
            "theta": _theta(row, where) if "rho_certified" in row else None}


def _noise_checks(spec: Spec, claims: Sequence[dict[str, Any] | None], key: str = "noise",
                  ) -> list[dict[str, Any] | None]:
    """The exact proof (:func:`sosalgo.sensitivity.exact.verify_noise`) of each claimed
    noise certificate, as the fields ``noise_verified`` ("exact" or "failed"),
    ``noise_proven`` (a float >= the proven bound), ``noise_fraction`` and
    ``noise_reason``; the claimed ``noise`` must be >= the proven bound. With ``key``
    "noise_limsup": the same for the bound on the limsup (``noise_limsup_verified``, ...)."""
    from sosalgo.kernel.exact import rational
    from sosalgo.sensitivity.exact import verify_noise

    out: list[dict[str, Any] | None] = []
    for c in claims:
        if c is None:
            out.append(None)
            continue
        res = {key: c["noise"], f"{key}_verified": str(Verdict.FAILED),
               f"{key}_proven": None, f"{key}_fraction": None,
               f"{key}_reason": f"claims a noise bound but {key}_certificate missing or null"}
        if c["cert"] is not None:
            pr = verify_noise(spec, c["kappa"], c["cert"], c["theta"],
                              limsup=key == "noise_limsup")
            res |= {f"{key}_verified": str(pr.verified), f"{key}_proven": pr.gamma_proven,
                    f"{key}_fraction": pr.gamma_fraction, f"{key}_reason": pr.reason}
            if pr.ok and c["noise"] is not None and \
                    rational(c["noise"]) < rational(pr.gamma_fraction):
                res |= {f"{key}_verified": str(Verdict.FAILED),
                        f"{key}_reason": f"claimed {key} {c['noise']!r} is below the proven "
                                         f"bound {pr.gamma_fraction}"}
        out.append(res)
    return out


def _noise_only(nz: dict[str, Any]) -> dict[str, Any]:
    """The check of a row that claims a noise bound but no rate certificate."""
    return {"kappa": nz["kappa"], "rho": None, "verified": "no rate certificate",
            "rho_proven": None, "rho_proven_float": None, "delta": None,
            "reason": None, "noise_only": True}


def verify_sublinear_rows(spec: Spec, rows: Sequence[Mapping[str, Any]],
                          out_dir: Path | None, simulate: bool = True,
                          family: CertificateFamily | None = None,
                          ) -> list[dict[str, Any] | None]:
    """Rows of a sublinear spec (analysis or design: ``constant``, ``certificate``, a
    design's ``theta``): the family's exact proof (``family``, default the spec's own,
    :func:`sosalgo.certificates.spec_family`: the sublinear family's
    :func:`sosalgo.certificates.exact_sublinear.verify_exact_sublinear`) and the simulation
    check of the constant; None for a row claiming no constant. Malformed rows raise
    ResultError before anything is verified or written."""
    fam = family or spec_family(spec)
    if fam is None:
        raise ResultError("rows: the spec's rows are rates, not constants (its m is not 0)")
    claims = []
    for i, row in enumerate(rows):
        where = f"rows[{i}]"
        if not isinstance(row, Mapping):
            raise ResultError(f"{where}: expected an object")
        if row.get("rate_type") != "sublinear":
            raise ResultError(f"{where}.rate_type: expected sublinear (the spec has m: 0)")
        C = _number(row.get("constant"), f"{where}.constant")
        cert = row.get("certificate")
        if cert is not None and not isinstance(cert, Mapping):
            raise ResultError(f"{where}.certificate: expected an object")
        theta = _theta(row, where)
        claims.append(None if C is None and row.get("certified") is not True
                      else (C, cert, theta))
    return [None if c is None else _sublinear_check(spec, fam, *c, out_dir, simulate)
            for c in claims]


def _sublinear_check(spec: Spec, fam: CertificateFamily, C: float | None,
                     cert: Mapping[str, Any] | None, theta: dict[str, float] | None,
                     out_dir: Path | None, simulate: bool) -> dict[str, Any]:
    """One row's check as plain values (the verdict as its string): the family's exact
    check of the constant C (no kappa); the proof document goes to ``out_dir`` as
    ``<name>-sublinear-certificate.json``."""
    res = fam.exact_check(spec, None, C, cert or {}, theta)
    out: dict[str, Any] = {
        "rate_type": "sublinear", "constant": C, "rho": None, "verified": str(res.verified),
        "constant_proven": res.constant_proven,
        "constant_proven_float": res.constant_proven_float, "rho_proven": None,
        "rho_proven_float": None, "delta": None, "reason": res.reason,
        "seconds": res.seconds}
    if out_dir is not None:
        inputs = json.dumps({"name": spec.name, "matrices": {k: str(v) for k, v in
                                                             spec.matrices.items()},
                             "constant": C, "certificate": cert, "theta": theta},
                            sort_keys=True, default=_plain)
        digest = hashlib.sha256(inputs.encode()).hexdigest()[:8]
        out["certificate_file"] = str(_write_once(
            out_dir, f"{spec.name}-sublinear-certificate.json",
            f"{spec.name}-sublinear-{digest}-certificate.json", digest, res.to_dict()))
    if simulate:
        out["simulation"] = _sublinear_simulation(spec, C, theta)
    return out


def _sublinear_simulation(spec: Spec, C: float | None,
                          theta: dict[str, float] | None) -> dict[str, Any] | None:
    """The simulation check of the constant (:mod:`sosalgo.proofs.simulate_sublinear`)."""
    from sosalgo.method import bind as bind_method
    from sosalgo.proofs.simulate_sublinear import simulate_sublinear

    if C is None:
        return None
    try:
        return simulate_sublinear(bind_method(spec, None, theta), C).to_dict()
    except (ModelError, ValueError, FloatingPointError, OverflowError) as exc:
        return {"ok": None, "skipped": f"not run: {exc}"}


def check_failed(check: Mapping[str, Any] | None) -> bool:
    """True when a verification result does not prove its certificate (exit code 3): not
    proven exactly, or a simulation that ran and found a violation (a skipped simulation,
    ``ok`` None, is no evidence either way and leaves the exact proof standing)."""
    if check is None:
        return False
    if any(check.get(f"{k}_verified", Verdict.EXACT) != Verdict.EXACT
           for k in ("noise", "noise_limsup")):
        return True  # a noise certificate that is not proven
    if check.get("noise_only"):
        return False
    sim = check.get("simulation")
    failed_sim = sim is not None and "skipped" not in sim and not sim.get("ok", False)
    return check.get("verified") != Verdict.EXACT or failed_sim
