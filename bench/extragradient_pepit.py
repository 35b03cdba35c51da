"""Korpelevich's extragradient in PEPit's own terms, for ``specs/extragradient.yaml``.

PEPit has no extragradient example; its closest, ``past_extragradient``, fixes the
question: F + the indicator of C (``LipschitzStronglyMonotoneOperatorCheap(mu=0, L)`` and
``ConvexIndicatorFunction``), x_0 projected on C first, the worst |x_n - x_{n-1}|^2 when
|x_0 - x*|^2 <= 1. The method: x~ = P_C(x - gamma F x), x+ = P_C(x - gamma F x~).
Run it in PEPit's interpreter (``$SOSALGO_PEPIT_PYTHON bench/extragradient_pepit.py``):
one line per (gamma, n) with PEPit's value (Clarabel); ``tests/test_operators.py``
records them and checks ``sosalgo pep specs/extragradient.yaml --steps n --set gamma=..``
against them.
"""

from __future__ import annotations

CASES = ((0.25, 1), (0.25, 2), (0.25, 5), (0.125, 3))


def extragradient(n: int, gamma: float, L: float = 1.0) -> float:
    from PEPit import PEP
    from PEPit.functions import ConvexIndicatorFunction
    from PEPit.operators import LipschitzStronglyMonotoneOperatorCheap
    from PEPit.primitive_steps import proximal_step

    problem = PEP()
    ind_c = problem.declare_function(ConvexIndicatorFunction)
    F = problem.declare_function(LipschitzStronglyMonotoneOperatorCheap, mu=0, L=L)
    xs = (F + ind_c).stationary_point()
    x0 = problem.set_initial_point()
    problem.set_initial_condition((x0 - xs) ** 2 <= 1)
    x, _, _ = proximal_step(x0, ind_c, gamma)
    prev = x
    for _ in range(n):
        xt, _, _ = proximal_step(x - gamma * F.gradient(x), ind_c, gamma)
        prev = x
        x, _, _ = proximal_step(x - gamma * F.gradient(xt), ind_c, gamma)
    problem.set_performance_metric((x - prev) ** 2)
    return problem.solve(wrapper="cvxpy", solver="CLARABEL", verbose=0)


if __name__ == "__main__":
    for gamma, n in CASES:
        print(f"gamma={gamma} n={n} PEPit={extragradient(n, gamma)!r}")
