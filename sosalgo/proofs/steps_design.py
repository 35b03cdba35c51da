"""``sosalgo verify`` on a ``design --steps`` document: each row's ``tau_certified`` is
proven again (the PEP's dual certificate at the row's exact schedule, as ``sosalgo pep``
proves it) and its ``lower_bound`` too (the leaves cover the spec's box, each leaf's
bound re-proven by its argument, :func:`sosalgo.design_search.steps_bound.reprove`). A row
without a lower bound, or with leaves that do not cover the box, is "unsupported": verify
cannot back it and exits 3. ``floor`` is recomputed from its theorem."""

from __future__ import annotations

import math
from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from sosalgo.errors import InputError
from sosalgo.spec import Spec

__all__ = ["verify_steps_document", "verify_steps_row"]

MAX_LEAVES = 5000  # coverage is checked pairwise


def verify_steps_document(doc: Mapping[str, Any], spec: Spec, where: str = "result"
                          ) -> list[dict[str, Any]]:
    rows = doc.get("rows", [doc])
    if not isinstance(rows, list) or not rows:
        raise InputError(f"{where}: rows: expected a non-empty list")
    return [verify_steps_row(r, spec, f"{where}: rows[{i}]" if "rows" in doc else where)
            for i, r in enumerate(rows)]


def _claim(items: list[dict[str, str]], field: str, status: str, detail: str) -> None:
    items.append({"field": field, "status": status, "detail": detail})


def verify_steps_row(row: Mapping[str, Any], spec: Spec, where: str = "result"
                     ) -> dict[str, Any]:
    """One check (``verified`` "exact" when every claim is backed, else "failed" with
    ``reason``), in the form of a pep document's check."""
    items: list[dict[str, str]] = []
    try:
        steps = int(row["steps"])
        kappa = row.get("kappa")
        kappa = None if kappa is None else float(kappa)
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{where}: steps, kappa: expected numbers") from None
    upper = _upper(items, row, spec, kappa, steps, where)
    lower = _lower(items, row, spec, kappa, steps, where)
    _floor(items, row, spec, steps, where)
    bad = [c for c in items if c["status"] != "backed"]
    return {"kind": "design-steps", "kappa": kappa, "steps": steps,
            "verified": "failed" if bad else "exact",
            "tau_proven": None if upper is None else str(upper),
            "tau_lower": None if lower is None else str(lower),
            "tau_lower_float": None if lower is None else float(lower),
            "reason": None if not bad else
            f"{bad[0]['field']}: {bad[0]['status']}: {bad[0]['detail']}",
            "claims": items}


def _upper(items: list[dict[str, str]], row: Mapping[str, Any], spec: Spec,
           kappa: float | None, steps: int, where: str) -> Fraction | None:
    from sosalgo.design_search.steps import steps_problem
    from sosalgo.spec import read_spec_text
    from sosalgo.worstcase.evaluate import steps_evaluator

    field = f"{where}.tau_certified"
    claim, sched = row.get("tau_certified"), row.get("schedule_exact")
    if claim is None:
        _claim(items, field, "unsupported", "no certified worst case")
        return None
    if not isinstance(sched, dict) or not sched:
        _claim(items, field, "unsupported", "no schedule_exact to prove it at")
        return None
    text = row.get("spec_text")  # the text the design ran on (its --set applied)
    text = text if isinstance(text, str) else read_spec_text(spec.source)
    prob = steps_problem(spec, kappa, steps, list(row.get("free") or []))
    _, proven = steps_evaluator(spec, text, kappa, steps, prob)
    try:
        tp, _ = proven({str(k): v for k, v in sched.items()})
    except (InputError, ValueError, ArithmeticError) as exc:
        _claim(items, field, "contradicted", f"the PEP at the schedule failed: {exc}")
        return None
    if tp is None:
        _claim(items, field, "contradicted", "the certificate is not proven again")
    elif tp <= Fraction(float(claim)):
        _claim(items, field, "backed", f"tau_N(schedule) <= {tp} (proven exactly)")
    else:
        _claim(items, field, "contradicted", f"proven {float(tp):.12g} > claimed {claim}")
    return tp


def _lower(items: list[dict[str, str]], row: Mapping[str, Any], spec: Spec,
           kappa: float | None, steps: int, where: str) -> Fraction | None:
    field = f"{where}.lower_bound"
    claim = row.get("lower_bound")
    leaves = (row.get("bound") or {}).get("leaves")
    if claim is None:
        _claim(items, field, "unsupported", "no lower bound to verify")
        return None
    if not isinstance(leaves, list) or not leaves or len(leaves) > MAX_LEAVES:
        _claim(items, field, "unsupported", "no leaves to re-prove (or too many)")
        return None
    from sosalgo.design_search.steps import flat_names, steps_problem
    from sosalgo.design_search.steps_bound import reprove
    from sosalgo.design_search.steps_model import Unsupported, parametric_pep

    prob = steps_problem(spec, kappa, steps, list(row.get("free") or []))
    boxes = [(_fracs(lf["lo"]), _fracs(lf["hi"])) for lf in leaves]
    if not _covers(boxes, prob.box):
        _claim(items, field, "unsupported", "the leaves do not cover the box")
        return None
    try:
        pp = prob.model or parametric_pep(spec, kappa, steps, flat_names(prob.layout))
    except Unsupported as exc:
        _claim(items, field, "unsupported", str(exc))
        return None
    low = None
    for lf, (lo, hi) in zip(leaves, boxes, strict=True):
        plo, phi = ((_fracs(lf["proven_on"][0]), _fracs(lf["proven_on"][1]))
                    if "proven_on" in lf else (lo, hi))
        if not _inside((lo, hi), (plo, phi)):
            _claim(items, field, "contradicted", "a leaf is outside the box it was proven on")
            return None
        b = reprove(pp, plo, phi, str(lf.get("how")), _point(lf), _slopes(lf), _gram(lf))
        low = b if low is None else min(low, b)
    assert low is not None
    if low >= Fraction(float(claim)):
        _claim(items, field, "backed", f"tau_N >= {low} on every leaf (proven exactly)")
    else:
        _claim(items, field, "contradicted", f"re-proven {float(low):.12g} < claimed {claim}")
    return low


def _point(leaf: Mapping[str, Any]) -> list[list[int]] | None:
    """The robust point's factor (integers), None when missing or malformed."""
    try:
        return [[int(str(v)) for v in row] for row in leaf["point"]]
    except (KeyError, TypeError, ValueError):
        return None


def _slopes(leaf: Mapping[str, Any]) -> list[list[Fraction]] | None:
    """The robust point's slopes F1 (None: absent, i.e. constant function values)."""
    try:
        return [[Fraction(str(v)) for v in row] for row in leaf["slopes"]]
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None


def _gram(leaf: Mapping[str, Any]) -> list[list[list[Fraction]]] | None:
    """The affine point's matrices G_0, G_1, ... (None when missing or malformed)."""
    try:
        return [[[Fraction(str(v)) for v in row] for row in G] for G in leaf["gram"]]
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None


def _fracs(v: Any) -> tuple[Fraction, ...]:
    return tuple(Fraction(str(x)) for x in v)


def _inside(a: tuple, b: tuple) -> bool:
    return all(bl <= al and ah <= bh for al, ah, bl, bh in zip(a[0], a[1], b[0], b[1],
                                                              strict=True))


def _covers(boxes: list[tuple], root: list[tuple[Fraction, Fraction]]) -> bool:
    """The boxes lie in the root, their interiors are disjoint and their volumes (over the
    root's axes of positive width) add up to the root's: they cover it."""
    rlo = tuple(a for a, _ in root)
    rhi = tuple(b for _, b in root)
    axes = [i for i in range(len(root)) if rhi[i] > rlo[i]]

    def vol(lo: tuple, hi: tuple) -> Fraction:
        return math.prod((hi[i] - lo[i] for i in axes), start=Fraction(1))

    if not all(len(lo) == len(root) and _inside((lo, hi), (rlo, rhi)) for lo, hi in boxes):
        return False
    if sum((vol(lo, hi) for lo, hi in boxes), Fraction(0)) != vol(rlo, rhi):
        return False
    for i, (alo, ahi) in enumerate(boxes):
        for blo, bhi in boxes[i + 1:]:
            if all(max(alo[k], blo[k]) < min(ahi[k], bhi[k]) for k in axes):
                return False
    return True


def _floor(items: list[dict[str, str]], row: Mapping[str, Any], spec: Spec, steps: int,
           where: str) -> None:
    from sosalgo.design_search.steps import drori_floor

    claim = row.get("floor")
    want = drori_floor(spec, steps)
    if claim is None:
        return
    if want is not None and math.isclose(float(claim), want, rel_tol=1e-12):
        _claim(items, f"{where}.floor", "backed", "Drori 2017's L/(2 theta_N^2) recomputed")
    else:
        _claim(items, f"{where}.floor", "contradicted", f"the theorem gives {want}")
