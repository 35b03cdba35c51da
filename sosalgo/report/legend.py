"""What the printed numbers mean: one name for each kind of bound, and the lines that say
what a certified rate or constant bounds (in the spec's own measure).

The names, used by every command's printed output and by the docs:

- **certified rate** (``rho``): proven, the worst-case rate over the class is at most it;
- **witnessed lower bound** (``rho_lower``): reached by an explicit function of the class
  (a quadratic or a self-similar trajectory), so the worst-case rate is at least it;
- **reference: NAME**: a closed form the spec lists for comparison (``references:``),
  computed in floating point, neither proven nor assumed by sosalgo;
- **proven lower bound** (``design``'s ``lower_bound``): no parameter value in the box is
  certified below it (a bound on the design problem, not on one method).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sosalgo.spec import Spec

__all__ = ["CERTIFIED", "PROVEN_LOWER", "REFERENCE", "TABLE1_LEGEND", "VERIFY_LEGEND", "WITNESSED",
           "measure_words", "noise_legend", "rate_legend", "rate_meaning", "reference_header",
           "set_lines", "sublinear_meaning"]

CERTIFIED = "certified rate"
WITNESSED = "witnessed lower bound"
REFERENCE = "reference"
PROVEN_LOWER = "proven lower bound"
VERIFY_LEGEND = ("verified: how the certificate was re-proven (rational or outward-rounded "
                 "arithmetic);\nrho_proven: the rate that proof establishes; simulation: the "
                 "method run on test functions\nof the class (evidence, not a proof)")
TABLE1_LEGEND = (f"rho_certified: {CERTIFIED}; closed_form_rate: {REFERENCE}, the spec's first "
                 "closed form (floating point; not proven by sosalgo)")


def set_lines(doc: Mapping[str, Any]) -> list[str]:
    """One line naming the ``--set`` overrides a result was computed with (none without)."""
    given = doc.get("set") or {}
    return ["with --set " + ", ".join(f"{k}={v}" for k, v in given.items())] if given else []


def reference_header(name: str) -> str:
    """The printed header of a spec's reference column."""
    return f"{REFERENCE}: {name}"


def measure_words(spec: Spec, point: str = "x_k") -> str:
    """The spec's measure at ``point``: f(x_k) - f*, sum_j f_j(x_k) - f_j*, |x_k - x*|^2."""
    if spec.measure == "distance":
        return f"|{point} - x*|^2"
    if len(spec.functions) > 1:
        return f"sum_j f_j({point}) - f_j*"
    return f"f({point}) - f*"


def _output_words(spec: Spec) -> str:
    if spec.output is None:
        return "x_k = E xi_k"
    return f"x_k = y{spec.output + 1}_k, the point of call {spec.output + 1}"


def rate_meaning(spec: Spec, family: str | None, lags: Sequence[Any] = (),
                 named: bool = False) -> list[str]:
    """Two lines: what the certified rate rho bounds for this spec and family (``named``:
    the family is named, when several are shown)."""
    measure = measure_words(spec)
    lag = max((int(x) for x in lags if isinstance(x, int | float)), default=0)
    tag = f" ({family})" if named and family else ""
    if family in (None, "theorem1"):
        bound = f"{measure} <= rho^(2k) V_0 for every k >= 0"
        start = "V_0 = f(x_0) - f* + (xi_0 - xi*)'P(xi_0 - xi*), P the certificate's"
    elif lag == 0:
        bound = f"{measure} <= rho^(2k) V_0 for every k >= 0"
        start = "V_0: the certificate's Lyapunov function at the start"
    else:
        bound = f"{measure} <= rho^(2(k-l)) V_l for every k >= l"
        start = (f"l: the certificate's lag (up to {lag}), V_l: its Lyapunov function at "
                 "step l")
    return [f"rho bounds{tag}: {bound}, {_output_words(spec)}",
            f"  {start}"]


def sublinear_meaning(spec: Spec) -> str:
    """One line: what a sublinear spec's certified constant c bounds (m: 0)."""
    from sosalgo.certificates.composite import sublinear_measure

    if sublinear_measure(spec) == "state_change":
        return ("c bounds: |xi_k+1 - xi_k|^2 <= c |xi_0 - xi*|^2 / k for every k >= 1 (xi: "
                "the state, e.g. Douglas-Rachford's w; xi* a fixed point, moving with the "
                "operators' answers at the solution), from any start xi_0")
    if sublinear_measure(spec) == "residual":
        calls = " + ".join(f"|u{i + 1}_k|^2" for i in range(spec.p))
        return (f"c bounds: {calls} <= c |x_0 - x*|^2 / k for every k >= 1 (u_k: the answer "
                "of the call at step k, e.g. x_k - T x_k), the method started at rest at x_0")
    return (f"c bounds: {measure_words(spec)} <= c |x_0 - x*|^2 / k for every k >= 1, the "
            f"method started at rest at x_0; {_output_words(spec)}")


def rate_legend(rows: Sequence[Mapping[str, Any]], references: Sequence[str]) -> list[str]:
    """The legend of a rate table: the certified rate, the bracket (when some row has a
    witnessed lower bound) and the spec's references (when it lists some)."""
    out = [f"rho: {CERTIFIED}, a proven upper bound on the worst-case rate over the class",
           "  (the squared quantities above shrink by rho^2 per step: compare a PEPit tau(N) "
           "with rho^(2N))"]
    if any(r.get("rho_lower") is not None for r in rows):
        out.append(f"worst-case rate in [a, b]: a = {WITNESSED} (reached by a function), "
                   f"b = {CERTIFIED}")
    if references:
        out.append(f"{REFERENCE}: NAME = the spec's closed form for comparison (floating "
                   "point; not proven by sosalgo)")
    return out


def noise_legend(details: bool) -> list[str]:
    """The legend of the noise table (``analyze --noise``)."""
    out = ["noise: certified bound on the sensitivity sqrt(avg_k E|x_k - x*|^2 / d) / sigma "
           "over the class,",
           "  gradients u_k = grad f(y_k) + w_k, w_k zero-mean, covariance sigma^2 I, "
           "independent of the past",
           "noise_quadratic: the sensitivity on quadratics (floating point; the worst case "
           "is at least it)",
           "noise_limsup: certified bound on sqrt(limsup_k E|x_k - x*|^2 / d) / sigma"]
    if details:
        out += ["noise_lag: the lag of noise's certificate; noise_check: how it was checked; "
                "noise_limsup_rho: rate of noise_limsup's certificate"]
    return out
