"""What ``sosalgo verify`` vouches for in the documents of ``sosalgo pep``: every claim of
a ``pep --json`` document (:func:`verify_pep_document`) and of a witness file
(:func:`verify_witness_file`) is re-derived from the spec, or reported.

A claim is *backed* (proven again here), *unsupported* (nothing in the document proves
it) or *contradicted* (what the document proves says otherwise); a document verifies only
when every claim is backed. The claims:

* ``tau_proven`` (a certificate's upper bound): proven again from the proof's exact
  multipliers (``multipliers_exact``, by pair label) and scale on the exact PEP rebuilt
  from the spec (:func:`sosalgo.worstcase.exact.reprove_certificate`); nothing is solved.
* a witness's ``tau_lower``: the witness checked again (:func:`sosalgo.worstcase.check.
  check_witness`); the claimed value must be what its data proves (not above it, and
  not below it by more than :data:`LOWER_REL`), about the class it claims: its ``class``
  (exact m, L, kappa, each function's parameters) and each function's class and float
  ``params`` must be the spec's at its kappa.
* ``tau`` (the float SDP value; ``tau_float`` in a witness, ``certificate.tau``): inside
  [tau_lower, tau_proven] up to :data:`TAU_REL` (the solver's accuracy); a side with no
  proof, or a witness more than :data:`LOOSE_REL` below it, leaves it unsupported, a
  value outside the proven bracket is contradicted. A
  proven tau_proven more than :data:`UPPER_REL` above its tau is true but not what the
  document's proof gives: inconsistent (so is a tau_lower below what its witness proves).
* labels that say a proof exists (``check_kind`` exact, ``proof.proven``,
  ``check.verified``) only with that proof; the exact coordinates (``x_exact``,
  ``iterates_exact``) equal to the recomputed trajectory, the float ones (``x``,
  ``iterates``) within :data:`FLOAT_REL` of them.

Solver diagnostics (``gap``, ``slack``, ``min_eig_slack``, ``min_value_slack``, float
``multipliers``, ``basis``, ``seconds``, ``detail`` texts, a witness's ``objective_floor``,
``slack``, ``mixed``, ``search`` and ``interpolant`` drawing) claim nothing and are not
checked.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from sosalgo.errors import InputError
from sosalgo.kinds import WITNESS_KIND
from sosalgo.spec import Spec
from sosalgo.worstcase.field_proof import FIELD_CHECK

__all__ = ["FLOAT_REL", "LOWER_REL", "TAU_REL", "is_pep_document", "passed",
           "pep_check_lines", "verify_pep_document", "verify_witness_file"]

TAU_REL = 1e-6  # a float tau may sit this far (relative) outside the proven bracket
LOWER_REL = 1e-9  # a claimed tau_lower may sit this far below what its witness proves
UPPER_REL = 1e-3  # a proven tau_proven is this close (relative) above its own tau
# a witness further below tau than this (relative) does not pin tau from below (the
# quadratic witness of a long horizon, sosalgo.worstcase.witness.quadratic_candidates: 1e-3
# of tau and less; a verified mix of the SDP's geometry sits within a few percent)
LOOSE_REL = 0.5
FLOAT_REL = 1e-8  # float coordinates against the exact ones (relative to the largest)
EXACT = "exact (rational and ball arithmetic)"
EXACT_RATIONAL = "exact (rational arithmetic)"  # a mirror spec's proof (no balls needed)
EXACT_FIELD = FIELD_CHECK  # a proof in Q(sqrt d) (:mod:`sosalgo.worstcase.field_proof`)


def is_pep_document(doc: Mapping[str, Any]) -> bool:
    """A ``pep --json`` document: one result, or ``rows`` of them (steps, tau, measure,
    initial in each)."""
    rows = doc.get("rows", [doc])
    return (isinstance(rows, list) and bool(rows) and all(
        isinstance(r, dict) and {"steps", "tau", "measure", "initial"} <= set(r)
        for r in rows))


class _Claims:
    """The verdicts of one document or row."""

    def __init__(self) -> None:
        self.items: list[dict[str, str]] = []

    def add(self, field: str, status: str, detail: str) -> None:
        self.items.append({"field": field, "status": status, "detail": detail})

    def backed(self, field: str, detail: str) -> None:
        self.add(field, "backed", detail)

    def bad(self) -> list[dict[str, str]]:
        return [c for c in self.items if c["status"] != "backed"]


def _num(v: Any, where: str, allow_none: bool = True) -> float | None:
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise InputError(f"{where}: expected a number, got {type(v).__name__}")
    return float(v)


def _fraction(v: Any, where: str) -> Fraction:
    if not isinstance(v, str):
        raise InputError(f"{where}: expected an exact number as a string 'p/q'")
    try:
        return Fraction(v)
    except (ValueError, ZeroDivisionError):
        raise InputError(f"{where}: not an exact number: {v[:40]!r}") from None


def _close(a: float, b: float, rel: float) -> bool:
    return math.isfinite(a) and abs(a - b) <= rel * max(abs(a), abs(b), 1e-300)


def _bracket(claims: _Claims, field: str, tau: float | None, lower: Fraction | None,
             upper: Fraction | None) -> None:
    """A float tau against the proven bracket (see the module)."""
    if tau is None:
        return
    if not math.isfinite(tau):
        claims.add(field, "unsupported", f"{tau}: an unbounded worst case is not proven")
        return
    if lower is not None and tau < float(lower) - TAU_REL * abs(float(lower)):
        claims.add(field, "contradicted", f"{tau:.10g} is below the proven lower bound "
                   f"{float(lower):.10g}")
    elif upper is not None and tau > float(upper) + TAU_REL * abs(float(upper)):
        claims.add(field, "contradicted", f"{tau:.10g} is above the proven upper bound "
                   f"{float(upper):.10g}")
    elif lower is None or upper is None:
        side = "no witness proves it from below" if lower is None else \
            "no certificate proves it from above"
        claims.add(field, "unsupported", f"{tau:.10g}: {side}")
    elif float(lower) < tau * (1 - LOOSE_REL):
        claims.add(field, "unsupported", f"{tau:.10g}: the witness proves only tau_N >= "
                   f"{float(lower):.10g} ({float(lower) / tau:.3g} of it)")
    else:
        claims.backed(field, f"within [{float(lower):.10g}, {float(upper):.10g}]")
    if upper is not None and float(upper) > tau + UPPER_REL * abs(tau):
        claims.add(field.rsplit(".", 1)[0] + ".tau_proven", "inconsistent",
                   f"{float(upper):.10g} is not the bound of this worst case ({tau:.10g}): "
                   f"a proof of it is at most {UPPER_REL:g} above")


def _upper(claims: _Claims, spec: Spec, ctx: Mapping[str, Any], proof: Any,
           claimed: Any, where: str) -> Fraction | None:
    """Re-prove a claimed tau_proven (None: no claim); the proven value or None."""
    from sosalgo.worstcase.exact import reprove_certificate
    from sosalgo.worstcase.field_proof import reprove_field_row
    from sosalgo.worstcase.finite_sum import reprove_finite_sum

    # a finite sum is a tree of outcomes: its own exact PEP; a proof over Q(sqrt d) its own
    reprove = reprove_finite_sum if spec.finite_sum is not None else reprove_certificate
    if isinstance(proof, dict) and proof.get("field") is not None \
            and spec.finite_sum is None:
        reprove = reprove_field_row
    if claimed is None:
        return None
    q = _fraction(claimed, f"{where}.tau_proven")
    if not isinstance(proof, dict):
        claims.add(f"{where}.tau_proven", "unsupported", "no proof in the document")
        return None
    if spec.mirror:  # Bregman steps: their own exact PEP
        from sosalgo.worstcase.mirror import reprove_mirror

        ok, why = reprove_mirror(spec, ctx["steps"], ctx["measure"], ctx["initial"],
                                 dict(proof) | {"tau_proven": claimed})
    else:
        ok, why = reprove(spec, ctx["kappa"], ctx["steps"], ctx["measure"],
                          ctx["initial"], dict(proof) | {"tau_proven": claimed})
    if not ok:
        claims.add(f"{where}.tau_proven", "contradicted" if "multipliers_exact" in proof
                   else "unsupported", f"{claimed} not proven: {why}")
        return None
    claims.backed(f"{where}.tau_proven", f"measure <= {float(q):.10g} proven again: {why}")
    return q


def _spec_class(spec: Spec, kappa: float | None) -> dict[str, Any] | None:
    """The spec's class at kappa (:func:`sosalgo.worstcase.exact.class_description`), None
    when it cannot be written exactly (then no claimed class matches it)."""
    from sosalgo.worstcase.exact import class_description

    try:
        return class_description(spec, kappa)
    except (ValueError, ArithmeticError):
        return None


def _check_class(claims: _Claims, spec: Spec, kappa: float | None, doc: Mapping[str, Any],
                 where: str) -> None:
    """A claimed ``class`` must be the spec's at kappa, exactly."""

    if "class" not in doc:
        return
    want = _spec_class(spec, kappa)
    if want is None or doc["class"] != want:
        claims.add(f"{where}.class", "contradicted", f"claims {doc['class']}, the spec "
                   f"at kappa {kappa} is {want}")
    else:
        claims.backed(f"{where}.class", f"m = {want['m']}, L = {want['L']}")


def _check_schedule(claims: _Claims, spec: Spec, ctx: Mapping[str, Any],
                    row: Mapping[str, Any], where: str) -> None:
    """A claimed ``schedule`` (a method that changes with k: each parameter per step)
    must be the spec's over the row's steps, to 1e-12."""
    if "schedule" not in row:
        return
    from sosalgo.worstcase.steps import spec_steps

    said = row["schedule"]
    try:
        sm = spec_steps(spec, ctx["kappa"], ctx["steps"])
        want = {} if sm is None else sm.schedule  # None: one method, no schedule
        same = isinstance(said, dict) and set(said) == set(want) and all(
            len(said[p]) == len(v) and all(_close(float(a), float(b), 1e-12)
                                           for a, b in zip(said[p], v, strict=True))
            for p, v in want.items())
    except (InputError, ValueError, TypeError):
        same, want = False, None
    if same:
        claims.backed(f"{where}.schedule", "the spec's parameters per step")
    else:
        claims.add(f"{where}.schedule", "contradicted", f"claims {str(said)[:80]}, the spec "
                   f"gives {str(want)[:80]}")


def _ctx(row: Mapping[str, Any], spec: Spec, where: str) -> dict[str, Any]:
    """kappa, steps, measure, initial of a row or witness, checked against the spec."""
    from sosalgo.worstcase.bind import has_kappa
    from sosalgo.worstcase.core import MAX_STEPS
    from sosalgo.worstcase.exact import document_kappa

    kappa = document_kappa(_num(row.get("kappa"), f"{where}.kappa"), row.get("kappa_exact"),
                           where)
    none = not has_kappa(spec)  # m: 0: the class has no kappa
    if none != (kappa is None):
        raise InputError(f"{where}.kappa: " + ("an m: 0 spec has no kappa" if none
                                               else "missing"))
    steps = row.get("steps")
    if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= MAX_STEPS:
        raise InputError(f"{where}.steps: expected an integer in 1..{MAX_STEPS}")
    for key in ("measure", "initial"):
        if not isinstance(row.get(key), str):
            raise InputError(f"{where}.{key}: expected the terms as a string")
    if row.get("spec") not in (None, spec.name):
        raise InputError(f"{where}.spec: for '{row.get('spec')}', the spec is '{spec.name}'")
    return {"kappa": kappa, "steps": steps, "measure": row["measure"],
            "initial": row["initial"]}


def _certificate(claims: _Claims, spec: Spec, ctx: Mapping[str, Any], cert: Any,
                 where: str) -> Fraction | None:
    """The claims of a ``certificate``: tau_proven re-proven, its labels consistent."""
    if cert is None:
        return None
    if not isinstance(cert, dict):
        raise InputError(f"{where}.certificate: expected an object")
    proof = cert.get("proof")
    upper = _upper(claims, spec, ctx, proof, cert.get("tau_proven"), f"{where}.certificate")
    exact_kind = cert.get("check_kind") in (EXACT, EXACT_RATIONAL, EXACT_FIELD)
    if exact_kind != (cert.get("tau_proven") is not None):
        claims.add(f"{where}.certificate.check_kind", "contradicted",
                   f"{cert.get('check_kind')!r} with tau_proven {cert.get('tau_proven')}")
    if isinstance(proof, dict):
        said = proof.get("proven")
        if said and proof.get("tau_proven") != cert.get("tau_proven"):
            claims.add(f"{where}.certificate.proof.tau_proven", "contradicted",
                       "differs from the certificate's tau_proven")
        if bool(said) != (cert.get("tau_proven") is not None) or (said and upper is None):
            claims.add(f"{where}.certificate.proof.proven", "contradicted",
                       f"{said!r} with tau_proven {cert.get('tau_proven')} "
                       + ("proven" if upper is not None else "not proven"))
        pf = proof.get("tau_proven_float")
        if pf is not None and (upper is None or not _close(_num(pf, where) or 0.0,
                                                            float(upper), 1e-12)):
            claims.add(f"{where}.certificate.proof.tau_proven_float", "contradicted",
                       f"{pf} is not the proven {upper}")
        _check_class(claims, spec, ctx["kappa"], proof, f"{where}.certificate.proof")
    return upper


def verify_pep_document(doc: Mapping[str, Any], spec: Spec,
                        where: str = "result") -> list[dict[str, Any]]:
    """One check per row of a ``pep --json`` document (see the module): ``verified``
    "exact" when every claim of the row is backed, "failed" otherwise (``reason`` the
    first claim that is not, ``claims`` all of them)."""
    rows = doc.get("rows", [doc])
    out = []
    for i, row in enumerate(rows):
        w = f"{where}: rows[{i}]" if "rows" in doc else where
        out.append(_verify_row(row, spec, w))
    return out


def _verify_row(row: Mapping[str, Any], spec: Spec, where: str) -> dict[str, Any]:
    ctx = _ctx(row, spec, where)
    claims = _Claims()
    _check_class(claims, spec, ctx["kappa"], row, where)
    _check_schedule(claims, spec, ctx, row, where)
    tau = _num(row.get("tau"), f"{where}.tau")
    upper = _certificate(claims, spec, ctx, row.get("certificate"), where)
    lower = None
    wit = row.get("witness")
    if wit is not None:
        if not isinstance(wit, dict):
            raise InputError(f"{where}.witness: expected an object")
        for key in ("kappa", "steps", "measure", "initial"):
            if wit.get(key) != row.get(key):
                claims.add(f"{where}.witness.{key}", "contradicted",
                           f"{wit.get(key)!r}, the row says {row.get(key)!r}")
        sub = verify_witness_file(wit, spec, f"{where}.witness", own_upper=False)
        claims.items += sub["claims"]
        lower = None if sub["tau_lower"] is None else Fraction(sub["tau_lower"])
    from sosalgo.worstcase.terms import NONE_TEXT

    if lower is None and str(row.get("initial", "")).strip() == NONE_TEXT:
        lower = Fraction(0)  # no initial condition: every vector and value 0 is an instance
    if tau is None and (upper is not None or lower is not None):
        claims.add(f"{where}.tau", "contradicted", "null with a proven bound")
    _bracket(claims, f"{where}.tau", tau, lower, upper)
    cert = row.get("certificate")
    if isinstance(cert, dict) and cert.get("tau") is not None:
        _bracket(claims, f"{where}.certificate.tau", _num(cert["tau"], where), lower, upper)
    if tau is None and upper is None and lower is None:
        claims.add(f"{where}", "unsupported", "no worst case and no bound: nothing to verify")
    return _verdict(claims, ctx, tau, upper, lower)


def _verdict(claims: _Claims, ctx: Mapping[str, Any], tau: float | None,
             upper: Fraction | None, lower: Fraction | None) -> dict[str, Any]:
    from sosalgo.kernel.exact import fraction_str

    bad = claims.bad()
    return {"kind": "pep", "kappa": ctx["kappa"], "steps": ctx["steps"], "tau": tau,
            "verified": "failed" if bad else "exact",
            "tau_proven": None if upper is None else fraction_str(upper),
            "tau_proven_float": None if upper is None else float(upper),
            "tau_lower": None if lower is None else fraction_str(lower),
            "tau_lower_float": None if lower is None else float(lower),
            "reason": None if not bad else f"{bad[0]['field']}: {bad[0]['status']}: "
                                           f"{bad[0]['detail']}",
            "claims": claims.items}


def verify_witness_file(doc: Mapping[str, Any], spec: Spec, where: str = "witness",
                        own_upper: bool = True) -> dict[str, Any]:
    """The claims of a witness (see the module): the check of :func:`sosalgo.worstcase.check.
    check_witness` plus every claim the file makes. ``verified`` True (``verdict``
    "exact") only when all are backed; ``tau_lower`` the proven lower bound (None when
    the check fails)."""
    from sosalgo.worstcase.check import check_witness

    if doc.get("kind") != WITNESS_KIND:
        raise InputError(f"{where}.kind: expected '{WITNESS_KIND}'")
    ctx = _ctx(doc, spec, where)
    claims = _Claims()
    chk = check_witness(dict(doc), spec)
    said = doc.get("check") if isinstance(doc.get("check"), dict) else {}
    lower = Fraction(chk["tau_lower"]) if chk["verified"] else None
    _lower_claim(claims, said, lower, chk, where)
    _check_class(claims, spec, ctx["kappa"], doc, where)
    _function_claims(claims, spec, ctx["kappa"], doc, where)
    if doc.get("calls_per_step") != len(spec.oracles) or doc.get("call_steps") not in (
            ctx["steps"], ctx["steps"] + 1):
        claims.add(f"{where}.calls_per_step", "contradicted", f"the spec's method makes "
                   f"{len(spec.oracles)} call(s) per step, over {ctx['steps']} or "
                   f"{ctx['steps'] + 1} steps")
    if chk["verified"]:
        _coordinate_claims(claims, spec, ctx["kappa"], doc, where)
    upper = None
    if own_upper:
        up = doc.get("upper")
        if up is not None and not isinstance(up, dict):
            raise InputError(f"{where}.upper: expected an object")
        upper = _upper(claims, spec, ctx, up, (up or {}).get("tau_proven"), f"{where}.upper")
        _bracket(claims, f"{where}.tau_float", _num(doc.get("tau_float"), where), lower,
                 upper)
    elif doc.get("tau_float") is not None and lower is not None:
        tf = _num(doc["tau_float"], where) or 0.0
        if tf < float(lower) * (1 - TAU_REL):
            claims.add(f"{where}.tau_float", "contradicted", f"{tf:.10g} is below the "
                       f"proven lower bound {float(lower):.10g}")
    bad = claims.bad()
    return {"verified": not bad, "verdict": "failed" if bad else "exact", "check": chk,
            "tau_lower": chk["tau_lower"], "tau_lower_float": chk["tau_lower_float"],
            "tau_proven": None if upper is None else str(upper),
            "reason": None if not bad else f"{bad[0]['field']}: {bad[0]['status']}: "
                                           f"{bad[0]['detail']}",
            "claims": claims.items}


def _lower_claim(claims: _Claims, said: Mapping[str, Any], lower: Fraction | None,
                 chk: Mapping[str, Any], where: str) -> None:
    """The claimed ``check`` (verified, tau_lower, tau_lower_float) against the check."""
    field = f"{where}.check.tau_lower"
    if lower is None:
        claims.add(f"{where}.check", "contradicted" if said.get("verified") else
                   "unsupported", f"the witness does not verify: {chk.get('detail')}")
        return
    if said.get("verified") is not True:
        claims.add(f"{where}.check.verified", "contradicted",
                   f"{said.get('verified')!r}, the witness verifies")
    claimed = said.get("tau_lower")
    if claimed is None:
        claims.add(field, "unsupported", "no claimed lower bound")
        return
    q = _fraction(claimed, field)
    if q > lower:
        claims.add(field, "contradicted", f"{float(q):.12g} is above what the witness "
                   f"proves ({float(lower):.12g})")
    elif q < lower * (1 - Fraction(LOWER_REL)):
        claims.add(field, "contradicted", f"{float(q):.12g} is not what the witness proves "
                   f"({float(lower):.12g})")
    else:
        claims.backed(field, f"tau_N >= {float(q):.12g}")
    lf = said.get("tau_lower_float")
    if lf is None or not _close(_num(lf, f"{field}_float") or 0.0, float(q), 1e-12):
        claims.add(f"{field}_float", "contradicted", f"{lf} is not {float(q):.17g}")


def _function_claims(claims: _Claims, spec: Spec, kappa: float | None,
                     doc: Mapping[str, Any], where: str) -> None:
    """Each function's class name and float params are the spec's at kappa."""
    import sympy as sp

    want = (_spec_class(spec, kappa) or {}).get("functions", {})
    funcs = doc.get("functions")
    if not isinstance(funcs, dict) or set(funcs) != set(want):
        claims.add(f"{where}.functions", "contradicted",
                   f"the spec's functions are {sorted(want)}")
        return
    for name, fd in funcs.items():
        w = f"{where}.functions.{name}"
        if not isinstance(fd, dict) or fd.get("class") != want[name]["class"]:
            claims.add(f"{w}.class", "contradicted", f"the spec says {want[name]['class']}")
            continue
        params = fd.get("params") or {}
        exact = want[name]["params"]
        if not isinstance(params, dict) or set(params) != set(exact):
            claims.add(f"{w}.params", "contradicted", f"the spec's are {sorted(exact)}")
            continue
        for k, text in exact.items():
            val = float(sp.sympify(text))
            got = params[k]
            if isinstance(got, bool) or not isinstance(got, int | float) or not (
                    got == val or _close(float(got), val, 1e-12)):
                claims.add(f"{w}.params.{k}", "contradicted", f"{got}, the spec's class "
                           f"has {k} = {text}")


def _coordinate_claims(claims: _Claims, spec: Spec, kappa: float | None,
                       doc: Mapping[str, Any], where: str) -> None:
    """``x_exact``/``iterates_exact`` equal to the recomputed trajectory; ``x`` and
    ``iterates`` (floats) within :data:`FLOAT_REL` of it."""
    from sosalgo.worstcase.check import exact_points
    from sosalgo.worstcase.exact import exact_or_none

    steps = doc.get("steps")
    mt = exact_or_none(spec, kappa, steps if isinstance(steps, int) and not
                       isinstance(steps, bool) and 0 <= steps <= 10_000 else 0)
    if mt is None:
        return
    if "xi0_second" in doc:  # two runs: each point's float x against the recomputed one
        _contraction_coordinates(claims, mt, doc, where)
        return
    try:
        pts, its = exact_points(dict(doc), mt)
    except (KeyError, ValueError, TypeError, IndexError, ArithmeticError, StopIteration):
        claims.add(f"{where}", "contradicted", "the trajectory cannot be recomputed")
        return
    scale = max([abs(float(_mid(v))) for x in its for v in x] + [1e-300])
    for name, fd in doc["functions"].items():
        for i, pt in enumerate(fd.get("points") or []):
            w = f"{where}.functions.{name}.points[{i}]"
            _coords(claims, w, pt, pts.get(pt.get("label")), scale)
    for key in ("iterates_exact", "iterates"):
        got = doc.get(key)
        if got is None:
            continue
        if not isinstance(got, list) or len(got) != len(its):
            claims.add(f"{where}.{key}", "contradicted", f"expected {len(its)} iterates")
            continue
        for k, (x, want) in enumerate(zip(got, its, strict=True)):
            _coord_list(claims, f"{where}.{key}[{k}]", x, want, key.endswith("exact"),
                        scale)


def _contraction_coordinates(claims: _Claims, mt: Any, doc: Mapping[str, Any],
                             where: str) -> None:
    """Each point's ``x`` and the ``iterates`` (the second run's states) of a contraction
    witness within :data:`FLOAT_REL` (relative to the largest) of both runs recomputed
    (:mod:`sosalgo.worstcase.contraction_witness`)."""
    from sosalgo.kernel.arb import precision
    from sosalgo.worstcase.check import PREC, arb_view
    from sosalgo.worstcase.contraction_witness import contraction_positions

    try:
        with precision(PREC):
            pos, states = contraction_positions(dict(doc), arb_view(mt))
        want = {k: float(v[0].mid()) for k, v in pos.items()}
        its = [float(xi[0, 0].mid()) for xi in states[1]]
    except (KeyError, ValueError, TypeError, IndexError, ArithmeticError):
        claims.add(f"{where}", "contradicted", "the two runs cannot be recomputed")
        return
    scale = max([abs(v) for v in [*want.values(), *its]] + [1e-300])
    got = doc.get("iterates")
    if not (isinstance(got, list) and len(got) == len(its) and all(
            isinstance(x, list) and len(x) == 1 and isinstance(x[0], int | float)
            and not isinstance(x[0], bool) and abs(x[0] - w) <= FLOAT_REL * scale
            for x, w in zip(got, its, strict=True))):
        claims.add(f"{where}.iterates", "contradicted", "not the second run's states")
    for name, fd in doc["functions"].items():
        for i, pt in enumerate(fd.get("points") or []):
            x, w = pt.get("x"), want.get(pt.get("label"))
            if w is None or not isinstance(x, list) or len(x) != 1 or isinstance(
                    x[0], bool) or not isinstance(x[0], int | float) or abs(
                    x[0] - w) > FLOAT_REL * scale:
                claims.add(f"{where}.functions.{name}.points[{i}].x", "contradicted",
                           "not the recomputed point")


def _mid(v: Any) -> Fraction:
    return v.c if hasattr(v, "c") else Fraction(v)


def _coords(claims: _Claims, where: str, pt: Any, want: Any, scale: float) -> None:
    if not isinstance(pt, dict) or want is None:
        return
    for key, exact in (("x_exact", True), ("x", False)):
        if key in pt:
            _coord_list(claims, f"{where}.{key}", pt[key], want, exact, scale)


def _coord_list(claims: _Claims, where: str, got: Any, want: list[Any], exact: bool,
                scale: float) -> None:
    """One point's coordinates against the recomputed ones."""
    if not isinstance(got, list) or len(got) != len(want):
        claims.add(where, "contradicted", f"expected {len(want)} coordinates")
        return
    for c, (g, v) in enumerate(zip(got, want, strict=True)):
        if exact:
            ok = _exact_matches(g, v)
        else:
            ok = (isinstance(g, int | float) and not isinstance(g, bool)
                  and abs(float(g) - float(_mid(v))) <= FLOAT_REL * scale)
        if not ok:
            claims.add(f"{where}[{c}]", "contradicted", f"{g!r} is not the recomputed "
                       f"coordinate {float(_mid(v)):.17g}")
            return


def _exact_matches(got: Any, v: Any) -> bool:
    """A stored exact coordinate (``p/q``, or ``[lo, hi]`` around a ball) against the
    recomputed one (a rational, or a ball that must lie inside [lo, hi])."""
    try:
        if isinstance(got, list) and len(got) == 2 and all(isinstance(t, str) for t in got):
            lo, hi = Fraction(got[0]), Fraction(got[1])
            b_lo, b_hi = (v.c - v.r, v.c + v.r) if hasattr(v, "c") else (Fraction(v),) * 2
            return lo <= b_lo and b_hi <= hi
        if isinstance(got, str):
            exact_v = not hasattr(v, "c") or not v.r
            return exact_v and Fraction(got) == _mid(v)
    except (ValueError, ZeroDivisionError):
        return False
    return False


def passed(check: Mapping[str, Any]) -> bool:
    """Whether a check of :func:`verify_pep_document` (``verified`` "exact") or
    :func:`verify_witness_file` (``verified`` True) backs every claim."""
    return check.get("verified") in (True, "exact")


def pep_check_lines(name: str, checks: list[dict[str, Any]]) -> list[str]:
    """The printed verdicts of ``sosalgo verify`` on a pep document or witness file."""
    lines = []
    for c in checks:
        head = (f"{name}" + (f" kappa {c['kappa']:g}" if c.get("kappa") is not None else "")
                + (f" N = {c['steps']}" if c.get("steps") is not None else ""))
        if passed(c):
            bounds = [f"tau_N >= {c['tau_lower_float']:.10g}" if c.get("tau_lower") else "",
                      f"tau_N <= {float(Fraction(c['tau_proven'])):.10g}"
                      if c.get("tau_proven") else "",
                      f"C = {float(Fraction(c['constant_proven'])):.10g}"
                      if c.get("constant_proven") else ""]
            lines.append(f"{head}: verified (every claim backed; "
                         + ", ".join(b for b in bounds if b) + ")")
        else:
            why = str(c["reason"]).replace(f"{name}: ", "").replace(f"{name}.", "")
            lines.append(f"{head}: NOT verified: {why}")
    return lines
