"""Residual analysis: is the model's error noise, and if not, what is its structure?

Pure functions of arrays (numpy/scipy, vectorised), independent of the robot and of the measured
quantity: a *channel* is any measured signal the model predicts (the base angular rate
``omega_base_body`` wx, wy, wz in rad/s for the free-floating robot; joint torques in N m for a
fixed-base arm), so every function takes C channels. Time ``t_s`` is in s; joint angles ``q`` in
rad, rates ``dq`` in rad/s (revolute joints), ``T`` samples, ``n`` joints.

The standard tests that tell a structured error from noise (Ljung, *System Identification*, 2nd
ed. 1999, sec. 16.6; Box, Jenkins & Reinsel, *Time Series Analysis*, ch. 8 and 11):

* :func:`fit_percent`: ``100 (1 - |y - yhat| / |y - mean y|)`` per channel (2-norms), the "fit"
  figure system-identification tools report;
* :func:`noise_floor_std`: a data-only estimate of the white-noise standard deviation that ignores
  smooth structure (median absolute deviation of differences);
* :func:`autocorrelation` with the band :func:`white_noise_band` and the portmanteau test
  :func:`ljung_box` (whiteness);
* :func:`cross_correlation` with the inputs (joint rates and accelerations) and a per-input test;
* :func:`dominant_frequencies`: significant spectral lines of the residual;
* :func:`failing_segments`: the time windows where the residual exceeds the noise, with what the
  arm was doing there;
* :func:`analyse_residuals`: all of it in one :class:`ResidualAnalysis`.

Multiple testing: every "significant" below is at ``alpha = 1 - confidence`` *family-wise*
(Bonferroni or Holm over the lags, windows, inputs and channels that make up one question), so a
residual of pure noise is declared structured with probability at most ``alpha``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import fft as sp_fft
from scipy import optimize, signal, stats

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import jsonable

#: 1 / Phi^-1(3/4): turns a median absolute deviation of Gaussian data into a standard deviation
_MAD_TO_STD = 1.0 / float(stats.norm.ppf(0.75))

#: T x relative variance of :func:`noise_floor_std` on Gaussian white noise, per difference order.
#: Measured by Monte Carlo (2e7 samples per T for T = 200, 1000, 3000, 10000: 1.64-1.68 and
#: 1.90-2.02); checked by ``tests/test_residual_analysis.py``. The iid-sample MAD has 1.36.
_NOISE_FLOOR_RELATIVE_VARIANCE = {1: 1.63, 2: 1.97}

#: a joint "moves" in a segment if its largest |dq| there exceeds this (rad/s): 0.57 deg/s, far
#: above joint-rate sensor noise (1e-4 rad/s) and far below commanded excitation rates (0.1-1 rad/s)
MOVING_THRESHOLD_RAD_S = 0.01


# --------------------------------------------------------------------------------------------- checks


def _array(x: ArrayLike, name: str, ndim: tuple[int, ...], min_rows: int = 1) -> FloatArray:
    """``x`` as a finite float array with one of the allowed dimensions and at least ``min_rows`` rows."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim not in ndim:
        raise SpaceIdInputError(f"{name}: expected an array with {' or '.join(map(str, ndim))} dimensions, got shape {a.shape}")
    if a.shape[0] < min_rows:
        raise SpaceIdInputError(f"{name}: expected at least {min_rows} samples (rows), got {a.shape[0]}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise SpaceIdInputError(f"{name}: expected finite values, got {a[tuple(bad)]} at index {tuple(int(i) for i in bad)}")
    return a


def _columns(x: ArrayLike, name: str, min_rows: int = 1) -> tuple[FloatArray, bool]:
    """``x`` (T,) or (T, C) as (T, C), and whether it was one-dimensional."""
    a = _array(x, name, (1, 2), min_rows)
    return (a[:, None], True) if a.ndim == 1 else (a, False)


def _check_lag(max_lag: int, n_samples: int, name: str) -> int:
    if not isinstance(max_lag, (int, np.integer)) or isinstance(max_lag, bool) or not 1 <= max_lag < n_samples:
        raise SpaceIdInputError(f"{name}: expected an integer 1 <= max_lag < T = {n_samples}, got {max_lag!r}")
    return int(max_lag)


def _check_probability(value: float, name: str) -> float:
    if not 0.0 < value < 1.0:
        raise SpaceIdInputError(f"{name}: expected a probability strictly between 0 and 1, got {value!r}")
    return float(value)


def _check_same_rows(n_samples: int, **arrays: FloatArray) -> None:
    for name, a in arrays.items():
        if a.shape[0] != n_samples:
            raise SpaceIdInputError(f"{name}: expected {n_samples} samples (rows, one per time step), got shape {a.shape}")


# ------------------------------------------------------------------------------------- fit and noise


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


# ----------------------------------------------------------------------------------- correlations


def white_noise_band(n_samples: int, alpha: float = 0.01) -> float:
    """Half-width ``z_{1-alpha/2} / sqrt(T)`` of the pointwise confidence band of a sample
    auto- or cross-correlation of white noise (two-sided, level ``alpha``)."""
    _check_probability(alpha, "white_noise_band: alpha")
    return float(stats.norm.isf(alpha / 2.0) / math.sqrt(n_samples))


def _centred_spectrum(x: FloatArray, n_fft: int) -> tuple[FloatArray, NDArray[np.complex128]]:
    """Population std (C,) of the columns of ``x`` (T, C) and the real FFT of the centred columns."""
    centred = x - x.mean(axis=0)
    return np.sqrt(np.mean(centred**2, axis=0)), sp_fft.rfft(centred, n=n_fft, axis=0)


def _autocorrelation_columns(x: FloatArray, max_lag: int) -> FloatArray:
    """Sample autocorrelation (L+1, C) of the columns of ``x`` (T, C); a constant column gives 1, 0, 0, ..."""
    n_samples = x.shape[0]
    n_fft = sp_fft.next_fast_len(n_samples + max_lag, real=True)
    std, spectrum = _centred_spectrum(x, n_fft)
    acov = sp_fft.irfft(np.abs(spectrum) ** 2, n=n_fft, axis=0)[: max_lag + 1] / n_samples
    variance = std**2
    out = np.zeros_like(acov)
    out[0] = 1.0
    nonzero = variance > 0.0
    out[:, nonzero] = acov[:, nonzero] / variance[nonzero]
    return out


def autocorrelation(x: ArrayLike, max_lag: int) -> FloatArray:
    """Sample autocorrelation ``r_k = sum_t (x_t - m)(x_{t+k} - m) / sum_t (x_t - m)^2``, k = 0..L.

    The biased (1/T) estimator, so ``|r_k| <= 1``; for white noise ``r_k`` (k >= 1) is approximately
    N(0, 1/T): compare it with :func:`white_noise_band`. A constant signal gives 1, 0, 0, ...

    Args:
        x: (T,) or (T, C).
        max_lag: L, 1 <= L < T.

    Returns:
        (L+1,) for (T,) input, (L+1, C) for (T, C).
    """
    a, one_d = _columns(x, "autocorrelation: x", min_rows=2)
    acf = _autocorrelation_columns(a, _check_lag(max_lag, a.shape[0], "autocorrelation: max_lag"))
    return acf[:, 0] if one_d else acf


def _ljung_box_from_acf(acf: FloatArray, n_samples: int) -> tuple[FloatArray, FloatArray]:
    lags = acf.shape[0] - 1
    k = np.arange(1, lags + 1)
    q = n_samples * (n_samples + 2.0) * np.sum(acf[1:] ** 2 / (n_samples - k)[:, None], axis=0)
    return q, stats.chi2.sf(q, lags)


def ljung_box(x: ArrayLike, lags: int) -> tuple[Any, Any]:
    """Ljung-Box portmanteau test of whiteness: ``Q = T (T+2) sum_{k=1}^{h} r_k^2 / (T-k)``.

    Under "x is white noise" Q ~ chi2(h) (h = ``lags``; no degrees of freedom are removed for fitted
    model parameters: a physical model with a few parameters fitted to T >> h samples barely changes
    the distribution). A small p-value says the residual has autocorrelation: structure.

    Args:
        x: (T,) or (T, C).
        lags: h, 1 <= h < T.

    Returns:
        (Q, p_value): floats for (T,) input, (C,) arrays for (T, C).
    """
    a, one_d = _columns(x, "ljung_box: x", min_rows=2)
    acf = _autocorrelation_columns(a, _check_lag(lags, a.shape[0], "ljung_box: lags"))
    q, p = _ljung_box_from_acf(acf, a.shape[0])
    return (float(q[0]), float(p[0])) if one_d else (q, p)


@dataclass
class CrossCorrelation:
    """Cross-correlation of one residual channel with m inputs and a test per input.

    Sign convention: ``ccf[j, L + k] = sum_t (r_{t+k} - mean r)(u_{j,t} - mean u_j) / (T std(r) std(u_j))``,
    i.e. at a positive lag k the residual *follows* the input by k samples (a causal effect of the
    input shows at k >= 0). Biased (1/T) estimator, ``|ccf| <= 1``.

    The test of input j: under "the residual is white noise independent of the input" every
    ``sqrt(T) ccf[j, k]`` is N(0, 1) whatever the input's own autocorrelation (it holds conditionally
    on a deterministic input); ``statistic[j] = sqrt(T / variance_factor[j]) max_k |ccf[j, k]|`` and
    ``p_value[j] = min(1, (2L+1) 2 Phi(-statistic))`` (Bonferroni over the 2L+1 lags, valid although
    neighbouring lags are correlated). ``variance_factor`` is Bartlett's correction for a residual that
    is itself autocorrelated, ``1 + 2 sum_{k=1}^{L} (1 - k/(L+1)) rho_r(k) rho_u(k)`` (at least 1),
    which keeps a structured residual from correlating "significantly" with every smooth input
    (Ljung 1999, sec. 16.6). It only sees autocorrelation up to lag L: a residual drifting more slowly
    than that can still correlate spuriously with slow inputs, so the ranking describes, it does not
    prove a cause. An input with zero variance has ccf 0 and p 1.

    Attributes:
        lags: (2L+1,) lag in samples, -L..L.
        ccf: (m, 2L+1).
        band: white-noise pointwise band ``z_{1-alpha/2} / sqrt(T)``.
        variance_factor, statistic, p_value: (m,).
        peak_ccf: (m,) the ccf value (signed) of largest magnitude; ``peak_lag``: (m,) its lag in samples.
    """

    lags: NDArray[np.int64]
    ccf: FloatArray
    band: float
    variance_factor: FloatArray
    statistic: FloatArray
    p_value: FloatArray
    peak_ccf: FloatArray
    peak_lag: NDArray[np.int64]


def _cross_correlation_columns(residual: FloatArray, inputs: FloatArray, max_lag: int, alpha: float) -> list[CrossCorrelation]:
    """:class:`CrossCorrelation` of every residual column (T, C) with the inputs (T, m), via one FFT product."""
    n_samples = residual.shape[0]
    n_fft = sp_fft.next_fast_len(n_samples + max_lag, real=True)
    std_r, spec_r = _centred_spectrum(residual, n_fft)
    std_u, spec_u = _centred_spectrum(inputs, n_fft)
    # cross[s, c, j] = sum_t r_c(t + s) u_j(t) for s = 0..L at index s and s = -L..-1 at n_fft + s
    cross = sp_fft.irfft(spec_r[:, :, None] * np.conj(spec_u)[:, None, :], n=n_fft, axis=0)
    lags = np.arange(-max_lag, max_lag + 1)
    denominator = n_samples * std_r[:, None] * std_u[None, :]
    valid = denominator > 0.0
    ccf = np.where(valid, cross[lags % n_fft] / np.where(valid, denominator, 1.0), 0.0)  # (2L+1, C, m)
    ccf = np.moveaxis(ccf, 0, -1)  # (C, m, 2L+1)
    acf_r = _autocorrelation_columns(residual, max_lag)[1:]  # (L, C)
    acf_u = _autocorrelation_columns(inputs, max_lag)[1:]  # (L, m)
    taper = 1.0 - np.arange(1, max_lag + 1) / (max_lag + 1.0)
    factor = np.maximum(1.0, 1.0 + 2.0 * np.einsum("k,kc,km->cm", taper, acf_r, acf_u))
    peak_index = np.argmax(np.abs(ccf), axis=-1)
    peak = np.take_along_axis(ccf, peak_index[..., None], axis=-1)[..., 0]
    statistic = np.abs(peak) * np.sqrt(n_samples / factor)
    p_value = np.where(valid, np.minimum(1.0, (2 * max_lag + 1) * 2.0 * stats.norm.sf(statistic)), 1.0)
    band = white_noise_band(n_samples, alpha)
    return [
        CrossCorrelation(lags, ccf[c], band, factor[c], statistic[c], p_value[c], peak[c], lags[peak_index[c]])
        for c in range(residual.shape[1])
    ]


def cross_correlation(residual: ArrayLike, inputs: ArrayLike, max_lag: int, alpha: float = 0.01) -> CrossCorrelation:
    """Normalised cross-correlation of a residual with m inputs at lags -L..L, with a test per input.

    See :class:`CrossCorrelation` for the sign convention, the band and the test.

    Args:
        residual: (T,) one channel.
        inputs: (T, m) or (T,), e.g. joint rates dq (rad/s) and accelerations ddq (rad/s^2).
        max_lag: L, 1 <= L < T.
        alpha: level of the band (two-sided, pointwise).
    """
    r = _array(residual, "cross_correlation: residual", (1,), min_rows=2)
    u, _ = _columns(inputs, "cross_correlation: inputs", min_rows=2)
    _check_same_rows(r.shape[0], **{"cross_correlation: inputs": u})
    _check_probability(alpha, "cross_correlation: alpha")
    return _cross_correlation_columns(r[:, None], u, _check_lag(max_lag, r.shape[0], "cross_correlation: max_lag"), alpha)[0]


# ------------------------------------------------------------------------------------------ spectrum


class SpectralPeak(NamedTuple):
    """A significant spectral line: frequency (Hz), amplitude of the fitted sinusoid (unit of the
    signal) and p-value against white noise (Bonferroni over the periodogram ordinates)."""

    frequency_hz: float
    amplitude: float
    p_value: float


def _hann_power(y: FloatArray) -> FloatArray:
    """``|rfft(w y)|^2 / sum(w^2)`` with a periodic Hann window w along axis 0: each ordinate of white
    noise of variance sigma^2 has mean sigma^2 (exponentially distributed), away from 0 and Nyquist."""
    window = signal.windows.hann(y.shape[0], sym=False)
    shaped = window if y.ndim == 1 else window[:, None]
    return np.abs(sp_fft.rfft(shaped * y, axis=0)) ** 2 / np.sum(window**2)


def periodogram(x: ArrayLike, dt_s: float) -> tuple[FloatArray, FloatArray]:
    """One-sided Hann-windowed periodogram of the centred columns of ``x``.

    Args:
        x: (T,) or (T, C), unit u.
        dt_s: sample period, s.

    Returns:
        ``frequency_hz`` (T//2 + 1,) and the power spectral density (T//2 + 1,) or (T//2 + 1, C) in
        u^2/Hz; white noise of std sigma has the level ``2 sigma^2 dt_s`` (away from 0 and Nyquist).
    """
    a = _array(x, "periodogram: x", (1, 2), min_rows=4)
    if not dt_s > 0.0:
        raise SpaceIdInputError(f"periodogram: dt_s must be > 0 s, got {dt_s!r}")
    return sp_fft.rfftfreq(a.shape[0], dt_s), 2.0 * dt_s * _hann_power(a - a.mean(axis=0))


def white_spectrum_level(power: ArrayLike, n_samples: int, alpha: float = 0.01) -> tuple[FloatArray, FloatArray]:
    """White-noise level of a periodogram and the height a spectral line must exceed to be significant.

    ``level = median(power_k) / ln 2`` over the ordinates k = 1..(T-1)//2 (0 and Nyquist excluded; for
    white noise every ordinate is ``level * Exp(1)``, whose median is ``level ln 2``) and
    ``threshold = level ln(M / alpha)`` with M those ordinates: the Bonferroni level-alpha bound of
    :func:`dominant_frequencies`.

    Args:
        power: (T//2 + 1,) or (T//2 + 1, C), e.g. from :func:`periodogram` (any scale).
        n_samples: T, the length of the series the periodogram came from.
        alpha: family-wise false-alarm probability.

    Returns:
        (level, threshold), each () or (C,), unit of ``power``.
    """
    p = _array(power, "white_spectrum_level: power", (1, 2), min_rows=3)
    if p.shape[0] != n_samples // 2 + 1:
        raise SpaceIdInputError(
            f"white_spectrum_level: power must have T//2 + 1 = {n_samples // 2 + 1} rows for T = {n_samples}, got {p.shape[0]}"
        )
    _check_probability(alpha, "white_spectrum_level: alpha")
    n_ordinates = (n_samples - 1) // 2
    level = np.median(p[1 : n_ordinates + 1], axis=0) / math.log(2.0)
    return level, level * math.log(n_ordinates / alpha)


def _refine_frequency(y: FloatArray, t_index: FloatArray, bin_guess: float) -> float:
    """Frequency (cycles per sample) within one bin of ``bin_guess`` maximising the periodogram of ``y``."""
    n_samples = y.shape[0]

    def negative_power(cycles_per_sample: float) -> float:
        return -float(np.abs(np.exp(-2j * np.pi * cycles_per_sample * t_index) @ y) ** 2)

    low, high = (max(bin_guess - 1.0, 0.25) / n_samples, min(bin_guess + 1.0, n_samples / 2 - 0.25) / n_samples)
    return float(
        optimize.minimize_scalar(negative_power, bounds=(low, high), method="bounded", options={"xatol": 1e-6 / n_samples}).x
    )


def dominant_frequencies(x: ArrayLike, dt_s: float, n: int = 3, alpha: float = 0.01) -> list[SpectralPeak]:
    """The strongest spectral lines of ``x`` that are significant against a white-noise spectrum.

    Iterative "find, fit, subtract": the Hann-windowed periodogram ``I_k`` of the current signal is
    compared with the white-noise level ``S0 = median(I) / ln 2`` (for white Gaussian noise every
    ordinate is ``S0 Exp(1)``, whose median is ``S0 ln 2``; the median ignores a few lines). The
    highest local maximum has p-value ``min(1, M exp(-I_max / S0))`` (Bonferroni over the M
    ordinates between 0 and the Nyquist frequency, both excluded); if below ``alpha`` its frequency
    is refined to the maximum of the (unwindowed) periodogram within one bin, a sinusoid (plus a
    constant) is fitted there by least squares and subtracted, and the search repeats. Subtracting
    the fitted line removes its leakage, so side lobes of a strong line are not reported.
    A broadband (e.g. low-pass) residual yields its strongest bins as "lines".

    Args:
        x: (T,) signal, e.g. one residual channel; T >= 16.
        dt_s: sample period, s (> 0).
        n: largest number of lines returned.
        alpha: family-wise false-alarm probability for white noise.

    Returns:
        Up to ``n`` :class:`SpectralPeak` (frequency_hz, amplitude, p_value), largest amplitude first;
        empty for white noise (with probability about 1 - alpha).
    """
    y = _array(x, "dominant_frequencies: x", (1,), min_rows=16)
    if not dt_s > 0.0:
        raise SpaceIdInputError(f"dominant_frequencies: dt_s must be > 0 s, got {dt_s!r}")
    if n < 0:
        raise SpaceIdInputError(f"dominant_frequencies: n must be >= 0, got {n!r}")
    _check_probability(alpha, "dominant_frequencies: alpha")
    n_samples = y.shape[0]
    t_index = np.arange(n_samples, dtype=np.float64)
    ordinates = np.arange(1, (n_samples - 1) // 2 + 1)  # excludes 0 and the Nyquist frequency
    y = y - y.mean()
    peaks: list[SpectralPeak] = []
    for _ in range(n):
        power = np.append(_hann_power(y), 0.0)  # padded for odd T
        inner = power[ordinates]
        level = float(white_spectrum_level(power[:-1], n_samples, alpha)[0])
        is_peak = (inner >= power[ordinates - 1]) & (inner >= power[ordinates + 1])
        if not level > 0.0 or not is_peak.any():
            break
        k = int(ordinates[is_peak][np.argmax(inner[is_peak])])
        p_value = min(1.0, ordinates.size * math.exp(-power[k] / level))
        if p_value >= alpha:
            break
        cycles = _refine_frequency(y, t_index, float(k))
        design = np.column_stack([np.cos(2 * np.pi * cycles * t_index), np.sin(2 * np.pi * cycles * t_index), np.ones(n_samples)])
        coefficients = np.linalg.lstsq(design, y, rcond=None)[0]
        y = y - design @ coefficients
        peaks.append(SpectralPeak(cycles / dt_s, float(np.hypot(coefficients[0], coefficients[1])), p_value))
    return sorted(peaks, key=lambda peak: -peak.amplitude)


# ------------------------------------------------------------------------------------------ segments


@dataclass
class Segment:
    """A time segment where the residual exceeds the noise, and what the arm did there.

    Attributes:
        t_start_s, t_end_s: the segment's window edges (s).
        n_samples: samples in it.
        rms_over_noise: ``sqrt(mean over samples and channels of (r / sigma)^2)``; 1 for noise.
        channel_rms_over_noise: (C,) the same per channel.
        statistic: ``sum (r / sigma)^2`` over the segment.
        p_value: smallest Holm-adjusted p-value of its windows (family-wise over all windows).
        joint_names: (n,) names, ``q1``..``qn`` by default.
        moving_joints: names of the joints whose max |dq| exceeds ``moving_threshold_rad_s``, fastest first.
        max_abs_dq_rad_s: (n,) largest |dq| per joint, rad/s.
        rms_ddq_rad_s2: (n,) RMS joint acceleration per joint (dq differentiated), rad/s^2.
        q_span_rad: (n,) range of motion (max - min of q) per joint, rad.
        moving_threshold_rad_s: the threshold used.
    """

    t_start_s: float
    t_end_s: float
    n_samples: int
    rms_over_noise: float
    channel_rms_over_noise: FloatArray
    statistic: float
    p_value: float
    joint_names: list[str]
    moving_joints: list[str]
    max_abs_dq_rad_s: FloatArray
    rms_ddq_rad_s2: FloatArray
    q_span_rad: FloatArray
    moving_threshold_rad_s: float = MOVING_THRESHOLD_RAD_S

    def describe(self, channel_names: tuple[str, ...] | list[str] | None = None, max_joints: int = 3) -> str:
        """One line: when, how far above the noise, on which channel, which joints moved (fastest first) how fast."""
        n_channels = len(self.channel_rms_over_noise)
        names = list(channel_names) if channel_names is not None else [f"ch{c + 1}" for c in range(n_channels)]
        worst = int(np.argmax(self.channel_rms_over_noise))
        text = (
            f"t = {self.t_start_s:.2f}-{self.t_end_s:.2f} s: residual {self.rms_over_noise:.2f} x noise "
            f"(largest on {names[worst]}: {self.channel_rms_over_noise[worst]:.2f} x; p = {self.p_value:.2g}); "
        )
        if not self.moving_joints:
            return text + f"arm at rest (all |dq| < {self.moving_threshold_rad_s:g} rad/s)"
        index = {name: i for i, name in enumerate(self.joint_names)}
        moves = ", ".join(
            f"{name} (|dq| up to {self.max_abs_dq_rad_s[index[name]]:.3g} rad/s, RMS ddq {self.rms_ddq_rad_s2[index[name]]:.3g} rad/s^2)"
            for name in self.moving_joints[:max_joints]
        )
        more = len(self.moving_joints) - max_joints
        return text + f"moving {moves}" + (f" and {more} more joint(s)" if more > 0 else "")


def _normalised_square(residual: FloatArray, noise_std: FloatArray) -> FloatArray:
    """(r / sigma)^2 per sample and channel; a channel with sigma = 0 gives 0 where r = 0, inf elsewhere."""
    square = residual**2
    variance = noise_std**2
    return np.divide(square, variance, out=np.where(square > 0.0, np.inf, 0.0), where=variance > 0.0)


def _holm_adjusted(p_values: FloatArray) -> FloatArray:
    """Holm step-down adjusted p-values (family-wise error control over all entries)."""
    m = p_values.size
    order = np.argsort(p_values)
    adjusted_sorted = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p_values[order]))
    adjusted = np.empty_like(p_values)
    adjusted[order] = adjusted_sorted
    return adjusted


def _window_index(t_s: FloatArray, window_s: float) -> FloatArray:
    """Window number of each sample (windows of ``window_s`` from t[0]); a last window shorter than half is merged."""
    index = np.floor((t_s - t_s[0]) / window_s + 1e-9).astype(np.int64)
    last = index[-1]
    if last > 0 and t_s[-1] - (t_s[0] + last * window_s) < 0.5 * window_s:
        index[index == last] = last - 1
    return index


def failing_segments(
    t_s: ArrayLike,
    residual: ArrayLike,
    noise_std: ArrayLike,
    q: ArrayLike,
    dq: ArrayLike,
    window_s: float = 2.0,
    confidence: float = 0.99,
    max_segments: int = 10,
    noise_dof: float | None = None,
    joint_names: list[str] | tuple[str, ...] | None = None,
    moving_threshold_rad_s: float = MOVING_THRESHOLD_RAD_S,
) -> list[Segment]:
    """The time segments whose residual exceeds the noise, ranked by excess (RMS / noise).

    The log is partitioned into windows of ``window_s`` (from ``t_s[0]``; a last window shorter than
    half is merged into the previous one). In each window, ``S = sum (r / sigma)^2`` over its samples
    and the C channels is chi2(n_w C) under "noise only" with a known sigma; with an *estimated* sigma
    (``noise_dof`` = its effective degrees of freedom summed over channels, e.g.
    ``C * noise_floor_dof(T)``) ``S / (n_w C)`` is tested against F(n_w C, noise_dof) instead. Windows
    whose Holm-adjusted p-value is below ``1 - confidence`` are flagged (family-wise over the windows),
    consecutive flagged windows merge into a segment, and segments are ranked by ``rms_over_noise``.

    Args:
        t_s: (T,) time, s, strictly increasing.
        residual: (T, C) measured - predicted.
        noise_std: (C,) or scalar white-noise std per channel (unit of residual), >= 0.
        q: (T, n) joint angles, rad. dq: (T, n) joint rates, rad/s (differentiated for ddq).
        window_s: window length, s (> 0).
        confidence: e.g. 0.99.
        max_segments: at most this many segments are returned.
        noise_dof: None if ``noise_std`` is known; else the effective degrees of freedom of its estimate.
        joint_names: (n,) names; default ``q1``..``qn``.
        moving_threshold_rad_s: a joint moves in a segment if its max |dq| there exceeds this.

    Returns:
        Up to ``max_segments`` :class:`Segment`, largest ``rms_over_noise`` first; empty if none fails.
    """
    t = _array(t_s, "failing_segments: t_s", (1,), min_rows=2)
    if np.any(np.diff(t) <= 0.0):
        raise SpaceIdInputError("failing_segments: t_s must be strictly increasing")
    r, _ = _columns(residual, "failing_segments: residual")
    q_arr, _ = _columns(q, "failing_segments: q")
    dq_arr, _ = _columns(dq, "failing_segments: dq")
    _check_same_rows(
        t.shape[0], **{"failing_segments: residual": r, "failing_segments: q": q_arr, "failing_segments: dq": dq_arr}
    )
    if q_arr.shape != dq_arr.shape:
        raise SpaceIdInputError(f"failing_segments: q {q_arr.shape} and dq {dq_arr.shape} must have the same shape (T, n)")
    sigma = np.broadcast_to(_array(np.atleast_1d(noise_std), "failing_segments: noise_std", (1,)), (r.shape[1],))
    if np.any(sigma < 0.0) or np.asarray(noise_std).size not in (1, r.shape[1]):
        raise SpaceIdInputError(
            f"failing_segments: noise_std must be >= 0, scalar or one per channel ({r.shape[1]}), got {noise_std!r}"
        )
    if not window_s > 0.0:
        raise SpaceIdInputError(f"failing_segments: window_s must be > 0 s, got {window_s!r}")
    if noise_dof is not None and not noise_dof > 0.0:
        raise SpaceIdInputError(f"failing_segments: noise_dof must be > 0 or None, got {noise_dof!r}")
    alpha = 1.0 - _check_probability(confidence, "failing_segments: confidence")
    n_joints = q_arr.shape[1]
    names = list(joint_names) if joint_names is not None else [f"q{i + 1}" for i in range(n_joints)]
    if len(names) != n_joints:
        raise SpaceIdInputError(f"failing_segments: joint_names must name the {n_joints} joints, got {len(names)}")

    z2 = _normalised_square(r, sigma)  # (T, C)
    index = _window_index(t, window_s)
    n_windows = int(index[-1]) + 1
    per_window = np.bincount(index, weights=z2.sum(axis=1), minlength=n_windows)
    counts = np.bincount(index, minlength=n_windows)
    present = counts > 0
    dof = counts[present] * r.shape[1]
    with np.errstate(invalid="ignore"):
        if noise_dof is None:
            raw_p = stats.chi2.sf(per_window[present], dof)
        else:
            raw_p = stats.f.sf(per_window[present] / dof, dof, noise_dof)
    raw_p = np.where(np.isnan(raw_p), 0.0, raw_p)  # inf / inf: a noiseless channel with residual
    adjusted = np.ones(n_windows)
    adjusted[present] = _holm_adjusted(raw_p)
    flagged = present & (adjusted < alpha)

    ddq = np.gradient(dq_arr, t, axis=0, edge_order=2) if t.shape[0] > 2 else np.zeros_like(dq_arr)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flagged.astype(np.int8), [0]])))
    segments = []
    for first, stop in zip(edges[::2], edges[1::2], strict=True):
        mask = (index >= first) & (index < stop)
        seg_z2 = z2[mask]
        max_dq = np.max(np.abs(dq_arr[mask]), axis=0)
        moving = [names[j] for j in np.argsort(-max_dq, kind="stable") if max_dq[j] > moving_threshold_rad_s]
        segments.append(
            Segment(
                t_start_s=float(max(t[0], t[0] + first * window_s)),
                t_end_s=float(t[-1] if stop == n_windows else t[0] + stop * window_s),
                n_samples=int(mask.sum()),
                rms_over_noise=float(np.sqrt(seg_z2.mean())),
                channel_rms_over_noise=np.sqrt(seg_z2.mean(axis=0)),
                statistic=float(seg_z2.sum()),
                p_value=float(adjusted[first:stop].min()),
                joint_names=names,
                moving_joints=moving,
                max_abs_dq_rad_s=max_dq,
                rms_ddq_rad_s2=np.sqrt(np.mean(ddq[mask] ** 2, axis=0)),
                q_span_rad=np.ptp(q_arr[mask], axis=0),
                moving_threshold_rad_s=moving_threshold_rad_s,
            )
        )
    segments.sort(key=lambda s: -s.rms_over_noise)
    return segments[:max_segments]


# ---------------------------------------------------------------------------------------- analysis


@dataclass
class ResidualAnalysis:
    """Everything :func:`analyse_residuals` found about ``residual = measured - predicted``.

    Per channel c (C channels, names ``channel_names``): ``fit_percent``, ``residual_rms`` (unit of the
    channel), ``noise_std`` (given or estimated: ``noise_source``), ``rms_over_noise``, Ljung-Box
    ``ljung_box_q``/``ljung_box_p`` over ``max_lag`` lags, ``acf`` (C, L+1) with the pointwise band
    ``acf_band`` and the lags outside it ``significant_acf_lags`` (pointwise: about ``alpha L`` lags of
    white noise fall outside by chance), ``ccf`` (C, m, 2L+1) with the m inputs ``input_names`` (lags in
    samples, see :class:`CrossCorrelation`) and its per-input ``ccf_p_value``/``ccf_peak``/``ccf_peak_lag``
    (C, m), ``correlated_inputs`` (per channel, the significant inputs ranked by |peak ccf|), and
    ``dominant_frequencies`` (per channel, list of :class:`SpectralPeak`). ``segments``: the failing
    time segments (all channels together).

    Verdicts at ``confidence`` (alpha = 1 - confidence), family-wise over channels and inputs:
    ``white`` (no channel's Ljung-Box p below alpha / C), ``uncorrelated_with_inputs`` (no ccf test
    p below alpha / (C m)), ``consistent_with_noise`` (both, and no failing segment).
    """

    channel_names: list[str]
    input_names: list[str]
    joint_names: list[str]
    confidence: float
    n_samples: int
    dt_s: float
    t_start_s: float
    t_end_s: float
    max_lag: int
    fit_percent: FloatArray
    residual_rms: FloatArray
    noise_std: FloatArray
    noise_source: str
    noise_dof: float | None
    rms_over_noise: FloatArray
    ljung_box_q: FloatArray
    ljung_box_p: FloatArray
    acf: FloatArray
    acf_band: float
    significant_acf_lags: list[list[int]]
    ccf: FloatArray
    ccf_band: float
    ccf_variance_factor: FloatArray
    ccf_p_value: FloatArray
    ccf_peak: FloatArray
    ccf_peak_lag: NDArray[np.int64]
    correlated_inputs: list[list[dict[str, Any]]]
    dominant_frequencies: list[list[SpectralPeak]]
    segments: list[Segment]
    notes: list[str] = field(default_factory=list)

    @property
    def alpha(self) -> float:
        return 1.0 - self.confidence

    @property
    def white(self) -> bool:
        """Every channel passes Ljung-Box at alpha / C (Bonferroni over channels)."""
        return bool(np.all(self.ljung_box_p >= self.alpha / len(self.channel_names)))

    @property
    def uncorrelated_with_inputs(self) -> bool:
        """No channel correlates significantly with any input (Bonferroni over channels and inputs)."""
        return not any(self.correlated_inputs)

    @property
    def consistent_with_noise(self) -> bool:
        """White, uncorrelated with the inputs and no failing time segment."""
        return self.white and self.uncorrelated_with_inputs and not self.segments

    def channel_rows(self) -> list[dict[str, Any]]:
        """One table row per channel (for a report): fit, RMS, noise, whiteness, strongest input and line."""
        rows = []
        for c, name in enumerate(self.channel_names):
            best = self.correlated_inputs[c][0] if self.correlated_inputs[c] else None
            line = self.dominant_frequencies[c][0] if self.dominant_frequencies[c] else None
            rows.append(
                {
                    "channel": name,
                    "fit %": float(self.fit_percent[c]),
                    "residual RMS": float(self.residual_rms[c]),
                    f"noise std ({self.noise_source})": float(self.noise_std[c]),
                    "RMS / noise": float(self.rms_over_noise[c]),
                    "Ljung-Box p": float(self.ljung_box_p[c]),
                    "white": bool(self.ljung_box_p[c] >= self.alpha / len(self.channel_names)),
                    "most correlated input": ""
                    if best is None
                    else f"{best['input']} ({best['peak_ccf']:+.2f} at {best['lag_s']:+.2f} s)",
                    "dominant line": "" if line is None else f"{line.frequency_hz:.3g} Hz (amp. {line.amplitude:.3g})",
                }
            )
        return rows

    def segment_rows(self) -> list[dict[str, Any]]:
        """One table row per failing segment, ranked."""
        return [
            {
                "rank": i + 1,
                "t start [s]": s.t_start_s,
                "t end [s]": s.t_end_s,
                "RMS / noise": s.rms_over_noise,
                "worst channel": self.channel_names[int(np.argmax(s.channel_rms_over_noise))],
                "p (Holm)": s.p_value,
                "moving joints": ", ".join(s.moving_joints) or "none",
                "max |dq| [rad/s]": float(np.max(s.max_abs_dq_rad_s)) if s.max_abs_dq_rad_s.size else 0.0,
            }
            for i, s in enumerate(self.segments)
        ]

    def structure_description(self) -> str:
        """A few plain sentences: whiteness, dominant frequencies, correlated inputs, where in time."""
        if not np.any(self.residual_rms > 0.0):
            return "The residual is exactly zero on every channel: the model reproduces the measurement."
        level = f"{100 * self.confidence:g} %"
        ratio = f"{np.nanmin(self.rms_over_noise):.2f}-{np.nanmax(self.rms_over_noise):.2f}"
        if self.consistent_with_noise:
            return (
                f"The residuals are consistent with white noise at {level} confidence on every channel: Ljung-Box over "
                f"{self.max_lag} lags passes, they do not correlate with any input and no time segment exceeds the noise; "
                f"residual RMS is {ratio} x the noise floor ({self.noise_source})."
            )
        sentences = []
        structured = [c for c in range(len(self.channel_names)) if self.ljung_box_p[c] < self.alpha / len(self.channel_names)]
        if structured:
            parts = ", ".join(f"{self.channel_names[c]} (Ljung-Box p = {self.ljung_box_p[c]:.2g})" for c in structured)
            sentences.append(
                f"The residuals are not white at {level} confidence on {parts}; RMS {ratio} x the noise floor ({self.noise_source})."
            )
        else:
            sentences.append(
                f"The residuals pass the Ljung-Box whiteness test at {level} confidence; RMS {ratio} x the noise floor ({self.noise_source})."
            )
        lines = [
            f"{self.channel_names[c]} at " + ", ".join(f"{p.frequency_hz:.3g} Hz (amplitude {p.amplitude:.3g})" for p in peaks)
            for c, peaks in enumerate(self.dominant_frequencies)
            if peaks
        ]
        sentences.append(
            ("Dominant frequencies: " + "; ".join(lines) + ".")
            if lines
            else "No significant spectral line (the structure is broadband or absent)."
        )
        correlated = [(self.channel_names[c], entry) for c, entries in enumerate(self.correlated_inputs) for entry in entries[:2]]
        if correlated:
            correlated.sort(key=lambda item: -abs(item[1]["peak_ccf"]))
            text = "; ".join(
                f"{channel} with {e['input']} (ccf {e['peak_ccf']:+.2f} at lag {e['lag_s']:+.2f} s)"
                for channel, e in correlated[:4]
            )
            sentences.append(f"It correlates most with the inputs: {text}.")
        else:
            sentences.append("It does not correlate significantly with any input (joint rates, accelerations).")
        if self.segments:
            worst = "; ".join(s.describe(self.channel_names) for s in self.segments[:3])
            sentences.append(f"It exceeds the noise in {len(self.segments)} time segment(s), largest first: {worst}.")
        else:
            sentences.append("No time segment exceeds the noise.")
        return " ".join(sentences + self.notes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dictionary of all fields (arrays as lists, non-finite numbers as None) and the verdicts."""
        out = {name: getattr(self, name) for name in self.__dataclass_fields__ if name != "segments"}
        out["segments"] = [
            {name: getattr(s, name) for name in s.__dataclass_fields__} | {"description": s.describe(self.channel_names)}
            for s in self.segments
        ]
        out |= {
            "white": self.white,
            "uncorrelated_with_inputs": self.uncorrelated_with_inputs,
            "consistent_with_noise": self.consistent_with_noise,
            "structure_description": self.structure_description(),
        }
        return jsonable(out)


def analyse_residuals(
    t_s: ArrayLike,
    measured: ArrayLike,
    predicted: ArrayLike,
    q: ArrayLike,
    dq: ArrayLike,
    noise_std: ArrayLike | None = None,
    channel_names: tuple[str, ...] | list[str] = ("wx", "wy", "wz"),
    input_names: tuple[str, ...] | list[str] | None = None,
    confidence: float = 0.99,
    max_lag: int = 50,
    window_s: float = 2.0,
    n_frequencies: int = 3,
    joint_names: tuple[str, ...] | list[str] | None = None,
) -> ResidualAnalysis:
    """All residual tests of ``measured - predicted`` in one :class:`ResidualAnalysis`.

    Inputs for the cross-correlation are the joint rates ``dq`` and the joint accelerations
    ``ddq = d(dq)/dt`` (``numpy.gradient``, second order), named ``dq1..dqn, ddq1..ddqn``.
    Spectra and correlations treat the samples as equally spaced at the median sample period (a
    note is added if the spacing varies by more than 1 %). ``max_lag`` is reduced to T // 4 for
    short logs (noted).

    Args:
        t_s: (T,) time, s, strictly increasing.
        measured, predicted: (T, C), unit of the channel (e.g. rad/s for ``omega_base_body``).
        q: (T, n) joint angles, rad; dq: (T, n) joint rates, rad/s.
        noise_std: (C,) or scalar known white-noise std per channel; None estimates it with
            :func:`noise_floor_std` (tests then account for the estimate's uncertainty).
        channel_names: (C,) names. input_names: (2n,) names of dq and ddq columns.
        confidence: confidence of every verdict (family-wise per question).
        max_lag: L for autocorrelation, Ljung-Box and cross-correlation.
        window_s: window of :func:`failing_segments`. n_frequencies: lines per channel.
        joint_names: (n,) names for the segments; default ``q1``..``qn``.
    """
    t = _array(t_s, "analyse_residuals: t_s", (1,), min_rows=16)
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        raise SpaceIdInputError(f"analyse_residuals: t_s must be strictly increasing (row {int(np.argmax(dt <= 0)) + 1})")
    y, _ = _columns(measured, "analyse_residuals: measured")
    yhat, _ = _columns(predicted, "analyse_residuals: predicted")
    q_arr, _ = _columns(q, "analyse_residuals: q")
    dq_arr, _ = _columns(dq, "analyse_residuals: dq")
    n_samples = t.shape[0]
    _check_same_rows(
        n_samples, **{"analyse_residuals: measured": y, "analyse_residuals: q": q_arr, "analyse_residuals: dq": dq_arr}
    )
    if yhat.shape != y.shape:
        raise SpaceIdInputError(f"analyse_residuals: predicted must have the shape of measured {y.shape}, got {yhat.shape}")
    if q_arr.shape != dq_arr.shape:
        raise SpaceIdInputError(f"analyse_residuals: q {q_arr.shape} and dq {dq_arr.shape} must have the same shape (T, n)")
    n_channels, n_joints = y.shape[1], dq_arr.shape[1]
    channels = list(channel_names)
    if len(channels) != n_channels:
        raise SpaceIdInputError(f"analyse_residuals: channel_names must name the {n_channels} channels, got {channels}")
    inputs_named = (
        list(input_names)
        if input_names is not None
        else [f"dq{i + 1}" for i in range(n_joints)] + [f"ddq{i + 1}" for i in range(n_joints)]
    )
    if len(inputs_named) != 2 * n_joints:
        raise SpaceIdInputError(
            f"analyse_residuals: input_names must name the {2 * n_joints} inputs (dq then ddq), got {len(inputs_named)}"
        )
    joints = list(joint_names) if joint_names is not None else [f"q{i + 1}" for i in range(n_joints)]
    alpha = 1.0 - _check_probability(confidence, "analyse_residuals: confidence")
    notes = []
    dt_s = float(np.median(dt))
    if np.max(np.abs(dt - dt_s)) > 0.01 * dt_s:
        notes.append(
            f"Note: the sampling is not uniform (steps {dt.min():.4g}-{dt.max():.4g} s); correlations and spectra treat samples as equally spaced at {dt_s:.4g} s."
        )
    lags = _check_lag(max_lag, n_samples, "analyse_residuals: max_lag")
    if lags > n_samples // 4:
        lags = n_samples // 4
        notes.append(f"Note: max_lag reduced from {max_lag} to {lags} (a quarter of the {n_samples} samples).")

    residual = y - yhat
    if noise_std is None:
        sigma, source, dof = noise_floor_std(residual), "estimated", n_channels * noise_floor_dof(n_samples)
    else:
        sigma = np.broadcast_to(_array(np.atleast_1d(noise_std), "analyse_residuals: noise_std", (1,)), (n_channels,)).copy()
        if np.any(sigma <= 0.0) or np.asarray(noise_std).size not in (1, n_channels):
            raise SpaceIdInputError(
                f"analyse_residuals: noise_std must be > 0, scalar or one per channel ({n_channels}), got {noise_std!r}"
            )
        source, dof = "given", None
    rms = np.sqrt(np.mean(residual**2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(sigma > 0.0, rms / np.where(sigma > 0.0, sigma, 1.0), np.where(rms > 0.0, np.inf, np.nan))

    acf = _autocorrelation_columns(residual, lags)  # (L+1, C)
    lb_q, lb_p = _ljung_box_from_acf(acf, n_samples)
    acf_band = white_noise_band(n_samples, alpha)
    ddq = np.gradient(dq_arr, t, axis=0, edge_order=2)
    inputs = np.hstack([dq_arr, ddq])
    ccfs = _cross_correlation_columns(residual, inputs, lags, alpha)
    threshold = alpha / (n_channels * inputs.shape[1])
    correlated = []
    for cc in ccfs:
        significant = np.flatnonzero(cc.p_value < threshold)
        significant = significant[np.argsort(-np.abs(cc.peak_ccf[significant]), kind="stable")]
        correlated.append(
            [
                {
                    "input": inputs_named[j],
                    "peak_ccf": float(cc.peak_ccf[j]),
                    "lag_samples": int(cc.peak_lag[j]),
                    "lag_s": float(cc.peak_lag[j] * dt_s),
                    "p_value": float(cc.p_value[j]),
                }
                for j in significant
            ]
        )
    lines = [dominant_frequencies(residual[:, c], dt_s, n=n_frequencies, alpha=alpha) for c in range(n_channels)]
    segments = failing_segments(
        t, residual, sigma, q_arr, dq_arr, window_s=window_s, confidence=confidence, noise_dof=dof, joint_names=joints
    )
    return ResidualAnalysis(
        channel_names=channels,
        input_names=inputs_named,
        joint_names=joints,
        confidence=float(confidence),
        n_samples=n_samples,
        dt_s=dt_s,
        t_start_s=float(t[0]),
        t_end_s=float(t[-1]),
        max_lag=lags,
        fit_percent=fit_percent(y, yhat),
        residual_rms=rms,
        noise_std=np.asarray(sigma, dtype=np.float64),
        noise_source=source,
        noise_dof=dof,
        rms_over_noise=ratio,
        ljung_box_q=lb_q,
        ljung_box_p=lb_p,
        acf=acf.T.copy(),
        acf_band=acf_band,
        significant_acf_lags=[(np.flatnonzero(np.abs(acf[1:, c]) > acf_band) + 1).tolist() for c in range(n_channels)],
        ccf=np.stack([cc.ccf for cc in ccfs]),
        ccf_band=acf_band,
        ccf_variance_factor=np.stack([cc.variance_factor for cc in ccfs]),
        ccf_p_value=np.stack([cc.p_value for cc in ccfs]),
        ccf_peak=np.stack([cc.peak_ccf for cc in ccfs]),
        ccf_peak_lag=np.stack([cc.peak_lag for cc in ccfs]),
        correlated_inputs=correlated,
        dominant_frequencies=lines,
        segments=segments,
        notes=notes,
    )
