"""The fixed-base arm's true parameters: the default friction, the nominal parameters and the prior they are drawn from.

The simulated arm's truth is drawn around the URDF's inertial parameters and a default friction
(:func:`default_friction_coefficients`, an ASSUMPTION of a few per cent of each joint's torque limit)
by :class:`ParameterPrior`, which also gives the exact prior std of every parameter and base parameter.
Parameters are in :class:`~spaceid_gym.arm.regressor.ArmRegressor` order (10 per body, then friction per joint).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from spaceid_gym.arm.arm_robot import ArmRobot
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.regressor import ArmRegressor, BaseParameterSet
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: Default friction as fractions of each joint's torque limit (ASSUMPTION, not UR data: a few per cent of
#: the rated torque is typical of harmonic-drive joints). Viscous: ``VISCOUS_FRACTION * limit / rate limit``.
COULOMB_FRACTION = 0.05
VISCOUS_FRACTION = 0.03
STRIBECK_FRACTION_OF_COULOMB = 0.3
#: the default asymmetric Coulomb friction: (1 + a) and (1 - a) times the Coulomb level in the + and - directions
COULOMB_ASYMMETRY = 0.3


def default_friction_coefficients(robot: ArmRobot, friction: FrictionModel | Sequence[str] | None) -> FloatArray:
    """Friction coefficients of the assumed default, shape (n, k) in the model's term order.

    Coulomb ``COULOMB_FRACTION * torque limit`` (N m), viscous ``VISCOUS_FRACTION * torque limit /
    rate limit`` (N m s/rad), Stribeck excess ``STRIBECK_FRACTION_OF_COULOMB * coulomb`` (N m),
    offset 0; asymmetric Coulomb ``(1 +- COULOMB_ASYMMETRY) * coulomb`` in the + and - directions. For the UR5: 7.5 / 1.4 N m and 1.43 / 0.27 N m s/rad on the 150 / 28 N m joints.
    """
    model = FrictionModel.coerce(friction)
    coulomb = COULOMB_FRACTION * robot.torque_limit_Nm
    values = {
        "coulomb": coulomb,
        "viscous": VISCOUS_FRACTION * robot.torque_limit_Nm / robot.dq_limit_rad_s,
        "stribeck": STRIBECK_FRACTION_OF_COULOMB * coulomb,
        "offset": np.zeros(robot.n_joints),
        "coulomb_positive": (1.0 + COULOMB_ASYMMETRY) * coulomb,
        "coulomb_negative": (1.0 - COULOMB_ASYMMETRY) * coulomb,
    }
    return np.stack([values[c] for c in model.columns], axis=1) if model.terms else np.zeros((robot.n_joints, 0))


def nominal_parameters(regressor: ArmRegressor) -> FloatArray:
    """The URDF's inertial parameters and the default friction (:func:`default_friction_coefficients`), shape (p,)."""
    p = regressor.nominal_parameters()
    p[regressor.n_inertial :] = default_friction_coefficients(regressor.robot, regressor.friction).ravel()
    return p


@dataclass(frozen=True)
class ParameterPrior:
    """The distribution true parameters are drawn from (:meth:`draw`) around the URDF and default friction.

    Per body (nominal mass ``m``, CoM ``c`` in the body frame, inertia ``I_C`` about the CoM):
    ``m' = m (1 + e_m)``, ``c' = c + d``, ``I_C' = I_C (1 + e_I) m'/m``, with ``e_m, e_I ~ U(-s, s)``
    (``s = relative_spread``) and each component of ``d ~ U(-com_spread_m, com_spread_m)``: always
    physically consistent. Friction coefficients ``f' = f_default (1 + e_f)``, ``e_f ~ U(-s_f, s_f)``.

    Attributes:
        relative_spread: ``s`` (default 0.1).
        com_spread_m: CoM shift half-range per axis, m (default 0.01).
        friction_spread: ``s_f`` (default 0.5).
    """

    relative_spread: float = 0.1
    com_spread_m: float = 0.01
    friction_spread: float = 0.5

    def __post_init__(self) -> None:
        for name in ("relative_spread", "com_spread_m", "friction_spread"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0.0 <= value < (1.0 if name != "com_spread_m" else np.inf)):
                raise SpaceIdInputError(f"parameter prior: {name} must be in [0, 1) (com_spread_m >= 0), got {value!r}")

    def draw(self, regressor: ArmRegressor, rng: np.random.Generator) -> FloatArray:
        """True parameters ``p`` (regressor order), shape (p,); 5 draws per body then one per friction coefficient."""
        n = regressor.n_joints
        z = rng.uniform(-1.0, 1.0, size=(n, 5)) * self._half_widths()
        friction = default_friction_coefficients(regressor.robot, regressor.friction)
        e_f = rng.uniform(-self.friction_spread, self.friction_spread, size=friction.shape)
        return np.concatenate(
            [*(_body_parameters(regressor.robot.model.inertias[k + 1], z[k]) for k in range(n)), (friction * (1 + e_f)).ravel()]
        )

    def parameter_std(self, regressor: ArmRegressor) -> FloatArray:
        """Exact std of each drawn parameter, shape (p,).

        A body's parameters are polynomials of degree <= 2 in each of its five independent uniform
        perturbations, so their mean and variance are exact on a Gauss-Legendre tensor grid of 3
        nodes per perturbation (exact to degree 5 per variable); friction coefficients are linear
        in theirs (``U(-a, a)`` has std ``a / sqrt(3)``).
        """
        nodes = np.sqrt(0.6) * np.array([-1.0, 0.0, 1.0])
        weights = np.array([5.0, 8.0, 5.0]) / 18.0  # Gauss-Legendre weights / 2: the U(-1, 1) density
        grid = np.stack(np.meshgrid(*[nodes] * 5, indexing="ij"), axis=-1).reshape(-1, 5) * self._half_widths()
        grid_weights = np.prod(np.stack(np.meshgrid(*[weights] * 5, indexing="ij"), axis=-1).reshape(-1, 5), axis=1)
        out = []
        for k in range(regressor.n_joints):
            values = np.array([_body_parameters(regressor.robot.model.inertias[k + 1], z) for z in grid])  # (243, 10)
            mean = grid_weights @ values
            out.append(np.sqrt(np.maximum(grid_weights @ (values - mean) ** 2, 0.0)))
        friction = default_friction_coefficients(regressor.robot, regressor.friction)
        out.append((np.abs(friction) * self.friction_spread / math.sqrt(3.0)).ravel())
        return np.concatenate(out)

    def _half_widths(self) -> FloatArray:
        """Half-widths of the five body perturbations ``(e_m, d_x, d_y, d_z, e_I)``."""
        return np.array([self.relative_spread, self.com_spread_m, self.com_spread_m, self.com_spread_m, self.relative_spread])

    def base_parameter_std(self, regressor: ArmRegressor, base: BaseParameterSet) -> FloatArray:
        """Prior std of each base parameter ``beta = K p`` (parameters taken independent), shape (r,), floored at 1e-12."""
        return np.maximum(np.sqrt((base.K**2) @ self.parameter_std(regressor) ** 2), 1e-12)

    def as_dict(self) -> dict[str, float]:
        """The settings for ``truth.json``."""
        return dataclasses.asdict(self)


def _body_parameters(nominal: pin.Inertia, z: FloatArray) -> FloatArray:
    """Dynamic parameters (10,) of a body perturbed by ``z = (e_m, d_x, d_y, d_z, e_I)`` (see :class:`ParameterPrior`)."""
    scale = 1.0 + z[0]
    inertia = pin.Inertia(nominal.mass * scale, nominal.lever + z[1:4], nominal.inertia * (1.0 + z[4]) * scale)
    return inertia.toDynamicParameters()
