"""Rate brackets: a witnessed lower bound ``rho_lower`` on the worst-case linear rate.

(a) ``quadratic``: every f_j the quadratic (q_j/2)|x|^2 of its class, at a rational
curvature q picked where the float spectral radius of the closed loop is largest. The
closed loop M(q) = A + B (I - Q D)^-1 Q C is built on the method's exact matrices (balls),
its characteristic polynomial by Faddeev–LeVerrier, and the Schur–Cohn test proves that
it has a root of modulus >= rho_lower (:func:`sosalgo.witnesses.balls.has_root_outside`).
The observability matrix of the output (x = E xi, or the output call's point) is proven
nonsingular, so every eigenvalue shows in the output: started on its (real or complex)
mode, |x_k - x*| decays no faster than rho_lower^k, and the measure (distance, or the
function values sum_j q_j/2 |x|^2 with some q_j > 0) with it.

(b) ``self-similar``: a trajectory with xi_K = rho^K xi_0 on functions of the classes
(:mod:`sosalgo.witnesses.trajectory`, checked exactly with every copy scaled by rho^(jK));
for each N, its first N periods lie on one function of the class, so no rate below rho
holds with any constant. Searched only when asked (or when no rate is certified): a
bisection on rational rho above the quadratic bound. ``cycle``: rho_lower = 1 from a
checked cycle (:mod:`sosalgo.witnesses.cycles`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from flint import arb, arb_mat

from sosalgo.kernel.arb import arb_fraction, arb_of, precision
from sosalgo.method import arb_method, arb_output_row
from sosalgo.oracles import Method

__all__ = ["BRACKET_KINDS", "Bracketed", "bracketed", "has_root_outside", "output_part",
           "quadratic_bracket", "quadratic_witness_fails", "rate_bracket",
           "self_similar_bracket"]

BRACKET_KINDS = ("quadratic", "self-similar")  # the --brackets choices
BELOW = (1e-12, 1e-9, 1e-7, 1e-5)  # rho_lower = r (1 - this): the first that is proven
GRID = 401
INWARD = (0.0, 1e-9, 1e-7, 1e-5)  # moves of q into its interval, tried in turn
MAX_K = 8
SELF_SIMILAR_STEPS = 8  # bisection steps on rho per length K


@dataclass
class Bracketed:
    """A method at one kappa: floats (``om``, the search) and balls (``am``, the proofs)."""

    spec: Any
    kappa: float
    theta: Mapping[str, float] | None
    om: Any  # OracleMethod
    am: Method  # over arb balls


def bracketed(spec: Any, kappa: float, theta: Mapping[str, float] | None = None
              ) -> Bracketed:
    """The method of ``spec`` at ``kappa`` for :func:`rate_bracket`."""
    from sosalgo.model import evaluate_algorithm
    from sosalgo.oracles import as_oracle_method

    om = as_oracle_method(evaluate_algorithm(spec, kappa, theta))
    return Bracketed(spec, kappa, theta, om, arb_method(spec, kappa, theta))


def _curvature_box(bk: Bracketed) -> list[tuple[Fraction, Fraction]] | None:
    """Exact curvature interval [lo, hi] of every function (q with (q/2)|x|^2 in the
    class, proven from the parameters' enclosures:
    :meth:`~sosalgo.classes.base.FunctionClass.exact_curvatures`), None when some class
    has none we know."""
    out = []
    for _, cls, params in bk.am.functions:
        cur = cls.exact_curvatures(
            lambda k, p=params: arb_fraction(p[k].lower()),
            lambda k, p=params: arb_fraction(p[k].upper()))
        if cur is None or cur[0] > cur[1]:
            return None
        out.append(cur)
    return out


def _loop_float(om: Any, q: np.ndarray) -> np.ndarray:
    """Closed loop A + B (I - Q D)^-1 Q C for curvatures q (per function; float)."""
    Qd = np.diag([q[j] for j in om.oracles])
    return om.A + om.B @ np.linalg.solve(np.eye(om.p) - Qd @ om.D, Qd @ om.C)


def _radii(om: Any, qs: np.ndarray) -> np.ndarray:
    """Spectral radius of the closed loop at each row of curvatures ``qs`` (float)."""
    qd = qs[:, list(om.oracles)]
    eye = np.eye(om.p)
    try:
        K = np.linalg.solve(eye - qd[:, :, None] * om.D, qd[:, :, None] * om.C)
        return np.abs(np.linalg.eigvals(om.A + om.B @ K)).max(axis=1)
    except np.linalg.LinAlgError:
        return np.array([_radius(om, q) for q in qs])


def _radius(om: Any, q: np.ndarray) -> float:
    try:
        return float(np.abs(np.linalg.eigvals(_loop_float(om, q))).max())
    except np.linalg.LinAlgError:
        return 0.0


def _seen_radius(om: Any, q: np.ndarray) -> float:
    """Largest |eigenvalue| of the closed loop among the modes the output row sees
    (float; |row v| > 1e-9 |row| |v| for the eigenvector v): a search heuristic only,
    the bracket is then proven exactly."""
    try:
        M = _loop_float(om, q)
        erow, drow = om.output_row()
        Qd = np.diag([q[j] for j in om.oracles])
        row = erow + drow @ np.linalg.solve(np.eye(om.p) - Qd @ om.D, Qd @ om.C)
        lam, V = np.linalg.eig(M)
    except np.linalg.LinAlgError:
        return 0.0
    seen = np.abs(row @ V) > 1e-9 * max(np.linalg.norm(row), 1e-300) * np.linalg.norm(V, axis=0)
    return float(np.abs(lam[seen]).max()) if seen.any() else 0.0


def _seen_radii(om: Any, qs: np.ndarray) -> np.ndarray:
    return np.array([_seen_radius(om, q) for q in qs])


def _argmax(om: Any, box: Sequence[tuple[Fraction, Fraction]],
            radii: Any = _radii) -> np.ndarray:
    """Curvatures where the float spectral radius (``radii``: of the whole loop, or of
    the modes the output sees) is largest: a grid (a product grid over several
    intervals), refined by golden sections around the best point."""
    axes = [np.linspace(float(lo), float(hi), GRID if len(box) == 1 else 21)
            if hi > lo else np.array([float(lo)]) for lo, hi in box]
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(box), -1).T
    best = grid[int(np.argmax(radii(om, grid)))].copy()
    g = (5 ** 0.5 - 1) / 2
    for j, ax in enumerate(axes):
        if len(ax) < 3:
            continue
        step = ax[1] - ax[0]
        a, b = max(ax[0], best[j] - step), min(ax[-1], best[j] + step)
        for _ in range(30):
            pair = np.array([best, best])
            pair[0, j], pair[1, j] = b - g * (b - a), a + g * (b - a)
            rc, rd = radii(om, pair)
            a, b = (a, pair[1, j]) if rc >= rd else (pair[0, j], b)
        cand = best.copy()
        cand[j] = 0.5 * (a + b)
        if radii(om, cand[None])[0] > radii(om, best[None])[0]:
            best = cand
    return best


def _rational_q(q: np.ndarray, box: Sequence[tuple[Fraction, Fraction]],
                inward: float = 0.0) -> list[Fraction]:
    """Dyadic curvatures near ``q`` inside the exact box, moved ``inward`` (a fraction of
    each interval's width) towards its middle."""
    out = []
    for v, (lo, hi) in zip(q, box, strict=True):
        r = min(max(Fraction(float(v)), lo), hi)
        out.append(Fraction(float(r + ((lo + hi) / 2 - r) * Fraction(inward))))
    return [min(max(r, lo), hi) for r, (lo, hi) in zip(out, box, strict=True)]


def _loop_exact(am: Method, q: Sequence[Fraction]) -> tuple[arb_mat, arb_mat]:
    """(M(q), output row) in balls."""
    p = am.p
    Qd = arb_mat(p, p)
    for i, j in enumerate(am.oracles):
        Qd[i, i] = arb_of(q[j])
    eye = arb_mat([[1 if i == j else 0 for j in range(p)] for i in range(p)])
    K = (eye - Qd * am.D).solve(Qd * am.C)
    erow, drow = arb_output_row(am)
    return am.A + am.B * K, erow + drow * K


def _observable(M: arb_mat, row: arb_mat) -> bool:
    n = M.nrows()
    rows = [row]
    for _ in range(n - 1):
        rows.append(rows[-1] * M)
    obs = arb_mat([[r[0, j] for j in range(n)] for r in rows])
    return not obs.det().contains(0)


def has_root_outside(coeffs: Sequence[arb], r: Fraction) -> bool:
    """Proof that the real polynomial sum c_k z^k (balls) has a root of modulus >= r > 0.

    Schur–Cohn on p(z) = sum c_k r^k z^k = sum a_k z^k: if |a_0| >= |a_n| the product of
    the roots has modulus >= 1; if |a_0| < |a_n| (proved), p and (a_n p - a_0 p*)/z (p*
    the reversed polynomial) have the same number of roots in the open unit disc less
    one (Rouché on the unit circle, where |p*| = |p|), so p has all its roots inside iff
    the reduced polynomial has. False when no proof was found (undecided signs too)."""
    rr = arb_of(r)
    a = [c * rr ** k for k, c in enumerate(coeffs)]
    while len(a) > 1:
        lead, const = a[-1], a[0]
        if abs(const) >= abs(lead) and abs(lead) > 0:
            return True
        if not abs(const) < abs(lead):
            return False
        rev = a[::-1]
        a = [lead * a[k + 1] - const * rev[k + 1] for k in range(len(a) - 1)]
    return False


def quadratic_bracket(bk: Bracketed) -> tuple[float, dict[str, Any]] | None:
    """(rho_lower, witness) from the slowest quadratic mode, proven exactly; None when
    no class has quadratics we know, the measure vanishes or no proof was found. Where
    the slowest mode does not show in the output (triple momentum at q = m), q moves
    into the interval until it does."""
    box = _curvature_box(bk)
    if box is None:
        return None
    q0 = _argmax(bk.om, box)
    if _seen_radius(bk.om, q0) < _radius(bk.om, q0) * (1 - 1e-9):  # the slowest mode hides
        q0 = _argmax(bk.om, box, _seen_radii)
    with precision():
        for inward in INWARD:
            q = _rational_q(q0, box, inward)
            if bk.om.measure == "function" and not any(v > 0 for v in q):
                return None  # every f_j = 0: the function values measure nothing
            M, row = _loop_exact(bk.am, q)
            if not _observable(M, row):  # drop the states that never reach the output
                M, row = output_part(M, row)
            if _observable(M, row):
                return _prove_radius(bk, q, M)
    return None


def quadratic_witness_fails(bk: Bracketed, curvatures: Mapping[str, Any],
                            rho: Fraction) -> str | None:
    """Re-check a quadratic witness (``rho_lower_witness`` of kind "quadratic") from
    scratch: None when ``rho`` is proven below the modulus of a mode of the loop on the
    quadratics with these ``curvatures`` (each inside its function's curvature interval,
    the mode seen by the output), else why not."""
    box = _curvature_box(bk)
    names = [name for name, _, _ in bk.am.functions]
    if box is None or set(curvatures) != set(names):
        return "the curvatures do not match the spec's functions"
    q = [Fraction(str(curvatures[n])) for n in names]
    if not all(lo <= v <= hi for v, (lo, hi) in zip(q, box, strict=True)):
        return "a curvature outside its function's class"
    with precision():
        M, row = _loop_exact(bk.am, q)
        if not _observable(M, row):
            M, row = output_part(M, row)
        if not _observable(M, row):
            return "the slow mode is not seen by the output"
        if not has_root_outside(M.charpoly().coeffs(), rho):
            return "no root of the loop on these quadratics is proven outside it"
    return None


def output_part(M: arb_mat, row: arb_mat) -> tuple[arb_mat, arb_mat]:
    """The closed loop restricted to the states that reach the output: R grows from the
    states the output row reads (entries not exactly 0) by every state some state of R
    reads (M[k, i] not exactly 0, k in R). For i outside R, M[k, i] = 0 for every k in R,
    so the R-subsystem is autonomous and gives the same output sequence, with the
    eigenvalues of M on R (e.g. the two-state form of gradient descent, whose first state
    is never read: only its mode 1 - h q remains)."""
    n = M.nrows()
    reach = {i for i in range(n) if not row[0, i].is_zero()}
    grow = True
    while grow:
        new = {i for i in range(n) for k in reach if not M[k, i].is_zero()} - reach
        reach |= new
        grow = bool(new)
    keep = sorted(reach)
    if not keep or len(keep) == n:
        return M, row
    Mr = arb_mat([[M[k, i] for i in keep] for k in keep])
    return Mr, arb_mat([[row[0, i] for i in keep]])


def _prove_radius(bk: Bracketed, q: list[Fraction], M: arb_mat
                  ) -> tuple[float, dict[str, Any]] | None:
    r = _radius(bk.om, np.array([float(v) for v in q]))
    if M.nrows() < bk.om.n:  # a reduced loop: its own radius
        mid = np.array([[float(M[i, j].mid()) for j in range(M.ncols())]
                        for i in range(M.nrows())])
        r = float(np.abs(np.linalg.eigvals(mid)).max())
    coeffs = M.charpoly().coeffs()
    for below in BELOW:
        rl = float(r * (1.0 - below))
        if rl > 0 and has_root_outside(coeffs, Fraction(rl)):
            names = [name for name, _, _ in bk.am.functions]
            return rl, {"kind": "quadratic", "rho_lower": str(Fraction(rl)),
                        "curvatures": {n: str(v) for n, v in zip(names, q, strict=True)},
                        "check": "Schur-Cohn on the characteristic polynomial in balls; "
                                 "observability matrix nonsingular" + (
                                     "" if M.nrows() == bk.om.n else
                                     f" (on the {M.nrows()} states that reach the output)")}
    return None


def _rho_grid(x: float) -> Fraction:
    return Fraction(round(x * 10**6), 10**6)


def self_similar_bracket(bk: Bracketed, lo: float, hi: float, seconds: float
                         ) -> tuple[float, dict[str, Any]] | None:
    """The largest rho in (lo, hi) with a checked self-similar trajectory found by
    bisection per length K = 1..8 within ``seconds``, or None."""
    from sosalgo.witnesses.cycles import context, search_trajectory, trajectory_json

    ctx = context(bk.spec, bk.kappa, bk.theta)
    deadline = time.perf_counter() + seconds
    best: tuple[float, dict[str, Any]] | None = None
    for K in range(1, MAX_K + 1):
        a, b = max(lo, best[0] if best else lo), hi
        for _ in range(SELF_SIMILAR_STEPS):
            rho = _rho_grid(0.5 * (a + b))
            if not float(rho) > a or time.perf_counter() > deadline:
                break
            traj = search_trajectory(ctx, K, rho ** K, deadline)
            if traj is None:
                b = float(rho)
                continue
            a = float(rho)
            best = (a, {"kind": "self-similar", "rho_lower": str(rho),
                        "trajectory": trajectory_json(ctx, traj)})
        if time.perf_counter() > deadline:
            break
    return best


def rate_bracket(bk: Bracketed, upper: float | None, self_similar: bool = False,
                 seconds: float = 5.0) -> tuple[float | None, str | None, dict | None]:
    """(rho_lower, its kind, its witness): the quadratic bound, beaten by a self-similar
    trajectory when asked for and one is found below ``upper`` (or 1)."""
    quad = quadratic_bracket(bk)
    lo = quad[0] if quad else 0.0
    out = (quad[0], "quadratic", quad[1]) if quad else (None, None, None)
    top = 1.0 if upper is None else min(upper, 1.0)
    if self_similar and top > lo + 1e-6:
        ss = self_similar_bracket(bk, lo, top, seconds)
        if ss is not None and ss[0] > lo:
            return ss[0], "self-similar", ss[1]
    return out
