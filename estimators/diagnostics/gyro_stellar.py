"""Gyro-stellar consistency: does the integrated gyro rotate the base as the star tracker says it did?

A log with attitude quaternions (a star tracker) carries a second, model-free measurement of the base's
rotation. Over an interval ``[t_s, t_e]`` the gyro's rates, integrated on SO(3), give a rotation ``G``; the
star tracker gives ``S = R(t_s)^T R(t_e)``. Their mismatch, per unit time,

    e = log(S^T G) / (t_e - t_s)        (rad/s, base body frame),

is noise for a perfect gyro whatever the dynamics (momentum, torques, slosh, payload all rotate the base
*really*), and is the interval's mean of ``omega_gyro - omega_base`` for a gyro that is biased,
mis-scaled or late. This separates a gyro bias from a system momentum, which this robot's gyro rates
alone barely tell apart (both add a nearly constant rate).

Intervals are disjoint (no shared star-tracker sample), so their errors are independent; their noise
``sqrt(2) sigma_st / dt_int`` (star tracker) and ``ARW / sqrt(dt_int)`` (gyro) is estimated from the
spread of ``e`` (median absolute deviation), so no noise level needs to be known.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from spaceid_gym.log import MeasurementLog
from spaceid_gym.sim.lie import matrix_from_quat, so3_exp

FloatArray = NDArray[np.float64]

#: default interval length (s): long enough that the star tracker's noise averages down, short enough for many intervals
DEFAULT_INTERVAL_S = 1.0


@dataclass(frozen=True)
class GyroStellarCheck:
    """The gyro's rotation against the star tracker's over disjoint intervals of one log.

    Attributes:
        rate_error: ``e`` per interval (J, 3), rad/s, base body frame.
        std: per-axis noise std of ``e`` (3,), rad/s (robust estimate from the spread).
        bounds: sample index ``(start, end)`` of each interval (J, 2).
        t_s: the log's sample times (T,), s.
    """

    rate_error: FloatArray
    std: FloatArray
    bounds: NDArray[np.intp]
    t_s: FloatArray

    @classmethod
    def from_log(cls, log: MeasurementLog, interval_s: float = DEFAULT_INTERVAL_S) -> GyroStellarCheck | None:
        """The check on ``log``; ``None`` when the log has no attitude or is shorter than four intervals."""
        if log.quat_base_to_inertial_wxyz is None:
            return None
        t = np.asarray(log.t_s, dtype=float)
        step = max(round(interval_s / float(np.median(np.diff(t)))), 1)
        starts = np.arange(0, len(t) - step, step + 1)  # disjoint: the next interval starts one sample later
        if len(starts) < 4:
            return None
        bounds = np.stack((starts, starts + step), axis=1)
        omega = np.asarray(log.omega_base_body_rad_s, dtype=float)
        quat = np.asarray(log.quat_base_to_inertial_wxyz, dtype=float)
        errors = np.empty((len(bounds), 3))
        for j, (s, e) in enumerate(bounds):
            gyro = np.eye(3)
            for k in range(s, e):
                gyro = gyro @ so3_exp(0.5 * (omega[k] + omega[k + 1]) * (t[k + 1] - t[k]))
            star = matrix_from_quat(quat[s]).T @ matrix_from_quat(quat[e])
            errors[j] = Rotation.from_matrix(star.T @ gyro).as_rotvec() / (t[e] - t[s])
        deviation = np.abs(errors - np.median(errors, axis=0))
        std = 1.4826 * np.median(deviation, axis=0)
        return cls(errors, np.maximum(std, 1e-300), bounds, t)

    def predicted(self, gyro_error: FloatArray) -> FloatArray:
        """Expected ``e`` (J, 3) for a model's ``omega_gyro - omega_base`` (T, 3): its trapezoidal mean per interval."""
        t = self.t_s
        out = np.empty((len(self.bounds), 3))
        for j, (s, e) in enumerate(self.bounds):
            segment = gyro_error[s : e + 1]
            out[j] = np.trapezoid(segment, t[s : e + 1], axis=0) / (t[e] - t[s])
        return out

    def chi2(self, gyro_error: FloatArray) -> float:
        """``sum ((e - predicted) / std)^2`` over intervals and axes: ~ chi2(3J) when the model's gyro is right."""
        z = (self.rate_error - self.predicted(gyro_error)) / self.std
        return float(np.sum(z * z))

    @property
    def n_values(self) -> int:
        """3J, the number of values in :meth:`chi2`."""
        return self.rate_error.size

    def mean_rate_error(self) -> tuple[FloatArray, FloatArray]:
        """The mean of ``e`` (3,) (a constant gyro bias shows here) and its standard error (3,), rad/s."""
        return self.rate_error.mean(axis=0), self.std / np.sqrt(len(self.rate_error))
