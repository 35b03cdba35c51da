"""The interface between certificate families and the solvers that use them."""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from sosalgo.kernel.conic import ExactBlock, LMIProblem

if TYPE_CHECKING:  # only for annotations: families do not depend on the model at run time
    import sympy as sp

    from sosalgo.model import Algorithm
    from sosalgo.spec.types import Spec


__all__ = ["CertificateFamily", "check_matrix", "check_number", "complement_basis", "compress",
           "null_basis", "restricted_eigenvalues", "snap_basis"]


class CertificateFamily(Protocol):
    """A family of Lyapunov certificates for linear rates on F(m, L).

    Beside the LMI data (``problem``), a family says how it is shown and checked:

    - ``label``: its name in tables and figure legends;
    - ``is_default``: the family of specs without a ``certificate:`` field (its outputs carry
      no family suffix, its JSON rows no ``certificate`` object);
    - ``supports_moment``: the paper's moment relaxation (``design --method moment``) is
      built on its symbolic form;
    - ``certificate_parts``: the named parts a result must carry to claim a certificate;
    - ``parse_certificate``, ``exact_check`` and ``lyapunov``: how ``sosalgo verify`` reads,
      proves and simulates one of its certificates.

    The members after ``lyapunov`` have defaults (Theorem 1's behaviour): a family that
    subclasses this class explicitly inherits them. ``option_names`` and ``options()`` name
    its keyword options (e.g. the interpolation family's ``lag``): they go into output file
    names and run settings; ``csv_columns``/``csv_cells``/``cert_from_csv``/``p_size`` give
    its own CSV columns; ``summary`` the two eigenvalues of its results; ``auto_lags`` and
    ``guess_problem`` steer the rate search; ``listing`` its text for ``sosalgo lmi``
    (None: the entries of its main matrix); ``applies_to`` why it refuses a spec.
    """

    name: str
    description: str
    label: str
    is_default: bool
    supports_moment: bool
    certificate_parts: tuple[str, ...]
    option_names: tuple[str, ...] = ()
    # how the rate search treats it (analysis.py): ``tight`` starts the search at the rate
    # on quadratics; ``fallback_solvers`` replaces the solver chain where the margin path
    # cannot check a point (None: the default chain)
    tight: bool = False
    # design proves a lower bound over the whole parameter box (``exact_problem``)
    box_lower_bound: bool = False
    fallback_solvers: tuple[str, ...] | None = None

    def problem(self, alg: Algorithm) -> LMIProblem:
        """Assemble the feasibility data for a numeric algorithm."""
        ...

    def exact_problem(
        self, A: sp.Matrix, B: sp.Matrix, C: sp.Matrix, E: sp.Matrix, m: sp.Expr, L: sp.Expr
    ) -> list[ExactBlock] | None:
        """The data of :meth:`problem` in exact arithmetic (sympy; A..E may hold the design
        parameters), same variables and blocks; None when the family offers none (then
        design proves no lower bound for it)."""
        ...

    def symbolic(
        self, A: sp.Matrix, B: sp.Matrix, C: sp.Matrix, E: sp.Matrix, m: sp.Expr, L: sp.Expr
    ) -> tuple[sp.Matrix, dict[str, Any]]:
        """The main matrix inequality M ⪯ 0 in symbols, and the symbols it uses."""
        ...

    def matrix(self, alg: Algorithm, rho: float, cert: dict[str, Any]) -> np.ndarray:
        """The main matrix M at a numeric certificate (for reporting and checks)."""
        ...

    def parse_certificate(self, parts: Mapping[str, Any], n: int) -> dict[str, Any]:
        """The certificate named by ``parts`` (from a result row), its values checked;
        missing parts are None. Raises ValueError('<part>: what is wrong') when malformed."""
        ...

    def exact_check(self, spec: Spec, kappa: float, rho: float, cert: Mapping[str, Any],
                    theta: Mapping[str, float] | None = None) -> Any:
        """Proof in exact arithmetic that ``cert`` certifies ``rho`` (an object with
        ``verified``, ``rho_proven``, ``rho_proven_float``, ``delta``, ``reason`` and
        ``to_dict()``; see :mod:`sosalgo.proofs`)."""
        ...

    def lyapunov(self, cert: Mapping[str, Any]) -> dict[str, Any]:
        """The keyword arguments of :func:`sosalgo.proofs.simulate_check` that make it follow
        this certificate's Lyapunov function (``P`` and, when it has more, ``lyapunov``)."""
        ...

    # -- members with defaults -----------------------------------------------------------
    def options(self) -> dict[str, Any]:
        """The family's options and their values (None: the family's default)."""
        return {k: getattr(self, k, None) for k in self.option_names}

    def with_options(self, **options: Any) -> CertificateFamily:
        """A copy with ``options`` set; ValueError names an unknown or invalid one."""
        unknown = sorted(set(options) - set(self.option_names))
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown option of family {self.name}")
        if not options:
            return self
        fam = copy.copy(self)
        for k, v in options.items():
            setattr(fam, k, v)
        return fam

    def p_size(self, n: int) -> int:
        """Side of the certificate's matrix P (its CSV columns P11..): n by default."""
        return n

    def csv_columns(self, n: int) -> list[str]:
        """Its own CSV columns after the common ones (none by default)."""
        return []

    def csv_cells(self, n: int, cert: Mapping[str, Any] | None) -> dict[str, Any]:
        """The cells of :meth:`csv_columns` for a certificate (None: no certificate)."""
        return {}

    def cert_from_csv(self, n: int, row: Mapping[str, str], P: Any) -> dict[str, Any] | None:
        """The certificate of a CSV row (inverse of :meth:`csv_cells`): P and lambda by
        default (None when the row has no P)."""
        if P is None:
            return None
        lam = row.get("lambda") or None
        return {"P": P, "lambda": None if lam is None else float(lam)}

    def summary(self, alg: Algorithm, rho: float, cert: dict[str, Any]) -> dict[str, float]:
        """``max_eig_M`` (of :meth:`matrix`, <= 0) and ``min_eig_P`` (>= 0) at a certificate;
        NaN when they cannot be evaluated."""
        M = np.asarray(self.matrix(alg, rho, cert), dtype=float)
        P = np.asarray(cert["P"], dtype=float)
        if not (np.all(np.isfinite(M)) and np.all(np.isfinite(P))):
            return {"max_eig_M": math.nan, "min_eig_P": math.nan}
        return {"max_eig_M": float(np.linalg.eigvalsh(M)[-1]),
                "min_eig_P": float(np.linalg.eigvalsh(P)[0])}

    def auto_lags(self, n: int) -> tuple[int, ...]:
        """The members the analysis tries, best rate kept, when the user chose none (the
        interpolation family's lags); () by default: the family is used as it is."""
        return ()

    def searches_past_certified(self, alg: Algorithm) -> bool:
        """Whether the choice among :meth:`auto_lags` goes on for ``alg`` once a member
        certifies a rate (True by default: the best over the members is kept)."""
        return True

    def guess_problem(self, alg: Algorithm) -> LMIProblem | None:
        """A cheaper member whose rate tells the search where to look (never certifies);
        None by default."""
        return None

    def listing(self, spec: Spec, symbols: dict[str, Any], latex: bool) -> str | None:
        """Its own text for ``sosalgo lmi`` from the symbols of :meth:`symbolic`; None (the
        default) prints the entries of the main matrix."""
        return None

    def applies_to(self, spec: Spec) -> str | None:
        """Why the family cannot certify ``spec`` (one line for the user), None when it can
        (the default: every spec)."""
        return None


def check_number(value: Any, part: str, allow_none: bool = True) -> float | None:
    """``value`` as a float (None passes when allowed); ValueError naming ``part`` else."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{part}: expected a number, got {type(value).__name__}")
    return float(value)


def check_matrix(value: Any, n: int, part: str) -> list[list[float]] | None:
    """``value`` as an n x n list of lists of floats (None passes); ValueError else."""
    if value is None:
        return None
    if not (isinstance(value, list) and len(value) == n
            and all(isinstance(r, list) and len(r) == n for r in value)):
        raise ValueError(f"{part}: expected a {n}x{n} list of lists of numbers")
    return [[check_number(v, part, allow_none=False) for v in row] for row in value]


def null_basis(R: np.ndarray, rel: float = 1e-10) -> np.ndarray:
    """Orthonormal basis (columns) of the null space of the rows R (singular values below
    ``rel`` times the largest, or 1, count as 0)."""
    _, sv, vt = np.linalg.svd(R)
    top = max(1.0, float(sv[0])) if len(sv) else 1.0
    return vt[int(np.sum(sv > rel * top)):].T.copy()


def complement_basis(W: np.ndarray | None) -> np.ndarray | None:
    """Orthonormal basis of the orthogonal complement of the columns of W (None when W has
    none: the whole space)."""
    if W is None or W.shape[1] == 0:
        return None
    return null_basis(W.T)


def compress(Q: np.ndarray | None, *mats: np.ndarray) -> tuple[np.ndarray, ...]:
    """Q' M Q of every matrix (stacks of them too); the matrices themselves without Q."""
    if Q is None:
        return mats
    return tuple(Q.T @ M @ Q for M in mats)


def restricted_eigenvalues(M: np.ndarray, W: np.ndarray | None) -> np.ndarray:
    """Eigenvalues of the symmetric M on the complement of the directions W when M vanishes
    on them (to rounding), else of M itself. Directions where every matrix of a family's
    block vanishes carry a 0 eigenvalue for every certificate, rounded to either sign."""
    Q = complement_basis(W)
    if Q is not None:
        scale = max(float(np.abs(M).max(initial=0.0)), 1e-300)
        if float(np.abs(M @ W).max()) <= 1e-12 * scale:
            M = Q.T @ M @ Q
    return np.linalg.eigvalsh(M)


def snap_basis(K: np.ndarray, tol: float = 1e-3, max_den: int = 16) -> np.ndarray:
    """A basis of the span of K's columns in reduced echelon form with entries close to
    small-denominator fractions snapped to them (structural kernels are such spans; the
    eigenvectors found at a solver's point are only close to them)."""
    from fractions import Fraction

    import scipy.linalg as sla

    q = K.shape[1]
    if not q:
        return K
    _, _, piv = sla.qr(K.T, pivoting=True)
    E = K @ np.linalg.inv(K[piv[:q], :])
    snapped = np.vectorize(lambda v: float(Fraction(v).limit_denominator(max_den)))(E)
    return np.where(np.abs(snapped - E) <= tol, snapped, E)
