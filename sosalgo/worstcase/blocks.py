"""Gram-level class conditions in the PEP: a matrix over all the points of one function
that must be positive semidefinite (linear operators, quadratics; Bousselmi, Hendrickx,
Glineur, "Interpolation conditions for linear operators and applications to performance
estimation problems").

A class gives each such condition as a symmetric 2 x 2 K
(:meth:`sosalgo.classes.base.FunctionClass.blocks`): over the function's points a, b
(tilted data, in the units of :mod:`sosalgo.worstcase.structure`: g/s times s),

    T[a, b] = [x_a; g_a]' K [x_b; g_b],      T ⪰ 0.

In the dual the condition takes a matrix multiplier Lambda ⪰ 0 and S gains
- sum_ab Lambda_ab T_ab(G) (:func:`block_columns`, the dual solve of
:mod:`sosalgo.worstcase.sdp`). A positive semidefinite Lambda = sum_i e_i v_i v_i' (its
eigenvalues e_i >= 0, eigenvectors v_i) is exactly the sum of the scalar conditions
v_i' T v_i >= 0 (each valid on every member of the class, since T ⪰ 0) with multipliers
e_i. After the first solve the PEP keeps those rank-one cuts (:func:`with_cuts`; the
vectors v_i as binary rationals, the same in the float and the exact PEP) as extra
constraints and is solved again: its value is the same (the cut PEP is a relaxation, and
Lambda's factors are a certificate of it), and every later step — the margin ladder, the
exact proof in ball arithmetic, ``verify`` — reads the cuts as ordinary inequalities with
multipliers >= 0. The exact multiplier of a block is thus Lambda = V diag(e) V' with V
rational and e >= 0 proven: positive semidefinite by construction (an exact LDL'-type
factor), and its contribution to S enters the ball-arithmetic Cholesky check of S.
"""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction
from typing import Any

import numpy as np
import scipy.sparse as sps

from sosalgo.kernel.conic import svec, unsvec
from sosalgo.worstcase.structure import PEPFrame, PEPStructure

__all__ = ["block_columns", "block_data", "block_form", "cut_vectors", "with_cuts"]

CUT_BITS = 40  # significant bits of a cut vector's entries


def block_data(mt: PEPFrame, st: PEPStructure) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(K, Zx, Zg) of every block of a float PEP: Zx, Zg the rows of its points and of
    their subgradients (times s) on the basis (empty once the PEP has its cuts)."""
    if st.cuts:
        return []
    out = []
    for j, r, idx in st.blocks:
        if not idx:
            continue
        Zx = np.vstack([st.points[j][a].x for a in idx]).astype(float)
        Zg = np.vstack([st.points[j][a].g for a in idx]).astype(float) * float(mt.s)
        out.append((np.asarray(mt.blocks[j][r], float), Zx, Zg))
    return out


def block_form(K: np.ndarray, Zx: np.ndarray, Zg: np.ndarray, Lam: np.ndarray) -> np.ndarray:
    """sum_ab Lambda_ab T_ab as a matrix on the basis (so that <it, G> = <Lambda, T(G)>)."""
    cross = Zx.T @ Lam @ Zg
    return K[0, 0] * (Zx.T @ Lam @ Zx) + K[0, 1] * (cross + cross.T) + K[1, 1] * (
        Zg.T @ Lam @ Zg)


def block_columns(blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
                  w: np.ndarray) -> list[tuple[sps.csr_matrix, int]]:
    """Per block: (the matrix whose column c is svec of :func:`block_form` at Lambda =
    unsvec(e_c), on H = W^-1 G W^-1, in the solver's units; the block's size)."""
    out = []
    for K, Zx, Zg in blocks:
        n = Zx.shape[0]
        m = n * (n + 1) // 2
        cols = [svec(block_form(K, Zx * w, Zg * w, unsvec(np.eye(m)[c], n)))
                for c in range(m)]
        out.append((sps.csr_matrix(np.column_stack(cols)), n))
    return out


def cut_vectors(st: PEPStructure, lams: list[np.ndarray]) -> list[tuple[int, int, list[Any]]]:
    """The rank-one cuts of the blocks' multipliers: every eigenvector of each Lambda,
    rounded to binary rationals of :data:`CUT_BITS` bits (the cut PEP keeps all of them:
    its value is then that of the block PEP up to the rounding)."""
    cuts = []
    live = [(j, r, idx) for j, r, idx in st.blocks if idx]
    for (j, r, _), Lam in zip(live, lams, strict=True):
        _, V = np.linalg.eigh(0.5 * (Lam + Lam.T))
        for v in V.T:
            v = v / np.abs(v).max()
            cuts.append((j, r, [float(np.round(t * 2.0 ** CUT_BITS) / 2.0 ** CUT_BITS)
                                for t in v]))
    return cuts


def with_cuts(mt: PEPFrame, st: PEPStructure, cuts: list[tuple[int, int, list[Any]]]
              ) -> PEPStructure:
    """A copy of ``st`` whose extras end with the cuts v' T v >= 0 (float or exact, as
    ``mt``; the same labels either way)."""
    extras, labels = list(st.extras), list(st.labels)
    index = {(j, r): idx for j, r, idx in st.blocks}
    count: dict[tuple[int, int], int] = {}
    for j, r, vec in cuts:
        idx = index.get((j, r))
        if idx is None or j >= len(mt.blocks) or r >= len(mt.blocks[j]):
            raise ValueError(f"cut of block {j}.{r}: the PEP has no such block")
        if len(vec) != len(idx):
            raise ValueError(f"cut of block {j}.{r}: {len(vec)} entries for {len(idx)} points")
        K = mt.blocks[j][r]
        zero = st.points[j][idx[0]].x * 0
        xv, gv = zero, zero
        for a, t in zip(idx, vec, strict=True):
            c = Fraction(t) if mt.exact else float(t)
            xv = xv + st.points[j][a].x * c
            gv = gv + st.points[j][a].g * c
        gv = gv * mt.s
        X = np.vstack([xv, zero, gv, zero])
        Qc = np.full((4, 4), Fraction(0) if mt.exact else 0.0, dtype=object if mt.exact
                     else float)
        for (u, v), (p, q) in {(0, 0): (0, 0), (0, 2): (0, 1), (2, 0): (1, 0),
                               (2, 2): (1, 1)}.items():
            Qc[u, v] = K[p, q]
        count[(j, r)] = count.get((j, r), 0) + 1
        lab = f"{mt.functions[j][0]}:block{r + 1}.{count[(j, r)]}"
        extras.append((lab, X, Qc))
        labels.append(lab)
    constants = st.constants
    if constants is not None:  # one constant per row: the cuts' are 0
        zero = Fraction(0) if mt.exact else 0.0
        constants = np.concatenate([constants, np.array([zero] * (len(extras)
                                                                  - len(st.extras)),
                                                        dtype=constants.dtype)])
    return replace(st, extras=extras, labels=labels, cuts=list(st.cuts) + list(cuts),
                   constants=constants)

