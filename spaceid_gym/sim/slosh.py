"""Fuel slosh in the free-floating simulator: the sloshing mass as a body (a point mass on an isotropic
spring-damper, or a pendulum on a hinge), the rigid base without it, the pinocchio model with it, and its
equations of motion (base twist and slosh acceleration). Used by :mod:`spaceid_gym.sim.simulator`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numba import njit

from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.settings import HiddenEffects
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import RigidBodyInertia, point_mass_inertia
from spaceid_gym.physics.momentum import momentum_world_to_base
from spaceid_gym.robots.robot import Robot

#: the largest second hinge angle of the pendulum the simulator integrates, rad (:meth:`SloshBody.check_chart`): at 85
#: deg the inertia about the first hinge axis is cos^2 = 0.8 % of the mass's ``m L^2``
CHART_LIMIT_RAD = float(np.radians(85.0))


@dataclass(frozen=True)
class SloshBody:
    """The slosh point mass and its restoring law.

    Attributes:
        mass_kg: the slosh mass ``m``, kg.
        stiffness_n_m, damping_n_s_m: the spring ``k`` (N/m) and damper ``c`` (N s/m) at the mass; for the
            pendulum, its lateral equivalent at small angles (the law at any angle is :meth:`joint_force`).
        anchor_m: the rest point of the mass (the tank point), base frame (3,), m.
        length_m: the pendulum's rod length ``L``, m; ``None`` for the spring model.
        rot_base_hinge: the pendulum's hinge frame ``[e1 e2 a]`` in the base frame (3, 3): the joints turn
            about ``e1`` and then the turned ``e2``, the rod is ``a`` at zero angles; ``None`` for the spring model.
    """

    mass_kg: float
    stiffness_n_m: float
    damping_n_s_m: float
    anchor_m: FloatArray
    length_m: float | None = None
    rot_base_hinge: FloatArray | None = None

    @property
    def is_pendulum(self) -> bool:
        """True for the pendulum, False for the spring model."""
        return self.length_m is not None

    @property
    def n_coordinates(self) -> int:
        """The number of slosh joint coordinates: 3 (spring: displacement) or 2 (pendulum: hinge angles)."""
        return 2 if self.is_pendulum else 3

    @property
    def hinge_m(self) -> FloatArray:
        """The pendulum's hinge point, base frame (3,), m: ``anchor - L a``."""
        assert self.length_m is not None and self.rot_base_hinge is not None
        return self.anchor_m - self.length_m * self.rot_base_hinge[:, 2]

    def joint_stiffness_damping(self) -> tuple[float, float]:
        """Stiffness and damping on each slosh joint coordinate: ``(k, c)`` (N/m, N s/m) for the spring model,
        ``(k L^2, c L^2)`` (N m/rad, N m s/rad) for the pendulum, its small-angle limit (the same lateral force at the
        mass; :meth:`joint_force` is the law at any angle)."""
        if self.length_m is None:
            return self.stiffness_n_m, self.damping_n_s_m
        square = self.length_m * self.length_m
        return self.stiffness_n_m * square, self.damping_n_s_m * square

    def joint_force(self, x: FloatArray, dx: FloatArray) -> FloatArray:
        """The restoring and damping generalized force on the slosh joints at coordinates and rates ``x, dx`` (m and
        m/s for the spring, rad and rad/s for the pendulum).

        The spring model: ``-k x - c dx`` (N). The pendulum (N m): the mass under the effective acceleration ``g = k L /
        m`` along the rod's rest axis (Abramson, NASA SP-106, ch. 6), the potential ``V = k L^2 (1 - cos x0 cos x1)``
        (``cos x0 cos x1`` is the rod's cosine with its rest axis), and the damper ``c`` on the mass's velocity relative
        to the base, the dissipation ``c L^2 (cos^2 x1 dx0^2 + dx1^2) / 2``: ``-k L^2 [sin x0 cos x1, cos x0 sin x1] -
        c L^2 [cos^2 x1 dx0, dx1]``. Both are the spring's ``-k L^2 x - c L^2 dx`` at small angles and coordinate-free
        (the same pendulum whatever the hinge's chart)."""
        stiffness, damping = self.joint_stiffness_damping()
        if self.length_m is None:
            return -stiffness * x - damping * dx
        s0, c0, s1, c1 = np.sin(x[0]), np.cos(x[0]), np.sin(x[1]), np.cos(x[1])
        return -stiffness * np.array([s0 * c1, c0 * s1]) - damping * np.array([c1 * c1 * dx[0], dx[1]])

    def check_chart(self, x: FloatArray, t_s: float) -> None:
        """Raise :class:`SpaceIdInputError` if the pendulum's second hinge angle ``x[1]`` (rad) is beyond
        :data:`CHART_LIMIT_RAD` at time ``t_s`` (s): the universal joint's chart is singular at ``x1 = +-90 deg`` (the
        rod along ``e1``, where turning about ``e1`` moves nothing), and the fixed-step integration loses its accuracy
        before it. A motion started within the limit (:func:`initial_slosh`) meets it before the singularity. Nothing
        for the spring model."""
        if self.is_pendulum and not abs(float(x[1])) <= CHART_LIMIT_RAD:
            raise SpaceIdInputError(
                f"hidden effect 'slosh': the pendulum swung to {np.degrees(x[1]):.1f} deg about its second hinge axis at "
                f"t = {t_s:.3f} s, beyond the {np.degrees(CHART_LIMIT_RAD):.0f} deg its universal joint's chart allows "
                "(singular at 90 deg); a longer rod, a higher slosh frequency or a gentler excitation swings it less"
            )

    def displacement(self, x: FloatArray, dx: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The mass's displacement from its rest point and its rate relative to the base (3,), base axes, m and
        m/s, from the joint coordinates and rates ``x, dx``: themselves for the spring model; for the pendulum the
        rod ``L Rx(x0) Ry(x1) e_z`` in the hinge frame, minus its rest ``L e_z``."""
        if self.length_m is None or self.rot_base_hinge is None:
            return x, dx
        s0, c0, s1, c1 = np.sin(x[0]), np.cos(x[0]), np.sin(x[1]), np.cos(x[1])
        rod = np.array([s1, -s0 * c1, c0 * c1 - 1.0])
        rate = np.array([c1 * dx[1], -c0 * c1 * dx[0] + s0 * s1 * dx[1], -s0 * c1 * dx[0] - c0 * s1 * dx[1]])
        return self.length_m * (self.rot_base_hinge @ rod), self.length_m * (self.rot_base_hinge @ rate)


def slosh_body(effects: HiddenEffects, tank_point_m: FloatArray | None) -> SloshBody | None:
    """The slosh point mass of ``effects`` at ``tank_point_m`` (spring or pendulum); ``None`` without slosh or with zero slosh mass."""
    if effects.slosh_mass_kg is None or effects.slosh_mass_kg == 0.0:
        return None
    anchor = None if tank_point_m is None else np.asarray(tank_point_m, dtype=float)
    if anchor is None or anchor.shape != (3,) or not np.all(np.isfinite(anchor)):
        raise SpaceIdInputError(
            f"tank_point_m: the 'slosh' effect needs the tank position (3 finite numbers, m), got {tank_point_m!r}"
        )
    stiffness, damping = effects.slosh_stiffness_damping()
    if effects.slosh_model != "pendulum":
        return SloshBody(effects.slosh_mass_kg, stiffness, damping, anchor)
    axis = np.asarray(effects.slosh_axis, dtype=float)
    return SloshBody(effects.slosh_mass_kg, stiffness, damping, anchor, effects.slosh_length_m, hinge_frame(axis))


def hinge_frame(axis_base: FloatArray) -> FloatArray:
    """A right-handed orthonormal frame ``[e1 e2 a]`` (3, 3) whose third column is ``axis_base`` normalised.

    ``e1`` is ``y x a`` normalised (or ``a x x`` when ``a`` is within 25 deg of ``y``), ``e2 = a x e1``; for
    ``a = z`` the frame is the identity (the hinge angles turn about the base x and y axes).
    """
    a = axis_base / np.linalg.norm(axis_base)
    e1 = np.cross([0.0, 1.0, 0.0], a) if abs(a[1]) < 0.9 else np.cross(a, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return np.column_stack((e1, np.cross(a, e1), a))


def initial_slosh(slosh: SloshBody, slosh_m: FloatArray | None, slosh_angles_rad: FloatArray | None) -> FloatArray:
    """The slosh joint coordinates at reset: ``slosh_m`` (spring) or ``slosh_angles_rad`` (pendulum), default zero."""
    name, unit, given, other = "slosh_m", "m, base axes", slosh_m, slosh_angles_rad
    if slosh.is_pendulum:
        name, unit, given, other = "slosh_angles_rad", "rad, the hinge angles", slosh_angles_rad, slosh_m
    if other is not None:
        model = "pendulum" if slosh.is_pendulum else "spring"
        raise SpaceIdInputError(f"reset: the {model} slosh model starts from {name}; the other is not for it")
    size = slosh.n_coordinates
    x0 = np.zeros(size) if given is None else np.asarray(given, dtype=float)
    if x0.shape != (size,) or not np.all(np.isfinite(x0)):
        raise SpaceIdInputError(f"reset: {name} expected {size} finite numbers ({unit}), got {given!r}")
    if slosh.is_pendulum and not abs(x0[1]) <= CHART_LIMIT_RAD:
        raise SpaceIdInputError(
            f"reset: slosh_angles_rad[1] expected within +-{CHART_LIMIT_RAD:.4f} rad ({np.degrees(CHART_LIMIT_RAD):.0f} deg, "
            f"the universal joint's chart is singular at 90 deg), got {x0[1]!r}"
        )
    return x0


def base_without_slosh(base: RigidBodyInertia, slosh: SloshBody) -> RigidBodyInertia:
    """The rigid base: ``base`` minus the slosh point mass at its rest point (mass, first moment and inertia subtract)."""
    m, r = slosh.mass_kg, slosh.anchor_m
    mass = base.mass_kg - m
    if mass <= 0.0:
        raise SpaceIdInputError(f"hidden effect 'slosh': slosh mass {m:g} kg is not below the base mass {base.mass_kg:g} kg")
    com_base = np.asarray(base.com_m, dtype=float)
    com = (base.mass_kg * com_base - m * r) / mass
    # inertia about the new CoM: parallel-axis theorem on both parts
    inertia = (
        np.asarray(base.inertia_com_kgm2, dtype=float)
        + base.mass_kg * point_mass_inertia(com_base - com)
        - m * point_mass_inertia(r - com)
    )
    return RigidBodyInertia(mass, com, inertia).validate(
        f"hidden effect 'slosh': the rigid base after taking {m:g} kg out at the tank {r.tolist()} m"
    )


def model_with_slosh(robot: Robot, rigid_base: RigidBodyInertia, slosh: SloshBody) -> pin.Model:
    """``robot``'s model with ``rigid_base`` and the slosh point mass on its joints: prismatic x, y, z (base axes)
    at its anchor (spring), or revolute about ``e1`` and ``e2`` at the hinge, the mass ``L`` along the rod (pendulum)."""
    model = robot.model_with_base(rigid_base)
    if slosh.length_m is None:
        placement, lever = pin.SE3(np.eye(3), slosh.anchor_m), np.zeros(3)
        joints = (("slosh_x", pin.JointModelPX()), ("slosh_y", pin.JointModelPY()), ("slosh_z", pin.JointModelPZ()))
    else:
        placement, lever = pin.SE3(slosh.rot_base_hinge, slosh.hinge_m), np.array([0.0, 0.0, slosh.length_m])
        joints = (("slosh_hinge_e1", pin.JointModelRX()), ("slosh_hinge_e2", pin.JointModelRY()))
    parent = 1
    for name, joint in joints:
        parent = model.addJoint(parent, joint, placement, name)
        placement = pin.SE3.Identity()
    model.appendBodyToJoint(parent, pin.Inertia(slosh.mass_kg, lever, np.zeros((3, 3))), pin.SE3.Identity())
    return model


@njit(cache=True)
def slosh_base_twist(
    mass: FloatArray,
    com_base_m: FloatArray,
    com_world_m: FloatArray,
    rot_wb: FloatArray,
    momentum_world: FloatArray,
    dq: FloatArray,
    slosh_rate: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Base twist (6,) and position ``p_wb`` (3,) from ``H_bb v = h_base - H_bm dq - H_bs dx`` (with the slosh joints).

    ``mass``: joint-space mass matrix ``(6 + n + s)^2`` (upper triangle read), base rows first, then the
    arm's n, then the s slosh joints' (s = ``slosh_rate.shape[0]``); ``com_base_m``: the system CoM in the base frame.
    """
    n = dq.shape[0]
    p = com_world_m - rot_wb @ com_base_m
    rhs = momentum_world_to_base(momentum_world, rot_wb, p)
    h_bb = np.empty((6, 6))
    for a in range(6):
        for b in range(6):
            h_bb[a, b] = mass[min(a, b), max(a, b)]
        for k in range(n):
            rhs[a] -= mass[a, 6 + k] * dq[k]
        for k in range(slosh_rate.shape[0]):
            rhs[a] -= mass[a, 6 + n + k] * slosh_rate[k]
    return np.linalg.solve(h_bb, rhs), p


@njit(cache=True)
def slosh_acceleration(
    mass: FloatArray,
    nle: FloatArray,
    torque_base: FloatArray,
    slosh_force: FloatArray,
    ddq: FloatArray,
) -> FloatArray:
    """Slosh joint accelerations (s,) from the base and slosh rows of ``M a + nle = tau``, the arm's ``ddq`` (n,) given.

    ``tau`` = ``[0, 0, 0, torque_base]`` on the base (a pure torque, base axes) and ``slosh_force`` (s,) on the s
    slosh joints (:meth:`SloshBody.joint_force`); ``mass`` as in :func:`slosh_base_twist` (upper triangle read),
    ``nle`` (6 + n + s,).
    """
    n = ddq.shape[0]
    size = 6 + slosh_force.shape[0]
    free = np.empty(size, dtype=np.int64)
    free[:6] = np.arange(6)
    free[6:] = np.arange(6 + n, size + n)
    lhs = np.empty((size, size))
    rhs = np.empty(size)
    for a in range(size):
        i = free[a]
        for b in range(size):
            j = free[b]
            lhs[a, b] = mass[min(i, j), max(i, j)]
        coupling = 0.0
        for k in range(n):
            coupling += mass[min(i, 6 + k), max(i, 6 + k)] * ddq[k]
        rhs[a] = -coupling - nle[i]
    rhs[3:6] += torque_base
    rhs[6:] += slosh_force
    return np.linalg.solve(lhs, rhs)[6:]
