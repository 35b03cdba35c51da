"""The interpolation family on the oracle model: several functions, proximal steps, measures.

Written for :class:`sosalgo.oracles.OracleMethod` (xi+ = A xi + B u, y = C xi + D u,
u_i in ∂f_{j(i)}(y_i), output x = E xi or a call's point y_o). Deviations from a fixed point
with x* = 0 (every class is invariant under translation) and optimal subgradients s_j*
(sum 0): each function is replaced by its tilted version

    h_j(z) = f_j(z) - f_j* - <s_j*, z - x*> >= 0,   ∂h_j(z) = ∂f_j(z) - s_j*,

minimal (0) at x* with subgradient 0 there, so that every call sees the seed's setting
(Taylor, Van Scoy, Lessard 2018): its input deviation u~ = u - s_j* is a subgradient of
h_j, every function value h_j >= 0, and the dynamics of the deviations are linear
because the fixed point exists for every x* and s* (:mod:`sosalgo.oracles`). A class
whose interpolation inequalities are invariant under adding linear functions (smooth,
convex, strongly convex) gives h_j the same inequalities; a class that is not (indicators)
gives its ``tilted`` inequalities (:meth:`sosalgo.classes.base.FunctionClass.tilted`).
The measures are exact in these terms: sum_j f_j(x) - f_j* = sum_j h_j(x) (the s_j* sum to
0) and |x - x*|^2. The Lyapunov function, lag l,

    V_k = z_k' P z_k + sum_{t=0..l} sum_i p_{t,i} h_{j(i)}(y_{k-t,i}) + c sum_j h_j(x_k),

z_k = (xi_k - xi*, u~_k, ..., u~_{k-l}); c is present only when some function is evaluated
at the output point beside the calls (``measure: function``, a smooth function there, with
a free subgradient). Conditions (D), (Df), (P), (Pf) as in
:mod:`sosalgo.certificates.interpolation`, with the class's inequalities between all
ordered pairs of points of each function: its calls in the window, its optimal point
(0, 0, 0) and, for ``measure: function``, the output point. ``measure: function`` puts
sum_j h_j(x_l) in (Pf), ``measure: distance`` puts |x_l|^2 in (P).

Units: the inputs are scaled by s = L (u = s u~, psi = s psi~) and each inequality by its
largest coefficient, for the solver; :func:`unpack` returns original units.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sosalgo.certificates.base import complement_basis, compress, null_basis, restricted_eigenvalues
from sosalgo.kernel.conic import AffineBlock, LMIProblem, sym_basis, unit_quads

__all__ = ["STATE_CHANGE", "CompositeStructure", "composite_problem", "composite_parts",
           "composite_structure", "facial_reduction", "isotropic_directions",
           "reduced_summary", "residual_measured",
           "sublinear_measure"]


@dataclass
class _Point:
    func: int
    label: str
    x: np.ndarray  # row on w: the point minus x*
    g: np.ndarray  # row on w: the subgradient, in units of s
    psi: int | None  # its psi in phi (None: the optimum or an operator, no values)


@dataclass
class CWindow:
    """Row maps, Lyapunov selections, inequalities and measure of one window."""

    width: int
    nphi: int
    Z: dict[int, np.ndarray]
    F: dict[int, np.ndarray]
    labels: list[str]
    Mq: np.ndarray  # (k, width, width) quadratic parts of the inequalities
    mq: np.ndarray  # (k, nphi) their parts on phi
    sigma: np.ndarray  # (k,) the scale each inequality was divided by
    meas_lin: np.ndarray  # (nphi,) the measure at time l (positivity window)
    meas_quad: np.ndarray  # (width, width)
    # (width, k) orthonormal basis of the window's isotropic directions (see
    # :func:`isotropic_directions`); (width, 0) when there are none
    iso: np.ndarray | None = None


@dataclass
class CompositeStructure:
    n: int
    p: int
    lag: int
    npi: int
    has_c: bool
    dec: CWindow
    pos: CWindow

    @property
    def nz(self) -> int:
        return self.n + self.p * (self.lag + 1)


def output_call(om: Any) -> int | None:
    """The call whose point is the output: ``output: y<i>``, or a gradient call i with
    C_i = E and D_i = 0 (then x = y_i and the output needs no point of its own)."""
    if om.output is not None or om.E is None:
        return om.output
    scale = max(1.0, float(np.abs(om.E).max()))
    for i in range(om.p):
        if (np.abs(om.C[i] - om.E[0]).max() <= 1e-14 * scale
                and not np.any(om.D[i])):
            return i
    return None


def _layout(om: Any, steps: int, lag: int) -> tuple[list[int], list[int], int]:
    """(output times, functions evaluated at the output beside the calls, width)."""
    J = len(om.functions)
    x_times: list[int] = []
    extra: list[int] = []
    if om.measure == "function":
        x_times = [t for t in (steps - 2, steps - 1) if t >= lag]
        oc = output_call(om)
        out_f = None if oc is None else om.oracles[oc]
        extra = [j for j in range(J) if j != out_f]
    width = om.n + om.p * steps + len(extra) * len(x_times)
    return x_times, extra, width


def _points(om: Any, steps: int, lag: int, s: float):
    """Rows of the window (Xi, U, Y, output rows, S rows) and the points of each function."""
    n, p, J = om.n, om.p, len(om.functions)
    x_times, extra, width = _layout(om, steps, lag)
    eye = np.eye(width)
    U = [eye[n + p * t: n + p * (t + 1)] for t in range(steps)]
    Xi = [eye[:n]]
    for t in range(steps - 1):
        Xi.append(om.A @ Xi[t] + (s * om.B) @ U[t])
    Y = [om.C @ Xi[t] + (s * om.D) @ U[t] for t in range(steps)]
    out = {t: (Y[t][om.output] if om.output is not None else (om.E @ Xi[t])[0])
           for t in range(steps)}
    pts: list[list[_Point]] = [[] for _ in range(J)]
    npsi = 0
    valued = [getattr(fn.cls, "has_values", True) for fn in om.functions]  # operator: none
    for t in range(steps):
        for i, j in enumerate(om.oracles):
            pts[j].append(_Point(j, f"y{i + 1}[{t}]", Y[t][i], U[t][i],
                                 npsi if valued[j] else None))
            npsi += valued[j]
    k = n + p * steps
    for t in x_times:
        for j in extra:
            pts[j].append(_Point(j, f"x[{t}]", out[t], eye[k], npsi))
            npsi += 1
            k += 1
    for j in range(J):
        pts[j].append(_Point(j, "*", np.zeros(width), np.zeros(width), None))
    return {"Xi": Xi, "U": U, "out": out, "x_times": x_times, "width": width}, pts, npsi


def _value(pt: _Point, nphi: int, s: float) -> np.ndarray:
    """h_j(point) on phi: s psi~ (0 at the optimum)."""
    lin = np.zeros(nphi)
    if pt.psi is not None:
        lin[pt.psi] = s
    return lin


def _inequalities(om: Any, pts: list, nphi: int, s: float, rescale: bool):
    """Labels, quadratic and phi parts, scales of every (tilted) class inequality of every
    ordered pair of points of one function."""
    labels, Ms, ms, sig = [], [], [], []
    gs = np.diag([1.0, 1.0, s, s])
    width = len(pts[0][0].x)
    for j, fn in enumerate(om.functions):
        ineqs = fn.cls.tilted(fn.params)
        vals = [_value(pt, nphi, s) for pt in pts[j]]
        for a, pa in enumerate(pts[j]):
            for b, pb in enumerate(pts[j]):
                if a == b:
                    continue
                X = gs @ np.vstack([pa.x, pb.x, pa.g, pb.g])
                for r, ineq in enumerate(ineqs):
                    lin = ineq.alpha * (vals[a] - vals[b])
                    quad = X.T @ ineq.Q @ X
                    scale = max(float(np.abs(lin).max(initial=0.0)), float(np.abs(quad).max()))
                    scale = scale if rescale and scale > 0 else 1.0
                    tag = "" if len(ineqs) == 1 else f"#{r}"
                    labels.append(f"{fn.name}:{pa.label}>{pb.label}{tag}")
                    Ms.append(quad / scale)
                    ms.append(lin / scale)
                    sig.append(scale)
    return (labels, np.array(Ms).reshape(-1, width, width), np.array(ms).reshape(len(ms), nphi),
            np.array(sig))


def _window(om: Any, lag: int, steps: int, s: float, rescale: bool) -> CWindow:
    rows, pts, nphi = _points(om, steps, lag, s)
    Xi, U = rows["Xi"], rows["U"]
    labels, Mq, mq, sigma = _inequalities(om, pts, nphi, s, rescale)
    valued = range(om.p)
    psi_of = {pt.label: pt.psi for fp in pts for pt in fp if pt.psi is not None}
    Z, F = {}, {}
    for t in range(lag, steps):
        Z[t] = np.vstack([Xi[t]] + [U[t - tau] for tau in range(lag + 1)])
        sel = [[psi_of[lab]] if (lab := f"y{i + 1}[{t - tau}]") in psi_of else []
               for tau in range(lag + 1) for i in valued]  # []: an operator's call
        xs = [pt.psi for fp in pts for pt in fp if pt.label == f"x[{t}]"]
        if any(pt.label.startswith("x[") for fp in pts for pt in fp):
            sel.append(xs)
        Ft = np.zeros((len(sel), nphi))
        for r, cols in enumerate(sel):
            Ft[r, cols] = 1.0
        F[t] = Ft
    meas_lin, meas_quad = _measure(om, pts, rows, steps - 1, nphi, s)
    iso = isotropic_directions(om, pts, Z, meas_quad)
    return CWindow(rows["width"], nphi, Z, F, labels, Mq, mq, sigma, meas_lin, meas_quad, iso)


def isotropic_directions(om: Any, pts: list, Z: dict[int, np.ndarray],
                         meas_quad: np.ndarray) -> np.ndarray:
    """Orthonormal basis (width x k) of the directions w of a window on which every
    quadratic form of the certificate is 0 whatever the certificate: each row map z_t is 0,
    every subgradient is 0, the measure's point does not move, and the only points that move
    are those of functions whose inequalities have no |x_a - x_b|^2 part (convex,
    indicators: with zero subgradients their forms vanish). With a lag l >= 1 and a singular
    A such directions exist (the part of xi_0 that A^l kills but a call still sees:
    Chambolle-Pock's state in ker A moves only its dual call's point).

    Along such a w, (D) ⪯ 0 and (P) ⪰ 0 force D w = 0 and Pq w = 0: no certificate is
    strictly feasible, and a solver asked for a margin finds none although lag l - 1's
    certificate (padded) is feasible. See :func:`facial_reduction`."""
    rows = [Zt for Zt in Z.values()] + [np.array([pt.g for fp in pts for pt in fp])]
    rows += [meas_quad]
    for j, fn in enumerate(om.functions):
        if any(np.any(ineq.Q[:2, :2] != 0) for ineq in fn.cls.tilted(fn.params)):
            rows.append(np.array([pt.x for pt in pts[j]]))
    return null_basis(np.vstack(rows))


def facial_reduction(win: CWindow) -> tuple[np.ndarray | None, np.ndarray]:
    """(Q, drop) for a window's matrix block: the multipliers to fix at 0 (``drop``, a
    boolean mask over the inequalities: those whose form does not vanish on the isotropic
    directions W, for G w = 0 on W) and an orthonormal basis Q of the complement of W
    (None when W = {0}), so that G ⪯ 0 is the same as Q' G Q ⪯ 0 on what is left.

    Sound: it only removes certificates (dropped multipliers are 0), and Q' G Q ⪯ 0 with
    G W = 0 is G ⪯ 0. Nesting: a certificate of lag l - 1, padded, uses none of the
    dropped multipliers (its forms vanish on the isotropic directions of lag l, which the
    shift maps into those of lag l - 1; at lag 0 there are none), so it stays a
    certificate of the reduced lag-l problem."""
    W = win.iso
    k = len(win.Mq)
    if W is None or W.shape[1] == 0:
        return None, np.zeros(k, dtype=bool)
    MW = np.abs(win.Mq @ W).reshape(k, -1).max(axis=1, initial=0.0)
    size = np.abs(win.Mq).reshape(k, -1).max(axis=1, initial=0.0)
    drop = MW > 1e-9 * np.maximum(size, 1e-300)
    return complement_basis(W), drop


STATE_CHANGE = "state_change"  # |xi_k+1 - xi_k|^2: several operators (optimum moves)


def residual_measured(om: Any) -> Any:
    """The method measured as the family measures it: for one operator only (no function
    values), ``measure: residual``, sum_i |u_i|^2 of the calls at time k (u = x - T x for a
    nonexpansive T; x_k - x_{k+1} = alpha u for a resolvent step); for several operators
    (their optimal answers s_j* sum to 0 but need not be 0) :data:`STATE_CHANGE`,
    |xi_{k+1} - xi_k|^2, which does not see s*; else ``om`` itself."""
    from dataclasses import replace

    if om.functions and all(not fn[1].has_values for fn in om.functions):
        return replace(om, measure="residual" if len(om.functions) == 1 else STATE_CHANGE)
    return om


def sublinear_measure(spec: Any) -> str:
    """The measure of the family's constant for ``spec``: ``residual`` (sum_i |u_i|^2 of
    the calls at time k) when every function is an operator class, else the spec's own."""
    from sosalgo.classes import CLASSES

    if spec.functions and all(not CLASSES[d.cls].has_values for d in spec.functions.values()):
        return "residual" if len(spec.functions) == 1 else STATE_CHANGE
    return spec.measure


def _measure(om: Any, pts: list, rows: dict, t: int, nphi: int,
             s: float) -> tuple[np.ndarray, np.ndarray]:
    """The measure at time t, divided by its unit (s for function values)."""
    if om.measure == "distance":
        xo = rows["out"][t]
        return np.zeros(nphi), np.outer(xo, xo)
    if om.measure == "residual":  # sum_i |u_i|^2 of the calls at t (u = s u~), over s
        return np.zeros(nphi), s * rows["U"][t].T @ rows["U"][t]
    if om.measure == STATE_CHANGE:  # |xi_t+1 - xi_t|^2 = |(A - I) xi~_t + B u~_t|^2
        dx = (om.A - np.eye(om.n)) @ rows["Xi"][t] + (s * om.B) @ rows["U"][t]
        return np.zeros(nphi), dx.T @ dx
    lin = np.zeros(nphi)
    oc = output_call(om)
    here = {f"x[{t}]"} | ({f"y{oc + 1}[{t}]"} if oc is not None else set())
    for fp in pts:
        for pt in fp:
            if pt.label in here:
                lin = lin + _value(pt, nphi, s) / s
    return lin, np.zeros((rows["width"], rows["width"]))


def composite_structure(om: Any, lag: int, s: float = 1.0,
                        rescale: bool = False) -> CompositeStructure:
    """Both windows of an oracle method for lag ``lag`` (units s; see the module)."""
    dec = _window(om, lag, lag + 2, s, rescale)
    pos = _window(om, lag, lag + 1, s, rescale)
    npi = pos.F[lag].shape[0]
    has_c = npi > om.p * (lag + 1)
    return CompositeStructure(om.n, om.p, lag, npi, has_c, dec, pos)


def _layout_x(st: CompositeStructure) -> dict[str, slice]:
    nP = st.nz * (st.nz + 1) // 2
    k1 = nP + st.npi
    k2 = k1 + len(st.dec.labels)
    return {"P": slice(0, nP), "pi": slice(nP, k1), "eta": slice(k1, k2),
            "lam": slice(k2, k2 + len(st.pos.labels))}


def reductions(st: CompositeStructure, lay: dict[str, slice]):
    """(Q of (D), Q of (P), indices into x of the multipliers fixed at 0) by
    :func:`facial_reduction` of both windows."""
    Qd, drop_d = facial_reduction(st.dec)
    Qp, drop_p = facial_reduction(st.pos)
    gone = np.concatenate([np.arange(lay["eta"].start, lay["eta"].stop)[drop_d],
                           np.arange(lay["lam"].start, lay["lam"].stop)[drop_p]])
    return Qd, Qp, gone


def _blocks(st: CompositeStructure, lay: dict[str, slice]) -> list[AffineBlock]:
    """(D), (P) and the scalar rows, as in the seed's interpolation family; the measure is
    the constant of (P) (distance) or of (Pf) (function values). Both matrix blocks are
    restricted to the complement of their isotropic directions, the multipliers that do
    not vanish there fixed at 0 (:func:`facial_reduction`)."""
    d, p, lag = st.dec, st.pos, st.lag
    pairs = sym_basis(st.nz)
    nvar, nP = lay["lam"].stop, len(pairs)
    sD, sP = d.width, p.width
    D0, D1, P0 = np.zeros((nvar, sD, sD)), np.zeros((nvar, sD, sD)), np.zeros((nvar, sP, sP))
    D0[:nP] = unit_quads(d.Z[lag + 1], pairs)
    D1[:nP] = -unit_quads(d.Z[lag], pairs)
    P0[:nP] = -unit_quads(p.Z[lag], pairs)
    D0[lay["eta"]] = d.Mq
    P0[lay["lam"]] = p.Mq
    Qd, Qp, gone = reductions(st, lay)
    D0[gone], D1[gone], P0[gone] = 0.0, 0.0, 0.0
    D0c, D1c, zd = compress(Qd, D0, D1, np.zeros((sD, sD)))
    P0c, mqc = compress(Qp, P0, p.meas_quad)
    blocks = [AffineBlock("decrease", zd, zd, D0c, D1c),
              AffineBlock("positivity", mqc, np.zeros_like(mqc), P0c, np.zeros_like(P0c))]
    return blocks + _scalar_blocks(st, lay, gone)


def _scalar_blocks(st: CompositeStructure, lay: dict[str, slice],
                   gone: np.ndarray) -> list[AffineBlock]:
    """(Df), (Pf), the multipliers' signs and the normalization, as 1 x 1 blocks."""
    d, p, lag = st.dec, st.pos, st.lag
    nvar = lay["lam"].stop
    one, zero = np.zeros((1, 1)), np.zeros((nvar, 1, 1))
    zero.flags.writeable = False
    nmult = nvar - lay["eta"].start
    S0 = np.zeros((d.nphi + p.nphi + nmult, nvar))
    S1 = np.zeros((d.nphi, nvar))
    S0[: d.nphi, lay["pi"]] = d.F[lag + 1].T
    S1[:, lay["pi"]] = -d.F[lag].T
    S0[: d.nphi, lay["eta"]] = d.mq.T
    S0[d.nphi: d.nphi + p.nphi, lay["pi"]] = -p.F[lag].T
    S0[d.nphi: d.nphi + p.nphi, lay["lam"]] = p.mq.T
    S0[: d.nphi + p.nphi, gone] = 0.0  # a dropped multiplier is only bounded (mult[k])
    S0[d.nphi + p.nphi + np.arange(nmult), lay["eta"].start + np.arange(nmult)] = -1.0
    col0, col1 = S0[:, :, None, None], S1[:, :, None, None]
    blocks = []
    for q in range(d.nphi):
        blocks.append(AffineBlock(f"decrease-f[{q}]", one, one, col0[q], col1[q]))
    for q in range(p.nphi):
        blocks.append(AffineBlock(f"positivity-f[{q}]", np.full((1, 1), p.meas_lin[q]), one,
                                  col0[d.nphi + q], zero, strict=False))
    for k in range(nmult):
        blocks.append(AffineBlock(f"mult[{k}]", one, one, col0[d.nphi + p.nphi + k], zero,
                                  strict=False))
    blocks.append(AffineBlock("normalization", -np.ones((1, 1)), one, zero, zero))
    return blocks


def composite_problem(om: Any, lag: int, family: str = "interpolation") -> LMIProblem:
    """Affine blocks in x = (P_ab (a <= b), p, c, eta, lambda) for an oracle method, built in
    units s = L with each inequality scaled; ``unpack`` returns original units."""
    s = float(om.L)
    st = composite_structure(om, lag, s, rescale=True)
    lay = _layout_x(st)
    blocks = _blocks(st, lay)
    gone = reductions(st, lay)[2]
    p = st.pos
    Fp = p.F[lag]

    def project(x: np.ndarray) -> np.ndarray:
        x = np.array(x, dtype=float)
        x[lay["eta"]] = np.maximum(x[lay["eta"]], 0.0)
        x[lay["lam"]] = np.maximum(x[lay["lam"]], 0.0)
        x[gone] = 0.0  # fixed at 0 by the facial reduction
        lam, pi = x[lay["lam"]], x[lay["pi"]]
        for q in range(p.nphi):  # raise p (or c) until positivity-f[q] holds exactly
            owners = np.flatnonzero(Fp[:, q])
            if not len(owners):
                continue
            terms = lam * p.mq[:, q]
            need = float(p.meas_lin[q]) + float(np.sum(terms))
            need += 1e-13 * (1.0 + float(np.sum(np.abs(terms))))
            pi[owners[0]] = max(pi[owners[0]], need)
        x[lay["pi"]] = pi
        return x

    def unpack(x: np.ndarray) -> dict[str, Any]:
        return _unpack(st, lay, s, om.measure, family, x)

    return LMIProblem(lay["lam"].stop, tuple(blocks), unpack, project)


def _unpack(st: CompositeStructure, lay: dict[str, slice], s: float, measure: str,
            family: str, x: np.ndarray) -> dict[str, Any]:
    """Original units: u = s u~ gives P = v Dz P~ Dz (Dz = diag(I_n, I/s)), p = v p~ / s and
    multipliers v mult~ / sigma, v = s for function values (V = s V~), 1 for distance."""
    v = s if measure == "function" else 1.0
    Pn = np.zeros((st.nz, st.nz))
    for k, (a, b) in enumerate(sym_basis(st.nz)):
        Pn[a, b] = Pn[b, a] = x[lay["P"]][k]
    dz = np.concatenate([np.ones(st.n), np.full(st.nz - st.n, 1.0 / s)])
    # an operator call's p multiplies no value (a zero row of F): 0, not the solver's
    # arbitrary number, so that V reads the same wherever it is evaluated
    idle = [not (np.any(st.pos.F[st.lag][r]) or any(np.any(F[r]) for F in st.dec.F.values()))
            for r in range(st.npi)]
    pi = [0.0 if idle[r] else float(t) * v / s for r, t in enumerate(x[lay["pi"]])]
    npv = st.npi - (1 if st.has_c else 0)

    def mult(labels: list[str], vals: np.ndarray, sig: np.ndarray) -> dict[str, float]:
        return {lab: float(t) * v / g for lab, t, g in zip(labels, vals, sig, strict=True)}

    return {
        "family": family, "lag": st.lag, "measure": measure, "inputs": st.p,
        "P": v * (dz[:, None] * Pn * dz[None, :]),
        "p": pi[:npv], "c": pi[npv] if st.has_c else None,
        "multipliers": {"decrease": mult(st.dec.labels, x[lay["eta"]], st.dec.sigma),
                        "positivity": mult(st.pos.labels, x[lay["lam"]], st.pos.sigma)},
    }


def composite_parts(om: Any, rho: float, cert: dict[str, Any]) -> dict[str, np.ndarray]:
    """(D, Df, Pq, Pf) at a certificate in original units: D ⪯ 0, Df <= 0, Pq ⪰ 0, Pf >= 0
    prove the rate (see the module docstring)."""
    st = composite_structure(om, int(cert["lag"]))
    d, p, lag, r = st.dec, st.pos, st.lag, rho ** 2
    P = np.asarray(cert["P"], dtype=float)
    pi = np.array(list(cert["p"]) + ([cert["c"]] if st.has_c else []), dtype=float)
    eta = np.array([cert["multipliers"]["decrease"][k] for k in d.labels])
    lam = np.array([cert["multipliers"]["positivity"][k] for k in p.labels])
    Z1, Z0, Zp = d.Z[lag + 1], d.Z[lag], p.Z[lag]
    D = Z1.T @ P @ Z1 - r * (Z0.T @ P @ Z0) + np.tensordot(eta, d.Mq, axes=1)
    Df = d.F[lag + 1].T @ pi - r * (d.F[lag].T @ pi) + eta @ d.mq
    Pq = Zp.T @ P @ Zp - np.tensordot(lam, p.Mq, axes=1) - p.meas_quad
    Pf = p.F[lag].T @ pi - p.meas_lin - lam @ p.mq
    return {"D": D, "Df": Df, "Pq": Pq, "Pf": Pf}


def reduced_summary(om: Any, rho: float, cert: dict[str, Any]) -> dict[str, float]:
    """max eig of (D) and min eig of (P) at a certificate, each without its window's
    isotropic directions when the matrix vanishes there (as every certificate of
    :func:`composite_problem` does), else on the whole window."""
    pt = composite_parts(om, rho, cert)
    st = composite_structure(om, int(cert["lag"]))
    return {"max_eig_M": float(restricted_eigenvalues(pt["D"], st.dec.iso)[-1]),
            "min_eig_P": float(restricted_eigenvalues(pt["Pq"], st.pos.iso)[0])}
