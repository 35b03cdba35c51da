"""Constraints on the instance: ``pep: {constraints: ["LEFT REL RIGHT", ...]}``.

A relation between sums of terms of the measure language (``f(x_0)``, ``grad(x_0)``,
``dist(x_1)``, ``dist(P, Q)``; coefficients expressions of m, L, kappa and the spec's
parameters), REL one of ``==``, ``<=``, ``>=``. It restricts the PEP to the instances
that satisfy it, as PEPit's ``problem.add_constraint`` (Polyak's step: gamma |g_0|^2 =
2 (f(x_0) - f*)). Written as LEFT - RIGHT = sum_i c_i |v_i|^2 + a F (v_i rows of the
basis, at most four squared terms), each relation is a row of the PEP after the class
inequalities, X = (v_1, ..., v_4), Qc = diag(c_i), with its values a (``extra_values``):

    ">=": X' Qc X + a F >= 0,   "<=": -(X' Qc X + a F) >= 0,   "==": both,

each with a multiplier >= 0 (an equality's free-sign multiplier is the difference of its
two); a side may have a constant term c, which makes the row X' Qc X + a F + c >= 0 with
c >= 0 (the PEP is then inhomogeneous: the bound is proven as t + sum_c mu_c c, t >= 0 the
initial condition's multiplier); a point x_k makes one constraint per step k = 0..N
(labels ``constraint[i]k<k>``). The multipliers enter the dual certificate like an
interpolation pair's: S = tau I0 - M - sum_k lambda_k Q_k - sum_c mu_c X_c' Qc_c X_c,
c_F = tau i_F - m_F - sum lambda_k a_k - sum_c mu_c a_c
(:func:`sosalgo.worstcase.sdp.pep_data`, the exact proof
:func:`sosalgo.worstcase.exact.prove_at`). No witness is built for a constrained PEP, and the
witness check refuses one (it would have to prove the constraints too).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sosalgo.errors import InputError

__all__ = ["MAX_SQUARES", "constraint_rows", "spec_constraints"]

MAX_SQUARES = 4  # squared terms per constraint (the rows X of a PEP row)


def spec_constraints(spec: Any, p: int) -> list[tuple[str, list[Any]]]:
    """The spec's ``pep.constraints``, parsed (an InputError naming the file and the
    entry)."""
    from sosalgo.worstcase.terms import parse_constraint

    names = frozenset(getattr(spec, "parameters", None) or ())
    out = []
    for i, text in enumerate((getattr(spec, "pep", None) or {}).get("constraints") or ()):
        try:
            out.append(parse_constraint(text, f"pep.constraints[{i}]", p, names))
        except InputError as exc:
            raise InputError(f"{spec.source}: {exc}") from None
    return out


def constraint_rows(mt: Any, steps: int, point_row: Any, grad_row: Any, value_at: Any,
                    state: dict[str, Any]) -> None:
    """Append each constraint's rows to ``state["extras"]``, their values (F index ->
    coefficient) to ``state["extra_values"]`` and their constants to
    ``state["extra_consts"]`` (by extras index); a constraint at x_k, one per step.
    ``point_row(q, opt)``: the row of a term's point; ``grad_row(row, key, opt)``: the
    gradient's row there; ``value_at(row, key, opt)``: {F index: s} of f there."""
    from sosalgo.worstcase.terms import every_step

    for i, (rel, terms) in enumerate(mt.constraints):
        for tag, at_k in every_step(list(terms), steps):
            _constraint_rows(mt, steps, f"constraint[{i}]{tag}", f"pep.constraints[{i}]", rel,
                             at_k, point_row, grad_row, value_at, state)


def _constraint_rows(mt: Any, steps: int, label: str, opt: str, rel: str, terms: list[Any],
                     point_row: Any, grad_row: Any, value_at: Any,
                     state: dict[str, Any]) -> None:
    """The rows of one constraint: X' Qc X + a F + c >= 0 for each sign of ``rel``; c >= 0
    (the relation holds at 0: G = 0, F = 0)."""
    from sosalgo.worstcase.terms import CONST_KIND, DIFF_KIND, at_steps

    vecs, coefs, values, const = [], [], {}, 0
    for t in at_steps(list(terms), steps, opt):
        c = mt.coef(t)
        if t.kind == CONST_KIND:
            const = const + c
            continue
        rows = [point_row(q, opt) for q in t.point.split("__")]
        if t.kind == "f":
            for k, v in value_at(rows[0], t.point, opt).items():
                values[k] = values.get(k, 0) + c * v
            continue
        vecs.append(rows[0] - rows[1] if t.kind == DIFF_KIND else rows[0] if
                    t.kind == "dist" else grad_row(rows[0], t.point, opt))
        coefs.append(c)
    if len(vecs) > MAX_SQUARES:
        raise InputError(f"{opt}: at most {MAX_SQUARES} squared terms (dist, grad) in "
                         "one constraint")
    zero = state["eye"][0] * 0
    X = np.vstack(vecs + [zero] * (MAX_SQUARES - len(vecs)))
    signs = {"==": (1, -1), ">=": (1,), "<=": (-1,)}[rel]
    if not mt.exact and any(float(const) * sg < 0 for sg in signs):
        raise InputError(f"{opt}: its constant side must hold at 0 (terms <= a constant "
                         ">= 0, or >= a constant <= 0; an equality has no constant)")
    for sg in signs:
        Qc = np.zeros((MAX_SQUARES, MAX_SQUARES), dtype=object if mt.exact else float)
        for r, c in enumerate(coefs):
            Qc[r, r] = c * sg
        tag = "" if len(signs) == 1 else ("+" if sg > 0 else "-")
        state["extra_values"][len(state["extras"])] = {k: v * sg
                                                       for k, v in values.items()}
        if bool(const.c != 0 or const.r != 0) if hasattr(const, "c") else const != 0:
            state["extra_consts"][len(state["extras"])] = const * sg
        state["extras"].append((f"{label}{tag}", X, Qc))
