"""The identification model of the free-floating robot: base rate from joint motion, batched.

With zero system momentum the base twist satisfies ``(I_base + I_arm(q)) v = -h_arm(q, dq)``, where
``I_arm`` is the arm's composite spatial inertia and ``h_arm = H_bm dq`` the momentum of the arm's
own motion, both in the base frame (they do not depend on the base's parameters and are computed
once per log with pinocchio). Summing base and arm into one spatial inertia ``(m, c, Ic)`` gives the
closed form ``omega = -Ic^{-1} (L - c x P)`` with ``[P; L] = h_arm`` (the inverse of a spatial
inertia, with ``Ic`` the composite inertia about the composite CoM), evaluated here
for P parameter vectors times T samples in one compiled (numba) loop, no per-sample Python.

This model never touches the simulator's integration path: it needs only the log's ``q`` and ``dq``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numba import njit
from numpy.typing import NDArray

from spaceid_gym.log import MeasurementLog
from spaceid_gym.physics.fuel import base_params10_after_fuel
from spaceid_gym.physics.inertia import point_mass_inertia
from spaceid_gym.robots import Robot

FloatArray = NDArray[np.float64]


class MomentumModel:
    """Predicts the base angular velocity (base body frame) over a log, for many base parameter sets.

    Args:
        robot: the robot (its URDF's full-tank base is the nominal base).
        log: the measurement window; only ``q_rad`` and ``dq_rad_s`` are used.

    Attributes:
        n_samples: T.
        arm_mass_kg: total arm mass.
    """

    def __init__(self, robot: Robot, log: MeasurementLog) -> None:
        self.robot = robot
        model = pin.Model(robot.model)
        model.inertias[1] = pin.Inertia.Zero()  # composite of the arm alone
        data = model.createData()
        q_full = pin.neutral(model)
        n = log.n_samples
        first_moment = np.empty((n, 3))
        inertia_origin = np.empty((n, 3, 3))
        arm_momentum = np.empty((n, 6))
        for i, (q, dq) in enumerate(zip(log.q_rad, log.dq_rad_s, strict=True)):
            q_full[7:] = q
            coupling = pin.crba(model, data, q_full)[:6, 6:]
            arm = data.Ycrb[1]
            first_moment[i] = arm.mass * arm.lever
            inertia_origin[i] = arm.inertia + arm.mass * point_mass_inertia(arm.lever)
            arm_momentum[i] = coupling @ dq
        self.arm_mass_kg = float(sum(model.inertias[i].mass for i in range(2, model.njoints)))
        self.n_samples = n
        self._first_moment = first_moment  # (T, 3), kg m, base frame
        # (T, 6) kg m^2 about the base origin: xx, xy, yy, xz, yz, zz (pinocchio's order)
        self._inertia6 = np.ascontiguousarray(inertia_origin[:, [0, 0, 1, 0, 1, 2], [0, 1, 1, 2, 2, 2]])
        self._momentum = arm_momentum  # (T, 6), [P; L] of the arm's motion, base frame

    def predict_base_params(self, params10: FloatArray, samples: slice | NDArray[np.intp] = slice(None)) -> FloatArray:
        """Base angular velocity for base inertial parameters ``params10`` (P, 10), pinocchio order.

        Args:
            params10: base parameters about the base-frame origin, shape (P, 10) or (10,).
            samples: which samples of the log (default all).

        Returns:
            ``omega_base_body`` in rad/s, shape (P, T, 3) (or (T, 3) for a single parameter vector).
        """
        p = np.atleast_2d(np.asarray(params10, dtype=float))
        omega = _base_rate(p, self.arm_mass_kg, self._first_moment[samples], self._inertia6[samples], self._momentum[samples])
        return omega[0] if np.ndim(params10) == 1 else omega

    def predict_fuel(self, theta: FloatArray, samples: slice | NDArray[np.intp] = slice(None)) -> FloatArray:
        """Base angular velocity for fuel parameters ``theta = [mdf kg, bf m (3)]``, shape (P, 4) or (4,).

        Returns shape (P, T, 3) (or (T, 3) for one vector), rad/s, base body frame.
        """
        full = self.robot.base_full
        return self.predict_base_params(base_params10_after_fuel(full.to_params10(), full.com_m, theta), samples)


@njit(cache=True)
def _base_rate(
    params10: FloatArray, arm_mass: float, first: FloatArray, inertia6: FloatArray, momentum: FloatArray
) -> FloatArray:
    """``omega`` (P, T, 3) for base parameters (P, 10) and per-sample arm terms (T, ...); see the module docstring."""
    n_p, n_t = params10.shape[0], first.shape[0]
    out = np.empty((n_p, n_t, 3))
    for i in range(n_p):
        mass = params10[i, 0] + arm_mass
        for t in range(n_t):
            cx = (params10[i, 1] + first[t, 0]) / mass  # composite CoM, base frame
            cy = (params10[i, 2] + first[t, 1]) / mass
            cz = (params10[i, 3] + first[t, 2]) / mass
            # composite inertia about its CoM, Ic = J - m S(c): [[a b e] [b d f] [e f g]]
            a = params10[i, 4] + inertia6[t, 0] - mass * (cy * cy + cz * cz)
            b = params10[i, 5] + inertia6[t, 1] + mass * cx * cy
            d = params10[i, 6] + inertia6[t, 2] - mass * (cx * cx + cz * cz)
            e = params10[i, 7] + inertia6[t, 3] + mass * cx * cz
            f = params10[i, 8] + inertia6[t, 4] + mass * cy * cz
            g = params10[i, 9] + inertia6[t, 5] - mass * (cx * cx + cy * cy)
            px, py, pz = momentum[t, 0], momentum[t, 1], momentum[t, 2]
            # the base carries -h_arm: omega = Ic^{-1} r with r = -(L - c x P)
            rx = -(momentum[t, 3] - (cy * pz - cz * py))
            ry = -(momentum[t, 4] - (cz * px - cx * pz))
            rz = -(momentum[t, 5] - (cx * py - cy * px))
            c00, c01, c02 = d * g - f * f, e * f - b * g, b * f - d * e
            c11, c12, c22 = a * g - e * e, b * e - a * f, a * d - b * b
            inv_det = 1.0 / (a * c00 + b * c01 + e * c02)
            out[i, t, 0] = (c00 * rx + c01 * ry + c02 * rz) * inv_det
            out[i, t, 1] = (c01 * rx + c11 * ry + c12 * rz) * inv_det
            out[i, t, 2] = (c02 * rx + c12 * ry + c22 * rz) * inv_det
    return out
