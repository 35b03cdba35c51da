"""The PEP of a finite-sum spec (``finite_sum:``, :mod:`sosalgo.spec.finite_sum`) as a
tree of outcomes, in exact arithmetic: every coefficient is a rational ball
(:class:`~sosalgo.kernel.exact.Ball`), the floats the solver sees are their centres.

The Gram basis: the start (each state vector, each memory vector ``phi[j]`` its own), the
gradients at x* (all but the last function's: the weighted sum of the gradients at x* is
0, F = mean of the drawn functions + the others), then every new gradient or proximal
point as the program creates it; x* is the origin. Each of the n functions f_1..f_n is a
function of its own (same class), with the points it was called at in every branch; one
step maps every leaf of the tree to n leaves (index i drawn uniformly), and ``E[...]`` is
the average over the leaves. A constraint is ``form >= 0``: linear in the Gram matrix,
the function values and a constant."""

from __future__ import annotations

import ast
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import sympy as sp

from sosalgo.errors import InputError
from sosalgo.kernel.exact import Ball, enclose
from sosalgo.spec.finite_sum import FiniteSum, check_program_text

__all__ = ["Form", "MAX_LEAVES", "NO_INITIAL", "PointSet", "Problem", "build_problem",
           "check_own_conditions"]

MAX_LEAVES = 64  # n**N leaves at most (the tree of outcomes after N steps)
MAX_POWER = 64  # |exponent| of a power of numbers at most
ZERO = Ball(0)
NO_INITIAL = "none"  # a per-step program's default: no initial condition (the class's
# constants, M and D, bound the measure)


@dataclass
class Vec:
    """A vector: its exact coefficient (a sympy number) per basis index."""

    c: dict[int, sp.Expr]

    def key(self) -> tuple[tuple[int, sp.Expr], ...]:
        """The exact coefficients: two points are one only when they are equal as
        written (merging two points that differ would force equal gradients: a PEP
        below the truth; two names for one point only weaken it)."""
        return tuple(sorted((k, v) for k, v in self.c.items() if v != 0))


def _add(a: dict, b: dict, s: int = 1) -> dict:
    out = dict(a)
    for k, v in b.items():
        v = v if s > 0 else -v
        out[k] = out[k] + v if k in out else v
    return out


def _scale(a: dict, s: Any) -> dict:
    return {k: s * v for k, v in a.items()}


@dataclass
class Form:
    """``sum g[(a, b)] <e_a, e_b> + sum v[k] F_k + const`` (a <= b: the Gram entries)."""

    g: dict[tuple[int, int], Ball] = field(default_factory=dict)
    v: dict[int, Ball] = field(default_factory=dict)
    const: Ball = ZERO

    def plus(self, o: Form, s: int = 1) -> Form:
        return Form(_add(self.g, o.g, s), _add(self.v, o.v, s),
                    self.const + o.const if s > 0 else self.const - o.const)

    def times(self, s: Ball) -> Form:
        return Form(_scale(self.g, s), _scale(self.v, s), s * self.const)


def _enclosed(x: sp.Expr, cache: dict[Any, Ball]) -> Ball:
    if x not in cache:
        cache[x] = enclose(x)
    return cache[x]


def inner(a: Vec, b: Vec, cache: dict[Any, Ball], used: list[Vec]) -> Form:
    """<a, b> as a form (its coefficients enclosed); both vectors go to ``used``."""
    used += [a, b]
    g: dict[tuple[int, int], Ball] = {}
    for i, x in a.c.items():
        for j, y in b.c.items():
            k = (min(i, j), max(i, j))
            xy = _enclosed(x, cache) * _enclosed(y, cache)
            g[k] = g[k] + xy if k in g else xy
    return Form(g)


@dataclass
class PointSet:
    """The points of one function: (x, g, value index) each."""

    name: str
    cls: Any
    params: dict[str, Ball]
    points: list[tuple[Vec, Vec, int]] = field(default_factory=list)


@dataclass
class Problem:
    """The exact PEP: basis size, value count, the constraints ``form >= 0`` by label,
    the measure (its maximum is the worst case)."""

    d: int
    nv: int
    labels: list[str]
    forms: list[Form]
    measure: Form
    basis: list[str]
    leaves: int
    used: list[Vec] = field(default_factory=list)  # every vector of an inner product


class _Builder:
    """Evaluates the program and the terms, registering points and basis vectors."""

    def __init__(self, fs: FiniteSum, n: int, env: dict[str, sp.Expr],
                 functions: list[PointSet], weights: list[Fraction], source: str):
        self.fs, self.n, self.env, self.source = fs, n, env, source
        self.functions = functions
        self.index = {(ps.name): k for k, ps in enumerate(functions)}
        self.d, self.nv, self.basis = 0, 0, []
        self.cache: dict[Any, Ball] = {}
        self.weights = weights
        self.used: list[Vec] = []
        self.blocks: dict[Any, list[Vec]] = {}  # the decomposed vectors' blocks
        self.extra: list[tuple[str, Form]] = []  # their orthogonality (two rows each)
        self.history: list[dict[str, Any]] = []  # per step: the state before it
        self.lazy: dict[str, Vec] = {}  # the start's free vectors, made at their first read

    def inner(self, a: Vec, b: Vec) -> Form:
        return inner(a, b, self.cache, self.used)

    # -- basis -----------------------------------------------------------------------
    def new(self, label: str) -> Vec:
        self.basis.append(label)
        self.d += 1
        return Vec({self.d - 1: sp.Integer(1)})

    def value(self) -> int:
        self.nv += 1
        return self.nv - 1

    def ball(self, x: sp.Expr) -> Ball:
        if not x.is_real or x.free_symbols:
            raise InputError(f"{self.source}: finite_sum: {x} is not a real number here")
        return _enclosed(x, self.cache)

    def optimum(self) -> None:
        """x* = 0 for every function, gradients summing (weighted) to 0."""
        gs = [self.new(f"g*_{ps.name}") for ps in self.functions[:-1]]
        acc: dict[int, sp.Expr] = {}
        for w, g in zip(self.weights, gs, strict=False):
            acc = _add(acc, _scale(g.c, sp.Rational(w.numerator, w.denominator)))
        wl = self.weights[-1]
        last = Vec(_scale(acc, sp.Rational(-wl.denominator, wl.numerator)))
        for ps, g in zip(self.functions, [*gs, last], strict=True):
            ps.points.append((Vec({}), g, self.value()))

    def free_reference(self) -> None:
        """xs = 0 a point of every function that is not one per step (in its domain:
        inside the set of an indicator), its subgradient free; a per-step function gets
        xs when a term or the step calls it there."""
        for ps in self.functions[self.n:]:
            ps.points.append((Vec({}), self.new(f"g*_{ps.name}"), self.value()))

    def block(self, v: Vec, k: int) -> Vec:
        """The k-th of v's n orthogonal blocks (n - 1 new basis vectors, the last the
        rest), orthogonal to every other block of every decomposed vector (PEPit's block
        partition: <P_a u, P_b w> = 0 for a != b)."""
        key = v.key()
        if key not in self.blocks:
            tag = len(self.blocks) + 1
            parts = [self.new(f"block{tag}_{a + 1}") for a in range(self.n - 1)]
            rest = dict(v.c)
            for p in parts:
                rest = _add(rest, p.c, -1)
            parts.append(Vec(rest))
            for t, other in enumerate([*self.blocks.values(), parts]):
                for a in range(self.n):
                    for b in range(self.n):
                        if a == b or (other is parts and b < a):
                            continue
                        form = self.inner(parts[a], other[b])
                        lab = f"block{tag}.{a + 1}:block{t + 1}.{b + 1}"
                        self.extra += [(lab + "+", form), (lab + "-", form.times(Ball(-1)))]
            self.blocks[key] = parts
        return self.blocks[key][k]

    def point(self, k: int, x: Vec) -> tuple[Vec, int]:
        """The gradient and value index of function k at x (registered when new)."""
        ps = self.functions[k]
        for y, g, v in ps.points:
            if y.key() == x.key():
                return g, v
        g = self.new(f"g_{ps.name}{len(ps.points)}")
        v = self.value()
        ps.points.append((x, g, v))
        return g, v


@dataclass
class _Ctx:
    state: dict[str, Any]
    leaves: list[dict[str, Any]] | None
    i: int | None = None
    j: int | None = None
    where: str = ""


class _Eval:
    """One expression of the program or of a term, at a context."""

    def __init__(self, b: _Builder):
        self.b = b

    def fail(self, ctx: _Ctx, msg: str) -> InputError:
        return InputError(f"{self.b.source}: {ctx.where}: {msg}")

    def run(self, node: ast.AST, ctx: _Ctx) -> Any:
        if isinstance(node, ast.Expression):
            return self.run(node.body, ctx)
        if isinstance(node, ast.Constant):
            return sp.Rational(str(node.value)) if isinstance(node.value, float) \
                else sp.Integer(node.value)
        if isinstance(node, ast.Name):
            return self.name(node.id, ctx)
        if isinstance(node, ast.UnaryOp):
            v = self.run(node.operand, ctx)
            return v if isinstance(node.op, ast.UAdd) else self.mul(sp.Integer(-1), v, ctx)
        if isinstance(node, ast.BinOp):
            return self.binop(node, ctx)
        if isinstance(node, ast.Subscript):
            return self.subscript(node, ctx)
        if isinstance(node, ast.Call):
            return self.call(node, ctx)
        raise self.fail(ctx, f"{type(node).__name__} is not allowed here")

    def name(self, name: str, ctx: _Ctx) -> Any:
        if name == "xs":
            return Vec({})
        if name == "i" and self.b.fs.per_step and ctx.i is not None:
            return sp.Integer(ctx.i)  # the step's index, 0-based
        if name in ctx.state and ctx.state[name] is None:  # first read: a free vector
            if name not in self.b.lazy:
                self.b.lazy[name] = self.b.new(f"{name}_0")
            return self.b.lazy[name]
        if name in ctx.state:
            if ctx.leaves is not None and len(ctx.leaves) > 1 and ctx.state is ctx.leaves[0] \
                    and name in self.b.fs.memory() | {s for s, _ in self.b.fs.state}:
                raise self.fail(ctx, f"{name} depends on the draw: write the term inside "
                                     "E[...]")
            v = ctx.state[name]
            if isinstance(v, list):
                raise self.fail(ctx, f"{name} is one vector per function: {name}[j] or "
                                     f"{name}[i]")
            return v
        if name in self.b.env:
            return self.b.env[name]
        raise self.fail(ctx, f"unknown name {name!r}")

    def index(self, node: ast.AST, ctx: _Ctx) -> int:
        which = node.id if isinstance(node, ast.Name) else None
        k = ctx.i if which == "i" else ctx.j if which == "j" else None
        if k is None:
            raise self.fail(ctx, "an index is i (the drawn one, in the step) or j (inside "
                                 "mean(...))")
        return k

    def subscript(self, node: ast.Subscript, ctx: _Ctx) -> Any:
        base = node.value.id if isinstance(node.value, ast.Name) else None
        if base == "E":
            return self.expectation(node.slice, ctx)
        if base in self.b.fs.memory() and base in ctx.state:
            if ctx.leaves is not None and len(ctx.leaves) > 1 and ctx.state is ctx.leaves[0]:
                raise self.fail(ctx, f"{base} depends on the draw: write the term inside "
                                     "E[...]")
            return ctx.state[base][self.index(node.slice, ctx)]
        raise self.fail(ctx, f"{base}[...]: not a memory of the state")

    def expectation(self, node: ast.AST, ctx: _Ctx) -> Any:
        if ctx.leaves is None or ctx.state is not ctx.leaves[0]:
            raise self.fail(ctx, "E[...] is a term's expectation over the draws (not in "
                                 "the step, nor nested)")
        total: Any = None
        for leaf in ctx.leaves:
            v = self.run(node, _Ctx(leaf, None, where=ctx.where))
            total = v if total is None else self.add(total, v, 1, ctx)
        return self.mul(sp.Rational(1, len(ctx.leaves)), total, ctx)

    def functions(self, node: ast.AST, ctx: _Ctx) -> list[int]:
        """The functions a sum names: ``h + f[i]``, ``f[:i+1]`` (f_0 .. f_i)."""
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            return self.functions(node.left, ctx) + self.functions(node.right, ctx)
        if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Slice):
            sl = node.slice
            if not (isinstance(node.value, ast.Name) and node.value.id == self.b.fs.function
                    and sl.step is None and sl.upper is not None):
                raise self.fail(ctx, f"a range of functions is {self.b.fs.function}[a:b]")
            lo = self.scalar(sl.lower, ctx) if sl.lower is not None else sp.Integer(0)
            hi = self.scalar(sl.upper, ctx)
            if not (lo.is_Integer and hi.is_Integer and 0 <= lo < hi <= self.b.n):
                raise self.fail(ctx, f"{self.b.fs.function}[{lo}:{hi}]: not a range of "
                                     f"0..{self.b.n}")
            return list(range(int(lo), int(hi)))
        return [self.function(node, ctx)]

    def function(self, node: ast.AST, ctx: _Ctx) -> int:
        """The index of the function a call names: f[i], f[j] or a function's name."""
        fs = self.b.fs
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) \
                and node.value.id == fs.function:
            return self.index(node.slice, ctx)
        if isinstance(node, ast.Name) and node.id in self.b.index and node.id != fs.function:
            return self.b.index[node.id] + 0
        raise self.fail(ctx, f"expected a function: {fs.function}[i], {fs.function}[j] or "
                             "another function's name")

    def call(self, node: ast.Call, ctx: _Ctx) -> Any:
        fn = node.func
        if isinstance(fn, ast.Subscript) or (isinstance(fn, ast.Name)
                                             and fn.id in self.b.index):
            return self.value_call(node, ctx)
        name, args = fn.id, node.args  # type: ignore[union-attr]
        arity = {"grad": 2, "prox": 3, "mean": 1, "sqrt": 1, "block": 2, "argmin": 1,
                 "lmo": 2, "sum": 1}
        if name not in arity or len(args) != arity[name] or node.keywords:
            raise self.fail(ctx, f"{name}(): unknown or wrong number of arguments "
                                 "(grad(f, x), prox(f, t, w), mean(e), sqrt(c), "
                                 "argmin(f), lmo(h, d), sum(e))")
        if name == "mean":
            return self.mean(args[0], ctx)
        if name == "sum":
            return self.over_steps(args[0], ctx)
        if name == "argmin":
            return self.split_point(self.functions(args[0], ctx), None, Vec({}), ctx)
        if name == "lmo":
            return self.lmo(self.function(args[0], ctx), self.vector(args[1], ctx), ctx)
        if name == "sqrt":
            return sp.sqrt(self.scalar(args[0], ctx))
        if name == "block":
            if not self.b.fs.blocks:
                raise self.fail(ctx, "block(v, i): only with finite_sum.blocks")
            return self.b.block(self.vector(args[0], ctx), self.index(args[1], ctx))
        if name == "grad":
            return self.grad(self.function(args[0], ctx), self.vector(args[1], ctx), ctx)
        ks = self.functions(args[0], ctx)
        if len(ks) > 1:
            return self.split_point(ks, self.scalar(args[1], ctx), self.vector(args[2], ctx),
                                    ctx)
        return self.prox(ks[0], self.scalar(args[1], ctx), self.vector(args[2], ctx), ctx)

    def grad(self, k: int, x: Vec, ctx: _Ctx) -> Vec:
        if not self.b.functions[k].cls.explicit:
            raise self.fail(ctx, f"grad({self.b.functions[k].name}, ...): its class "
                                 f"{self.b.functions[k].cls.name} has no gradient oracle")
        return self.b.point(k, x)[0]

    def prox(self, k: int, t: sp.Expr, w: Vec, ctx: _Ctx) -> Vec:
        ps = self.b.functions[k]
        if not ps.cls.proximal or not t.is_positive:
            raise self.fail(ctx, f"prox({ps.name}, t, w): needs a class with a proximal "
                                 "oracle and a step t > 0")
        y = self.b.new(f"prox_{ps.name}{len(ps.points)}")
        g = Vec(_scale(_add(w.c, y.c, -1), 1 / t))
        ps.points.append((y, g, self.b.value()))
        return y

    def split_point(self, ks: list[int], t: sp.Expr | None, w: Vec, ctx: _Ctx) -> Vec:
        """y = prox of t (f_a + f_b + ...) at w (t None: y a minimizer of the sum): a new
        point of each, subgradients new vectors but the last, which makes them sum to
        (w - y)/t (to 0)."""
        for k in ks:
            ps = self.b.functions[k]
            if not (ps.cls.proximal or ps.cls.explicit):
                raise self.fail(ctx, f"{ps.name}: its class {ps.cls.name} has no oracle")
        if t is not None and not t.is_positive:
            raise self.fail(ctx, "prox(f, t, w): a step t > 0")
        y = self.b.new(f"{'argmin' if t is None else 'prox'}{self.b.d}")
        rest = {} if t is None else _scale(_add(w.c, y.c, -1), 1 / t)
        for pos, k in enumerate(ks):
            ps = self.b.functions[k]
            g = Vec(rest) if pos == len(ks) - 1 else self.b.new(f"g_{ps.name}{len(ps.points)}")
            rest = _add(rest, g.c, -1)
            ps.points.append((y, g, self.b.value()))
        return y

    def lmo(self, k: int, d: Vec, ctx: _Ctx) -> Vec:
        """v in argmin over the set of <d, v>: a point of the indicator h, -d normal there."""
        ps = self.b.functions[k]
        if not getattr(ps.cls, "zero_values", False):
            raise self.fail(ctx, f"lmo({ps.name}, d): a linear minimization over a set, "
                                 "needs an indicator")
        v = self.b.new(f"lmo_{ps.name}{len(ps.points)}")
        ps.points.append((v, Vec(_scale(d.c, -1)), self.b.value()))
        return v

    def over_steps(self, node: ast.AST, ctx: _Ctx) -> Any:
        """sum(e): e summed over the steps k = 0..N-1, its state names the state before
        step k and i = k (a regret: sum(f[i](x) - f[i](xs)))."""
        if not self.b.fs.per_step or ctx.leaves is None or ctx.i is not None:
            raise self.fail(ctx, "sum(...) is a term's sum over the steps of a per-step "
                                 "program (functions.f.per_step), not nested")
        total: Any = None
        for k, st in enumerate(self.b.history):
            v = self.run(node, _Ctx(st, None, k, None, ctx.where))
            total = v if total is None else self.add(total, v, 1, ctx)
        return sp.Integer(0) if total is None else total

    def value_call(self, node: ast.Call, ctx: _Ctx) -> Form:
        if len(node.args) != 1 or node.keywords:
            raise self.fail(ctx, "a function value is f[j](point)")
        k = self.function(node.func, ctx)
        if not self.b.functions[k].cls.has_values:
            raise self.fail(ctx, f"{self.b.functions[k].name} has no function values")
        x = self.vector(node.args[0], ctx)
        if not self.b.functions[k].cls.explicit:
            for y, _, v in self.b.functions[k].points:
                if y.key() == x.key():
                    return Form(v={v: Ball(1)})
            raise self.fail(ctx, "the value of a function without a gradient oracle: only "
                                 "at its prox points and x*")
        return Form(v={self.b.point(k, x)[1]: Ball(1)})

    def mean(self, node: ast.AST, ctx: _Ctx) -> Any:
        if ctx.j is not None:
            raise self.fail(ctx, "mean(...) nested")
        total: Any = None
        for j in range(self.b.n):
            v = self.run(node, _Ctx(ctx.state, ctx.leaves, ctx.i, j, ctx.where))
            total = v if total is None else self.add(total, v, 1, ctx)
        return self.mul(sp.Rational(1, self.b.n), total, ctx)

    def vector(self, node: ast.AST, ctx: _Ctx) -> Vec:
        v = self.run(node, ctx)
        if not isinstance(v, Vec):
            raise self.fail(ctx, f"{ast.unparse(node)[:40]}: expected a vector")
        return v

    def scalar(self, node: ast.AST, ctx: _Ctx) -> sp.Expr:
        v = self.run(node, ctx)
        if not isinstance(v, sp.Expr):
            raise self.fail(ctx, f"{ast.unparse(node)[:40]}: expected a number")
        return v

    # -- arithmetic ------------------------------------------------------------------
    def binop(self, node: ast.BinOp, ctx: _Ctx) -> Any:
        a, b = self.run(node.left, ctx), self.run(node.right, ctx)
        op = node.op
        if isinstance(op, ast.Add | ast.Sub):
            return self.add(a, b, 1 if isinstance(op, ast.Add) else -1, ctx)
        if isinstance(op, ast.Mult):
            if isinstance(a, Vec) and isinstance(b, Vec):
                return self.b.inner(a, b)
            return self.mul(a, b, ctx) if isinstance(a, sp.Expr) else self.mul(b, a, ctx)
        if isinstance(op, ast.Div):
            if not isinstance(b, sp.Expr) or b.is_zero is not False:
                raise self.fail(ctx, "division by a nonzero number only")
            return self.mul(1 / b, a, ctx)
        if isinstance(a, Vec) and b == 2:
            return self.b.inner(a, a)
        if isinstance(a, sp.Expr) and isinstance(b, sp.Expr):
            if not (b.is_Rational and abs(b) <= MAX_POWER):
                raise self.fail(ctx, f"a power of numbers: the exponent must be a rational "
                                     f"number of at most {MAX_POWER} in absolute value")
            return a ** b
        raise self.fail(ctx, "** is v**2 (a squared norm) or a power of numbers")

    def add(self, a: Any, b: Any, s: int, ctx: _Ctx) -> Any:
        if isinstance(a, sp.Expr) and isinstance(b, sp.Expr):
            return a + s * b
        if isinstance(a, Vec) and isinstance(b, Vec):
            return Vec(_add(a.c, b.c, s))
        a, b = self.form(a, ctx), self.form(b, ctx)
        return a.plus(b, s)

    def form(self, a: Any, ctx: _Ctx) -> Form:
        if isinstance(a, Form):
            return a
        if isinstance(a, sp.Expr):
            return Form(const=self.b.ball(a))
        raise self.fail(ctx, "a vector added to a number (use v**2 or u*v for numbers)")

    def mul(self, s: sp.Expr, a: Any, ctx: _Ctx) -> Any:
        if not isinstance(s, sp.Expr):
            raise self.fail(ctx, "a product of a number and a vector or a term")
        if isinstance(a, sp.Expr):
            return s * a
        if isinstance(a, Vec):
            self.b.ball(s)  # a real number
            return Vec(_scale(a.c, s))
        return a.times(self.b.ball(s))


def _start(b: _Builder) -> dict[str, Any]:
    state: dict[str, Any] = {}
    if b.fs.start:  # each vector free at its first read (none unused), then the program
        state = {name: None for name, _ in b.fs.state}
        ev = _Eval(b)
        for k, (target, _, text) in enumerate(b.fs.start):
            where = f"finite_sum.start[{k}]"
            ctx = _Ctx(state, None, None, None, where)
            val = ev.run(check_program_text(text, where, _fail(b.source)), ctx)
            if not isinstance(val, Vec):
                raise ev.fail(ctx, "the start assigns vectors")
            state[target] = val
        return {name: state[name] for name, _ in b.fs.state}
    for name, per in b.fs.state:
        state[name] = ([b.new(f"{name}{j + 1}_0") for j in range(b.n)] if per
                       else b.new(f"{name}_0"))
    return state


def _steps(b: _Builder, ev: _Eval, start: dict[str, Any], steps: int) -> list[dict]:
    programs = [(t, ix, check_program_text(e, f"finite_sum.step[{k}]", _fail(b.source)))
                for k, (t, ix, e) in enumerate(b.fs.step)]
    leaves = [start]
    for step in range(steps):
        nxt = []
        for leaf in leaves:
            for i in ([step] if b.fs.per_step else range(b.n)):
                st = {k: (list(v) if isinstance(v, list) else v) for k, v in leaf.items()}
                if b.fs.per_step:
                    b.history.append(st)
                    st = dict(st)
                for k, (target, indexed, tree) in enumerate(programs):
                    ctx = _Ctx(st, None, i, None, f"finite_sum.step[{k}]")
                    val = ev.run(tree, ctx)
                    if not isinstance(val, Vec):
                        raise ev.fail(ctx, "the step assigns vectors")
                    if indexed:
                        st[target][i] = val
                    else:
                        st[target] = val
                nxt.append({k: st[k] for k in leaf})
        leaves = nxt
    return leaves


def _fail(source: str) -> Any:
    return lambda where, msg: InputError(f"{source}: {where}: {msg}")


def term_form(b: _Builder, text: str, where: str, leaves: list[dict], compare: bool | None
              ) -> Form:
    """A term (``E[...]``, ``a <= b``) as a form: the measure as written, a comparison
    ``a <= b`` as ``b - a`` (>= 0), a bare initial term ``t`` as ``1 - t``."""
    tree = check_program_text(text, where, _fail(b.source), compare)
    ev = _Eval(b)
    ctx = _Ctx(leaves[0], leaves, where=where)
    body = tree.body
    if isinstance(body, ast.Compare):
        lo, hi = body.left, body.comparators[0]
        if isinstance(body.ops[0], ast.GtE):
            lo, hi = hi, lo
        return ev.form(ev.run(hi, ctx), ctx).plus(ev.form(ev.run(lo, ctx), ctx), -1)
    val = ev.form(ev.run(body, ctx), ctx)
    return Form(const=Ball(1)).plus(val, -1) if compare is None else val


def build_problem(fs: FiniteSum, n: int, env: dict[str, sp.Expr], functions: list[PointSet],
                  steps: int, measure: str, initial: str, source: str) -> Problem:
    """The exact PEP after ``steps`` steps (see the module): ``functions`` the drawn
    f_1..f_n then the others, each with its class and exact parameters."""
    if not fs.per_step and n ** steps > MAX_LEAVES:
        raise InputError(f"--steps: {n}**{steps} outcomes exceed {MAX_LEAVES} (the tree "
                         "of draws); ask fewer steps or a smaller count")
    copies = 0 if fs.blocks or fs.per_step else n
    weights = [Fraction(1, n)] * copies + [Fraction(1)] * (len(functions) - copies)
    b = _Builder(fs, n, env, functions, weights, source)
    # a minimizer's gradients come after the start's vectors (x_0 first in the basis):
    # Clarabel's inexact duals depend on the order, and in this one SGD's are proven at
    # the second margin; a free xs's points come before the start, which may call them
    if fs.reference == "free":
        b.free_reference()
    start = _start(b)
    if fs.reference != "free":
        b.optimum()
    ev = _Eval(b)
    forms: list[Form] = []
    labels: list[str] = []
    for k, text in enumerate(fs.constraints):
        forms.append(term_form(b, text, f"finite_sum.constraints[{k}]", [start], True))
        labels.append(f"constraint{k + 1}")
    if initial != NO_INITIAL:
        forms.append(term_form(b, initial, "initial", [start], None))
        labels.append("initial")
    leaves = _steps(b, ev, start, steps)
    mform = term_form(b, measure, "measure", leaves, False)
    labels += [lab for lab, _ in b.extra]
    forms += [f for _, f in b.extra]
    for ps in functions if fs.per_step else ():
        for label, form in _own_conditions(b, ps):
            forms.append(form)
            labels.append(label)
    for ps in () if fs.per_step else functions:
        for a, (xa, ga, fa) in enumerate(ps.points):
            for c, (xb, gb, fb) in enumerate(ps.points):
                if a == c:
                    continue
                for r, form in enumerate(_pair(b, ps, (xa, xb, ga, gb), fa, fb)):
                    forms.append(form)
                    labels.append(f"{ps.name}:{a},{c}#{r}")
    return Problem(b.d, b.nv, labels, forms, mform, b.basis, len(leaves), b.used)


def _pair(b: _Builder, ps: PointSet, X: tuple[Vec, Vec, Vec, Vec], fa: int, fb: int
          ) -> list[Form]:
    out = []
    for alpha, Q in ps.cls.exact_tilted(ps.params):
        form = Form(v={fa: Ball.of(alpha)}).plus(Form(v={fb: Ball.of(alpha)}), -1) \
            if alpha != 0 else Form()
        for r in range(4):
            for s in range(4):
                q = Ball.of(Q[r][s])
                if q.c or q.r:
                    form = form.plus(b.inner(X[r], X[s]).times(q))
        out.append(form)
    return out


def own_conditions(cls: Any, params: dict[str, Ball]) -> list[tuple[Any, Any, Any, bool]]:
    """A class's interpolation conditions on its own data (not tilted): (alpha, Q,
    constant, on one point?) each, ``alpha (f_a - f_b) + <Q X, X> + constant >= 0``;
    [] when the class has none to give (tilted only)."""
    from sosalgo.classes.base import FunctionClass

    if not (cls.has_values and (cls.tilt_invariant or cls.alone
                                or getattr(cls, "zero_values", False))) \
            or type(cls).blocks is not FunctionClass.blocks:  # Gram-level conditions
        return []
    exact = cls.exact_pinned(params)
    scopes = [q.scope for q in cls.pinned({k: float(v.c) for k, v in params.items()})]
    consts = cls.exact_constants(params) or [0] * len(exact or ())
    if exact is None or len(scopes) != len(exact) or len(consts) != len(exact):
        return []
    out = []
    for (alpha, Q), c, scope in zip(exact, consts, scopes, strict=True):
        one = scope == "optimum"  # on g_a alone (|g_a| <= M): each point once
        if one and (alpha != 0 or any(Q[r][s] for r in range(4) for s in range(4)
                                      if (r, s) != (2, 2))):
            return []  # a condition relative to a minimizer (quadratic growth, PL)
        out.append((alpha, Q, c, one))
    return out


def check_own_conditions(cls: Any, source: str, name: str) -> None:
    """InputError unless a per-step program may take the class (its own conditions)."""
    if not own_conditions(cls, {k: Ball(1) for k in cls.parameters}):
        raise InputError(f"{source}: functions.{name}.class: {cls.name} is not taken in a "
                         "per-step program (a class with function values and its own "
                         "interpolation conditions: convex, Lipschitz, indicators)")


def _own_conditions(b: _Builder, ps: PointSet) -> list[tuple[str, Form]]:
    """Every condition of ``ps``'s class among its own points (not tilted), labelled."""
    out = []
    pts = ps.points
    for r, (alpha, Q, c, one) in enumerate(own_conditions(ps.cls, ps.params)):
        pairs = [(a, a) for a in range(len(pts))] if one else \
            [(a, e) for a in range(len(pts)) for e in range(len(pts)) if a != e]
        for a, e in pairs:
            (xa, ga, fa), (xb, gb, fb) = pts[a], pts[e]
            form = Form(const=Ball.of(c)) if c else Form()
            if alpha != 0:
                form = form.plus(Form(v={fa: Ball.of(alpha)})).plus(
                    Form(v={fb: Ball.of(alpha)}), -1)
            X = (xa, xb, ga, gb)
            for p in range(4):
                for q in range(4):
                    w = Ball.of(Q[p][q])
                    if w.c or w.r:
                        form = form.plus(b.inner(X[p], X[q]).times(w))
            out.append((f"{ps.name}:{a}" + ("" if one else f",{e}") + f"#{r}", form))
    return out
