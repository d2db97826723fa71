"""One RKMK4 step of the free-floating base's attitude on SO(3), and the base twist it integrates (numba-compiled).

``R = R0 exp([theta]x)`` with ``d theta/dt = dexp^{-1}(theta, omega_base_body)``, so the rotation stays exactly
orthonormal; the body rate at each stage follows from the system momentum (:mod:`spaceid_gym.physics.momentum`) and
the base terms there (:data:`BaseTerms`). Used by :class:`~spaceid_gym.sim.simulator.FreeFloatingSimulator` every
control period (its module docstring: why the scheme keeps fourth order).
"""

from __future__ import annotations

import pinocchio as pin
from numba import njit

from spaceid_gym.arrays import FloatArray
from spaceid_gym.physics.momentum import momentum_world_to_base
from spaceid_gym.sim.lie import dexp_inv, so3_exp

#: ``(composite inertia, its inverse (6, 6), H_bm dq (6,), system CoM in base frame (3,), in inertial frame (3,))``
BaseTerms = tuple[pin.Inertia, FloatArray, FloatArray, FloatArray, FloatArray]


@njit(cache=True)
def base_twist_at_attitude(
    rot_wb: FloatArray,
    momentum_world: FloatArray,
    h_bb_inv: FloatArray,
    arm: FloatArray,
    com_base_m: FloatArray,
    com_world_m: FloatArray,
) -> FloatArray:
    """Base twist ``[v; omega]`` (base axes) from ``H_bb v = h_base(R, p) - H_bm dq``, shape (6,).

    The base position follows from the system CoM: ``p = c_world - R c_base``.
    """
    p = com_world_m - rot_wb @ com_base_m
    return h_bb_inv @ (momentum_world_to_base(momentum_world, rot_wb, p) - arm)


@njit(cache=True)
def rkmk4_attitude(
    rot0: FloatArray,
    omega0: FloatArray,
    h: float,
    momentum_mid: FloatArray,
    inv_mid: FloatArray,
    arm_mid: FloatArray,
    com_base_mid: FloatArray,
    com_world_mid: FloatArray,
    momentum_end: FloatArray,
    inv_end: FloatArray,
    arm_end: FloatArray,
    com_base_end: FloatArray,
    com_world_end: FloatArray,
) -> FloatArray:
    """One RKMK4 step of length ``h`` for the base attitude on SO(3).

    ``R = R0 exp([theta]x)`` with ``d theta/dt = dexp^{-1}(theta, omega_base_body)``. The body rate
    is ``omega0`` at the start; at ``t + h/2`` and ``t + h`` it follows from the system momentum and
    the base terms there (:data:`BaseTerms`) and the stage attitude. Compiled with numba (it runs
    every env step).
    """
    k1 = omega0.copy()
    th2 = 0.5 * h * k1
    k2 = dexp_inv(
        th2, base_twist_at_attitude(rot0 @ so3_exp(th2), momentum_mid, inv_mid, arm_mid, com_base_mid, com_world_mid)[3:]
    )
    th3 = 0.5 * h * k2
    k3 = dexp_inv(
        th3, base_twist_at_attitude(rot0 @ so3_exp(th3), momentum_mid, inv_mid, arm_mid, com_base_mid, com_world_mid)[3:]
    )
    th4 = h * k3
    k4 = dexp_inv(
        th4, base_twist_at_attitude(rot0 @ so3_exp(th4), momentum_end, inv_end, arm_end, com_base_end, com_world_end)[3:]
    )
    return rot0 @ so3_exp((h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4))
