"""The certificate of a design's dual lower bound, and its re-proof from scratch.

A dual bound (:mod:`sosalgo.design_search.dualbound`) is a cover of Θ × [0, T²] by boxes, each
proven to hold no certificate of the family for ρ² in [0, r_box]. Its certificate lists
every proof made: the box (centre and half-widths in the scaled coordinates z ∈ [-1, 1]^k
of :mod:`sosalgo.design_search.polymodel`), its r, and how it was proven — ``dual`` with the
dual matrices Z (and the SDP's covers and bounds, only hints for the enclosures) or
``mode``. Matrices are stored as their exact binary64 values (:func:`encode`).

:func:`check_bound_certificate` trusts none of it: it rebuilds the exact polynomial data
from the spec, re-runs every box proof in ball arithmetic
(:class:`~sosalgo.design_search.boxproof.BoxProver`,
:class:`~sosalgo.design_search.modes.ModeTest`),
drops the proofs that fail, and computes what the remaining ones cover: walking the
dyadic splits of the root box [-1, 1]^k (the search's own splitting rule: halve the
widest side), a box is covered up to the largest of its own proven r and the smallest
cover of its two halves. The root's cover r proves that no θ ∈ Θ is certified with
ρ² < r.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["BOUND_CERTIFICATE_KIND", "BoundCheck", "bound_certificate", "box_cover",
           "check_bound_certificate", "dyadic_half"]

BOUND_CERTIFICATE_KIND = "dual-boxes"
MAX_PROOFS = 200_000
MAX_BYTES = 256 * 2**20  # inflated size of a certificate's proofs
ENCODING = "json+zlib+base64"
MAX_SPLITS = 64  # halvings per side (the search stops below 1e-10 ~ 2^-33)


def encode(a: Any) -> dict[str, Any]:
    """A float array as its exact binary64 values: shape and the little-endian bytes in
    base64 (compact, and unchanged by JSON indentation)."""
    arr = np.ascontiguousarray(np.asarray(a, dtype=float), dtype="<f8")
    return {"shape": list(arr.shape), "f64": base64.b64encode(arr.tobytes()).decode()}


def decode(o: Any) -> np.ndarray:
    """Inverse of :func:`encode`; ValueError when malformed or not finite."""
    if not isinstance(o, Mapping) or not isinstance(o.get("f64"), str):
        raise ValueError("expected {shape, f64}")
    shape = o.get("shape")
    if not isinstance(shape, list) or not all(isinstance(n, int) and 0 <= n <= 4096
                                              for n in shape) or len(shape) > 4:
        raise ValueError("shape: expected at most 4 sizes")
    size = 8 * int(np.prod(shape))
    try:
        raw = base64.b64decode(o["f64"], validate=True)
    except binascii.Error as exc:
        raise ValueError(f"f64: not base64 ({exc})") from None
    if len(raw) != size:
        raise ValueError("f64: size does not match the shape")
    return _finite(np.frombuffer(raw, dtype="<f8").reshape(shape).astype(float))


def _mats(terms: Any) -> Any:
    return None if terms is None else [encode(np.stack(blk)) for blk in terms]


def _bounds(bounds: Any) -> Any:
    if bounds is None:
        return None
    return [None if bd is None else [[int(c), int(a), encode(v)] for (c, a), v in bd.items()]
            for bd in bounds]


def bound_certificate(state: Any, free: Sequence[str]) -> dict[str, Any]:
    """The JSON certificate of a bound search's state: every proof it made, as the
    compact JSON list of proofs deflated and base64-encoded (``data``; one string keeps
    the document small whatever its indentation)."""
    proofs = [{"z": p["z"].tolist(), "w": p["w"].tolist(), "r": p["r"], "how": p["how"],
               "Z": _mats(p["Z"]), "bounds": _bounds(p["bounds"]),
               "covers": _mats(p["covers"])} for p in state.proofs]
    raw = json.dumps(proofs, separators=(",", ":")).encode()
    return {"kind": BOUND_CERTIFICATE_KIND, "free": list(free), "target_r": state.target,
            "proofs": len(proofs), "encoding": ENCODING,
            "data": base64.b64encode(zlib.compress(raw, 9)).decode()}


def _proofs(cert: Mapping[str, Any]) -> list[Any]:
    """The list of proofs of a certificate (ValueError when malformed or too large)."""
    if cert.get("encoding") != ENCODING or not isinstance(cert.get("data"), str):
        raise ValueError(f"encoding: expected {ENCODING!r} with its data")
    try:
        inflate = zlib.decompressobj()
        raw = inflate.decompress(base64.b64decode(cert["data"], validate=True), MAX_BYTES)
        if inflate.unconsumed_tail:
            raise ValueError(f"data: more than {MAX_BYTES} bytes")
        proofs = json.loads(raw)
    except (zlib.error, binascii.Error, UnicodeDecodeError, RecursionError) as exc:
        raise ValueError(f"data: not {ENCODING} ({type(exc).__name__})") from None
    if not isinstance(proofs, list) or len(proofs) > MAX_PROOFS:
        raise ValueError(f"data: expected a list of at most {MAX_PROOFS} proofs")
    return proofs


@dataclass
class BoundCheck:
    """The re-proof of a bound certificate: ``r`` is what the proofs that held cover
    (no θ of Θ is certified with ρ² < r), ``failed`` how many proofs did not hold."""

    r: float
    proofs: int
    failed: int
    reason: str

    @property
    def rho(self) -> float:
        """sqrt(r) rounded down (a float <= the proven bound on ρ)."""
        return float(np.nextafter(math.sqrt(self.r), 0.0)) if self.r > 0 else 0.0


def _decode_mats(terms: Any) -> list[list[np.ndarray]]:
    return [list(decode(blk)) for blk in terms]


def _decode_bounds(bounds: Any) -> tuple:
    if bounds is None:
        return (None, None)
    return tuple(None if bd is None else {(int(c), int(a)): decode(v) for c, a, v in bd}
                 for bd in bounds)


def _finite(a: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(a)):
        raise ValueError("non-finite entry")
    return a


def _one_proof(model: Any, prover: Any, modes: Any, p: Mapping[str, Any]
               ) -> tuple[tuple, float] | None:
    """(box key, r) when the proof holds on re-checking, else None."""
    k = model.poly.k
    z, w = _finite(np.asarray(p["z"], float)), _finite(np.asarray(p["w"], float))
    r = float(p["r"])
    if z.shape != (k,) or w.shape != (k,) or not 0 <= r <= 1 or np.any(w < 0) or \
            np.any(np.abs(z) + w > 1) or not all(map(dyadic_half, w)):
        return None
    if p["how"] == "mode":
        ok = modes.proves(z, w, r)
    elif p["how"] == "dual":
        Zs = _decode_mats(p["Z"])
        covers = None if p.get("covers") is None else _decode_mats(p["covers"])
        ok = prover.proves(z, w, Zs, _decode_bounds(p.get("bounds")), (0.0, r), covers)
    else:
        return None
    return ((*z.tolist(), *w.tolist()), r) if ok else None


def dyadic_half(w: float) -> bool:
    """A half-width of the search's boxes: 0 or 2^-j, j <= MAX_SPLITS (so the walk of
    :func:`box_cover` stays shallow whatever the certificate says)."""
    mant, exp = math.frexp(float(w))
    return w == 0 or (mant == 0.5 and -MAX_SPLITS <= exp - 1 <= 0)


def box_cover(best: dict[tuple, float], boxes: np.ndarray, z: np.ndarray, w: np.ndarray
           ) -> float:
    """What the proven boxes inside (z, w) cover (see module docstring)."""
    own = best.get((*z.tolist(), *w.tolist()), 0.0)
    k = len(z)
    inside = np.all(np.abs(boxes[:, :k] - z) + boxes[:, k:] <= w, axis=1) & \
        np.any(boxes[:, k:] < w, axis=1)
    if not inside.any() or not w.size or w.max() <= 0:
        return own
    i = int(np.argmax(w))
    half = w.copy()
    half[i] *= 0.5
    kids = []
    for sign in (-1.0, 1.0):
        zc = z.copy()
        zc[i] += sign * half[i]
        kids.append(box_cover(best, boxes[inside], zc, half))
    return max(own, min(kids))


def check_bound_certificate(model: Any, cert: Mapping[str, Any]) -> BoundCheck:
    """Re-prove a bound certificate on ``model``, the exact data of the family over Θ
    rebuilt from the spec (:func:`sosalgo.design_search.bound_model`; module docstring).
    ValueError when the certificate is malformed."""
    from sosalgo.design_search.boxproof import BoxProver

    if not isinstance(cert, Mapping) or cert.get("kind") != BOUND_CERTIFICATE_KIND:
        raise ValueError(f"kind: expected {BOUND_CERTIFICATE_KIND!r}")
    proofs = _proofs(cert)
    prover = BoxProver(model.poly, model.structure.dep,
                       [(b, vars_) for b, vars_, _ in model.structure.cone])
    best: dict[tuple, float] = {}
    failed = 0
    for p in proofs:
        try:
            got = _one_proof(model, prover, model.modes, p)
        except (ValueError, TypeError, KeyError, IndexError, OverflowError):
            got = None
        if got is None:
            failed += 1
            continue
        best[got[0]] = max(best.get(got[0], 0.0), got[1])
    k = model.poly.k
    root_w = np.ones(k) * (model.poly.half > 0)
    boxes = np.array([list(key) for key in best]) if best else np.zeros((0, 2 * k))
    r = box_cover(best, boxes, np.zeros(k), root_w) if best else 0.0
    reason = (f"{len(proofs) - failed} of {len(proofs)} box proofs re-proven in ball "
              f"arithmetic; they cover Θ × [0, {r!r}] in ρ²")
    return BoundCheck(r, len(proofs), failed, reason)
