"""The witness check of the oracle calls themselves: every exact call's answer is the
gradient its function has at the call's point (exact rationals), every inexact one within
its relative error of it, or of the answer itself for a proximal call (ball arithmetic;
:mod:`sosalgo.worstcase.inexact`), and every exact line search step ends where the next
gradient is orthogonal to the step's direction (:mod:`sosalgo.worstcase.linesearch`). Used by
:func:`sosalgo.worstcase.check.check_witness`."""

from __future__ import annotations

from fractions import Fraction
from typing import Any

__all__ = ["call_checks"]


def _label(i: int, k: int, p: int) -> str:
    return f"y{k}" if p == 1 else f"y{i + 1}_{k}"


def call_checks(doc: dict[str, Any], av: Any) -> tuple[int, int]:
    """(calls checked, calls not proven) of a witness: the answer d of every call
    (``calls``) against the gradient g its function has at the call's point: d = g
    exactly for an exact call, eps^2 |g|^2 - |d - g|^2 >= 0 in ball arithmetic for an
    inexact gradient call and eps^2 |d|^2 - |d - g|^2 >= 0 for an inexact proximal one
    (the error y - prox within eps of the step y - v; eps of the exact method)."""
    from sosalgo.worstcase.exact import ball

    mt = av.mt
    p = mt.p
    checked = bad = 0
    twins = getattr(mt, "twins", None) or {}
    for k in range(int(doc["call_steps"])):
        for i, j in enumerate(mt.oracles):
            name = mt.functions[j][0]
            # a gradient_of call answers the true subgradient of its source's point
            label = _label(twins.get(i, i), k, p)
            pt = next((q for q in doc["functions"][name]["points"] if q["label"] == label),
                      None)
            checked += 1
            if pt is None:
                bad += 1
                continue
            d, g = doc["calls"][k][i], pt["g"]
            if i not in mt.errors:
                bad += any(Fraction(a) != Fraction(b) for a, b in zip(d, g, strict=True))
                continue
            e = ball(mt.errors[i])
            gb = [ball(v) for v in g]
            gap = [ball(a) - b for a, b in zip(d, gb, strict=True)]
            diff = sum((v * v for v in gap), ball(0))  # (arb 0) ** 2 is nan
            ref = _reference(doc, mt, k, i, gb)
            bad += not (e * e * sum((b * b for b in ref), ball(0)) - diff >= 0)
    if getattr(mt, "line_search", False):
        c, b = _line_search_checks(doc, mt)
        checked, bad = checked + c, bad + b
    return checked, bad


def _reference(doc: dict[str, Any], mt: Any, k: int, i: int, g: list[Any]) -> list[Any]:
    """The vector inexact call i's error is relative to, in balls: ``relative_to``'s
    combination of the step's answers, else the answer (a proximal call) or g."""
    from sosalgo.worstcase.exact import ball
    from sosalgo.worstcase.inexact import is_prox_call

    refs = getattr(mt, "error_refs", None) or {}
    if i in refs:
        rows = doc["calls"][k]
        return [sum((ball(Fraction(c)) * ball(rows[a][r]) for a, c in enumerate(refs[i])
                     if c), ball(0)) for r in range(len(g))]
    return [ball(a) for a in doc["calls"][k][i]] if is_prox_call(mt, i, k) else g


def _line_search_checks(doc: dict[str, Any], mt: Any) -> tuple[int, int]:
    """(steps checked, not proven): <g_{k+1}, d_k> = 0 exactly for every step (the
    point x_{k+1} = x_k + t_k d_k minimizes the convex f on the line: an exact line
    search), g_{k+1} the gradient of the point of call k + 1, d_k the answer of call k."""
    name = mt.functions[0][0]
    grads = {q["label"]: q["g"] for q in doc["functions"][name]["points"]}
    bad = 0
    N = int(doc["steps"])
    for k in range(N):
        g = grads.get(_label(0, k + 1, mt.p))
        d = doc["calls"][k][0]
        bad += g is None or sum((Fraction(a) * Fraction(b) for a, b in zip(g, d, strict=True)),
                                Fraction(0)) != 0
    return N, bad
