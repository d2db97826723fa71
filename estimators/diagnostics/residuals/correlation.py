"""Whiteness: autocorrelation with its white-noise band, the Ljung-Box test, cross-correlation with the inputs."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import fft as sp_fft
from scipy import stats

from estimators.diagnostics.residuals._checks import _array, _check_lag, _check_probability, _check_same_rows, _columns
from spaceid_gym.arrays import FloatArray


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


#: Gaussian white-noise series simulated for the Ljung-Box null distribution of one length and lag count
LJUNG_BOX_NULL_DRAWS = 20_000

#: chi-square p-values in ``[LJUNG_BOX_SIMULATED_ABOVE, LJUNG_BOX_SIMULATED_BELOW)`` are replaced by the simulated
#: null's (:func:`ljung_box_null`): the chi-square's tail is too light on short logs (see :func:`ljung_box`). The
#: tests of whiteness here are at 0.01 or below; above it the chi-square's p-value is kept
LJUNG_BOX_SIMULATED_BELOW = 0.01

#: the fewest samples per lag at which the chi-square's p-value is kept whatever its size (the simulation's cost grows
#: with the samples: about 1 s per 1000): at 50 lags on 6001 samples (120 per lag) the chi-square calls a log's three
#: axes structured 1.18 +- 0.10 times as often as their level of 0.005 says (20000 logs), on 3001 (60 per lag) 1.22
#: +- 0.12 times, on 1201 (24 per lag) 1.90 +- 0.14 times; a 60 s log at up to 100 Hz is simulated
LJUNG_BOX_CHI2_SAMPLES_PER_LAG = 200

#: below this chi-square p-value the residual is structured at any level a diagnosis uses and the chi-square's own
#: p-value is kept (no simulation): the simulated null's share beyond it is 1.5e-4 at 16 lags on 64 samples, 2.5e-4
#: at 50 on 200, 1e-4 at 50 on 301 and 5e-5 (none of the 20000) at 50 on 1201, all below the diagnosis's whiteness
#: level (0.00167); the chi-square's p-value is that much too small there
LJUNG_BOX_SIMULATED_ABOVE = 1e-8

#: the seed of the simulated null (a fixed draw: the same statistic gets the same p-value in every run)
_LJUNG_BOX_NULL_SEED = 20261128


def _ljung_box_q(acf: FloatArray, n_samples: int) -> FloatArray:
    lags = acf.shape[0] - 1
    k = np.arange(1, lags + 1)
    return n_samples * (n_samples + 2.0) * np.sum(acf[1:] ** 2 / (n_samples - k)[:, None], axis=0)


@functools.lru_cache(maxsize=16)
def ljung_box_null(n_samples: int, lags: int) -> FloatArray:
    """The Ljung-Box statistics, sorted, of :data:`LJUNG_BOX_NULL_DRAWS` Gaussian white-noise series of
    ``n_samples`` samples over ``lags`` lags (read-only; one fixed seed; cached per process).

    The statistic does not depend on the noise's scale, so this is its null distribution for any white
    Gaussian residual of that length. It costs about 1 s per 1000 samples of the series."""
    _check_lag(lags, n_samples, "ljung_box_null: lags")
    rng = np.random.default_rng(_LJUNG_BOX_NULL_SEED)
    chunk = max(1, min(LJUNG_BOX_NULL_DRAWS, 4_000_000 // n_samples))
    q = np.concatenate(
        [
            _ljung_box_q(_autocorrelation_columns(rng.standard_normal((n_samples, size)), lags), n_samples)
            for size in np.diff(np.r_[0:LJUNG_BOX_NULL_DRAWS:chunk, LJUNG_BOX_NULL_DRAWS])
        ]
    )
    q.sort()
    q.setflags(write=False)
    return q


def _ljung_box_from_acf(acf: FloatArray, n_samples: int) -> tuple[FloatArray, FloatArray]:
    lags = acf.shape[0] - 1
    q = _ljung_box_q(acf, n_samples)
    p = stats.chi2.sf(q, lags)
    tail = (p < LJUNG_BOX_SIMULATED_BELOW) & (p >= LJUNG_BOX_SIMULATED_ABOVE)
    if n_samples >= LJUNG_BOX_CHI2_SAMPLES_PER_LAG * lags:
        tail[:] = False
    if np.any(tail):
        null = ljung_box_null(n_samples, lags)
        beyond = null.size - np.searchsorted(null, q[tail], side="left")
        # capped at the switch, and beyond every simulated statistic the chi-square's p if it is smaller: so that p
        # never increases with Q
        simulated = np.minimum((1.0 + beyond) / (null.size + 1.0), LJUNG_BOX_SIMULATED_BELOW)
        p[tail] = np.where(beyond > 0, simulated, np.minimum(p[tail], 1.0 / (null.size + 1.0)))
    return q, p


def ljung_box(x: ArrayLike, lags: int) -> tuple[Any, Any]:
    """Ljung-Box portmanteau test of whiteness: ``Q = T (T+2) sum_{k=1}^{h} r_k^2 / (T-k)``.

    Under "x is Gaussian white noise" Q is approximately chi2(h) (h = ``lags``; no degrees of freedom are
    removed for fitted model parameters: a physical model with a few parameters fitted to T >> h samples
    barely changes the distribution). The approximation's tail is too light when h is not small against T:
    at 50 lags on 1201 samples (60 s at 20 Hz) the chi-square calls one white series structured 2.2 times as
    often as its level of 0.0017 says, 1.4 times at 0.01 (60000 series), and a log's three gyro axes 1.9 times at
    0.005 over the three (``benchmarks/whiteness_null.py``). So, on logs of fewer than
    :data:`LJUNG_BOX_CHI2_SAMPLES_PER_LAG` samples per lag, a chi-square p-value below
    :data:`LJUNG_BOX_SIMULATED_BELOW` is replaced by the share of simulated white-noise statistics at least
    as large (:func:`ljung_box_null`, ``(1 + count) / (1 + draws)``, capped at the switch, an exact test up to the simulation's
    own error, about 25 % relative at a level of 1e-3); beyond every simulated statistic, and wherever the
    chi-square's p-value is below :data:`LJUNG_BOX_SIMULATED_ABOVE`, the chi-square's smaller p-value is kept
    (there the residual is structured at any level of interest; that p-value is too small, by 10^4 times at 1e-8 on
    the shortest logs). Between the chi-square's 0.99 point and the simulated one the p-value is 0.01 (the cap), for
    any test at a level above 0.01 it is the chi-square's. A small p-value says the residual has autocorrelation:
    structure.

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
