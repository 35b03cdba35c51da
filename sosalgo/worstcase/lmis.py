"""Class LMIs on tuples of points in the PEP (:class:`sosalgo.classes.base.TupleLMI`):
for every tuple of points of one function, ``T = T0(G, F) + sum_k M_k E_k ⪰ 0`` for some
free real M_k (Rubbens, Hendrickx, Taylor 2025: the "expensive" conditions of
PEPit's Lipschitz / cocoercive strongly monotone operators and smooth Lojasiewicz
functions; necessary conditions, not known sufficient: the PEP is an upper bound).

In the dual each LMI takes a matrix multiplier Lambda ⪰ 0 with <Lambda, E_k> = 0 for
every free M_k (the stationarity in M_k), and S, c_F gain -<Lambda, T0(G, F)>
(:func:`lmi_columns`, the dual solve of :mod:`sosalgo.worstcase.sdp`). Any such Lambda
makes ``<Lambda, T0(G, F)> >= 0`` valid on every member of the class (for the member's
M: <Lambda, T> >= 0 since both are PSD, and the M part is 0). After the first solve the
PEP keeps one such scalar cut per LMI (:func:`lmi_cuts`) as an extra constraint and is
solved again: its value is the same up to rounding (a relaxation of the LMI PEP, which
Lambda certifies), and every later step — the margin ladder, the exact proof, ``verify``
— reads the cuts as ordinary inequalities with multipliers >= 0.

A cut's matrix is exact: its entries are binary rationals except one pivot entry per
free multiplier (an entry where E_k alone is nonzero, with a rational coefficient),
which :func:`cut_matrix` solves for, so that <Lambda, E_k> = 0 holds exactly (balls when
the class data are balls); Lambda ⪰ 0 is then proven (exact LDL' on rationals, a
definite ball matrix otherwise) before the cut is used, in the proof as in ``verify``
(a cut that is not PSD is refused). Before rounding, Lambda is moved a little into the
interior of the cone (plus t P0, P0 a fixed positive definite matrix orthogonal to
every E_k, the smallest t of :data:`INTERIOR` that leaves it definite in floating point).
"""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction
from typing import Any

import numpy as np
import scipy.sparse as sps

from sosalgo.kernel.conic import svec, unsvec
from sosalgo.worstcase.structure import PEPFrame, PEPStructure

__all__ = ["cut_matrix", "lmi_columns", "lmi_cuts", "lmi_data", "with_lmi_cuts"]

CUT_BITS = 40  # significant bits of a cut's entries (relative to its largest)
INTERIOR = (0.0, 2.0 ** -36, 2.0 ** -30, 2.0 ** -24, 2.0 ** -18, 2.0 ** -12)
IDLE = 1e-7  # a multiplier below this (relative to the largest) is the solver's noise
DEFINITE = 2.0 ** -44  # a cut's smallest eigenvalue in floating point, at least


def lmi_data(mt: PEPFrame, st: PEPStructure) -> list[tuple[Any, np.ndarray, list[int | None]]]:
    """(TupleLMI, Z, F indices) of every LMI of a float PEP: Z the rows of the tuple's
    points and subgradients (times s) on the basis (empty once the PEP has its cuts)."""
    if st.lmi_cuts:
        return []
    out = []
    for j, r, idx in st.lmis:
        Z, fidx = tuple_rows(mt, st, j, idx)
        out.append((mt.lmis[j][r], np.asarray(Z, float), fidx))
    return out


def tuple_rows(mt: PEPFrame, st: PEPStructure, j: int, idx: tuple[int, ...]
               ) -> tuple[np.ndarray, list[int | None]]:
    """(Z = rows of x_1..x_p, s g_1..s g_p on the basis; the points' F indices)."""
    pts = [st.points[j][a] for a in idx]
    Z = np.vstack([p.x for p in pts] + [p.g * mt.s for p in pts])
    return Z, [p.f for p in pts]


def lmi_form(lmi: Any, Z: np.ndarray, fidx: list[int | None], Lam: np.ndarray, nF: int,
             s: float) -> tuple[np.ndarray, np.ndarray]:
    """(<Lambda, T0> as a matrix on the basis, its row on F) in floats."""
    Qc = np.einsum("uv,uvab->ab", Lam, lmi.gram)
    vals = np.einsum("uv,uva->a", Lam, lmi.values)
    a = np.zeros(nF)
    for i, f in enumerate(fidx):
        if f is not None:
            a[f] += s * vals[i]
    return Z.T @ Qc @ Z, a


def lmi_columns(lmis: list[tuple[Any, np.ndarray, list[int | None]]], w: np.ndarray,
                v: np.ndarray, nF: int, s: float
                ) -> list[tuple[sps.csr_matrix, sps.csr_matrix, sps.csr_matrix, int]]:
    """Per LMI, in the solver's units (H = W^-1 G W^-1, F' = F / V): the matrices whose
    column c is svec of <Lambda, T0> on H, its row on F', and <Lambda, E_k>, at Lambda =
    unsvec(e_c); and the LMI's size."""
    out = []
    for lmi, Z, fidx in lmis:
        n = lmi.size
        m = n * (n + 1) // 2
        S, F, E = [], [], []
        for c in range(m):
            Lam = unsvec(np.eye(m)[c], n)
            q, a = lmi_form(lmi, Z * w, fidx, Lam, nF, s)
            S.append(svec(q))
            F.append(a * v)
            E.append(np.einsum("uv,kuv->k", Lam, lmi.free))
        E_ = np.column_stack(E) if len(lmi.free) else np.zeros((0, m))
        out.append((sps.csr_matrix(np.column_stack(S)), sps.csr_matrix(np.column_stack(F)),
                    sps.csr_matrix(E_), n))
    return out


def pivots(lmi: Any) -> list[tuple[int, int]]:
    """One entry (u <= v) per free multiplier where its E_k alone is nonzero (a
    coefficient +-1 first); ValueError when some E_k has none."""
    free = np.asarray([[[float(getattr(x, "c", x)) for x in row] for row in E]
                       for E in lmi.free], float).reshape(len(lmi.free), lmi.size, lmi.size)
    out = []
    for k in range(len(free)):
        cand = [(u, v) for u in range(lmi.size) for v in range(u, lmi.size)
                if free[k, u, v] != 0 and not np.any(np.delete(free[:, u, v], k))]
        if not cand:
            raise ValueError(f"free multiplier {k + 1} of an LMI: no entry of its own")
        cand.sort(key=lambda e: abs(abs(free[k][e]) - 1.0) > 0)
        out.append(cand[0])
    return out


def _others(lmi: Any) -> list[tuple[int, int]]:
    """The upper-triangle entries that are not pivots (a cut's stored entries)."""
    piv = set(pivots(lmi))
    return [(u, v) for u in range(lmi.size) for v in range(u, lmi.size) if (u, v) not in piv]


def cut_matrix(lmi: Any, entries: list[Any], exact: bool) -> np.ndarray:
    """The cut's Lambda from its stored entries, the pivots solved for (<Lambda, E_k> =
    0 exactly); ValueError unless Lambda ⪰ 0 is proven (floats: no eigenvalue below
    -1e-9 of its largest entry)."""
    others = _others(lmi)
    if len(entries) != len(others):
        raise ValueError(f"cut of an LMI of size {lmi.size}: {len(entries)} entries for "
                         f"{len(others)}")
    n = lmi.size
    zero = Fraction(0) if exact else 0.0
    Lam = np.full((n, n), zero, dtype=object if exact else float)
    for (u, v), x in zip(others, entries, strict=True):
        Lam[u, v] = Lam[v, u] = Fraction(x) if exact else float(x)
    for k, (p, q) in enumerate(pivots(lmi)):
        E = lmi.free[k]
        coef = E[p, q] * (1 if p == q else 2)
        if exact:
            coef = _rational(coef)
        rest = sum((E[u, v] * Lam[u, v] for u in range(n) for v in range(n)
                    if (u, v) not in ((p, q), (q, p))), zero)
        Lam[p, q] = Lam[q, p] = -rest * (1 / coef) if exact else -rest / coef
    _check_psd(Lam, exact)
    return Lam


def _rational(x: Any) -> Fraction:
    if isinstance(x, int | Fraction):
        if x == 0:
            raise ValueError("an LMI pivot coefficient is 0")
        return Fraction(x)
    if getattr(x, "r", None) == 0 and x.c != 0:
        return Fraction(x.c)
    raise ValueError("an LMI's free multiplier has no rational pivot coefficient")


def _check_psd(Lam: np.ndarray, exact: bool) -> None:
    from sosalgo.kernel.exact import prove_definite, prove_psd, symmetrize_balls

    if not exact:
        top = max(float(np.abs(Lam).max()), 1e-300)
        if float(np.linalg.eigvalsh(Lam.astype(float))[0]) < -1e-9 * top:
            raise ValueError("an LMI cut's matrix is not positive semidefinite")
        return
    if all(isinstance(x, int | Fraction) or getattr(x, "r", 1) == 0 for x in Lam.flat):
        ok = prove_psd([[Fraction(getattr(x, "c", x)) for x in row] for row in Lam]).psd
    else:
        ok = prove_definite(symmetrize_balls(Lam), 1)[0]
    if not ok:
        raise ValueError("an LMI cut's matrix is not proven positive semidefinite")


def _interior(lmi: Any) -> np.ndarray:
    """P0 ⪰ 0 with <P0, E_k> = 0 for every k and tr P0 = size, as definite as possible
    (a small SDP); the identity when the LMI has no free multiplier."""
    from sosalgo.kernel.solvers import solve_attempts

    n = lmi.size
    if not len(lmi.free):
        return np.eye(n)
    m = n * (n + 1) // 2
    free = np.asarray(lmi.free, float)
    eye = svec(np.eye(n))
    A = sps.vstack([sps.csr_matrix(np.column_stack([np.vstack([svec(E) for E in free]
                                                              + [eye]),
                                                    np.zeros(len(free) + 1)])),
                    sps.hstack([-sps.identity(m), sps.csr_matrix(eye[:, None])])]).tocsc()
    b = np.concatenate([np.zeros(len(free)), [float(n)], np.zeros(m)])
    q = np.zeros(m + 1)
    q[-1] = -1.0
    sol, _, _ = solve_attempts(A, q, b, [("zero", len(free) + 1), ("psd", n)],
                               ((True, 1e-8), (False, 1e-7)))
    if sol is None:
        raise ValueError("an LMI has no positive definite multiplier orthogonal to its "
                         "free multipliers")
    return unsvec(np.array(sol.x)[:m], n)


def lmi_cuts(st: PEPStructure, mt: PEPFrame, lams: list[np.ndarray]
             ) -> list[tuple[int, int, tuple[int, ...], list[Fraction]]]:
    """One cut per LMI from its multiplier Lambda (see the module): (function, LMI,
    tuple of points, the stored entries as binary rationals); an LMI whose Lambda is
    about 0 gets the cut of the interior matrix P0."""
    cuts, cache = [], {}
    most = max([float(np.abs(Lam).max()) for Lam in lams] + [0.0])
    for (j, r, idx), Lam in zip(st.lmis, lams, strict=True):
        top = float(np.abs(Lam).max())
        if not np.isfinite(top):
            continue
        lmi = mt.lmis[j][r]
        if (j, r) not in cache:
            cache[(j, r)] = _interior(lmi)
        P0 = cache[(j, r)]
        # a multiplier that is the solver's noise: the interior matrix's cut, which keeps
        # the cut PEP bounded where the LMI did
        L0 = 0.5 * (Lam + Lam.T) / top if top > IDLE * most else P0
        for t in INTERIOR:
            entries = [_binary(x) for x in _stored(lmi, L0 + t * P0)]
            full = cut_matrix_or_none(lmi, entries)
            if full is not None and np.linalg.eigvalsh(full)[0] >= DEFINITE:
                cuts.append((j, r, tuple(idx), entries))
                break
    return cuts


def cut_matrix_or_none(lmi: Any, entries: list[Fraction]) -> np.ndarray | None:
    try:
        return cut_matrix(lmi, [float(x) for x in entries], exact=False).astype(float)
    except ValueError:
        return None


def _stored(lmi: Any, Lam: np.ndarray) -> list[float]:
    return [float(Lam[u, v]) for u, v in _others(lmi)]


def _binary(x: float) -> Fraction:
    return Fraction(float(np.round(x * 2.0 ** CUT_BITS) / 2.0 ** CUT_BITS))


def _cut_row(mt: PEPFrame, j: int, r: int, entries: list[Any]) -> tuple[np.ndarray, list[Any]]:
    """(sum_uv Lambda_uv gram_uv, sum_uv Lambda_uv values_uv) of a cut, its Lambda proven
    PSD first; kept on the method (the exact proof rebuilds its structure per attempt).
    Sums over the nonzero coefficients only."""
    key = (j, r, tuple(entries))
    if key in mt.lmi_rows:
        return mt.lmi_rows[key]
    lmi = mt.lmis[j][r]
    Lam = cut_matrix(lmi, entries, mt.exact)
    zero = Fraction(0) if mt.exact else 0.0
    p2, p = lmi.gram.shape[2], lmi.values.shape[2]
    Qc = np.full((p2, p2), zero, dtype=object if mt.exact else float)
    vals = [zero] * p
    for u in range(lmi.size):
        for v in range(lmi.size):
            lam = Lam[u, v]
            if _is_zero(lam):
                continue
            for a, b in zip(*np.nonzero(_nonzero_mask(lmi.gram[u, v])), strict=True):
                Qc[a, b] = Qc[a, b] + lmi.gram[u, v, a, b] * lam
            for i in np.flatnonzero(_nonzero_mask(lmi.values[u, v])):
                vals[i] = vals[i] + lmi.values[u, v, i] * lam
    mt.lmi_rows[key] = (Qc, vals)
    return Qc, vals


def _is_zero(x: Any) -> bool:
    return x == 0 if not hasattr(x, "r") else (x.c == 0 and x.r == 0)


def _nonzero_mask(a: np.ndarray) -> np.ndarray:
    return np.vectorize(lambda x: not _is_zero(x), otypes=[bool])(a) if a.dtype == object \
        else a != 0


def with_lmi_cuts(mt: PEPFrame, st: PEPStructure,
                  cuts: list[tuple[int, int, tuple[int, ...], list[Any]]]) -> PEPStructure:
    """A copy of ``st`` whose extras end with the cuts <Lambda, T0(G, F)> >= 0 (float or
    exact, as ``mt``; the same labels either way); ValueError for a cut of no LMI of
    this PEP or whose matrix is not proven PSD."""
    extras, labels = list(st.extras), list(st.labels)
    values = dict(st.extra_values)
    known = {(j, r, tuple(idx)) for j, r, idx in st.lmis}
    zero = Fraction(0) if mt.exact else 0.0
    count: dict[tuple[int, int, tuple[int, ...]], int] = {}
    for j, r, idx, entries in cuts:
        if (j, r, tuple(idx)) not in known:
            raise ValueError(f"cut of LMI {j}.{r} at {tuple(idx)}: the PEP has no such LMI")
        Z, fidx = tuple_rows(mt, st, j, tuple(idx))
        Qc, vals = _cut_row(mt, j, r, list(entries))
        av = np.full(st.nF, zero, dtype=object if mt.exact else float)
        for i, f in enumerate(fidx):
            if f is not None:
                av[f] = av[f] + mt.s * vals[i]
        names = ",".join(st.points[j][a].label for a in idx)
        key = (j, r, tuple(idx))
        count[key] = count.get(key, 0) + 1
        lab = f"{mt.functions[j][0]}:lmi{r + 1}({names}).{count[key]}"
        values[len(extras)] = av
        extras.append((lab, Z, Qc))
        labels.append(lab)
    constants = st.constants
    if constants is not None:  # one constant per row: the cuts' are 0
        constants = np.concatenate([constants, np.array(
            [zero] * (len(extras) - len(st.extras)), dtype=constants.dtype)])
    return replace(st, extras=extras, labels=labels, extra_values=values,
                   lmi_cuts=list(st.lmi_cuts) + [tuple(c) for c in cuts],
                   constants=constants)
