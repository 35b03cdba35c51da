"""Re-proving an analysis row's ``rho_lower`` from its witness (``rho_lower_witness``
or ``cycle``), never from the row's own number.

* ``quadratic``: the witness names the curvatures q (exact rationals, each inside its
  function's curvature interval, proven from the class parameters' enclosures); the
  closed loop on (q/2)|x|² is rebuilt in ball arithmetic, restricted to the states the
  output reads, and the claimed rho_lower is proven to be below the modulus of some
  root of its characteristic polynomial (Schur–Cohn in balls) with the output observing
  it: no certificate can prove a rate below it.
* ``self-similar``: the trajectory is re-checked exactly (every interpolation
  inequality, :func:`sosalgo.witnesses.cycles.check_cycle`) and its factor s must be
  >= rho_lower^K.
* ``cycle``: rho_lower = 1, backed when the cycle re-checks exactly.
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from sosalgo.proofs.ledger import BACKED, CONTEXT, CONTRADICTED, UNSUPPORTED, frac

__all__ = ["check_rho_lower"]


def check_rho_lower(spec: Any, row: Mapping[str, Any]) -> tuple[str, str, Any]:
    """(status, reason, proven) of the row's ``rho_lower`` claim."""
    claimed = row.get("rho_lower")
    if claimed is None:
        return CONTEXT, "none", None
    c = frac(claimed)
    if c is None:
        return CONTRADICTED, "not a number", None
    if c <= 0:
        return BACKED, "a rate is never below 0", "0"
    kind, wit = row.get("rho_lower_kind"), row.get("rho_lower_witness")
    try:
        kappa, theta = float(row["kappa"]), row.get("theta") or None
        if kind == "cycle":
            return _cycle(spec, kappa, theta, row.get("cycle"), c)
        if not isinstance(wit, Mapping):
            return UNSUPPORTED, "no witness to re-prove it from", None
        if kind == "quadratic" and wit.get("kind") == "quadratic":
            return _quadratic(spec, kappa, theta, wit, c)
        if kind == "self-similar" and wit.get("kind") == "self-similar":
            return _self_similar(spec, kappa, theta, wit, c)
    except (KeyError, TypeError, ValueError, ZeroDivisionError, ArithmeticError) as exc:
        return CONTRADICTED, f"the witness does not re-check ({type(exc).__name__})", None
    return UNSUPPORTED, f"unknown witness kind {kind!r}", None


def _cycle(spec: Any, kappa: float, theta: Any, cyc: Any, c: Fraction) -> tuple:
    from sosalgo.witnesses.cycles import check_cycle

    if not isinstance(cyc, Mapping):
        return UNSUPPORTED, "rho_lower_kind cycle without a cycle", None
    ok, why = check_cycle(spec, kappa, cyc, theta)
    if not ok:
        return CONTRADICTED, f"the cycle does not re-check: {why}", None
    return (BACKED, "a cycle (no convergence): re-checked exactly", "1") if c <= 1 else \
        (CONTRADICTED, "above 1, what a cycle proves", "1")


def _quadratic(spec: Any, kappa: float, theta: Any, wit: Mapping[str, Any],
               c: Fraction) -> tuple:
    from sosalgo.witnesses.brackets import bracketed, quadratic_witness_fails

    curv = wit.get("curvatures")
    if not isinstance(curv, Mapping):
        return CONTRADICTED, "the witness names no curvatures", None
    why = quadratic_witness_fails(bracketed(spec, kappa, theta), curv, c)
    if why is not None:
        return CONTRADICTED, why, None
    return BACKED, ("re-proven: a mode of the loop on quadratics with these curvatures "
                    "is slower (Schur-Cohn in balls)"), str(c)


def _self_similar(spec: Any, kappa: float, theta: Any, wit: Mapping[str, Any],
                  c: Fraction) -> tuple:
    from sosalgo.witnesses.cycles import check_cycle

    traj = wit.get("trajectory")
    if not isinstance(traj, Mapping):
        return UNSUPPORTED, "no trajectory", None
    ok, why = check_cycle(spec, kappa, traj, theta)
    if not ok:
        return (UNSUPPORTED if "only exact" in why else CONTRADICTED,
                f"the trajectory does not re-check: {why}", None)
    s, K = Fraction(str(traj["factor"])), int(traj["length"])
    if s >= c ** K:
        return BACKED, "re-checked exactly: a self-similar trajectory with factor >= rho^K", \
            str(s)
    return CONTRADICTED, "the trajectory's factor is below rho_lower^K", str(s)
