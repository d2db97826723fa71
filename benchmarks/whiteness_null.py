"""How often the diagnosis's whiteness test calls white noise structured: the false alarm of the Ljung-Box test
(:func:`~estimators.diagnostics.residuals.correlation.ljung_box`, 50 lags as ``analyse_residuals`` uses them,
Bonferroni over the gyro's three axes) on Gaussian white noise as long as a 60 s log at 20, 50 and 100 Hz, next to
its nominal level, and the same for the chi-square approximation alone (the reference: the textbook test, which the
diagnosis used until its tail was simulated). A clean log whose residual is white noise is ``unexplained`` at this
rate (when no candidate is significant): the chi-square approximation is anti-conservative on short logs.

With ``--logs``: the same test's p-value per axis on the gyro noise the simulator drew for clean logs of the
variation matrix (the log less the same draw simulated with noise scaled by 1e-9, whose motion is the same): white
noise that the test may call structured, as on clean logs 9830, 9842, 9864 and 9874.

    python benchmarks/whiteness_null.py
    python benchmarks/whiteness_null.py --draws 20000 --alpha 0.005
    python benchmarks/whiteness_null.py --logs 9830,9842,9864,9874
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np
from scipy import stats

from estimators.diagnostics.residuals.correlation import ljung_box
from spaceid_gym.arrays import FloatArray
from spaceid_gym.variations import draw_variation, simulate_variation

#: the samples of a 60 s log at 20, 50 and 100 Hz
LOG_SAMPLES = (1201, 3001, 6001)

#: the lags of the diagnosis's Ljung-Box test (``analyse_residuals``' default)
LAGS = 50


def false_alarm(n_samples: int, draws: int, alpha: float, rng: np.random.Generator, chunk: int = 2000) -> tuple[float, float]:
    """The shares of ``draws`` white-noise logs (``n_samples`` x 3) failing Ljung-Box on some axis at ``alpha / 3``:
    with the test's p-value (simulated in the tail) and with the chi-square approximation's alone."""
    failed, failed_chi2 = 0, 0
    for start in range(0, draws, chunk):
        size = min(chunk, draws - start)
        q, p = ljung_box(rng.standard_normal((n_samples, 3 * size)), LAGS)
        failed += int(np.sum(np.any(p.reshape(size, 3) < alpha / 3, axis=1)))
        failed_chi2 += int(np.sum(np.any(stats.chi2.sf(q, LAGS).reshape(size, 3) < alpha / 3, axis=1)))
    return failed / draws, failed_chi2 / draws


def simulated_gyro_noise_p(seed: int, seconds: float = 60.0) -> tuple[str, FloatArray]:
    """The clean log ``seed``'s description and the Ljung-Box p-value (3,) of its gyro noise, per axis."""
    case = draw_variation("none", seed)
    log = simulate_variation(case, seconds).measurement_log()
    quiet = simulate_variation(dataclasses.replace(case, noise_scale=1e-9), seconds).measurement_log()
    noise = log.omega_base_body_rad_s - quiet.omega_base_body_rad_s
    return f"{case.robot}, {case.rate_hz} Hz, {case.attitude}, noise x{case.noise_scale:.2f}", ljung_box(noise, LAGS)[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--draws", type=int, default=6000, help="white-noise logs per length (default 6000)")
    parser.add_argument("--alpha", type=float, default=0.005, help="the test's level per log (the diagnosis's: 0.005)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--logs", default=None, help="comma-separated clean variation-matrix seeds: their gyro noise")
    args = parser.parse_args()
    if args.logs is not None:
        for seed in (int(s) for s in args.logs.split(",")):
            label, p = simulated_gyro_noise_p(seed)
            print(f"clean log {seed} ({label}): gyro noise's Ljung-Box p per axis " + " ".join(f"{v:.2g}" for v in p))
        return
    rng = np.random.default_rng(args.seed)
    print(f"Ljung-Box over {LAGS} lags, Bonferroni over 3 axes, nominal false alarm per log {args.alpha:.4f}:")
    for n_samples in LOG_SAMPLES:
        rate, rate_chi2 = false_alarm(n_samples, args.draws, args.alpha, rng)
        se, se_chi2 = (math.sqrt(r * (1.0 - r) / args.draws) for r in (rate, rate_chi2))
        print(
            f"  {n_samples:5d} samples: the test {rate:.4f} +- {se:.4f} ({rate / args.alpha:.2f} x nominal); "
            f"the chi-square approximation alone {rate_chi2:.4f} +- {se_chi2:.4f} ({rate_chi2 / args.alpha:.2f} x)"
        )


if __name__ == "__main__":
    main()
