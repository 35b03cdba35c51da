"""The proof that a box of θ holds no certificate: condition (F) of
:mod:`sosalgo.design_search.dualbound` checked in ball arithmetic over the whole box.

Given float dual matrices Z_d(u) = Z_d0 + Σ_j u_j Z_dj (their exact binary values are the
certificate) for the θ-dependent blocks, this module proves, for every u ∈ [-1, 1]^k:

1. Z_d(u) ⪰ 0 (:func:`sosalgo.design_search.enclosure.psd_on_box` on the affine terms);
2. h(u, r) = Σ_d <Z_d(u), C_d(u, r)> > 0 and
3. Z_c(u, r) = -Φ_c⁻¹ g(u, r) ⪰ 0 for every cone block c, with
   g_i(u, r) = Σ_d <Z_d(u), L_di(u, r)>,

at both ends of an r-interval (both conditions are affine in r, so the ends suffice),
from the exact polynomial data of :mod:`sosalgo.design_search.polymodel` shifted to the box in
ball arithmetic. Every arithmetic step is outward rounded, so a True is a proof that the
family's inequalities have no solution at any (θ, r) of the box × the r-interval.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from flint import arb, arb_mat

import sosalgo.design_search.enclosure as enc
from sosalgo.design_search.polymodel import PolyLMI

__all__ = ["BoxProver"]


class BoxProver:
    """Rigorous check of a box's dual certificate (see module docstring)."""

    def __init__(self, model: PolyLMI, dep: list[int],
                 cones: list[tuple[int, list[int]]]):
        assert model.balls is not None and model.cols is not None
        self.model, self.dep = model, dep
        self.k = model.k
        self.nvar = model.template.nvar
        rows = model.balls.tolist()
        base = rows[0]  # cone blocks are θ-free: the constant row
        self.cones = []
        for b, vars_ in cones:
            start, (_, s, _) = model.cols[b]["l0"]
            pairs = [(a, c) for a in range(s) for c in range(a, s)]
            phi = arb_mat([[base[start + i * s * s + a * s + c] * (1 if a == c else 2)
                            for a, c in pairs] for i in vars_])
            inv = phi.inv()  # a ball matrix containing Φ⁻¹ exactly
            self.cones.append((vars_, s, pairs, inv))
        dims = [d + 1 for d in model.degrees]
        ext = [d + 2 for d in model.degrees]
        self.ext_degrees = tuple(d + 1 for d in model.degrees)
        self.even = enc.even_mask(self.ext_degrees)
        grid = list(np.ndindex(*dims)) if dims else [()]
        self.place = []  # row of u^α · u_j on the extended grid, j = 0 (none), 1..k
        for j in range(self.k + 1):
            self.place.append([int(np.ravel_multi_index(
                tuple(a + (1 if i == j - 1 else 0) for i, a in enumerate(alpha)), ext))
                if alpha else 0 for alpha in grid])
        self.next = int(np.prod(ext)) if ext else 1
        self.data = [self._block_data(rows, d) for d in dep]

    def _block_data(self, rows: list[list[arb]], d: int) -> arb_mat:
        """Block d's coefficients as a ((2 + 2 nvar) M) x s² ball matrix: rows (o, β) for
        the outputs o = c0, c1, l0 per variable, l1 per variable and monomials β."""
        cols = self.model.cols[d]
        s2 = int(np.prod(cols["c0"][1]))
        nv, M = self.nvar, len(rows)
        starts = [cols["c0"][0], cols["c1"][0]]
        starts += [cols["l0"][0] + i * s2 for i in range(nv)]
        starts += [cols["l1"][0] + i * s2 for i in range(nv)]
        return arb_mat([[rows[b][st + e] for e in range(s2)] for st in starts
                        for b in range(M)])

    def proves(self, zc: np.ndarray, w: np.ndarray, Zs: list[list[np.ndarray]],
               bounds: Sequence[dict | None], rs: Sequence[float],
               covers: list[list[np.ndarray]] | None = None) -> bool:
        """(F) on the box center zc ± w for every r between min(rs) and max(rs).
        ``bounds`` (per r) and ``covers`` (per block: S_j of Z_j) are the SDP's
        candidate matrices for the covers of :func:`~sosalgo.design_search.enclosure.psd_on_box`."""
        for d, terms in enumerate(Zs):
            if not self._z_psd(terms, None if covers is None else covers[d]):
                return False
        Y = self._contract(zc, w, Zs)
        for r, bd in zip(rs, bounds, strict=True):
            rb = arb(float(r))
            h = [Y[a][0] + rb * Y[a][1] for a in range(self.next)]
            if not enc.poly_positive(h, self.even):
                return False
            nv = self.nvar
            g = [[Y[a][2 + i] + rb * Y[a][2 + nv + i] for i in range(nv)]
                 for a in range(self.next)]
            for c, (vars_, s, pairs, inv) in enumerate(self.cones):
                coef = [self._cone_matrix(g[a], vars_, s, pairs, inv) for a in range(self.next)]
                cand = None if bd is None else {a: v for (cc, a), v in bd.items() if cc == c}
                if not enc.psd_on_box(coef, self.even, cand):
                    return False
        return True

    def _z_psd(self, terms: list[np.ndarray], covers: list[np.ndarray] | None) -> bool:
        """Z(u) = Z_0 + Σ_j u_j Z_j ⪰ 0 on the box (exact binary values of the floats)."""
        coef = [[[arb(float(v)) for v in row] for row in 0.5 * (t + t.T)] for t in terms]
        even = np.array([True] + [False] * (len(terms) - 1))
        cand = None if covers is None else {j + 1: S for j, S in enumerate(covers)}
        return enc.psd_on_box(coef, even, cand)

    def _contract(self, zc: np.ndarray, w: np.ndarray,
                  Zs: list[list[np.ndarray]]) -> list[list[arb]]:
        """Rows (extended monomials u^α of the box) of [h_c0, h_c1, g_l0 (nvar), g_l1
        (nvar)]: the data contracted with each term Z_dj first (exact floats), then shifted
        to the box (the shift acts on monomials only, so the two commute)."""
        nout, K = 2 + 2 * self.nvar, self.k + 1
        R = None
        for D, terms in zip(self.data, Zs, strict=True):
            Zm = np.array([(0.5 * (Z + Z.T)).ravel() for Z in terms]).T  # s² x (k+1)
            part = D * enc.ball_matrix(Zm)
            R = part if R is None else R + part
        M = len(self.place[0])
        flat = R.tolist()  # rows (o, β), columns j
        Q = arb_mat([[flat[o * M + b][j] for j in range(K) for o in range(nout)]
                     for b in range(M)])
        S = enc.box_shift(zc, w, self.model.degrees)
        Y = (S * Q).tolist()
        out = [[arb(0)] * nout for _ in range(self.next)]
        for b in range(M):
            for j in range(K):
                e = self.place[j][b]
                for o in range(nout):
                    out[e][o] += Y[b][j * nout + o]
        return out

    @staticmethod
    def _cone_matrix(g: list[arb], vars_: list[int], s: int, pairs, inv: arb_mat
                     ) -> list[list[arb]]:
        """Z_c = -Φ⁻¹ g on the cone's variables, as a symmetric s x s ball matrix."""
        gv = [g[i] for i in vars_]
        Z = [[arb(0)] * s for _ in range(s)]
        for q, (a, c) in enumerate(pairs):
            v = -sum((inv[q, i] * gv[i] for i in range(len(vars_))), arb(0))
            Z[a][c] = Z[c][a] = v
        return Z
