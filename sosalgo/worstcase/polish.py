"""Polishing a float dual certificate of the PEP before its exact proof.

An interior-point answer (tau, lambda) is accurate to the solver's tolerance (about 1e-8
relative): its S = tau I0 - M - sum lambda_k Q_k has eigenvalues of about -1e-8 |S| on
the directions the worst case uses, and a proof has to pay for them (a margin, or a mix
with an interior certificate, costs tau about that error times tr H). At the optimum S
has low rank s and c_F vanishes where the worst case's values are positive, so the
answer is refined by Gauss-Newton on the square system

    S(tau, lambda) = U U',   c_F(tau, lambda)_i = 0 (tight i),

unknowns the multipliers of the pairs the answer uses and U (d x s), from the answer's
own lambda and the top s eigenvectors of S (s at the largest gap of S's spectrum); when
S's null space is the smaller (r = d - s < s), the same system as S(tau, lambda) V = 0
with V (d x r) the null space (its gauge fixed by V0' V = I). tau is first held at the
answer's reported value (a proof never goes below it, and a system with many more
unknowns than equations, such as gradient descent's S of rank d - 1, would otherwise
drift along its solutions), then left free. The solution has the other eigenvalues of S
zero to double precision, so the mix with an interior
certificate (or the margin) that makes S positive definite costs tau about 1e-16 |S|
tr H instead of 1e-8. The result is only a candidate: the exact proof checks S ⪰ 0,
lambda >= 0 and c_F >= 0 in rational and ball arithmetic as for any other candidate,
and a polish that does not converge (or makes a multiplier negative) is dropped.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sosalgo.kernel.conic import svec, svec_index
from sosalgo.worstcase.sdp import PEPData, SDPAnswer, residual, value_residual

__all__ = ["polished"]

SUPPORT = 1e-7  # a multiplier below this times the largest (in S's units) is dropped
TIGHT = 1e-6  # c_F_i below this times |S| is made exactly 0 (the worst case's F_i > 0)
ITERATIONS = 12
CONVERGED = 1e-13  # the system's residual, relative to |S|: the iterations stop there
ACCEPTED = 1e-10  # a polished answer's residual at most this (the solver's is about 1e-8;
# OGM at N = 50 stalls near 1e-12, the mix with an interior certificate covers the rest)
MAX_ENTRIES = 3_000_000  # a Jacobian with more entries is not formed (24 MB): not polished
CHUNK = 256  # pairs per dense block of Q_k


def polished(data: PEPData, ans: SDPAnswer, tau: float | None = None) -> SDPAnswer | None:
    """``ans`` with (tau, lambda, S) refined as in the module (``tau``: the value to hold
    first, the answer's own by default), or None when the refinement does not converge."""
    if ans.lam is None or ans.S is None or ans.tau is None or np.any(data.consts()):
        return None
    w = data.w
    Sh = ans.S * np.outer(w, w)
    top = float(np.abs(Sh).max())
    if not top > 0:
        return None
    supp = _support(data, ans.lam)
    cF = value_residual(data, float(ans.tau), ans.lam) * data.v
    tight = np.arange(data.st.nF) if data.st.free_values else \
        np.flatnonzero(np.abs(cF) < TIGHT * top)
    ev, vec = np.linalg.eigh(Sh)
    s = _rank(ev)
    d = data.st.d
    if not 0 < s < d:
        return None
    sys_ = _System(data, supp, tight, top, vec[:, ev.argsort()[::-1][:s]] * np.sqrt(
        np.sort(ev)[::-1][:s]) if s <= d - s else vec[:, ev.argsort()[:d - s]], s <= d - s)
    if sys_.entries() > MAX_ENTRIES:
        return None
    held = float(ans.tau) if tau is None else tau
    for fixed in (True, False):
        got = sys_.solve(held, ans.lam, fixed)
        if got is not None:
            t, lam = got
            return replace(ans, tau=t, lam=lam, S=residual(data, t, lam), primal=t,
                           const=0.0)
    return None


def _support(data: PEPData, lam: np.ndarray) -> np.ndarray:
    """The pairs whose lambda_k times its largest entry of Q_k (on H) is at least
    SUPPORT times the largest such product."""
    weight = np.zeros_like(lam)
    used = np.flatnonzero(lam > 0)
    for at in range(0, len(used), CHUNK):
        idx = used[at:at + CHUNK]
        weight[idx] = lam[idx] * np.abs(data.q(idx, scaled=True)).max(axis=(1, 2))
    return np.flatnonzero(weight > SUPPORT * max(float(weight.max(initial=0.0)), 1e-300))


def _rank(ev: np.ndarray) -> int:
    """S's numerical rank: the count above the largest ratio between consecutive
    eigenvalues (those below 1e-16 of the largest counted as that)."""
    top = float(ev.max(initial=0.0))
    if not top > 0:
        return 0
    e = np.maximum(np.sort(ev)[::-1], 1e-16 * top)
    return int(np.argmax(e[:-1] / e[1:])) + 1 if len(e) > 1 else 1


class _System:
    """The module's system on the pairs ``supp``: U U' form (``outer``, B = U, d x s) or
    null-space form (B = V, d x r)."""

    def __init__(self, data: PEPData, supp: np.ndarray, tight: np.ndarray, top: float,
                 B: np.ndarray, outer: bool) -> None:
        self.data, self.supp, self.tight, self.top = data, supp, tight, top
        self.B0, self.outer = B, outer
        w = data.w
        self.ww = np.outer(w, w)
        self.Qh = data.q(supp, scaled=True)
        self.I0h = data.st.init_q.astype(float) * self.ww
        self.fcols = np.concatenate([  # c_F's rows: tau, then lambda
            (data.st.init_f.astype(float)[tight] * data.v[tight])[None],
            -(data.a[supp][:, tight] * data.v[tight])])

    def entries(self) -> int:
        d, b = self.B0.shape
        rows = (d * (d + 1) // 2 if self.outer else d * b + b * b) + len(self.tight)
        return rows * (1 + len(self.supp) + d * b)

    def residual(self, tau: float, lam: np.ndarray, B: np.ndarray) -> np.ndarray:
        data = self.data
        Sh = residual(data, tau, lam) * self.ww
        cF = (value_residual(data, tau, lam) * data.v)[self.tight]
        if self.outer:
            body = svec(Sh - B @ B.T)
        else:
            body = np.concatenate([(Sh @ B).ravel(), self.top * (  # the gauge, unitless
                self.B0.T @ B - np.eye(B.shape[1])).ravel()])
        return np.concatenate([body, cF]) / self.top

    def jacobian(self, tau: float, lam: np.ndarray, B: np.ndarray) -> np.ndarray:
        d, b = B.shape
        if self.outer:
            coef = np.concatenate([svec(self.I0h)[None], -svec(self.Qh)]).T
            dB = -_outer_columns(B, d).T
        else:
            Sh = residual(self.data, tau, lam) * self.ww
            coef = np.concatenate([(self.I0h @ B).ravel()[None],
                                   -(self.Qh @ B).reshape(len(self.supp), -1)]).T
            coef = np.vstack([coef, np.zeros((b * b, coef.shape[1]))])
            dB = np.vstack([np.kron(Sh, np.eye(b)), self.top * np.kron(self.B0.T, np.eye(b))])
        top = np.hstack([coef, dB])
        fl = np.hstack([self.fcols.T, np.zeros((len(self.tight), d * b))])
        return np.vstack([top, fl]) / self.top

    def solve(self, tau: float, lam0: np.ndarray, fixed: bool
              ) -> tuple[float, np.ndarray] | None:
        """Gauss-Newton from (tau, lam0 on the support, B0) until the residual is below
        CONVERGED or stalls; (tau, lambda) when it ends below ACCEPTED with every
        multiplier of the support positive."""
        lam = np.zeros_like(lam0)
        lam[self.supp] = lam0[self.supp]
        B, m = self.B0.copy(), len(self.supp)
        last, slow = np.inf, 0
        for _ in range(ITERATIONS):
            r = self.residual(tau, lam, B)
            now = float(np.abs(r).max())
            slow = slow + 1 if now > 0.5 * last else 0
            if now < CONVERGED or slow >= 2:  # converged, or not converging
                break
            last = now
            J = self.jacobian(tau, lam, B)
            if fixed:  # tau held: its column out
                J = J[:, 1:]
            # the multipliers' columns in relative units (a small one changes little and
            # stays positive), the others normalized
            norm = np.linalg.norm(self.jacobian(tau, lam, B) if fixed else J, axis=0)
            norm[norm == 0] = 1.0
            unit = 1.0 / norm
            unit[1:1 + m] = lam[self.supp]
            if fixed:
                unit = unit[1:]
            step = np.linalg.lstsq(J * unit, -r, rcond=None)[0] * unit
            if fixed:
                step = np.concatenate([[0.0], step])
            tau += float(step[0])
            lam[self.supp] += step[1:1 + m]
            B = B + step[1 + m:].reshape(B.shape)
        r = self.residual(tau, lam, B)
        if not float(np.abs(r).max()) < ACCEPTED or np.any(lam[self.supp] <= 0):
            return None
        return tau, lam


def _outer_columns(U: np.ndarray, d: int) -> np.ndarray:
    """svec of d(U U')/dU_ij = e_i u_j' + u_j e_i', one row per (i, j) (row-major, as
    U.reshape)."""
    s = U.shape[1]
    r, c, scale = svec_index(d)
    out = np.zeros((d * s, len(r)))
    for i in range(d):  # the entries (i, c) and (r, i) of the upper triangle
        out[i * s:(i + 1) * s] = ((r == i) * U[c].T + (c == i) * U[r].T) * scale
    return out
