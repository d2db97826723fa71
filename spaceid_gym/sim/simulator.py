"""Free-floating space-robot simulator: the truth the estimators never see.

Physics
-------
No gravity (orbital free fall) and no external wrench on the base, so the system's spatial
momentum ``h_world`` is constant. The base's six equations of motion are integrated once, exactly:
its twist follows from momentum conservation (:mod:`spaceid_gym.physics.momentum`) with the
*true* base mass properties (after fuel consumption). The arm joints follow the rate servo of
:mod:`spaceid_gym.sim.servo` in closed form.

Integration
-----------
The system CoM moves uniformly, ``c(t) = c(0) + P t / M``, so the base position follows exactly
from the attitude: ``p_wb = c(t) - R_wb c_base(q)``. Only the attitude ``R_wb`` is integrated, with
a fourth-order Runge-Kutta-Munthe-Kaas scheme on SO(3): ``R = R0 exp([theta]x)`` with
``d theta/dt = dexp^{-1}(theta, omega_base_body)``, so the rotation stays exactly orthonormal.
Each control period is split at the servo's switch times so that every integrated interval is
smooth and the scheme keeps its fourth order. Momentum is conserved to round-off by construction;
tests check it with pinocchio's centroidal momentum, check the motion against the Newton-Euler
equations (zero base wrench) and check the integrator's order, independently.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numba import njit
from numpy.typing import NDArray

from spaceid_gym.physics.inertia import RigidBodyInertia
from spaceid_gym.physics.momentum import momentum_world_to_base
from spaceid_gym.robots.robot import Robot
from spaceid_gym.sim.lie import dexp_inv, quat_from_matrix, so3_exp
from spaceid_gym.sim.servo import RateServo, default_servo

FloatArray = NDArray[np.float64]


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
    """

    t_s: float
    rot_wb: FloatArray
    p_wb_m: FloatArray
    q_rad: FloatArray
    dq_rad_s: FloatArray
    ddq_rad_s2: FloatArray
    v_base_body: FloatArray
    composite_inertia: pin.Inertia

    @property
    def omega_base_body(self) -> FloatArray:
        """Base angular velocity in the base body frame (3,), rad/s (what a gyro measures)."""
        return self.v_base_body[3:]

    @property
    def quat_wb(self) -> FloatArray:
        """Base attitude quaternion, scalar first ``[w, x, y, z]``, base-to-inertial."""
        return quat_from_matrix(self.rot_wb)

    def pinocchio_configuration(self) -> FloatArray:
        """pinocchio ``q``: ``[p (3), quat (x, y, z, w), q_arm]``."""
        w, x, y, z = self.quat_wb
        return np.concatenate((self.p_wb_m, [x, y, z, w], self.q_rad))

    def pinocchio_velocity(self) -> FloatArray:
        """pinocchio ``v``: ``[v_lin_body, omega_body, dq]``."""
        return np.concatenate((self.v_base_body, self.dq_rad_s))


class FreeFloatingSimulator:
    """Integrates a free-floating robot whose joints follow commanded rates.

    Args:
        robot: the robot description (its full-tank base is replaced by ``base``).
        base: the true current base mass properties (e.g. from
            :func:`spaceid_gym.physics.fuel.base_after_fuel`).
        servo: the joint servo; default :func:`spaceid_gym.sim.servo.default_servo`.
        substeps: integration intervals per smooth piece of a control period (>= 1).
    """

    def __init__(
        self,
        robot: Robot,
        base: RigidBodyInertia,
        servo: RateServo | None = None,
        substeps: int = 1,
    ) -> None:
        if substeps < 1:
            raise ValueError(f"substeps: expected >= 1, got {substeps}")
        self.robot = robot
        self.model = robot.model_with_base(base)
        self.data = self.model.createData()
        self.servo = servo if servo is not None else default_servo(robot.rate_limit_rad_s)
        self.substeps = int(substeps)
        self.total_mass_kg = float(sum(inertia.mass for inertia in self.model.inertias))
        self.momentum_world = np.zeros(6)
        self._zero_momentum = True
        self._com0_world = np.zeros(3)
        self._q_full = pin.neutral(self.model)
        self.state = self.reset()

    def reset(
        self,
        q0_rad: FloatArray | None = None,
        rot_wb: FloatArray | None = None,
        momentum_world: FloatArray | None = None,
    ) -> FreeFloatingState:
        """Start with the joints at rest and the system CoM at the inertial origin.

        Args:
            q0_rad: initial joint angles (n,); default the robot's home configuration.
            rot_wb: initial base attitude; default identity.
            momentum_world: constant system momentum ``[P; L]`` about the inertial origin (6,),
                N s and N m s; default zero (the paper's assumption). A non-zero ``L`` makes the
                base spin (residual spin, stored wheel momentum).
        """
        n = self.robot.n_joints
        q0 = self.robot.home_configuration() if q0_rad is None else np.asarray(q0_rad, dtype=float)
        rot = np.eye(3) if rot_wb is None else np.asarray(rot_wb, dtype=float)
        self.momentum_world = np.zeros(6) if momentum_world is None else np.asarray(momentum_world, dtype=float)
        self._zero_momentum = not self.momentum_world.any()
        terms = self._base_terms(0.0, q0, np.zeros(n))
        twist = base_twist_at_attitude(rot, self.momentum_world, *terms[1:])
        p = terms[3] - rot @ terms[0].lever
        self.state = FreeFloatingState(0.0, rot, p, q0.copy(), np.zeros(n), np.zeros(n), twist, terms[0])
        return self.state

    def base_twist(self, q_rad: FloatArray, dq_rad_s: FloatArray, rot_wb: FloatArray, t_s: float = 0.0) -> FloatArray:
        """Base twist ``[v_lin; omega]`` (base axes) from momentum conservation, shape (6,)."""
        return base_twist_at_attitude(rot_wb, self.momentum_world, *self._base_terms(t_s, q_rad, dq_rad_s)[1:])

    def step(self, rate_command_rad_s: FloatArray, dt_s: float) -> FreeFloatingState:
        """Hold the joint-rate command for ``dt_s`` seconds and advance the state.

        The command is limited by :meth:`RateServo.limit_command` (rate and joint limits).
        """
        s = self.state
        servo = self.servo
        u = servo.limit_command(rate_command_rad_s, s.q_rad, self.robot.q_lower_rad, self.robot.q_upper_rad, dt_s)
        # split at the servo's switch times, where the joint acceleration jumps: keeps fourth order
        switches = servo.switch_times(s.dq_rad_s, u).tolist()
        cuts = sorted({0.0, dt_s, *(t for t in switches if 0.0 < t < dt_s)})
        if self.substeps > 1:
            cuts = sorted({float(t) for a, b in itertools.pairwise(cuts) for t in np.linspace(a, b, self.substeps + 1)})
        # joint motion at every interval's midpoint and end (t = 0 is the current state)
        times = [t for a, b in itertools.pairwise(cuts) for t in (0.5 * (a + b), b)]
        q_t, dq_t, ddq_t = servo.motion(s.q_rad, s.dq_rad_s, u, times)
        rot, twist = s.rot_wb, s.v_base_body
        for i in range(len(cuts) - 1):
            mid = self._base_terms(s.t_s + times[2 * i], q_t[2 * i], dq_t[2 * i])
            end = self._base_terms(s.t_s + times[2 * i + 1], q_t[2 * i + 1], dq_t[2 * i + 1])
            rot = rkmk4_attitude(rot, twist[3:], cuts[i + 1] - cuts[i], self.momentum_world, *mid[1:], *end[1:])
            twist = base_twist_at_attitude(rot, self.momentum_world, *end[1:])
        p = end[3] - rot @ end[0].lever
        self.state = FreeFloatingState(s.t_s + dt_s, rot, p, q_t[-1], dq_t[-1], ddq_t[-1], twist, end[0])
        return self.state

    def _base_terms(self, t_s: float, q_rad: FloatArray, dq_rad_s: FloatArray) -> BaseTerms:
        """What the base twist depends on at ``(t, q, dq)``, apart from the attitude.

        Returns ``(composite, H_bb^{-1} (6, 6), H_bm dq (6,), CoM in base frame (3,), CoM in the inertial frame (3,))``,
        ``composite`` the whole robot's spatial inertia in the base frame (``H_bb``).
        """
        self._q_full[7:] = q_rad
        coupling = pin.crba(self.model, self.data, self._q_full)[:6, 6:]
        composite = self.data.Ycrb[1].copy()
        return composite, composite.inverse(), coupling @ dq_rad_s, composite.lever, self._com_world(t_s)

    def _com_world(self, t_s: float) -> FloatArray:
        """System CoM in the inertial frame: it moves uniformly with the linear momentum."""
        if self._zero_momentum:
            return self._com0_world
        return self._com0_world + self.momentum_world[:3] * (t_s / self.total_mass_kg)


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
    momentum_world: FloatArray,
    inv_mid: FloatArray,
    arm_mid: FloatArray,
    com_base_mid: FloatArray,
    com_world_mid: FloatArray,
    inv_end: FloatArray,
    arm_end: FloatArray,
    com_base_end: FloatArray,
    com_world_end: FloatArray,
) -> FloatArray:
    """One RKMK4 step of length ``h`` for the base attitude on SO(3).

    ``R = R0 exp([theta]x)`` with ``d theta/dt = dexp^{-1}(theta, omega_base_body)``. The body rate
    is ``omega0`` at the start; at ``t + h/2`` and ``t + h`` it follows from the base terms there
    (:data:`BaseTerms`) and the stage attitude. Compiled with numba (it runs every env step).
    """
    k1 = omega0.copy()
    th2 = 0.5 * h * k1
    k2 = dexp_inv(
        th2, base_twist_at_attitude(rot0 @ so3_exp(th2), momentum_world, inv_mid, arm_mid, com_base_mid, com_world_mid)[3:]
    )
    th3 = 0.5 * h * k2
    k3 = dexp_inv(
        th3, base_twist_at_attitude(rot0 @ so3_exp(th3), momentum_world, inv_mid, arm_mid, com_base_mid, com_world_mid)[3:]
    )
    th4 = h * k3
    k4 = dexp_inv(
        th4, base_twist_at_attitude(rot0 @ so3_exp(th4), momentum_world, inv_end, arm_end, com_base_end, com_world_end)[3:]
    )
    return rot0 @ so3_exp((h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4))
