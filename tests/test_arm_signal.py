"""Signal processing: zero-phase filter, differentiation, resampling, decimation, the identification chain."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from spaceid_gym.arm import ArmLog, decimate, differentiate, lowpass_zero_phase, prepare_for_identification, resample_uniform
from spaceid_gym.errors import SpaceIdInputError

DT = 0.008  # the UR5 controller's 125 Hz


def _fit_sinusoid(t: np.ndarray, x: np.ndarray, f_hz: float) -> tuple[float, float]:
    """Amplitude and phase (rad) of the best fit ``A sin(w t + phi)``."""
    w = 2 * np.pi * f_hz
    (a, b), *_ = np.linalg.lstsq(np.column_stack([np.sin(w * t), np.cos(w * t)]), x, rcond=None)
    return float(np.hypot(a, b)), float(np.arctan2(b, a))


def test_lowpass_has_zero_phase_and_unit_gain_below_cutoff() -> None:
    t = np.arange(2000) * DT
    f, cutoff = 1.0, 8.0
    x = np.sin(2 * np.pi * f * t + 0.4)
    y = lowpass_zero_phase(x, DT, cutoff)
    inner = slice(200, -200)
    amplitude, phase = _fit_sinusoid(t[inner], y[inner], f)
    assert amplitude == pytest.approx(1.0, abs=1e-3)
    assert abs(phase - 0.4) / (2 * np.pi * f) < 1e-6  # delay below 1 us
    # the same Butterworth filter run causally (one pass) delays the sine by milliseconds: the check can fail
    causal = scipy.signal.sosfilt(scipy.signal.butter(4, cutoff, fs=1 / DT, output="sos"), x)
    assert abs(_fit_sinusoid(t[inner], causal[inner], f)[1] - 0.4) / (2 * np.pi * f) > 5e-3


def test_lowpass_removes_above_cutoff_and_filters_every_column() -> None:
    t = np.arange(1500) * DT
    slow, fast = np.sin(2 * np.pi * 0.5 * t), 0.5 * np.sin(2 * np.pi * 30.0 * t)
    x = np.stack([slow + fast, 2 * slow], axis=1)[:, :, None]  # (T, 2, 1): any trailing shape
    y = lowpass_zero_phase(x, DT, 5.0)
    assert y.shape == x.shape
    inner = slice(100, -100)
    # double-pass order-4 Butterworth: |H|^2 = 1 / (1 + (30/5)^8) = 6e-7 at 30 Hz
    np.testing.assert_allclose(y[inner, 0, 0], slow[inner], atol=1e-5)
    np.testing.assert_allclose(y[inner, 1, 0], 2 * slow[inner], atol=1e-5)


def test_lowpass_rejects_bad_arguments() -> None:
    x = np.zeros(100)
    with pytest.raises(SpaceIdInputError, match=r"cutoff_hz must be in \(0, Nyquist = 62.5 Hz\)"):
        lowpass_zero_phase(x, DT, 70.0)
    with pytest.raises(SpaceIdInputError, match="dt_s"):
        lowpass_zero_phase(x, 0.0, 5.0)
    with pytest.raises(SpaceIdInputError, match="at least 13 samples"):
        lowpass_zero_phase(x[:5], DT, 5.0)


def test_differentiate_sinusoid_to_the_stencils_accuracy() -> None:
    f = 2.0
    w, h = 2 * np.pi * f, DT
    t = np.arange(500) * h
    x = np.sin(w * t)
    d = differentiate(x, h)
    exact = w * np.cos(w * t)
    # inside: the 5-point stencil's exact response to a sinusoid, and its bound (w h)^4 / 30
    gain = (8 * np.sin(w * h) - np.sin(2 * w * h)) / (6 * h * w)
    np.testing.assert_allclose(d[2:-2], gain * exact[2:-2], atol=1e-9)
    assert np.max(np.abs(d[2:-2] - exact[2:-2])) <= 1.01 * (w * h) ** 4 / 30 * w
    # the ends: second-order formulas, error below (w h)^2 / 3 of the amplitude
    assert np.max(np.abs(d[[0, 1, -2, -1]] - exact[[0, 1, -2, -1]])) <= (w * h) ** 2 / 3 * w
    # plain central differences would miss the inner bound by far
    central = np.gradient(x, h)
    assert np.max(np.abs(central[2:-2] - exact[2:-2])) > 100 * (w * h) ** 4 / 30 * w
    with pytest.raises(SpaceIdInputError, match="at least 3 samples"):
        differentiate(x[:2], h)


def _log(t: np.ndarray, f_hz: float = 1.0, effort_kind: str = "current_A") -> ArmLog:
    """Two joints moving as sines; effort = 2 dq + 0.1 ddq (a linear 'dynamics')."""
    w = 2 * np.pi * f_hz
    q = np.stack([np.sin(w * t), 0.5 * np.sin(w * t + 1.0)], axis=1)
    dq = np.stack([w * np.cos(w * t), 0.5 * w * np.cos(w * t + 1.0)], axis=1)
    ddq = -(w**2) * q
    return ArmLog(t, q, dq, None, 2 * dq + 0.1 * ddq, effort_kind=effort_kind, name="sines")


def test_resample_uniform_is_exact_for_linear_signals_and_refuses_long_gaps() -> None:
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.0074, 0.0083, 300))
    t[150:] += 0.016  # a missing pair of samples
    log = ArmLog(t, np.stack([1 + 2 * t, -t], 1), np.stack([3 * t, t], 1), np.stack([t, t], 1), np.stack([5 - t, t], 1))
    out = resample_uniform(log, DT)
    np.testing.assert_allclose(np.diff(out.t_s), DT, rtol=1e-9)
    assert out.t_s[0] == t[0] and out.t_s[-1] <= t[-1] < out.t_s[-1] + DT
    np.testing.assert_allclose(out.q_rad, np.stack([1 + 2 * out.t_s, -out.t_s], 1), atol=1e-12)
    np.testing.assert_allclose(out.effort[:, 0], 5 - out.t_s, atol=1e-12)
    np.testing.assert_allclose(out.ddq_rad_s2[:, 1], out.t_s, atol=1e-12)
    with pytest.raises(SpaceIdInputError, match=r"gap of 2\d\.\d+ ms after t ="):
        resample_uniform(log, DT, max_gap_s=0.015)


def test_decimate_keeps_sample_times_and_removes_aliases() -> None:
    t = 0.5 + np.arange(1200) * DT
    log = _log(t)
    plain = decimate(log, 4, antialias=False)
    np.testing.assert_array_equal(plain.t_s, t[::4])
    np.testing.assert_array_equal(plain.q_rad, log.q_rad[::4])
    # a 20 Hz component would alias at the new 31.25 Hz rate; the anti-alias filter (7.8 Hz) removes it
    noisy = ArmLog(t, log.q_rad + 0.1 * np.sin(2 * np.pi * 20 * t)[:, None], log.dq_rad_s, None, log.effort)
    clean = decimate(noisy, 4)
    np.testing.assert_array_equal(clean.t_s, t[::4])
    np.testing.assert_allclose(clean.q_rad[30:-30], log.q_rad[::4][30:-30], atol=1e-4)
    assert decimate(log, 1) is log
    with pytest.raises(SpaceIdInputError, match="factor must be an integer"):
        decimate(log, 0)
    jittered = ArmLog(t + np.random.default_rng(1).uniform(0, 1e-3, t.size), log.q_rad, log.dq_rad_s, None, log.effort)
    with pytest.raises(SpaceIdInputError, match="not uniformly sampled"):
        decimate(jittered, 2)


@pytest.mark.parametrize("jitter", [False, True])
def test_prepare_for_identification_chain(jitter) -> None:
    rng = np.random.default_rng(2)
    t = np.arange(3000) * DT
    if jitter:
        t = t + rng.uniform(-4e-4, 4e-4, t.size)
    clean = _log(t)
    dq_noisy = clean.dq_rad_s + rng.normal(0, 1e-3, clean.dq_rad_s.shape)
    noisy = ArmLog(t, clean.q_rad, dq_noisy, None, dq_noisy.copy(), effort_kind="current_A", name="sines")
    cutoff, factor = 5.0, 3
    out = prepare_for_identification(noisy, cutoff_hz=cutoff, decimate_factor=factor)
    # time: uniform at factor * dt, starting after the dropped edge (3 / cutoff)
    dt = np.median(np.diff(t))
    n_edge = int(np.ceil(3.0 / cutoff / dt))
    np.testing.assert_allclose(np.diff(out.t_s), factor * dt, rtol=1e-9)
    assert out.t_s[0] == pytest.approx(t[0] + n_edge * dt, abs=1e-12)
    assert out.effort_kind == "current_A" and out.name == "sines"
    # effort and rate went through the same filter (here they are the same signal)
    np.testing.assert_allclose(out.effort, out.dq_rad_s, atol=1e-12)
    # the acceleration from the filtered rate: exact ddq = -w^2 q, within 0.2 % of its amplitude
    # (measured 0.04 %, 0.07 % with jitter; differentiating the unfiltered rate noise alone gives ~0.8 %)
    exact = _log(out.t_s)
    w = 2 * np.pi
    assert np.max(np.abs(out.ddq_rad_s2 + w**2 * exact.q_rad)) < 2e-3 * w**2
    # angles: filtered without loss; with jitter, linear interpolation errs by up to (w dt)^2 / 8 = 3.2e-4
    np.testing.assert_allclose(out.q_rad, exact.q_rad, atol=5e-4 if jitter else 1e-5)


def test_prepare_for_identification_rejects_a_cutoff_that_decimation_would_alias() -> None:
    log = _log(np.arange(500) * DT)
    with pytest.raises(SpaceIdInputError, match=r"cutoff_hz = 10.0 must be in \(0, 7.8125\] Hz"):
        prepare_for_identification(log, cutoff_hz=10.0, decimate_factor=4)
    with pytest.raises(SpaceIdInputError, match="leaves nothing"):
        prepare_for_identification(log.select(slice(0, 60)), cutoff_hz=2.0)
