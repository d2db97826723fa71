"""Fuel consumption: the base's mass properties after fuel is drawn from a point-mass tank.

The paper (source 1, eqs. 10-12) models consumed fuel ``mdf`` (kg) as a point mass removed from a
tank at ``bf`` (m, base frame, **relative to the full-tank CoM** ``bI``). Exact rigid-body physics:

* ``m0 = mI - mdf``                                   (eq. 10)
* ``b0 = bI - (mdf / m0) bf``                          (eq. 11; the CoM moves *away* from the tank.
  The printed ``+`` holds only if ``bf`` points from the tank to the CoM.)
* ``I0 = II - mdf S(bf) - (mdf^2 / m0) S(bf)``         (eq. 12, corrected; ``S(b) = |b|^2 E - b b^T``)

where ``II`` is the full-tank inertia about ``bI`` and ``I0`` the remaining base's inertia about
its new CoM ``b0``. In the 10 inertial parameters about the base-frame origin the removal is a plain
subtraction of the point mass's parameters, which gives the analytic Jacobian used for the Fisher
information.
"""

from __future__ import annotations

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import RigidBodyInertia, point_mass_inertia

#: names of the 4 fuel parameters, in order
FUEL_PARAMETER_NAMES = ("fuel_consumed_kg", "tank_x_m", "tank_y_m", "tank_z_m")


def check_fuel(base_full: RigidBodyInertia, fuel_consumed_kg: float, tank_position_m: FloatArray) -> None:
    """Raise :class:`SpaceIdInputError` unless ``0 <= mdf < mI`` and ``bf`` is a finite 3-vector."""
    bf = np.asarray(tank_position_m, dtype=float)
    if bf.shape != (3,) or not np.all(np.isfinite(bf)):
        raise SpaceIdInputError(f"tank_position_m: expected 3 finite numbers (m), got {tank_position_m!r}")
    if not np.isfinite(fuel_consumed_kg) or fuel_consumed_kg < 0.0:
        raise SpaceIdInputError(f"fuel_consumed_kg: expected a finite value >= 0 kg, got {fuel_consumed_kg!r}")
    if fuel_consumed_kg >= base_full.mass_kg:
        raise SpaceIdInputError(
            f"fuel_consumed_kg: {fuel_consumed_kg:g} kg is not below the full-tank base mass {base_full.mass_kg:g} kg"
        )


def base_after_fuel(base_full: RigidBodyInertia, fuel_consumed_kg: float, tank_position_m: FloatArray) -> RigidBodyInertia:
    """Base mass properties after ``mdf`` kg of fuel left the tank at ``bf`` (eqs. 10-12, corrected).

    Args:
        base_full: full-tank base (mass ``mI``, CoM ``bI`` in the base frame, inertia ``II`` about ``bI``).
        fuel_consumed_kg: ``mdf``, 0 <= mdf < mI.
        tank_position_m: ``bf``, shape (3,): tank position relative to the full-tank CoM, base axes.

    Returns:
        The remaining base, validated as a physical body (raises if the removal leaves a
        non-physical inertia, e.g. a tank placed outside the body).
    """
    check_fuel(base_full, fuel_consumed_kg, tank_position_m)
    bf = np.asarray(tank_position_m, dtype=float)
    mdf = float(fuel_consumed_kg)
    m0 = base_full.mass_kg - mdf
    b0 = np.asarray(base_full.com_m, dtype=float) - (mdf / m0) * bf
    s = point_mass_inertia(bf)
    inertia0 = np.asarray(base_full.inertia_com_kgm2, dtype=float) - mdf * s - (mdf * mdf / m0) * s
    return RigidBodyInertia(m0, b0, inertia0).validate(f"base after removing {mdf:g} kg of fuel at tank position {bf.tolist()} m")


def _point_mass_params10(r_m: FloatArray) -> FloatArray:
    """Inertial parameters (pinocchio order) of a unit point mass at ``r`` (..., 3) about the origin."""
    x, y, z = r_m[..., 0], r_m[..., 1], r_m[..., 2]
    return np.stack([np.ones_like(x), x, y, z, y * y + z * z, -x * y, x * x + z * z, -x * z, -y * z, x * x + y * y], axis=-1)


def base_params10_after_fuel(base_full_params10: FloatArray, com_full_m: FloatArray, theta: FloatArray) -> FloatArray:
    """Base inertial parameters (about the base origin) after fuel removal; batched.

    Args:
        base_full_params10: full-tank base parameters, shape (10,).
        com_full_m: full-tank CoM ``bI`` in the base frame, shape (3,).
        theta: fuel parameters ``[mdf, bf_x, bf_y, bf_z]``, shape (..., 4).

    Returns:
        shape (..., 10): ``params_full - params(point mass mdf at bI + bf)``.
    """
    th = np.asarray(theta, dtype=float)
    mdf = th[..., 0]
    r = np.asarray(com_full_m, dtype=float) + th[..., 1:4]
    return np.asarray(base_full_params10, dtype=float) - mdf[..., None] * _point_mass_params10(r)


def base_params10_fuel_jacobian(com_full_m: FloatArray, theta: FloatArray) -> FloatArray:
    """d(base params10)/d(theta) of :func:`base_params10_after_fuel`, shape (10, 4) (analytic)."""
    mdf, bf = float(theta[0]), np.asarray(theta[1:4], dtype=float)
    x, y, z = np.asarray(com_full_m, dtype=float) + bf
    jac = np.zeros((10, 4))
    jac[:, 0] = -_point_mass_params10(np.array([x, y, z]))
    # derivatives of the point-mass entries with respect to x, y, z
    d_point = np.array(
        [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [0, 2 * y, 2 * z],
            [-y, -x, 0],
            [2 * x, 0, 2 * z],
            [-z, 0, -x],
            [0, -z, -y],
            [2 * x, 2 * y, 0],
        ],
        dtype=float,
    )
    jac[:, 1:4] = -mdf * d_point
    return jac
