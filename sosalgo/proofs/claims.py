"""What each field of a result row claims and how ``sosalgo verify`` backs it (the
handlers of :class:`sosalgo.proofs.ledger.RowLedger`; docs/verify.md lists them).

Directions (a claim is backed when the proof is at least as good as claimed):

* a rate (``rho``, ``rho_certified``, ``rho_proven``, ``rho_at_values``) or an upper
  bound (``noise``, ``constant``): the exact proof's value <= the claim (the exact check
  proves the certificate at a rational at most 1e-7 relatively above the reported float,
  the documented tolerance of Theorem 1's check);
* a lower bound (``lower_bound``, ``rho_lower``, ``floor``): the bound re-proven (or the
  theorem's value) >= the claim;
* a cap (``max_rate``, ``max_noise``, a pareto point's ``cap``): the proven value <= it;
* a value of the spec (``L``, ``measure``, ``params``, ``references``, a tuning's
  ``theta``): recomputed from the spec and equal.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from sosalgo.proofs.ledger import (
    BACKED,
    CONTEXT,
    CONTRADICTED,
    RECOMPUTED,
    UNSUPPORTED,
    RowLedger,
    frac,
    why_not,
)

__all__ = ["HANDLERS"]


def _claims_rate(L: RowLedger) -> bool:
    r = L.row
    if "rho_certified" in r:
        return r.get("rho_certified") is not None
    return r.get("certified") is True or r.get("rho") is not None


def rate(L: RowLedger, field: str) -> None:
    """``rho`` / ``rho_certified`` / ``certified`` / the certificate's parts."""
    v, cert = L.row.get(field), L.row.get("certificate")
    if field in ("P", "lambda") and isinstance(cert, Mapping) and field in cert \
            and cert[field] != v:
        L.add(field, CONTRADICTED, f"not the {field} of the row's certificate")
    elif field == "certified" and v is False or not _claims_rate(L):
        L.add(field, CONTEXT, "claims no certified rate")
    elif L.rate_ok():
        what = "the certificate" if field not in ("rho", "rho_certified", "certified") \
            else "proven exactly"
        L.add(field, BACKED, f"{what}: rate <= rho_proven (exact check)",
              L.check.get("rho_proven"))
    else:
        L.add(field, CONTRADICTED, why_not(L.check))


def rho_proven(L: RowLedger, field: str) -> None:
    """A proven rational rate ("p/q"): the certificate proven exactly at it (or at a
    smaller rational by the row's check)."""
    v = frac(L.row.get(field))
    if L.row.get(field) is None:
        L.add(field, CONTEXT, "claims no proven rate")
    elif v is None:
        L.add(field, CONTRADICTED, "not a number")
    elif L.rate_ok() and frac(L.check.get("rho_proven")) <= v:
        L.add(field, BACKED, "the exact proof's rate <= the claim", L.check["rho_proven"])
    elif exact_at(L, v):
        L.add(field, BACKED, "the certificate proven exactly at this rational", str(v))
    else:
        L.add(field, CONTRADICTED, "the certificate is not proven at this rate",
              (L.check or {}).get("rho_proven"))


def exact_at(L: RowLedger, rho: Fraction) -> bool:
    """The row's certificate proven exactly at the rational ``rho`` (cached)."""
    from sosalgo.certificates import get_family
    from sosalgo.proofs.results import row_kappa

    cache = L.cache.setdefault("exact_at", {})
    if rho not in cache:
        row = L.row
        try:
            fam = get_family(str(row.get("family") or L.spec.certificate))
            parts = row.get("certificate") if row.get("certificate") is not None else row
            cert = fam.parse_certificate(parts, L.spec.n)
            ex = fam.exact_check(L.spec, row_kappa(row, "row"), rho, cert,
                                 row.get("theta") or None)
            cache[rho] = ex.verified == "exact" and frac(ex.rho_proven) <= rho
        except Exception:  # noqa: BLE001 - a certificate that cannot be checked proves nothing
            cache[rho] = False
    return cache[rho]


def proven_rate(L: RowLedger) -> Fraction | None:
    """The best rate proven for the row: its claimed ``rho_proven`` when that is proven,
    else the row check's."""
    claimed = frac(L.row.get("rho_proven"))
    if claimed is not None and exact_at(L, claimed):
        return claimed
    return frac((L.check or {}).get("rho_proven")) if L.rate_ok() else None


def check_kind(key: str) -> Any:
    """``rho_check`` / ``noise_check`` / ``verified``: "exact" must be proven; "float"
    is unsupported (only exact proofs are vouched for)."""
    def handler(L: RowLedger, field: str) -> None:
        v = L.row.get(field)
        ok = L.rate_ok() if key == "rho" else _noise_ok(L, key)
        if v in (None, "none"):
            L.add(field, CONTEXT, "claims no check")
        elif v != "exact":
            L.add(field, UNSUPPORTED, f"{v!r}: only exact proofs are vouched for")
        elif ok:
            L.add(field, BACKED, "proven exactly")
        else:
            L.add(field, CONTRADICTED, "claims exact, but " + (
                why_not(L.check) if key == "rho" else _noisewhy_not(L, key)))
    return handler


def _noise_ok(L: RowLedger, key: str) -> bool:
    return bool(L.check) and L.check.get(f"{key}_verified") == "exact"


def _noisewhy_not(L: RowLedger, key: str) -> str:
    if not L.check or f"{key}_verified" not in L.check:
        return f"no {key} certificate was checked"
    return str(L.check.get(f"{key}_reason") or "not proven")


def noise(key: str) -> Any:
    def handler(L: RowLedger, field: str) -> None:
        if L.row.get(field) is None and field == key:
            L.add(field, CONTEXT, f"claims no {key} bound")
        elif field != key and L.row.get(key) is None and L.row.get(field) is None:
            L.add(field, CONTEXT, f"claims no {key} bound")
        elif _noise_ok(L, key):
            L.add(field, BACKED, f"proven exactly: {key} >= the proven bound",
                  L.check.get(f"{key}_fraction"))
        else:
            L.add(field, CONTRADICTED, _noisewhy_not(L, key))
    return handler


def limsup_rho(L: RowLedger, field: str) -> None:
    """The rate of the limsup certificate: its own ``rho``, proven with it."""
    v, cert = L.row.get(field), L.row.get("noise_limsup_certificate")
    if v is None:
        L.add(field, CONTEXT, "none")
    elif not _noise_ok(L, "noise_limsup") or not isinstance(cert, Mapping):
        L.add(field, CONTRADICTED, _noisewhy_not(L, "noise_limsup"))
    elif frac(cert.get("rho")) is not None and frac(cert.get("rho")) <= frac(v):
        L.add(field, BACKED, "the rate of the proven limsup certificate", cert.get("rho"))
    else:
        L.add(field, CONTRADICTED, "not the rate of the limsup certificate", cert.get("rho"))


def lag_of(cert_key: str) -> Any:
    """A lag: the lag of the certificate it names (whose check backs the claim)."""
    def handler(L: RowLedger, field: str) -> None:
        v, cert = L.row.get(field), L.row.get(cert_key)
        if v is None:
            L.add(field, CONTEXT, "none")
        elif not isinstance(cert, Mapping) or "lag" not in cert:
            L.add(field, CONTEXT, "the family's option (no certificate names a lag)")
        elif cert["lag"] == v and not isinstance(v, bool):
            L.add(field, CONTEXT, f"the lag of {cert_key} (checked there)")
        else:
            L.add(field, CONTRADICTED, f"not the lag of {cert_key} ({cert['lag']!r})")
    return handler


def constant(L: RowLedger, field: str) -> None:
    """A sublinear row's ``constant`` (and ``certified``, ``certificate``)."""
    if L.row.get("constant") is None and L.row.get("certified") is not True:
        L.add(field, CONTEXT, "claims no constant")
    elif L.rate_ok():
        L.add(field, BACKED, "proven exactly: constant >= the proven constant",
              L.check.get("constant_proven"))
    else:
        L.add(field, CONTRADICTED, why_not(L.check, "constant"))


def cap(L: RowLedger, field: str) -> None:
    """``max_rate`` / ``cap`` (the rate) and ``max_noise`` (the noise): proven <= cap."""
    c, key = L.row.get(field), "noise" if field == "max_noise" else "rate"
    if c is None:
        L.add(field, CONTEXT, "no cap")
        return
    if frac(c) is None:
        L.add(field, CONTRADICTED, "not a number")
        return
    if key == "noise":
        proven = frac((L.check or {}).get("noise_fraction")) if _noise_ok(L, "noise") \
            else None
    else:
        proven = proven_rate(L)
    claimed = L.row.get("noise" if key == "noise" else "rho", L.row.get("rho_certified"))
    if proven is None:
        L.add(field, CONTEXT if claimed is None else CONTRADICTED,
              f"no {key} was found under the cap" if claimed is None else
              f"the {key} under the cap is not proven")
    elif proven <= frac(c):
        L.add(field, BACKED, f"the proven {key} is <= the cap", str(proven))
    else:
        L.add(field, CONTRADICTED, f"the proven {key} is above the cap", str(proven))


def noise_quadratic(L: RowLedger, field: str) -> None:
    """The sensitivity on the quadratics: recomputed in floating point."""
    from sosalgo.model import bind

    v = L.row.get(field)
    if v is None:
        L.add(field, CONTEXT, "none")
        return
    try:
        theta = L.row.get("theta") or None
        got = quadratic_noise(L.spec, bind(L.spec, float(L.row["kappa"]), theta))
    except Exception as exc:  # noqa: BLE001 - a value that cannot be recomputed
        L.add(field, UNSUPPORTED, f"cannot be recomputed: {type(exc).__name__}")
        return
    ok = isinstance(v, int | float) and math.isclose(v, got, rel_tol=1e-6)
    L.add(field, RECOMPUTED if ok else CONTRADICTED,
          "recomputed in floating point (a sampled value, not a proof)"
          if ok else "differs from its recomputation", got)


def quadratic_noise(spec: Any, alg: Any) -> float:
    """The sensitivity on the quadratics, as ``analyze --noise`` computes it."""
    if not alg.has_seed_form:
        from sosalgo.sensitivity.composite import composite_noise_quadratic

        return composite_noise_quadratic(alg)[0]
    from sosalgo.sensitivity.quadratic import noise_quadratic as on_quadratics

    return on_quadratics(alg).gamma


def _recomputed(L: RowLedger, field: str, compute: Any) -> Any:
    """``compute(kappa)`` (NaN for a row without kappa): the spec's value of a claim the
    row makes; None, its entry added, when the row claims nothing (context) or when the
    value cannot be recomputed (unsupported)."""
    if not L.row.get(field):
        L.add(field, CONTEXT, "none")
        return None
    kappa = L.row.get("kappa")
    try:
        return compute(float("nan") if kappa is None else float(kappa))
    except Exception as exc:  # noqa: BLE001 - a value that cannot be recomputed
        L.add(field, UNSUPPORTED, f"cannot be recomputed: {type(exc).__name__}: {exc}"[:200])
        return None


def references(L: RowLedger, field: str) -> None:
    from sosalgo.spec.references import reference_values

    refs = L.row.get(field)
    got = _recomputed(L, field, lambda kappa: reference_values(L.spec, kappa))
    if got is None:
        return
    same = isinstance(refs, Mapping) and set(refs) == set(got) and all(
        refs[k] == got[k] or (isinstance(refs[k], float) and isinstance(got[k], float)
                              and math.isclose(refs[k], got[k], rel_tol=1e-12))
        for k in got)
    L.add(field, RECOMPUTED if same else CONTRADICTED,
          "the spec's closed-form references, recomputed" if same
          else "differ from the spec's references", got)


def spec_value(L: RowLedger, field: str) -> None:
    """``L`` and ``measure`` of a sublinear row: the spec's own."""
    from sosalgo.certificates.composite import sublinear_measure

    want = float(L.spec.L) if field == "L" else sublinear_measure(L.spec)
    v = L.row.get(field)
    ok = v == want and not isinstance(v, bool)
    L.add(field, BACKED if ok else CONTRADICTED,
          "the spec's value" if ok else f"the spec says {want!r}", want)


def params(L: RowLedger, field: str) -> None:
    from sosalgo.model import parameter_values

    v = L.row.get(field)
    got = _recomputed(L, field, lambda kappa: parameter_values(L.spec, kappa,
                                                               L.row.get("theta") or None))
    if got is None:
        return
    ok = isinstance(v, Mapping) and all(
        k in got and (v[k] == got[k] or (math.isnan(v[k]) and math.isnan(got[k])))
        for k in v if isinstance(v[k], float))
    ok = ok and all(isinstance(x, float | int) and not isinstance(x, bool)
                    for x in v.values())
    L.add(field, BACKED if ok else CONTRADICTED,
          "the spec's parameter values (and theta)" if ok else "differ from the spec's")


def floor(L: RowLedger, field: str) -> None:
    """A theorem: 1 - 1/sqrt(kappa) where it holds (:func:`~sosalgo.design_search.floor.
    class_floor`); the claim must not exceed it."""
    from sosalgo.design_search.floor import class_floor

    v = L.row.get(field)
    if v is None:
        L.add(field, CONTEXT, "none")
        return
    try:
        got = class_floor(L.spec, float(L.row["kappa"]))
    except (KeyError, TypeError, ValueError):
        got = None
    if got is None:
        L.add(field, CONTRADICTED, "no floor is a theorem for this problem class")
    elif frac(v) is not None and frac(v) <= frac(got):
        L.add(field, BACKED, "<= the theorem's value 1 - 1/sqrt(kappa) (as a float)", got)
    else:
        L.add(field, CONTRADICTED, "above the theorem's value", got)


def witness(L: RowLedger, field: str) -> None:
    from sosalgo.proofs.lowers import check_rho_lower

    status, reason, proven = check_rho_lower(L.spec, L.row)
    L.add(field, status, reason, proven)


def cycle(L: RowLedger, field: str) -> None:
    from sosalgo.witnesses.cycles import check_cycle

    cyc = L.row.get(field)
    if cyc is None:
        L.add(field, CONTEXT, "none")
        return
    if not isinstance(cyc, Mapping):
        L.add(field, CONTRADICTED, "not a cycle")
        return
    try:
        ok, why = check_cycle(L.spec, float(L.row["kappa"]), cyc, L.row.get("theta"))
    except Exception as exc:  # noqa: BLE001 - a malformed cycle proves nothing
        ok, why = False, f"{type(exc).__name__}"
    L.add(field, BACKED if ok else CONTRADICTED, f"re-checked exactly: {why}")


def witness_part(L: RowLedger, field: str) -> None:
    L.add(field, CONTEXT, "the witness of rho_lower (checked there)")


def kappa_exact(L: RowLedger, field: str) -> None:
    """``kappa_exact``: the exact kappa the row's proofs are about (checked on reading to
    be the number ``kappa`` is the float of)."""
    L.add(field, CONTEXT, "the exact kappa the claims are proven about (kappa is its float)")


def kappa_enclosure(L: RowLedger, field: str) -> None:
    """``kappa_enclosure`` [lo, hi]: an irrational kappa's ball, holding ``kappa_exact``."""
    from sosalgo.kernel.exact import enclose
    from sosalgo.kernel.kappa import exact_kappa

    ends = L.row.get(field)
    lo, hi = (frac(ends[0]), frac(ends[1])) if isinstance(ends, list) and len(ends) == 2 \
        else (None, None)
    try:
        val = exact_kappa(str(L.row.get("kappa_exact")))
        ball = enclose(val, 40)
    except (ValueError, ArithmeticError):
        ball = None
    if lo is None or hi is None or ball is None:
        L.add(field, UNSUPPORTED, "expected [lo, hi] around the row's kappa_exact")
    elif lo <= ball.lo and ball.hi <= hi:
        L.add(field, BACKED, "holds kappa_exact (ball arithmetic)")
    else:
        L.add(field, CONTRADICTED, "does not hold kappa_exact")


def certificate_of(what: str) -> Any:
    def handler(L: RowLedger, field: str) -> None:
        L.add(field, CONTEXT, f"the certificate of {what} (checked there)")
    return handler


HANDLERS: dict[str, Any] = {
    "rho": rate, "rho_certified": rate, "certified": rate, "P": rate, "lambda": rate,
    "certificate": rate, "rho_proven": rho_proven, "rho_check": check_kind("rho"),
    "noise_check": check_kind("noise"), "verified": check_kind("rho"),
    "noise": noise("noise"),
    "noise_certificate": noise("noise"), "noise_lag": lag_of("noise_certificate"),
    "lag": lag_of("certificate"),
    "noise_limsup": noise("noise_limsup"), "noise_limsup_certificate": noise("noise_limsup"),
    "noise_limsup_check": check_kind("noise_limsup"),
    "noise_limsup_lag": lag_of("noise_limsup_certificate"),
    "noise_limsup_rho": limsup_rho,
    "noise_quadratic": noise_quadratic, "references": references, "max_rate": cap,
    "max_noise": cap, "cap": cap, "floor": floor, "rho_lower": witness,
    "rho_lower_kind": witness_part, "rho_lower_witness": witness_part, "cycle": cycle,
    "bound_certificate": certificate_of("lower_bound"),
    "values_certificate": certificate_of("rho_at_values"),
    "kappa_exact": kappa_exact, "kappa_enclosure": kappa_enclosure,
}
SUBLINEAR: dict[str, Any] = {
    "constant": constant, "certified": constant, "certificate": constant,
    "L": spec_value, "measure": spec_value, "params": params,
}
