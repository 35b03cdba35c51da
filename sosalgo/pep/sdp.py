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
    """The float data: every inequality as (Q_k on G, a_k on F) divided by sigma_k."""

    st: PEPStructure
    Q: np.ndarray  # (K, d, d)
    a: np.ndarray  # (K, nF)
    sigma: np.ndarray


def pep_data(mt: Method, st: PEPStructure) -> PEPData:
    K, d = len(st.pairs), st.d
    Xs = np.zeros((K, 4, d))
    a = np.zeros((K, st.nF))
    Qc = np.zeros((K, 4, 4))
    for k in range(K):
        _, a[k], Xs[k] = st.pair_rows(mt, k)
        j, _, _, r = st.pairs[k]
        Qc[k] = mt.ineqs[j][r][1]
    Q = np.einsum("kai,kab,kbj->kij", Xs, Qc, Xs, optimize=True)
    Q = 0.5 * (Q + Q.transpose(0, 2, 1))
    sig = np.maximum(np.abs(Q).reshape(K, -1).max(axis=1, initial=0.0),
                     np.abs(a).max(axis=1, initial=0.0))
    sig[sig == 0] = 1.0
    return PEPData(st, Q / sig[:, None, None], a / sig[:, None], sig)


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
    """One solve. ``objective``: "measure" (the PEP; ``margin`` eps as in the module) or
    "trace" (minimize tr G with measure >= ``floor`` and every inequality >= ``slack``:
    the rank reduction of the witness). The measure is divided by ``unit`` for the solver
    (about tau: the margins and the solver's tolerances are then relative to tau); the
    answer is in the original units."""
    import clarabel

    st = data.st
    d, nF, K = st.d, st.nF, len(st.pairs)
    nG = d * (d + 1) // 2
    meas = np.concatenate([svec(st.meas_q.astype(float)), st.meas_f.astype(float)]) / unit
    init = np.concatenate([svec(st.init_q.astype(float)), st.init_f.astype(float)])
    if objective == "measure":
        eps_g = np.concatenate([svec(np.eye(d)), np.ones(nF)]) * margin
        q = -(meas + eps_g)
    else:
        q = np.concatenate([svec(np.eye(d)), np.zeros(nF)])
    ineq = -np.hstack([svec(data.Q), data.a])
    rows = [init[None, :], ineq, np.hstack([np.zeros((nF, nG)), -np.eye(nF)])]
    b = [np.ones(1), np.full(K, -slack), np.zeros(nF)]
    if floor is not None:
        rows.append(-meas[None, :])
        b.append(np.array([-floor / unit]))
    nn = sum(r.shape[0] for r in rows)
    rows.append(np.hstack([-np.eye(nG), np.zeros((nG, nF))]))
    b.append(np.zeros(nG))
    A = sps.csc_matrix(np.vstack(rows))
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
    lam = np.maximum(z[1:1 + K], 0.0) / data.sigma * unit
    ans = SDPAnswer("solved", raw, -float(sol.obj_val) * unit, -float(sol.obj_val_dual) * unit,
                    unsvec(x[:nG], d), x[nG:], float(z[0]) * unit, lam)
    if objective == "measure":
        ans.S = residual(data, ans.tau, lam)
    return ans


def residual(data: PEPData, tau: float, lam: np.ndarray) -> np.ndarray:
    """S = tau I0 - M - sum lambda_k Q_k (unscaled multipliers)."""
    st = data.st
    w = lam * data.sigma
    S = tau * st.init_q.astype(float) - st.meas_q.astype(float)
    return S - np.tensordot(w, data.Q, axes=1)


def value_residual(data: PEPData, tau: float, lam: np.ndarray) -> np.ndarray:
    """c_F = tau i_F - m_F - sum lambda_k a_k (must be >= 0)."""
    st = data.st
    return (tau * st.init_f.astype(float) - st.meas_f.astype(float)
            - (lam * data.sigma) @ data.a)
