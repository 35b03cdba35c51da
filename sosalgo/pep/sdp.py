"""The PEP SDP in Clarabel's conic form, and its dual certificate.

Primal (x = (svec G, F)): maximize <M, G> + m_F F subject to <I0, G> + i_F F <= 1 (dual
tau), alpha_k (F_a - F_b) + <Q_k, G> >= 0 (dual lambda_k, each row scaled by its largest
coefficient sigma_k), F >= 0 (dual c_F), G ⪰ 0 (dual S). Weak duality: for tau, lambda >= 0,

    S = tau I0 - M - sum_k lambda_k Q_k ⪰ 0,   c_F = tau i_F - m_F - sum_k lambda_k a_k >= 0

imply measure <= tau on every feasible (G, F), hence on every function of the classes.
``margin`` solves the primal with objective M + eps I, m_F + eps: its dual has
S ⪰ eps I and c_F >= eps, a certificate that survives rounding (tau grows by eps times
the trace of the worst case, about eps relative).
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sps

from sosalgo.pep.structure import Method, PEPStructure
from sosalgo.solvers import SolverStatus, solver_status

__all__ = ["PEPData", "SDPAnswer", "pep_data", "solve_pep", "svec_index"]

SQRT2 = math.sqrt(2.0)


@functools.cache
def svec_index(d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, scale) of Clarabel's svec: upper triangle column by column."""
    r = np.array([i for j in range(d) for i in range(j + 1)], dtype=int)
    c = np.array([j for j in range(d) for i in range(j + 1)], dtype=int)
    return r, c, np.where(r == c, 1.0, SQRT2)


def svec(M: np.ndarray) -> np.ndarray:
    r, c, s = svec_index(M.shape[-1])
    return M[..., r, c] * s


def unsvec(v: np.ndarray, d: int) -> np.ndarray:
    r, c, s = svec_index(d)
    out = np.zeros((d, d))
    out[r, c] = v / s
    out[c, r] = v / s
    return out


@dataclass
class PEPData:
    """The float data: pair k is alpha_k (F_a - F_b) + tr(Qc_k X_k G X_k') >= 0, divided
    by sigma_k (its largest coefficient on (svec G, F)); ``active``: the pairs the next
    solve starts from (grown by :func:`solve_pep`, see the module)."""

    st: PEPStructure
    X: np.ndarray  # (K, 4, d): rows of (x_a, x_b, g_a, g_b) on the basis
    Qc: np.ndarray  # (K, 4, 4)
    a: np.ndarray  # (K, nF), scaled
    sigma: np.ndarray
    active: np.ndarray

    def q(self, idx: np.ndarray) -> np.ndarray:
        """The scaled Q_k = X_k' Qc_k X_k / sigma_k of the pairs ``idx`` (len, d, d)."""
        X = self.X[idx]
        Q = np.einsum("kai,kab,kbj->kij", X, self.Qc[idx], X, optimize=True)
        return 0.5 * (Q + Q.transpose(0, 2, 1)) / self.sigma[idx, None, None]

    def values(self, G: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Every scaled inequality at (G, F), without forming the Q_k."""
        XG = self.X @ G
        M = np.einsum("kui,kvi->kuv", XG, self.X)
        return np.einsum("kuv,kuv->k", self.Qc, M) / self.sigma + self.a @ F


CHUNK = 512


def pep_data(mt: Method, st: PEPStructure) -> PEPData:
    K, d = len(st.pairs), st.d
    X = np.zeros((K, 4, d))
    a = np.zeros((K, st.nF))
    Qc = np.zeros((K, 4, 4))
    for k in range(K):
        _, a[k], X[k] = st.pair_rows(mt, k)
        j, _, _, r = st.pairs[k]
        Qc[k] = mt.ineqs[j][r][1]
    sig = np.abs(a).max(axis=1, initial=0.0)
    for lo in range(0, K, CHUNK):  # the largest |Q_k| entry, a chunk at a time (memory)
        Xc = X[lo:lo + CHUNK]
        Q = np.einsum("kai,kab,kbj->kij", Xc, Qc[lo:lo + CHUNK], Xc, optimize=True)
        sig[lo:lo + CHUNK] = np.maximum(sig[lo:lo + CHUNK],
                                        np.abs(Q).reshape(len(Q), -1).max(axis=1, initial=0))
    sig[sig == 0] = 1.0
    return PEPData(st, X, Qc, a / sig[:, None], sig, seed_pairs(st))


def seed_pairs(st: PEPStructure) -> np.ndarray:
    """The pairs every solve starts with: those with x*, with an extra point (a term's),
    and between calls at most one step apart (the pairs of the known worst cases)."""
    keep = []
    for k, (j, a, b, _) in enumerate(st.pairs):
        ta, tb = st.points[j][a].t, st.points[j][b].t
        if ta is None or tb is None or abs(ta - tb) <= 1:
            keep.append(k)
    return np.array(keep, dtype=int)


@dataclass
class SDPAnswer:
    status: str  # solved | unbounded | infeasible | failed (and the raw status)
    raw: str
    primal: float | None = None
    dual: float | None = None
    G: np.ndarray | None = None
    F: np.ndarray | None = None
    tau: float | None = None
    lam: np.ndarray | None = None  # in the units of the unscaled inequalities
    S: np.ndarray | None = None


# tight tolerances; Clarabel's defaults; then a stronger static regularization, which
# solves the harder PEPs (long horizons, prox points) that end "almost solved" otherwise
ATTEMPTS = ((True, 1e-8), (False, 1e-8), (True, 1e-7), (False, 1e-7), (False, 1e-6))


@contextlib.contextmanager
def _quiet_stderr():
    """Clarabel's Rust panics (caught below) print to file descriptor 2: hide them."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


@functools.cache
def _settings(precise: bool, reg: float) -> Any:
    import clarabel

    s = clarabel.DefaultSettings()
    s.verbose = False
    s.max_iter = 400
    s.static_regularization_constant = reg
    s.direct_solve_method = "faer"  # supernodal LDL: 2-4x faster on these dense rows
    if precise:
        s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = 1e-10
        s.tol_ktratio = 1e-10
    return s


def solve_pep(data: PEPData, margin: float = 0.0, objective: str = "measure",
              floor: float | None = None, slack: float = 0.0,
              unit: float = 1.0) -> SDPAnswer:
    """One PEP solve by constraint generation (see the module). ``objective``: "measure"
    (the PEP; ``margin`` eps as in the module) or "trace" (minimize tr G with measure >=
    ``floor`` and every inequality >= ``slack``: the rank reduction of the witness). The
    measure is divided by ``unit`` for the solver (about tau: the margins and the
    solver's tolerances are then relative to tau); the answer is in the original units."""
    K = len(data.st.pairs)
    active = data.active
    while True:
        ans = _solve_active(data, active, margin, objective, floor, slack, unit)
        if len(active) == K or ans.status == "infeasible":  # a relaxation: so is the PEP
            break
        if ans.status != "solved":  # unbounded or failed on a relaxation: decide on all
            active = np.arange(K)
            continue
        assert ans.G is not None and ans.F is not None
        v = data.values(ans.G, ans.F)
        v[active] = np.inf
        scale = max(1.0, float(np.abs(ans.G).max()), float(np.abs(ans.F).max(initial=0.0)))
        bad = np.flatnonzero(v < (0.5 * slack if slack > 0 else -VIOLATION * scale))
        if not len(bad):
            break
        bad = bad[np.argsort(v[bad])][:max(len(active), MIN_ADD)]
        active = np.union1d(active, bad)
    data.active = active
    return ans


VIOLATION = 1e-9  # an omitted inequality below -VIOLATION * scale joins the solve
MIN_ADD = 64  # joins per round: at least this many, or as many as are active


def _solve_active(data: PEPData, active: np.ndarray, margin: float, objective: str,
                  floor: float | None, slack: float, unit: float) -> SDPAnswer:
    """The SDP on the pairs ``active`` (Clarabel; the attempts of :data:`ATTEMPTS`)."""
    import clarabel

    st = data.st
    d, nF, K = st.d, st.nF, len(active)
    nG = d * (d + 1) // 2
    meas = np.concatenate([svec(st.meas_q.astype(float)), st.meas_f.astype(float)]) / unit
    init = np.concatenate([svec(st.init_q.astype(float)), st.init_f.astype(float)])
    if objective == "measure":
        q = -(meas + np.concatenate([svec(np.eye(d)), np.ones(nF)]) * margin)
    else:
        q = np.concatenate([svec(np.eye(d)), np.zeros(nF)])
    rows = [sps.csr_matrix(init[None, :]),
            sps.csr_matrix(-np.hstack([svec(data.q(active)), data.a[active]])),
            sps.hstack([sps.csr_matrix((nF, nG)), -sps.identity(nF)])]
    b = [np.ones(1), np.full(K, -slack), np.zeros(nF)]
    if floor is not None:
        rows.append(sps.csr_matrix(-meas[None, :]))
        b.append(np.array([-floor / unit]))
    nn = sum(r.shape[0] for r in rows)
    rows.append(sps.hstack([-sps.identity(nG), sps.csr_matrix((nG, nF))]))
    b.append(np.zeros(nG))
    A = sps.csc_matrix(sps.vstack(rows))
    A.eliminate_zeros()
    cones = [clarabel.NonnegativeConeT(nn), clarabel.PSDTriangleConeT(d)]
    P = sps.csc_matrix((nG + nF, nG + nF))
    raw, st_ = "no attempt ended", SolverStatus.FAILED
    for precise, reg in ATTEMPTS:
        try:
            with _quiet_stderr():
                sol = clarabel.DefaultSolver(P, q, A, np.concatenate(b), cones,
                                             _settings(precise, reg)).solve()
        except BaseException as exc:  # Clarabel's Rust panics (an eigenvalue failure)
            if isinstance(exc, KeyboardInterrupt | SystemExit | MemoryError):
                raise
            continue
        raw = str(sol.status)
        st_ = solver_status(raw)
        if st_ == SolverStatus.SOLVED or raw == "DualInfeasible":
            break
    if raw == "DualInfeasible":
        return SDPAnswer("unbounded", raw)
    if st_ == SolverStatus.INFEASIBLE:
        return SDPAnswer("infeasible", raw)
    if st_ != SolverStatus.SOLVED:
        return SDPAnswer("failed", raw)
    x, z = np.array(sol.x), np.array(sol.z)
    lam = np.zeros(len(data.st.pairs))
    lam[active] = np.maximum(z[1:1 + K], 0.0) / data.sigma[active] * unit
    ans = SDPAnswer("solved", raw, -float(sol.obj_val) * unit, -float(sol.obj_val_dual) * unit,
                    unsvec(x[:nG], d), x[nG:], float(z[0]) * unit, lam)
    if objective == "measure":
        ans.S = residual(data, ans.tau, lam)
    return ans


def residual(data: PEPData, tau: float, lam: np.ndarray) -> np.ndarray:
    """S = tau I0 - M - sum lambda_k Q_k (unscaled multipliers)."""
    st = data.st
    idx = np.flatnonzero(lam)
    S = tau * st.init_q.astype(float) - st.meas_q.astype(float)
    return S - np.tensordot(lam[idx] * data.sigma[idx], data.q(idx), axes=1)


def value_residual(data: PEPData, tau: float, lam: np.ndarray) -> np.ndarray:
    """c_F = tau i_F - m_F - sum lambda_k a_k (must be >= 0)."""
    st = data.st
    return (tau * st.init_f.astype(float) - st.meas_f.astype(float)
            - (lam * data.sigma) @ data.a)
