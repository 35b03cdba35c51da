"""Per-step coefficients written into case files, where they depend on the argument set and
a spec's sequences cannot carry them (the test checks the case files against these)."""

from __future__ import annotations

from math import sqrt


def silver_strongly_convex(kappa: float, n: int) -> list[float]:
    """The strongly convex silver step sizes (Altschuler, Parrilo), in units of 1/L: n split
    in powers of two (low bits first), each block of 2^j steps built recursively from
    psi(t) = (1 + kappa t)/(1 + t) at the pair (y_j, z_j), y_0 = z_0 = 1/kappa."""
    steps: list[float] = []
    for j in range(n.bit_length()):
        if n >> j & 1:
            steps += _silver_block(kappa, j)
    return steps


def _silver_block(kappa: float, j: int) -> list[float]:
    def psi(t: float) -> float:
        return (1 + kappa * t) / (1 + t)

    z = 1 / kappa
    block = [psi(z)]
    for _ in range(j):
        r = (1 - z) + sqrt(1 + (1 - z) ** 2)
        y, z = z / r, z * r
        block = block[:-1] + [psi(y)] + block[:-1] + [psi(z)]
    return block


def ogm_g(n: int) -> tuple[list[float], list[float]]:
    """OGM-G (Kim, Fessler) as momentum-schedule.yaml's beta_k and gamma_k: its sequence
    runs backwards, theta_n = 1, theta_k = (1 + sqrt(1 + 4 theta_{k+1}^2))/2 (8 for k = 0)."""
    theta = [1.0]
    for i in range(n):
        theta.append((1 + sqrt((8 if i == n - 1 else 4) * theta[-1] ** 2 + 1)) / 2)
    theta.reverse()
    beta = [(theta[k] - 1) * (2 * theta[k + 1] - 1) / (theta[k] * (2 * theta[k] - 1))
            for k in range(n)]
    gamma = [(2 * theta[k + 1] - 1) / (2 * theta[k] - 1) for k in range(n)]
    return beta, gamma


def accelerated_proximal_point(a0: float, gammas: list[float]) -> list[float]:
    """alpha_k of the accelerated proximal point method (Guler) with steps gammas and A_0 = a0:
    alpha_k = (sqrt((A_k g_k)^2 + 4 A_k g_k) - A_k g_k)/2, A_{k+1} = (1 - alpha_k) A_k."""
    alphas, a = [], a0
    for g in gammas:
        alpha = (sqrt((a * g) ** 2 + 4 * a * g) - a * g) / 2
        alphas.append(alpha)
        a *= 1 - alpha
    return alphas
