"""The windows of the noise-sensitivity certificate (docs/noise.md).

The method runs with noisy gradients, xi_{t+1} = A xi_t + B (g_t + w_t), g_t = grad f(y_t),
y_t = C xi_t, x_t = E xi_t (coordinates relative to the fixed point xi* = u x*, so that
y* = x* = 0 and g* = 0; the d = 1 templates, ⊗ I_d implied). With the lag l >= 0 the
Lyapunov function at time k sees the lifted state

    h_k = (xi_{k-l}, g_{k-l}, ..., g_k, w_{k-l}, ..., w_{k-1})        (n + 2l + 1 entries)
    V_k = h_k' P h_k + sum_{j=0..l} p_j (f(y_{k-j}) - f*).

A window is written on the vector v = (xi_0, g_0, ..., g_{T-1}, w_0, ..., w_{T-2}) (time 0
is k - l; T = l + 2 for the decrease window, whose last noise w_{l} is the new noise w_k,
and T = l + 1 for the positivity window, on which v = h_k itself), with the function
values phi = (f_0, ..., f_{T-1}) - f*. Interpolation pairs q_ij >= 0 of the function class
are formed between every ordered pair of the points y_0, ..., y_{T-1} and the minimizer.

The same builder runs on floats (the SDP data) and on object arrays of exact numbers
(rationals, :class:`sosalgo.verify.exact.Ball`) for the exact verifier: it only adds,
multiplies and stacks.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["NoiseWindow", "add_noise_terms", "noise_window", "noise_parts", "past_noise",
           "state_size"]


def state_size(n: int, lag: int) -> int:
    """Size of the lifted state h_k (and of P): n + 2 lag + 1."""
    return n + 2 * lag + 1


@dataclass
class NoiseWindow:
    """One window: row maps on v, its interpolation pairs and the noise column."""

    n: int
    lag: int
    steps: int  # T: gradients g_0..g_{T-1}
    width: int  # length of v
    H: dict[int, Any]  # H[t]: rows of h at time t (t = lag, lag + 1) as maps on v
    x_row: Any  # x_l = E xi_l (the measured point at time k)
    labels: list[str]  # "i>j" for the pair q_ij
    Mq: list[Any]  # quadratic part of q_ij (width x width)
    mq: list[Any]  # linear part of q_ij on phi (steps entries)
    noise: int | None  # column of the new noise w_k in v (decrease window), else None
    measurable: list[int]  # columns known at time k (free cross terms with w_k)


def _zeros(shape: tuple[int, ...], obj: bool) -> np.ndarray:
    return np.full(shape, 0, dtype=object) if obj else np.zeros(shape)


def _eye(n: int, obj: bool) -> np.ndarray:
    out = _zeros((n, n), obj)
    for i in range(n):
        out[i, i] = 1
    return out


def noise_window(A: Any, B: Any, C: Any, E: Any, alpha: Any, Q: Any, lag: int, steps: int,
                 obj: bool = False) -> NoiseWindow:
    """The window of ``steps`` gradients (l + 2: decrease, l + 1: positivity) for the class
    inequality ``alpha (f_i - f_j) + X' Q X >= 0``, X = (y_i, y_j, g_i, g_j)."""
    n = A.shape[0]
    nw = steps - 1
    width = n + steps + nw
    unit = _eye(width, obj)
    G = [unit[n + t: n + t + 1] for t in range(steps)]
    W = [unit[n + steps + t: n + steps + t + 1] for t in range(nw)]
    Xi = [unit[:n]]
    for t in range(steps - 1):
        Xi.append(A @ Xi[t] + B @ (G[t] + W[t]))
    H = {t: np.vstack([Xi[t - lag]] + G[t - lag: t + 1] + W[t - lag: t])
         for t in (lag, lag + 1) if t < steps}
    pts = [(f"y{t}", C @ Xi[t], G[t], t) for t in range(steps)]
    pts.append(("*", _zeros((1, width), obj), _zeros((1, width), obj), None))
    labels, Mq, mq = [], [], []
    for ni, yi, gi, fi in pts:
        for nj, yj, gj, fj in pts:
            if ni == nj:
                continue
            X = np.vstack([yi, yj, gi, gj])
            Mq.append(X.T @ Q @ X)
            lin = _zeros((steps,), obj)
            if fi is not None:
                lin[fi] = lin[fi] + alpha
            if fj is not None:
                lin[fj] = lin[fj] - alpha
            mq.append(lin)
            labels.append(f"{ni}>{nj}")
    decrease = steps == lag + 2
    noise = n + steps + lag if decrease else None
    measurable = [i for i in range(width) if i not in (noise, n + lag + 1)] if decrease else []
    return NoiseWindow(n, lag, steps, width, H, E @ Xi[lag], labels, Mq, mq, noise, measurable)


def past_noise(win: NoiseWindow) -> list[tuple[int, list[int]]]:
    """The past noises w_t (t = 0 .. l - 1, not the new one) of a window, each with the
    columns known before it is drawn (xi_0, g_0 .. g_t, w_0 .. w_{t-1}): (column, known).
    A term w_t' (c . known) has mean zero; E|w_t|^2 <= sigma^2 d."""
    n, steps = win.n, win.steps
    return [(n + steps + t, list(range(n + t + 1)) + list(range(n + steps, n + steps + t)))
            for t in range(win.lag)]


def add_noise_terms(M: Any, win: NoiseWindow, r: Any, cross: Any, sign: int = 1) -> Any:
    """M + sign (sum r_t e_t e_t' + sum cross (e_t k' + k e_t')) over :func:`past_noise`."""
    cs = iter(cross)
    for rt, (col, known) in zip(r, past_noise(win), strict=True):
        M[col, col] = M[col, col] + sign * rt
        for k in known:
            ck = sign * next(cs)
            M[col, k] = M[col, k] + ck
            M[k, col] = M[k, col] + ck
    return M


def _values(win: NoiseWindow, t: int, p: Any, obj: bool) -> np.ndarray:
    """The function-value part of V at time t as coefficients on phi: p_j on f_{t-j}."""
    out = _zeros((win.steps,), obj)
    for j in range(win.lag + 1):
        out[t - j] = out[t - j] + p[j]
    return out


def noise_parts(dec: NoiseWindow, pos: NoiseWindow, P: Any, p: Any, s: Any, c: Any, eta: Any,
                lam: Any, obj: bool = False, rho2: Any = None,
                past: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The four parts of the certificate (docs/noise.md):

    ``D`` ⪯ 0 and ``Df`` <= 0 (decrease: E V_{k+1} - V_k + |x_k - x*|^2 <= s sigma^2 d),
    ``Pq`` ⪰ 0 and ``Pf`` >= 0 (positivity: V_k >= 0), where
    D = H_{l+1}' P H_{l+1} - H_l' P H_l + x_l' x_l + sum eta M - s e_w e_w' - (e_w c' + c e_w'),
    c the free cross terms of the new noise with the columns known at time k.

    With ``rho2`` (= rho^2) the discounted form of ``noise_limsup`` (docs/noise.md, "The limsup
    itself"): D = H_{l+1}' P H_{l+1} - rho2 H_l' P H_l + ... (no output term; the function
    values likewise discounted: E V_{k+1} <= rho^2 V_k + s sigma^2 d) and the output term
    moved into the positivity part, Pq = H_l' P H_l - x_l' x_l - ... (V_k >= |x_k - x*|^2),
    both relaxed by the past noises (:func:`add_noise_terms`; ``past``: ``sd``, ``cd`` in D,
    ``r``, ``cp`` in Pq) so that they hold in expectation: E V_{k+1} <= rho^2 E V_k +
    (s + sum sd) sigma^2 d and E V_k >= E|x_k - x*|^2 - sum r sigma^2 d."""
    lag = dec.lag
    H1, H0 = dec.H[lag + 1], dec.H[lag]
    xx = dec.x_row.T @ dec.x_row
    if rho2 is None:
        D = H1.T @ P @ H1 - H0.T @ P @ H0 + xx
        Df = _values(dec, lag + 1, p, obj) - _values(dec, lag, p, obj)
    else:
        D = H1.T @ P @ H1 - rho2 * (H0.T @ P @ H0)
        Df = _values(dec, lag + 1, p, obj) - rho2 * _values(dec, lag, p, obj)
    for e, M, mv in zip(eta, dec.Mq, dec.mq, strict=True):
        D = D + e * M
        Df = Df + e * mv
    w = dec.noise
    D[w, w] = D[w, w] - s
    for ci, col in zip(c, dec.measurable, strict=True):
        D[w, col] = D[w, col] - ci
        D[col, w] = D[col, w] - ci
    Pq = pos.H[lag].T @ P @ pos.H[lag]
    if rho2 is not None:
        Pq = Pq - pos.x_row.T @ pos.x_row
        if past is not None:
            D = add_noise_terms(D, dec, past["sd"], past["cd"], -1)
            Pq = add_noise_terms(Pq, pos, past["r"], past["cp"])
    Pf = _values(pos, lag, p, obj)
    for lv, M, mv in zip(lam, pos.Mq, pos.mq, strict=True):
        Pq = Pq - lv * M
        Pf = Pf - lv * mv
    return {"D": D, "Df": Df, "Pq": Pq, "Pf": Pf}
