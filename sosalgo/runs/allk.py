"""``sosalgo analyze`` on a spec whose matrices are closed forms in k: one bound for every
N, proven exactly (docs/all-k.md). Python: :func:`allk_run`."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping
from fractions import Fraction
from pathlib import Path
from typing import Any

from sosalgo import inputs
from sosalgo.kinds import ALLK_KIND
from sosalgo.spec import Spec

__all__ = ["allk_document", "allk_lines", "allk_run"]

DEGREES = (2, 1)  # O(1/N^2) first, then O(1/N)


def allk_run(spec: Spec | str | Path, out_dir: str | Path = "outputs",
             overrides: Mapping[str, str] | None = None, write: bool = True) -> dict[str, Any]:
    """The all-k bound of a spec whose matrices are rational functions of k: a potential
    of degree 2 (then 1) searched and proven exactly; the ``all-k`` document, written to
    ``DIR/<name>-allk.json``. A spec of another form: SpecError naming the field."""
    from sosalgo.certificates.allk import closed_form_system
    from sosalgo.certificates.exact_allk import prove_all_k
    from sosalgo.runs import spec_with_text

    spec, text = spec_with_text(spec, None, overrides, varying=True)
    system = closed_form_system(spec)
    out = inputs.out_dir(out_dir) if write else None
    start = time.perf_counter()
    tried = []
    for degree in DEGREES:
        result = prove_all_k(system, degree)
        tried.append({"degree": degree, "verified": result.proof.verified,
                      "reason": result.proof.reason})
        if result.proof.verified == "exact":
            break
    doc = allk_document(spec, text, result, time.perf_counter() - start, system)
    doc["attempts"] = tried
    if overrides:
        doc["set"] = dict(overrides)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        path = out / f"{spec.name}-allk.json"
        doc["file"] = str(path)
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(doc, indent=2), encoding="utf-8")
        tmp.replace(path)
    return doc


def _up(q: Fraction) -> float:
    """The smallest float >= q."""
    f = float(q)
    return f if Fraction(f) >= q else math.nextafter(f, math.inf)


def _poly_text(coeffs: list[float], var: str = "k") -> str:
    terms = [f"{c:.6g}" + ("" if j == 0 else f" {var}" if j == 1 else f" {var}^{j}")
             for j, c in enumerate(coeffs) if c != 0]
    return " + ".join(terms).replace("+ -", "- ") or "0"


def _weights(cert: Mapping[str, Fraction], degree: int, var: str = "k") -> dict[str, Any]:
    """P(k) and p(k) as readable polynomials (floats; the certificate has the fractions)."""
    size = max(int(n[1]) for n in cert if n.startswith("P")) + 1
    P = [[_poly_text([float(cert[f"P{min(i, j)}{max(i, j)}_{t}"]) for t in range(degree + 1)],
                     var) for j in range(size)] for i in range(size)]
    return {"P": P, "p": _poly_text([float(cert[f"p_{t}"]) for t in range(degree + 1)], var)}


def _references(spec: Spec) -> dict[str, str]:
    from sosalgo.kernel.expr.parse import to_sympy

    return {name: str(to_sympy(expr)) for name, expr in spec.references.items()}


def allk_document(spec: Spec, text: str, result: Any, seconds: float,
                  system: Any = None) -> dict[str, Any]:
    """The ``all-k`` document of a proof (:class:`sosalgo.certificates.exact_allk.AllKResult`)
    of ``system`` (:class:`sosalgo.certificates.allk.AllKSystem`; None: closed forms in k)."""
    from sosalgo.certificates.allk import bound_argument

    proof, cert = result.proof, result.certificate
    how = ({"argument": "N", "floor": "N", "variable": "k"} if system is None
           else bound_argument(system))
    arg, floor = how["argument"], how["floor"]
    doc: dict[str, Any] = {
        "kind": ALLK_KIND, "spec": spec.name, "source": spec.source, "spec_text": text,
        "rate_type": "all-k", "L": spec.L, "degree": result.degree,
        "bound": (f"f(x_N) - f* <= C |x_0 - x*|^2 / a({arg}) <= C |x_0 - x*|^2 / "
                  f"({floor} + c)^{result.degree} for every N >= 1"),
        "certified": proof.verified == "exact", "verified": proof.verified,
        "reason": proof.reason, "constant_estimate": result.estimate,
        "solves": result.solves, "seconds": round(seconds, 3),
        "references": _references(spec),
    }
    if system is not None and system.recurrence is not None:
        doc |= {"sequence": system.recurrence.name, "argument": arg, "floor": floor,
                "growth": (f"{system.recurrence.name}_k >= 1 + k/2, by induction from "
                           f"{system.recurrence.name}_{{k+1}} - {system.recurrence.name}_k "
                           "- 1/2 = 1/(4w) > 0 (proven exactly)")}
    if proof.verified != "exact" or cert is None:
        return doc | {"constant": None, "constant_proven": None, "certificate": None}
    doc |= {
        "constant": _up(proof.constant), "constant_proven": str(proof.constant),
        "a": [str(c) for c in proof.a], "a_float": [float(c) for c in proof.a],
        "offset": str(proof.offset), "slack": result.slack,
        "weights": _weights(cert, result.degree, how["variable"]),
        "certificate": {name: str(v) for name, v in cert.items()},
        "minors": proof.minors,
    }
    return doc


def _sequence_lines(doc: Mapping[str, Any]) -> list[str]:
    """The head of the lines when a's argument is a sequence's value (theta_{N-1})."""
    d, arg, floor, s = doc["degree"], doc["argument"], doc["floor"], doc["sequence"]
    shift = floor.split("+")[1].split(")")[0].strip()  # (N + 1)/2: 1
    in_n = Fraction(doc["constant_proven"]) * 2**d  # C / (floor)^d = C 2^d / (N + shift)^d
    return [f"{doc['spec']}: a bound for every N >= 1, proved (exact)",
            f"  f(x_N) - f* <= C |x_0 - x*|^2 / a({arg}),  a(t) = "
            f"{_poly_text(doc['a_float'], 't')} >= t^{d}",
            f"  {arg} >= {floor}: {doc['growth']}",
            f"  C = {doc['constant']:.7g}   (proven: {doc['constant_proven']}; "
            f"the SDP's optimum {doc['constant_estimate']:.7g})",
            f"  so f(x_N) - f* <= {doc['constant']:.7g} |x_0 - x*|^2 / {arg}^{d}"
            f" <= {_up(in_n):.7g} |x_0 - x*|^2 / (N + {shift})^{d}  ({s}: the "
            "spec's sequence)"]


def allk_lines(doc: Mapping[str, Any]) -> list[str]:
    """What ``sosalgo analyze`` prints for an ``all-k`` document."""
    d = doc["degree"]
    if not doc["certified"]:
        why = "; ".join(f"degree {t['degree']}: {t['reason']}" for t in doc.get("attempts", []))
        return [f"{doc['spec']}: no bound for every N proven ({why or doc['reason']})"]
    a = doc["a_float"]
    a_text = _poly_text(a, "N")
    lines = [f"{doc['spec']}: a bound for every N >= 1, proved (exact)",
             f"  f(x_N) - f* <= C |x_0 - x*|^2 / a(N),  a(N) = {a_text}"
             f" >= (N + {doc['offset']})^{d}",
             f"  C = {doc['constant']:.7g}   (proven: {doc['constant_proven']}; "
             f"the SDP's optimum {doc['constant_estimate']:.7g})",
             f"  so f(x_N) - f* <= {doc['constant']:.7g} |x_0 - x*|^2 / "
             f"(N + {doc['offset']})^{d}"]
    if doc.get("sequence"):
        lines = _sequence_lines(doc)
    v = f"{doc['sequence']}_k" if doc.get("sequence") else "k"
    lines += [f"  potential phi_k = z_k' P({v}) z_k + p({v}) (f(q_k) - f*), "
              "z_k = (xi_k - xi*, g_k), "
             "q_k = C(k) xi_k" + ("" if doc["L"] == 1 else " (of f/L, whose gradient is g/L)")
             + ":",
             f"    p({v}) = {doc['weights']['p']}"]

    for i, row in enumerate(doc["weights"]["P"]):
        lines.append(f"    P({v})[{i}] = [" + ", ".join(row) + "]")
    for name, expr in doc["references"].items():
        lines.append(f"  reference {name}: {expr}")
    if doc.get("file"):
        lines.append(f"  wrote {doc['file']}")
    return lines
