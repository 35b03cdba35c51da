"""An independent reference for Theorem 1: no sosalgo code.

The judge of ``sosalgo design``'s lower bound. It shares nothing with sosalgo (only numpy,
scipy and clarabel), so a bug in sosalgo's bound cannot hide behind the same bug here.

- :func:`theorem1_matrix` writes M of Theorem 1 straight from the formulas.
- :func:`certify` solves the LMI at one rho with Clarabel and re-checks the returned
  certificate in float64 in the original units (m, L): P symmetrized, eigenvalues of P
  down to -1e-6 (relative) raised to a hair above 0, lam >= 0, then max eig M <= 0 and
  min eig P >= 0 on exactly the (P, lam) returned. Any solver status but Solved fails.
- :func:`best_rate` is the best certified rate over a box of 1 or 2 free parameters
  (dense samples, a root-find on rho per sample, local polishing).
- :func:`random_case` generates specs (YAML text in sosalgo's format) and the same
  methods as numpy functions of theta, including adversarial ones.

Units. The solver works in the normalized class F(m/L, 1): with B~ = L B, D = diag(I, L),
D' M(A, B, C, E, m, L, P, lam) D = L M(A, B~, C, E, m/L, 1, P/L, lam) exactly (each N_i
picks up the factor L through its u-row, M0 through B = B~/L), and D is invertible, so a
normalized certificate (P~, lam) is the certificate (L P~, lam) of the original problem.
The re-check is always done on the original problem.

Hidden modes. Where the output x = E xi and the gradient point y = C xi do not see a
mode (an A-invariant subspace in ker C and ker E), Theorem 1 can hold only with M
singular, so the strict margin is 0. The judge then solves the LMI of the observable part
(coordinates V_o, P = V_o P_o V_o'): M is M_o padded with zeros, exactly. Its float
re-check allows max eig M <= 1e-12 * (1 + |M|) for the rounding of those zero rows (and
requires the reduced M_o <= 0 strictly); every other certificate needs max eig M <= 0.
(When the hidden subspace is spanned by coordinates, as in the generated cases, the zero
rows are exact zeros.) sosalgo's own analysis, which needs a strict margin, does not
certify such points; Theorem 1 does, so a bound must stay below them too.
"""

from __future__ import annotations

import ast
import math
import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache

import clarabel
import numpy as np
from scipy import sparse
from scipy.optimize import minimize, minimize_scalar

Matrices = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
MethodFn = Callable[[np.ndarray], Matrices]

MIN_C = 1e-7  # c >= MIN_C in the homogenized problem: normalized certificates tr P~ < 1e7
HIDDEN_TOL = 1e-12  # relative slack of the zero rows of a reduced (hidden-mode) certificate
UNOBSERVABLE_TOL = 1e-13  # relative singular value of the observability matrix taken as 0
P_CLIP = 1e-6  # relative size of negative eigenvalues of P clipped (M is re-checked)
RHO_TOL = 1e-6  # width of the final rho bracket
SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class Certificate:
    """A Theorem 1 certificate re-checked in float64 (original units)."""

    rho: float
    P: np.ndarray
    lam: float
    max_eig_M: float
    min_eig_P: float
    margin: float  # Clarabel's t in normalized units (M~ + t I <= 0)
    reduced: bool = False  # solved on the observable part (hidden modes)


def _mats(A, B, C, E) -> Matrices:
    """The four templates as 2-D float arrays with the shapes n x n, n x 1, 1 x n, 1 x n."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    n = A.shape[0]
    B = np.asarray(B, dtype=float).reshape(n, 1)
    C = np.asarray(C, dtype=float).reshape(1, n)
    E = np.asarray(E, dtype=float).reshape(1, n)
    return A, B, C, E


def theorem1_matrix(A, B, C, E, m: float, L: float, P, lam: float, rho: float) -> np.ndarray:
    """M = M0 + rho^2 M1 + (1 - rho^2) M2 + lam M3 of Theorem 1, (n+1) x (n+1).

    P may carry leading batch dimensions (..., n, n); M then has the same ones.
    """
    A, B, C, E = _mats(A, B, C, E)
    n = A.shape[0]
    P = np.asarray(P, dtype=float)
    AB = np.hstack([A, B])
    Pbig = np.zeros(P.shape[:-2] + (n + 1, n + 1))
    Pbig[..., :n, :n] = P
    M0 = AB.T @ P @ AB - rho**2 * Pbig
    last = np.zeros((1, n + 1))
    last[0, n] = 1.0
    zero = np.zeros((1, 1))
    X1 = np.vstack([np.hstack([E @ A - C, E @ B]), last])
    X2 = np.vstack([np.hstack([C - E, zero]), last])
    X3 = np.vstack([np.hstack([C, zero]), last])
    Q1 = np.array([[L / 2, 0.5], [0.5, 0.0]])
    Q2 = np.array([[-m / 2, 0.5], [0.5, 0.0]])
    Q4 = np.array([[-m * L / (m + L), 0.5], [0.5, -1.0 / (m + L)]])
    N1 = X1.T @ Q1 @ X1
    N2 = X2.T @ Q2 @ X2
    N3 = X3.T @ Q2 @ X3
    N4 = X3.T @ Q4 @ X3
    M = M0 + rho**2 * (N1 + N2) + (1 - rho**2) * (N1 + N3) + lam * N4
    return (M + np.swapaxes(M, -1, -2)) / 2


@cache
def _svec_index(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and weights of Clarabel's PSD triangle: the upper triangle by
    columns, off-diagonals times sqrt 2."""
    rows, cols = np.triu_indices(n)
    order = np.lexsort((rows, cols))
    r, c = rows[order], cols[order]
    return r, c, np.where(r == c, 1.0, SQRT2)


def _svec(M: np.ndarray) -> np.ndarray:
    r, c, w = _svec_index(M.shape[0])
    return w * M[r, c]


@cache
def _basis(n: int) -> tuple[np.ndarray, ...]:
    """Symmetric basis of n x n matrices: E_ij + E_ji (i <= j, E_ii once)."""
    out = []
    for i, j in zip(*np.triu_indices(n), strict=True):
        Z = np.zeros((n, n))
        Z[i, j] = Z[j, i] = 1.0
        out.append(Z)
    return tuple(out)


@cache
def _static(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows of the margin problem that do not depend on the method (k states):
    c + tr P~ + lam = 1, P~ >= 0, lam >= 0, c >= MIN_C; and svec(I) for t."""
    basis = _basis(k)
    nv = len(basis)
    nx = nv + 3
    zero = np.zeros((1, nx))
    zero[0, :nv] = [np.trace(Z) for Z in basis]
    zero[0, nv:nv + 2] = 1.0
    pcone = np.zeros((nv, nx))
    for j, Z in enumerate(basis):
        pcone[:, j] = -_svec(Z)
    nonneg = np.zeros((2, nx))
    nonneg[0, nv] = nonneg[1, nv + 1] = -1.0
    return zero, np.vstack([pcone, nonneg]), _svec(np.eye(k + 1))


@cache
def _empty(nx: int) -> sparse.csc_matrix:
    """The zero quadratic cost of the margin problem."""
    return sparse.csc_matrix((nx, nx))


@dataclass
class _Lmi:
    """The normalized LMI of one method, affine in r = rho^2: M(r) = (1 - r) M(0) + r M(1).

    ``ends[i]`` holds, at rho = i, the svec columns of the parts of M~ multiplying each
    entry of P~, lam, and c (the constant part), in this order.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    E: np.ndarray
    m: float
    L: float
    V: np.ndarray | None  # observable coordinates (hidden modes), None for all of xi
    k: int = 0
    ends: list[np.ndarray] = field(default_factory=list)


def _observable(A, C, E) -> np.ndarray | None:
    """An orthonormal basis of the observable subspace of (A, [C; E]) if it is proper."""
    n = A.shape[0]
    rows, R = [], np.vstack([C, E])
    for _ in range(n):
        rows.append(R)
        R = R @ A
    obs = np.vstack(rows)
    _, s, Vt = np.linalg.svd(obs)
    rank = int(np.sum(s > UNOBSERVABLE_TOL * max(1.0, s[0])))
    if rank == n:
        return None
    V = Vt[:rank].T
    V[np.abs(V) < 1e-14] = 0.0  # a coordinate subspace (the usual case) stays exact
    return np.linalg.qr(V)[0]


def _build(A, B, C, E, m: float, L: float) -> _Lmi:
    """Normalized data of the (observable part of the) method; see the module docstring.

    Every part of M~ is read off :func:`theorem1_matrix` (M is affine in P, lam and
    rho^2), so the solver sees exactly the formulas the re-check uses.
    """
    A, B, C, E = _mats(A, B, C, E)
    V = _observable(A, C, E)
    Ao, Bo, Co, Eo = (A, B, C, E) if V is None else (V.T @ A @ V, V.T @ B, C @ V, E @ V)
    k = Ao.shape[0]
    lmi = _Lmi(A, B, C, E, m, L, V, k)
    args = (Ao, L * Bo, Co, Eo, m / L, 1.0)
    zero, basis = np.zeros((k, k)), np.array(_basis(k))
    r, c, w = _svec_index(k + 1)
    for rho in (0.0, 1.0):
        const = theorem1_matrix(*args, zero, 0.0, rho)
        cols = theorem1_matrix(*args, basis, 0.0, rho) - const
        lam = theorem1_matrix(*args, zero, 1.0, rho) - const
        stack = np.concatenate([cols, lam[None], const[None]])
        lmi.ends.append((w * stack[:, r, c]).T)
    return lmi


def _solve(lmi: _Lmi, rho: float) -> tuple[str, np.ndarray]:
    """max t s.t. c M~const + M~(P~, lam) + t I <= 0, P~, lam >= 0, c >= MIN_C,
    c + tr P~ + lam = 1.

    The homogenized margin problem (normalized units): t > 0 exactly when the LMI has a
    strict solution with tr P~ + lam < 1/MIN_C - 1, and then (P~/c, lam/c) is a normalized
    certificate. Variables: the entries of P~ (basis :func:`_basis`), lam, c, t.
    """
    r = rho * rho
    zero, rest, eye = _static(lmi.k)
    top = np.column_stack([(1 - r) * lmi.ends[0] + r * lmi.ends[1], eye])
    dense = np.vstack([zero, top, rest])
    rows, nx = dense.shape
    # every entry stored (explicit zeros are fine for Clarabel): CSC by hand is cheap
    Amat = sparse.csc_matrix((dense.T.ravel(), np.tile(np.arange(rows), nx),
                              np.arange(0, rows * nx + 1, rows)), shape=(rows, nx))
    b = np.zeros(rows)
    b[0], b[-1] = 1.0, -MIN_C
    q = np.zeros(nx)
    q[-1] = -1.0
    cones = [clarabel.ZeroConeT(1), clarabel.PSDTriangleConeT(lmi.k + 1),
             clarabel.PSDTriangleConeT(lmi.k), clarabel.NonnegativeConeT(2)]
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    solver = clarabel.DefaultSolver(_empty(nx), q, Amat, b, cones, settings)
    sol = solver.solve()
    return str(sol.status), np.asarray(sol.x, dtype=float)


def _recheck(lmi: _Lmi, x: np.ndarray, rho: float, margin: float) -> Certificate | None:
    """Map a normalized solution back to (P, lam) and check Theorem 1 in float64."""
    basis = _basis(lmi.k)
    c = float(x[len(basis) + 1])
    if not c > 0.5 * MIN_C:
        return None
    Pk = sum(v * Z for v, Z in zip(x[: len(basis)], basis, strict=True)) * (lmi.L / c)
    Pk = (Pk + Pk.T) / 2
    w, U = np.linalg.eigh(Pk)
    scale = max(1.0, abs(w).max())
    if w.min() < -P_CLIP * scale:
        return None
    # clipped to a hair above 0, so that the computed min eig P is >= 0 despite rounding
    Pk = (U * np.maximum(w, 1e-13 * scale)) @ U.T
    lam = max(float(x[len(basis)]) / c, 0.0)
    P = Pk if lmi.V is None else lmi.V @ Pk @ lmi.V.T
    P = (P + P.T) / 2
    M = theorem1_matrix(lmi.A, lmi.B, lmi.C, lmi.E, lmi.m, lmi.L, P, lam, rho)
    top = float(np.linalg.eigvalsh(M).max())
    min_p = float(np.linalg.eigvalsh(P).min())
    if lmi.V is None:
        ok = top <= 0.0 and min_p >= 0.0
    else:
        Mo = theorem1_matrix(lmi.V.T @ lmi.A @ lmi.V, lmi.V.T @ lmi.B, lmi.C @ lmi.V,
                             lmi.E @ lmi.V, lmi.m, lmi.L, Pk, lam, rho)
        slack = HIDDEN_TOL * (1.0 + np.abs(M).max())
        ok = float(np.linalg.eigvalsh(Mo).max()) <= 0.0 and top <= slack and min_p >= -slack
    if not ok:
        return None
    return Certificate(rho, P, lam, top, min_p, margin, lmi.V is not None)


def _certify_lmi(lmi: _Lmi, rho: float) -> tuple[Certificate | None, float]:
    """(checked certificate or None, Clarabel's margin t; nan when not Solved)."""
    try:
        status, x = _solve(lmi, rho)
    except Exception:  # noqa: BLE001 - any solver failure means "not certified"
        return None, math.nan
    if status != "Solved":
        return None, math.nan
    t = float(x[-1])
    if not t > 0.0:
        return None, t
    return _recheck(lmi, x, rho, t), t


def certify(A, B, C, E, m: float, L: float, rho: float
            ) -> tuple[bool, np.ndarray | None, float | None, float]:
    """(ok, P, lam, margin): is rho certified by Theorem 1? P, lam in original units."""
    cert, t = _certify_lmi(_build(A, B, C, E, m, L), rho)
    if cert is None:
        return False, None, None, t
    return True, cert.P, cert.lam, t


def _rate(lmi: _Lmi, hi: float = 1.0, tol: float = RHO_TOL
          ) -> tuple[float, Certificate | None, float]:
    """Smallest certified rho in [0, hi] (to tol), its certificate, and the margin at hi.

    Returns (inf, None, t_hi) when hi is not certified. Illinois false position on the
    margin t(rho) inside a bracket, falling back to bisection; only checked certificates
    move the upper end, so the answer is certified whatever the root-finder does.
    """
    top, t_hi = _certify_lmi(lmi, hi)
    if top is None:
        return math.inf, None, t_hi
    rho, cert, _ = _rate_from(lmi, hi, top, t_hi, tol)
    return rho, cert, t_hi


def method_rate(A, B, C, E, m: float, L: float, tol: float = RHO_TOL
                ) -> tuple[float, Certificate | None]:
    """Best certified rate of one method (inf and None when rho = 1 is not certified)."""
    rho, cert, _ = _rate(_build(A, B, C, E, m, L), tol=tol)
    return rho, cert


def _rate_from(lmi: _Lmi, hi: float, top: Certificate, t_hi: float, tol: float = RHO_TOL,
               probe: float | None = None) -> tuple[float, Certificate, float]:
    """:func:`_rate` when hi is already certified (by ``top``, margin t_hi); ``probe``
    is a first guess of hi minus the answer (a small improvement while polishing).
    Also returns the slope dt/drho of the margin across the final bracket (nan if unknown).
    """
    a, fa, b, fb, best = 0.0, math.nan, hi, t_hi, top
    if probe is not None and hi - probe > 0.0:
        cert, t = _certify_lmi(lmi, hi - probe)
        if cert is None:
            a, fa = hi - probe, (t if t <= 0.0 else math.nan)
        else:
            best, b, fb = cert, hi - probe, t
    raw = [fa, fb]  # the margins at a and b, without Illinois' halving
    side, solves = 0, 0
    while b - a > tol and solves < 60:
        w = b - a
        if math.isfinite(fa) and fa < 0.0 < fb:
            x = min(max(b - fb * w / (fb - fa), a + 0.02 * w), b - 0.02 * w)
        else:
            x = a + 0.5 * w
        cert, t = _certify_lmi(lmi, x)
        solves += 1
        if cert is not None:
            best, b, fb, raw[1] = cert, x, t, t
            fa, side = (fa / 2 if side == 1 else fa), 1
        else:
            a, fa = x, (t if t <= 0.0 else math.nan)
            raw[0] = fa
            fb, side = (fb / 2 if side == -1 else fb), -1
    slope = (raw[1] - raw[0]) / (b - a) if b > a else math.nan
    return best.rho, best, slope


@dataclass
class Best:
    """The best certified point of a box search (rho = inf when nothing is certified)."""

    rho: float = math.inf
    theta: np.ndarray | None = None
    cert: Certificate | None = None
    evaluations: int = 0


class _Search:
    """Screening of points against the best certified rate so far (one solve per point)."""

    def __init__(self, fn: MethodFn, m: float, L: float, lo: np.ndarray, hi: np.ndarray):
        self.fn, self.m, self.L = fn, m, L
        self.lo, self.hi = lo, hi
        self.best = Best()
        self.slope = 1.0  # dt/drho of the margin at the last root found

    def clip(self, z: np.ndarray) -> np.ndarray:
        return np.minimum(np.maximum(np.asarray(z, dtype=float), self.lo), self.hi)

    def screen(self, theta: np.ndarray) -> float:
        """The rate at theta if it beats the best so far (which it then becomes), else an
        estimate from the margin at the best rate (for polishing; never a certified rate)."""
        theta = self.clip(theta)
        self.best.evaluations += 1
        try:
            lmi = _build(*self.fn(theta), self.m, self.L)
        except (ValueError, np.linalg.LinAlgError):
            return 3.0
        thr = min(self.best.rho, 1.0)
        top, t = _certify_lmi(lmi, thr)
        if top is None:  # about thr + (rate - thr), to first order in the margin
            gap = -t / self.slope if math.isfinite(t) and t <= 0 else 1.0
            return thr + min(gap, 1.0)
        probe = 1e-3 if math.isfinite(self.best.rho) else None
        rho, cert, slope = _rate_from(lmi, thr, top, t, probe=probe)
        if math.isfinite(slope) and slope > 0:
            self.slope = slope
        if rho < self.best.rho:
            self.best = Best(rho, theta.copy(), cert, self.best.evaluations)
        return rho


def _axis(lo: float, hi: float, points: int) -> np.ndarray:
    """points evenly spaced in [lo, hi] (ends included), plus the center and 0 inside."""
    if not hi > lo:
        return np.array([lo])
    xs = [lo + (hi - lo) * i / (points - 1) for i in range(points)]
    xs += [0.5 * (lo + hi)] + ([0.0] if lo < 0.0 < hi else [])
    return np.unique(np.array(xs))


def _samples(lo: np.ndarray, hi: np.ndarray, points: int, seed: int) -> np.ndarray:
    """The sample grid (every combination of the axes) in a fixed random order."""
    axes = [_axis(a, b, points) for a, b in zip(lo, hi, strict=True)]
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(axes), -1).T
    return grid[np.random.default_rng(seed).permutation(len(grid))]


def best_rate(fn: MethodFn, m: float, L: float, lo: Sequence[float], hi: Sequence[float],
              points: int | None = None, starts: int = 6, maxfev: int = 100,
              seed: int = 0) -> Best:
    """Best certified rate over the box [lo, hi] of 1 or 2 free parameters.

    ``fn(theta)`` gives (A, B, C, E). Dense samples (41 per axis in 1-D, 15 x 15 in 2-D,
    plus centers and 0 where a range crosses it) screened against the best rate so far;
    a finer grid over the cells around the best sample (thin certified wedges); then
    local polishing from the best point and the next best samples not next to an earlier
    start: bounded scalar searches along each coordinate (the faces through the point,
    where hidden modes live), Nelder-Mead from the two best, and restarts from the best
    with smaller steps. The result's ``cert`` is a Theorem 1 certificate at ``theta``
    re-checked in float64; ``rho`` is within ~1e-6 above the smallest rate it certifies.
    """
    lo_a, hi_a = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    search = _Search(fn, m, L, lo_a, hi_a)
    points = points or (41 if len(lo_a) == 1 else 15)
    samples = _samples(lo_a, hi_a, points, seed)
    values = np.array([search.screen(theta) for theta in samples])
    if search.best.theta is None:
        return search.best
    step = np.where(hi_a > lo_a, hi_a - lo_a, 1.0) / (points - 1)
    x0 = search.best.theta.copy()  # a finer grid over the grid cells around the best sample
    local = _samples(np.maximum(lo_a, x0 - step), np.minimum(hi_a, x0 + step),
                     9 if len(lo_a) > 1 else 17, seed)
    for theta in local:
        search.screen(theta)
    chosen: list[np.ndarray] = [search.best.theta.copy()]
    for j in np.argsort(values, kind="stable"):
        if len(chosen) == starts:
            break
        if all(np.abs((samples[j] - c) / step).max() > 1.5 for c in chosen):
            chosen.append(samples[j])
    for j, x0 in enumerate(chosen):  # coordinate searches from each, Nelder-Mead from two
        _polish(search, x0, step, maxfev, simplex=j < 2)
    for k in range(1, 4):  # restarts from the best point, smaller and smaller steps
        before = search.best.rho
        _polish(search, search.best.theta.copy(), step / 4**k, maxfev)
        if not search.best.rho < before - 1e-7:
            break
    return search.best


def _polish(search: _Search, x0: np.ndarray, step: np.ndarray, maxfev: int,
            simplex: bool = True) -> None:
    """Coordinate searches within one step of x0, then (2-D, ``simplex``) Nelder-Mead
    from where they ended."""
    d = len(x0)
    x, fx = x0.copy(), search.screen(x0)
    for i in range(d):
        x, fx = _polish_axis(search, x, fx, i, step[i], 60 if d == 1 else 24)
    if d == 1 or not simplex:
        return
    init = [x] + [x + np.eye(d)[i] * step[i] * (1 if x[i] < search.hi[i] else -1)
                  for i in range(d)]
    minimize(search.screen, x, method="Nelder-Mead",
             options={"initial_simplex": np.array(init), "maxfev": maxfev,
                      "xatol": 1e-9 * float(step.max()), "fatol": 1e-9})


def _polish_axis(search: _Search, x0: np.ndarray, f0: float, i: int, step: float,
                 maxfev: int) -> tuple[np.ndarray, float]:
    """Bounded scalar search along coordinate i within one step of x0 (value f0 there);
    returns the better of x0 and the search's end point, with its value."""
    a, b = max(search.lo[i], x0[i] - step), min(search.hi[i], x0[i] + step)
    if not b > a:
        return x0, f0

    def at(v: float) -> np.ndarray:
        x = x0.copy()
        x[i] = v
        return x

    res = minimize_scalar(lambda v: search.screen(at(v)), bounds=(a, b), method="bounded",
                          options={"xatol": 1e-10 * max(1.0, b - a), "maxiter": maxfev})
    return (at(float(res.x)), float(res.fun)) if res.fun < f0 else (x0, f0)


# ---------------------------------------------------------------- random specs

Params = dict[str, tuple[str, tuple[str, str] | None]]  # name -> (value, range or None)
KAPPAS = (2.0, 10.0, 100.0)


@dataclass(frozen=True)
class Case:
    """A generated spec: its YAML text and the same method as numpy arrays of theta."""

    name: str
    family: str
    kappa: float
    free: tuple[str, ...]
    params: Params
    matrices: dict[str, list[list[str]]]
    m: float = 1.0

    @property
    def L(self) -> float:
        return self.kappa * self.m

    def _env(self) -> dict[str, float]:
        return {"m": self.m, "L": self.L, "kappa": self.kappa}

    def _eval(self, expr: str, env: dict[str, float]) -> float:
        return float(_arith(_compiled(expr), env))

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The free parameters' ranges at this kappa."""
        env = self._env()
        ends = [[self._eval(e, env) for e in self.params[p][1]] for p in self.free]
        return np.array([a for a, _ in ends]), np.array([b for _, b in ends])

    def method(self, theta: Sequence[float]) -> Matrices:
        """(A, B, C, E) at the free parameters theta (the others at their values)."""
        env = self._env()
        for p, (value, _) in self.params.items():
            env[p] = self._eval(value, env)
        env.update(zip(self.free, (float(t) for t in theta), strict=True))
        A, B, C, E = ([[self._eval(e, env) for e in row] for row in self.matrices[k]]
                      for k in "ABCE")
        return _mats(A, B, C, E)

    @property
    def yaml(self) -> str:
        lines = [f"name: {self.name}", f"description: generated ({self.family})",
                 "parameters:"]
        for p, (value, rng) in self.params.items():
            lines.append(f"  {p}: {value}" if rng is None else
                         f"  {p}: {{value: {value}, range: [{rng[0]}, {rng[1]}]}}")
        lines.append("matrices:")
        for k in "ABCE":
            rows = ", ".join("[" + ", ".join(row) + "]" for row in self.matrices[k])
            lines.append(f"  {k}: [{rows}]")
        if self.m != 1.0:
            lines.append(f"m: {self.m!r}")
        lines.append(f"kappa: [{self.kappa!r}]")
        return "\n".join(lines) + "\n"


@cache
def _compiled(expr: str) -> ast.expr:
    """Our own generated arithmetic (numbers, names, + - * / **), parsed, never eval'ed."""
    return ast.parse(expr, mode="eval").body


_OPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
        ast.Div: operator.truediv, ast.Pow: operator.pow}


def _arith(node: ast.expr, env: dict[str, float]) -> float:
    """Value of a parsed arithmetic expression (anything else is refused)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, int | float):
        return float(node.value)
    if isinstance(node, ast.Name):
        return env[node.id]
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return -_arith(node.operand, env)
    if isinstance(node, ast.BinOp) and type(node.op) in _OPS:
        return _OPS[type(node.op)](_arith(node.left, env), _arith(node.right, env))
    raise ValueError(f"not generated arithmetic: {ast.dump(node)}")


def _num(x: float) -> str:
    """A dyadic number as an exact decimal (repr of such a float is exact)."""
    return repr(float(x))


def _pick(rng: np.random.Generator, options: Sequence):
    return options[int(rng.integers(len(options)))]


def _free(rng: np.random.Generator, pairs: Sequence, singles: Sequence) -> tuple[str, ...]:
    """Two free parameters three times out of four, else one."""
    return tuple(_pick(rng, pairs) if rng.random() < 0.75 else (_pick(rng, singles),))


def _step(rng: np.random.Generator) -> tuple[str, tuple[str, str]]:
    """A step h (value, range in units of 1/L); the range always reaches 2/L."""
    return _pick(rng, ["1/L", "1.5/L", "0.75/L", "1.875/L"]), _pick(
        rng, [("0", "2/L"), ("0", "2/L"), ("0.25/L", "2/L")])


def _momentum(rng: np.random.Generator) -> tuple[Params, dict, tuple[str, ...]]:
    """Heavy-ball / Nesterov family in (x, x - x_prev) coordinates, output x + delta v."""
    params: Params = {
        "h": _step(rng),
        "beta": (_pick(rng, ["0.25", "0.5"]), _pick(rng, [("0", "1"), ("-0.25", "0.875")])),
        "gamma": (_pick(rng, ["0", "0.25", "0.5"]), ("-0.5", "1")),
        "delta": ("0", ("-0.5", "0.5")),
    }
    mats = {"A": [["1", "beta"], ["0", "beta"]], "B": [["-h"], ["-h"]],
            "C": [["1", "gamma"]], "E": [["1", "delta"]]}
    free = _free(rng, [("h", "beta"), ("beta", "gamma"), ("h", "gamma"), ("gamma", "delta"),
                       ("beta", "delta")], ["beta", "gamma", "h", "delta"])
    return params, mats, free


def _crossterm(rng: np.random.Generator) -> tuple[Params, dict, tuple[str, ...]]:
    """A decaying side state z fed by the gradient and seen through g and e (products
    of two free parameters in A + q B C, as in the crossterm spec)."""
    params: Params = {
        # steps near 2/L leave a slow mode 1 - L h that only the coupling b g can remove
        "h": (_pick(rng, ["1.5/L", "1.875/L", "1/L", "1.9375/L"]), ("0", "2/L")),
        "a": (_pick(rng, ["0.5", "0.75", "0.8125"]), ("0", "1")),
        "b": (_pick(rng, ["0.5", "1"]), _pick(rng, [("-2", "2"), ("-8", "8"), ("-0.5", "1.5")])),
        "g": (_pick(rng, ["0.25", "0.5"]),
              _pick(rng, [("-1", "1"), ("-1", "1"), ("-0.25", "0.75")])),
        "e": ("0", ("-0.5", "0.5")),
    }
    mats = {"A": [["1", "0"], ["0", "a"]], "B": [["-h"], ["b"]],
            "C": [["1", "g"]], "E": [["1", "e"]]}
    free = _free(rng, [("b", "g"), ("h", "g"), ("g", "e"), ("b", "e"), ("a", "g"), ("h", "b")],
                 ["g", "b", "e"])
    return params, mats, free


def _hidden(rng: np.random.Generator) -> tuple[Params, dict, tuple[str, ...]]:
    """A slow (or unstable) mode s that x and y see wherever the coupling p is not 0.

    On p = 0 (inside the range, or on its edge) the mode is unobservable and Theorem 1
    certifies the gradient step's rate; off it the rate is at least s. With a second
    free parameter q the coupling is the product p q (hidden on two crossing lines).
    """
    lo, hi = _pick(rng, [("-0.5", "0.5"), ("-0.25", "0.75"), ("0", "0.5"), ("-0.375", "0.125"),
                         ("-0.5", "0")])
    second = _pick(rng, ["h", "q", "b", None])
    coup = "p*q" if second == "q" else "p"
    gains = [_pick(rng, ["0", "0.5", "-1"]) for _ in range(3)]
    if all(g == "0" for g in gains):
        gains[int(rng.integers(3))] = "1"
    d0, c0, e0 = (("0" if g == "0" else f"{g}*{coup}") for g in gains)
    params: Params = {
        "s": (_pick(rng, ["0.9375", "0.96875", "1.0625"]), None),
        "h": (_pick(rng, ["1.5/L", "1.875/L", "1/L"]), ("0", "2/L")),
        "b": (_pick(rng, ["0", "0.25", "-0.5"]), ("-0.5", "0.5")),
        "p": ("0.125" if float(hi) >= 0.125 else "-0.125", (lo, hi)),
    }
    if second == "q":
        params["q"] = ("0.5", ("-1", "1"))
    mats = {"A": [["1", d0], ["0", "s"]], "B": [["-h"], ["b"]],
            "C": [["1", c0]], "E": [["1", e0]]}
    return params, mats, ("p",) if second is None else ("p", second)


def _filter3(rng: np.random.Generator) -> tuple[Params, dict, tuple[str, ...]]:
    """Momentum plus a gradient filter s+ = a s + grad, fed back through w (hidden at w = 0)."""
    params: Params = {
        "h": _step(rng),
        "beta": (_pick(rng, ["0.25", "0.5"]), ("0", "1")),
        "gamma": (_pick(rng, ["0", "0.25"]), ("-0.5", "1")),
        "w": (_pick(rng, ["-0.25/L", "0.125/L", "0"]), ("-0.5/L", "0.5/L")),
        "a": (_pick(rng, ["0.5", "0.75", "0.9375"]), ("0", "0.9375")),
    }
    mats = {"A": [["1", "beta", "w"], ["0", "beta", "w"], ["0", "0", "a"]],
            "B": [["-h"], ["-h"], ["1"]], "C": [["1", "gamma", "0"]], "E": [["1", "0", "0"]]}
    free = _free(rng, [("h", "w"), ("beta", "w"), ("w", "a"), ("gamma", "w"), ("h", "beta")],
                 ["w", "beta", "a"])
    return params, mats, free


def _lag3(rng: np.random.Generator) -> tuple[Params, dict, tuple[str, ...]]:
    """Momentum with the previous velocity as a third state, seen through c3 and e3."""
    params: Params = {
        "h": _step(rng),
        "beta": (_pick(rng, ["0.25", "0.5"]), ("0", "1")),
        "gamma": (_pick(rng, ["0", "0.25"]), ("-0.5", "1")),
        "c3": (_pick(rng, ["0", "0.125"]), ("-0.5", "0.5")),
        "e3": ("0", ("-0.25", "0.25")),
    }
    mats = {"A": [["1", "beta", "0"], ["0", "beta", "0"], ["0", "1", "0"]],
            "B": [["-h"], ["-h"], ["0"]], "C": [["1", "gamma", "c3"]], "E": [["1", "0", "e3"]]}
    free = _free(rng, [("c3", "gamma"), ("c3", "e3"), ("beta", "c3"), ("h", "c3")],
                 ["c3", "e3"])
    return params, mats, free


FAMILIES = {"crossterm": _crossterm, "hidden": _hidden, "momentum": _momentum,
            "filter3": _filter3, "lag3": _lag3}
ORDER = ("crossterm", "hidden", "momentum", "filter3", "hidden", "lag3")


def random_case(seed: int) -> Case:
    """A deterministic random spec: the family cycles with the seed (hidden modes twice)."""
    rng = np.random.default_rng([16, seed])
    family = ORDER[seed % len(ORDER)]
    params, mats, free = FAMILIES[family](rng)
    kappa = float(rng.choice(KAPPAS, p=[0.3, 0.45, 0.25]))
    if family == "hidden" and float(params["s"][0]) < 1.0:
        kappa = float(_pick(rng, [2.0, 10.0]))  # where the gradient step beats s
    m = float(_pick(rng, [1.0, 1.0, 1.0, 0.5, 2.0]))
    return Case(f"case-{seed}-{family}", family, kappa, free, params, mats, m)


def crossterm_case() -> Case:
    """The crossterm spec (free b, g at kappa 10)."""
    params: Params = {"h": ("1.9/L", ("0", "2/L")), "a": ("0.8", ("0", "1")),
                      "b": ("1", ("-10", "10")), "g": ("0.5", ("-1", "1"))}
    mats = {"A": [["1", "0"], ["0", "a"]], "B": [["-h"], ["b"]],
            "C": [["1", "g"]], "E": [["1", "0"]]}
    return Case("crossterm", "crossterm", 10.0, ("b", "g"), params, mats)


def hidden_case() -> Case:
    """A slow mode 0.9375 that x and y see unless p = 0 (inside the range): certified at
    the gradient step's (kappa - 1)/(kappa + 1) there only (free h, p at kappa 10)."""
    params: Params = {"h": ("1.5/L", ("0", "2/L")), "p": ("0.25", ("-0.25", "0.5"))}
    mats = {"A": [["1", "0"], ["0", "0.9375"]], "B": [["-h"], ["0"]],
            "C": [["1", "p"]], "E": [["1", "p"]]}
    return Case("hidden", "hidden", 10.0, ("h", "p"), params, mats)


FIXED = {"crossterm": crossterm_case, "hidden": hidden_case}


def judge(case: Case) -> Best:
    """The judge's best certified rate over the case's box."""
    lo, hi = case.box()
    return best_rate(case.method, case.m, case.L, lo, hi)


def make_case(key: int | str) -> Case:
    """A fixed case by name, or the random case of a seed."""
    return FIXED[key]() if isinstance(key, str) else random_case(key)


def judge_key(key: int | str) -> Best:
    """:func:`judge` of :func:`make_case` (picklable for worker processes)."""
    return judge(make_case(key))
