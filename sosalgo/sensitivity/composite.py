"""Noise sensitivity of composite methods (docs/noise.md,
composite specs): noise on the gradient calls of the smooth function(s).

The noisy calls i (gradient calls on ``smooth_strongly_convex`` functions) get
u_i = grad f(y_i) + w_i; the method with the noise is the oracle method with the noises
as extra inputs, xi+ = A xi + B (u + Pi w), y = C xi + D (u + Pi w): :func:`noisy_model`
appends one call per noisy call to an input-only pseudo-function (no inequalities), so
that the composite windows of :mod:`sosalgo.certificates.composite` (points, subgradients,
function values of every function, the optimum) carry the noise columns w_t and the
Lyapunov state z_k = (xi_k, u_k..u_{k-l}, w_k..w_{k-l}). The dissipation inequality

    V_{k+1} - V_k + |x_{k+1} - x*|^2 <= s |w_{k+1}|^2 + 2 w_{k+1}' (c . known)      (D)

(``known``: the columns not depending on w_{k+1}) with V_k >= 0 gives, summed,
(1/T) sum E|x_k - x*|^2 / d <= s sigma^2 n_w, n_w the number of noisy calls: gamma (per
sigma^2 and per noisy call) <= sqrt(s).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from sosalgo.certificates.composite import composite_structure
from sosalgo.kernel.solvers import SolverStatus, cvxpy_solve
from sosalgo.oracles import BoundFunction, Method
from sosalgo.sensitivity.sdp import GAP_TOL, MARGINS, NoiseCertificate, check_lag

__all__ = ["noisy_calls", "noisy_model", "composite_noise_certificate",
           "composite_noise_parts", "composite_noise_quadratic", "exact_noise_structure",
           "known_columns",
           "real_rows"]


class NoiseInput:
    """The pseudo-class of the noise inputs: no inequality (any value)."""

    name = "noise"

    def tilted(self, params: Any) -> list[Any]:
        return []


NOISE = NoiseInput()


def real_calls(nm: Method) -> int:
    """How many calls of the noisy model ``nm`` are the method's own (the noise calls come
    after them)."""
    return sum(1 for j in nm.oracles if nm.functions[j].cls is not NOISE)


def noisy_calls(om: Any) -> list[int]:
    """The gradient calls (D_ii = 0) on functions of classes with ``noisy_gradients``
    (smooth_strongly_convex)."""
    return [i for i, j in enumerate(om.oracles)
            if om.functions[j].cls.noisy_gradients and om.D[i, i] == 0]


def _augment(A: Any, B: Any, C: Any, D: Any, noisy: list[int], zero: Any) -> tuple:
    """(B, C, D) with the noise columns B Pi, D Pi and zero rows for the noise calls."""
    p, nw = C.shape[0], len(noisy)
    Bw, Dw = B[:, noisy], D[:, noisy]
    Cz = np.full((nw, C.shape[1]), zero, dtype=C.dtype)
    Dz = np.full((nw, p + nw), zero, dtype=D.dtype)
    return np.hstack([B, Bw]), np.vstack([C, Cz]), np.vstack([np.hstack([D, Dw]), Dz])


def noisy_model(om: Any, exact: Any = None) -> Method:
    """The noisy model of an OracleMethod ``om``: the method with the noises as extra
    calls (A, B, C, D, E augmented; a pseudo-class ``noise``, measure ``distance``), over
    floats (or, with ``exact`` the method over balls, over balls)."""
    noisy = noisy_calls(om)
    J = len(om.functions)
    noise = (BoundFunction("noise", NOISE, {}),)  # type: ignore[arg-type]
    oracles = tuple(om.oracles) + (J,) * len(noisy)
    if exact is None:
        B, C, D = _augment(om.A, om.B, om.C, om.D, noisy, 0.0)
        return Method(om.A, B, C, D, om.E, om.m, float(om.L), tuple(om.functions) + noise,
                      oracles, om.output, "distance")
    from sosalgo.kernel.exact import Ball

    B, C, D = _augment(exact.A, exact.B, exact.C, exact.D, noisy, Ball(0))
    return replace(exact, B=B, C=C, D=D, functions=tuple(exact.functions) + noise,
                   oracles=oracles, measure="distance")


def known_columns(nm: Method, lag: int, width: int) -> list[int]:
    """Columns of the decrease window not depending on the new noise w_{l+1}: all but the
    noise columns at time l + 1 and the calls at l + 1 whose point depends on them."""
    p, pr, t = nm.p, real_calls(nm), lag + 1
    unknown = set(range(pr, p))
    grew = True
    while grew:
        grew = False
        for i in range(pr):
            if i not in unknown and any(nm.D[i, j] != 0 for j in unknown if j != i):
                unknown.add(i)
                grew = True
    drop = {nm.n + p * t + i for i in unknown}
    return [k for k in range(width) if k not in drop]


def real_rows(nm: Method, lag: int, nphi: int) -> tuple[list[int], list[int]]:
    """(rows of F, columns of phi) of the real calls (the noise calls carry no values)."""
    pr = real_calls(nm)
    rows = [tau * nm.p + i for tau in range(lag + 1) for i in range(pr)]
    return rows, [q for q in range(nphi) if q % nm.p < pr]


def composite_noise_parts(nm: Any, st: Any, cert: dict[str, Any],
                          known: list[int]) -> dict[str, Any]:
    """(D, Df, Pq, Pf) of (D) at a certificate (float or exact numbers): D ⪯ 0, Df <= 0,
    Pq ⪰ 0, Pf >= 0 prove gamma <= sqrt(s)."""
    d, p, lag = st.dec, st.pos, st.lag
    rows, cols = real_rows(nm, lag, d.nphi)
    P, pi, s, c = cert["P"], np.array(cert["p"], dtype=object), cert["s"], cert["c"]
    eta, lam = cert["eta"], cert["lam"]
    Z1, Z0, Zp = d.Z[lag + 1], d.Z[lag], p.Z[lag]
    D = Z1.T @ P @ Z1 - Z0.T @ P @ Z0 + d.meas_quad
    for e, M in zip(eta, d.Mq, strict=True):
        D = D + e * M
    noise = [nm.n + nm.p * (lag + 1) + i for i in range(real_calls(nm), nm.p)]
    ci = iter(c)
    for w in noise:
        D[w, w] = D[w, w] - s
        for k in known:
            v = next(ci)
            D[w, k] = D[w, k] - v
            D[k, w] = D[k, w] - v
    Df = d.F[lag + 1][rows].T @ pi - d.F[lag][rows].T @ pi
    Pq = Zp.T @ P @ Zp
    Pf = p.F[lag][rows].T @ pi
    for e, mv in zip(eta, d.mq, strict=True):
        Df = Df + e * mv
    for v, M, mv in zip(lam, p.Mq, p.mq, strict=True):
        Pq = Pq - v * M
        Pf = Pf - v * mv
    return {"D": D, "Df": Df[cols], "Pq": Pq, "Pf": Pf[real_rows(nm, lag, p.nphi)[1]]}


def _solve(nm: Method, st: Any, known: list[int], margin: float,
           weight: float) -> tuple[str, dict[str, Any] | None, str]:
    """One SDP (cvxpy, Clarabel) at ``margin`` with the supply weighted by ``weight``."""
    import cvxpy as cp

    d, p, lag = st.dec, st.pos, st.lag
    nz = d.Z[lag].shape[0]
    pr = real_calls(nm)
    nw = nm.p - pr
    var = {"P": cp.Variable((nz, nz), symmetric=True), "p": cp.Variable((lag + 1) * pr),
           "s": cp.Variable(), "c": cp.Variable(nw * len(known)),
           "eta": cp.Variable(len(d.labels), nonneg=True),
           "lam": cp.Variable(len(p.labels), nonneg=True)}
    scaled = replace(d, meas_quad=weight * d.meas_quad)
    st2 = replace(st, dec=scaled)
    ex = _cvx_parts(nm, st2, var, known)
    W, Wp = d.width, p.width
    cons = [ex["D"] << -margin * np.eye(W), ex["Pq"] >> margin * np.eye(Wp),
            ex["Df"] <= -margin, ex["Pf"] >= margin]
    prob = cp.Problem(cp.Minimize(var["s"]), cons)
    end = cvxpy_solve(prob, cp.CLARABEL, tol_gap_abs=GAP_TOL, tol_gap_rel=GAP_TOL)
    if end.error is not None:  # a crash is just "no answer"
        return "failed", None, f"exception: {type(end.error).__name__}"
    if end.status != SolverStatus.SOLVED:
        return ("infeasible" if end.status == SolverStatus.INFEASIBLE else "failed"), None, \
            f"clarabel: {prob.status}"
    vals = {k: np.array(v.value, dtype=float) / weight for k, v in var.items()}
    vals["s"] = float(vals["s"])
    vals["eta"], vals["lam"] = np.maximum(vals["eta"], 0.0), np.maximum(vals["lam"], 0.0)
    return "solved", vals, f"clarabel: {prob.status}, margin {margin:g}"


def _cvx_parts(nm: Method, st: Any, var: dict[str, Any], known: list[int]) -> dict:
    """The parts as cvxpy expressions (affine in the variables)."""
    import cvxpy as cp

    d, p, lag = st.dec, st.pos, st.lag
    rows, cols = real_rows(nm, lag, d.nphi)
    Z1, Z0, Zp = d.Z[lag + 1], d.Z[lag], p.Z[lag]
    W = d.width
    D = Z1.T @ var["P"] @ Z1 - Z0.T @ var["P"] @ Z0 + d.meas_quad
    D = D + sum(var["eta"][k] * d.Mq[k] for k in range(len(d.labels)))
    noise = [nm.n + nm.p * (lag + 1) + i for i in range(real_calls(nm), nm.p)]
    k = 0
    for w in noise:
        D = D - var["s"] * _unit(W, w, w)
        for col in known:
            D = D - var["c"][k] * (_unit(W, w, col) + _unit(W, col, w))
            k += 1
    Df = (d.F[lag + 1][rows] - d.F[lag][rows]).T @ var["p"] + d.mq.T @ var["eta"]
    Pq = Zp.T @ var["P"] @ Zp - sum(var["lam"][k] * p.Mq[k] for k in range(len(p.labels)))
    Pf = p.F[lag][rows].T @ var["p"] - p.mq.T @ var["lam"]
    return {"D": (D + D.T) / 2, "Df": cp.hstack([Df[q] for q in cols]), "Pq": (Pq + Pq.T) / 2,
            "Pf": cp.hstack([Pf[q] for q in real_rows(nm, lag, p.nphi)[1]])}


def _unit(W: int, a: int, b: int) -> np.ndarray:
    out = np.zeros((W, W))
    out[a, b] = 1.0
    return out


def float_checks(parts: dict[str, Any]) -> dict[str, float]:
    """Largest violation of each part at a point (floating-point check)."""
    return {"max_eig_D": float(np.linalg.eigvalsh(parts["D"].astype(float))[-1]),
            "max_Df": float(np.max(parts["Df"].astype(float))),
            "min_eig_Pq": float(np.linalg.eigvalsh(parts["Pq"].astype(float))[0]),
            "min_Pf": float(np.min(parts["Pf"].astype(float)))}


def composite_noise_certificate(om: Any, lag: int = 0, quadratic: float = 1.0,
                                margins: tuple[float, ...] = MARGINS) -> NoiseCertificate:
    """Certified gamma (per noisy call) of an OracleMethod ``om`` with lag ``lag``
    (original units; ``quadratic``: the quadratic value, used to scale the supply)."""
    check_lag(lag)
    start = time.perf_counter()
    if not math.isfinite(quadratic):
        return NoiseCertificate(None, lag, "infeasible", "none",
                                detail="unstable on a quadratic of the class")
    nm = noisy_model(om)
    st = composite_structure(nm, lag)
    known = known_columns(nm, lag, st.dec.width)
    weight = 1.0 / max(quadratic, 1e-6) ** 2
    status, detail, checks = "failed", "", {}
    for margin in margins:
        status, vals, detail = _solve(nm, st, known, margin, weight)
        if vals is None:
            if status == "infeasible":
                break
            continue
        checks = float_checks(composite_noise_parts(nm, st, vals, known))
        if (checks["max_eig_D"] <= 0 and checks["max_Df"] <= 0 and checks["min_eig_Pq"] >= 0
                and checks["min_Pf"] >= 0 and vals["s"] > 0):
            cert = {"lag": lag, "noisy": [f"y{i + 1}" for i in noisy_calls(om)], "P": vals["P"],
                    "p": vals["p"].tolist(), "s": vals["s"], "c": vals["c"].tolist(),
                    "multipliers": {
                        "decrease": dict(zip(st.dec.labels, vals["eta"].tolist(), strict=True)),
                        "positivity": dict(zip(st.pos.labels, vals["lam"].tolist(),
                                               strict=True))}}
            return NoiseCertificate(math.sqrt(vals["s"]), lag, "certified", "float", cert,
                                    checks, time.perf_counter() - start, detail)
        status, detail = "failed", detail + "; floating-point check failed"
    return NoiseCertificate(None, lag, status, "none", None, checks,
                            time.perf_counter() - start, detail)


def _loop_gamma2(nm: Method, K: np.ndarray) -> float:
    """gamma^2 per noisy call of the linear loop u = K y (K: curvature per real call)."""
    pr, n = real_calls(nm), nm.n
    nw = nm.p - pr
    C, D = nm.C[:pr], nm.D[:pr, :pr]
    Pi = nm.D[:pr, pr:]  # D Pi
    M = np.linalg.solve(np.eye(pr) - K @ D, K)  # u = M (C xi + D Pi w)
    Aq = nm.A + nm.B[:, :pr] @ M @ C
    Bq = nm.B[:, :pr] @ M @ Pi + nm.B[:, pr:]
    if np.max(np.abs(np.linalg.eigvals(Aq))) >= 1.0:
        return math.inf
    if nm.output is None:
        Eo, Fo = nm.E[0], np.zeros(nw)
    else:
        o = nm.output
        Eo = C[o] + D[o] @ M @ C
        Fo = D[o] @ M @ Pi + Pi[o]
    X = np.linalg.solve(np.eye(n * n) - np.kron(Aq, Aq), (Bq @ Bq.T).reshape(-1))
    return float((Eo @ X.reshape(n, n) @ Eo + Fo @ Fo) / nw)


def composite_noise_quadratic(om: Any, points: int = 41) -> tuple[float, list[float]]:
    """max of gamma over every function at its class's quadratics (q/2)|x|^2 (q on a grid
    of [lo, hi] from ``curvatures``, 0 for convex and indicators): (gamma, worst q's)."""
    import itertools

    nm = noisy_model(om)
    ranges = [fn.cls.curvatures(fn.params) or (0.0, 0.0) for fn in om.functions]
    grids = [np.linspace(lo, hi, points) if hi > lo else np.array([lo]) for lo, hi in ranges]
    best, worst = -math.inf, [0.0] * len(grids)
    for qs in itertools.product(*grids):
        K = np.diag([qs[j] for j in om.oracles])
        g2 = _loop_gamma2(nm, K)
        if g2 > best:
            best, worst = g2, [float(q) for q in qs]
    return math.sqrt(best), worst


def exact_noise_structure(spec: Any, kappa: float, theta: Any, lag: int, digits: int) -> tuple:
    """(float noisy model, exact windows of the exact method as a structure, known
    columns): the data of the exact proof (:mod:`sosalgo.sensitivity.exact`)."""
    from types import SimpleNamespace

    from sosalgo.certificates.exact_composite import (
        exact_class_inequalities,
        exact_oracle_method,
        exact_window,
        fixed_point_failure,
    )
    from sosalgo.model import bind

    om = bind(spec, float(kappa), theta)
    nm = noisy_model(om)
    exact = exact_oracle_method(spec, kappa, theta, digits)
    bad = fixed_point_failure(exact, om)  # proven exactly (sympy), as for the rates
    if bad:
        raise ValueError(bad)
    ex = noisy_model(om, exact)
    ineqs = [exact_class_inequalities(c, pr)[0] for _, c, pr in ex.functions[:-1]] + [[]]
    st = SimpleNamespace(lag=lag, dec=exact_window(ex, lag, lag + 2, ineqs),
                         pos=exact_window(ex, lag, lag + 1, ineqs))
    return nm, st, known_columns(nm, lag, st.dec.width)

