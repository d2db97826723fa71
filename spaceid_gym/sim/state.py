"""The free-floating robot's instantaneous state: what the simulator advances and the sensors measure.

Frames and units: the base attitude ``rot_wb`` rotates base-frame vectors into the inertial frame; the base twist
``v_base_body`` is in base axes; SI units (m, rad, s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from spaceid_gym.arrays import FloatArray
from spaceid_gym.sim.lie import quat_from_matrix


@dataclass
class FreeFloatingState:
    """Instantaneous state of the free-floating robot.

    Attributes:
        t_s: time (s).
        rot_wb: base attitude, base-to-inertial rotation matrix (3, 3).
        p_wb_m: base origin in the inertial frame (3,), m.
        q_rad, dq_rad_s: arm joint angles and rates (n,).
        ddq_rad_s2: arm joint accelerations (n,) just before ``t_s``.
        v_base_body: base twist ``[v_lin; omega]`` in base axes (6,), m/s and rad/s.
        composite_inertia: the whole robot's spatial inertia in the base frame (``H_bb``).
        slosh_m, slosh_rate_m_s: slosh mass displacement from its rest point and its rate (3,),
            base axes, m and m/s; ``None`` without slosh. Truth only: never measured. For the spring
            model they are the slosh joint coordinates.
        slosh_angles_rad, slosh_angle_rates_rad_s: the pendulum's two hinge angles and their rates
            (2,), rad and rad/s (its joint coordinates); ``None`` otherwise.
    """

    t_s: float
    rot_wb: FloatArray
    p_wb_m: FloatArray
    q_rad: FloatArray
    dq_rad_s: FloatArray
    ddq_rad_s2: FloatArray
    v_base_body: FloatArray
    composite_inertia: pin.Inertia
    slosh_m: FloatArray | None = None
    slosh_rate_m_s: FloatArray | None = None
    slosh_angles_rad: FloatArray | None = None
    slosh_angle_rates_rad_s: FloatArray | None = None

    @property
    def slosh_coordinates(self) -> tuple[FloatArray, FloatArray] | None:
        """The slosh joints' coordinates and rates: ``(slosh_m, slosh_rate_m_s)`` for the spring model, the
        hinge angles and their rates for the pendulum; ``None`` without slosh."""
        if self.slosh_angles_rad is not None and self.slosh_angle_rates_rad_s is not None:
            return self.slosh_angles_rad, self.slosh_angle_rates_rad_s
        if self.slosh_m is not None and self.slosh_rate_m_s is not None:
            return self.slosh_m, self.slosh_rate_m_s
        return None

    @property
    def omega_base_body(self) -> FloatArray:
        """Base angular velocity in the base body frame (3,), rad/s (what a gyro measures)."""
        return self.v_base_body[3:]

    @property
    def quat_wb(self) -> FloatArray:
        """Base attitude quaternion, scalar first ``[w, x, y, z]``, base-to-inertial."""
        return quat_from_matrix(self.rot_wb)

    def pinocchio_configuration(self) -> FloatArray:
        """pinocchio ``q``: ``[p (3), quat (x, y, z, w), q_arm]`` (+ the slosh coordinates with slosh)."""
        w, x, y, z = self.quat_wb
        slosh = self.slosh_coordinates
        if slosh is None:
            return np.concatenate((self.p_wb_m, [x, y, z, w], self.q_rad))
        return np.concatenate((self.p_wb_m, [x, y, z, w], self.q_rad, slosh[0]))

    def pinocchio_velocity(self) -> FloatArray:
        """pinocchio ``v``: ``[v_lin_body, omega_body, dq]`` (+ the slosh rates with slosh)."""
        slosh = self.slosh_coordinates
        if slosh is None:
            return np.concatenate((self.v_base_body, self.dq_rad_s))
        return np.concatenate((self.v_base_body, self.dq_rad_s, slosh[1]))
