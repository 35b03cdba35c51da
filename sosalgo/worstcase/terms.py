"""Measures and initial conditions of the PEP: sums of terms ``c*f``, ``c*dist``, ``c*grad``.

``f`` = sum_j f_j(x) - f_j*, ``dist`` = |x - x*|^2, ``grad`` = |grad f(x)|^2 of the smooth
part (the functions of a class with a gradient oracle), ``sdist`` = |xi - xi*|^2 over
every state block (an initial ``sdist`` makes the start free), ``mingrad`` = the minimum
over the iterates x_0, ..., x_N of |grad f(x_k)|^2 and ``minf`` = the minimum over them of
f(x_k) - f* (measures only, coefficient > 0: :func:`expand_min`), ``dist(P, Q)`` =
|P - Q|^2 between two points of the trajectory (``dist(x_N, x_N-1)``: the last step's
length; kind ``diff``); ``c`` is an expression in m, L, kappa. A measure term may name its
point: ``f(x_N)`` (the output, the default), ``grad(x_3)`` (the output after 3 steps),
``dist(y_N)`` (the point of the single call), ``grad(y2_N)`` (the point of call 2),
``grad(x_N-1)`` (the output one step before the last), ``y<i>_N-j`` (call i's point j
steps before the last), ``f(y_k)`` / ``grad(y<i>_k)``
(a call's point at step k); ``inner(P, Q)`` = <P - x*, Q - x*>, a side ``g(P)`` the sum of
the functions' (sub)gradients at P; an initial term may name any point too, and
``free`` (initial only) frees the start. ``sdist(x_0)`` (initial only) is |xi_0 - xi*|^2
at the method's own start (at rest at x_0, or its ``initial_state``), which it does not
free. ``--initial none``: no initial condition (no terms: a homogeneous question, worst
case 0 or unbounded). Coefficients may name the spec's parameters. The string is parsed
by :mod:`sosalgo.kernel.expr` (never evaluated) and split into its linear terms; anything
nonlinear in the terms is refused.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from sosalgo.errors import InputError
from sosalgo.kernel.expr.tree import Expr, ExprError, evaluate, parse_tree
from sosalgo.spec.initial_state import linear_parts

__all__ = ["BACK_POINT", "CONST_KIND", "DIFF_KIND", "EVERY", "KINDS", "MINF_KIND", "MIN_KIND",
           "MIN_OF", "OUT0", "REST", "Term", "at_steps", "describe_terms", "dominates",
           "every_step", "expand_min", "free_start", "parse_constraint", "parse_terms"]

MIN_KIND = "mingrad"  # min over k = 0..N of |grad f(x_k)|^2
MINF_KIND = "minf"  # min over k = 0..N of f(x_k) - f*
MIN_OF = {MIN_KIND: "grad", MINF_KIND: "f"}  # a minimum over the iterates, of which kind
DIFF_KIND = "diff"  # |P - Q|^2 between two points: dist(P, Q)
INNER_KIND = "inner"  # <P - x*, Q - x*> of two points or gradients: inner(P, Q)
FREE_KIND = "free"  # an initial term that only frees the start (contributes nothing)
NONE_TEXT = "none"  # --initial none: no initial condition (a homogeneous question)
KINDS = ("f", "dist", "grad", "sdist", MIN_KIND, MINF_KIND, DIFF_KIND, "contraction",
         INNER_KIND, FREE_KIND)
# contraction: |xi_N - xi'_N|^2 of two runs (:mod:`sosalgo.worstcase.contraction`; alone)
_ARG = r"([A-Za-z0-9_]+(?:\s*-\s*\d+)?)"
_AT = re.compile(r"\b(f|dist|grad)\s*\(\s*" + _ARG + r"\s*\)")
_REST = re.compile(r"\bsdist\s*\(\s*x_0\s*\)")  # sdist(x_0): at the method's own start
REST = "rest"  # the point of sdist(x_0): |xi_0 - xi*|^2, the start not freed
_PAIR = re.compile(r"\bdist\s*\(\s*" + _ARG + r"\s*,\s*" + _ARG + r"\s*\)")
_ARGN = r"[A-Za-z0-9_]+(?:\s*-\s*\d+)?"
_GARG = r"(g\s*\(\s*" + _ARGN + r"\s*\)|" + _ARGN + r")"  # a point or g(point)
_INNER = re.compile(r"\binner\s*\(\s*" + _GARG + r"\s*,\s*" + _GARG + r"\s*\)")
_POINT = re.compile(r"^(x|y(\d*))_(N|k|\d+)$")
EVERY = "xk"  # a constraint's x_k: one constraint per step k = 0..N (:func:`every_step`)
CONST_KIND = "const"  # a constraint's constant term (:func:`parse_constraint`)
CALL_AT = re.compile(r"^y(\d+)t(\d+)$")  # a call's point at step k: y<i>t<k>
GRAD_OF = "G"  # an inner term's gradient at a point: G<point key>
_BEFORE = re.compile(r"^x_N\s*-\s*(\d+)$")  # x_N-j: the output j steps before the last
STEP_POINT = re.compile(r"^x(\d+)$")  # a measure's x_k, k a number: the output at step k
BACK_POINT = re.compile(r"^xm(\d+)$")  # a measure's x_N-j: the output at step N - j
_CALL_BEFORE = re.compile(r"^y(\d*)_N\s*-\s*(\d+)$")  # y<i>_N-j: call i at step N - j
CALL_BACK = re.compile(r"^y(\d+)m(\d+)$")  # its key: y<i>m<j>
OUT0 = "x0out"  # x_N-j at step 0: the output there (the start x_0 unless an output call)


@dataclass(frozen=True)
class Term:
    """``coef * kind(point)``: point "x" (the output at step N), "x<k>" (the output at step
    k; "x0" is also the start), "xm<j>" (the output at step N - j), "y<i>" (call i at step
    N, 1-based), "y<i>t<k>" (call i at step k); a ``diff`` or ``inner`` term's point is its
    two points joined by "__" (an inner side "G<point>": the (sub)gradient there)."""

    kind: str
    point: str
    coef: Expr

    def value(self, m: float, L: float, kappa: float,
              params: Mapping[str, float] | None = None) -> float:
        """The coefficient in floating point (NaN when it is not finite); ``params``:
        the spec's parameter values, which a coefficient may name."""
        try:
            v = evaluate(self.coef, {**(params or {}), "m": m, "L": L, "kappa": kappa})
        except (ValueError, ZeroDivisionError, OverflowError):
            v = math.nan
        return v


def _placeholder(kind: str, point: str) -> str:
    return f"{kind}__{point}"


def _rewrite(text: str, option: str, initial: bool, p: int) -> str:
    """Replace ``kind(point)`` by placeholder names; check the points."""

    def sub(mt: re.Match[str]) -> str:
        return _placeholder(mt.group(1), _point_key(mt.group(2), option, initial, p))

    def pair(mt: re.Match[str]) -> str:
        a, b = (_point_key(mt.group(k), option, initial, p) for k in (1, 2))
        if a == b:
            raise InputError(f"{option}: dist(P, Q): two different points")
        return _placeholder(DIFF_KIND, f"{a}__{b}")

    def inner(mt: re.Match[str]) -> str:
        keys = []
        for k in (1, 2):
            arg = re.sub(r"\s+", "", mt.group(k))
            grad = arg.startswith("g(")
            key = _point_key(arg[2:-1] if grad else arg, option, initial, p)
            keys.append(GRAD_OF + key if grad else key)
        return _placeholder(INNER_KIND, "__".join(sorted(keys)))

    def rest(mt: re.Match[str]) -> str:
        if not initial:
            raise InputError(f"{option}: sdist(x_0): an initial term (the measure's sdist "
                             "is at x_N)")
        return _placeholder("sdist", REST)

    return _AT.sub(sub, _PAIR.sub(pair, _INNER.sub(inner, _REST.sub(rest, text))))


def _point_key(pt: str, option: str, initial: bool, p: int) -> str:
    """The key of a point as written (x_N, x_<k>, x_N-<j>, y_N, y<i>_N, y_<k>, y<i>_<k>):
    see :class:`Term`."""
    pt = re.sub(r"\s+", "", pt)
    back = _BEFORE.match(pt)
    if back:
        return f"xm{int(back.group(1))}" if int(back.group(1)) else "x"
    call_back = _CALL_BEFORE.match(pt)
    if call_back and int(call_back.group(2)):  # y<i>_N-j (j = 0: y<i>_N, below)
        key = _point_key(f"y{call_back.group(1)}_N", option, initial, p)
        return f"{key}m{int(call_back.group(2))}"
    if call_back:
        pt = f"y{call_back.group(1)}_N"
    hit = _POINT.match(pt)
    if hit is None:
        raise InputError(f"{option}: unknown point {pt!r} (use x_N, x_<k>, x_N-<j>, y_N, "
                         "y<i>_N, y<i>_N-<j>, y_<k>, y<i>_<k>)")
    step = hit.group(3)
    if step == "k":
        if hit.group(1) != "x":
            raise InputError(f"{option}: {pt}: the generic step k is for x_k only")
        return EVERY
    if hit.group(1) == "x":
        return "x" if step == "N" else f"x{int(step)}"
    i = int(hit.group(2) or (1 if p == 1 else 0))
    if not 1 <= i <= p:
        raise InputError(f"{option}: {pt}: the method has {p} oracle call(s) per step"
                         + ("; name one: y1_N .. y{p}_N" if i == 0 else ""))
    return f"y{i}" if step == "N" else f"y{i}t{int(step)}"


def parse_terms(text: object, option: str, initial: bool, p: int,
                params: Collection[str] = (), constraint: bool = False) -> list[Term]:
    """The terms of ``text`` (an InputError naming ``option`` for anything else);
    ``params``: the spec's parameter names, which coefficients may use besides m, L,
    kappa. An initial condition ``none`` has no terms (a homogeneous question).
    ``constraint``: a side of a constraint, which may have a constant term (kind
    :data:`CONST_KIND`) and points x_k (:data:`EVERY`)."""
    if initial and isinstance(text, str) and text.strip() == NONE_TEXT:
        return []
    if not isinstance(text, str) or not text.strip():
        raise InputError(f"{option}: expected terms such as 'f', '2*dist', 'L/2*grad'")
    src = _rewrite(text, option, initial, p)
    consts = frozenset({"m", "L", "kappa", *params}) - set(KINDS)
    names = {*consts, *KINDS}
    names |= {w for w in re.findall(r"\b\w+__\w+\b", src)}
    try:
        tree = parse_tree(src, names)
    except ExprError as exc:
        raise InputError(f"{option}: {exc}") from None
    parts = linear_parts(tree, consts, option)
    if "1" in parts and not constraint:
        raise InputError(f"{option}: a constant term; every term multiplies f, dist or grad")
    if not constraint and any(EVERY in key.split("__")[1:] for key in parts):
        raise InputError(f"{option}: x_k: a generic step is for pep.constraints only")
    mins = [k for k in MIN_OF if k in parts]
    if mins and initial:
        raise InputError(f"{option}: {mins[0]} is a measure (the initial condition is linear)")
    if FREE_KIND in parts and not initial:
        raise InputError(f"{option}: free: an initial term (it frees the start)")
    out = []
    for key, coef in parts.items():
        if key == "1":
            out.append(Term(CONST_KIND, "", coef))
            continue
        kind, _, point = key.partition("__")
        out.append(Term(kind, point or ("x0" if initial else "x"), coef))
    return out


def free_start(initial: Sequence[Term]) -> bool:
    """Whether ``initial`` leaves the start free: ``none`` (no terms), ``free`` or an
    ``sdist`` term other than ``sdist(x_0)`` (at the method's own start)."""
    return not initial or any(t.kind == FREE_KIND or (t.kind == "sdist" and t.point != REST)
                              for t in initial)


RELATIONS = ("==", "<=", ">=")


def parse_constraint(text: object, option: str, p: int, scalars: frozenset[str]
                     ) -> tuple[str, list[Term]]:
    """``LEFT REL RIGHT`` (REL one of ==, <=, >=; each side terms as a measure's, at any
    point a measure may name, x_0 included) as (REL, the terms of LEFT - RIGHT)."""
    if not isinstance(text, str):
        raise InputError(f"{option}: expected a relation such as 'grad(x_0) <= 2*f(x_0)'")
    found = [r for r in RELATIONS if r in text]
    if len(found) != 1 or text.count(found[0]) != 1:
        raise InputError(f"{option}: expected one relation ==, <= or >= between two sums of "
                         "terms")
    left, _, right = text.partition(found[0])
    if not left.strip() or not right.strip():
        raise InputError(f"{option}: a term on each side of {found[0]} (write 0 as 0*f)")
    terms = parse_terms(f"{left} - ({right})", option, False, p, scalars, constraint=True)
    bad = [t.kind for t in terms if t.kind in (*MIN_OF, "sdist", "contraction")]
    if bad:
        raise InputError(f"{option}: {bad[0]}: not in a constraint (f, dist, grad, "
                         "dist(P, Q))")
    return found[0], terms


def every_step(terms: list[Term], steps: int) -> list[tuple[str, list[Term]]]:
    """A constraint's terms at each step: [("", terms)] without a point x_k, else
    [("k<k>", terms at x_k)] for k = 0..N (x_N the output after the last step)."""
    if not any(EVERY in t.point.split("__") for t in terms):
        return [("", terms)]

    def at(point: str, k: int) -> str:
        return point if point != EVERY else "x" if k == steps else f"x{k}"

    return [(f"k{k}", [Term(t.kind, "__".join(at(q, k) for q in t.point.split("__")),
                            t.coef) for t in terms]) for k in range(steps + 1)]


def at_steps(terms: list[Term], steps: int, option: str) -> list[Term]:
    """``terms`` with each point x_N-j (key "xm<j>") written as the output at step N - j
    (key "x<N - j>"; at step 0 :data:`OUT0`, the output there, which an output call
    makes another point than the start) for N = ``steps`` (InputError naming ``option``
    before step 0)."""

    def key(point: str) -> str:
        call = CALL_BACK.match(point)
        if call is not None:  # call i at step N - j
            k = steps - int(call.group(2))
            if k < 0:
                raise InputError(f"{option}: y{call.group(1)}_N-{call.group(2)}: before the "
                                 f"start (N = {steps})")
            return f"y{call.group(1)}t{k}"
        back = BACK_POINT.match(point)
        if back is None:
            return point
        k = steps - int(back.group(1))
        if k < 0:
            raise InputError(f"{option}: x_N-{back.group(1)}: before the start (N = {steps})")
        return "x" if k == steps else f"x{k}" if k else OUT0

    return [Term(t.kind, "__".join(_grad_key(q, key) for q in t.point.split("__")), t.coef)
            for t in terms]


def _grad_key(point: str, key: Callable[[str], str]) -> str:
    """``key`` of a point, through an inner term's gradient marker."""
    if point.startswith(GRAD_OF):
        return GRAD_OF + key(point[len(GRAD_OF):])
    return key(point)


def describe_terms(terms: list[Term]) -> str:
    """A readable form: ``1*f(x) + L/2*dist(x0)``."""
    return " + ".join(f"({t.coef})*{t.kind}({t.point})" for t in terms)


def _point_text(t: Term) -> str:
    """The point of a term as written: x_N, x_<k>, y<i>_N."""
    if t.point == "x":
        return "x_N"
    if t.point == OUT0:
        return "x_0"
    hit = STEP_POINT.match(t.point)
    return f"x_{hit.group(1)}" if hit else f"{t.point}_N"


def _term_text(t: Term, weight: Fraction = Fraction(1), point: str | None = None,
               kind: str | None = None) -> str:
    w = "" if weight == 1 else f"{weight.numerator}/{weight.denominator}*"
    where = "" if (kind or t.kind) == "sdist" else f"({point or _point_text(t)})"
    return f"({t.coef})*{w}{kind or t.kind}{where}"


def expand_min(terms: list[Term], steps: int, weights: list[Fraction]) -> str:
    """The measure with its ``mingrad`` term c min_k |grad f(x_k)|^2 replaced by
    c sum_k w_k |grad f(x_k)|^2 (x_N written x_N; ``minf`` likewise with f(x_k) - f*): an
    upper bound of it when the weights are >= 0 and sum to 1, and its worst case equals the
    minimum's at the minimax weights (max over the PEP of min_k = min over the weights of
    the max; the weights are found by :mod:`sosalgo.worstcase.minimum`)."""
    if len(weights) != steps + 1 or any(w < 0 for w in weights) or sum(weights) != 1:
        raise ValueError("weights: steps + 1 rationals >= 0 summing to 1")
    out = []
    for t in terms:
        if t.kind not in MIN_OF:
            out.append(_term_text(t))
            continue
        out += [_term_text(t, w, "x_N" if k == steps else f"x_{k}", MIN_OF[t.kind])
                for k, w in enumerate(weights)]
    return " + ".join(out)


def dominates(measure: list[Term], bound: list[Term], steps: int,
              value: Callable[[Term], Any]) -> str | None:
    """Why ``bound`` (a linear measure) is not an upper bound of ``measure`` (None when
    it is): the terms other than ``mingrad`` equal, and the mingrad term's coefficient c
    (value > 0) covered by c w_k grad(x_k), w_k >= 0 summing to at least 1 (exact
    values: ``value`` of a term's coefficient, rationals or balls)."""
    mins = [t for t in measure if t.kind in MIN_OF]
    rest = [t for t in measure if t.kind not in MIN_OF]
    if len(mins) != 1:
        return "the measure has no mingrad or minf term"
    inner = MIN_OF[mins[0].kind]
    c = value(mins[0])
    if not c > 0:
        return "the mingrad coefficient is not positive"
    key = {(t.kind, t.point): t for t in rest}
    points = {f"x{k}" for k in range(steps)} | {"x"}
    total = 0
    for t in bound:
        if (t.kind, t.point) in key:
            if value(t) != value(key.pop((t.kind, t.point))):
                return f"{t.kind}({t.point}): a coefficient differs from the measure's"
        elif t.kind == inner and t.point in points:
            w = value(t)
            if not w >= 0:
                return f"grad({t.point}): a negative weight"
            total = total + w
        else:
            return f"{t.kind}({t.point}): not a term of the measure"
    if key:
        return "a term of the measure is missing from the bound"
    return None if total >= c else "the weights sum to less than the mingrad coefficient"
