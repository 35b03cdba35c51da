"""The ``mingrad`` measure: c min_{0<=k<=N} |grad f(x_k)|^2 + (linear terms) (``minf``:
the same with f(x_k) - f*).

The worst case max over the PEP of c min_k q_k(G) + l(G, F) equals min over weights w in
the simplex of max over the PEP of c sum_k w_k q_k(G) + l(G, F) (a bilinear saddle over a
convex feasible set and the compact simplex: Sion's minimax theorem). This module finds
the weights: the dual of the PEP with an epigraph variable t <= q_k, whose multipliers are
the w_k (minimize tau over tau, lambda >= 0, w >= 0, sum w = 1 with tau I0 - c sum w_k M_k
- M_l - sum lambda Q ⪰ 0 and the same on the values). Rounded to rationals summing to 1
exactly, they give a linear measure (:func:`sosalgo.worstcase.terms.expand_min`) whose every
value bounds the minimum's from above, and whose worst case is the minimum's up to the
solver's accuracy: its certificate is proven exactly as for any linear measure.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np
import scipy.sparse as sps

from sosalgo.errors import InputError
from sosalgo.kernel.conic import svec
from sosalgo.kernel.solvers import SolverStatus, solve_attempts
from sosalgo.worstcase.sdp import pep_data
from sosalgo.worstcase.structure import PEPFrame, build_structure
from sosalgo.worstcase.terms import Term, parse_terms

__all__ = ["min_floors", "min_weights", "rational_weights"]

ATTEMPTS = ((True, 1e-8), (False, 1e-8), (False, 1e-7))


def _forms(mt: PEPFrame, steps: int, mterms: list[Term], iterms: list[Term],
           option: str) -> tuple[Any, list[tuple[np.ndarray, np.ndarray]]]:
    """(structure of the whole measure, [(form on G, form on F) of c |grad f(x_k)|^2
    plus the linear terms, k = 0..N]), every structure with the same pairs and basis."""
    from sosalgo.worstcase.terms import expand_min

    forms, base = [], None
    for k in range(steps + 1):
        w = [Fraction(int(i == k)) for i in range(steps + 1)]
        text = expand_min(mterms, steps, w)
        st = build_structure(mt, steps, parse_terms(text, option, False, mt.p), iterms)
        if base is None:
            whole = expand_min(mterms, steps, [Fraction(1, steps + 1)] * (steps + 1))
            base = build_structure(mt, steps, parse_terms(whole, option, False, mt.p), iterms)
        if st.labels != base.labels or st.basis != base.basis:
            raise InputError(f"{option}: the minimum over the iterates: their points differ "
                             "by step")
        forms.append((st.meas_q, st.meas_f))
    return base, forms


def min_floors(mt: PEPFrame, steps: int, mterms: list[Term], iterms: list[Term],
               option: str = "--measure") -> list[tuple[np.ndarray, np.ndarray]]:
    """The forms (on G, on F) of c |grad f(x_k)|^2 + (linear terms), k = 0..N."""
    return _forms(mt, steps, mterms, iterms, option)[1]


def min_weights(mt: PEPFrame, steps: int, mterms: list[Term], iterms: list[Term],
                option: str = "--measure") -> list[float]:
    """The weights w_k (>= 0, summing to 1) of the minimax (see the module), in floats;
    InputError when the epigraph PEP is unbounded or fails."""
    st, forms = _forms(mt, steps, mterms, iterms, option)
    data = pep_data(mt, st)
    d, nF, K, M = st.d, st.nF, st.count, len(forms)  # the pairs and the extra rows
    nG = d * (d + 1) // 2
    ineq = sps.hstack([data.svec_rows(np.arange(K)), sps.csr_matrix(data.a)]).tocsr()
    sig = np.asarray(abs(ineq).max(axis=1).todense()).ravel() if K else np.ones(0)
    sig[sig == 0] = 1.0
    cols = (sps.diags(1.0 / sig) @ ineq).T.tocsr()  # (nG + nF) x K
    init = np.concatenate([svec(st.init_q.astype(float)), st.init_f.astype(float)])
    W = np.column_stack([np.concatenate([svec(q.astype(float)), f.astype(float)])
                         for q, f in forms])  # (nG + nF) x M
    body = sps.hstack([sps.csr_matrix(-init[:, None]), cols, sps.csr_matrix(W)]).tocsr()
    nv = 1 + K + M
    A = sps.vstack([
        sps.hstack([sps.csr_matrix((1, 1 + K)), sps.csr_matrix(np.ones((1, M)))]),
        sps.hstack([sps.csr_matrix((K + M, 1)), -sps.identity(K + M)]),
        body[nG:], body[:nG]]).tocsc()
    b = np.concatenate([[1.0], np.zeros(K + M + nF + nG)])
    q = np.zeros(nv)
    q[0] = 1.0
    q[1:1 + K] = data.consts() / sig  # the inequalities' constants (0: homogeneous)
    cones = [("zero", 1), ("nonneg", K + M + nF), ("psd", d)]
    sol, raw, status = solve_attempts(A, q, b, cones, ATTEMPTS)
    if sol is None or status != SolverStatus.SOLVED:
        raise InputError(f"{option}: the PEP's minimum over the iterates was not "
                         f"solved ({raw}; unbounded for this initial condition?)")
    w = np.clip(np.array(sol.x)[1 + K:], 0.0, None)
    return list(w / w.sum())


def rational_weights(w: list[float], digits: int = 12) -> list[Fraction]:
    """Rationals >= 0 summing to exactly 1, each within about 10^-digits of ``w``: the
    largest takes the remainder."""
    q = [Fraction(round(v * 10 ** digits), 10 ** digits) for v in w]
    top = int(np.argmax(w))
    q[top] = 1 - sum(v for i, v in enumerate(q) if i != top)
    if q[top] < 0:
        raise ValueError("weights: not a distribution")
    return q
