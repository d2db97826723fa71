"""How well the model fits and how large the noise is: fit percent and the data-only noise floor."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from estimators.diagnostics.residuals._checks import _columns
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: 1 / Phi^-1(3/4): turns a median absolute deviation of Gaussian data into a standard deviation
_MAD_TO_STD = 1.0 / float(stats.norm.ppf(0.75))

#: T x relative variance of :func:`noise_floor_std` on Gaussian white noise, per difference order.
#: Measured by Monte Carlo (2e7 samples per T for T = 200, 1000, 3000, 10000: 1.64-1.68 and
#: 1.90-2.02); checked by ``tests/test_residual_analysis.py``. The iid-sample MAD has 1.36.
_NOISE_FLOOR_RELATIVE_VARIANCE = {1: 1.63, 2: 1.97}


def fit_percent(measured: ArrayLike, predicted: ArrayLike) -> FloatArray:
    """Fit in percent per channel: ``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` (2-norms over time).

    100 for a perfect prediction, 0 for predicting the mean, negative when worse than the mean.
    A constant measured channel (zero denominator) gives ``nan``.

    Args:
        measured: y, (T, C) or (T,), any unit.
        predicted: yhat, same shape and unit.

    Returns:
        (C,) fit in percent ((1,) for one-dimensional input).
    """
    y, _ = _columns(measured, "fit_percent: measured")
    yhat, _ = _columns(predicted, "fit_percent: predicted")
    if yhat.shape != y.shape:
        raise SpaceIdInputError(f"fit_percent: predicted must have the shape of measured {y.shape}, got {yhat.shape}")
    error = np.linalg.norm(y - yhat, axis=0)
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spread > 0.0, 100.0 * (1.0 - error / np.where(spread > 0.0, spread, 1.0)), np.nan)


def noise_floor_std(residual: ArrayLike, order: int = 2) -> FloatArray:
    """Data-only estimate of the white-noise standard deviation, robust to smooth structure.

    ``sigma = MAD(d) / (Phi^-1(3/4) sqrt(binom(2k, k)))`` with ``d`` the k-th differences of the
    residual (``order`` = k; binom = 2 for k = 1, 6 for k = 2: the variance of the k-th difference
    of white noise) and MAD the median absolute deviation from the median. If more than half of the
    differences are equal (quantised data, MAD = 0), it falls back to their RMS.

    Bias: a structure ``s(t)`` with power spectrum ``S(f)`` adds
    ``(1 / binom(2k, k)) * integral (2 sin(pi f dt))^(2k) S(f) df`` to the estimated variance
    (exactly for the RMS form, approximately for the MAD). A smooth structure is suppressed by
    ``(2 pi f dt)^(2k)``: a sinusoid of amplitude A at f << 1/dt adds ``A^2 (2 pi f dt)^4 / 12`` for
    k = 2 (at 0.1 Hz and 50 Hz: 1e-5 A^2). Structure *not* smooth at the sample rate (steps, spikes
    in many samples, oscillations near the Nyquist frequency) biases it up; noise that is not
    white (e.g. low-pass filtered by the sensor) biases it down, since the differences only see
    its high-frequency part. On white Gaussian noise its relative standard deviation is
    ``sqrt(1.97 / T)`` for k = 2 (2.6 % at T = 3000), see :func:`noise_floor_dof`.

    Args:
        residual: (T, C) or (T,), any unit; T > order.
        order: difference order k, 1 or 2 (default 2: also ignores linear drifts).

    Returns:
        (C,) noise standard deviation per channel, unit of ``residual``.
    """
    if order not in _NOISE_FLOOR_RELATIVE_VARIANCE:
        raise SpaceIdInputError(f"noise_floor_std: order must be 1 or 2, got {order!r}")
    r, _ = _columns(residual, "noise_floor_std: residual", min_rows=order + 1)
    d = np.diff(r, n=order, axis=0)
    scale = math.sqrt(math.comb(2 * order, order))
    mad = stats.median_abs_deviation(d, axis=0)  # median |d - median(d)|, unscaled
    rms = np.sqrt(np.mean(d**2, axis=0))
    return np.where(mad > 0.0, mad * _MAD_TO_STD, rms) / scale


def noise_floor_dof(n_samples: int, order: int = 2) -> float:
    """Effective degrees of freedom ``nu`` of the variance estimate ``noise_floor_std(...)**2``.

    On white Gaussian noise ``sigma_hat^2 / sigma^2`` behaves like ``chi2(nu) / nu`` with
    ``nu = (T - k) / (2 kappa)``, kappa the measured ``T * var(sigma_hat / sigma)`` (1.97 for k = 2,
    1.63 for k = 1; a known sigma has ``nu = inf``). Used to test windows against an estimated
    noise level with an F distribution instead of chi2.
    """
    if order not in _NOISE_FLOOR_RELATIVE_VARIANCE:
        raise SpaceIdInputError(f"noise_floor_dof: order must be 1 or 2, got {order!r}")
    return max(n_samples - order, 1) / (2.0 * _NOISE_FLOOR_RELATIVE_VARIANCE[order])
