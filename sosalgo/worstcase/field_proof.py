"""Exact PEP proofs over a quadratic field Q(sqrt d).

When the spec's numbers are irrational only through one square root (sqrt(mu),
sqrt(kappa) with rational mu, kappa: the accelerated gradient flow, robust momentum), the
tight dual certificate S is often singular along a direction with entries in Q(sqrt d)
while the PEP leaves that direction free: no margin makes S definite there, no rational
multipliers make S v = 0 for an irrational v, and balls cannot prove an exact zero. Here
everything is exact in Q(sqrt d) (:mod:`sosalgo.kernel.qfield`):

1. the exact PEP is built with every number an element of the field;
2. the float certificate's null space (eigenvalues of the scaled S near 0) is recognised
   in the field, entry by entry of its echelon form (PSLQ guesses: only step 4 decides);
3. tau and the multipliers on the float support are solved exactly in the field from
   S(tau, lambda) v = 0 on that null space and c_F = 0 where the float c_F vanishes (free
   unknowns at their recognised float values): tau* is an exact element a + b sqrt(d);
4. at a rational tau_proven >= tau* (tau* rounded outward, about 1e-12 above), the proof
   decides exactly: every multiplier >= 0, c_F(tau_proven) >= 0, and
   S(tau_proven) = tau_proven I0 - M - sum lambda_k Q_k ⪰ 0 by LDL^T with diagonal
   pivoting in the field (exact zeros on the free directions).

The proof carries ``field`` ({"sqrt": d}), ``multipliers_exact`` (label -> [a, b], the
multiplier a + b sqrt(d)), ``tau_exact`` ([a, b]) and ``tau_exact_text`` (its closed
form); :func:`reprove_field` re-proves step 4 from them alone.
"""

from __future__ import annotations

import time
from fractions import Fraction
from typing import Any

import numpy as np

from sosalgo.worstcase.structure import PEPFrame, PEPStructure, build_structure
from sosalgo.worstcase.terms import Term

FIELD_CHECK = "exact (quadratic field arithmetic)"
NULL_TOLS = (1e-7, 1e-6, 1e-8)  # eigenvalues of the scaled S counted as its null space
SUPPORT_CUTS = (1e-7, 1e-4, 1e-3)  # multipliers below this share of the largest: dropped
ZERO_F = (1e-6, 1e-3)  # value residuals this small (relative) are made exactly 0
# (max coefficient, relative tolerance) of the recognised entries, from short and exact to
# coarse: an interior-point answer on a degenerate face spreads ~1e-5 on pairs the exact
# certificate does not use (entries below 10 tol are taken as 0; the proof decides)
RECOGNIZE = ((100, 1e-9), (10 ** 3, 1e-8), (100, 1e-6), (100, 1e-4), (10 ** 4, 1e-8))
FIELD_MAX_D = 24  # basis size the field proof takes on (exact arithmetic grows fast)
FIELD_SECONDS = 10.0  # CPU seconds the attempts may take before the search gives up


def spec_radicand(spec: Any, kappa: float | None, terms: list[Term]) -> int | None:
    """The squarefree d of the one square root the spec's exact numbers (its parameters,
    matrices and the coefficients of ``terms``) use, None when they use none or more
    (:func:`sosalgo.kernel.qfield.radicand`)."""
    from sosalgo.kernel.expr.parse import to_sympy
    from sosalgo.kernel.qfield import radicand
    from sosalgo.worstcase.exact import exact_values

    try:
        env, mats = exact_values(spec, kappa)
        exprs = [v for v in env.values() if not getattr(v, "free_symbols", None)]
        exprs += [e for M in mats.values() for e in M]
        exprs += [to_sympy(t.coef).xreplace(env) for t in terms]
    except (ValueError, ArithmeticError, TypeError):
        return None
    return radicand(exprs)


def field_structure(spec: Any, kappa: float | None, steps: int, mterms: list[Term],
                    iterms: list[Term], st_float: PEPStructure, plain: bool
                    ) -> tuple[PEPFrame, PEPStructure, int] | None:
    """(method, structure, d) of the PEP over Q(sqrt d); None when the spec is not in one
    quadratic field, or the structure differs from the float one. ``plain``: the float
    solve's basis had no deadbeat gain (K = 0)."""
    d = spec_radicand(spec, kappa, mterms + iterms)
    if d is None:
        return None
    try:
        mt, st = _rebuilt(spec, kappa, steps, mterms, iterms, d, plain)
    except (ValueError, ArithmeticError, TypeError):
        return None
    if st.labels != st_float.labels or st.basis != st_float.basis or st.extras \
            or st.constants is not None or st.free_values or st.d > FIELD_MAX_D:
        return None
    return mt, st, d


def _pair_forms(mt: PEPFrame, st: PEPStructure, support: list[int]
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(X' Q X on G, a on F) of the pairs ``support``, exactly."""
    out = []
    for k in support:
        _, av, X = st.pair_rows(mt, k)
        j, _, _, r = st.pairs[k]
        Q = np.array(mt.ineqs[j][r][1], dtype=object)
        out.append((X.T.dot(Q).dot(X), av))
    return out


def _slack(st: PEPStructure, forms: list[tuple[np.ndarray, np.ndarray]],
           tau: Any, lam: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    """(S, c_F) = (tau I0 - M - sum lambda_k Q_k, tau i_F - m_F - sum lambda_k a_k)."""
    S = np.array(st.init_q, dtype=object) * tau - np.array(st.meas_q, dtype=object)
    cF = np.array(st.init_f, dtype=object) * tau - np.array(st.meas_f, dtype=object)
    for (Q, a), lk in zip(forms, lam, strict=True):
        if lk != 0:
            S = S - Q * lk
            cF = cF - a * lk
    return S, cF


def _null_space(S: np.ndarray, w: np.ndarray, d: int, tol: float,
                rec: tuple[int, float], by_range: bool) -> list[list[Any]] | None:
    """The null space of the float S (scaled eigenvalues below ``tol`` of its largest
    entry) exactly in Q(sqrt d): its echelon form recognised entry by entry, or
    (``by_range``) the echelon form of S's range recognised and its kernel taken exactly
    (a rank-one S has a short range vector where its null space's echelon form has long
    entries). None when an entry is not recognised or there is no null space."""
    Sh = S * np.outer(w, w)
    scale = max(1.0, float(np.abs(Sh).max()))
    vals, vecs = np.linalg.eigh(0.5 * (Sh + Sh.T))
    small = np.abs(vals) <= tol * scale
    if not small.any():
        return None
    if by_range:  # the range of the unscaled S: rows u with S = sum c u u' (v -> w v)
        rows = _recognized(_echelon((vecs[:, ~small] / np.asarray(w)[:, None]).T), d, rec)
        return None if rows is None else _kernel(rows, S.shape[0], d)
    return _recognized(_echelon((vecs[:, small] * np.asarray(w)[:, None]).T), d, rec)


def _echelon(R: np.ndarray) -> np.ndarray:
    """The reduced row echelon form of the rows of ``R`` (complete pivoting: the largest
    remaining entry first, so that the other entries stay short)."""
    R = R.copy()
    r, used = 0, []
    big = float(np.abs(R).max()) if R.size else 0.0
    while r < R.shape[0]:
        sub = np.abs(R[r:, :])
        sub[:, used] = 0.0
        i, c = np.unravel_index(int(np.argmax(sub)), sub.shape)
        if sub[i, c] <= 1e-8 * big:
            break
        R[[r, r + i]] = R[[r + i, r]]
        R[r] /= R[r, c]
        for k in range(R.shape[0]):
            if k != r:
                R[k] -= R[k, c] * R[r]
        used.append(c)
        r += 1
    return R[:r]


def _recognized(R: np.ndarray, d: int, rec: tuple[int, float]) -> list[list[Any]] | None:
    from sosalgo.kernel.qfield import QSqrt, recognize

    out = []
    for row in R:
        vec = []
        for x in row:
            q = (QSqrt(0, 0, d) if abs(x) <= max(1e-9, 10 * rec[1])
                 else recognize(float(x), d, *rec))
            if q is None:
                return None
            vec.append(q)
        out.append(vec)
    return out


def _kernel(rows: list[list[Any]], n: int, d: int) -> list[list[Any]] | None:
    """A basis of {v : u v = 0 for every u of ``rows``}, exactly (Gauss-Jordan in the
    field)."""
    from sosalgo.kernel.qfield import QSqrt, back_substitute, solve_linear

    zero = QSqrt(0, 0, d)
    system = solve_linear([list(r) for r in rows], [zero] * len(rows))
    if system is None:
        return None
    cols = system[2]
    free = cols[:cols.index(-1)]
    out = []
    for f in free:
        out.append(back_substitute(system, [QSqrt(int(g == f), 0, d) for g in free], n))
    return out or None


def _solve(st: PEPStructure, forms: list[tuple[np.ndarray, np.ndarray]],
           null: list[list[Any]], tau: float, lam: list[float], zero_f: list[int],
           d: int, rec: tuple[int, float]) -> tuple[Any, list[Any]] | None:
    """(tau*, lambda) exact in Q(sqrt d): S(tau, lambda) v = 0 for each v of ``null`` and
    c_F[i] = 0 for i in ``zero_f``; the free unknowns at their recognised float values
    (tau is the last unknown, so that it is the first left free: the float answer's most
    accurate number). None when inconsistent, a free value is not recognised, or a
    multiplier is < 0."""
    from sosalgo.kernel.qfield import back_substitute, recognize, solve_linear

    I0 = np.array(st.init_q, dtype=object)
    M = np.array(st.meas_q, dtype=object)
    eqs, rhs = [], []
    for v in null:
        vv = np.array(v, dtype=object)
        iv, mv = I0.dot(vv), M.dot(vv)
        qv = [Q.dot(vv) for Q, _ in forms]
        for i in range(st.d):
            eqs.append([-q[i] for q in qv] + [iv[i]])
            rhs.append(mv[i])
    for i in zero_f:
        eqs.append([-a[i] for _, a in forms] + [st.init_f[i]])
        rhs.append(st.meas_f[i])
    if st.bare:  # no initial condition: the proof is at tau = 0 exactly
        eqs.append([Fraction(0)] * len(forms) + [Fraction(1)])
        rhs.append(Fraction(0))
    system = solve_linear(eqs, rhs)
    if system is None:
        return None
    cols = system[2]
    guesses = list(lam) + [tau]
    values = []
    for f in cols[:cols.index(-1)]:
        q = recognize(guesses[f], d, *rec)
        if q is None:
            return None
        values.append(q)
    x = back_substitute(system, values, len(guesses))
    if any(v < 0 for v in x[:-1]):
        return None
    return x[-1], x[:-1]


def _prove(st: PEPStructure, forms: list[tuple[np.ndarray, np.ndarray]], tau_star: Any,
           lam: list[Any]) -> tuple[Fraction, str, bool] | None:
    """(tau_proven, detail, at_exact): a rational tau_proven >= tau* at which c_F >= 0
    and S ⪰ 0 are proven exactly (at_exact False); else, when tau* >= 0, the same proven
    at tau* itself (at_exact True: measure <= tau* initial for every instance, so
    measure <= tau* <= tau_proven whenever initial <= 1, whatever initial's sign: the
    initial form need not be PSD, as a Lyapunov function from a free start is not)."""
    from sosalgo.worstcase.exact import TAU_STEPS, above

    star = _q(tau_star, _field_d(lam, tau_star))
    if st.bare:  # tau = 0 exactly (measure <= 0 everywhere)
        ok, why = proven_at(st, forms, Fraction(0), lam) if star == 0 else (False, "")
        return (Fraction(0), why, False) if ok else None
    for step in TAU_STEPS:
        tq = above(star.upper(), Fraction(step))
        ok, why = proven_at(st, forms, tq, lam)
        if ok:
            return tq, why, False
    if star >= 0:
        ok, why = proven_at(st, forms, star, lam)
        if ok:
            return above(star.upper(), Fraction(TAU_STEPS[0])), why, True
    return None


def _field_d(lam: list[Any], tau: Any) -> int:
    return next(v.d for v in [tau, *lam] if hasattr(v, "d"))


def proven_at(st: PEPStructure, forms: list[tuple[np.ndarray, np.ndarray]], tq: Fraction,
              lam: list[Any]) -> tuple[bool, str]:
    """(proven, detail): multipliers >= 0, c_F >= 0 and S ⪰ 0 at ``tq``, exactly."""
    from sosalgo.kernel.qfield import field_psd

    if any(v < 0 for v in lam):
        return False, "a negative multiplier"
    S, cF = _slack(st, forms, tq, lam)
    bad = [i for i, c in enumerate(cF) if c < 0]
    if bad:
        return False, f"value residual {bad[0]} is negative"
    ok, why = field_psd(S.tolist())
    return ok, (f"S ⪰ 0: {why}; c_F >= 0 (exact)" if ok else f"S is not PSD: {why}")


Answer = tuple[np.ndarray, float, np.ndarray, np.ndarray]  # a float (S, tau, lambda, c_F)


def prove_in_field(spec: Any, kappa: float | None, mt_float: PEPFrame, st_float: PEPStructure,
                   mterms: list[Term], iterms: list[Term], answers: list[Answer],
                   w: np.ndarray) -> dict[str, Any]:
    """The proof over Q(sqrt d) of one of the float certificates ``answers`` (S, tau,
    lambda, c_F; the most accurate first): a proof dict as
    :func:`sosalgo.worstcase.exact.prove_certificate` gives, ``proven`` False with a
    ``detail`` when none is found."""
    t0 = time.perf_counter()
    out: dict[str, Any] = {"proven": False, "tau_proven": None, "tau_proven_float": None}
    got = field_structure(spec, kappa, st_float.steps, mterms, iterms, st_float,
                          not np.any(mt_float.K))
    if got is None:
        return out | {"detail": "not in one quadratic field Q(sqrt d)",
                      "seconds": time.perf_counter() - t0}
    mt, st, d = got
    detail = "no exact multipliers in the field make the certificate's null rows zero"
    cpu0 = time.process_time()
    for S, tau, lam, cf in answers:
        top = float(np.max(lam, initial=0.0))
        cscale = 1.0 + float(np.abs(cf).max(initial=0.0))
        for null, rec, cut, zero in ((n, r, c, z) for n, r in _attempts(S, w, d)
                                     for c in SUPPORT_CUTS for z in ZERO_F):
            if time.process_time() - cpu0 > FIELD_SECONDS:
                return out | {"detail": f"{detail} (search stopped after "
                                        f"{FIELD_SECONDS:g} CPU seconds)",
                              "seconds": time.perf_counter() - t0}
            zero_f = [i for i in range(st.nF) if abs(cf[i]) <= zero * cscale]
            support = [k for k, v in enumerate(lam[:len(st.pairs)]) if v > cut * top]
            forms = _pair_forms(mt, st, support)
            sol = _solve(st, forms, null, tau, [float(lam[k]) for k in support],
                         zero_f, d, rec)
            if sol is None:
                continue
            done = _prove(st, forms, *sol)
            if done is None:
                detail = "the field's certificate is not proven PSD"
                continue
            return out | _proof_fields(spec, kappa, st, d, support, sol, done, w,
                                       not np.any(mt_float.K)) | {
                "seconds": time.perf_counter() - t0}
    return out | {"detail": detail, "seconds": time.perf_counter() - t0}


TIGHT_RECOGNIZE = ((10 ** 4, 1e-11), (10 ** 5, 1e-11), (10 ** 5, 1e-10))  # of a polished answer


def _attempts(S: np.ndarray, w: np.ndarray, d: int):  # type: ignore[no-untyped-def]
    """(null space, recognition) pairs to try, cheapest first: no null space (tau and the
    multipliers the value residuals leave free recognised from an accurate answer), then
    S's null space recognised (:func:`_null_space`) at each of :data:`RECOGNIZE`."""
    for rec in TIGHT_RECOGNIZE:
        yield [], rec
    for rec in RECOGNIZE:
        for tol, by_range in ((t, r) for t in NULL_TOLS for r in (True, False)):
            null = _null_space(S, w, d, tol, rec, by_range)
            if null is not None:
                yield null, rec


def _proof_fields(spec: Any, kappa: float | None, st: PEPStructure, d: int,
                  support: list[int], sol: tuple[Any, list[Any]],
                  done: tuple[Fraction, str], w: np.ndarray, plain: bool) -> dict[str, Any]:
    """The fields of a proven field certificate (see the module)."""
    from sosalgo.kernel.exact import fraction_str, rational
    from sosalgo.worstcase.exact import class_description

    tau_star, lk = sol
    tq, why, at_exact = done
    where = "at tau_exact >= 0 (so measure <= tau_exact <= tau_proven when initial <= 1)" \
        if at_exact else "at tau_proven"
    return {"proven": True, "tau_proven": fraction_str(tq), "tau_proven_float": float(tq),
            "delta": "0", "detail": f"in Q(sqrt({d})), {where}: {why}",
            "field": {"sqrt": d}, "plain_basis": plain, "at": "tau_exact" if at_exact
            else "tau_proven",
            "tau_exact": _parts(tau_star, d), "tau_exact_text": _q(tau_star, d).text(),
            "multipliers_nonzero": sum(1 for v in lk if v != 0),
            "multipliers_exact": {st.labels[k]: _parts(v, d)
                                  for k, v in zip(support, lk, strict=True) if v != 0},
            "scale": [fraction_str(rational(float(v))) for v in w],
            "class": class_description(spec, kappa)}


def _q(v: Any, d: int) -> Any:
    from sosalgo.kernel.qfield import QSqrt

    return v if isinstance(v, QSqrt) else QSqrt(Fraction(v), 0, d)


def _parts(v: Any, d: int) -> list[str]:
    return _q(v, d).parts()


def reprove_field_row(spec: Any, kappa: float | None, steps: int, measure: str,
                      initial: str, proof: dict[str, Any]) -> tuple[bool, str]:
    """:func:`reprove_field` on the terms of a ``pep`` row (``sosalgo verify``)."""
    from sosalgo.worstcase.exact import exact_or_none
    from sosalgo.worstcase.terms import parse_terms

    if not isinstance(proof.get("field"), dict):
        return False, "malformed proof: field: expected an object {\"sqrt\": d}"
    try:
        mt = exact_or_none(spec, kappa, int(steps))
        if mt is None:
            return False, "the exact method cannot be built"
        mterms = parse_terms(measure, "measure", False, mt.p, spec.parameters)
        iterms = parse_terms(initial, "initial", True, mt.p, spec.parameters)
    except (ValueError, TypeError, ArithmeticError) as exc:
        return False, f"malformed proof: {type(exc).__name__}: {exc}"
    return reprove_field(spec, kappa, int(steps), mterms, iterms, proof)


def reprove_field(spec: Any, kappa: float | None, steps: int, mterms: list[Term],
                  iterms: list[Term], proof: dict[str, Any]) -> tuple[bool, str]:
    """(proven, detail): the proof's claim measure <= tau_proven re-proven from its
    ``field`` and ``multipliers_exact`` alone on the PEP rebuilt over Q(sqrt d); nothing
    is solved. A field the spec's numbers do not live in is refused."""
    from sosalgo.kernel.qfield import parse_element

    try:
        d = int(proof["field"]["sqrt"])
        tq = Fraction(proof["tau_proven"])
        lab = proof["multipliers_exact"]
        if not isinstance(lab, dict):
            raise ValueError("multipliers_exact: expected an object")
        want = spec_radicand(spec, kappa, mterms + iterms)
        if want != d:
            return False, f"the spec's numbers are not in Q(sqrt({d}))"
        mt, st = _rebuilt(spec, kappa, int(steps), mterms, iterms, d,
                          proof.get("plain_basis") is True)
        index = {name: k for k, name in enumerate(st.labels)}
        unknown = [k for k in lab if k not in index]
        if unknown:
            return False, f"multiplier {unknown[0]!r} is not a pair of this PEP"
        support = sorted(index[k] for k in lab)
        lam = [parse_element(lab[st.labels[k]], d) for k in support]
    except (ValueError, TypeError, KeyError, ZeroDivisionError, ArithmeticError) as exc:
        return False, f"malformed proof: {type(exc).__name__}: {exc}"
    forms = _pair_forms(mt, st, support)
    if proof.get("at") == "tau_exact":  # proven at the exact tau* >= 0, tau_proven >= it
        try:
            star = parse_element(proof["tau_exact"], d)
        except (ValueError, TypeError, KeyError, ZeroDivisionError) as exc:
            return False, f"malformed proof: tau_exact: {exc}"
        if not (star >= 0 and tq >= star):
            return False, "tau_exact is negative or above tau_proven"
        ok, why = proven_at(st, forms, star, lam)
        return ok, f"in Q(sqrt({d})), at tau_exact = {star.text()}: {why}"
    ok, why = proven_at(st, forms, tq, lam)
    return ok, f"in Q(sqrt({d})): {why}"


def _rebuilt(spec: Any, kappa: float | None, steps: int, mterms: list[Term],
             iterms: list[Term], d: int, plain: bool) -> tuple[PEPFrame, PEPStructure]:
    """The exact method and PEP over Q(sqrt d), in the basis the proof was made in
    (``plain``: no deadbeat gain, the basis :func:`sosalgo.worstcase.core.pep` falls back
    to when a free direction drifts)."""
    from sosalgo.worstcase.bind import bound_method, class_kappa
    from sosalgo.worstcase.exact import exact_method

    om, _ = bound_method(spec, class_kappa(spec, kappa))
    mt = exact_method(spec, kappa, om, steps, field=d)
    if plain:
        mt.K = np.full(mt.K.shape, Fraction(0), dtype=object)
        mt.structures.clear()
    st = build_structure(mt, steps, mterms, iterms)
    return mt, st
