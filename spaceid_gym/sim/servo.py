"""Joint rate servo with rate and acceleration limits, integrated in closed form.

Each arm joint follows its commanded rate ``u`` (clipped to the joint's rate limit) through a
first-order rate loop with gain ``k`` (1/s) whose output acceleration is limited to ``a_max``:

    ddq = clip(k (u - dq), -a_max, a_max).

This is the behaviour of a geared space-manipulator joint under a high-gain rate controller with
an acceleration (current) limit. Within a control period ``u`` is constant and the motion has a
closed form: constant acceleration until ``|u - dq| = a_max / k`` (the *switch time*), then an
exponential approach to ``u``. The simulator splits its integration steps at switch times so that
everything it integrates is smooth.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from spaceid_gym.arrays import FloatArray


@dataclass(frozen=True)
class RateServo:
    """Acceleration-limited first-order rate servo for n joints.

    Attributes:
        gain_per_s: loop gain ``k`` per joint (1/s), shape (n,).
        accel_limit_rad_s2: acceleration limit ``a_max`` per joint (rad/s^2), shape (n,).
        rate_limit_rad_s: commanded-rate limit per joint (rad/s), shape (n,).
    """

    gain_per_s: FloatArray
    accel_limit_rad_s2: FloatArray
    rate_limit_rad_s: FloatArray

    def limit_command(
        self, u_rad_s: FloatArray, q_rad: FloatArray, q_lower: FloatArray, q_upper: FloatArray, period_s: float
    ) -> FloatArray:
        """Clip commanded rates to the rate limit and to a braking envelope near the joint limits.

        A command held for ``period_s`` towards a limit at distance ``d`` is capped so that moving
        for ``T = period + 4/k`` and then braking with half the acceleration authority
        ``a = a_max / 2`` stays inside: ``u T + u^2 / (2 a) <= d``, i.e.
        ``u <= a (sqrt(T^2 + 2 d / a) - T)``. Close to the limit this is ``u = d / T``, and with the
        servo's first-order lag the approach ``s^2 + k s + k / T`` is critically damped or slower
        for ``T >= 4/k``: the joint creeps to the limit without overshoot. A joint already past a
        limit is commanded back. Commands held for long periods can still overshoot slightly
        (about 1e-7 rad at 0.2 s, 4e-4 rad at 1 s; none at the default 0.02 s).
        """
        return _limit_command(
            np.asarray(u_rad_s, dtype=float),
            q_rad,
            q_lower,
            q_upper,
            self.rate_limit_rad_s,
            self.accel_limit_rad_s2,
            self.gain_per_s,
            period_s,
        )

    def switch_times(self, dq0: FloatArray, u: FloatArray) -> FloatArray:
        """Time (s) at which each joint leaves acceleration saturation; 0 if it is not saturated."""
        return _switch_times(dq0, u, self.accel_limit_rad_s2, self.gain_per_s)

    def motion(
        self, q0: FloatArray, dq0: FloatArray, u: FloatArray, t_s: Sequence[float] | FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Closed-form joint motion under a constant command.

        Args:
            q0, dq0: joint angles (rad) and rates (rad/s) at t = 0, shape (n,).
            u: commanded rates (already limited), shape (n,).
            t_s: times since the command was applied, m values, each >= 0.

        Returns:
            ``(q, dq, ddq)``, each shape (m, n).
        """
        return _motion(q0, dq0, u, self.accel_limit_rad_s2, self.gain_per_s, np.asarray(t_s, dtype=float))


# The servo's arithmetic is compiled with numba: it runs every env step on a handful of joints,
# where numpy's per-call overhead would dominate.


@njit(cache=True)
def _limit_command(
    u: FloatArray, q: FloatArray, lo: FloatArray, hi: FloatArray, rate: FloatArray, acc: FloatArray, k: FloatArray, period: float
) -> FloatArray:
    out = np.empty_like(u)
    for j in range(u.shape[0]):
        a = 0.5 * acc[j]
        hold = period + 4.0 / k[j]
        up = -rate[j] if q[j] > hi[j] else a * (math.sqrt(hold * hold + 2.0 * max(hi[j] - q[j], 0.0) / a) - hold)
        down = -rate[j] if q[j] < lo[j] else a * (math.sqrt(hold * hold + 2.0 * max(q[j] - lo[j], 0.0) / a) - hold)
        out[j] = min(max(u[j], -rate[j], -down), rate[j], up)
    return out


@njit(cache=True)
def _switch_times(dq0: FloatArray, u: FloatArray, acc: FloatArray, k: FloatArray) -> FloatArray:
    return np.maximum((np.abs(u - dq0) - acc / k) / acc, 0.0)


@njit(cache=True)
def _motion(
    q0: FloatArray, dq0: FloatArray, u: FloatArray, acc: FloatArray, k: FloatArray, times: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    m, n = times.shape[0], q0.shape[0]
    q, dq, ddq = np.empty((m, n)), np.empty((m, n)), np.empty((m, n))
    for j in range(n):
        e0 = u[j] - dq0[j]
        t1 = max((abs(e0) - acc[j] / k[j]) / acc[j], 0.0)
        # error at the switch; while saturated k * e1 = +-a_max, so one formula covers both phases
        e1 = math.copysign(acc[j] / k[j], e0) if t1 > 0.0 else e0
        k_e1 = k[j] * e1
        for i in range(m):
            tc = min(times[i], t1)  # time spent saturated
            tau = times[i] - tc  # time spent in the exponential phase
            decay = math.exp(-k[j] * tau)
            q[i, j] = q0[j] + (dq0[j] + 0.5 * k_e1 * tc) * tc + u[j] * tau - e1 * (1.0 - decay) / k[j]
            dq[i, j] = dq0[j] + k_e1 * tc + e1 * (1.0 - decay)
            ddq[i, j] = k_e1 * decay
    return q, dq, ddq


def default_servo(rate_limit_rad_s: FloatArray, ramp_time_s: float = 0.5, gain_per_s: float = 10.0) -> RateServo:
    """Servo whose acceleration limit reaches the rate limit in ``ramp_time_s`` (default 0.5 s).

    The gain (10 1/s, a 0.1 s time constant) and the 0.5 s ramp are those of geared space
    manipulator joints moving at a few degrees per second; tests check that the torques this
    motion needs stay inside the URDF effort limits.
    """
    rate = np.asarray(rate_limit_rad_s, dtype=float)
    return RateServo(np.full_like(rate, gain_per_s), rate / ramp_time_s, rate)
