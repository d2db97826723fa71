"""A fractional delay that is all-pass: ``x(t - d)`` for uniformly sampled series, by a phase ramp in frequency.

Why not an interpolating polynomial: the series delayed here is the *prediction* of the gyro, computed from noisy
joint rates, so it carries their white noise. A local interpolator (linear, Catmull-Rom) between samples is a
low-pass filter as well as a delay: at a lag of a quarter sample, Catmull-Rom's weights sum to one but their squares
to 0.81, so the delayed prediction carries 19 % less of that noise. A least-squares fit then "finds" a delay of a
fraction of a sample on a log without any, because smoothing the prediction lowers the residual (seen: a clean
100 Hz log of paper6 with a smooth random excitation, delay -2.7 ms, likelihood ratio 87). The delay here multiplies
the series' discrete Fourier transform by ``exp(-2 pi i f d)``: it moves every frequency by the same time and keeps
every frequency's amplitude, so it cannot lower the noise a series carries (Parseval), and on signals inside the
band it is the ideal (sinc) band-limited delay.

One exception: at the Nyquist frequency a real series cannot be moved by a fraction of a sample (the bin keeps the
real part of its phase factor, ``cos(pi lag)``), so near it the ramp loses power after all. ``band`` restricts the
delay to the content below a frequency, leaving the noise above it where it is (see
:class:`~estimators.models.effect_models.Delay`).

Ends: the series is extended by holding its first and last values over more samples than the largest lag (a log
that starts and ends at rest is unchanged by it), so that the circular transform does not wrap the end onto the
start; the samples read from before the first are then the first value, as a gyro that lags reads at the start.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft, rfftfreq

from spaceid_gym.arrays import FloatArray

#: samples of held value added at each end beyond the largest lag: the sinc's tail past the held values' slope change
#: decays as 1/n^2, so a few tens of samples keep the wrap-around below 1e-4 of the series' steps
PAD_MARGIN_SAMPLES = 64


def delay_samples(x: FloatArray, lag: FloatArray, band: tuple[float, float] | None = None) -> FloatArray:
    """``x`` (P, T, C) read ``lag[p]`` samples earlier (fractional, any sign: a negative lag reads later), all-pass.

    ``band`` ``(f1, f2)`` (cycles per sample, ``0 < f1 < f2``) delays only the content below ``f1``, none above ``f2``,
    with a raised-cosine blend between: the phase factor is ``1 + (exp(-2 pi i f lag) - 1) w(f)``.

    Raises:
        ValueError: ``x`` is not (P, T, C), ``lag`` is not (P,) finite numbers, or a bad ``band``.
    """
    x = np.asarray(x, dtype=float)
    lag = np.asarray(lag, dtype=float)
    if x.ndim != 3 or lag.shape != (x.shape[0],) or not np.all(np.isfinite(lag)):
        raise ValueError(f"delay_samples: expected x (P, T, C) and finite lags (P,), got {x.shape} and {lag.shape}")
    n_t = x.shape[1]
    pad = math.ceil(float(np.max(np.abs(lag), initial=0.0))) + PAD_MARGIN_SAMPLES
    n = next_fast_len(n_t + 2 * pad, real=True)
    extended = np.concatenate((np.repeat(x[:, :1], pad, axis=1), x, np.repeat(x[:, -1:], n - n_t - pad, axis=1)), axis=1)
    frequency = rfftfreq(n)
    phase = np.exp(-2j * np.pi * frequency[None, :, None] * lag[:, None, None])
    if band is not None:
        f1, f2 = band
        if not 0.0 < f1 < f2:
            raise ValueError(f"delay_samples: expected a band 0 < f1 < f2 (cycles per sample), got {band!r}")
        blend = np.clip((frequency - f1) / (f2 - f1), 0.0, 1.0)
        weight = 0.5 * (1.0 + np.cos(np.pi * blend))  # 1 below f1, 0 above f2
        phase = 1.0 + (phase - 1.0) * weight[None, :, None]
    return irfft(rfft(extended, axis=1) * phase, n=n, axis=1)[:, pad : pad + n_t]
