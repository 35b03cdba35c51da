"""The interpolation ("tight") certificate family: Lyapunov functions with function values.

Following Taylor, Van Scoy and Lessard (ICML 2018), written for sosalgo's state-space form
xi+ = A xi + B u, u = grad f(y), y = C xi, x = E xi (reduced d = 1 templates, Remark 1).
With the lag l >= 0 and z_k = (xi_k - xi*, u_k, u_{k-1}, ..., u_{k-l}),

    V_k = z_k' P z_k + sum_{j=0..l} p_j (f(y_{k-j}) - f*) + c (f(x_k) - f*),

P symmetric (not required PSD), p, c free. A rate rho is certified when, for r = rho^2,

    (D)   V_{k+1} - r V_k + sum eta_ij q_ij <= 0   as a quadratic form + linear form in the
          function values of the window y_0..y_{l+1}, x_l, x_{l+1}, x*  (eta_ij >= 0),
    (P)   V_k - (f(x_k) - f*) - sum lambda_ij q_ij >= 0   on the window y_0..y_l, x_l, x*,

where q_ij = (L - m)(f_i - f_j) + 1/2 [x_i; x_j; g_i; g_j]' MM [x_i; x_j; g_i; g_j] >= 0 are
the F(m, L) interpolation inequalities between every ordered pair of points of a window
(Taylor, Hendrickx, Glineur 2017). On a trajectory every q_ij >= 0 and every f - f* >= 0,
so V_{k+1} <= r V_k and f(x_k) - f* <= V_k, hence f(x_k) - f* <= rho^(2(k-l)) V_l.

The quadratic parts are matrix inequalities, the function-value parts hold coefficient-wise
(each f - f* >= 0). Theorem 1 is the special case P = [P_T1 0; 0 0], p = 0, c = 1, so this
family never certifies a worse rate. When E = C the x-points coincide with the y-points and
are dropped (c merges into p_0).

A certificate of lag l is one of lag l + 1 (P padded with zeros, p_{l+1} = 0, the
multipliers of the window's older points 0), so larger lags never certify less in exact
arithmetic, and sometimes much more (heavy ball). For the solver, which needs a margin,
the directions of a window on which every matrix vanishes for every certificate (a state
killed by A^l and never read) are removed first (:func:`null_directions`; on the oracle
model :func:`sosalgo.certificates.composite.facial_reduction`). Without a given lag the
analysis tries the lags of :meth:`Interpolation.auto_lags` and keeps the best rate
(:func:`sosalgo.analysis.analyze_algorithm`); a certificate always names its own lag.

The same structure builder works on floats (the LMI data), rationals/balls (the exact
verifier) and sympy (``sosalgo lmi``): it only uses sums, products and stacking.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from sosalgo.certificates.base import (
    CertificateFamily,
    complement_basis,
    compress,
    null_basis,
    restricted_eigenvalues,
)
from sosalgo.kernel.conic import AffineBlock, LMIProblem, sym_basis, unit_quads

if TYPE_CHECKING:  # only for annotations: families do not depend on the model at run time
    import sympy as sp

    from sosalgo.model import Algorithm
    from sosalgo.spec.types import Spec

__all__ = ["INTERPOLATION", "Interpolation", "Structure", "structure", "evaluate"]


@dataclass
class Window:
    """One window of the method: row maps on the lifted vector w and the point list."""

    width: int  # length of w
    nphi: int  # number of function values
    Z: dict[int, Any]  # Z_t: rows (xi_t, u_t, u_{t-1}, ..., u_{t-l}) as maps on w
    F: dict[int, Any]  # F_t: 0/1 rows selecting f(y_t), ..., f(y_{t-l}), f(x_t) from phi
    labels: list[str]  # pair labels "i>j" (q_ij >= 0 for this ordered pair)
    Mq: list[Any]  # quadratic part of q_ij (width x width)
    mq: list[Any]  # linear part of q_ij on phi (nphi)
    iso: Any = None  # float windows: :func:`null_directions` (width x k)


@dataclass
class Structure:
    """Both windows of a method for a given lag (see module docstring)."""

    n: int
    lag: int
    has_x: bool
    dec: Window  # decrease window, times 0..l+1
    pos: Window  # positivity window, times 0..l
    norm: Any  # the "1" of V >= f(x_l) - f*, as a vector on phi of the positivity window

    @property
    def nz(self) -> int:
        return self.n + self.lag + 1

    @property
    def npi(self) -> int:
        return self.lag + 1 + (1 if self.has_x else 0)


def _zeros(shape: tuple[int, ...], obj: bool) -> np.ndarray:
    return np.zeros(shape, dtype=object) if obj else np.zeros(shape)


def _window(A, B, C, E, m, L, lag: int, steps: int, has_x: bool, obj: bool) -> Window:
    """Window with gradients u_0..u_{steps-1}, x-points at times steps-2, steps-1 (decrease)
    or steps-1 (positivity); ``steps`` = l + 2 (decrease) or l + 1 (positivity)."""
    if not obj:
        return _window_float(A, B, C, E, m, L, lag, steps, has_x)
    n = A.shape[0]
    x_times = [t for t in (steps - 2, steps - 1) if t >= lag] if has_x else []
    width = n + steps + len(x_times)
    nphi = steps + len(x_times)

    def unit(k: int) -> np.ndarray:
        e = _zeros((1, width), obj)
        e[0, k] = 1
        return e

    U = [unit(n + t) for t in range(steps)]
    V = {t: unit(n + steps + i) for i, t in enumerate(x_times)}
    Xi = [np.hstack([np.eye(n, dtype=object), _zeros((n, width - n), obj)])]
    for t in range(steps - 1):
        Xi.append(A @ Xi[t] + B @ U[t])
    Z, F = {}, {}
    for t in range(lag, steps):
        Z[t] = np.vstack([Xi[t]] + [U[t - j] for j in range(lag + 1)])
        rows = [t - j for j in range(lag + 1)] + ([steps + x_times.index(t)] if has_x else [])
        Ft = _zeros((len(rows), nphi), obj)
        for r, k in enumerate(rows):
            Ft[r, k] = 1
        F[t] = Ft
    # points: (name, x row, g row, index in phi or None for x*)
    pts = [(f"y{t}", C @ Xi[t], U[t], t) for t in range(steps)]
    pts += [(f"x{t}", E @ Xi[t], V[t], steps + i) for i, t in enumerate(x_times)]
    pts.append(("*", _zeros((1, width), obj), _zeros((1, width), obj), None))
    MM = _mm(m, L, obj)
    half = Fraction(1, 2)
    labels, Mq, mq = [], [], []
    for ni, xi, gi, fi in pts:
        for nj, xj, gj, fj in pts:
            if ni == nj:
                continue
            X = np.vstack([xi, xj, gi, gj])
            Mq.append(_scale(X.T @ MM @ X, half))
            lin = _zeros((nphi,), obj)
            if fi is not None:
                lin[fi] = lin[fi] + (L - m)
            if fj is not None:
                lin[fj] = lin[fj] - (L - m)
            mq.append(lin)
            labels.append(f"{ni}>{nj}")
    return Window(width, nphi, Z, F, labels, Mq, mq)


def _mm(m: Any, L: Any, obj: bool) -> np.ndarray:
    """The F(m, L) interpolation form on [x_i; x_j; g_i; g_j] (times 1/2 in q_ij)."""
    return np.array([[-m * L, m * L, m, -L], [m * L, -m * L, -m, L], [m, -m, -1, 1],
                     [-L, L, 1, -1]], dtype=object if obj else float)


@dataclass(frozen=True)
class _Shape:
    """What a float window takes from its shape alone (n, lag, steps, has_x): shared,
    read-only."""

    x_times: tuple[int, ...]
    width: int
    nphi: int
    F: dict[int, np.ndarray]  # as in Window
    Zu: dict[int, np.ndarray]  # the gradient rows (u_t, ..., u_{t-l}) of Z_t
    G: np.ndarray  # gradient row of every point (y_t, x_t, *), on w
    ii: np.ndarray  # ordered pairs (i, j), i != j, of points
    jj: np.ndarray
    sign: np.ndarray  # pairs x nphi: +1 at f_i, -1 at f_j (times L - m in m_ij)
    labels: tuple[str, ...]


@functools.lru_cache(maxsize=128)
def _shape(n: int, lag: int, steps: int, has_x: bool) -> _Shape:
    x_times = tuple(t for t in (steps - 2, steps - 1) if t >= lag) if has_x else ()
    width, nphi = n + steps + len(x_times), steps + len(x_times)
    eye = np.eye(width)
    F, Zu = {}, {}
    for t in range(lag, steps):
        rows = [t - j for j in range(lag + 1)] + ([steps + x_times.index(t)] if has_x else [])
        F[t] = np.eye(nphi)[rows]
        Zu[t] = eye[[n + t - j for j in range(lag + 1)]]
    npts = steps + len(x_times) + 1
    G = np.zeros((npts, width))
    G[:-1] = eye[n: n + nphi]  # u_t of y_t, then the x-points' gradients; x*: 0
    names = [f"y{t}" for t in range(steps)] + [f"x{t}" for t in x_times] + ["*"]
    idx = [(i, j) for i in range(npts) for j in range(npts) if i != j]
    ii, jj = np.array([i for i, _ in idx]), np.array([j for _, j in idx])
    sign = np.zeros((len(idx), nphi))
    for r, (i, j) in enumerate(idx):  # the last point (x*) has no value
        if i < nphi:
            sign[r, i] += 1.0
        if j < nphi:
            sign[r, j] -= 1.0
    for a in (G, ii, jj, sign, *F.values(), *Zu.values()):
        a.flags.writeable = False
    labels = tuple(f"{names[i]}>{names[j]}" for i, j in idx)
    return _Shape(x_times, width, nphi, F, Zu, G, ii, jj, sign, labels)


def _window_float(A, B, C, E, m, L, lag: int, steps: int, has_x: bool) -> Window:
    """The float case of :func:`_window` (same rows and pairs; the shape-only parts are
    cached, the interpolation pairs computed all at once)."""
    n = A.shape[0]
    sh = _shape(n, lag, steps, has_x)
    Xi = np.zeros((steps, n, sh.width))
    Xi[0, :, :n] = np.eye(n)
    for t in range(steps - 1):  # xi_{t+1} = A xi_t + B u_t
        Xi[t + 1] = A @ Xi[t]
        Xi[t + 1, :, n + t] += B[:, 0]
    Z = {t: np.vstack([Xi[t], sh.Zu[t]]) for t in range(lag, steps)}
    xs = np.zeros((len(sh.G), sh.width))
    xs[:steps] = (C @ Xi)[:, 0, :]  # y_t = C xi_t
    for i, t in enumerate(sh.x_times):
        xs[steps + i] = E @ Xi[t]
    X = np.stack([xs[sh.ii], xs[sh.jj], sh.G[sh.ii], sh.G[sh.jj]], axis=1)  # (pairs, 4, w)
    Mq = 0.5 * (X.transpose(0, 2, 1) @ _mm(m, L, False) @ X)
    iso = null_directions(Z, xs, sh.G)
    return Window(sh.width, sh.nphi, Z, dict(sh.F), list(sh.labels), list(Mq),
                  list((L - m) * sh.sign), iso)


def null_directions(Z: dict[int, np.ndarray], xs: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Orthonormal basis (width x k) of the directions of a window on which every row map
    z_t, every point and every gradient is 0, so that every matrix of the window's
    inequality vanishes there, for every certificate. With a lag l >= 1 they exist when a
    part of xi_0 is killed by A^l and never seen (a state the method resets and never
    reads): the inequality can then not hold strictly, and the solver, asked for a margin,
    finds none; the problem is solved without them (:meth:`Interpolation._problem`)."""
    return null_basis(np.vstack([*Z.values(), xs, G]))


def _scale(M: np.ndarray, half: Any) -> np.ndarray:
    out = np.empty(M.shape, dtype=object)
    for idx in np.ndindex(M.shape):
        out[idx] = M[idx] * half
    return out


def has_output_point(C: np.ndarray, E: np.ndarray) -> bool:
    """False when x_k = y_k (E = C exactly), so the x-points are the y-points."""
    try:
        return not np.array_equal(np.asarray(C, float), np.asarray(E, float))
    except TypeError:
        import sympy as sp

        return any(sp.simplify(a - b) != 0 for a, b in zip(np.ravel(C), np.ravel(E), strict=True))


def structure(A, B, C, E, m, L, lag: int, has_x: bool, obj: bool = False) -> Structure:
    """Windows, row maps and interpolation pairs (float arrays, or object arrays of exact
    numbers / sympy expressions when ``obj``)."""
    n = A.shape[0]
    dec = _window(A, B, C, E, m, L, lag, lag + 2, has_x, obj)
    pos = _window(A, B, C, E, m, L, lag, lag + 1, has_x, obj)
    norm = _zeros((pos.nphi,), obj)
    norm[pos.nphi - 1 if has_x else lag] = 1  # f(x_l), or f(y_l) when x = y
    return Structure(n, lag, has_x, dec, pos, norm)


def evaluate(st: Structure, r: Any, P: Any, pi: Any, eta: Any, lam: Any) -> dict[str, Any]:
    """The four inequality parts at a certificate, in the units of ``st``:

    ``D`` (⪯ 0), ``Df`` (<= 0 entrywise), ``Pq`` (⪰ 0), ``Pf`` (>= 0 entrywise), where
    D = Z_{l+1}' P Z_{l+1} - r Z_l' P Z_l + sum eta M, Df = F_{l+1}' pi - r F_l' pi + sum eta m,
    Pq = Z+' P Z+ - sum lambda M+, Pf = F+' pi - norm - sum lambda m+.
    """
    d, p, lag = st.dec, st.pos, st.lag
    Z1, Z0, Zp = d.Z[lag + 1], d.Z[lag], p.Z[lag]
    D = Z1.T @ P @ Z1 - r * (Z0.T @ P @ Z0)
    Df = d.F[lag + 1].T @ pi - r * (d.F[lag].T @ pi)
    for e, M, mv in zip(eta, d.Mq, d.mq, strict=True):
        D = D + e * M
        Df = Df + e * mv
    Pq = Zp.T @ P @ Zp
    Pf = p.F[lag].T @ pi - st.norm
    for lv, M, mv in zip(lam, p.Mq, p.mq, strict=True):
        Pq = Pq - lv * M
        Pf = Pf - lv * mv
    return {"D": D, "Df": Df, "Pq": Pq, "Pf": Pf}


AUTO_LAG_EXTRA = 3  # without a given lag, the analysis tries the lags n - 1 .. n + 3 (<= 8)


class Interpolation(CertificateFamily):
    """Lyapunov functions with interpolation conditions, lag l given or (``lag=None``)
    chosen by the analysis among :meth:`auto_lags` (its problem is then that of l = n - 1)."""

    name = "interpolation"
    label = "interpolation"
    is_default = False
    supports_moment = False  # the moment relaxation is built on Theorem 1's M
    box_lower_bound = False  # no exact_problem: design proves no box-wide lower bound
    certificate_parts = ("P", "p", "lag")
    option_names = ("lag",)
    tight = True  # its rate is often the rate on quadratics: the search starts there
    # points the margin search cannot check sit on a degenerate boundary (tight rates),
    # where SCS only runs into its iteration limit: Clarabel alone is asked
    fallback_solvers = ("clarabel-fast", "clarabel")
    description = ("interpolation: V = z'Pz + sum p_j (f(y_{k-j}) - f*) + c (f(x_k) - f*), "
                   "F(m, L) interpolation inequalities (tight)")

    def __init__(self, lag: int | None = None):
        if lag is not None and (not isinstance(lag, int) or isinstance(lag, bool)
                                or not 0 <= lag <= 8):
            raise ValueError("lag: must be an integer in 0..8")
        self.lag = lag
        # oracle calls per iteration of the specs it serves (sizes P and the CSV columns;
        # set by :meth:`for_inputs`, not an option)
        self.inputs = 1

    def for_inputs(self, p: int) -> Interpolation:
        """A copy sized for methods with ``p`` oracle calls per iteration."""
        fam = Interpolation(self.lag)
        fam.inputs = int(p)
        return fam

    def lag_for(self, n: int) -> int:
        """The lag of :meth:`problem`: the given one, else n - 1 (the first auto lag)."""
        return n - 1 if self.lag is None else self.lag

    def auto_lags(self, n: int) -> tuple[int, ...]:
        """The lags the analysis tries, in order, when none is given: n - 1 .. n + 3 (at
        most 8; see :func:`sosalgo.analysis.analyze_algorithm`); () for a given lag."""
        if self.lag is not None:
            return ()
        return tuple(range(max(n - 1, 0), min(n + AUTO_LAG_EXTRA, 8) + 1))

    def fallback_lags(self, n: int) -> tuple[int, ...]:
        """Lags below :meth:`auto_lags` that the choice of lag also tries, after the others,
        each only where it beats the best rate by the tolerance: lag 0, the smallest and
        best-conditioned problem. A certificate of a smaller lag is one of a larger lag
        (the windows' directions where every matrix vanishes removed, see
        :func:`sosalgo.certificates.composite.facial_reduction`), but near kappa 1000 the
        solver may still certify a slightly slower rate at a larger lag (Chambolle-Pock
        with unit steps: 0.9993 at lag 2, 0.9990 at lag 0). () for a given lag."""
        lags = self.auto_lags(n)
        return (0,) if lags and lags[0] > 0 else ()

    def has_null_directions(self, alg: Algorithm, lag: int) -> bool:
        """Whether a window of lag ``lag`` has directions where every certificate's matrices
        vanish (:func:`null_directions`, on the oracle model
        :func:`sosalgo.certificates.composite.isotropic_directions`): its certificates then
        have exact zero eigenvalues there."""
        if not alg.has_seed_form:
            from sosalgo.certificates.composite import composite_structure

            st = composite_structure(alg, lag)
        else:
            st = self._structure(alg, normalized=True, lag=lag)
        return any(w.iso is not None and w.iso.shape[1] > 0 for w in (st.dec, st.pos))

    def searches_past_certified(self, alg: Algorithm) -> bool:
        """With one oracle call per iteration, larger lags are tried (see
        :func:`sosalgo.analysis.analyze_algorithm`). With p >= 2 calls the lifted state grows
        by p per lag and each further lag's LMI is several times larger (accelerated proximal
        gradient: 86 unknowns at l = 1, 200 at l = 3, a 20x longer solve); on no shipped
        composite spec does a larger lag certify a better rate, so the first lag that
        certifies is kept (larger ones are tried only while none does; ``--lag`` asks for
        one)."""
        return alg.p == 1

    def max_lag(self, n: int) -> int:
        """The largest lag a certificate of this family can have (sizes the CSV columns)."""
        lags = self.auto_lags(n)
        return lags[-1] if lags else self.lag_for(n)

    def with_options(self, lag: int | None = None) -> Interpolation:
        return Interpolation(lag).for_inputs(self.inputs)

    # -- layout of the decision vector -----------------------------------------------------
    def _layout(self, st: Structure) -> dict[str, slice]:
        nP = st.nz * (st.nz + 1) // 2
        k1 = nP + st.npi
        k2 = k1 + len(st.dec.labels)
        return {"P": slice(0, nP), "pi": slice(nP, k1), "eta": slice(k1, k2),
                "lam": slice(k2, k2 + len(st.pos.labels))}

    def _structure(self, alg: Algorithm, normalized: bool, has_x: bool | None = None,
                   lag: int | None = None) -> Structure:
        lag = self.lag_for(alg.n) if lag is None else lag
        hx = has_output_point(alg.C, alg.E) if has_x is None else has_x
        if normalized:
            return structure(alg.A, alg.B * alg.L, alg.C, alg.E, alg.m / alg.L, 1.0, lag, hx)
        return structure(alg.A, alg.B, alg.C, alg.E, alg.m, alg.L, lag, hx)

    def problem(self, alg: Algorithm) -> LMIProblem:
        """Affine blocks in x = (P_ab (a <= b), p_0..p_l, c, eta, lambda), built for the
        normalized class F(m/L, 1) with B scaled by L; ``unpack`` returns original units.
        A method of the oracle model (several calls, proximal steps, other classes) gets
        the generic construction of :mod:`sosalgo.certificates.composite`."""
        if not alg.has_seed_form:
            from sosalgo.certificates.composite import composite_problem

            return composite_problem(alg, self.lag_for(alg.n), self.name)
        return self._problem(alg, None)

    def guess_problem(self, alg: Algorithm) -> LMIProblem | None:
        """The cheapest member of the family, lag 0 without the output point (as if E = C:
        no x-points, no c), or None when that is :meth:`problem` itself. The analysis uses
        its margin only to guess where the rate is; every certified rate and bracket end
        comes from :meth:`problem`. Its rate is usually the family's up to the search
        tolerance (the tight rate does not depend on E: a certificate with V positive
        definite dominates a multiple of f(x_k) - f* for any E; lag 0 and lag 1 agree on
        gradient descent, Nesterov and triple momentum), and it is 3-5x cheaper to solve
        (blocks 4x4 and 3x3, 15 variables, instead of 7x7 and 5x5, 55 variables, for
        n = 2, l = 1). Where the rates differ (heavy ball, lag 1), the search goes on."""
        if not alg.has_seed_form:
            return None if self.lag_for(alg.n) == 0 else Interpolation(0).problem(alg)
        if self.lag_for(alg.n) == 0 and not has_output_point(alg.C, alg.E):
            return None
        return Interpolation(0)._problem(alg, False)

    def _problem(self, alg: Algorithm, has_x: bool | None) -> LMIProblem:
        st = self._structure(alg, normalized=True, has_x=has_x)
        lay = self._layout(st)
        pairs = sym_basis(st.nz)
        nvar = lay["lam"].stop
        d, p, lag = st.dec, st.pos, st.lag
        Z1, Z0, Zp = d.Z[lag + 1], d.Z[lag], p.Z[lag]
        sD, sP = d.width, p.width
        D0, D1 = np.zeros((nvar, sD, sD)), np.zeros((nvar, sD, sD))
        P0 = np.zeros((nvar, sP, sP))
        nP = len(pairs)
        D0[:nP] = unit_quads(Z1, pairs)
        D1[:nP] = -unit_quads(Z0, pairs)
        P0[:nP] = -unit_quads(Zp, pairs)
        for k, M in enumerate(d.Mq):
            D0[lay["eta"].start + k] = M
        for k, M in enumerate(p.Mq):
            P0[lay["lam"].start + k] = M
        D0, D1 = compress(complement_basis(d.iso), D0, D1)
        (P0,) = compress(complement_basis(p.iso), P0)
        sD, sP = D0.shape[1], P0.shape[1]
        blocks = [
            AffineBlock("decrease", np.zeros((sD, sD)), np.zeros((sD, sD)), D0, D1),
            AffineBlock("positivity", np.zeros((sP, sP)), np.zeros((sP, sP)), P0,
                        np.zeros_like(P0)),
        ]
        one = np.zeros((1, 1))
        zero = np.zeros((nvar, 1, 1))  # shared (read-only) rho^2 part of the rho-free rows
        zero.flags.writeable = False
        # the scalar rows, all at once: row q of S0 (S1) is l0 (l1) of one 1x1 block
        npos, nmult = p.nphi, nvar - lay["eta"].start
        S0 = np.zeros((d.nphi + npos + nmult, nvar))
        S1 = np.zeros((d.nphi, nvar))
        S0[: d.nphi, lay["pi"]] = d.F[lag + 1].T
        S1[:, lay["pi"]] = -d.F[lag].T
        if d.mq:
            S0[: d.nphi, lay["eta"]] = np.array(d.mq).T
        S0[d.nphi: d.nphi + npos, lay["pi"]] = -p.F[lag].T
        if p.mq:
            S0[d.nphi: d.nphi + npos, lay["lam"]] = np.array(p.mq).T
        S0[d.nphi + npos + np.arange(nmult), lay["eta"].start + np.arange(nmult)] = -1.0
        col0, col1 = S0[:, :, None, None], S1[:, :, None, None]
        for q in range(d.nphi):
            blocks.append(AffineBlock(f"decrease-f[{q}]", one, one, col0[q], col1[q]))
        for q in range(npos):
            blocks.append(AffineBlock(f"positivity-f[{q}]", np.full((1, 1), st.norm[q]), one,
                                      col0[d.nphi + q], zero, strict=False))
        for k in range(nmult):
            blocks.append(AffineBlock(f"mult[{k}]", one, one, col0[d.nphi + npos + k], zero,
                                      strict=False))
        blocks.append(AffineBlock("normalization", -np.ones((1, 1)), one, zero, zero))
        Fp = p.F[lag]
        mpos = np.array(p.mq) if p.mq else np.zeros((0, p.nphi))

        def project(x: np.ndarray) -> np.ndarray:
            x = np.array(x, dtype=float)
            x[lay["eta"]] = np.maximum(x[lay["eta"]], 0.0)
            x[lay["lam"]] = np.maximum(x[lay["lam"]], 0.0)
            lam = x[lay["lam"]]
            pi = x[lay["pi"]]
            for q in range(p.nphi):  # raise p_j (or c) until positivity-f[q] holds exactly
                j = int(np.flatnonzero(Fp[:, q])[0])
                terms = lam * mpos[:, q]
                need = float(st.norm[q]) + float(np.sum(terms))
                need += 1e-13 * (1.0 + float(np.sum(np.abs(terms))))
                pi[j] = max(pi[j], need)
            x[lay["pi"]] = pi
            return x

        def unpack(x: np.ndarray) -> dict[str, Any]:
            return self._unpack(st, lay, alg.L, x)

        return LMIProblem(nvar, tuple(blocks), unpack, project)

    def _unpack(self, st: Structure, lay: dict[str, slice], L: float,
                x: np.ndarray) -> dict[str, Any]:
        """Original units: with u = L u~, V = L V~ gives P = L D^-1 P~ D^-1 (D = diag(I_n,
        L I_{l+1})), p = p~, c = c~, and q_ij = L^2 q~_ij gives eta = eta~/L, lambda = lambda~/L."""
        Pn = np.zeros((st.nz, st.nz))
        for k, (a, b) in enumerate(sym_basis(st.nz)):
            Pn[a, b] = Pn[b, a] = x[lay["P"]][k]
        dinv = np.concatenate([np.ones(st.n), np.full(st.lag + 1, 1.0 / L)])
        P = (L * dinv)[:, None] * Pn * dinv[None, :]  # L D^-1 first: no overflow at tiny L
        pi = [float(v) for v in x[lay["pi"]]]
        return {
            "family": self.name,
            "lag": st.lag,
            "P": P,
            "p": pi[: st.lag + 1],
            "c": pi[st.lag + 1] if st.has_x else None,
            "multipliers": {
                "decrease": {lab: float(v) / L for lab, v in zip(st.dec.labels, x[lay["eta"]],
                                                                 strict=True)},
                "positivity": {lab: float(v) / L for lab, v in zip(st.pos.labels, x[lay["lam"]],
                                                                   strict=True)},
            },
        }

    def parts(self, alg: Algorithm, rho: float, cert: dict[str, Any]) -> dict[str, Any]:
        """The inequality parts (D, Df, Pq, Pf) at a certificate (at its own lag), original
        units (floats)."""
        if not alg.has_seed_form:
            from sosalgo.certificates.composite import composite_parts

            return composite_parts(alg, rho, cert)
        st = self._structure(alg, normalized=False, lag=int(cert["lag"]))
        pi = np.array(list(cert["p"]) + ([cert["c"]] if st.has_x else []), float)
        mult = cert["multipliers"]
        eta = [mult["decrease"][k] for k in st.dec.labels]
        lam = [mult["positivity"][k] for k in st.pos.labels]
        return evaluate(st, rho**2, np.asarray(cert["P"], float), pi, eta, lam)

    def matrix(self, alg: Algorithm, rho: float, cert: dict[str, Any]) -> np.ndarray:
        """The decrease matrix (D) at a numeric certificate (original units)."""
        return self.parts(alg, rho, cert)["D"]

    def summary(self, alg: Algorithm, rho: float, cert: dict[str, Any]) -> dict[str, float]:
        """max eig of (D) (<= 0) and min eig of the positivity matrix (>= 0); on the oracle
        model without the directions where every certificate's matrices vanish
        (:func:`sosalgo.certificates.composite.reduced_summary`); each without the directions
        where every matrix of its window vanishes (:func:`null_directions`)."""
        if not alg.has_seed_form:
            from sosalgo.certificates.composite import reduced_summary

            return reduced_summary(alg, rho, cert)
        pt = self.parts(alg, rho, cert)
        st = self._structure(alg, normalized=False, lag=int(cert["lag"]))
        return {"max_eig_M": float(restricted_eigenvalues(pt["D"], st.dec.iso)[-1]),
                "min_eig_P": float(restricted_eigenvalues(pt["Pq"], st.pos.iso)[0])}

    # -- tables ------------------------------------------------------------------------------
    def p_size(self, n: int) -> int:
        """Side of the P of the leading CSV columns P11...: that of :meth:`problem`'s lag
        (a larger auto lag's further entries have columns of their own, see
        :meth:`csv_columns`)."""
        return n + self.inputs * (self.lag_for(n) + 1)

    def _extra_entries(self, n: int, side: int) -> list[tuple[str, int, int]]:
        """(column, i, j) of the entries of a side x side P beyond the leading columns."""
        k = self.p_size(n)
        return [(f"P{i + 1}{j + 1}", i, j) for i in range(side) for j in range(max(i, k), side)]

    def csv_columns(self, n: int) -> list[str]:
        """Extra CSV columns (after the common ones): family, lag, p0..pl, c, multipliers,
        then (auto lag) the entries of P beyond the leading ones, up to the largest lag."""
        top, k = self.max_lag(n), self.inputs
        return (["family", "lag"] + [f"p{j}" for j in range(k * (top + 1))]
                + ["c", "multipliers"]
                + [name for name, _, _ in self._extra_entries(n, n + k * (top + 1))])

    def csv_cells(self, n: int, cert: Mapping[str, Any] | None) -> dict[str, Any]:
        """CSV cells of a certificate (multipliers as one JSON object: pair -> value); the
        lag is the certificate's (empty without one when the lag is chosen)."""
        out: dict[str, Any] = {"family": self.name, "lag": self.lag}
        if cert is None:
            return out
        out["lag"] = int(cert["lag"])
        out.update({f"p{j}": float(v) for j, v in enumerate(cert["p"])})
        out["c"] = cert["c"]
        out["multipliers"] = json.dumps(cert["multipliers"], separators=(",", ":"))
        P = np.asarray(cert["P"], dtype=float)
        out.update({name: float(P[i, j]) for name, i, j in self._extra_entries(n, len(P))})
        return out

    def cert_from_csv(self, n: int, row: Mapping[str, str], P: Any) -> dict[str, Any] | None:
        """Inverse of :meth:`csv_cells` (None when the row has no certificate); ``P`` is the
        matrix of the leading columns, completed from the further ones to the row's lag."""
        if P is None or not row.get("multipliers"):
            return None
        lag = int(row["lag"])
        side = n + self.inputs * (lag + 1)
        full = np.zeros((side, side))
        lead = np.asarray(P, dtype=float)[:side, :side]
        full[: len(lead), : len(lead)] = lead
        for name, i, j in self._extra_entries(n, side):
            full[i, j] = full[j, i] = float(row[name])
        return {"family": self.name, "lag": lag, "P": full.tolist(),
                "p": [float(row[f"p{j}"]) for j in range(self.inputs * (lag + 1))
                      if row.get(f"p{j}") not in (None, "")],
                "c": float(row["c"]) if row.get("c") else None,
                "multipliers": json.loads(row["multipliers"])}

    def symbolic(self, A, B, C, E, m, L) -> tuple[sp.Matrix, dict[str, Any]]:
        """Symbolic row maps and interpolation pairs; the returned matrix is the decrease
        block (D) with symbolic P, p, c and multipliers (large: printed on request)."""
        import sympy as sp

        n = A.shape[0]
        lag = self.lag_for(n)
        hx = any(sp.simplify(C[0, j] - E[0, j]) != 0 for j in range(n))
        st = structure(*(np.array(M.tolist(), dtype=object) for M in (A, B, C, E)), m, L, lag,
                       hx, obj=True)
        P = sp.zeros(st.nz, st.nz)
        for i, j in sym_basis(st.nz):
            P[i, j] = P[j, i] = sp.Symbol(f"P{i + 1}{j + 1}", real=True)
        rho = sp.Symbol("rho", nonnegative=True)
        return sp.Matrix(st.dec.Z[lag + 1]), {
            "P": P, "rho": rho, "structure": st, "lag": lag, "has_x": hx,
        }

    def listing(self, spec: Spec, symbols: dict[str, Any], latex: bool) -> str:
        """Its ``sosalgo lmi`` text: windows, Lyapunov function, interpolation pairs."""
        from sosalgo.certificates.listing import interpolation_listing

        return interpolation_listing(spec, symbols, latex)

    def exact_problem(self, A, B, C, E, m, L) -> None:
        """None: P is not sign-constrained here (its positivity comes from the S-procedure),
        so design has no box-wide dual bound for this family (see ``design``)."""
        return None

    # -- verification (sosalgo verify) ---------------------------------------------------
    def parse_certificate(self, parts: Mapping[str, Any], n: int) -> dict[str, Any]:
        """The parts as given: the exact check itself fails a malformed certificate."""
        return dict(parts)

    def exact_structure(self, A, B, C, E, m, L, lag: int, has_x: bool) -> Structure:
        """The windows of the method on exact numbers (object arrays: rationals, balls)."""
        return structure(A, B, C, E, m, L, lag, has_x, obj=True)

    def exact_parts(self, st: Structure, r: Any, P: Any, pi: Any, eta: Any,
                    lam: Any) -> dict[str, Any]:
        """(D, Df, Pq, Pf) at a certificate on exact numbers (see :func:`evaluate`)."""
        return evaluate(st, r, P, pi, eta, lam)

    def exact_check(self, spec: Spec, kappa: float, rho: float, cert: Mapping[str, Any],
                    theta: Mapping[str, float] | None = None, **options: Any) -> Any:
        """Exact rational proof of (D) and (P), the certificate's own lag
        (:func:`sosalgo.certificates.exact_interpolation.verify_exact_interpolation`; on the
        oracle model :func:`sosalgo.certificates.exact_composite.verify_exact_composite`)."""
        if not spec.has_seed_form:
            from sosalgo.certificates.exact_composite import verify_exact_composite

            return verify_exact_composite(spec, kappa, rho, cert, theta, **options)
        from sosalgo.certificates.exact_interpolation import verify_exact_interpolation

        return verify_exact_interpolation(spec, kappa, rho, cert, theta, family=self, **options)

    def lyapunov(self, cert: Mapping[str, Any]) -> dict[str, Any]:
        """V = z'Pz + sum p_j (f(y_{k-j}) - f*) + c (f(x_k) - f*) on z = (xi, u_k..u_{k-l})."""
        return {"P": np.asarray(cert["P"], dtype=float),
                "lyapunov": {"lag": int(cert["lag"]), "p": [float(v) for v in cert["p"]],
                             "c": None if cert.get("c") is None else float(cert["c"])}}


INTERPOLATION = Interpolation()
