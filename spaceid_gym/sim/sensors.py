"""Sensor models: gyro, joint encoders, joint-rate sensors, star tracker.

Default noise levels are those of hardware classes flown on spacecraft and space manipulators:

* **Gyro** (base angular rate, base body frame): a navigation-grade fibre-optic gyro of the
  LN-200S class, angle random walk 0.07 deg/sqrt(h) = 2.04e-5 rad/sqrt(s). A rate output
  averaged over a period ``dt`` carries white noise of standard deviation ``ARW / sqrt(dt)``
  (1.44e-4 rad/s at 50 Hz); the model adds that noise to the instantaneous rate at the sample
  time. An optional constant bias (rad/s), default zero, and an optional scale-factor/misalignment
  matrix ``E``: ``omega_meas = (I + E) omega + bias + noise`` (default none, ``E = 0``).
* **Joint encoders**: 20-bit absolute encoders on the joint output (resolution 6.0e-6 rad); the
  default white noise 5e-6 rad covers quantisation and electronics.
* **Joint-rate sensors** (resolver/tachometer rate): white noise density 1.4e-5 rad/s/sqrt(Hz),
  1e-4 rad/s at 50 Hz.
* **Star tracker** (base attitude): 5 arcsec (2.4e-5 rad) per axis, applied as a small random
  rotation of the true attitude.

**Attitude source** (:data:`ATTITUDE_SOURCES`, ``SensorModel.attitude_source``): what the log's
quaternion columns hold.

* ``star_tracker`` (default): the star tracker's white noise of ``attitude_noise_rad`` per axis.
* ``exact``: the true attitude, noise-free (as an on-board filter's smoothed output is often
  logged by other simulators).
* ``fused``: the output of an on-board attitude filter fed by the (noisy) gyro and the (noisy)
  star tracker, run sample by sample (:mod:`spaceid_gym.sim.attitude_filter`): its error is the
  star tracker's noise low-passed plus the gyro's integrated noise, correlated in time.
* ``none``: no attitude measurement; the log has no quaternion columns
  (``quat_base_to_inertial_wxyz`` is ``None``).

**Noise scale** (``SensorModel.noise_scale``): one factor on every noise standard deviation (gyro,
encoders, joint rates, star tracker), e.g. 0.3 to 3 for sensors better or worse than the defaults;
the gyro bias and scale factor are not noise and are not scaled.

All draws come from the generator passed in (the env's ``np_random``); :meth:`SensorModel.noise_free`
gives exact measurements.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numba import njit

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.sim.attitude_filter import AttitudeFilter, filter_gain, filter_time_constant_s, steady_state_error_std_rad
from spaceid_gym.sim.lie import quat_from_matrix, quat_from_rotation_vector, quat_multiply
from spaceid_gym.sim.state import FreeFloatingState

#: one arcsecond in rad
ARCSEC_RAD = math.pi / (180.0 * 3600.0)

#: what the log's attitude columns hold (see the module docstring)
ATTITUDE_SOURCES = ("none", "star_tracker", "exact", "fused")


class Sampler(Protocol):
    """``sample(state, rng, gyro_state=None) -> Measurement``, see :meth:`SensorModel.sampler`."""

    def __call__(
        self, state: FreeFloatingState, rng: np.random.Generator, gyro_state: FreeFloatingState | None = None
    ) -> Measurement: ...


@dataclass(frozen=True)
class SensorModel:
    """Noise levels of the robot's sensors (see the module docstring for the defaults' sources).

    Attributes:
        gyro_arw_rad_sqrt_s: gyro angle random walk (rad/sqrt(s)); per-sample std ``ARW/sqrt(dt)``.
        gyro_bias_rad_s: constant gyro bias, base body frame, shape (3,).
        joint_angle_noise_rad: encoder white-noise std (rad).
        joint_rate_noise_density_rad_s_sqrt_hz: joint-rate white-noise density; std ``d/sqrt(dt)``.
        attitude_noise_rad: star-tracker noise per axis (rad).
        gyro_scale_misalignment: ``E`` (3, 3) in ``omega_meas = (I + E) omega + bias`` (diagonal:
            scale-factor errors, off-diagonal: misalignment), ``None`` for none.
        attitude_source: one of :data:`ATTITUDE_SOURCES`: ``star_tracker`` (default), ``exact``,
            ``fused`` or ``none`` (see the module docstring).
        noise_scale: factor (> 0) on every noise standard deviation (gyro, encoders, joint rates,
            star tracker); the ``*_std_*`` methods include it, the fields above do not.
        attitude_filter_time_constant_s: correction time constant (s) of the ``fused`` source's
            filter; ``None`` (default) for the steady-state Kalman gain of the gyro and star-tracker
            noise (:func:`~spaceid_gym.sim.attitude_filter.filter_gain`).
    """

    gyro_arw_rad_sqrt_s: float = 0.07 * math.pi / 180.0 / 60.0
    gyro_bias_rad_s: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))
    joint_angle_noise_rad: float = 5e-6
    joint_rate_noise_density_rad_s_sqrt_hz: float = 1.4e-5
    attitude_noise_rad: float = 5.0 * ARCSEC_RAD
    gyro_scale_misalignment: tuple[tuple[float, float, float], ...] | None = None
    attitude_source: str = "star_tracker"
    noise_scale: float = 1.0
    attitude_filter_time_constant_s: float | None = None

    def __post_init__(self) -> None:
        for name in (
            "gyro_arw_rad_sqrt_s",
            "joint_angle_noise_rad",
            "joint_rate_noise_density_rad_s_sqrt_hz",
            "attitude_noise_rad",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise SpaceIdInputError(f"sensor noise '{name}': expected a finite value >= 0, got {value!r}")
        bias = np.asarray(self.gyro_bias_rad_s, dtype=float)
        if bias.shape != (3,) or not np.all(np.isfinite(bias)):
            raise SpaceIdInputError(f"sensor 'gyro_bias_rad_s': expected 3 finite numbers (rad/s), got {self.gyro_bias_rad_s!r}")
        if self.gyro_scale_misalignment is not None:
            scale = np.asarray(self.gyro_scale_misalignment, dtype=float)
            if scale.shape != (3, 3) or not np.all(np.isfinite(scale)):
                raise SpaceIdInputError(
                    f"sensor 'gyro_scale_misalignment': expected a 3x3 matrix of finite numbers, got {self.gyro_scale_misalignment!r}"
                )
        if self.attitude_source not in ATTITUDE_SOURCES:
            raise SpaceIdInputError(
                f"sensor 'attitude_source': expected one of {', '.join(ATTITUDE_SOURCES)}, got {self.attitude_source!r}"
            )
        if not (np.isfinite(self.noise_scale) and self.noise_scale > 0.0):
            raise SpaceIdInputError(f"sensor 'noise_scale': expected a finite factor > 0, got {self.noise_scale!r}")
        tau = self.attitude_filter_time_constant_s
        if tau is not None and not (np.isfinite(tau) and tau > 0.0):
            raise SpaceIdInputError(
                f"sensor 'attitude_filter_time_constant_s': expected a finite time > 0 s or None, got {tau!r}"
            )

    @classmethod
    def noise_free(cls) -> SensorModel:
        """Exact measurements (no noise, no bias)."""
        return cls(0.0, (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)

    def gyro_std_rad_s(self, dt_s: float) -> float:
        """Per-sample gyro noise std at sample period ``dt_s`` (rad/s), noise scale included."""
        return self.noise_scale * self.gyro_arw_rad_sqrt_s / math.sqrt(dt_s)

    def joint_angle_std_rad(self) -> float:
        """Encoder noise std (rad), noise scale included."""
        return self.noise_scale * self.joint_angle_noise_rad

    def joint_rate_std_rad_s(self, dt_s: float) -> float:
        """Per-sample joint-rate noise std at sample period ``dt_s`` (rad/s), noise scale included."""
        return self.noise_scale * self.joint_rate_noise_density_rad_s_sqrt_hz / math.sqrt(dt_s)

    def star_tracker_std_rad(self) -> float:
        """Star-tracker noise std per axis (rad), noise scale included (what ``star_tracker`` logs, what ``fused`` is fed)."""
        return self.noise_scale * self.attitude_noise_rad

    def attitude_filter_gain(self, dt_s: float) -> float:
        """Correction gain per sample of the ``fused`` source's filter at sample period ``dt_s``."""
        return filter_gain(
            dt_s, self.noise_scale * self.gyro_arw_rad_sqrt_s, self.star_tracker_std_rad(), self.attitude_filter_time_constant_s
        )

    def as_dict(self, dt_s: float) -> dict[str, object]:
        """Noise settings with the per-sample standard deviations at ``dt_s`` (for truth.json).

        The field names hold the settings as configured; the ``*_std_*`` entries are the standard
        deviations applied (``noise_scale`` included). ``attitude_source`` says what the quaternion
        columns hold; ``star_tracker_std_rad`` is there when a star tracker is used
        (``star_tracker``, ``fused``); ``fused`` adds its filter's gain, time constant (``None`` for
        a gain of 0: an exact gyro and the default gain) and predicted steady-state error std per
        axis (``attitude_filter_*``).
        """
        settings: dict[str, object] = {
            "gyro_arw_rad_sqrt_s": self.gyro_arw_rad_sqrt_s,
            "gyro_std_rad_s": self.gyro_std_rad_s(dt_s),
            "gyro_bias_rad_s": list(self.gyro_bias_rad_s),
            "joint_angle_noise_rad": self.joint_angle_noise_rad,
            "joint_angle_std_rad": self.joint_angle_std_rad(),
            "joint_rate_noise_density_rad_s_sqrt_hz": self.joint_rate_noise_density_rad_s_sqrt_hz,
            "joint_rate_std_rad_s": self.joint_rate_std_rad_s(dt_s),
            "attitude_noise_rad": self.attitude_noise_rad,
            "attitude_source": self.attitude_source,
            "noise_scale": self.noise_scale,
            "sample_period_s": dt_s,
        }
        if self.attitude_source in ("star_tracker", "fused"):
            settings["star_tracker_std_rad"] = self.star_tracker_std_rad()
        if self.attitude_source == "fused":
            gain = self.attitude_filter_gain(dt_s)
            arw = self.noise_scale * self.gyro_arw_rad_sqrt_s
            settings["attitude_filter_gain"] = gain
            tau = filter_time_constant_s(gain, dt_s)
            settings["attitude_filter_time_constant_s"] = tau if math.isfinite(tau) else None  # None: never corrects
            settings["attitude_filter_error_std_rad"] = steady_state_error_std_rad(gain, dt_s, arw, self.star_tracker_std_rad())
        if self.gyro_scale_misalignment is not None:
            settings["gyro_scale_misalignment"] = self.gyro_scale_misalignment
        return settings

    def sampler(self, n_joints: int, dt_s: float) -> Sampler:
        """A function that measures a state at sample period ``dt_s``, drawing from the given generator.

        ``sample(state, rng, gyro_state=None)``: the gyro measures ``gyro_state`` when given (the
        state at an earlier time, for a gyro that lags the encoders), else ``state``. Each sample
        draws ``2 n + 6`` standard normals in a fixed order (encoders, joint rates, gyro, star
        tracker), whatever the attitude source (``exact`` and ``none`` leave the star tracker's
        three unused), so a seeded generator reproduces the same noise and gives the same gyro,
        encoder and joint-rate noise with every source.

        The ``fused`` source's filter lives in the returned function: one sampler measures one
        window, its samples in time order (a sample earlier than the last restarts the filter).
        """
        n = n_joints
        scale = np.concatenate(
            (
                np.full(n, self.joint_angle_std_rad()),
                np.full(n, self.joint_rate_std_rad_s(dt_s)),
                np.full(3, self.gyro_std_rad_s(dt_s)),
            )
        )
        bias = np.concatenate((np.zeros(2 * n), np.asarray(self.gyro_bias_rad_s, dtype=float)))
        source = self.attitude_source
        attitude_std = 0.0 if source == "exact" else self.star_tracker_std_rad()
        attitude_filter = AttitudeFilter(self.attitude_filter_gain(dt_s)) if source == "fused" else None
        gain = None if self.gyro_scale_misalignment is None else np.eye(3) + np.asarray(self.gyro_scale_misalignment, dtype=float)

        def sample(
            state: FreeFloatingState, rng: np.random.Generator, gyro_state: FreeFloatingState | None = None
        ) -> Measurement:
            twist = (state if gyro_state is None else gyro_state).v_base_body
            if gain is not None:  # only the angular part is measured
                twist = np.concatenate((twist[:3], gain @ twist[3:]))
            y, quat = _noisy(
                state.q_rad,
                state.dq_rad_s,
                twist,
                state.rot_wb,
                rng.standard_normal(2 * n + 6),
                scale,
                bias,
                attitude_std,
            )
            if source == "none":
                return Measurement(y[:n], y[n : 2 * n], y[2 * n :], None)
            if attitude_filter is not None:
                quat = attitude_filter.update(state.t_s, y[2 * n :], quat)
            return Measurement(y[:n], y[n : 2 * n], y[2 * n :], quat)

        return sample


@njit(cache=True)
def _noisy(
    q: FloatArray,
    dq: FloatArray,
    twist: FloatArray,
    rot_wb: FloatArray,
    noise: FloatArray,
    scale: FloatArray,
    bias: FloatArray,
    attitude_std: float,
) -> tuple[FloatArray, FloatArray]:
    """``[q, dq, omega] + bias + scale * noise`` and the attitude quaternion rotated by star-tracker noise."""
    n = q.shape[0]
    y = np.empty(2 * n + 3)
    y[:n], y[n : 2 * n], y[2 * n :] = q, dq, twist[3:]
    y += bias + scale * noise[: 2 * n + 3]
    return y, quat_multiply(quat_from_matrix(rot_wb), quat_from_rotation_vector(attitude_std * noise[2 * n + 3 :]))


@dataclass(frozen=True)
class Measurement:
    """One sample: joint angles/rates (n,), gyro rate (3,, base body), attitude quaternion [w,x,y,z] (``None``: not measured)."""

    q_rad: FloatArray
    dq_rad_s: FloatArray
    omega_base_body_rad_s: FloatArray
    quat_base_to_inertial_wxyz: FloatArray | None
