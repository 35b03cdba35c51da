"""The interface of a function class: parameters, oracles, interpolation data.

A class describes the functions one name of a spec's ``functions:`` may stand for. The
interpolation certificate family only reads the data declared here:

- ``parameters`` and their default expressions (in m, L, kappa of the spec);
- ``oracles``: which calls it answers (``gradient``, ``subgradient``, ``proximal``);
- :meth:`FunctionClass.inequalities`: its pairwise interpolation inequalities, each
  ``alpha (f_a - f_b) + X' Q X >= 0`` with ``X = (x_a, x_b, g_a, g_b)`` (the d = 1
  template; ``⊗ I_d`` implied), required for every ordered pair of points (a, b) of one
  function (Taylor, Hendrickx, Glineur 2017, Thm. 4 and Section 3);
- :meth:`FunctionClass.tilted`: the inequalities of the tilted functions
  h(z) = f(z) - f(x*) - <s*, z - x*> (s* a subgradient at x*), which the certificate uses;
  the class's own inequalities when ``tilt_invariant`` (the class is closed under adding
  linear functions);
- ``convex``: every function of the class is convex (False: no Lyapunov family of
  ``analyze`` applies; ``pep`` answers);
- ``has_values``: the members have function values (False: operators,
  :mod:`sosalgo.classes.operator`: no values, every inequality has alpha = 0, and a
  measure or initial condition in f is refused);
- inhomogeneous and optimum-only conditions (:class:`Inequality` ``constant`` and
  ``scope``; :meth:`FunctionClass.exact_constants`), with ``homogeneous`` False (no
  Lyapunov family applies), ``alone`` (conditions on the function itself, not the tilted
  one: the only function of its spec), ``minimizer`` (a nonconvex class whose PEP keeps
  x*), ``interpolating`` (False: necessary conditions only, the PEP an upper bound);
- ``zero_values``: every function value is 0 (indicators: f = 0 on the set);
- ``finite_everywhere``: the function has a (sub)gradient at every point, so it may be
  evaluated where the method never queries it (the output point of ``measure: function``);
- :meth:`FunctionClass.curvatures`: the curvatures q of the quadratics (q/2)|x|^2 in the
  class (an interval, or None), for the rate-on-quadratics lower bound;
  :meth:`FunctionClass.exact_curvatures` the same from rational bounds of the parameters
  (the quadratic rate brackets);
- :meth:`FunctionClass.exact_tilted`: the exact twin of :meth:`FunctionClass.tilted`, on
  exact parameters (balls), for the exact checks (None: the float data are enclosed);
- :meth:`FunctionClass.strong_convexity`: a modulus every function of the class has
  (searching cycles needs one); :meth:`FunctionClass.gradient_floor`: the lower complexity
  bound of methods that query gradients of it alone (the class floor of a design);
  ``noisy_gradients``: its gradient calls may carry noise (noise sensitivity);
- ``tilted_text``: its tilted inequality as text and LaTeX (``sosalgo lmi`` listings);
- :meth:`FunctionClass.test_functions`: functions of the class with closed-form proximal
  steps (:mod:`sosalgo.classes.members`), for simulations;
- :meth:`FunctionClass.blocks`: Gram-level conditions (linear operators, quadratics): a
  matrix over all the points of one function that must be positive semidefinite, each
  entry ``[x_a; g_a]' K [x_b; g_b]`` (K 2 x 2, tilted data); :meth:`exact_blocks` their
  exact twin. A class with blocks is not ``homogeneous`` (no Lyapunov family takes
  them; ``pep`` answers, :mod:`sosalgo.worstcase.blocks`).
- :meth:`FunctionClass.lmis`: small LMIs on tuples of points (:class:`TupleLMI`, built
  with :mod:`sosalgo.classes.lmi_forms`), each entry linear in the tuple's Gram entries
  and values plus free multipliers of its own (the "expensive" conditions of
  Rubbens, Hendrickx, Taylor 2025); :meth:`exact_lmis` their exact twin
  (:mod:`sosalgo.worstcase.lmis`). A class with LMIs is not ``homogeneous``.

:data:`sosalgo.classes.SEED_CLASS` is F(m, L), the class of a spec without ``functions:``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.classes.members import ProxFunction, quadratic

__all__ = ["ANCHOR", "FunctionClass", "Inequality", "ORACLE_KINDS", "PAIR_SCOPES",
           "TupleLMI", "check_mu_below_L", "convex_form", "exact_convex_form"]

ORACLE_KINDS = ("gradient", "subgradient", "proximal")


PAIR_SCOPES = ("pairs", "optimum", "anchor")
ANCHOR = "o"  # the label prefix of an anchored class's origin point (``anchored``)


def check_mu_below_L(params: Mapping[str, float], zero: bool = False) -> None:
    """ValueError('<parameter>: ...') unless 0 < mu <= L < inf (the classes with a
    growth modulus mu below a smoothness L; ``zero``: mu = 0 allowed, a spectrum or a
    modulus in [0, L])."""
    mu, L = params["mu"], params["L"]
    if not (np.isfinite(L) and L > 0):
        raise ValueError(f"L: must be positive and finite, got {L:g}")
    if zero and not (np.isfinite(mu) and 0 <= mu <= L):
        raise ValueError(f"mu: must be in [0, L] = [0, {L:g}], got {mu:g}")
    if not zero and not (np.isfinite(mu) and 0 < mu <= L):
        raise ValueError(f"mu: must be in (0, L] = (0, {L:g}], got {mu:g}")

@dataclass(frozen=True)
class Inequality:
    """``alpha (f_a - f_b) + X' Q X + constant >= 0`` on ``X = (x_a, x_b, g_a, g_b)``
    (Q 4 x 4), required for every ordered pair of points (``scope`` "pairs") or only for
    each point a with b = x*, the minimizer (``scope`` "optimum": quadratic growth, error
    bounds, Lojasiewicz conditions; a condition on the point alone, such as |g_a|^2 <=
    M^2, is one of these with Q on g_a only; ``scope`` "anchor": for each point a with b
    = o, the origin of an ``anchored`` class). ``constant`` >= 0, in the units of f (an
    inhomogeneous condition: M^2, D^2); the PEP of a class with a constant is no longer
    scale invariant, its worst case is the one under ``initial <= 1``."""

    alpha: float
    Q: np.ndarray
    constant: float = 0.0
    scope: str = "pairs"


@dataclass(frozen=True)
class TupleLMI:
    """``T = T0(z, f) + sum_k M_k E_k ⪰ 0`` for some real M_k (the free multipliers), for
    every ordered tuple of ``arity`` points of one function that are not all the same
    point (x* among them), with x* appended as its last point when ``optimum``. On the
    tuple's p points, z = (x_1, ..., x_p, g_1, ..., g_p) and f = (f_1, ..., f_p):
    ``T0[u, v] = z' gram[u, v] z + values[u, v] . f``; ``free[k]`` is E_k (m x m,
    symmetric). Entries are floats, or rationals and balls in the exact twin."""

    arity: int
    gram: np.ndarray  # (m, m, 2p, 2p)
    values: np.ndarray  # (m, m, p)
    free: np.ndarray  # (nfree, m, m)
    optimum: bool = False

    @property
    def size(self) -> int:
        return int(self.gram.shape[0])


class FunctionClass:
    """Base of the shipped classes; a new class overrides the members below."""

    name: str = ""
    description: str = ""
    parameters: tuple[str, ...] = ()
    defaults: Mapping[str, str] = {}
    oracles: frozenset[str] = frozenset()
    convex: bool = True
    has_values: bool = True
    zero_values: bool = False
    finite_everywhere: bool = False
    tilt_invariant: bool = True
    noisy_gradients: bool = False
    tilted_text: tuple[str, str] | None = None  # (plain, LaTeX); None: listed by its data
    # every (q/2)|x|^2 with q >= 0 is in the class (witnesses may pick any curvature)
    free_curvature: bool = False
    # every condition is a pairwise homogeneous inequality (no constant, no condition
    # about x* alone): False, no Lyapunov family of ``analyze`` applies; ``pep`` answers
    homogeneous: bool = True
    # its conditions hold for the function itself, not for the tilted one (a bound on
    # |g|, on f - f*): the PEP takes it as the only function of the spec, whose optimal
    # subgradient is then 0 (tilted = own data)
    alone: bool = False
    # its conditions are necessary but not sufficient for interpolation: a PEP over them
    # is an upper bound of the worst case, not necessarily tight (said in the output)
    interpolating: bool = True
    # several operators of this class (and no other) take the sublinear family's state
    # change |xi_{k+1} - xi_k|^2 from a free start: each of its inequalities vanishes on
    # the fixed points that move with the optimal answers (maximally monotone operators)
    state_change_rates: bool = False
    # the PEP keeps a minimizer x* for it although it is not convex (the class has a
    # global minimizer by assumption: PL, RSI/EB)
    minimizer: bool = False
    # its functions are positively homogeneous about an origin o (support functions): the
    # PEP adds o as a free point of the function with tilted value and subgradient 0, and
    # the inequalities of scope "anchor" hold between each point and o
    anchored: bool = False
    # a linear operator with a transpose call (``{function: M, transpose: true}``), so that
    # functions may be composed with it (:mod:`sosalgo.spec.adjoint`)
    transposable: bool = False
    # how its transpose's calls enter the PEP: 0, points of their own (with the equalities
    # <x_a, M' u_b> = <M x_a, u_b>); 1, M' = M (points of M); -1, M' = -M (points of M,
    # the answer negated)
    transpose_sign: int = 0
    # an operator class that is exactly the set of operators satisfying its pairwise
    # conditions (so a normal linear operator satisfying them is a member: the linear
    # witnesses of operator designs, :mod:`sosalgo.design_search.witness`)
    pairwise_defined: bool = False

    def check(self, params: Mapping[str, float]) -> None:
        """Raise ValueError('<parameter>: what is wrong') for invalid values."""

    def inequalities(self, params: Mapping[str, float]) -> list[Inequality]:
        """The pairwise interpolation inequalities at these parameter values."""
        raise NotImplementedError

    def tilted(self, params: Mapping[str, float]) -> list[Inequality]:
        """Inequalities valid for the tilted functions h = f - f(x*) - <s*, . - x*> (values
        and subgradients of h): the class's own when ``tilt_invariant``."""
        if not self.tilt_invariant:
            raise NotImplementedError(f"class {self.name}: not tilt invariant, give tilted()")
        return self.inequalities(params)

    def pinned(self, params: Mapping[str, float]) -> list[Inequality]:
        """The inequalities where the PEP pins the function's optimal subgradient at 0
        (indicators alone, :func:`sosalgo.oracles.pinned_optimum`): the tilted function is
        then the function itself; by default :meth:`tilted` (a class whose own
        conditions are tighter gives them)."""
        return self.tilted(params)

    def exact_pinned(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]] | None:
        """The exact twin of :meth:`pinned` (as :meth:`exact_tilted` is of :meth:`tilted`)."""
        return self.exact_tilted(params)

    def curvatures(self, params: Mapping[str, float]) -> tuple[float, float] | None:
        """[lo, hi] such that (q/2)|x|^2 is in the class for q in [lo, hi] (None: none)."""
        return None

    def exact_curvatures(self, lower: Callable[[str], Fraction],
                         upper: Callable[[str], Fraction],
                         ) -> tuple[Fraction, Fraction] | None:
        """A rational [lo, hi] such that (q/2)|x|^2 is in the class for every q in it and
        every parameter value p with ``lower(p) <= p <= upper(p)`` (rational bounds of each
        parameter's enclosure); None: none known."""
        return None

    def exact_tilted(self, params: Mapping[str, Any]) -> list[tuple[Any, Any]] | None:
        """The exact twin of :meth:`tilted`: (alpha, Q) of each inequality, computed from the
        exact parameters (balls) with rational constants, so that every entry encloses the
        exact value; None: no exact data (the float data are enclosed instead)."""
        return None

    def exact_constants(self, params: Mapping[str, Any]) -> list[Any] | None:
        """The exact twin of each inequality's ``constant`` (balls or rationals, from the
        exact parameters), in the order of :meth:`exact_tilted`; None: every constant is
        0 (a class with a nonzero constant must give them)."""
        return None

    def blocks(self, params: Mapping[str, float]) -> list[np.ndarray]:
        """The Gram-level conditions: each a symmetric 2 x 2 K such that the matrix
        T[a, b] = [x_a; g_a]' K [x_b; g_b] over every point of one function (tilted data,
        x* a zero row) is positive semidefinite ([] by default: pairwise conditions only)."""
        return []

    def exact_blocks(self, params: Mapping[str, Any]) -> list[np.ndarray] | None:
        """The exact twin of :meth:`blocks` (object arrays of rationals or balls, from
        the exact parameters); None: no blocks."""
        return None

    def lmis(self, params: Mapping[str, float]) -> list[TupleLMI]:
        """The LMI conditions on tuples of points ([] by default: scalar conditions only;
        :mod:`sosalgo.worstcase.lmis`)."""
        return []

    def exact_lmis(self, params: Mapping[str, Any]) -> list[TupleLMI] | None:
        """The exact twin of :meth:`lmis` (object arrays of rationals or balls, from the
        exact parameters; each free direction E_k rational); None: none."""
        return None

    def strong_convexity(self, params: Mapping[str, float]) -> float:
        """A modulus mu > 0 such that every function of the class is mu-strongly convex
        (0: none)."""
        return 0.0

    def gradient_floor(self, params: Mapping[str, float]) -> float | None:
        """A rate no first-order method querying gradients of one function of the class
        alone can beat on the whole class (a theorem), or None."""
        return None

    def listing_text(self, params: Mapping[str, float], latex: bool) -> str:
        """The pairwise inequality of the tilted functions, for listings: ``tilted_text``,
        else the description and the data (alpha, Q)."""
        if self.tilted_text is not None:
            return self.tilted_text[1] if latex else self.tilted_text[0]
        import sympy as sp  # listings only: numeric work never imports sympy

        data = "; ".join(f"alpha = {q.alpha:g}, Q = {sp.sstr(sp.Matrix(q.Q))}"
                         for q in self.tilted(params))
        return f"{self.description}: alpha (h_a - h_b) + X'QX >= 0, {data}"

    def test_functions(self, params: Mapping[str, float], xs: np.ndarray,
                       rng: np.random.Generator) -> list[ProxFunction]:
        """Functions of the class at these parameters with closed-form proximal steps, built
        around the minimizer ``xs`` (:mod:`sosalgo.classes.members`): by default the
        quadratics at both ends of :meth:`curvatures` (none without)."""
        cur = self.curvatures(params)
        if cur is None:
            return []
        lo, hi = cur
        d = len(xs)
        return [quadratic(np.full(d, lo), xs, rng, "quad-lo"),
                quadratic(np.full(d, hi), xs, rng, "quad-hi")]

    @property
    def explicit(self) -> bool:
        """Whether the class answers a (sub)gradient call (a zero diagonal entry of D)."""
        return bool({"gradient", "subgradient"} & self.oracles)

    @property
    def proximal(self) -> bool:
        """Whether the class answers a proximal step (a diagonal entry -t of D)."""
        return "proximal" in self.oracles


def convex_form(mu: float = 0.0) -> np.ndarray:
    """Q of ``f_a - f_b - <g_b, x_a - x_b> - mu/2 |x_a - x_b|^2 >= 0`` on (x_a, x_b, g_a, g_b)
    (convex for mu = 0, mu-strongly convex otherwise)."""
    Q = np.zeros((4, 4))
    Q[0, 3] = Q[3, 0] = -0.5  # -<g_b, x_a>
    Q[1, 3] = Q[3, 1] = 0.5  # +<g_b, x_b>
    Q[:2, :2] -= 0.5 * mu * np.array([[1.0, -1.0], [-1.0, 1.0]])
    return Q


def exact_convex_form(mu: Any = 0) -> np.ndarray:
    """:func:`convex_form` on exact numbers: ``mu`` a ball or a rational; entries are
    rationals or balls (object array)."""
    h = Fraction(1, 2)
    Q = np.full((4, 4), Fraction(0), dtype=object)
    Q[0, 3] = Q[3, 0] = -h
    Q[1, 3] = Q[3, 1] = h
    Q[0, 0] = Q[1, 1] = -(mu * h)
    Q[0, 1] = Q[1, 0] = mu * h
    return Q
