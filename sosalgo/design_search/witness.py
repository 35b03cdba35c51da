"""A proven lower bound for the design of operator methods: linear witnesses over the box.

The box-wide dual bound (:mod:`sosalgo.design_search.dualbound`) needs a family's exact
form, which the interpolation family does not have. For an operator spec whose state is
one-dimensional (Douglas-Rachford, Davis-Yin, forward-backward, ...) this module proves a
lower bound of the *true* worst-case rate over the whole box instead, hence of every
certified rate:

* **Instances.** On C = R^2 the complex number z = a + ib acts as the normal linear
  operator [[a, -b], [b, a]]: for u = z x, <u_a - u_b, x_a - x_b> = a |x_a - x_b|^2 and
  |u_a - u_b|^2 = |z|^2 |x_a - x_b|^2, so z is in an operator class when every form of
  the class (:meth:`~sosalgo.classes.operator.OperatorClass.forms`, ``cross <du, dx> +
  xx |dx|^2 + uu |du|^2 >= 0``) has ``cross a + xx + uu |z|^2 >= 0`` (checked in exact
  rationals); a linear operator with these pairwise properties on all of R^2 is a member of
  the class (monotone, strongly monotone, cocoercive, Lipschitz, ...: each is defined by
  its pairwise condition, and a continuous monotone linear operator is maximal). A
  function contributes a quadratic (q/2)|x|^2, q real in its ``curvatures``.
* **The method on them** is linear: with one z_j per function, every call answers
  u = Z (C xi + D u), so xi+ = T xi with the complex scalar
  T = A + B (I - Z D)^{-1} Z C, and the output is x = e xi (e = C_o + D_o (I - ZD)^{-1} Z C,
  or E). From any xi_0 != 0, |x_k| = |e| |T|^k |xi_0|: when e != 0 no bound
  |x_k - x*| <= c rho^k |xi_0 - xi*| holds with rho < |T|. So rate(theta) >= |T(theta, z)|.
* **Over a box** of theta (scaled coordinates of :mod:`sosalgo.design_search.polymodel`,
  the exact polynomial entries of the method), by the mean value theorem
  |T|^2(theta) >= |T|^2(c) - sum_i sup_box |d_i |T|^2| w_i, c the box's center and w_i its
  half-widths. |T(c)|^2 and the derivatives over the whole box are enclosed in ball
  arithmetic (python-flint ``acb``, outward rounded; forward-mode dual numbers), every
  pivot of the elimination and e are proven nonzero on the box. The instance z of a box
  comes from a floating-point search at its center (it proposes, it never proves).

Branch and bound splits the box with the smallest proven value until every box is at least
the target or the time is up; the bound is the square root of the smallest proven value
(rounded down), a proof for every theta of the box in either case.
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from itertools import product
from typing import Any

import numpy as np
from flint import acb, arb, fmpq

from sosalgo.design_search.polymodel import ExactMethod, exact_method

__all__ = ["WITNESS_CERTIFICATE_KIND", "WitnessBound", "check_witness_certificate",
           "witness_bound"]

ARITHMETIC = "ball arithmetic (python-flint acb, outward rounded) on exact polynomial data"
MARGIN = 1e-9  # instances kept this far (relative) inside their class in the float search
WITNESS_CERTIFICATE_KIND = "linear witnesses"
SEARCH_BAND = 1e-6  # a box whose best instance is this close to the target (in rho^2) at
# its center searches anew
POOL = 16  # instances kept


class _Dual:
    """Value, gradient and Hessian (second-order forward mode) over acb balls."""

    __slots__ = ("v", "d", "h")

    def __init__(self, v: Any, d: list[Any], h: list[list[Any]] | None = None):
        k = len(d)
        self.v, self.d = v, d
        self.h = h if h is not None else [[0] * k for _ in range(k)]

    def _lift(self, o: Any) -> _Dual:
        return o if isinstance(o, _Dual) else _Dual(o, [0] * len(self.d))

    def __add__(self, o: Any) -> _Dual:
        o = self._lift(o)
        return _Dual(self.v + o.v, [a + b for a, b in zip(self.d, o.d, strict=True)],
                     [[a + b for a, b in zip(r, q, strict=True)]
                      for r, q in zip(self.h, o.h, strict=True)])

    __radd__ = __add__

    def __neg__(self) -> _Dual:
        return _Dual(-self.v, [-a for a in self.d], [[-a for a in r] for r in self.h])

    def __sub__(self, o: Any) -> _Dual:
        return self + (-self._lift(o))

    def __rsub__(self, o: Any) -> _Dual:
        return self._lift(o) - self

    def __mul__(self, o: Any) -> _Dual:
        o = self._lift(o)
        k = len(self.d)
        d = [self.v * o.d[i] + self.d[i] * o.v for i in range(k)]
        h = [[self.v * o.h[i][j] + self.h[i][j] * o.v + self.d[i] * o.d[j]
              + self.d[j] * o.d[i] for j in range(k)] for i in range(k)]
        return _Dual(self.v * o.v, d, h)

    __rmul__ = __mul__

    def inverse(self) -> _Dual:
        k = len(self.d)
        r = 1 / self.v
        r2 = r * r
        d = [-a * r2 for a in self.d]
        h = [[-self.h[i][j] * r2 + 2 * self.d[i] * self.d[j] * r2 * r for j in range(k)]
             for i in range(k)]
        return _Dual(r, d, h)

    def __truediv__(self, o: Any) -> _Dual:
        return self * (o.inverse() if isinstance(o, _Dual) else self._lift(o).inverse())

    def __rtruediv__(self, o: Any) -> _Dual:
        return self._lift(o) * self.inverse()


def _value(x: Any) -> Any:
    return x.v if isinstance(x, _Dual) else x


def _nonzero(x: Any) -> bool:
    v = _value(x)
    return (not v.contains(0)) if isinstance(v, acb) else v != 0


@dataclass
class _Terms:
    """A polynomial entry: (coefficient as acb, as complex float, exponents) per term."""

    terms: list[tuple[acb, complex, tuple[int, ...]]]

    def at(self, zs: Sequence[Any], balls: bool) -> Any:
        out: Any = 0
        for c_ball, c_float, exps in self.terms:
            t: Any = c_ball if balls else c_float
            for z, e in zip(zs, exps, strict=True):
                for _ in range(e):
                    t = z * t if isinstance(z, _Dual) else t * z
            out = t + out if isinstance(t, _Dual) else out + t
        return out


def _terms(expr: Any, zs: list[Any]) -> _Terms:
    import sympy as sp

    poly = sp.Poly(sp.expand(expr), *zs) if zs else None
    items = poly.terms() if poly is not None else [((), sp.sympify(expr))]
    out = []
    for exps, c in items:
        c = sp.nsimplify(c) if not c.is_Rational else c
        if not c.is_Rational:
            raise ValueError(f"entry coefficient {c} is not rational")
        q = Fraction(int(c.p), int(c.q))
        if q:
            out.append((acb(arb(fmpq(q.numerator, q.denominator))), complex(float(q)),
                        tuple(int(e) for e in exps)))
    return _Terms(out)


class WitnessBound:
    """The spec's method on linear instances, exact in theta (see the module)."""

    def __init__(self, spec: Any, kappa: float, free: Sequence[str]):
        from sosalgo.model import bind

        om = bind(spec, kappa)
        self.method: ExactMethod = exact_method(spec, kappa, free)
        mats = self.method.matrices
        if mats["A"].shape[0] != 1 or om.measure != "distance":
            raise ValueError("linear witnesses take a one-dimensional state and a distance")
        self.k = len(free)
        zs = self.method.box.zs
        self.ent = {key: [[_terms(mats[key][i, j], zs) for j in range(mats[key].shape[1])]
                          for i in range(mats[key].shape[0])] for key in mats}
        self.calls = list(om.oracles)  # call i -> function index
        self.output = om.output
        self.sets = [_ClassSet.of(fn) for fn in om.functions]
        self.scale = max(float(om.L), 1e-300)

    # ---------------------------------------------------------------- the method
    def transition(self, zs: Sequence[Any], inst: Sequence[Any], balls: bool
                   ) -> tuple[Any, Any] | None:
        """(T, e) at theta ``zs`` on instance ``inst`` (one number per function); None
        when a pivot (or, in balls, its enclosure) is zero."""
        return self.on(self.matrices(zs, balls), inst)

    def matrices(self, zs: Sequence[Any], balls: bool) -> dict[str, list[list[Any]]]:
        """The method's matrices at theta ``zs`` (floats, or balls)."""
        return {key: [[t.at(zs, balls) for t in row] for row in rows]
                for key, rows in self.ent.items()}

    def on(self, ev: dict[str, list[list[Any]]], inst: Sequence[Any]
           ) -> tuple[Any, Any] | None:
        """(T, e) of the method with matrices ``ev`` on instance ``inst``."""
        p = len(self.calls)
        zc = [inst[f] for f in self.calls]
        M = [[(1 if i == j else 0) - zc[i] * ev["D"][i][j] for j in range(p)]
             for i in range(p)]
        rhs = [zc[i] * ev["C"][i][0] for i in range(p)]
        u = _solve(M, rhs)
        if u is None:
            return None
        T = ev["A"][0][0]
        for j in range(p):
            T = T + ev["B"][0][j] * u[j]
        if self.output is None:
            e = ev["E"][0][0]
        else:
            o = self.output
            e = ev["C"][o][0]
            for j in range(p):
                e = e + ev["D"][o][j] * u[j]
        return T, e

    def rate2(self, z: Sequence[float], inst: Sequence[complex],
              ev: dict[str, list[list[Any]]] | None = None) -> float:
        """|T|^2 in floats (0 where the instance is singular); ``ev``: the matrices at
        ``z`` when already evaluated."""
        if ev is None:
            ev = self.matrices([complex(v) for v in z], balls=False)
        out = self.on(ev, inst)
        return 0.0 if out is None or out[1] == 0 else abs(out[0]) ** 2

    # ---------------------------------------------------------------- the proof
    def proven(self, center: Sequence[float], half: Sequence[float],
               inst: Sequence[complex]) -> float:
        """A float <= |T|^2 at every theta of the box (proven; -inf when not): second-order
        Taylor at the center, |T|^2 >= f(c) - sum |f_i(c)| w_i - 1/2 sum sup|f_ij| w_i w_j."""
        if not all(s.member(z) for s, z in zip(self.sets, inst, strict=True)):
            return -math.inf
        zb = [_exact_acb(v) for v in inst]
        at_c = self._duals(center, [0.0] * self.k, zb)
        over = self._duals(center, half, zb)
        if at_c is None or over is None:
            return -math.inf
        f_c, grad_c, _ = at_c
        _, _, hess = over
        low = f_c
        for g, w in zip(grad_c, half, strict=True):
            low -= abs(g) * arb(float(w))
        for i, wi in enumerate(half):
            for j, wj in enumerate(half):
                low -= abs(hess[i][j]) * arb(float(wi)) * arb(float(wj)) / 2
        return float(low.lower()) if low.is_finite() else -math.inf

    def _duals(self, center: Sequence[float], half: Sequence[float], zb: list[acb]
               ) -> tuple[arb, list[arb], list[list[arb]]] | None:
        """(f, its gradient, its Hessian) of f = |T|^2 enclosed over the box (a point when
        ``half`` is 0); None when a pivot or e may vanish there."""
        k = self.k
        box = [_Dual(acb(arb(float(c), float(w))), [1 if i == j else 0 for i in range(k)])
               for j, (c, w) in enumerate(zip(center, half, strict=True))]
        out = self.transition(box, zb, balls=True)
        if out is None or not _nonzero(out[1]):
            return None
        T = out[0] if isinstance(out[0], _Dual) else _Dual(out[0], [0] * k)
        Tc = T.v.conjugate()
        d = [acb(a) for a in T.d]
        f = (T.v * Tc).real
        grad = [2 * (Tc * a).real for a in d]
        hess = [[2 * (d[i].conjugate() * d[j] + Tc * acb(T.h[i][j])).real
                 for j in range(k)] for i in range(k)]
        return f, grad, hess

    # ---------------------------------------------------------------- the search
    def instance(self, z: Sequence[float], start: Sequence[complex] | None) -> list[complex]:
        """A float search for the slowest instance at theta ``z`` (never a proof): each
        number is pulled into its class along the segment from an interior anchor."""
        from scipy.optimize import minimize

        ev = self.matrices([complex(v) for v in z], balls=False)
        starts = [list(start)] if start is not None else self._samples(z, ev)
        best, best_v = list(starts[0]), -1.0
        for s0 in starts:
            x0 = _pack(s0, self.sets)
            res = minimize(lambda x: -self.rate2(z, self._pulled(x), ev), x0,
                           method="Nelder-Mead",
                           options={"maxiter": 80 * len(x0), "xatol": 1e-11,
                                    "fatol": 1e-14})
            for x in (res.x, x0):
                inst = self._pulled(x)
                v = self.rate2(z, inst, ev)
                if v > best_v:
                    best, best_v = inst, v
        return best

    def _pulled(self, x: np.ndarray) -> list[complex]:
        return [s.pull(v, self.scale) for s, v in zip(self.sets, _unpack(x, self.sets),
                                                      strict=True)]

    def _samples(self, z: Sequence[float], ev: dict[str, list[list[Any]]]
                 ) -> list[list[complex]]:
        """The three slowest of a grid of instances (starts of the search)."""
        grids = [s.grid(self.scale) for s in self.sets]
        scored = [(self.rate2(z, list(c), ev), list(c)) for c in product(*grids)]
        scored.sort(key=lambda t: -t[0])
        return [c for _, c in scored[:3]] or [[g[0] for g in grids]]


def _solve(M: list[list[Any]], rhs: list[Any]) -> list[Any] | None:
    """Gaussian elimination without pivoting; None at a (possibly) zero pivot."""
    p = len(rhs)
    M = [row[:] for row in M]
    rhs = rhs[:]
    for j in range(p):
        if not _nonzero(M[j][j]):
            return None
        for i in range(j + 1, p):
            f = M[i][j] / M[j][j]
            M[i] = [M[i][c] - f * M[j][c] for c in range(p)]
            rhs[i] = rhs[i] - f * rhs[j]
    u: list[Any] = [0] * p
    for j in reversed(range(p)):
        acc = rhs[j]
        for c in range(j + 1, p):
            acc = acc - M[j][c] * u[c]
        u[j] = acc / M[j][j]
    return u


def _exact_acb(v: complex) -> acb:
    return acb(arb(float(v.real)), arb(float(v.imag)))


def _pack(inst: Sequence[complex], sets: Sequence[_ClassSet]) -> np.ndarray:
    out: list[float] = []
    for s, v in zip(sets, inst, strict=True):
        out += [v.real, v.imag] if s.complex else [v.real]
    return np.array(out)


def _unpack(x: np.ndarray, sets: Sequence[_ClassSet]) -> list[complex]:
    out, i = [], 0
    for s in sets:
        if s.complex:
            out.append(complex(x[i], x[i + 1]))
            i += 2
        else:
            out.append(complex(x[i], 0.0))
            i += 1
    return out


class _ClassSet:
    """The numbers z whose normal linear operator (or quadratic) is in a class."""

    def __init__(self, forms: list[tuple[Fraction, Fraction, Fraction]] | None,
                 interval: tuple[Fraction, Fraction | None] | None):
        self.forms, self.interval = forms, interval
        self.complex = forms is not None
        self._anchor: complex | None = None

    @classmethod
    def of(cls, fn: Any) -> _ClassSet:
        from sosalgo.classes.operator import OperatorClass

        params = {k: Fraction(float(v)) for k, v in fn.params.items()
                  if isinstance(v, (int, float))}
        if isinstance(fn.cls, OperatorClass):
            if not fn.cls.pairwise_defined:  # a linear class: z is not a member
                raise ValueError(f"{fn.name}: class {fn.cls.name} is not defined by its "
                                 "pairwise conditions alone")
            forms = fn.cls.forms(params)
            return cls([tuple(Fraction(c) for c in f) for f in forms], None)
        cur = fn.cls.curvatures(fn.params)
        if cur is None or fn.cls.has_values is False or not math.isfinite(float(cur[0])):
            raise ValueError(f"{fn.name}: class {fn.cls.name} has no quadratics")
        hi = Fraction(float(cur[1])) if math.isfinite(float(cur[1])) else None
        return cls(None, (Fraction(float(cur[0])), hi))

    def member(self, z: complex) -> bool:
        """Exactly (rationals of the floats): the instance is in the class."""
        a, b = Fraction(z.real), Fraction(z.imag)
        if self.forms is None:
            lo, hi = self.interval
            return b == 0 and lo <= a and (hi is None or a <= hi)
        return all(cross * a + xx + uu * (a * a + b * b) >= 0
                   for cross, xx, uu in self.forms)

    def inside(self, z: complex, scale: float) -> bool:
        """In floats, at least MARGIN (relative) inside (the search's constraint)."""
        if self.forms is None:
            lo, hi = self.interval
            return float(lo) <= z.real <= (math.inf if hi is None else float(hi)) and \
                math.isfinite(z.real)
        a, n2 = z.real, z.real ** 2 + z.imag ** 2
        if not math.isfinite(n2):
            return False
        tol = MARGIN * (1.0 + scale + n2)
        return all(float(c) * a + float(x) + float(u) * n2 >= tol for c, x, u in self.forms)

    def pull(self, z: complex, scale: float) -> complex:
        """z if inside, else the last inside point of the segment from the anchor to z
        (the sets are convex: intersections of half-planes and discs)."""
        if self.forms is None:
            lo, hi = self.interval
            top = math.inf if hi is None else float(hi)
            return complex(min(max(z.real, float(lo)), top, 1e300), 0.0)
        if not math.isfinite(abs(z)):
            z = 0j
        if self.inside(z, scale):
            return z
        a = self.anchor(scale)
        lo, hi = 0.0, 1.0
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.inside(a + mid * (z - a), scale) else (lo, mid)
        return a + lo * (z - a)

    def anchor(self, scale: float) -> complex:
        """An interior point: the grid point farthest inside (the smallest form value,
        relative to the size of the point, largest)."""
        if self._anchor is None:
            def depth(p: complex) -> float:
                n2 = abs(p) ** 2
                return min(float(c) * p.real + float(x) + float(u) * n2
                           for c, x, u in self.forms) / (1.0 + scale + n2)
            self._anchor = max(self.grid(scale), key=depth)
        return self._anchor

    def grid(self, scale: float) -> list[complex]:
        if self.forms is None:
            lo, hi = self.interval
            top = float(lo) + 10 * scale if hi is None else float(hi)
            return [complex(v) for v in np.linspace(float(lo), top, 5)]
        vals = [0.0, 0.01, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0, 1.5, 2.0, 10.0]
        ims = [0.0, 0.1, 0.25, 0.5, 0.75, 1.0, 2.0, 10.0]
        pts = [complex(a * scale, s * b * scale) for a in vals for b in ims for s in (1, -1)]
        pts = [p for p in pts if self.inside(p, scale)]
        return pts or [complex(0.0)]


@dataclass
class _Box:
    center: tuple[float, ...]
    half: tuple[float, ...]
    inst: list[complex]

    def split(self) -> list[_Box]:
        j = int(np.argmax(self.half))
        h = list(self.half)
        h[j] /= 2
        out = []
        for s in (-1, 1):
            c = list(self.center)
            c[j] += s * h[j]
            out.append(_Box(tuple(c), tuple(h), self.inst))
        return out


def _prove_box(wb: WitnessBound, box: _Box, pool: list[list[complex]], t2: float
               ) -> tuple[list[complex], float]:
    """(instance, proven value) of a box: the best proof of the two instances of the pool
    slowest at its center; a new search there when none reaches ``t2`` at the center
    (splitting cannot help then), its result added to the pool."""
    ev = wb.matrices([complex(v) for v in box.center], balls=False)
    ranked = sorted(pool, key=lambda inst: -wb.rate2(box.center, inst, ev))[:2]
    best, val = ranked[0], -math.inf
    for inst in ranked:
        v = wb.proven(box.center, box.half, inst)
        if v > val:
            best, val = inst, v
    if val < t2 and wb.rate2(box.center, ranked[0], ev) < t2 + SEARCH_BAND:
        found = wb.instance(box.center, ranked[0])
        v = wb.proven(box.center, box.half, found)
        pool.append(found)
        del pool[:-POOL]
        if v > val:
            best, val = found, v
    return best, val


def witness_bound(spec: Any, kappa: float, free: Sequence[str], target: float,
                  deadline: float, min_half: float = 1e-7) -> tuple[float | None, dict]:
    """(proven lower bound of every rate over the box, details), by branch and bound
    until every box is proven at ``target`` or ``deadline`` (``time.perf_counter``) has
    passed; (None, details with the reason) when the spec is out of this argument's reach."""
    t0 = time.perf_counter()
    try:
        wb = WitnessBound(spec, kappa, free)
    except (ValueError, KeyError) as exc:
        return None, {"method": "witness", "status": "unsupported", "reason": str(exc)}
    k = wb.k
    root = _Box(tuple([0.0] * k), tuple([1.0] * k), [])
    root.inst = wb.instance(root.center, None)
    heap: list[tuple[float, int, _Box]] = []
    count = 0

    pool = [root.inst]  # the instances found so far (the slowest at a box is tried)
    t2 = target * target

    def push(box: _Box) -> None:
        nonlocal count
        box.inst, val = _prove_box(wb, box, pool, t2)
        count += 1
        heapq.heappush(heap, (val, count, box))

    push(root)
    while heap[0][0] < target * target and time.perf_counter() < deadline:
        val, _, box = heapq.heappop(heap)
        if max(box.half) < min_half:
            heapq.heappush(heap, (val, 0, box))
            break
        for child in box.split():
            push(child)
    low = heap[0][0]
    lb = math.sqrt(low) if low > 0 else 0.0
    lb = float(np.nextafter(lb, 0.0)) if lb > 0 else 0.0
    status = "proved" if low >= target * target else "partial"
    cert = {"kind": WITNESS_CERTIFICATE_KIND, "free": list(free),
            "proofs": [{"z": list(b.center), "w": list(b.half), "r": min(max(v, 0.0), 1.0),
                        "instance": [[c.real, c.imag] for c in b.inst]} for v, _, b in heap]}
    return lb, {"method": "witness", "status": status, "target": target, "boxes": count,
                "leaves": len(heap), "arithmetic": ARITHMETIC,
                "seconds": time.perf_counter() - t0,
                "instance_at_bound": [[v.real, v.imag] for v in heap[0][2].inst],
                "_certificate": cert}


def check_witness_certificate(spec: Any, kappa: float, free: Sequence[str],
                              cert: Mapping[str, Any]) -> Any:
    """Re-prove a witness bound certificate: each box's value in ball arithmetic on its
    instance (exact class membership included), then what the boxes that held cover of
    the box Θ (the walk of :mod:`sosalgo.design_search.boundcheck`). ValueError when the
    certificate is malformed."""
    from sosalgo.design_search.boundcheck import BoundCheck, box_cover, dyadic_half

    if not isinstance(cert, Mapping) or cert.get("kind") != WITNESS_CERTIFICATE_KIND:
        raise ValueError(f"kind: expected {WITNESS_CERTIFICATE_KIND!r}")
    wb = WitnessBound(spec, kappa, free)
    k = wb.k
    best: dict[tuple, float] = {}
    proofs = list(cert.get("proofs") or [])
    failed = 0
    for p in proofs:
        z, w = np.asarray(p["z"], float), np.asarray(p["w"], float)
        r = float(p["r"])
        inst = [complex(float(a), float(b)) for a, b in p["instance"]]
        ok = (z.shape == (k,) and w.shape == (k,) and np.all(np.isfinite(z))
              and np.all(np.abs(z) + w <= 1) and all(map(dyadic_half, w)) and 0 <= r <= 1
              and len(inst) == len(wb.sets) and wb.proven(z, w, inst) >= r)
        if not ok:
            failed += 1
            continue
        key = (*z.tolist(), *w.tolist())
        best[key] = max(best.get(key, 0.0), r)
    boxes = np.array([list(key) for key in best]) if best else np.zeros((0, 2 * k))
    r = box_cover(best, boxes, np.zeros(k), np.ones(k)) if best else 0.0
    reason = (f"{len(proofs) - failed} of {len(proofs)} witness boxes re-proven in ball "
              f"arithmetic; every rate over Θ is at least sqrt({r!r})")
    return BoundCheck(r, len(proofs), failed, reason)
