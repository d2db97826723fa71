"""The residual's spectrum: Hann-windowed periodogram, the white-noise level and the significant spectral lines."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy import fft as sp_fft
from scipy import optimize, signal

from estimators.diagnostics.residuals._checks import _array, _check_probability
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


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
