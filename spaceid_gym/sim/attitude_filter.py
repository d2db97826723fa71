"""On-board attitude filter: the ``fused`` attitude source of :class:`~spaceid_gym.sim.sensors.SensorModel`.

A multiplicative complementary filter on SO(3), run sample by sample on what the spacecraft
measures: the gyro rate (base body frame) and the star tracker's quaternion. It keeps an estimate
``q_hat`` (base to inertial, ``[w, x, y, z]``) and at each sample ``k`` (time ``t_k``):

1. **propagate** with the measured rate, averaged over the interval (trapezoid rule):
   ``q_hat <- q_hat (x) exp(dt (omega_{k-1} + omega_k) / 2)``, ``dt = t_k - t_{k-1}``;
2. **correct** toward the star tracker ``q_st``: ``delta = log(q_hat^-1 (x) q_st)`` (a rotation
   vector in the body frame, rad), ``q_hat <- q_hat (x) exp(K delta)`` with the gain ``0 <= K <= 1``.

The first sample takes the star tracker's quaternion. For small errors, per axis, the error
``e_k = (1 - K) (e_{k-1} + w_k) + K v_k`` (``w_k`` the integrated gyro noise over the interval,
variance ``q = ARW^2 dt``; ``v_k`` the star-tracker noise, variance ``r``): the output error is the
star tracker's noise low-passed with the time constant ``tau = -dt / ln(1 - K)`` plus the gyro's
random walk, pulled back with the same time constant, so it is correlated from sample to sample
(lag-1 autocorrelation about ``1 - K``) and bounded. Its steady-state variance is
``P = ((1 - K)^2 q + K^2 r) / (1 - (1 - K)^2)`` (:func:`steady_state_error_std_rad`).

Gain (:func:`filter_gain`): by default the steady-state Kalman gain of that scalar model,
``P- = (q + sqrt(q^2 + 4 q r)) / 2``, ``K = P- / (P- + r)``, the gain that minimises ``P``: with
the default sensors at 50 Hz (LN-200S-class gyro, 5 arcsec star tracker) ``K = 0.11``,
``tau = 0.17 s`` and an error of 8.1e-6 rad (1.7 arcsec) per axis, a third of the star tracker's.
A given time constant sets ``K = 1 - exp(-dt / tau)`` instead; a long one lets the gyro's random
walk dominate (10 s: about ``ARW sqrt(tau / 2)`` = 4.6e-5 rad, more than the star tracker alone).
The filter estimates no gyro bias: a biased gyro shifts the estimate by about ``bias * tau``.
The gyro samples are instantaneous rates (the simulator's gyro model), not angle increments, so the
trapezoid rule also leaves an integration error where the rate turns abruptly (the arm's servo
switching): up to 7e-7 rad per sample for paper6 under rate commands stepped every second, part of the
``fused`` error that the small-error model above leaves out.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.sim.lie import quat_from_rotation_vector, quat_multiply


def filter_gain(
    sample_period_s: float, gyro_arw_rad_sqrt_s: float, star_tracker_std_rad: float, time_constant_s: float | None = None
) -> float:
    """The filter's correction gain ``K`` per sample (see the module docstring).

    Args:
        sample_period_s: the filter's update period ``dt`` (s), > 0.
        gyro_arw_rad_sqrt_s: angle random walk of the gyro it integrates (rad/sqrt(s)), >= 0.
        star_tracker_std_rad: star-tracker noise per axis (rad), >= 0.
        time_constant_s: the correction time constant ``tau`` (s), > 0; ``None`` for the
            steady-state Kalman gain of the two noise levels (1 if the star tracker is exact, 0 if
            the gyro is and the star tracker is not).
    """
    if not (math.isfinite(sample_period_s) and sample_period_s > 0.0):
        raise SpaceIdInputError(f"attitude filter: sample period must be a positive number of seconds, got {sample_period_s!r}")
    if time_constant_s is not None:
        if not (math.isfinite(time_constant_s) and time_constant_s > 0.0):
            raise SpaceIdInputError(
                f"attitude filter: time constant must be a positive number of seconds, got {time_constant_s!r}"
            )
        return -math.expm1(-sample_period_s / time_constant_s)
    q = gyro_arw_rad_sqrt_s**2 * sample_period_s
    r = star_tracker_std_rad**2
    if r == 0.0:
        return 1.0
    prior = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))
    return prior / (prior + r)


def filter_time_constant_s(gain: float, sample_period_s: float) -> float:
    """The time constant ``tau = -dt / ln(1 - K)`` (s) of a gain: ``inf`` for ``K = 0``, 0 for ``K = 1``."""
    if gain <= 0.0:
        return math.inf
    if gain >= 1.0:
        return 0.0
    return -sample_period_s / math.log1p(-gain)


def steady_state_error_std_rad(
    gain: float, sample_period_s: float, gyro_arw_rad_sqrt_s: float, star_tracker_std_rad: float
) -> float:
    """Steady-state std (rad, per axis) of the filter's attitude error, small-error model of the module docstring.

    ``inf`` for ``K = 0`` with a noisy gyro (pure integration drifts without bound).
    """
    q = gyro_arw_rad_sqrt_s**2 * sample_period_s
    r = star_tracker_std_rad**2
    keep = (1.0 - gain) ** 2
    if keep >= 1.0:
        return math.inf if q > 0.0 else star_tracker_std_rad
    return math.sqrt((keep * q + gain * gain * r) / (1.0 - keep))


class AttitudeFilter:
    """The multiplicative complementary filter of the module docstring, one :meth:`update` per sample.

    Args:
        gain: correction gain ``K`` per sample, in [0, 1] (see :func:`filter_gain`).
    """

    def __init__(self, gain: float) -> None:
        if not (math.isfinite(gain) and 0.0 <= gain <= 1.0):
            raise SpaceIdInputError(f"attitude filter: gain must be in [0, 1], got {gain!r}")
        self.gain = float(gain)
        self._quat_wxyz: FloatArray | None = None
        self._t_s = 0.0
        self._omega_body_rad_s = np.zeros(3)

    def update(self, t_s: float, omega_body_rad_s: FloatArray, quat_star_tracker_wxyz: FloatArray) -> FloatArray:
        """The estimate at ``t_s`` (base to inertial, ``[w, x, y, z]``, ``w >= 0``) after this sample.

        Args:
            t_s: sample time (s). The first sample, or one earlier than the last, (re)starts the
                filter at the star tracker's quaternion.
            omega_body_rad_s: measured base rate at ``t_s``, base body frame (3,), rad/s.
            quat_star_tracker_wxyz: the star tracker's attitude at ``t_s``, unit quaternion (4,).
        """
        omega = np.asarray(omega_body_rad_s, dtype=float)
        measured = np.asarray(quat_star_tracker_wxyz, dtype=float)
        if self._quat_wxyz is None or t_s < self._t_s:
            estimate = measured / np.linalg.norm(measured)
        else:
            estimate = _filter_step(self._quat_wxyz, self._omega_body_rad_s, omega, t_s - self._t_s, measured, self.gain)
        if estimate[0] < 0.0:
            estimate = -estimate
        self._quat_wxyz, self._t_s, self._omega_body_rad_s = estimate, float(t_s), omega.copy()
        return estimate.copy()


@njit(cache=True)
def _rotation_vector_from_quat(quat: FloatArray) -> FloatArray:
    """Rotation vector (rad) of a unit quaternion ``[w, x, y, z]``, the shorter way round (angle <= pi)."""
    w, v = quat[0], quat[1:].copy()
    if w < 0.0:
        w, v = -w, -v
    norm_v = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if norm_v < 1e-12:
        return 2.0 * v / w
    return (2.0 * math.atan2(norm_v, w) / norm_v) * v


@njit(cache=True)
def _filter_step(
    estimate: FloatArray, omega_before: FloatArray, omega: FloatArray, dt_s: float, measured: FloatArray, gain: float
) -> FloatArray:
    """One propagation (trapezoid rate over ``dt_s``) and correction (``gain`` toward ``measured``), normalised."""
    propagated = quat_multiply(estimate, quat_from_rotation_vector(0.5 * dt_s * (omega_before + omega)))
    inverse = np.array([propagated[0], -propagated[1], -propagated[2], -propagated[3]])
    delta = _rotation_vector_from_quat(quat_multiply(inverse, measured))
    corrected = quat_multiply(propagated, quat_from_rotation_vector(gain * delta))
    return corrected / math.sqrt(np.sum(corrected * corrected))
