"""Polishing a float dual certificate of the PEP before its exact proof.

An interior-point answer (tau, lambda) is accurate to the solver's tolerance (about 1e-8
relative): its S = tau I0 - M - sum lambda_k Q_k has eigenvalues of about -1e-8 |S| on
the directions the worst case uses, and a proof has to pay for them (a margin, or a mix
with an interior certificate, costs tau about that error times tr H). At the optimum S
has low rank s and c_F vanishes where the worst case's values are positive, so the
answer is refined by Gauss-Newton on the square system

    S(tau, lambda) = U U',   c_F(tau, lambda)_i = 0 (tight i),

unknowns tau, the multipliers of the pairs the answer uses and U (d x s), from the
answer's own (tau, lambda) and the top s eigenvectors of S. Its solution has the other
d - s eigenvalues of S zero to double precision, so the mix with an interior
certificate (or the margin) that makes S positive definite costs tau about 1e-16 |S|
tr H instead of 1e-8. The result is only a candidate: the exact proof checks S ⪰ 0,
lambda >= 0 and c_F >= 0 in rational and ball arithmetic as for any other candidate,
and a polish that does not converge (or makes a multiplier negative) is dropped.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sosalgo.kernel.conic import svec, svec_index
from sosalgo.pep.sdp import PEPData, SDPAnswer, residual, value_residual

__all__ = ["polished"]

SUPPORT = 1e-7  # a multiplier below this times the largest (in S's units) is dropped
RANKS = (1e-5, 1e-3)  # S's rank: its eigenvalues above this times the largest
TIGHT = 1e-6  # c_F_i below this times |S| is made exactly 0 (the worst case's F_i > 0)
ITERATIONS = 8
MAX_ENTRIES = 10_000_000  # a Jacobian with more entries is not formed (80 MB): not polished
CHUNK = 256  # pairs per dense block of Q_k


def polished(data: PEPData, ans: SDPAnswer) -> SDPAnswer | None:
    """``ans`` with (tau, lambda, S) refined as in the module, or None when no rank of
    :data:`RANKS` converges to a residual below the answer's own."""
    if ans.lam is None or ans.S is None or ans.tau is None or np.any(data.consts()):
        return None
    w = data.w
    Sh = ans.S * np.outer(w, w)
    top = float(np.abs(Sh).max())
    if not top > 0:
        return None
    lam = ans.lam
    weight = np.zeros_like(lam)
    used = np.flatnonzero(lam > 0)
    for at in range(0, len(used), CHUNK):  # lambda_k times its largest entry of Q_k on H
        idx = used[at:at + CHUNK]
        weight[idx] = lam[idx] * np.abs(data.q(idx, scaled=True)).max(axis=(1, 2))
    supp = np.flatnonzero(weight > SUPPORT * max(float(weight.max(initial=0.0)), 1e-300))
    cF = value_residual(data, float(ans.tau), lam) * data.v
    tight = np.flatnonzero(np.abs(cF) < TIGHT * top)
    if data.st.free_values:
        tight = np.arange(data.st.nF)
    start = _residual_norm(data, float(ans.tau), lam, None, tight, top)
    best = None
    for rank_tol in RANKS:
        got = _newton(data, ans, supp, tight, rank_tol, top)
        if got is not None and (best is None or got[2] < best[2]):
            best = got
    if best is None or not best[2] < start:
        return None
    tau, new, _ = best
    S = residual(data, tau, new)
    return replace(ans, tau=tau, lam=new, S=S, primal=tau, const=0.0)


def _residual_norm(data: PEPData, tau: float, lam: np.ndarray, U: np.ndarray | None,
                   tight: np.ndarray, top: float) -> float:
    """max |S - U U'| (scaled; U None: the negative part of S) and max |c_F| on ``tight``,
    relative to |S|."""
    w = data.w
    Sh = residual(data, tau, lam) * np.outer(w, w)
    if U is None:
        ev = np.linalg.eigvalsh(Sh)
        off = float(-ev.min(initial=0.0))
    else:
        off = float(np.abs(Sh - U @ U.T).max())
    cF = value_residual(data, tau, lam) * data.v
    return max(off, float(np.abs(cF[tight]).max(initial=0.0))) / top


def _newton(data: PEPData, ans: SDPAnswer, supp: np.ndarray, tight: np.ndarray,
            rank_tol: float, top: float) -> tuple[float, np.ndarray, float] | None:
    """(tau, lambda, relative residual) of Gauss-Newton on the module's system with
    S's rank from ``rank_tol``; None when it does not converge or a multiplier of the
    support turns negative."""
    d, w = data.st.d, data.w
    ev, vec = np.linalg.eigh(ans.S * np.outer(w, w))  # type: ignore[operator]
    keep = ev > rank_tol * ev.max()
    s = int(keep.sum())
    nsv = d * (d + 1) // 2
    if not 0 < s < d or (nsv + len(tight)) * (1 + len(supp) + d * s) > MAX_ENTRIES:
        return None
    U = vec[:, keep] * np.sqrt(ev[keep])
    tau = float(ans.tau)  # type: ignore[arg-type]
    lam = np.zeros_like(ans.lam)
    lam[supp] = ans.lam[supp]  # type: ignore[index]
    Qh = data.q(supp, scaled=True)
    I0h = data.st.init_q.astype(float) * np.outer(w, w)
    aT = data.a[supp][:, tight] * data.v[tight]  # (len supp, len tight)
    iF = data.st.init_f.astype(float)[tight] * data.v[tight]
    cols = np.concatenate([svec(I0h)[None], -svec(Qh)])  # tau, then lambda
    fcols = np.concatenate([iF[None], -aT])
    ucols = _outer_columns(U, d)
    J = np.zeros((nsv + len(tight), 1 + len(supp) + d * s))
    J[:nsv, :1 + len(supp)] = cols.T
    J[nsv:, :1 + len(supp)] = fcols.T
    J[:nsv, 1 + len(supp):] = -ucols.T
    res, kept = np.inf, (tau, lam.copy())
    for _ in range(ITERATIONS):
        Sh = residual(data, tau, lam) * np.outer(w, w)
        cF = value_residual(data, tau, lam) * data.v
        r = np.concatenate([svec(Sh - U @ U.T), cF[tight]]) / top
        new_res = float(np.abs(r).max())
        if not new_res < 0.5 * res:
            break
        res, kept = new_res, (tau, lam.copy())
        if res < 1e-15:
            break
        J[:nsv, 1 + len(supp):] = -_outer_columns(U, d).T
        norm = np.linalg.norm(J, axis=0)
        norm[norm == 0] = 1.0
        step = np.linalg.lstsq(J / norm, -r * top, rcond=None)[0] / norm
        tau += float(step[0])
        lam[supp] += step[1:1 + len(supp)]
        U = U + step[1 + len(supp):].reshape(d, s)
    tau, lam = kept
    if np.any(lam[supp] <= 0) or not np.isfinite(res):
        return None
    return tau, lam, _residual_norm(data, tau, lam, None, tight, top)


def _outer_columns(U: np.ndarray, d: int) -> np.ndarray:
    """svec of d(U U')/dU_ij = e_i u_j' + u_j e_i', one row per (i, j) (row-major, as
    U.reshape)."""
    s = U.shape[1]
    r, c, scale = svec_index(d)
    out = np.zeros((d * s, len(r)))
    for i in range(d):  # the entries (i, c) and (r, i) of the upper triangle
        out[i * s:(i + 1) * s] = ((r == i) * U[c].T + (c == i) * U[r].T) * scale
    return out
