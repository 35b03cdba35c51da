"""The certified noise sensitivity of a bound method: one SDP, solved by Clarabel.

``noise_certificate(alg, lag)`` minimizes s over (P, p, s, c, eta, lambda) subject to the
parts of :func:`sosalgo.sensitivity.window.noise_parts` (decrease ⪯ 0, positivity ⪰ 0,
their function-value rows, eta, lambda >= 0), each strict by a small margin so that the
certificate survives rounding to rationals; gamma = sqrt(s) is then an upper bound on the
sensitivity over the whole class F(m, L) (docs/noise.md).

The problem is solved for f/L in F(m/L, 1) (same iterates; B scaled by L, noise by 1/L),
where the data are of order one; the certificate is returned in original units. A
solution counts only when Clarabel reports *solved* and the point passes a
floating-point check of every part (``check_kind`` "float"); the exact proof is
:func:`sosalgo.sensitivity.exact.verify_noise`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sps

from sosalgo.classes import SEED_CLASS
from sosalgo.sensitivity.quadratic import quadratic_gamma2
from sosalgo.sensitivity.window import (
    NoiseWindow,
    add_noise_terms,
    noise_parts,
    noise_window,
    past_noise,
    state_size,
)
from sosalgo.solvers import SolverStatus, clarabel_solve, finite_data, solver_status, svec

__all__ = ["NoiseCertificate", "noise_certificate", "noise_windows", "MARGINS", "MAX_LAG",
           "attempt", "layout", "original_units", "supply_scale", "float_check", "check_lag",
           "scaled_problem"]

MARGINS = (1e-8, 1e-7, 1e-6, 1e-5)  # strictness tried in turn (the SDP data are of order one)
MAX_LAG = 6
GAP_TOL = 1e-7


@dataclass
class NoiseCertificate:
    """A certified upper bound ``gamma`` on the noise sensitivity (None: none found)."""

    gamma: float | None
    lag: int
    status: str  # "certified", "infeasible" (no certificate of this lag) or "failed"
    check_kind: str  # "float" (solver solved + floating-point check) or "none"
    certificate: dict[str, Any] | None = None  # original units: P, p, s, c, multipliers
    checks: dict[str, float] = field(default_factory=dict)  # eigenvalues at the point
    seconds: float = 0.0
    detail: str = ""

    @property
    def certified(self) -> bool:
        return self.gamma is not None

    def to_dict(self) -> dict[str, Any]:
        cert = None if self.certificate is None else {
            k: (v.tolist() if isinstance(v, np.ndarray) else v)
            for k, v in self.certificate.items()}
        return {"gamma": self.gamma, "lag": self.lag, "status": self.status,
                "check_kind": self.check_kind, "certificate": cert, "checks": self.checks,
                "seconds": self.seconds, "detail": self.detail}


def noise_windows(A: Any, B: Any, C: Any, E: Any, alpha: Any, Q: Any, lag: int,
                  obj: bool = False) -> tuple[NoiseWindow, NoiseWindow]:
    """(decrease window, positivity window) of lag ``lag``."""
    return (noise_window(A, B, C, E, alpha, Q, lag, lag + 2, obj),
            noise_window(A, B, C, E, alpha, Q, lag, lag + 1, obj))


def layout(N: int, lag: int, dec: NoiseWindow, pos: NoiseWindow,
           limsup: bool = False) -> dict[str, slice]:
    """Slices of the variables (P's upper triangle, p, s, c, eta, lambda, and with
    ``limsup`` the past-noise terms r, sd (>= 0 like the multipliers), cp, cd)."""
    pp, pd = (past_noise(pos), past_noise(dec)) if limsup else ([], [])
    sizes = [("P", N * (N + 1) // 2), ("p", lag + 1), ("s", 1), ("c", len(dec.measurable)),
             ("eta", len(dec.labels)), ("lam", len(pos.labels)), ("r", len(pp)),
             ("sd", len(pd)), ("cp", sum(len(k) for _, k in pp)),
             ("cd", sum(len(k) for _, k in pd))]
    out, k = {}, 0
    for name, size in sizes:
        out[name] = slice(k, k + size)
        k += size
    return out


def _pair_quads(H: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    """H' S_ab H for the symmetric unit matrices S_ab (a <= b) of P's basis."""
    ia, ib = np.array(pairs).T
    prod = np.einsum("ki,kj->kij", H[ia], H[ib])
    return prod + np.where((ia != ib)[:, None, None], prod.transpose(0, 2, 1), 0.0)


def _decrease_maps(dec: NoiseWindow, lay: dict[str, slice], nvar: int,
                   pairs: list[tuple[int, int]], weight: float, rho2: float | None = None,
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(constant, per-variable matrices) of D and the function-value rows Df (x -> Df);
    with ``rho2`` the discounted form of :func:`noise_parts` (no constant)."""
    lag, w, W = dec.lag, dec.noise, dec.width
    r2 = 1.0 if rho2 is None else rho2
    Dl = np.zeros((nvar, W, W))
    Dl[lay["P"]] = _pair_quads(dec.H[lag + 1], pairs) - r2 * _pair_quads(dec.H[lag], pairs)
    Dl[lay["s"].start, w, w] = -1.0
    for k, col in enumerate(dec.measurable):
        Dl[lay["c"].start + k, w, col] = Dl[lay["c"].start + k, col, w] = -1.0
    Dl[lay["eta"]] = np.array(dec.Mq)
    _past_maps(Dl, dec, lay["sd"], lay["cd"], -1.0)
    rows = np.zeros((dec.steps, nvar))
    for j in range(lag + 1):  # p_j on f_{l+1-j} in V_{k+1}, on f_{l-j} in V_k
        rows[lag + 1 - j, lay["p"].start + j] += 1.0
        rows[lag - j, lay["p"].start + j] -= r2
    rows[:, lay["eta"]] = np.array(dec.mq).T
    const = weight * (dec.x_row.T @ dec.x_row)
    return (const if rho2 is None else 0.0 * const), Dl, rows


def _past_maps(maps: np.ndarray, win: NoiseWindow, rs: slice, cs: slice, sign: float) -> None:
    """The per-variable matrices of the past-noise terms (:func:`add_noise_terms`)."""
    for k in range(rs.start, rs.stop):
        add_noise_terms(maps[k], win, np.eye(rs.stop - rs.start)[k - rs.start],
                        np.zeros(cs.stop - cs.start), sign)
    for k in range(cs.start, cs.stop):
        add_noise_terms(maps[k], win, np.zeros(rs.stop - rs.start),
                        np.eye(cs.stop - cs.start)[k - cs.start], sign)


def _positivity_maps(pos: NoiseWindow, lay: dict[str, slice], nvar: int,
                     pairs: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Per-variable matrices of -Pq and the rows of -Pf (both must be <= 0)."""
    W, lag = pos.width, pos.lag
    Pl = np.zeros((nvar, W, W))
    Pl[lay["P"]] = -_pair_quads(pos.H[lag], pairs)
    Pl[lay["lam"]] = np.array(pos.Mq)
    _past_maps(Pl, pos, lay["r"], lay["cp"], -1.0)
    rows = np.zeros((pos.steps, nvar))
    for j in range(lag + 1):
        rows[lag - j, lay["p"].start + j] -= 1.0
    rows[:, lay["lam"]] = np.array(pos.mq).T
    return Pl, rows


def _conic(dec: NoiseWindow, pos: NoiseWindow, lay: dict[str, slice], nvar: int,
           N: int, margin: float, weight: float = 1.0, rho2: float | None = None,
           ) -> tuple[sps.csc_matrix, np.ndarray, list[tuple[str, int]]]:
    """Clarabel's A, b and cone list for: D ⪯ -margin I, Pq ⪰ margin I, Df <= -margin,
    Pf >= margin, eta, lambda >= 0, with the supply |x_k - x*|^2 weighted by ``weight``
    (in D, or with ``rho2`` in Pq: the discounted form of :func:`noise_parts`)."""
    pairs = [(i, j) for i in range(N) for j in range(i, N)]
    D0, Dl, dfr = _decrease_maps(dec, lay, nvar, pairs, weight, rho2)
    Pl, pfr = _positivity_maps(pos, lay, nvar, pairs)
    signed = list(range(lay["eta"].start, lay["sd"].stop))  # eta, lambda (and r, sd) >= 0
    signed += [lay["s"].start] if rho2 is not None else []  # so is s (E|w|^2 <= sigma^2 d)
    nmult = len(signed)
    mult = np.zeros((nmult, nvar))
    mult[np.arange(nmult), signed] = -1.0
    lin = np.vstack([dfr, pfr, mult])
    b_lin = np.concatenate([np.full(len(dfr) + len(pfr), -margin), np.zeros(nmult)])
    xx = weight * (pos.x_row.T @ pos.x_row)
    blocks = [(D0, Dl), (xx if rho2 is not None else np.zeros(Pl.shape[1:]), Pl)]
    A_rows = [lin] + [svec(Gl, True).T for _, Gl in blocks]
    b = [b_lin] + [svec(-G0 - margin * np.eye(G0.shape[0]), True) for G0, _ in blocks]
    cones = [("nonneg", len(lin))] + [("psd", G0.shape[0]) for G0, _ in blocks]
    return sps.csc_matrix(np.vstack(A_rows)), np.concatenate(b), cones


def _clarabel(A: sps.csc_matrix, b: np.ndarray, q: np.ndarray,
              cones: list[tuple[str, int]]) -> tuple[SolverStatus, np.ndarray | None, str]:
    import clarabel

    from sosalgo.solvers import quiet_settings

    settings = quiet_settings()
    settings.presolve_enable = False
    # optimality to 1e-7 is plenty (the bound is what the checked point gives, and these
    # degenerate problems often stop at "almost solved" under 1e-8); feasibility keeps
    # Clarabel's 1e-8, and the floating-point check decides anyway
    settings.tol_gap_abs = settings.tol_gap_rel = GAP_TOL
    kinds = [clarabel.NonnegativeConeT(k) if kind == "nonneg" else clarabel.PSDTriangleConeT(k)
             for kind, k in cones]
    nv = A.shape[1]
    P0 = sps.csc_matrix((nv, nv))
    try:
        sol = clarabel_solve(P0, q, A, b, kinds, settings)
    except Exception as exc:  # noqa: BLE001 - a crash is just "no answer"
        return SolverStatus.FAILED, None, f"exception: {type(exc).__name__}"
    st = solver_status(str(sol.status))
    return st, (np.array(sol.x) if st == SolverStatus.SOLVED else None), str(sol.status)


def _unpack(x: np.ndarray, lay: dict[str, slice], N: int) -> dict[str, Any]:
    P = np.zeros((N, N))
    order = [(i, j) for i in range(N) for j in range(i, N)]
    vals = x[lay["P"]]
    for k, (i, j) in enumerate(order):
        P[i, j] = P[j, i] = vals[k]
    return {"P": P, "p": x[lay["p"]].copy(), "s": float(x[lay["s"]][0]),
            "c": x[lay["c"]].copy(), "eta": np.maximum(x[lay["eta"]], 0.0),
            "lam": np.maximum(x[lay["lam"]], 0.0),
            **{k: np.maximum(x[lay[k]], 0.0) for k in ("r", "sd")},
            **{k: x[lay[k]].copy() for k in ("cp", "cd")}}


def float_check(dec: NoiseWindow, pos: NoiseWindow, parts: dict[str, Any],
                rho2: float | None = None) -> dict[str, float]:
    """Floating-point check of the four parts (largest violation of each, <= 0 passes)."""
    val = noise_parts(dec, pos, parts["P"], parts["p"], parts["s"], parts["c"], parts["eta"],
                      parts["lam"], rho2=rho2, past=parts)
    return {"max_eig_D": float(np.linalg.eigvalsh(val["D"])[-1]),
            "max_Df": float(np.max(val["Df"])),
            "min_eig_Pq": float(np.linalg.eigvalsh(val["Pq"])[0]),
            "min_Pf": float(np.min(val["Pf"]))}


def original_units(parts: dict[str, Any], n: int, lag: int, L: float, dec: NoiseWindow,
                   pos: NoiseWindow) -> dict[str, Any]:
    """From f/L in F(m/L, 1) (gradients and noise divided by L) back to F(m, L): with
    h~ = S h (S = 1 on xi, 1/L on g and w), P = S P~ S, p = p~/L, s = s~/L^2, the cross
    terms c by 1/L (xi columns) or 1/L^2, and every multiplier by 1/L^2."""
    scale = np.concatenate([np.ones(n), np.full(2 * lag + 1, 1.0 / L)])
    cscale = np.concatenate([np.ones(n), np.full(dec.width - n, 1.0 / L)])[dec.measurable]
    extra = {}
    for win, rk, ck in ((pos, "r", "cp"), (dec, "sd", "cd")) if len(parts.get("r", ())) else ():
        kscale = np.concatenate([np.ones(n), np.full(win.width - n, 1.0 / L)])
        known = [k for _, ks in past_noise(win) for k in ks]  # past noises: like s and c
        extra |= {rk: [float(v) / L**2 for v in parts[rk]],
                  ck: [float(v) * kscale[k] / L for v, k in zip(parts[ck], known, strict=True)]}
    return extra | {
        "lag": lag,
        "P": scale[:, None] * parts["P"] * scale[None, :],
        "p": [float(v) / L for v in parts["p"]],
        "s": parts["s"] / L**2,
        "c": [float(v) * k / L for v, k in zip(parts["c"], cscale, strict=True)],
        "multipliers": {
            "decrease": {k: float(v) / L**2 for k, v in zip(dec.labels, parts["eta"],
                                                             strict=True)},
            "positivity": {k: float(v) / L**2 for k, v in zip(pos.labels, parts["lam"],
                                                               strict=True)}},
    }


def supply_scale(alg: Any) -> float:
    """The normalized quadratic sensitivity (L gamma_q)^2 on a coarse grid of curvatures:
    the supply is divided by it so that the SDP's solution is of order one (inf when some
    quadratic of the class makes the method unstable: then nothing can be certified)."""
    qs = np.linspace(alg.m, alg.L, 41)
    g2 = quadratic_gamma2(*(np.asarray(M, dtype=float) for M in (alg.A, alg.B, alg.C, alg.E)),
                          qs)
    return float(np.max(g2)) * float(alg.L) ** 2


def attempt(dec: NoiseWindow, pos: NoiseWindow, lay: dict[str, slice], N: int,
            margin: float, weight: float, rho2: float | None = None,
            ) -> tuple[str, dict[str, Any] | None, dict[str, float], str]:
    """One solve at ``margin``: (status, parts scaled back by 1/weight, checks, detail);
    with ``rho2`` the discounted form (``noise_limsup`` at rho = sqrt(rho2))."""
    nvar = lay["cd"].stop
    A, b, cones = _conic(dec, pos, lay, nvar, N, margin, weight, rho2)
    q = np.zeros(nvar)  # minimize s, or (1 - rho^2) ((s + sum sd) / (1 - rho^2) + sum r)
    q[lay["s"]] = q[lay["sd"]] = 1.0
    q[lay["r"]] = 0.0 if rho2 is None else 1.0 - rho2
    if not finite_data(A, b):
        return "failed", None, {}, "non-finite problem data"
    st, x, raw = _clarabel(A, b, q, cones)
    if st != SolverStatus.SOLVED or x is None:
        return ("infeasible" if st == SolverStatus.INFEASIBLE else "failed"), None, {}, \
            f"clarabel: {raw}"
    parts = _unpack(x, lay, N)
    parts = {k: v / weight for k, v in parts.items()}  # the supply back to weight 1
    checks = float_check(dec, pos, parts, rho2)
    ok = all(math.isfinite(v) for v in checks.values()) and (
        checks["max_eig_D"] <= 0 and checks["max_Df"] <= 0 and checks["min_eig_Pq"] >= 0
        and checks["min_Pf"] >= 0 and (parts["s"] > 0 or rho2 is not None and parts["s"] >= 0))
    if not ok:
        return "failed", None, checks, f"clarabel: {raw}; floating-point check failed"
    return "certified", parts, checks, f"clarabel: {raw}, margin {margin:g}"


def check_lag(lag: Any) -> None:
    """ValueError unless ``lag`` is an integer in 0..MAX_LAG."""
    if isinstance(lag, bool) or not isinstance(lag, int) or not 0 <= lag <= MAX_LAG:
        raise ValueError(f"lag: must be an integer in 0..{MAX_LAG}")


def scaled_problem(alg: Any, lag: int, limsup: bool = False,
                   ) -> tuple[NoiseWindow, NoiseWindow, int, dict[str, slice]]:
    """(decrease window, positivity window, size of P, variable layout) of lag ``lag``
    for f/L in F(m/L, 1) (B scaled by L); ``limsup``: the layout of noise_limsup."""
    check_lag(lag)
    L = float(alg.L)
    ineq = SEED_CLASS.inequalities({"m": alg.m / L, "L": 1.0})[0]
    dec, pos = noise_windows(alg.A, alg.B * L, alg.C, alg.E, ineq.alpha, ineq.Q, lag)
    N = state_size(alg.n, lag)
    return dec, pos, N, layout(N, lag, dec, pos, limsup)


def noise_certificate(alg: Any, lag: int = 1,
                      margins: tuple[float, ...] = MARGINS) -> NoiseCertificate:
    """Certified sensitivity bound of ``alg`` (an :class:`~sosalgo.model.Algorithm`: one
    gradient call on F(m, L)) with lag ``lag``: gamma with
    sqrt(long-run mean of E|x_k - x*|^2 / d) / sigma <= gamma for every f in F(m, L).

    The SDP is solved at the strictness ``margins`` in turn (relative to data of order one)
    until a solution passes the floating-point check."""
    start = time.perf_counter()
    scale = supply_scale(alg)
    if not math.isfinite(scale) or scale <= 0:
        check_lag(lag)
        return NoiseCertificate(None, lag, "infeasible", "none",
                                detail="unstable on a quadratic of the class",
                                seconds=time.perf_counter() - start)
    L = float(alg.L)
    dec, pos, N, lay = scaled_problem(alg, lag)
    status, checks, detail = "failed", {}, ""
    for margin in margins:
        status, parts, checks, detail = attempt(dec, pos, lay, N, margin, 1.0 / scale)
        if parts is not None:
            cert = original_units(parts, alg.n, lag, L, dec, pos)
            return NoiseCertificate(math.sqrt(cert["s"]), lag, "certified", "float", cert,
                                    checks, time.perf_counter() - start, detail)
        if status == "infeasible":
            break
    return NoiseCertificate(None, lag, status, "none", None, checks,
                            time.perf_counter() - start, detail)
