"""Residual analysis (estimators.diagnostics.residuals) on synthetic data with known answers.

References are independent of the implementation: direct sums instead of FFTs, closed forms,
distributions of the test statistics under white noise (false-alarm counts over fixed seeds with
bounds that hold with overwhelming probability), and injected structure whose location, frequency
and cause are known.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from scipy import stats

from estimators.diagnostics.residuals import (
    analyse_residuals,
    autocorrelation,
    band_limited_inputs,
    cross_correlation,
    dominant_frequencies,
    failing_segments,
    fit_percent,
    ljung_box,
    noise_floor_dof,
    noise_floor_std,
    periodogram,
    white_spectrum_level,
)
from estimators.diagnostics.residuals.correlation import (
    LJUNG_BOX_CHI2_SAMPLES_PER_LAG,
    LJUNG_BOX_NULL_DRAWS,
    LJUNG_BOX_SIMULATED_ABOVE,
    LJUNG_BOX_SIMULATED_BELOW,
    _ljung_box_from_acf,
    ljung_box_null,
)
from spaceid_gym.errors import SpaceIdInputError

DT_S = 0.02
T = 3001
T_S = np.arange(T) * DT_S


def multisine_joints(rng: np.random.Generator, n_joints: int = 6, t_s: np.ndarray = T_S) -> tuple[np.ndarray, np.ndarray]:
    """Smooth joint motion like the Fourier excitation: q (T, n) rad, dq (T, n) rad/s, harmonics of 0.025 Hz."""
    harmonics = 2 * np.pi * 0.025 * np.arange(1, 6)
    amplitude = rng.uniform(0.2, 1.0, (n_joints, 5))
    amplitude *= 0.3 / amplitude.sum(axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, (n_joints, 5))
    arg = harmonics * t_s[:, None, None] + phase
    dq = np.sum(amplitude * np.sin(arg), axis=2)
    q = np.sum(-amplitude / harmonics * np.cos(arg), axis=2)
    return q, dq


# ---------------------------------------------------------------------------------------- fit


def test_fit_percent_known_values() -> None:
    y = np.array([[1.0, 0.0], [2.0, 1.0], [3.0, 0.0], [4.0, 1.0]])
    assert np.allclose(fit_percent(y, y), 100.0)
    assert np.allclose(fit_percent(y, np.broadcast_to(y.mean(axis=0), y.shape)), 0.0)
    yhat = y + np.array([[0.1, 0.0], [-0.1, 0.0], [0.1, 0.0], [-0.1, 1.0]])
    # by hand: channel 1 error norm 0.2, spread sqrt(5) ; channel 2 error 1, spread 1
    assert np.allclose(fit_percent(y, yhat), [100 * (1 - 0.2 / math.sqrt(5.0)), 0.0])
    assert fit_percent(y, -y)[0] < 0.0
    assert np.isnan(fit_percent(np.ones(5), np.zeros(5))[0])
    with pytest.raises(SpaceIdInputError, match="predicted"):
        fit_percent(y, y[:, :1])


# ---------------------------------------------------------------------------------- noise floor


def test_noise_floor_on_white_noise_within_a_few_percent() -> None:
    sigma = np.array([1e-4, 2.0, 3e3])
    estimates = np.array(
        [noise_floor_std(np.random.default_rng(seed).normal(0.0, sigma, (3000, 3))) / sigma for seed in range(20)]
    )
    # relative std of one estimate is sqrt(1.97 / 3000) = 2.6 %: 10 % is a 3.9-sigma bound, the mean of 60 a 5.6-sigma one
    assert np.all(np.abs(estimates - 1.0) < 0.10)
    assert abs(estimates.mean() - 1.0) < 0.02


def test_noise_floor_ignores_a_slow_sinusoid_but_std_does_not() -> None:
    rng = np.random.default_rng(7)
    slow = 5.0 * np.sin(2 * np.pi * 0.1 * T_S + 0.3)  # 5 sigma amplitude at 0.1 Hz
    ratios = []
    for _ in range(10):
        x = rng.normal(0.0, 1.0, T) + slow
        ratios.append(float(noise_floor_std(x)[0]))
        assert np.std(x) > 3.0  # the naive estimate is far off: the test can fail
    # documented bias: A^2 (2 pi f dt)^4 / 12 = 25 * 0.0126^4 / 12, negligible
    assert np.all(np.abs(np.array(ratios) - 1.0) < 0.10) and abs(np.mean(ratios) - 1.0) < 0.03
    # first differences: bias A^2 (2 pi f dt)^2 / 4 = 1e-3 in variance, still small
    assert abs(float(noise_floor_std(rng.normal(0.0, 1.0, T) + slow, order=1)[0]) - 1.0) < 0.10


def test_noise_floor_relative_variance_matches_the_documented_constant() -> None:
    rng = np.random.default_rng(11)
    n = 500
    estimates = noise_floor_std(rng.standard_normal((n, 2000)))
    nu = noise_floor_dof(n)
    # var(sigma_hat^2 / sigma^2) = 2 / nu; its estimate from 2000 draws has a relative std of about 3.2 %
    assert np.var(estimates**2) == pytest.approx(2.0 / nu, rel=0.15)


def test_noise_floor_quantised_falls_back_to_rms() -> None:
    x = np.zeros(100)
    x[::10] = 1.0  # most second differences are 0: MAD = 0
    d = np.diff(x, n=2)
    assert noise_floor_std(x)[0] == pytest.approx(np.sqrt(np.mean(d**2) / 6.0))
    assert noise_floor_std(np.zeros(10))[0] == 0.0


# --------------------------------------------------------------------------- autocorrelation, Ljung-Box


def test_autocorrelation_matches_direct_sums() -> None:
    x = np.random.default_rng(3).normal(size=(257, 2)) + np.array([5.0, -1.0])
    acf = autocorrelation(x, 12)
    xc = x - x.mean(axis=0)
    direct = np.array([[np.sum(xc[k:, c] * xc[: len(x) - k, c]) / np.sum(xc[:, c] ** 2) for c in range(2)] for k in range(13)])
    assert acf.shape == (13, 2)
    assert np.allclose(acf, direct, atol=1e-13)
    assert np.allclose(autocorrelation(x[:, 0], 12), direct[:, 0], atol=1e-13)
    assert np.array_equal(autocorrelation(np.full(50, 3.0), 3), [1.0, 0.0, 0.0, 0.0])
    with pytest.raises(SpaceIdInputError, match="max_lag"):
        autocorrelation(x, 257)


def test_ljung_box_formula_and_chi2_p_value() -> None:
    x = np.random.default_rng(4).normal(size=400)
    r = autocorrelation(x, 10)
    q_direct = 400 * 402 * sum(r[k] ** 2 / (400 - k) for k in range(1, 11))
    q, p = ljung_box(x, 10)
    assert q == pytest.approx(q_direct, rel=1e-12)
    assert stats.chi2.sf(q_direct, 10) >= LJUNG_BOX_SIMULATED_BELOW  # the chi-square's p-value is kept up there
    assert p == pytest.approx(stats.chi2.sf(q_direct, 10), rel=1e-10)


def test_ljung_box_p_value_in_the_tail_is_the_simulated_nulls() -> None:
    rng = np.random.default_rng(41)
    x = rng.standard_normal((300, 400))
    x += np.sin(0.3 * np.arange(300))[:, None] * np.linspace(0.0, 0.5, 400)  # from none to strong: across the tail
    q, p = ljung_box(x, 20)
    chi2_p = stats.chi2.sf(q, 20)
    null = ljung_box_null(300, 20)
    assert null.size == LJUNG_BOX_NULL_DRAWS and np.all(np.diff(null) >= 0.0)
    simulated = (chi2_p < LJUNG_BOX_SIMULATED_BELOW) & (chi2_p >= LJUNG_BOX_SIMULATED_ABOVE)
    assert 20 < np.sum(simulated) < 380
    count = np.array([np.sum(null >= v) for v in q[simulated]])
    share = np.minimum((1.0 + count) / (null.size + 1.0), LJUNG_BOX_SIMULATED_BELOW)
    expected = np.where(count > 0, share, np.minimum(chi2_p[simulated], 1.0 / (null.size + 1.0)))
    assert np.allclose(p[simulated], expected, rtol=1e-12, atol=0.0)
    assert np.array_equal(p[~simulated], chi2_p[~simulated])
    order = np.argsort(q)
    assert np.all(np.diff(p[order]) <= 1e-12)  # never increases with Q, across the three regimes
    long = rng.standard_normal((LJUNG_BOX_CHI2_SAMPLES_PER_LAG * 20, 200))
    long[:, :100] += 0.1 * np.sin(0.3 * np.arange(long.shape[0]))[:, None]
    q_long, p_long = ljung_box(long, 20)
    assert np.any(p_long < LJUNG_BOX_SIMULATED_BELOW)
    assert np.array_equal(p_long, stats.chi2.sf(q_long, 20))  # enough samples per lag: the chi-square's own


def test_ljung_box_p_value_at_the_edges_of_the_simulated_tail() -> None:
    # statistics placed exactly through the lag-1 autocorrelation alone: Q = T (T+2) r_1^2 / (T-1)
    n_samples, lags = 1201, 50
    null = ljung_box_null(n_samples, lags)

    def p_of(q: np.ndarray) -> np.ndarray:
        acf = np.zeros((lags + 1, len(q)))
        acf[0] = 1.0
        acf[1] = np.sqrt(q * (n_samples - 1) / (n_samples * (n_samples + 2.0)))
        return _ljung_box_from_acf(acf, n_samples)[1]

    beyond = 1.01 * null[-1]  # beyond every simulated statistic, its chi-square p-value above the switch to 1e-8
    assert LJUNG_BOX_SIMULATED_ABOVE < stats.chi2.sf(beyond, lags) < 1.0 / (null.size + 1.0)
    just_below = stats.chi2.isf(0.0099, lags)  # simulated, and capped: the chi-square's tail is too light here
    at_switch = stats.chi2.isf(LJUNG_BOX_SIMULATED_BELOW, lags) * (1.0 - 1e-12)
    p = p_of(np.array([beyond, just_below, at_switch, null[-1] * (1.0 - 1e-9), null[-2] * (1.0 - 1e-9)]))
    assert p[0] == pytest.approx(stats.chi2.sf(beyond, lags), rel=1e-12)
    assert p[1] == LJUNG_BOX_SIMULATED_BELOW and p[2] == pytest.approx(LJUNG_BOX_SIMULATED_BELOW, rel=1e-9)
    assert p[3] == pytest.approx(2.0 / (null.size + 1.0), rel=1e-12)  # just below the largest draw: it counts
    assert p[4] == pytest.approx(3.0 / (null.size + 1.0), rel=1e-12)


def test_ljung_box_false_alarms_on_white_noise_are_about_alpha() -> None:
    x = np.random.default_rng(5).standard_normal((1000, 400))
    _, p = ljung_box(x, 20)
    # Binomial(400, 0.01): mean 4; P(count >= 13) ~ 1e-4. p-values roughly uniform: P(<0.5) in [0.4, 0.6] (4 sigma)
    assert np.sum(p < 0.01) <= 12
    assert 0.4 < np.mean(p < 0.5) < 0.6


def test_ljung_box_holds_its_level_in_the_tail_on_a_short_log() -> None:
    # 60 s at 20 Hz over the diagnosis's 50 lags, at its level per gyro axis (0.005 / 3), 40000 white series:
    # expected count 67 at the level. The binomial's sd 8 and the simulated null's own error (its tail quantile
    # from 33 of 20000 draws, ~17 %, 11 counts) give an sd of about 14: 25-109 (3 sd). The chi-square
    # approximation alone calls about 2.2 times the level structured (about 145 expected).
    level, draws = 0.005 / 3, 40_000
    rng = np.random.default_rng(20261129)
    tests = [ljung_box(rng.standard_normal((1201, 2000)), 50) for _ in range(draws // 2000)]
    q, p = np.concatenate([t[0] for t in tests]), np.concatenate([t[1] for t in tests])
    assert 25 <= np.sum(p < level) <= 109
    assert np.sum(stats.chi2.sf(q, 50) < level) > 1.5 * max(np.sum(p < level), 67)  # the reference it replaces


def test_ljung_box_rejects_ar1_and_sinusoid() -> None:
    rng = np.random.default_rng(6)
    e = rng.standard_normal(1000)
    ar1 = np.empty(1000)
    ar1[0] = e[0]
    for i in range(1, 1000):
        ar1[i] = 0.3 * ar1[i - 1] + e[i]
    assert ljung_box(ar1, 20)[1] < 1e-10
    sinusoid = rng.standard_normal(1000) + 0.5 * np.sin(2 * np.pi * 0.01 * np.arange(1000))
    assert ljung_box(sinusoid, 20)[1] < 1e-6


# ------------------------------------------------------------------------------------ cross-correlation


def test_cross_correlation_direct_sums_and_sign_convention() -> None:
    rng = np.random.default_rng(8)
    u = rng.normal(size=(500, 2))
    r = np.concatenate([np.zeros(5), u[:-5, 0]]) + 0.1 * rng.normal(size=500)  # r(t) = u0(t - 5): follows by 5 samples
    cc = cross_correlation(r, u, 10)
    rc, uc = r - r.mean(), u - u.mean(axis=0)
    for k in (-10, -3, 0, 5, 10):
        direct = [
            (np.sum(rc[k:] * uc[: 500 - k, j]) if k >= 0 else np.sum(rc[: 500 + k] * uc[-k:, j]))
            / (500 * rc.std() * uc[:, j].std())
            for j in range(2)
        ]
        assert np.allclose(cc.ccf[:, 10 + k], direct, atol=1e-13)
    assert cc.lags[10 + 5] == 5 and cc.peak_lag[0] == 5 and cc.peak_ccf[0] > 0.9
    assert cc.p_value[0] < 1e-50 and cc.p_value[1] > 0.01
    assert cc.band == pytest.approx(stats.norm.isf(0.005) / math.sqrt(500))
    constant = cross_correlation(r, np.ones((500, 1)), 3)
    assert np.all(constant.ccf == 0.0) and constant.p_value[0] == 1.0


def test_cross_correlation_test_holds_its_level_with_smooth_inputs() -> None:
    flagged = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        _, dq = multisine_joints(rng)
        flagged += int(np.any(cross_correlation(rng.standard_normal(T), dq, 50).p_value < 0.01 / 6))
    # family-wise level 1 % per seed: Binomial(100, 0.01), P(count >= 6) ~ 5e-4
    assert flagged <= 5


def test_residual_proportional_to_dq3_correlates_with_dq3_first() -> None:
    rng = np.random.default_rng(9)
    q, dq = multisine_joints(rng)
    sigma = 1e-4
    measured = rng.normal(0.0, sigma, (T, 3))
    measured[:, 1] += 2 * sigma * dq[:, 2] / dq[:, 2].std()
    ddq = np.gradient(dq, T_S, axis=0)
    measured[:, 2] += 2 * sigma * ddq[:, 1] / ddq[:, 1].std()  # a rate is told from an acceleration
    analysis = analyse_residuals(T_S, measured, np.zeros((T, 3)), q, dq)
    assert analysis.correlated_inputs[1][0]["input"] == "dq3"
    assert analysis.correlated_inputs[1][0]["lag_samples"] == 0
    assert analysis.correlated_inputs[2][0]["input"] == "ddq2"
    assert not analysis.correlated_inputs[0]
    assert not analysis.white and not analysis.uncorrelated_with_inputs
    assert "dq3" in analysis.structure_description()


@pytest.mark.parametrize("seed", range(5))
def test_measured_rate_noise_shared_by_the_prediction_is_not_taken_for_a_missing_input(seed: int) -> None:
    """The model predicts from the measured joint rates, so their noise is in the residual; the differentiated noise
    of ddq correlated with it one sample apart (a clean 100 Hz log, exact model, was 'correlated with ddq2'). The
    band-limited inputs see only the motion: no correlation, while the unfiltered inputs (the old rule) find it."""
    rng = np.random.default_rng(100 + seed)
    t_s = np.arange(6000) * 0.01  # 100 Hz
    q, dq_true = multisine_joints(rng, t_s=t_s)
    dq_noise = rng.normal(0.0, 1.4e-4, dq_true.shape)
    sensitivity = rng.normal(0.0, 0.5, (3, 6))  # d(predicted base rate)/d(joint rate), dimensionless
    residual = rng.normal(0.0, 1.8e-4, (6000, 3)) - dq_noise @ sensitivity.T
    band_limited = analyse_residuals(t_s, residual, np.zeros_like(residual), q, dq_true + dq_noise)
    unfiltered = analyse_residuals(t_s, residual, np.zeros_like(residual), q, dq_true + dq_noise, input_band_hz=None)
    assert band_limited.uncorrelated_with_inputs
    assert not unfiltered.uncorrelated_with_inputs
    assert any(entry["lag_samples"] == 1 for channel in unfiltered.correlated_inputs for entry in channel)


def test_band_limited_inputs_keep_a_slow_input_and_refuse_a_bad_cutoff() -> None:
    rng = np.random.default_rng(3)
    _q, dq = multisine_joints(rng)
    inputs = band_limited_inputs(dq, T_S, DT_S, 10.0)
    np.testing.assert_allclose(inputs[50:-50, :6], dq[50:-50], atol=1e-6 * np.abs(dq).max())  # edges: padding
    with pytest.raises(SpaceIdInputError, match="input_band_hz"):
        band_limited_inputs(dq, T_S, DT_S, 0.0)


# ---------------------------------------------------------------------------------------- spectrum


def test_dominant_frequency_of_a_sinusoid_within_one_bin() -> None:
    rng = np.random.default_rng(10)
    bin_hz = 1.0 / (T * DT_S)
    x = rng.standard_normal(T) + 0.4 * np.sin(2 * np.pi * 0.3712 * T_S + 1.0) + 0.25 * np.cos(2 * np.pi * 2.05 * T_S)
    peaks = dominant_frequencies(x, DT_S, n=3)
    assert len(peaks) == 2
    assert abs(peaks[0].frequency_hz - 0.3712) < bin_hz and abs(peaks[1].frequency_hz - 2.05) < bin_hz
    assert peaks[0].amplitude == pytest.approx(0.4, rel=0.2) and peaks[1].amplitude == pytest.approx(0.25, rel=0.3)
    assert peaks[0].p_value < 0.01


def test_strong_sinusoid_reports_no_side_lobes() -> None:
    x = np.random.default_rng(12).standard_normal(T) + 50.0 * np.sin(2 * np.pi * 1.234 * T_S)
    peaks = dominant_frequencies(x, DT_S, n=3)
    assert len(peaks) == 1 and abs(peaks[0].frequency_hz - 1.234) < 1e-3 and peaks[0].amplitude == pytest.approx(50.0, rel=1e-3)


def test_dominant_frequencies_of_white_noise_are_empty() -> None:
    found = sum(bool(dominant_frequencies(np.random.default_rng(seed).standard_normal(1000), DT_S)) for seed in range(200))
    # family-wise level 1 %: Binomial(200, 0.01), P(count >= 8) ~ 1e-4
    assert found <= 7


def test_periodogram_white_level() -> None:
    sigma = 0.3
    x = np.random.default_rng(13).normal(0.0, sigma, (4000, 2))
    frequency, psd = periodogram(x, DT_S)
    assert frequency[-1] == pytest.approx(0.5 / DT_S)
    level, threshold = white_spectrum_level(psd, 4000)
    # median-based level vs the known 2 sigma^2 dt (relative std of the median of ~2000 exponentials: ~3 %)
    assert np.allclose(level, 2 * sigma**2 * DT_S, rtol=0.12)
    assert np.allclose(threshold / level, math.log(1999 / 0.01))


# ------------------------------------------------------------------------------------------ segments


def bump_case(rng: np.random.Generator, sigma: float = 1e-4) -> tuple[np.ndarray, ...]:
    """Joint 3 moves only in [20, 24] s, joint 1 only in [40, 50] s; a residual bump in [20, 24] s on channel 2."""
    q = np.zeros((T, 6))
    dq = np.zeros((T, 6))
    window = (T_S >= 20.0) & (T_S <= 24.0)
    phase = np.pi * (T_S[window] - 20.0) / 4.0
    dq[window, 2] = 0.4 * np.sin(phase) ** 2
    q[:, 2] = np.cumsum(dq[:, 2]) * DT_S
    later = (T_S >= 40.0) & (T_S <= 50.0)
    dq[later, 0] = 0.2 * np.sin(np.pi * (T_S[later] - 40.0) / 10.0)
    residual = rng.normal(0.0, sigma, (T, 3))
    residual[window, 1] += 3.0 * sigma * np.sin(phase)
    return q, dq, residual


def test_injected_bump_is_the_top_failing_segment_and_names_the_joint() -> None:
    rng = np.random.default_rng(14)
    sigma = 1e-4
    q, dq, residual = bump_case(rng, sigma)
    segments = failing_segments(T_S, residual, np.full(3, sigma), q, dq)
    top = segments[0]
    assert (top.t_start_s, top.t_end_s) == pytest.approx((20.0, 24.0))
    assert top.moving_joints == ["q3"]
    assert top.max_abs_dq_rad_s[2] == pytest.approx(0.4, rel=1e-3)
    # RMS of 0.4 d/dt sin^2(pi t / 4) = 0.4 (pi / 4) sin(pi t / 2): 0.4 pi / (4 sqrt 2)
    assert top.rms_ddq_rad_s2[2] == pytest.approx(0.4 * math.pi / (4 * math.sqrt(2)), rel=0.01)
    assert top.channel_rms_over_noise[1] > 2.0 > 1.3 > top.channel_rms_over_noise[0]
    assert top.p_value < 0.01
    line = top.describe(["wx", "wy", "wz"])
    assert "20.00-24.00 s" in line and "q3" in line and "wy" in line and "q1" not in line
    analysis = analyse_residuals(T_S, residual, np.zeros((T, 3)), q, dq)  # estimated noise, F test
    assert (analysis.segments[0].t_start_s, analysis.segments[0].t_end_s) == pytest.approx((20.0, 24.0))
    assert "20.00-24.00 s" in analysis.structure_description()


def test_failing_segments_false_alarms_on_noise() -> None:
    flagged_known = flagged_estimated = 0
    q = np.zeros((T, 2))
    for seed in range(100):
        residual = np.random.default_rng(seed).normal(0.0, 2.0, (T, 3))
        flagged_known += bool(failing_segments(T_S, residual, 2.0, q, q))
        estimated = noise_floor_std(residual)
        flagged_estimated += bool(failing_segments(T_S, residual, estimated, q, q, noise_dof=3 * noise_floor_dof(T)))
    # family-wise 1 % per seed (Holm over 30 windows): Binomial(100, 0.01), P(count >= 6) ~ 5e-4
    assert flagged_known <= 5 and flagged_estimated <= 5


def test_failing_segments_partial_last_window_and_at_rest() -> None:
    t = np.arange(0.0, 5.1, 0.1)  # windows [0, 2), [2, 4), [4, 5]: the last (1 s) is half a window: kept
    residual = np.zeros((t.size, 1))
    residual[t >= 4.0] = 10.0
    segments = failing_segments(t, residual, 1.0, np.zeros((t.size, 1)), np.zeros((t.size, 1)))
    assert len(segments) == 1 and (segments[0].t_start_s, segments[0].t_end_s) == (4.0, 5.0)
    assert segments[0].moving_joints == [] and "arm at rest" in segments[0].describe()
    t2 = np.arange(0.0, 4.6, 0.1)  # last window 0.5 s < 1 s: merged into [2, 4.5]
    residual2 = np.zeros((t2.size, 1))
    residual2[t2 >= 4.0] = 10.0
    merged = failing_segments(t2, residual2, 1.0, np.zeros((t2.size, 1)), np.zeros((t2.size, 1)))
    assert (merged[0].t_start_s, merged[0].t_end_s) == pytest.approx((2.0, 4.5))


# ------------------------------------------------------------------------------------------ analysis


def test_analysis_of_white_noise_is_consistent_with_noise_and_json_able() -> None:
    rng = np.random.default_rng(15)
    q, dq = multisine_joints(rng)
    measured = rng.normal(0.0, 1e-4, (T, 3))
    analysis = analyse_residuals(T_S, measured, np.zeros((T, 3)), q, dq)
    assert analysis.white and analysis.uncorrelated_with_inputs and analysis.consistent_with_noise
    assert analysis.noise_source == "estimated" and np.allclose(analysis.rms_over_noise, 1.0, atol=0.1)
    assert "consistent with white noise" in analysis.structure_description()
    data = json.loads(json.dumps(analysis.to_dict()))
    assert data["white"] is True and len(data["acf"]) == 3 and len(data["ccf"][0]) == 12
    assert data["input_names"][:2] == ["dq1", "dq2"] and data["input_names"][6] == "ddq1"
    given = analyse_residuals(T_S, measured, np.zeros((T, 3)), q, dq, noise_std=1e-4)
    assert given.noise_source == "given" and np.allclose(given.noise_std, 1e-4)


def test_analysis_of_a_perfect_prediction() -> None:
    y = np.sin(T_S)[:, None] * np.ones((1, 3))
    still = np.zeros((T, 2))
    analysis = analyse_residuals(T_S, y, y, still, still)
    assert np.all(analysis.fit_percent == 100.0) and analysis.consistent_with_noise and not analysis.segments
    assert "exactly zero" in analysis.structure_description()
    json.dumps(analysis.to_dict(), allow_nan=False)


def test_analysis_is_fast() -> None:
    rng = np.random.default_rng(16)
    q, dq = multisine_joints(rng)
    measured = rng.normal(0.0, 1e-4, (T, 3)) + 3e-4 * np.sin(2 * np.pi * 0.2 * T_S)[:, None]
    analyse_residuals(T_S, measured, np.zeros((T, 3)), q, dq)
    times = []
    for _ in range(5):
        start = time.perf_counter()
        analyse_residuals(T_S, measured, np.zeros((T, 3)), q, dq)
        times.append(time.perf_counter() - start)
    assert min(times) < 0.2


def test_analysis_generic_channels_and_notes() -> None:
    rng = np.random.default_rng(17)
    t = np.cumsum(rng.uniform(0.015, 0.025, 400))
    q, dq = multisine_joints(rng, n_joints=2, t_s=t)
    names = [f"tau{i}" for i in range(1, 7)]
    analysis = analyse_residuals(t, rng.normal(size=(400, 6)), np.zeros((400, 6)), q, dq, channel_names=names, max_lag=200)
    assert analysis.channel_names == names and analysis.ccf.shape == (6, 4, 2 * 100 + 1)
    assert any("not uniform" in note for note in analysis.notes) and any("max_lag reduced" in note for note in analysis.notes)
    assert len(analysis.channel_rows()) == 6


def test_analysis_rejects_bad_input_with_named_messages() -> None:
    q, dq = np.zeros((100, 2)), np.zeros((100, 2))
    t, y = np.arange(100) * 0.1, np.zeros((100, 3))
    with pytest.raises(SpaceIdInputError, match="predicted"):
        analyse_residuals(t, y, y[:, :2], q, dq)
    with pytest.raises(SpaceIdInputError, match="channel_names"):
        analyse_residuals(t, y, y, q, dq, channel_names=("a", "b"))
    with pytest.raises(SpaceIdInputError, match="strictly increasing"):
        analyse_residuals(t[::-1], y, y, q, dq)
    with pytest.raises(SpaceIdInputError, match="confidence"):
        analyse_residuals(t, y, y, q, dq, confidence=1.5)
    with pytest.raises(SpaceIdInputError, match="noise_std"):
        analyse_residuals(t, y, y, q, dq, noise_std=[1.0, 0.0, 1.0])
    y_bad = y.copy()
    y_bad[3, 1] = np.nan
    with pytest.raises(SpaceIdInputError, match=r"measured.*finite.*\(3, 1\)"):
        analyse_residuals(t, y_bad, y, q, dq)
    with pytest.raises(SpaceIdInputError, match="dq"):
        analyse_residuals(t, y, y, q, dq[:50])


def test_noise_floor_uses_scipy_mad_with_the_hand_written_result() -> None:
    """scipy's median_abs_deviation replaced ``median(|d - median(d)|)``: the same numbers, bit for bit."""
    rng = np.random.default_rng(7)
    for rows in (5, 64, 3001):
        residual = rng.standard_t(3, size=(rows, 3)) + np.linspace(0.0, 1.0, rows)[:, None]
        d = np.diff(residual, n=2, axis=0)
        mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
        expected = mad * (1.0 / float(stats.norm.ppf(0.75))) / math.sqrt(math.comb(4, 2))
        np.testing.assert_array_equal(noise_floor_std(residual), expected)
