"""The oracle model: several oracle calls per iteration, the feedthrough D, the output.

A method on the problem min_x sum_j f_j(x) (each f_j in its class, :mod:`sosalgo.classes`)
is, in reduced d = 1 templates (``⊗ I_d`` implied),

    xi_{k+1} = A xi_k + B u_k,   y_k = C xi_k + D u_k,   u_{k,i} in ∂f_{j(i)}(y_{k,i}),

with p calls per iteration (B n x p, C p x n, D p x p lower triangular). A diagonal entry
D_ii = -t (t >= 0) makes call i a proximal step: y_i = v_i - t u_i with u_i in ∂f(y_i)
means y_i = prox_{t f}(v_i), v_i the rest of row i. The output is x_k = E xi_k, or the
point y_{k,i} of one call (``output: y<i>``).

Optimality: x* minimizes the sum iff 0 = sum_j s_j* with s_j* in ∂f_j(x*). The method must
have every such point as a fixed point with every y_i* = x*: for all x* and all s* with
sum_j s_j* = 0 there is xi* with xi* = A xi* + B u*, C xi* + D u* = x*, E xi* = x*, where
u*_i = s*_{j(i)} (every call to f_j returns s_j*). Everything is linear, so this is checked
on a basis: x* = 1 with s* = 0, and x* = 0 with each free direction of s* (J - 1 of them for
J functions; none for one function).

A spec with transpose calls of a linear operator M (:mod:`sosalgo.spec.adjoint`) gives
each call its own point at the solution instead (:meth:`OracleMethod.reference_tables`:
x* or M x* for a function, x* for M, s_g* for M^T) and its ``optimality:`` instead of
the sum; the fixed point is checked on x*, every s_j* and M x*.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from sosalgo.classes import CLASSES, SEED_CLASS, FunctionClass
from sosalgo.errors import ModelError
from sosalgo.spec.types import Spec, SpecError

__all__ = ["BOUND_NUMBER_TYPES", "NUMBER_TYPES", "BoundFunction", "CallShape", "Method",
           "OracleMethod",
           "as_oracle_method", "check_oracle_spec",
           "check_magnitudes", "check_relative_error", "composite_quadratic_rate",
           "consistent_solution", "relative_errors",
           "fixed_point_basis", "fixed_point_system", "seed_functions"]

FIXED_POINT_TOL = 1e-8
# Nonzero matrix entries must lie in [1/MAX_MAGNITUDE, MAX_MAGNITUDE] in magnitude: beyond,
# an entry is within a few decades of the floating-point range's ends and its sums and
# products leave it. Inside, a float check that overflows never certifies (it ends in inf or
# nan) and the fixed-point check is scale-free (:func:`consistent_solution`), so methods
# written in tiny or huge units (m = 1e-300) keep working.
MAX_MAGNITUDE = 1e305


# the number types a method's entries and class parameters may have: floats, balls
# (:class:`sosalgo.kernel.exact.Ball`, exact rationals with rational radii, the exact
# twin), arb balls (python-flint, outward rounded) and polynomials in the coordinates of a
# box of parameter values (sympy, exact coefficients); and the exact numbers of a quadratic
# field Q(sqrt d) (:class:`sosalgo.kernel.qfield.QSqrt`), in which the PEP's exact proof
# may build its method (class parameters, m and L then balls of radius 0)
NUMBER_TYPES = ("float", "ball", "arb", "poly", "field")
# the number types :func:`sosalgo.method.bind` binds a spec in
BOUND_NUMBER_TYPES = ("float", "ball", "arb", "poly")


class BoundFunction(NamedTuple):
    """One function of the problem: its name, class and parameters (numbers of the
    method's number type); a triple ``(name, cls, params)`` as well."""

    name: str
    cls: FunctionClass
    params: dict[str, Any]


class CallShape:
    """``n`` (states: rows of ``A``) and ``p`` (oracle calls: length of ``oracles``) of a
    method; a base of the oracle method and of the forms other modules build from it."""

    @property
    def n(self) -> int:
        A = self.A  # type: ignore[attr-defined]
        shape = getattr(A, "shape", None)  # arb matrices have nrows() instead
        return int(A.nrows() if shape is None else shape[0])

    @property
    def p(self) -> int:
        return len(self.oracles)  # type: ignore[attr-defined]


@dataclass(frozen=True, eq=False)
class Method(CallShape):
    """The one method of the oracle model (see the module docstring), over any number type
    of :data:`NUMBER_TYPES` (``numbers``): its matrices A, B, C, D, E (E None when the
    output is a call's point), its functions with their class parameters, and m, L, the
    spec's parameter values ``params``, all of that number type.

    ``oracles[i]`` is the index in ``functions`` of the function call i queries; ``output``
    the call whose point is the output (None: x = E xi); ``m``, ``L`` the spec's (they set
    kappa and the units of the certificate).

    Over floats it is :class:`OracleMethod` (checked on creation), in the seed's form
    :class:`sosalgo.model.Algorithm`. The other number types are bound by
    :func:`sosalgo.method.bind` (``numbers=``); a binding in exact numbers also keeps the
    spec's matrices with exact (sympy) entries, in the spec's layout (A, B, C, E, and D
    where the spec writes one), in ``matrices``, and the rational ``theta`` it was bound
    at; one over a box of parameter values keeps the box in ``box``.
    """

    # whether the method is in the seed's form, so that its certificates are built on
    # (A, B, C, E) alone (Theorem 1, the seed's interpolation windows, the seed's noise
    # sensitivity); False here: the constructions of the oracle model
    has_seed_form = False

    A: Any
    B: Any
    C: Any
    D: Any
    E: Any | None
    m: Any
    L: Any
    functions: tuple[BoundFunction, ...]
    oracles: tuple[int, ...]
    output: int | None = None
    measure: str = "function"
    params: dict[str, Any] = field(default_factory=dict)
    # inexact gradient calls: call index -> eps in [0, 1) (the answer d of the call has
    # |d - grad f(y)| <= eps |grad f(y)|); only ``sosalgo pep`` models them
    errors: dict[int, float] = field(default_factory=dict)
    # linear minimization calls: call index -> the gradient call giving the direction (the
    # call answers s - y, 0 at the fixed point; only ``sosalgo pep`` models them)
    lmo: dict[int, int] = field(default_factory=dict)
    # transpose calls and the optimality condition that pairs them (:class:`BoundAdjoint`);
    # None: every call at x*, the optimal subgradients summing to 0
    adjoint: BoundAdjoint | None = None
    numbers: str = "float"
    # exact bindings: the spec's matrices with exact entries (sympy; polynomials in the
    # box coordinates over ``poly``) and the rational parameter values set
    matrices: dict[str, Any] | None = None
    theta: dict[str, Any] | None = None
    # ``poly``: the box of the free parameters (:class:`sosalgo.exact_method.ParameterBox`)
    box: Any = None

    @property
    def kappa(self) -> Any:
        """L / m (inf when m = 0: a sublinear spec has no condition number); exact over
        exact numbers."""
        return self.L / self.m if self.m > 0 else float("inf")

    @property
    def balls(self) -> dict[str, list[list[Any]]]:
        """The enclosures of ``matrices`` (a binding in exact numbers), in its layout:
        name -> rows of balls."""
        assert self.matrices is not None, "a method bound in exact numbers"
        return {k: getattr(self, k).tolist() for k in self.matrices}

    def enclosures(self) -> dict[str, list[list[list[str]]]]:
        """[lo, hi] of every entry of ``balls`` as exact decimal/rational strings (lo ==
        hi if exact)."""
        from sosalgo.kernel.exact import fraction_str

        return {k: [[[fraction_str(b.lo), fraction_str(b.hi)] for b in row] for row in mat]
                for k, mat in self.balls.items()}

    def optimal_map(self) -> np.ndarray:
        """S (p x (J - 1)): u* = S s~ for the free optimal subgradients s~ = (s_1*, ...,
        s_{J-1}*), s_J* = -(s_1* + ... + s_{J-1}*). Indicators alone (a feasibility
        problem): x* lies in every set, where 0 is a normal vector of each, so s_j* = 0
        (S = 0: the fixed point does not move with them, and the PEP leaves them out)."""
        J = len(self.functions)
        if self.adjoint is not None:
            return self.reference_tables()[1][:, 1:1 + len(self.adjoint.free)]
        S = np.zeros((self.p, max(J - 1, 0)))
        if pinned_optimum(self.functions):
            return S
        lmo = getattr(self, "lmo", None) or {}  # the seed's Algorithm has none
        for i, j in enumerate(self.oracles):
            if i in lmo:  # answers s - y: 0 at the fixed point (s = y = x*)
                continue
            if j < J - 1:
                S[i, j] = 1.0
            else:
                S[i, :] = -1.0
        return S

    def reference_tables(self) -> tuple[np.ndarray, np.ndarray]:
        """(P, U), each p x (1 + F + 1): every call's point and answer at the solution on
        the columns (x*, the free optimal subgradients s_j* of the F functions that are
        not linear operators, M x*) of a spec with transpose calls
        (:mod:`sosalgo.spec.adjoint`): a call of f_j at x* (or at M x* when f_j is
        composed with M) answering s_j*, a call of M at x* answering M x*, a call of M^T
        at s_g* answering M^T s_g* = minus the optimality's other terms."""
        adj = self.adjoint
        assert adj is not None
        col = {j: 1 + c for c, j in enumerate(adj.free)}
        width = 2 + len(adj.free)
        P, U = np.zeros((self.p, width)), np.zeros((self.p, width))
        for i, j in enumerate(self.oracles):
            if i in adj.transposes:
                P[i, col[adj.dual[1]]] = 1.0
                for q in adj.plain:
                    U[i, col[q]] = -1.0
            elif j == adj.dual[0]:
                P[i, 0] = U[i, width - 1] = 1.0
            else:
                P[i, width - 1 if j in adj.images else 0] = 1.0
                U[i, col[j]] = 1.0
        return P, U


@dataclass(frozen=True)
class OracleMethod(Method):
    """The one method over floats (see :class:`Method`), checked on creation
    (:class:`ModelError`): the seed's form (one gradient call on f in F(m, L)) is the
    subclass :class:`sosalgo.model.Algorithm`, whose :attr:`has_seed_form` is True.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    E: np.ndarray | None
    m: float
    L: float

    def __post_init__(self) -> None:
        for k in ("A", "B", "C", "D", "E"):
            val = getattr(self, k)
            if val is None:
                continue
            arr = np.array(val, dtype=float, ndmin=2)
            check_magnitudes(k, arr)
            object.__setattr__(self, k, arr)
        n, p = self.A.shape[0], len(self.oracles)
        shapes = {"A": (n, n), "B": (n, p), "C": (p, n), "D": (p, p), "E": (1, n)}
        for k, shape in shapes.items():
            val = getattr(self, k)
            if val is not None and val.shape != shape:
                raise ModelError(f"matrices.{k}", f"must be {shape[0]}x{shape[1]}")
        if (self.E is None) == (self.output is None):
            raise ModelError("matrices.E", "give E or output, not both")
        self._check_calls()
        for fn in self.functions:
            try:
                fn.cls.check(fn.params)
            except ValueError as exc:
                raise ModelError(f"functions.{fn.name}.{exc}".split(": ", 1)[0],
                                   str(exc).split(": ", 1)[-1]) from None
        if fixed_point_basis(self) is None:
            raise ModelError("matrices", "the optimal point is not a fixed point: need xi* "
                               "with xi* = A xi* + B u*, C xi* + D u* = x* (every call at x*), "
                               "E xi* = x*, for every x* and optimal subgradients s_j* "
                               "summing to 0 (u*_i = s* of the function call i queries)")

    def _check_calls(self) -> None:
        D = self.D
        if np.any(np.triu(D, 1) != 0):
            i, j = np.argwhere(np.triu(D, 1) != 0)[0]
            raise ModelError(f"matrices.D[{i}][{j}]", "D must be lower triangular (call "
                               f"{i + 1} can only use calls 1..{i + 1})")
        for i, t in enumerate(-np.diag(D)):
            if t < 0:
                raise ModelError(f"matrices.D[{i}][{i}]", "a diagonal entry must be -t with "
                                   f"t >= 0 (a proximal step), got {-t:g}")

    def output_row(self) -> tuple[np.ndarray, np.ndarray]:
        """(row on xi, row on u) of the output point x = E xi or y_i = C_i xi + D_i u."""
        if self.output is None:
            assert self.E is not None
            return self.E[0], np.zeros(self.p)
        return self.C[self.output], self.D[self.output]


@dataclass(frozen=True)
class BoundAdjoint:
    """:class:`sosalgo.spec.adjoint.Adjoint` on function indices: the transpose calls, the
    functions composed with the operator, the optimality's plain terms and its transposed
    term (operator, function), and the functions with a free optimal subgradient."""

    transposes: frozenset[int]
    images: frozenset[int]
    plain: tuple[int, ...]
    dual: tuple[int, int]
    free: tuple[int, ...]


def bind_adjoint(spec: Spec) -> BoundAdjoint | None:
    """The spec's :class:`BoundAdjoint` (None without transpose calls)."""
    adj = getattr(spec, "adjoint", None)
    if adj is None:
        return None
    names = list(spec.functions)
    return BoundAdjoint(adj.transposes, frozenset(names.index(f) for f in adj.images),
                        tuple(names.index(f) for f in adj.plain),
                        (names.index(adj.dual[0]), names.index(adj.dual[1])),
                        tuple(j for j, f in enumerate(names) if f not in adj.operators))


def pinned_optimum(functions: Sequence[Any]) -> bool:
    """Whether every optimal subgradient is 0: indicators alone (x* lies in every set, and
    0 is a normal vector of each there), so each class's :meth:`pinned` inequalities
    (its own, not the tilted relaxation) hold at x*. ``functions``: objects with ``cls``
    (bound functions) or (name, class, params) triples."""
    classes = [getattr(f, "cls", None) or f[1] for f in functions]
    return bool(classes) and all(c.zero_values for c in classes)


def fixed_point_basis(om: OracleMethod, tol: float = FIXED_POINT_TOL) -> np.ndarray | None:
    """xi* for x* = 1, s* = 0 and for x* = 0 with each free optimal subgradient (columns),
    or None when one of them does not exist (least squares, relative residual ``tol``)."""
    return consistent_solution(*fixed_point_system(om), tol)


def fixed_point_system(om: OracleMethod) -> tuple[np.ndarray, np.ndarray]:
    """(lhs, rhs) of the fixed-point conditions: the basis X of :func:`fixed_point_basis`
    solves lhs X = rhs."""
    n, p = om.n, om.p
    erow, drow = om.output_row()
    lhs = np.vstack([np.eye(n) - om.A, om.C, erow[None, :]])
    if getattr(om, "adjoint", None) is not None:  # every call's own reference point
        P, U = om.reference_tables()
        e0 = np.zeros((1, P.shape[1]))
        e0[0, 0] = 1.0
        with np.errstate(all="ignore"):
            return lhs, np.vstack([om.B @ U, P - om.D @ U, e0 - drow[None, :] @ U])
    S = om.optimal_map()
    rhs = np.zeros((n + p + 1, 1 + S.shape[1]))
    rhs[n:, 0] = 1.0
    if S.shape[1]:
        with np.errstate(all="ignore"):
            rhs[:n, 1:] = om.B @ S
            rhs[n: n + p, 1:] = -om.D @ S
            rhs[n + p, 1:] = -(drow @ S)
    return lhs, rhs


def consistent_solution(lhs: np.ndarray, rhs: np.ndarray, tol: float = FIXED_POINT_TOL
                        ) -> np.ndarray | None:
    """A solution X of ``lhs X = rhs`` (least squares), or None when the system is not
    consistent. Each row, scaled so that its largest entry in ``[lhs | rhs]`` is 1 (so no
    norm overflows), must hold to ``tol`` relative to its own terms ``|lhs_i| |X| +
    |rhs_i|`` (a huge entry in one row cannot hide a violated row), up to the accuracy of
    least squares (a small multiple of machine epsilon times ``|lhs| |X|``)."""
    if not (np.all(np.isfinite(lhs)) and np.all(np.isfinite(rhs))):
        return None
    row = np.maximum(np.abs(lhs).max(axis=1, initial=0.0), np.abs(rhs).max(axis=1, initial=0.0))
    row[row == 0] = 1.0
    a, b = lhs / row[:, None], rhs / row[:, None]
    with np.errstate(all="ignore"):
        X, *_ = np.linalg.lstsq(a, b, rcond=None)
        if not np.all(np.isfinite(X)):
            return None
        terms = np.abs(a) @ np.abs(X) + np.abs(b)
        floor = 1e3 * np.finfo(float).eps * np.abs(a).sum() * np.abs(X).max(initial=0.0)
        ok = np.abs(a @ X - b) <= tol * terms + floor
    return X if np.all(ok) else None


def check_magnitudes(name: str, arr: np.ndarray) -> None:
    """ModelError unless every entry of matrix ``name`` is finite and every nonzero one
    within [1/MAX_MAGNITUDE, MAX_MAGNITUDE] in magnitude (see :data:`MAX_MAGNITUDE`)."""
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"matrices.{name}", "entries must be finite")
    mag = np.abs(arr)
    bad = (mag > MAX_MAGNITUDE) | ((mag > 0) & (mag < 1 / MAX_MAGNITUDE))
    if np.any(bad):
        i, j = np.argwhere(bad)[0]
        raise ModelError(f"matrices.{name}[{i}][{j}]", f"{arr[i, j]:.3g} is outside the "
                         f"magnitudes [1e-305, 1e305] floating-point checks can handle")


def check_oracle_spec(spec: Spec, fail: Callable[[str, str], SpecError]) -> None:
    """The checks that need no numbers: D lower triangular, each call's kind (a zero
    diagonal entry of D: (sub)gradient; any other: proximal step) answered by the class of
    the function it queries, and ``measure: function`` only where every f_j(x_k) exists."""
    D = spec.matrices.get("D")
    for i, fname in enumerate(spec.oracles):
        cls = CLASSES[spec.functions[fname].cls]
        diag = None if D is None else D[i][i]
        if D is not None:
            for j in range(i + 1, spec.p):
                if not _is_zero(D[i][j]):
                    raise fail(f"matrices.D[{i}][{j}]", "D must be lower triangular (call "
                               f"{i + 1} can only use calls 1..{i + 1})")
        if diag is not None and diag.is_constant and _value(diag) > 0:
            raise fail(f"matrices.D[{i}][{i}]", "a diagonal entry must be -t with t >= 0 (a "
                       f"proximal step), got {_value(diag):g}")
        prox = diag is not None and not _is_zero(diag)
        if i in getattr(spec, "twins", {}):  # no call of its own: its source's point
            _check_twin(spec, i, fail)
            continue
        if i in spec.lmo:
            _check_lmo(spec, i, cls, prox, fail)
            continue
        if i in spec.inexact:
            _check_inexact(spec, i, cls, prox, fail)
        if prox and not cls.proximal:
            raise fail(f"matrices.D[{i}][{i}]", f"a proximal step on {fname}, whose class "
                       f"{cls.name} has no proximal oracle")
        if not prox and not cls.explicit:
            raise fail(f"oracles[{i}]", f"{fname} ({cls.name}) answers proximal steps only: "
                       f"make D[{i}][{i}] = -t")
    if spec.measure == "function" and not getattr(spec, "mirror", None):  # mirror: its own
        _check_measure(spec, fail)


def _check_twin(spec: Spec, i: int, fail: Callable[[str, str], SpecError]) -> None:
    """A ``gradient_of: j`` call is at call j's point: the same rows of C and D (D_ij =
    D_jj, D_ii = 0), so that its answer, the true subgradient there, is where the
    method uses it."""
    import sympy as sp

    j = spec.twins[i]
    M = spec.sympy_matrices()
    D = M.get("D", sp.zeros(spec.p, spec.p))
    same = all(sp.simplify(M["C"][i, c] - M["C"][j, c]) == 0 for c in range(M["C"].shape[1]))
    same = same and all(sp.simplify(D[i, c] - D[j, c]) == 0 for c in range(spec.p)
                        if c not in (i, j))
    same = same and sp.simplify(D[i, j] - D[j, j]) == 0 and D[i, i] == 0
    if not same:
        raise fail(f"oracles[{i}].gradient_of", f"its point must be call {j + 1}'s: the "
                   f"same row of C, D[{i}][{j}] = D[{j}][{j}], D[{i}][{i}] = 0")
    if j in spec.lmo:
        raise fail(f"oracles[{i}].gradient_of", "not of a linear minimization call")


def _check_lmo(spec: Spec, i: int, cls: FunctionClass, prox: bool,
                fail: Callable[[str, str], SpecError]) -> None:
    """A linear minimization call queries an indicator (its set), with D_ii = 0; its
    direction is a gradient call (D_jj = 0) of a class with a gradient oracle."""
    where = f"oracles[{i}].lmo"
    if not cls.zero_values:  # an indicator: the LMO minimizes over its set
        sets = ", ".join(c.name for c in CLASSES.values() if c.zero_values)
        raise fail(where, f"a linear minimization oracle of {spec.oracles[i]}, whose class "
                   f"{cls.name} is not an indicator ({sets})")
    if prox:
        raise fail(f"matrices.D[{i}][{i}]", "a linear minimization call is no proximal step: "
                   "make it 0")
    j = spec.lmo[i]
    D = spec.matrices.get("D")
    direction = CLASSES[spec.functions[spec.oracles[j]].cls]
    if ("gradient" not in direction.oracles or j in spec.inexact
            or (D is not None and not _is_zero(D[j][j]))):
        raise fail(where, f"call {j + 1} must be an exact gradient call (its answer is the "
                   "direction)")



def _check_inexact(spec: Spec, i: int, cls: FunctionClass, prox: bool,
                   fail: Callable[[str, str], SpecError]) -> None:
    """An inexact call is a gradient call (D_ii = 0) on a class with gradients or a
    proximal step (D_ii = -t, on a class with a proximal oracle: checked with the other
    proximal steps), its relative error (when a constant) in [0, 1)."""
    where = f"oracles[{i}].relative_error"
    if not prox and "gradient" not in cls.oracles:
        raise fail(where, f"an inexact gradient of {spec.oracles[i]}, whose class {cls.name} "
                   "has no gradient oracle")
    eps = spec.inexact[i]
    if eps.is_constant and _relative_error_issue(_value(eps)):
        raise fail(where, _relative_error_issue(_value(eps)))


def _relative_error_issue(eps: float) -> str:
    """Why eps is not a relative error ("" when 0 <= eps < 1; at eps >= 1 the answer
    may be 0 anywhere, and nothing converges)."""
    if 0 <= eps < 1:
        return ""
    return f"must be in [0, 1) (|d - grad f| <= eps |grad f|), got {eps:g}"


def check_relative_error(where: str, eps: float) -> None:
    """ModelError naming ``where`` unless 0 <= eps < 1."""
    if _relative_error_issue(eps):
        raise ModelError(where, _relative_error_issue(eps))


def _check_measure(spec: Spec, fail: Callable[[str, str], SpecError]) -> None:
    at_output = None if spec.output is None else spec.oracles[spec.output]
    sets = {spec.oracles[i] for i in spec.lmo}  # in the set when the steps keep it there
    sets |= {spec.oracles[i] for i in getattr(spec, "epsilon", None) or {}}  # at every
    # iterate (:mod:`sosalgo.worstcase.epsilon`)
    for fname, decl in spec.functions.items():
        cls = CLASSES[decl.cls]
        if fname in sets:  # decided by the PEP (:mod:`sosalgo.worstcase.lmo`)
            continue
        if not cls.has_values:
            raise fail("measure", f"function: {fname} ({cls.name}) is an operator class, it "
                       "has no function values; use measure: distance")
        if fname != at_output and not cls.finite_everywhere:
            where = "E xi" if spec.output is None else f"y{spec.output + 1}"
            raise fail("measure", f"function: {fname} ({cls.name}) is not evaluated at the "
                       f"output {where}; use output: y<i> (a call to {fname}) or "
                       "measure: distance")


def _is_zero(e) -> bool:
    return bool(e.is_constant and _value(e) == 0)


def _value(e) -> float:
    from sosalgo.kernel.expr import constant_value

    return constant_value(e)


def bind_functions(spec: Spec, values: list[float],
                   spec_params: Mapping[str, float] | None = None) -> tuple[BoundFunction, ...]:
    """The spec's functions with their parameters at (m, L, kappa) = ``values`` and the
    spec's parameter values ``spec_params`` (which a class that only ``pep`` answers may
    name)."""
    from sosalgo.kernel.expr.compile import NumericError, compile_expression
    from sosalgo.spec.types import BASE_NAMES

    extra = dict(spec_params or {})
    names = (*BASE_NAMES, *extra)
    full = list(values) + [float(v) for v in extra.values()]
    out = []
    for fname, decl in spec.functions.items():
        params = {}
        for key, expr in decl.params.items():
            try:
                params[key] = float(compile_expression(expr, names)(full))
            except NumericError as exc:
                raise ModelError(f"functions.{fname}.{key}", str(exc)) from None
        out.append(BoundFunction(fname, CLASSES[decl.cls], params))
    return tuple(out)


def make_method(spec: Spec, mats: Mapping[str, np.ndarray], m: float, L: float,
                kappa: float, params: dict[str, float]) -> OracleMethod:
    """The :class:`OracleMethod` of a spec from its numeric matrices."""
    names = list(spec.functions)
    D = mats.get("D", np.zeros((spec.p, spec.p)))
    return OracleMethod(mats["A"], mats["B"], mats["C"], D, mats.get("E"), m, L,
                        bind_functions(spec, [m, L, kappa], params),
                        tuple(names.index(f) for f in spec.oracles), spec.output,
                        spec.measure, params, relative_errors(spec, m, L, kappa, params),
                        dict(getattr(spec, "lmo", None) or {}), bind_adjoint(spec))


def relative_errors(spec: Spec, m: float, L: float, kappa: float,
                    params: Mapping[str, float]) -> dict[int, float]:
    """The relative error of each inexact call at these values (ModelError naming the
    field when it is not in [0, 1))."""
    from sosalgo.kernel.expr.tree import evaluate

    out = {}
    for i, expr in spec.inexact.items():
        where = f"oracles[{i}].relative_error"
        try:
            eps = float(evaluate(expr, {"m": m, "L": L, "kappa": kappa, **params}))
        except (ValueError, ZeroDivisionError, OverflowError) as exc:
            raise ModelError(where, str(exc)) from None
        check_relative_error(where, eps)
        out[i] = eps
    return out


def seed_functions(m: float, L: float) -> tuple[BoundFunction, ...]:
    """The functions of the seed's form: one f in F(m, L)."""
    return (BoundFunction("f", SEED_CLASS, {"m": m, "L": L}),)


def as_oracle_method(alg: Any) -> OracleMethod:
    """A bound method as an :class:`OracleMethod`: itself when it is one (every bound
    method is, the seed's :class:`~sosalgo.model.Algorithm` included); any other object
    with the seed's A, B, C, E, m, L as the method of one gradient call on f in F(m, L),
    D = 0, x = E xi."""
    if isinstance(alg, OracleMethod):
        return alg
    return OracleMethod(alg.A, alg.B, alg.C, np.zeros((1, 1)), alg.E, alg.m, alg.L,
                        seed_functions(alg.m, alg.L), (0,), None, "function",
                        dict(alg.params))


def composite_quadratic_rate(om: OracleMethod, points: int = 201) -> float:
    """A lower bound of every rate: the largest spectral radius of the closed loop when
    every f_j is a quadratic (q_j/2)|x|^2 of its class (grid over each class's curvature
    interval; u = Q y, so u = (I - Q D)^-1 Q C xi). 0 when a class has no quadratic."""
    grids = []
    for fn in om.functions:
        cur = fn.cls.curvatures(fn.params)
        if cur is None:
            return 0.0
        lo, hi = cur
        grids.append(np.linspace(lo, hi, points) if hi > lo else np.array([lo]))
    if sum(len(g) > 1 for g in grids) > 1:  # several intervals: a coarser product grid
        grids = [g if len(g) == 1 else np.linspace(g[0], g[-1], 21) for g in grids]
    best = 0.0
    eye = np.eye(om.p)
    every = np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T
    qd = every[:, list(om.oracles)]  # all grid points at once (one loop when one is singular)
    try:
        K = np.linalg.solve(eye - qd[:, :, None] * om.D, qd[:, :, None] * om.C)
        return float(np.abs(np.linalg.eigvals(om.A + om.B @ K)).max(initial=0.0))
    except np.linalg.LinAlgError:
        pass
    for qs in every:
        Q = np.diag([qs[j] for j in om.oracles])
        try:
            K = np.linalg.solve(eye - Q @ om.D, Q @ om.C)
        except np.linalg.LinAlgError:
            continue
        best = max(best, float(np.abs(np.linalg.eigvals(om.A + om.B @ K)).max()))
    return best


