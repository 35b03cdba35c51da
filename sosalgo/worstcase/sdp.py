"""The PEP SDP in Clarabel's conic form, and its dual certificate.

Primal (x = (svec G, F)): maximize <M, G> + m_F F subject to <I0, G> + i_F F <= 1 (dual
tau), alpha_k (F_a - F_b) + <Q_k, G> >= 0 (dual lambda_k, each row scaled by its largest
coefficient sigma_k), F >= 0 (dual c_F), G ⪰ 0 (dual S). Weak duality: for tau, lambda >= 0,

    S = tau I0 - M - sum_k lambda_k Q_k ⪰ 0,   c_F = tau i_F - m_F - sum_k lambda_k a_k >= 0

imply measure <= tau on every feasible (G, F), hence on every function of the classes
(a lambda that is 0 on some pairs is still a certificate).

The measure is solved in this dual form (variables tau, lambda; :func:`_solve_dual`), G
and F read back as the dual variables of S and c_F. The entries of S that no Q_k, I0 or
M touches are structurally zero, and with the basis of :mod:`sosalgo.worstcase.structure` the
pairs one step apart touch a band only: Clarabel's chordal decomposition then splits the
PSD cone into small blocks (gradient descent at N = 100: 4 solves, 0.6 s of solver time),
where the primal form's cone is on every entry of G (a dense KKT block of d^2/2 rows, a
cost like d^6). Pairs far apart, which accelerated methods need, fill the band in; the
cost then approaches the dense one. The trace objective of the witness (a floor on the
measure, a slack on every inequality) is solved in the primal form.

Scale. The solver sees G = W H W and F = V F' (W, V positive diagonal, powers of two):
the late gradients and values of a converging method are orders of magnitude below
x_0 - x*, and the solver's tolerances would swallow them. W, V come from the previous
solve (W_cc ~ sqrt(G_cc), V_i ~ F_i), re-solving while they move by more than a factor 4.

Constraint generation. A solve keeps only the ``active`` pairs (first those with x*,
with a term's extra point and between calls at most one step apart,
:func:`seed_pairs`), checks every omitted inequality at the answer, adds the violated
ones (and the nearly tight ones with them) and solves again until none is violated: then
the answer is feasible for the whole PEP, so the value is tau_N (up to the solver's
tolerance), and the multipliers (0 on the omitted pairs) are its certificate. The rounds
that only set the scale or look for violated pairs take an "almost solved" answer as it
is (``rough``); only the last round, and every certificate, must end solved. Each pair's
svec Q_k is built once, on the few columns it uses (:meth:`PEPData.svec_rows`): memory
grows with the pairs, not with the pairs times d^2.

``margin`` solves the primal with objective M + eps W^-1 W^-1, m_F + eps / V (in the
solver's units: tr H and sum F'): its dual has S ⪰ eps W^-2 and c_F >= eps / V, a
certificate that survives rounding (tau grows by about eps times tr H + sum F'). A margin
solve keeps the pairs the measure's own solve ended with (no constraint generation: its
multipliers are a certificate whatever pairs they omit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sps

from sosalgo.kernel.conic import svec, svec_index, unsvec
from sosalgo.kernel.solvers import SolverStatus, solve_attempts
from sosalgo.worstcase.structure import PEPFrame, PEPStructure

__all__ = ["PEPData", "SDPAnswer", "pep_data", "solve_pep"]

SQRT2 = math.sqrt(2.0)


@dataclass
class PEPData:
    """The float data: pair k is alpha_k (F_a - F_b) + tr(Qc_k X_k G X_k') >= 0 (``a_k``
    its row on F); ``w``, ``v``: the current scale (see the module); ``active``: the pairs
    the next solve starts from (grown by :func:`solve_pep`)."""

    st: PEPStructure
    X: np.ndarray  # (K, 4, d): rows of (x_a, x_b, g_a, g_b) on the basis
    Qc: np.ndarray  # (K, 4, 4)
    a: np.ndarray  # (K, nF)
    active: np.ndarray
    w: np.ndarray  # (d,) G = W H W
    v: np.ndarray  # (nF,) F = V F'
    # the measure's solves also try the strong regularization (:data:`STRONG`), and a
    # margin solve that ends almost solved gives its multipliers as a candidate
    # certificate: methods that change with k (OGM ends "almost solved" at N = 30)
    strong: bool = False
    # an omitted pair violated by more (relative) joins the next solve; the constraint
    # generation ends when none is
    violation: float = 1e-9
    # the constant of each pair's inequality (0: homogeneous; :attr:`PEPStructure.constants`)
    c: np.ndarray | None = None
    # Gram-level conditions (K, Zx, Zg) with a matrix multiplier in the dual
    # (:mod:`sosalgo.worstcase.blocks`; empty once the PEP carries their rank-one cuts)
    blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    # class LMIs on tuples of points (TupleLMI, Z, F indices) with a matrix multiplier in
    # the dual (:mod:`sosalgo.worstcase.lmis`; empty once the PEP carries their cuts)
    lmis: list[tuple[Any, np.ndarray, list[int | None]]] = field(default_factory=list)
    s: float = 1.0  # the subgradients' unit (the LMIs' value rows)
    _svec: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    def q(self, idx: np.ndarray, scaled: bool = False) -> np.ndarray:
        """Q_k = X_k' Qc_k X_k of the pairs ``idx`` (len, d, d), on H when ``scaled``
        (dense: for a few pairs; the solves use :meth:`svec_rows`)."""
        X = self.X[idx] * self.w if scaled else self.X[idx]
        Q = np.einsum("kai,kab,kbj->kij", X, self.Qc[idx], X, optimize=True)
        return 0.5 * (Q + Q.transpose(0, 2, 1))

    def svec_rows(self, idx: np.ndarray, scaled: bool = False) -> sps.csr_matrix:
        """svec Q_k of the pairs ``idx`` as a sparse (len, d(d+1)/2) matrix, on H when
        ``scaled``. Each Q_k lives on the few basis columns its four rows use (a point
        combines the last few steps' b only): built on those columns once per pair and
        kept, so memory grows with the pairs' supports, not with len * d^2."""
        pos, val, ptr = [], [], [0]
        for k in np.asarray(idx, dtype=int):
            entry = self._svec.get(int(k))
            if entry is None:
                entry = self._svec[int(k)] = _pair_svec(self.X[k], self.Qc[k])
            pos.append(entry[0])
            val.append(entry[1])
            ptr.append(ptr[-1] + len(entry[0]))
        cols = np.concatenate(pos) if pos else np.zeros(0, dtype=np.int64)
        vals = np.concatenate(val) if val else np.zeros(0)
        if scaled:
            r, c, _ = svec_index(self.st.d)
            vals = vals * (self.w[r] * self.w[c])[cols]
        nG = self.st.d * (self.st.d + 1) // 2
        return sps.csr_matrix((vals, cols, np.array(ptr)), shape=(len(ptr) - 1, nG))

    def violations(self, G: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Every inequality at (G, F), relative to a bound on its largest coefficient in
        the solver's units, without forming the Q_k."""
        M = np.einsum("kui,kvi->kuv", self.X @ G, self.X)
        val = np.einsum("kuv,kuv->k", self.Qc, M) + self.a @ F + self.consts()
        xw = np.abs(self.X * self.w).max(axis=2)
        size = (np.abs(self.Qc).max(axis=(1, 2)) * xw.max(axis=1) ** 2
                + np.abs(self.a * self.v).max(axis=1, initial=0.0))
        return val / np.where(size > 0, size, 1.0)

    def consts(self) -> np.ndarray:
        """The constant of every pair's inequality (zeros for a homogeneous PEP)."""
        if self.c is None:
            self.c = (np.zeros(self.st.count) if self.st.constants is None
                      else self.st.constants.astype(float))
        return self.c


def _pair_svec(X: np.ndarray, Qc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(svec positions, values) of the nonzero upper-triangle entries of X' Qc X (one
    pair), computed on the columns X uses."""
    cols = np.flatnonzero(np.any(X != 0, axis=0))
    Xs = X[:, cols]
    Q = Xs.T @ Qc @ Xs
    Q = 0.5 * (Q + Q.T)
    i, j = np.triu_indices(len(cols))
    vals = Q[i, j] * np.where(i == j, 1.0, SQRT2)
    keep = vals != 0
    r, c = cols[i[keep]], cols[j[keep]]
    return (c * (c + 1) // 2 + r).astype(np.int64), vals[keep]


def pep_data(mt: PEPFrame, st: PEPStructure) -> PEPData:
    K, d = st.count, st.d
    R = max([4] + [len(Xe) for _, Xe, _ in st.extras])  # an LMI cut's rows: up to 2p
    X = np.zeros((K, R, d))
    a = np.zeros((K, st.nF))
    Qc = np.zeros((K, R, R))
    for k in range(len(st.pairs)):
        _, a[k], X[k, :4] = st.pair_rows(mt, k)
        j, _, _, r = st.pairs[k]
        Qc[k, :4, :4] = mt.ineqs[j][r][1]
    for e, (_, Xe, Qe) in enumerate(st.extras):  # values: a constraint's only
        k = len(st.pairs) + e
        n = len(Xe)
        X[k, :n], Qc[k, :n, :n] = np.asarray(Xe, float), np.asarray(Qe, float)
        if e in st.extra_values:
            a[k] = np.asarray(st.extra_values[e], float)
    from sosalgo.worstcase.blocks import block_data
    from sosalgo.worstcase.lmis import lmi_data

    return PEPData(st, X, Qc, a, seed_pairs(st), np.ones(d), np.ones(st.nF),
                   blocks=block_data(mt, st), lmis=lmi_data(mt, st), s=float(mt.s))


def seed_pairs(st: PEPStructure) -> np.ndarray:
    """The pairs every solve starts with: those with x*, with an extra point (a term's),
    and between calls at most one step apart (the pairs of the known worst cases)."""
    keep = []
    for k, (j, a, b, _) in enumerate(st.pairs):
        ta, tb = st.points[j][a].t, st.points[j][b].t
        if ta is None or tb is None or abs(ta - tb) <= 1:
            keep.append(k)
    keep += range(len(st.pairs), st.count)  # the extra constraints: every one
    return np.array(keep, dtype=int)


@dataclass
class SDPAnswer:
    status: str  # solved | unbounded | infeasible | failed (and the raw status)
    raw: str
    primal: float | None = None
    dual: float | None = None
    G: np.ndarray | None = None
    F: np.ndarray | None = None
    tau: float | None = None  # the dual's coefficient of the initial condition
    lam: np.ndarray | None = None  # in the units of the unscaled inequalities
    const: float = 0.0  # sum_k lambda_k c_k: the bound is tau + const (constants)
    S: np.ndarray | None = None
    size: float = 1.0  # tr H + sum F' (the solver's units): the margin's scale
    rounds: int = 0  # solves of the constraint generation
    blocks: list[np.ndarray] = field(default_factory=list)  # the blocks' multipliers
    lmis: list[np.ndarray] = field(default_factory=list)  # the class LMIs' multipliers


# tight tolerances; Clarabel's defaults; then a stronger static regularization, which
# solves the harder PEPs (long horizons, prox points) that end "almost solved" otherwise
ATTEMPTS = ((True, 1e-8), (False, 1e-8), (True, 1e-7), (False, 1e-7), (False, 1e-6))
# the measure's solves (dual form): Clarabel's defaults first (the rounds that only set
# the scale or find violated pairs stop at "almost solved"); PRECISE alone when
# ``precise``: a certificate the default tolerances left unproven (Nesterov N = 40,
# margin 1e-5: proven from the tight solve); when that solve is not solved (Nesterov
# N = 50), the ladder goes on to the next margin
# capped at TRACE_ITER iterations (Nesterov N = 80: "almost solved" after 133, 400 s)
PRECISE = ((True, 1e-8, 100),)
# second: without Clarabel's equilibration (the triple momentum method at N = 16 ends
# "almost solved" at every other attempt, its dual stalled; solved without it)
QUICK = ((False, 1e-8), (False, 1e-8, None, False), (True, 1e-8), (False, 1e-7),
         (False, 1e-6))
# margin solves only, when the above end "almost solved": a much stronger regularization
# (GD on L-smooth convex f at N = 20: a degenerate dual, rank-1 worst case); the answer is
# only a candidate certificate, which the exact check accepts or refuses
STRONG = ((False, 1e-5), (False, 1e-4))
# the witness's trace solves: the same attempts, at most TRACE_ITER iterations each
# (those that solve take 15-60; one that fails ran 400 — 20 s of the 45 s witness search
# of Nesterov at N = 20); a primal infeasible answer is final there (a slack too large)
TRACE_ITER = 100
TRACE = tuple((precise, reg, TRACE_ITER) for precise, reg in ATTEMPTS)


def solve_pep(data: PEPData, margin: float = 0.0, objective: str = "measure",
              floor: float | None = None, slack: float = 0.0,
              unit: float = 1.0, precise: bool = False, rescale: bool = True) -> SDPAnswer:
    """The PEP by constraint generation and rescaling (see the module). ``objective``:
    "measure" (the PEP; ``margin`` eps as in the module) or "trace" (minimize tr H with
    measure >= ``floor`` and every inequality >= ``slack`` relative to its largest
    coefficient: the rank reduction of the witness). The measure is divided by ``unit``
    for the solver (about tau); the answer is in the original units. ``precise``: the
    measure's solves try tight tolerances first (:data:`ATTEMPTS`, not :data:`QUICK`).
    ``rescale`` False: W, V stay as they are (a PEP whose worst case leaves a direction
    of G free: the rescaling chases it as it drifts)."""
    K = data.st.count
    # with constants the solver's problem is not scale invariant: the measure keeps its own
    # unit (dividing it by tau alone left the projected gradient on a set of diameter 0.1
    # "almost solved" at N = 2, and solved in unit 1)
    fixed = bool(np.any(data.consts())) or data.st.bare  # bare: a fixed normalization
    unit = 1.0 if fixed else unit
    active, rounds, rescales, resolved = data.active, 0, 0, False
    exact_next = objective != "measure" or margin > 0  # a certificate: never rough
    while True:
        tries = TRACE if objective == "trace" else PRECISE if precise else QUICK
        strong = (margin > 0 or (data.strong and objective == "measure")) and not precise
        if strong and data.strong and margin == 0:  # ends almost solved at the others
            tries = STRONG + tries
        elif strong:
            tries = tries + STRONG
        ans = _solve_active(data, active, margin, objective, floor, slack, unit, tries,
                            rough=not exact_next)
        rounds += 1
        if (objective == "measure" and margin == 0 and ans.G is not None
                and rescales < MAX_RESCALES and rescale
                and not data.st.bare  # bare: the measure is 0
                and np.all(np.isfinite(ans.G))):
            # a margin solve keeps the scale its measure's solve ended with (rescaled,
            # Nesterov at N = 80 solved its first margin twice: 60 s + 100 s)
            moved = _rescale(data, ans.G, ans.F)
            got = measure_value(data.st, ans.G, ans.F)
            if got > 0 and abs(math.log2(got / unit)) > 2 and not fixed:
                unit, moved = float(_pow2(np.array(got))), True
            if moved:
                rescales += 1
                continue
        if ans.status == "infeasible" or (len(active) == K and ans.status != "almost"):
            break  # an infeasible relaxation: so is the PEP
        if ans.status not in ("solved", "almost") and (objective == "trace" or margin > 0):
            break  # a failed rank reduction or certificate: the caller goes on without it
        if ans.status not in ("solved", "almost"):  # unbounded or failed on a relaxation
            active = np.arange(K)  # decide on all
            continue
        if margin > 0 and ans.status == "solved":
            break  # a certificate on the pairs found by the PEP's own solve (0 elsewhere)
        assert ans.G is not None and ans.F is not None
        viol = data.violations(ans.G, ans.F)
        viol[active] = np.inf
        bad = np.flatnonzero(viol < (0.5 * slack if slack > 0 else -data.violation))
        if not len(bad):
            if ans.status == "solved" and objective == "measure" and margin == 0 \
                    and not resolved and not fixed and _unit_off(data, ans, unit):
                unit, resolved = float(_pow2(np.array(measure_value(
                    data.st, ans.G, ans.F)))), True
                continue  # the last answer, solved again in its own unit
            if ans.status == "solved":
                break
            exact_next = True  # no violated pair at a rough answer: solve this set
            continue
        bad = bad[np.argsort(viol[bad])][:max(len(active), MIN_ADD)]
        if slack == 0:  # with the violated pairs, the most nearly tight ones: the next
            near = np.flatnonzero((viol >= -data.violation) & (viol < NEAR))  # round's
            bad = np.union1d(bad, near[np.argsort(viol[near])][:MIN_ADD])  # violated
        active = np.union1d(active, bad)
        exact_next = objective != "measure"
    data.active = active
    ans.rounds = rounds
    return ans


NEAR = 1e-6  # and when one does, up to MIN_ADD omitted ones below NEAR (relative) too
MIN_ADD = 64  # joins per round: at least this many, or as many as are active
MAX_RESCALES = 3
FLOOR = 1e-2  # W_cc >= FLOOR sqrt(measure), V_i >= FLOOR^2 measure
# and W_cc >= RANGE times the largest: a late gradient of a long horizon is far below
# x_0 - x* (Nesterov N = 100: 1e-12 of it); floored at 1e-8 of it, as it was, those
# directions stayed 1e4 too small for the solver: a seed solve took 283 iterations and
# its tau was 500 times the proven bound (18 iterations and 8.3e-25, just above the
# proven 8.08e-25, at 1e-14)
RANGE = 1e-14


def measure_value(st: PEPStructure, G: np.ndarray, F: np.ndarray) -> float:
    """The measure <M, G> + m_F F."""
    return float(np.sum(st.meas_q.astype(float) * G) + st.meas_f.astype(float) @ F)


def _unit_off(data: PEPData, ans: SDPAnswer, unit: float) -> bool:
    """Whether the unit of tau the solver saw is more than a factor 2 off the answer's
    measure. The unit is set while the scale moves (at most MAX_RESCALES times, spent
    on the cheap first rounds); a long horizon's later rounds move the measure again,
    and a solve in a unit off by that much was 3 % low (Nesterov N = 100: 7.81e-25, the
    same pairs in their own unit 8.08e-25, which the certificate proves)."""
    got = measure_value(data.st, ans.G, ans.F)  # type: ignore[arg-type]
    return got > 0 and abs(math.log2(got / unit)) > 1


def _pow2(x: np.ndarray) -> np.ndarray:
    return np.exp2(np.round(np.log2(x)))


def _rescale(data: PEPData, G: np.ndarray, F: np.ndarray) -> bool:
    """Set W, V from the answer (W_cc ~ sqrt(G_cc), V_i ~ F_i, floored at FLOOR times the
    measure's own size: a direction the worst case does not use keeps a moderate scale,
    so that the margin eps I on H stays a small perturbation); False when every factor
    moves by at most 4."""
    g = np.sqrt(np.clip(np.diag(G), 0.0, None))
    top = max(float(g.max(initial=0.0)), 1e-100)
    size = max(abs(measure_value(data.st, G, F)), (RANGE * top) ** 2, 1e-200)
    w = _pow2(np.maximum(g, max(RANGE * top, FLOOR * math.sqrt(size))))
    v = _pow2(np.maximum(np.clip(F, 0.0, None), FLOOR ** 2 * size))
    if np.all(np.abs(np.log2(w / data.w)) <= 2) and np.all(np.abs(np.log2(v / data.v)) <= 2):
        return False
    data.w, data.v = w, v
    return True


def _solve_active(data: PEPData, active: np.ndarray, margin: float, objective: str,
                  floor: float | None, slack: float, unit: float,
                  attempts: tuple[tuple[Any, ...], ...] = ATTEMPTS,
                  rough: bool = False) -> SDPAnswer:
    """The SDP on the pairs ``active`` in the solver's units (Clarabel; the attempts of
    :data:`ATTEMPTS`); G, F, lambda, tau back in the original units. The measure is
    solved in its dual form (:func:`_solve_dual`), the trace objective in the primal
    form. ``rough``: an "almost solved" answer ends the attempts (status "almost": its
    G, F set a scale or show violated pairs, nothing more)."""
    if objective == "measure":
        return _solve_dual(data, active, margin, unit, attempts, rough)
    st, w, v = data.st, data.w, data.v
    d, nF = st.d, st.nF
    nG = d * (d + 1) // 2
    meas = _scaled_form(data, st.meas_q, st.meas_f) / unit
    init = _initial_form(data)
    q = np.concatenate([svec(np.eye(d)), np.zeros(nF)])
    ineq = sps.hstack([data.svec_rows(active, scaled=True),
                       sps.csr_matrix(data.a[active] * v)]).tocsr()
    sig = _row_scale(ineq)
    rows = [sps.csr_matrix(init[None, :]), -sps.diags(1.0 / sig) @ ineq,
            sps.hstack([sps.csr_matrix((nF, nG)), -sps.identity(nF)])]
    # a row with no entry (an indicator's own condition at x*, its normal vector pinned
    # at 0: 0 >= 0) has no slack to give
    live = (np.asarray(abs(ineq).max(axis=1).todense()).ravel() > 0 if ineq.shape[0]
            else np.ones(0))
    if st.equalities is not None:  # half of an equality: no slack to give either
        live = live & ~st.equality_rows(int(np.max(active, initial=-1)) + 1)[active]
    b = [np.ones(1), data.consts()[active] / sig - slack * live, np.zeros(nF)]
    if floor is not None:  # a mingrad measure: each of its forms (st.floors) at the floor
        for form in ([meas] if st.floors is None else
                     [_scaled_form(data, fq, ff) / unit for fq, ff in st.floors]):
            rows.append(sps.csr_matrix(-form[None, :]))
            b.append(np.array([-floor / unit]))
    nn = sum(r.shape[0] for r in rows)
    rows.append(sps.hstack([-sps.identity(nG), sps.csr_matrix((nG, nF))]))
    b.append(np.zeros(nG))
    A = sps.csc_matrix(sps.vstack(rows))
    A.eliminate_zeros()
    cones = [("nonneg", nn), ("psd", d)]
    sol, raw, st_ = solve_attempts(A, q, np.concatenate(b), cones, attempts,
                                   final=("DualInfeasible", "PrimalInfeasible"))
    if raw == "DualInfeasible":
        return SDPAnswer("unbounded", raw)
    if st_ == SolverStatus.INFEASIBLE:
        return SDPAnswer("infeasible", raw)
    if sol is None:
        return SDPAnswer("failed", raw)
    x = np.array(sol.x)
    H, Fs = unsvec(x[:nG], d), x[nG:]
    G, F = H * np.outer(w, w), Fs * v
    if st_ != SolverStatus.SOLVED:
        return SDPAnswer("failed", raw, G=G if raw.startswith("Almost") else None, F=F)
    return SDPAnswer("solved", raw, -float(sol.obj_val) * unit, -float(sol.obj_val_dual) * unit,
                     G, F, size=float(np.trace(H)) + float(np.clip(Fs, 0, None).sum()))


def _scaled_form(data: PEPData, Q: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(svec of Q on H, f on F') of a quadratic and linear form of (G, F)."""
    return np.concatenate([svec(Q.astype(float) * np.outer(data.w, data.w)),
                           f.astype(float) * data.v])


def _initial_form(data: PEPData) -> np.ndarray:
    """The initial condition on (H, F'); with none (a homogeneous question, ``st.bare``)
    the solver's normalization tr H instead (not on F: the dual's c_F >= 0 is then the
    certificate's own): the worst case of the measure over it is <= 0 exactly when the
    measure is <= 0 everywhere (its sup is then 0, else unbounded)."""
    st = data.st
    if not st.bare:
        return _scaled_form(data, st.init_q, st.init_f)
    return np.concatenate([svec(np.eye(st.d)), np.zeros(st.nF)])


def _row_scale(M: sps.csr_matrix) -> np.ndarray:
    """The largest |entry| of each row (1 for an empty row)."""
    sig = np.asarray(abs(M).max(axis=1).todense()).ravel() if M.shape[0] else np.ones(0)
    sig[sig == 0] = 1.0
    return sig


def _solve_dual(data: PEPData, active: np.ndarray, margin: float, unit: float,
                attempts: tuple[tuple[Any, ...], ...], rough: bool) -> SDPAnswer:
    """The PEP on the pairs ``active`` in its dual form: minimize tau over (tau, lambda
    >= 0) with c_F = tau i_F - m_F - eps - sum lambda_k a_k >= 0 and S = tau I0 - M -
    eps I - sum lambda_k Q_k ⪰ 0 (solver's units, eps = ``margin``). The entries of S
    that no Q_k, I0 or M touches are structurally zero: Clarabel's chordal decomposition
    splits the PSD cone into small blocks along the band the basis gives (the primal
    form's cone is on every entry of G: dense, a cost like d^6). G and F are the dual
    variables of S and c_F (a PSD completion of the entries the pairs use)."""
    st = data.st
    d, nF, K = st.d, st.nF, len(active)
    nG = d * (d + 1) // 2
    meas = _scaled_form(data, st.meas_q, st.meas_f) / unit
    init = _initial_form(data)
    ineq = sps.hstack([data.svec_rows(active, scaled=True),
                       sps.csr_matrix(data.a[active] * data.v)]).tocsr()
    sig = _row_scale(ineq)
    cols = (sps.diags(1.0 / sig) @ ineq).T.tocsr()  # (nG + nF) x K: lambda_k's column
    body = sps.hstack([sps.csr_matrix(-init[:, None]), cols]).tocsr()
    # with constants the bound is tau initial + sum lambda_k c_k <= tau + ... only for
    # tau >= 0: the PEP under initial <= 1, not = 1 (where its sup may be below)
    t = int(bool(np.any(data.consts())))
    from sosalgo.worstcase.blocks import block_columns
    from sosalgo.worstcase.lmis import lmi_columns

    blk = block_columns(data.blocks, data.w)
    lmi = lmi_columns(data.lmis, data.w, data.v, nF, data.s)
    # the matrix multipliers: the blocks' (on S), then the LMIs' (on S and c_F, with
    # <Lambda, E_k> = 0 for their free multipliers: a zero cone)
    mats = [(c, sps.csr_matrix((nF, c.shape[1])), n) for c, n in blk] + [
        (c, f, n) for c, f, _, n in lmi]
    nb = sum(c.shape[1] for c, _, _ in mats)
    ne = sum(e.shape[0] for _, _, e, _ in lmi)
    sign = sps.csr_matrix(([-1.0] * t, ([0] * t, [0] * t)), shape=(t, 1 + K + nb))
    Sblk = sps.hstack([body[:nG]] + [c for c, _, _ in mats]).tocsr()
    Fblk = sps.hstack([body[nG:]] + [f for _, f, _ in mats]).tocsr()
    rows = [sign, sps.hstack([sps.csr_matrix((K, 1)), -sps.identity(K),
                              sps.csr_matrix((K, nb))]),
            Fblk, Sblk, sps.hstack([sps.csr_matrix((nb, 1 + K)), -sps.identity(nb)])]
    if ne:
        nbk = sum(c.shape[1] for c, _ in blk)
        rows.append(sps.hstack([sps.csr_matrix((ne, 1 + K + nbk)),
                                sps.block_diag([e for _, _, e, _ in lmi])]))
    A = sps.vstack(rows).tocsc()
    A.eliminate_zeros()
    seen = (linear_only(data) if t or st.margin_seen  # with constants: no margin where S
            else np.ones(d))  # is 0
    eye = np.concatenate([svec(np.diag(seen)), np.full(nF, 0.0 if st.free_values else 1.0)]
                         ) * margin  # free values: c_F = 0 (no margin there)
    b = np.concatenate([np.zeros(t + K), -(meas + eye)[nG:], -(meas + eye)[:nG],
                        np.zeros(nb + ne)])
    q = np.zeros(1 + K + nb)
    q[0] = 1.0
    q[1:1 + K] = data.consts()[active] / sig  # bound / unit = tau' + sum_k x_k c_k / sig_k
    cones = [("nonneg", t + K + nF), ("psd", d)] + [("psd", n) for _, _, n in mats] + (
        [("zero", ne)] if ne else [])
    sol, raw, st_ = solve_attempts(A, q, b, cones, attempts, final=(
        "PrimalInfeasible", "DualInfeasible") + (("AlmostSolved",) if rough else ()))
    if raw == "PrimalInfeasible":  # no certificate: the measure is unbounded
        return SDPAnswer("unbounded", raw)
    if raw == "DualInfeasible":
        return SDPAnswer("infeasible", raw)
    if sol is None:
        return SDPAnswer("failed", raw)
    x, z = np.array(sol.x), np.array(sol.z)[t:]
    H, Fs = unsvec(z[K + nF:K + nF + nG], d), z[K:K + nF]
    G, F = H * np.outer(data.w, data.w), Fs * data.v
    almost = raw.startswith("Almost")
    if st_ != SolverStatus.SOLVED and not (almost and margin > 0 and data.strong):
        # G, F of an almost solved problem: a scale only (with ``strong``, a margin
        # solve's almost solved multipliers are a candidate: the exact check decides)
        return SDPAnswer("almost" if almost and rough else "failed", raw,
                         G=G if almost else None, F=F)
    lam = np.zeros(st.count)
    lam[active] = np.maximum(x[1:1 + K], 0.0) / sig * unit
    ans = SDPAnswer("solved", raw, float(sol.obj_val_dual) * unit, float(sol.obj_val) * unit,
                    G, F, float(x[0]) * unit, lam,
                    size=float(np.trace(H)) + float(np.clip(Fs, 0, None).sum()),
                    const=float(lam @ data.consts()))
    ans.S = residual(data, ans.tau, lam)
    at = 1 + K
    for k, (_, _, n) in enumerate(mats):  # the multipliers, in the original units
        m = n * (n + 1) // 2
        (ans.blocks if k < len(blk) else ans.lmis).append(unsvec(x[at:at + m], n) * unit)
        at += m
    return ans


def linear_only(data: PEPData) -> np.ndarray:
    """1.0 for each basis direction some form has a square of (some pair's Q_k, I0 or M
    has a nonzero diagonal entry there), 0.0 for the others: S is 0 on those
    diagonals, so a certificate's S vanishes on their rows and no margin can hold there
    (a subgradient fixed at 0 in a tilted indicator enters as -s*, linearly only)."""
    st = data.st
    XQX = np.einsum("kui,kuv,kvi->i", np.abs(data.X), np.abs(data.Qc), np.abs(data.X))
    seen = (XQX + np.abs(np.diag(st.init_q.astype(float)))
            + np.abs(np.diag(st.meas_q.astype(float)))) > 0
    return seen.astype(float)


def residual(data: PEPData, tau: float, lam: np.ndarray) -> np.ndarray:
    """S = tau I0 - M - sum lambda_k Q_k (unscaled multipliers)."""
    st = data.st
    idx = np.flatnonzero(lam)
    S = tau * st.init_q.astype(float) - st.meas_q.astype(float)
    if len(idx):
        S = S - unsvec(data.svec_rows(idx).T @ lam[idx], st.d)
    return S


def value_residual(data: PEPData, tau: float, lam: np.ndarray) -> np.ndarray:
    """c_F = tau i_F - m_F - sum lambda_k a_k (must be >= 0)."""
    st = data.st
    return tau * st.init_f.astype(float) - st.meas_f.astype(float) - lam @ data.a
