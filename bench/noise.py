"""Certified noise sensitivity (sosalgo.sensitivity): time per certified bound (one SDP and
its floating-point check) at lags 0, 1, 2, the lag chosen by ``analyze --noise``, the
exact proof, and the quadratic value; then the bounds of four methods at kappa = 10, 100.
"""

from __future__ import annotations

from pathlib import Path

from bench.common import timed
from sosalgo.model import bind
from sosalgo.sensitivity.exact import verify_noise
from sosalgo.sensitivity.quadratic import noise_quadratic
from sosalgo.sensitivity.run import best_noise_certificate
from sosalgo.sensitivity.sdp import noise_certificate
from sosalgo.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"
METHODS = ("gradient", "nesterov", "heavy-ball", "triple-momentum")


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.1f}"


def timings(repeats: int) -> None:
    """Median (min) milliseconds per call on Nesterov's method at kappa = 10."""
    spec = load_spec(SPECS / "nesterov.yaml")
    alg = bind(spec, 10.0)
    noise_certificate(alg, 1)  # imports and first solver call out of the timings
    rows = [(f"certified bound, lag {lag}", lambda lag=lag: noise_certificate(alg, lag))
            for lag in (0, 1, 2)]
    rows.append(("certified bound, lag chosen (0 .. n + 1)",
                 lambda: best_noise_certificate(alg, None, noise_quadratic(alg).gamma)))
    cert = noise_certificate(alg, 1)
    verify_noise(spec, 10.0, cert.certificate)
    rows.append(("exact proof of the lag-1 bound",
                 lambda: verify_noise(spec, 10.0, cert.certificate)))
    rows.append(("quadratic value (grid + refinement)", lambda: noise_quadratic(alg)))
    print("| Nesterov, kappa = 10 | median ms | min ms |\n|---|---|---|")
    for label, fn in rows:
        med, _, low = timed(fn, repeats)
        print(f"| {label} | {_ms(med)} | {_ms(low)} |", flush=True)


def bounds() -> None:
    """Certified (lag chosen) against quadratic sensitivity."""
    print("\n| method | kappa | certified gamma | lag | quadratic gamma | ratio |\n"
          "|---|---|---|---|---|---|")
    for name in METHODS:
        for kappa in (10.0, 100.0):
            alg = bind(load_spec(SPECS / f"{name}.yaml"), kappa)
            quad = noise_quadratic(alg).gamma
            cert = best_noise_certificate(alg, None, quad)
            got = "none" if cert.gamma is None else f"{cert.gamma:.6f}"
            ratio = "" if cert.gamma is None else f"{cert.gamma / quad:.4f}"
            lag = cert.lag if cert.gamma is not None else ""
            print(f"| {name} | {kappa:g} | {got} | {lag} | {quad:.6f} | {ratio} |", flush=True)


def run(quick: bool = False) -> None:
    timings(5 if quick else 30)
    bounds()


if __name__ == "__main__":
    run()
