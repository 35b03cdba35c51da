"""Exact (rational) verification of a Theorem 1 certificate.

A certificate (rho, P, lambda) from a floating-point solver is re-checked without floating
point in the proof path:

1. The method is made exact. kappa and m become rationals (the exact binary value of the
   floats, so kappa = 10.0 is 10), L = kappa m, and every parameter is evaluated from the
   spec's own expressions (eq. 10 templates, tied parameters followed) with sympy. Entries
   that are irrational (e.g. (sqrt(10) - 1)/(sqrt(10) + 1)) are enclosed in rational balls
   c ± r by mpmath's outward-rounding interval arithmetic (``mpmath.iv``), rounded outwards
   to ``digits`` decimals. ``theta`` overrides are the exact binary values of the floats.
2. P and lambda are rounded to rationals (limit_denominator, then the exact binary value,
   then P + eps I); rho to the smallest candidate rational >= rho, then a few slightly
   larger ones (the proven rate is never below the requested one).
3. M of eq. (15), M = M0 + rho^2 (N1 + N2) + (1 - rho^2)(N1 + N3) + lambda N4 with the
   blocks of eq. (14), is computed in exact midpoint-radius arithmetic: its centre Mc is
   the exact Theorem 1 matrix of the centre method, and |M - Mc| <= R entrywise for every
   method inside the enclosures. With ||M - Mc||_2 <= ||R||_F <= eta, proving
   -Mc - t I ⪰ 0 exactly for a rational t >= eta proves M ⪯ -(t - eta) I = -delta I.
4. PSD-ness of rational symmetric matrices is decided by an LDL^T factorization with
   rational pivots; a zero pivot (semidefinite case) falls back to principal minors
   (n <= 8) or to LDL^T with diagonal pivoting. P ⪰ 0, lambda >= 0, 0 < rho <= 1 and the
   fixed point of eq. (11) (u with (I - A)u = 0, Cu = 1, Eu = 1, exactly, with sympy) are
   checked too.

By Remark 1 the full method is A ⊗ I_d, ..., with P ⊗ I_d, and its inequality is
M ⊗ I_d ⪯ 0 up to a permutation, so the d = 1 proof covers every dimension d.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from sosalgo.exact_method import (
    ExactAlgorithm,
    exact_algorithm,
    exact_fixed_point,
    scaled_method,
    units_far_from_one,
)
from sosalgo.kernel.exact import (
    DEFAULT_DIGITS,
    DEFAULT_MAX_DEN,
    DEFAULT_RHO_STEPS,
    Ball,
    BallMatrix,
    Matrix,
    PSDProof,
    Verdict,
    float_str,
    fraction_str,
    frobenius_bound,
    is_exact,
    object_matrix,
    prove_psd,
    rational,
    rho_candidates,
    round_down,
    symmetrize_balls,
)
from sosalgo.model import bind, fixed_point
from sosalgo.spec.types import MATRIX_NAMES, Spec

__all__ = [
    "ExactResult",
    "ProofResult",
    "theorem1_exact",
    "verify_exact",
    "write_certificate",
]


# --------------------------------------------------------------------------- ball arithmetic


def _mm(X: BallMatrix, Y: BallMatrix) -> BallMatrix:
    inner = range(len(Y))
    return [
        [sum((X[i][k] * Y[k][j] for k in inner), Ball(0)) for j in range(len(Y[0]))]
        for i in range(len(X))
    ]


def _tr(X: BallMatrix) -> BallMatrix:
    return [list(col) for col in zip(*X, strict=True)]


def _quad(X: BallMatrix, Q: BallMatrix) -> BallMatrix:
    return _mm(_tr(X), _mm(Q, X))


def _lin(*terms: tuple[Ball | Fraction | int, BallMatrix]) -> BallMatrix:
    s = len(terms[0][1])
    return [
        [sum((Ball.of(c) * T[i][j] for c, T in terms), Ball(0)) for j in range(s)]
        for i in range(s)
    ]


def theorem1_balls(
    A: BallMatrix, B: BallMatrix, C: BallMatrix, E: BallMatrix,
    m: Fraction, L: Fraction, P: Matrix, rho2: Fraction, lam: Fraction,
) -> BallMatrix:
    """M of eq. (15) from the blocks of eq. (14), in midpoint-radius arithmetic.

    Written from the paper independently of :mod:`sosalgo.certificates.theorem1`.
    """
    n = len(A)
    z, one, half = Ball(0), Ball(1), Ball(Fraction(1, 2))
    Pb = [[Ball(v) for v in row] for row in P]
    S = [A[i] + [B[i][0]] for i in range(n)]  # [A B], n x (n+1)
    M0 = _quad(S, Pb)
    for i in range(n):
        for j in range(n):
            M0[i][j] = M0[i][j] - rho2 * Pb[i][j]
    EA = _mm(E, A)[0]
    EB = _mm(E, B)[0][0]
    last = [z] * n + [one]
    X1 = [[EA[j] - C[0][j] for j in range(n)] + [EB], last]
    X2 = [[C[0][j] - E[0][j] for j in range(n)] + [z], last]
    X3 = [C[0][:] + [z], last]
    mb, Lb = Ball(m), Ball(L)
    Q1 = [[Lb * half, half], [half, z]]
    Q2 = [[-mb * half, half], [half, z]]
    Q4 = [[Ball(-m * L / (m + L)), half], [half, Ball(-1 / (m + L))]]
    N1, N2, N3, N4 = _quad(X1, Q1), _quad(X2, Q2), _quad(X3, Q2), _quad(X3, Q4)
    M = _lin((1, M0), (rho2, N1), (rho2, N2), (1 - rho2, N1), (1 - rho2, N3), (lam, N4))
    return symmetrize_balls(object_matrix(M))  # exact centres: the larger radius of a pair


def theorem1_exact(
    A: Sequence[Sequence[Any]], B: Sequence[Sequence[Any]], C: Sequence[Sequence[Any]],
    E: Sequence[Sequence[Any]], m: Any, L: Any, P: Sequence[Sequence[Any]], rho: Any, lam: Any,
) -> Matrix:
    """Exact M of eq. (15) for rational data (numbers convertible by ``Fraction``)."""
    def balls(X: Sequence[Sequence[Any]]) -> BallMatrix:
        return [[Ball(Fraction(v)) for v in row] for row in X]

    r = Fraction(rho)
    M = theorem1_balls(
        balls(A), balls(B), balls(C), balls(E), Fraction(m), Fraction(L),
        [[Fraction(v) for v in row] for row in P], r * r, Fraction(lam),
    )
    return [[b.c for b in row] for row in M]


def _p_candidates(P: np.ndarray, max_den: int) -> list[tuple[str, Matrix]]:
    n = P.shape[0]
    Ps = 0.5 * (P + P.T)
    exact = [[Fraction(float(Ps[i, j])) for j in range(n)] for i in range(n)]
    lim = [[v.limit_denominator(max_den) for v in row] for row in exact]
    scale = max((abs(v) for row in exact for v in row), default=Fraction(0))
    eps = Fraction(1, 10**12) * max(scale, Fraction(1))
    eps = Fraction(eps).limit_denominator(max_den) or Fraction(1, max_den)
    shifted = [[lim[i][j] + (eps if i == j else 0) for j in range(n)] for i in range(n)]
    out = [(f"limit_denominator({max_den})", lim)]
    if exact != lim:
        out.append(("exact binary value", exact))
    out.append((f"limit_denominator({max_den}) + {fraction_str(eps)} I", shifted))
    return out


# --------------------------------------------------------------------------- result


@dataclass
class ProofResult:
    """What every exact check reports: the verdict and the rate it proves."""

    spec: str
    verified: Verdict
    rho_requested: float
    rho_proven: str | None = None
    rho_proven_float: float | None = None
    reason: str | None = None
    attempts: int = 0
    seconds: float = 0.0
    kappa: str = ""
    m: str = ""
    L: str = ""
    params: dict[str, str] = field(default_factory=dict)
    units: str | None = None  # SCALED_UNITS when the certificate is proven for f/L

    @property
    def ok(self) -> bool:
        return self.verified == Verdict.EXACT


# the units of a proof made for f/L after the proof as written failed (tiny or huge m, L:
# a certificate found in normalized units rounds to rationals badly when written back)
SCALED_UNITS = ("f/L in F(m/L, 1) (gradients u/L, the method with B L; L as recorded): the "
                "certificate is proven in these units, and the rate is the same for F(m, L)")


@dataclass
class ExactResult(ProofResult):
    """Outcome of :func:`verify_exact`; ``to_dict`` has everything needed to re-check."""

    rho_step: float | None = None  # relative increase of rho that was needed
    P_rational: list[list[str]] | None = None
    P_rounding: str | None = None
    lambda_rational: str | None = None
    delta: str | None = None  # proven margin: M ⪯ -delta I
    delta_float: float | None = None
    perturbation: str | None = None  # bound on ||M - M(centre)||_2 over the enclosures
    M_proof: str | None = None
    P_proof: str | None = None
    fixed_point: list[str] | None = None
    theta: dict[str, str] = field(default_factory=dict)
    matrices: dict[str, list[list[str]]] = field(default_factory=dict)
    enclosures: dict[str, list[list[list[str]]]] = field(default_factory=dict)
    model_max_abs_diff: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: the exact method, m, L, rho, P, lambda and the proof outcome."""
        return {
            "certificate": "Theorem 1 (eq. 15), reduced d = 1 templates (Remark 1)",
            "spec": self.spec,
            "verified": str(self.verified),
            "rho_requested": self.rho_requested,
            "rho_proven": self.rho_proven,
            "rho_proven_float": self.rho_proven_float,
            "rho_step": self.rho_step,
            "P": self.P_rational,
            "P_rounding": self.P_rounding,
            "lambda": self.lambda_rational,
            "delta": self.delta,
            "delta_float": self.delta_float,
            "perturbation": self.perturbation,
            "M_proof": self.M_proof,
            "P_proof": self.P_proof,
            "fixed_point_u": self.fixed_point,
            "reason": self.reason,
            "attempts": self.attempts,
            "seconds": self.seconds,
            "kappa": self.kappa,
            "m": self.m,
            "L": self.L,
            "params": dict(self.params),
            "theta": dict(self.theta),
            "matrices": {k: [list(r) for r in v] for k, v in self.matrices.items()},
            "enclosures": self.enclosures,
            "model_max_abs_diff": self.model_max_abs_diff,
        } | ({"units": self.units} if self.units else {})


def write_certificate(result: ProofResult | Mapping[str, Any], path: str | Path) -> Path:
    """Write ``result.to_dict()`` (or a certificate document) as JSON (exact strings: any
    CAS can re-check it). Atomic: the file is whole or untouched, never half-written."""
    p = Path(path)
    doc = result if isinstance(result, Mapping) else result.to_dict()
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(json.dumps(doc, indent=2) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    finally:
        tmp.unlink(missing_ok=True)
    return p


# --------------------------------------------------------------------------- verification


def _prove_M(
    ex: ExactAlgorithm, P: Matrix, rho: Fraction, lam: Fraction
) -> tuple[bool, dict[str, Any]]:
    """Try to prove M(rho, P, lambda) ⪯ -delta I for every method in the enclosures."""
    M = theorem1_balls(
        ex.balls["A"], ex.balls["B"], ex.balls["C"], ex.balls["E"], ex.m, ex.L, P,
        rho * rho, lam,
    )
    eta = frobenius_bound(M)
    Mc = [[b.c for b in row] for row in M]
    s = len(Mc)
    # a margin to aim for (heuristic only: the proof below is exact)
    try:
        est = float(np.linalg.eigvalsh(np.array([[float(v) for v in row] for row in Mc]))[-1])
    except (OverflowError, np.linalg.LinAlgError):
        est = math.nan
    targets: list[Fraction] = []
    if math.isfinite(est) and est < 0 and Fraction(f"{-est / 2:.3g}") > eta:
        targets.append(Fraction(f"{-est / 2:.3g}"))
    targets.append(eta)
    proof = None
    for t in targets:
        S = [[-Mc[i][j] - (t if i == j else 0) for j in range(s)] for i in range(s)]
        proof = prove_psd(S)
        if proof.psd:
            return True, {"t": t, "eta": eta, "proof": proof}
    # not proven: is M ⪯ 0 false for sure? -Mc + eta I not PSD implies it.
    S = [[-Mc[i][j] + (eta if i == j else 0) for j in range(s)] for i in range(s)]
    disproof = prove_psd(S)
    try:
        scale = max(float(abs(v)) for row in Mc for v in row)
    except OverflowError:
        scale = math.inf
    detail = proof.detail if proof is not None else ""
    return False, {"eta": eta, "detail": detail, "disproved": not disproof.psd, "est": est,
                   "scale": scale}


def verify_exact(
    spec: Spec,
    kappa: float,
    rho: float,
    P: Any,
    lam: float,
    theta: Mapping[str, float] | None = None,
    *,
    max_den: int = DEFAULT_MAX_DEN,
    rho_steps: Sequence[float] = DEFAULT_RHO_STEPS,
    digits: int = DEFAULT_DIGITS,
) -> ExactResult:
    """Prove in exact arithmetic that (rho, P, lambda) is a Theorem 1 certificate.

    Checks P ⪰ 0, lambda >= 0, 0 < rho <= 1, the fixed point of eq. (11) and M ⪯ 0 of
    eq. (15) for the exact method of ``spec`` at ``kappa`` (``theta`` overrides input
    parameters with the exact values of the floats). Float P, lambda are rounded to
    rationals (several roundings are tried); exact inputs (Fraction, int, "p/q") are used
    as given. The rational rho that is proven is >= ``rho``: the relative increases
    ``rho_steps`` are tried in order (``rho_steps=(0,)`` proves ``rho`` itself).
    """
    start = time.perf_counter()
    try:
        ex = exact_algorithm(spec, kappa, theta, digits)
    except ValueError as exc:
        return ExactResult(spec=spec.name, verified=Verdict.FAILED, rho_requested=float(rho),
                           reason=f"the exact method cannot be built: {exc}",
                           seconds=time.perf_counter() - start)
    result = _new_result(spec, ex, rho)
    reason = _check_method(spec, kappa, theta, ex, result)
    if reason is None:
        reason = _prove(ex, result, P, lam, rho, max_den, rho_steps)
        if reason is not None and units_far_from_one(ex) and _prove(
                scaled_method(ex, ex.L), result, _scaled_P(P, ex.L), lam, rho, max_den,
                rho_steps) is None:
            reason, result.units = None, SCALED_UNITS  # see scaled_method
    result.reason = reason
    result.seconds = time.perf_counter() - start
    return result


def _prove(ex: ExactAlgorithm, result: ExactResult, P: Any, lam: Any, rho: Any,
           max_den: int, rho_steps: Sequence[float]) -> str | None:
    """The proof of (rho, P, lambda) for ``ex`` recorded in ``result`` (None), or why not."""
    inputs = _rational_inputs(P, lam, rho, len(ex.balls["A"]), max_den)
    if isinstance(inputs, str):
        return inputs
    rho_q, lam_opts, p_cands = inputs
    P_opts, reason = _psd_roundings(p_cands)
    if P_opts:
        reason = _search_proof(ex, result, rho_q, P_opts, lam_opts,
                               rho_candidates(rho_q, list(rho_steps), max_den))
    return reason


def _scaled_P(P: Any, s: Fraction) -> Any:
    """P for f/s: V/s = xi'(P/s)xi (lambda is the same: every term of M scales by 1/s);
    floats stay floats (candidates to round), exact entries exact; P itself when it
    cannot be divided (the proof then says why)."""
    try:
        raw = np.atleast_2d(np.asarray(P, dtype=object))
        if all(is_exact(v) for v in raw.flat):
            return [[fraction_str(rational(v) / s) for v in row] for row in raw]
        return raw.astype(float) / float(s)
    except (ArithmeticError, TypeError, ValueError):
        return P


def _new_result(spec: Spec, ex: ExactAlgorithm, rho: float) -> ExactResult:
    """A failed result that records the exact method (filled in as the proof proceeds)."""
    return ExactResult(
        spec=spec.name, verified=Verdict.FAILED, rho_requested=float(rho),
        kappa=fraction_str(ex.kappa), m=fraction_str(ex.m), L=fraction_str(ex.L),
        params={k: str(v) for k, v in ex.params.items()},
        theta={k: fraction_str(v) for k, v in ex.theta.items()},
        matrices={k: [[str(v) for v in mat.row(i)] for i in range(mat.shape[0])]
                  for k, mat in ex.matrices.items()},
        enclosures=ex.enclosures(),
    )


def _check_method(spec: Spec, kappa: float, theta: Mapping[str, float] | None,
                  ex: ExactAlgorithm, result: ExactResult) -> str | None:
    """The exact method agrees with the float model and has the fixed point of eq. (11);
    the reason when not."""
    try:
        alg = bind(spec, float(kappa), theta)
    except ValueError as exc:
        return f"the method cannot be evaluated: {exc}"
    diff = max(
        float(np.max(np.abs(np.array(getattr(alg, k), float)
                            - np.array([[float(b.c) for b in row] for row in ex.balls[k]]))))
        for k in MATRIX_NAMES
    )
    result.model_max_abs_diff = diff
    if not diff <= 1e-9 * (1 + max(float(np.max(np.abs(getattr(alg, k)))) for k in MATRIX_NAMES)):
        return f"exact matrices differ from sosalgo.model.bind by {diff:.3g}"
    u = exact_fixed_point(ex, fixed_point(alg))
    if u is None:
        return "fixed point of eq. (11) (u with (I - A)u = 0, Cu = 1, Eu = 1) not proven"
    result.fixed_point = [str(v) for v in u]
    return None


RationalInputs = tuple[Fraction, list[Fraction], list[tuple[str, Matrix]]]


def _rational_inputs(P: Any, lam: Any, rho: Any, n: int,
                     max_den: int) -> RationalInputs | str:
    """(rho, lambda candidates, (label, P) candidates) as rationals, or the reason the
    inputs cannot be used (shape, symmetry, finiteness, signs)."""
    P_raw = np.atleast_2d(np.asarray(P, dtype=object))
    if P_raw.shape != (n, n):
        return f"P has shape {P_raw.shape}, expected {(n, n)}"
    try:
        rho_q = rational(rho)
        if is_exact(lam):
            lam_opts = [rational(lam)]
        else:
            lam_exact = rational(float(lam))
            lam_q = lam_exact.limit_denominator(max_den)
            lam_opts = [lam_q] + ([lam_exact] if lam_exact != lam_q else [])
        if all(is_exact(v) for v in P_raw.flat):
            Pq = [[rational(P_raw[i, j]) for j in range(n)] for i in range(n)]
            if any(Pq[i][j] != Pq[j][i] for i in range(n) for j in range(i)):
                return "P is not symmetric"
            p_cands = [("as given (exact)", Pq)]
        else:
            P_float = P_raw.astype(float)
            if not np.all(np.isfinite(P_float)):
                return "P has entries that are not finite"
            if not np.array_equal(P_float, P_float.T):
                return "P is not symmetric (refused, never symmetrized)"
            p_cands = _p_candidates(P_float, max_den)
    except (ValueError, TypeError, OverflowError) as exc:
        return f"P, lambda and rho must be finite numbers: {exc}"
    if lam_opts[0] < 0:
        return f"lambda = {float(lam_opts[0]):.6g} < 0"
    if not 0 < rho_q <= 1:
        return f"rho = {float(rho_q)!r} is not in (0, 1] (Theorem 1)"
    return rho_q, lam_opts, p_cands


def _psd_roundings(p_cands: list[tuple[str, Matrix]]) -> tuple[list, str | None]:
    """The roundings of P proven ⪰ 0 (label, P, proof), and the first failure's reason."""
    P_opts = []
    first_p_reason = None
    for label, Pq in p_cands:
        pp = prove_psd(Pq)
        if pp.psd:
            P_opts.append((label, Pq, pp))
        elif first_p_reason is None:
            first_p_reason = f"P ⪰ 0 fails for P {label}: {pp.detail}"
    return P_opts, first_p_reason


def _search_proof(ex: ExactAlgorithm, result: ExactResult, rho_q: Fraction, P_opts: list,
                  lam_opts: list[Fraction], cands: list[Fraction]) -> str | None:
    """Try M ⪯ 0 for each rational rho (in order), rounding of P and lambda; record the
    first proof in ``result`` (None), else return the first failure's reason."""
    first_fail: str | None = None
    for rq in cands:
        for label, Pq, pp in P_opts:
            for lq in lam_opts:
                result.attempts += 1
                ok, info = _prove_M(ex, Pq, rq, lq)
                if ok:
                    _record_proof(result, info, rq, rho_q, label, Pq, pp, lq)
                    return None
                if first_fail is None:
                    verdict = (
                        "M ⪯ 0 is false (disproved exactly: -M(centre) + eta I is not PSD)"
                        if info["disproved"] else "M ⪯ 0 not proven"
                    )
                    first_fail = (
                        f"{verdict} at rho = {fraction_str(rq)} with P rounded by {label}; "
                        f"estimated max eig of M = {info['est']:.3g}; {info['detail']}"
                    )
                if info["disproved"] and info["est"] > 1e-6 * info["scale"]:
                    break  # clearly infeasible: other roundings of P, lambda cannot help
            else:
                continue
            break
    assert first_fail is not None
    return first_fail + f" (tried {len(cands)} rho values up to {float(cands[-1])!r})"


def _record_proof(result: ExactResult, info: dict[str, Any], rq: Fraction, rho_q: Fraction,
                  label: str, Pq: Matrix, pp: PSDProof, lq: Fraction) -> None:
    """Fill ``result`` with a proof of M(rq, Pq, lq) ⪯ -delta I and P ⪰ 0."""
    t, eta, proof = info["t"], info["eta"], info["proof"]
    result.verified = Verdict.EXACT
    result.rho_proven = fraction_str(rq)
    result.rho_proven_float = float(rq)
    result.rho_step = float(rq / rho_q - 1)
    result.P_rational = [[fraction_str(v) for v in row] for row in Pq]
    result.P_rounding = label
    result.lambda_rational = fraction_str(lq)
    margin = round_down(t - eta)
    result.delta = fraction_str(margin)
    result.delta_float = float(margin)
    result.perturbation = fraction_str(eta)
    result.M_proof = (f"-M(centre) - {float_str(t)} I ⪰ 0: {proof.kind} "
                      f"({proof.method})")
    result.P_proof = f"{pp.kind} ({pp.method})"
