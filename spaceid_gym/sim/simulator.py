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

Hidden effects (:class:`~spaceid_gym.effects.HiddenEffects`)
-----------------------------------------------------------
* ``initial_momentum``: the default system momentum of :meth:`FreeFloatingSimulator.reset`.
* ``external_torque``: a pure torque, inertial frame, ``tau(t) = tau0 + tau1 t``; the momentum is
  ``L(t) = L0 + tau0 t + tau1 t^2 / 2`` (linear momentum unchanged), and every RKMK4 stage uses
  the momentum at its own time.
* ``payload``: the dynamics run on :meth:`Robot.with_payload`.
* ``slosh``: a point mass ``m_s`` whose rest point is the tank point (``m_s`` is taken out of the
  rigid base there), on joints appended to the pinocchio model after the arm joints. The spring
  model (``slosh_model`` unset or ``"spring"``): three prismatic joints along the base axes at the
  tank point, coordinates ``x`` the displacement (m, base axes), pulled back by the spring-damper
  ``-k x - c dx``. The pendulum (``"pendulum"``): a universal joint at the hinge ``tank - L a``, two
  revolute joints about ``e1`` and then the turned ``e2`` (``(e1, e2, a)`` right-handed, base frame),
  the mass at ``L`` along the rod, which is ``a`` at zero angles; coordinates ``x`` the two angles
  (rad), pulled back as a pendulum under the effective acceleration ``L (2 pi f)^2`` along ``a``, at any
  angle, and damped on the mass's velocity relative to the base
  (:meth:`~spaceid_gym.sim.slosh.SloshBody.joint_force`; for small angles the torsional spring-damper
  ``-k L^2 x - c L^2 dx``). The universal joint's chart is singular at ``x1 = +-90 deg`` (the rod along
  ``e1``): a start or a step beyond 85 deg raises an error rather than lose accuracy. Either way the
  base twist still follows from the momentum, now with the slosh rates; the slosh accelerations
  follow from the equations of motion (CRBA + nonlinear effects) of the base and slosh coordinates
  with the arm accelerations known from the servo, the base wrench zero (or the external torque).
  The attitude and the slosh state ``(x, dx)`` are integrated together by the same RKMK4 (classical
  RK4 for ``x, dx``).
* ``delay``: :meth:`FreeFloatingSimulator.state_at` evaluates the trajectory at an earlier time by
  integrating from the start of the control period that contains it (the joint motion is closed form).
* ``gyro_bias`` / ``gyro_scale`` belong to the sensors (:class:`~spaceid_gym.sim.sensors.SensorModel`).
"""

from __future__ import annotations

import itertools
from collections import deque

import numpy as np
import pinocchio as pin

from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.settings import HiddenEffects
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import RigidBodyInertia
from spaceid_gym.robots.robot import Robot
from spaceid_gym.sim.attitude_step import BaseTerms, base_twist_at_attitude, rkmk4_attitude
from spaceid_gym.sim.lie import dexp_inv, so3_exp
from spaceid_gym.sim.servo import RateServo, default_servo
from spaceid_gym.sim.slosh import (
    base_without_slosh,
    initial_slosh,
    model_with_slosh,
    slosh_acceleration,
    slosh_base_twist,
    slosh_body,
)
from spaceid_gym.sim.state import FreeFloatingState

#: the longest step the env lets the attitude integrator take (s): a control period longer than this is cut into
#: :func:`integration_substeps_for` steps. At 0.02 s the RKMK4 attitude's global error is about 1e-9 rad over 10 s of
#: full-rate motion (``benchmarks/physics_checks.py``: 4.7e-8 at 0.05 s, fourth order); at one 0.05 s step per sample a
#: noise-free attitude carried an error the diagnosis took for a payload (clean 11240, ``quick3`` at 20 Hz)
MAX_INTEGRATION_STEP_S = 0.02


def integration_substeps_for(control_period_s: float) -> int:
    """The simulator's steps per control period of ``control_period_s`` so that none is longer than
    :data:`MAX_INTEGRATION_STEP_S`: 1 at 50 and 100 Hz, 3 at 20 Hz."""
    if not (np.isfinite(control_period_s) and control_period_s > 0.0):
        raise SpaceIdInputError(f"control_period_s: expected a positive number of seconds, got {control_period_s!r}")
    return max(1, int(np.ceil(control_period_s / MAX_INTEGRATION_STEP_S - 1e-9)))


class FreeFloatingSimulator:
    """Integrates a free-floating robot whose joints follow commanded rates.

    Args:
        robot: the robot description (its full-tank base is replaced by ``base``).
        base: the true current base mass properties (e.g. from
            :func:`spaceid_gym.physics.fuel.base_after_fuel`); with slosh, including the slosh
            mass at rest.
        servo: the joint servo; default :func:`spaceid_gym.sim.servo.default_servo`.
        substeps: integration intervals per smooth piece of a control period (>= 1).
        effects: hidden effects to simulate (see the module docstring); default none.
        tank_point_m: the tank's position in the base frame (full-tank CoM + ``bf``), m, shape (3,);
            required for ``slosh``.

    Attributes:
        model: the pinocchio model of the dynamics (true base, payload, slosh joints after the arm's),
            matching :meth:`FreeFloatingState.pinocchio_configuration`.
        arm_model: the same without the slosh joints (slosh mass at rest in the base), e.g. for rendering.
        slosh: the :class:`SloshBody`, or ``None``.
    """

    def __init__(
        self,
        robot: Robot,
        base: RigidBodyInertia,
        servo: RateServo | None = None,
        substeps: int = 1,
        effects: HiddenEffects | None = None,
        tank_point_m: FloatArray | None = None,
    ) -> None:
        if substeps < 1:
            raise ValueError(f"substeps: expected >= 1, got {substeps}")
        self.effects = effects if effects is not None else HiddenEffects()
        payload = self.effects.array("payload_params10")
        self.robot = robot if payload is None else robot.with_payload(RigidBodyInertia.from_params10(payload))
        self.arm_model = self.robot.model_with_base(base)
        self.slosh = slosh_body(self.effects, tank_point_m)
        if self.slosh is None:
            self.model = self.arm_model
        else:
            self.model = model_with_slosh(self.robot, base_without_slosh(base, self.slosh), self.slosh)
        self.data = self.model.createData()
        self.servo = servo if servo is not None else default_servo(self.robot.rate_limit_rad_s)
        self.substeps = int(substeps)
        self.total_mass_kg = float(sum(inertia.mass for inertia in self.model.inertias))
        torque, torque_rate = self.effects.array("external_torque_Nm"), self.effects.array("external_torque_rate_Nm_s")
        self._torque: tuple[FloatArray, FloatArray] | None = None
        if torque is not None or torque_rate is not None:
            self._torque = (np.zeros(3) if torque is None else torque, np.zeros(3) if torque_rate is None else torque_rate)
        self.momentum_world = np.zeros(6)
        self._zero_momentum = True
        self._com0_world = np.zeros(3)
        self._q_full = pin.neutral(self.model)
        delay = self.effects.delay_s
        self._history_s = 0.0 if delay is None else float(delay)
        self._history: deque[tuple[FreeFloatingState, FloatArray]] = deque()
        self.state = self.reset()

    def reset(
        self,
        q0_rad: FloatArray | None = None,
        rot_wb: FloatArray | None = None,
        momentum_world: FloatArray | None = None,
        slosh_m: FloatArray | None = None,
        slosh_angles_rad: FloatArray | None = None,
    ) -> FreeFloatingState:
        """Start with the joints at rest and the system CoM at the inertial origin.

        Args:
            q0_rad: initial joint angles (n,); default the robot's home configuration.
            rot_wb: initial base attitude; default identity.
            momentum_world: system momentum ``[P; L]`` at t = 0 about the inertial origin (6,),
                N s and N m s; default zero (the paper's assumption) or the ``initial_momentum``
                effect. A non-zero ``L`` makes the base spin (residual spin, stored wheel momentum).
                It stays constant unless the ``external_torque`` effect is set.
            slosh_m: initial slosh displacement from the rest point (3,), base axes, m (with the spring
                model; default zero); the slosh mass starts at rest relative to the base.
            slosh_angles_rad: initial hinge angles (2,), rad (with the pendulum; default zero), the mass at
                rest relative to the base.
        """
        n = self.robot.n_joints
        q0 = self.robot.home_configuration() if q0_rad is None else np.asarray(q0_rad, dtype=float)
        rot = np.eye(3) if rot_wb is None else np.asarray(rot_wb, dtype=float)
        if momentum_world is not None:
            self.momentum_world = np.asarray(momentum_world, dtype=float)
        else:
            self.momentum_world = self.effects.momentum_world()
        self._zero_momentum = not self.momentum_world.any()
        if self.slosh is not None:
            x0 = initial_slosh(self.slosh, slosh_m, slosh_angles_rad)
            rest = np.zeros_like(x0)
            twist, p = self._slosh_kinematics(0.0, rot, x0, rest, q0, np.zeros(n))[:2]
            composite = self.data.Ycrb[1].copy()
            self.state = self._slosh_state(0.0, rot, p, q0.copy(), np.zeros(n), np.zeros(n), twist, composite, x0, rest)
        else:
            if slosh_m is not None or slosh_angles_rad is not None:
                raise SpaceIdInputError(
                    "reset: slosh_m and slosh_angles_rad need the 'slosh' hidden effect with a slosh mass > 0"
                )
            terms = self._base_terms(0.0, q0, np.zeros(n))
            twist = base_twist_at_attitude(rot, self.momentum_world, *terms[1:])
            p = terms[3] - rot @ terms[0].lever
            self.state = FreeFloatingState(0.0, rot, p, q0.copy(), np.zeros(n), np.zeros(n), twist, terms[0])
        self._initial_state = self.state
        self._history.clear()
        return self.state

    def base_twist(self, q_rad: FloatArray, dq_rad_s: FloatArray, rot_wb: FloatArray, t_s: float = 0.0) -> FloatArray:
        """Base twist ``[v_lin; omega]`` (base axes) from momentum conservation, shape (6,) (slosh at rest)."""
        if self.slosh is not None:
            rest = np.zeros(self.slosh.n_coordinates)
            return self._slosh_kinematics(t_s, rot_wb, rest, rest, q_rad, dq_rad_s)[0]
        return base_twist_at_attitude(rot_wb, self._momentum_at(t_s), *self._base_terms(t_s, q_rad, dq_rad_s)[1:])

    def step(self, rate_command_rad_s: FloatArray, dt_s: float) -> FreeFloatingState:
        """Hold the joint-rate command for ``dt_s`` seconds and advance the state.

        The command is limited by :meth:`RateServo.limit_command` (rate and joint limits).
        """
        s = self.state
        u = self.servo.limit_command(rate_command_rad_s, s.q_rad, self.robot.q_lower_rad, self.robot.q_upper_rad, dt_s)
        self.state = self._advance(s, u, dt_s)
        if self._history_s > 0.0:  # keep the periods a delayed sensor may still look into
            self._history.append((s, u))
            while len(self._history) > 1 and self._history[1][0].t_s <= self.state.t_s - self._history_s:
                self._history.popleft()
        return self.state

    def state_at(self, t_s: float) -> FreeFloatingState:
        """The state at an earlier time ``t_s`` (for a sensor that lags), exactly on the simulated trajectory.

        Before the start (t = 0) the system is in its initial state. Within 1 ns of a control-period boundary
        the stored state is returned (so a whole-sample delay reproduces the log shifted, bit for
        bit); otherwise the period containing ``t_s`` is integrated from its start with its command
        (closed-form joint motion, RKMK4 for the rest). Only times back to ``delay_s`` of the
        ``delay`` effect are kept.

        Raises:
            SpaceIdInputError: ``t_s`` is later than the current time or older than the kept history.
        """
        tol = 1e-9
        now = self.state
        if t_s > now.t_s + tol:
            raise SpaceIdInputError(f"state_at: t = {t_s!r} s is after the current time {now.t_s!r} s")
        if t_s >= now.t_s - tol:
            return now
        if t_s <= self._initial_state.t_s + tol:  # at rest before the start: the initial state
            return self._initial_state
        for start, u in reversed(self._history):
            if t_s >= start.t_s - tol:
                offset = t_s - start.t_s
                return start if offset <= tol else self._advance(start, u, offset)
        raise SpaceIdInputError(
            f"state_at: t = {t_s!r} s is older than the kept history (the 'delay' effect sets its length, {self._history_s!r} s)"
        )

    def _advance(self, s: FreeFloatingState, u: FloatArray, dt_s: float) -> FreeFloatingState:
        """The state ``dt_s`` after ``s`` under the (limited) command ``u``."""
        servo = self.servo
        # split at the servo's switch times, where the joint acceleration jumps: keeps fourth order
        switches = servo.switch_times(s.dq_rad_s, u).tolist()
        cuts = sorted({0.0, dt_s, *(t for t in switches if 0.0 < t < dt_s)})
        if self.substeps > 1:
            cuts = sorted({float(t) for a, b in itertools.pairwise(cuts) for t in np.linspace(a, b, self.substeps + 1)})
        # joint motion at every interval's midpoint and end (t = 0 is the current state)
        times = [t for a, b in itertools.pairwise(cuts) for t in (0.5 * (a + b), b)]
        if self.slosh is not None:
            return self._advance_slosh(s, u, dt_s, cuts, times)
        q_t, dq_t, ddq_t = servo.motion(s.q_rad, s.dq_rad_s, u, times)
        rot, twist = s.rot_wb, s.v_base_body
        for i in range(len(cuts) - 1):
            t_mid, t_end = s.t_s + times[2 * i], s.t_s + times[2 * i + 1]
            mid = self._base_terms(t_mid, q_t[2 * i], dq_t[2 * i])
            end = self._base_terms(t_end, q_t[2 * i + 1], dq_t[2 * i + 1])
            h_end = self._momentum_at(t_end)
            rot = rkmk4_attitude(rot, twist[3:], cuts[i + 1] - cuts[i], self._momentum_at(t_mid), *mid[1:], h_end, *end[1:])
            twist = base_twist_at_attitude(rot, h_end, *end[1:])
        p = end[3] - rot @ end[0].lever
        return FreeFloatingState(s.t_s + dt_s, rot, p, q_t[-1], dq_t[-1], ddq_t[-1], twist, end[0])

    def _advance_slosh(
        self, s: FreeFloatingState, u: FloatArray, dt_s: float, cuts: list[float], times: list[float]
    ) -> FreeFloatingState:
        """:meth:`_advance` with the slosh mass: RKMK4 on ``(R, x, dx)`` over each smooth interval."""
        assert s.slosh_coordinates is not None
        q_t, dq_t, ddq_t = self.servo.motion(s.q_rad, s.dq_rad_s, u, [0.0, *times])  # row 0: just after the command
        rot, (x, v) = s.rot_wb, s.slosh_coordinates
        rates = self._slosh_rates(s.t_s, rot, x, v, q_t[0], dq_t[0], ddq_t[0])
        for i in range(len(cuts) - 1):
            h = cuts[i + 1] - cuts[i]
            k_omega, k_x, k_v = [rates[0][3:]], [v], [rates[1]]
            for c, j in ((0.5, 2 * i + 1), (0.5, 2 * i + 1), (1.0, 2 * i + 2)):
                theta = c * h * k_omega[-1]
                x_c, v_c = x + c * h * k_x[-1], v + c * h * k_v[-1]
                stage = self._slosh_rates(s.t_s + times[j - 1], rot @ so3_exp(theta), x_c, v_c, q_t[j], dq_t[j], ddq_t[j])
                k_omega.append(dexp_inv(theta, stage[0][3:]))
                k_x.append(v_c)
                k_v.append(stage[1])
            rot = rot @ so3_exp(_rk4_sum(h, k_omega))
            x, v = x + _rk4_sum(h, k_x), v + _rk4_sum(h, k_v)
            self.slosh.check_chart(x, s.t_s + cuts[i + 1])
            end = 2 * i + 2
            rates = self._slosh_rates(s.t_s + times[end - 1], rot, x, v, q_t[end], dq_t[end], ddq_t[end])
        composite = self.data.Ycrb[1].copy()  # of the last evaluation: the end state
        return self._slosh_state(s.t_s + dt_s, rot, rates[2], q_t[-1], dq_t[-1], ddq_t[-1], rates[0], composite, x, v)

    def _slosh_state(
        self,
        t_s: float,
        rot_wb: FloatArray,
        p_wb_m: FloatArray,
        q_rad: FloatArray,
        dq_rad_s: FloatArray,
        ddq_rad_s2: FloatArray,
        twist: FloatArray,
        composite: pin.Inertia,
        x: FloatArray,
        v: FloatArray,
    ) -> FreeFloatingState:
        """A state with the slosh joint coordinates ``x`` and rates ``v`` (the pendulum's also as the mass's displacement)."""
        assert self.slosh is not None
        displacement, rate = self.slosh.displacement(x, v)
        angles = (x, v) if self.slosh.is_pendulum else (None, None)
        return FreeFloatingState(t_s, rot_wb, p_wb_m, q_rad, dq_rad_s, ddq_rad_s2, twist, composite, displacement, rate, *angles)

    def _slosh_kinematics(
        self, t_s: float, rot_wb: FloatArray, x_slosh: FloatArray, dx_slosh: FloatArray, q_rad: FloatArray, dq_rad_s: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Base twist from the momentum with the slosh joints at ``x_slosh`` moving at ``dx_slosh`` (m or rad, 3 or 2).

        Leaves the CRBA of the configuration in ``self.data`` (``Ycrb[1]`` is the composite inertia).

        Returns ``(twist (6,), base position p_wb (3,), joint-space mass matrix (nv, nv), upper triangle valid)``.
        """
        n = self.robot.n_joints
        q_full = self._q_full
        q_full[7 : 7 + n] = q_rad
        q_full[7 + n :] = x_slosh
        mass = pin.crba(self.model, self.data, q_full)
        twist, p = slosh_base_twist(
            mass, self.data.Ycrb[1].lever, self._com_world(t_s), rot_wb, self._momentum_at(t_s), dq_rad_s, dx_slosh
        )
        return twist, p, mass

    def _slosh_rates(
        self,
        t_s: float,
        rot_wb: FloatArray,
        x_slosh: FloatArray,
        dx_slosh: FloatArray,
        q_rad: FloatArray,
        dq_rad_s: FloatArray,
        ddq_rad_s2: FloatArray,
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Base twist (6,), slosh joint accelerations (3 or 2) and base position ``p_wb`` (3,) at one instant.

        Solves the base and slosh rows of ``M a + nle = tau`` for the base and slosh accelerations,
        the arm's ``ddq`` given: ``tau`` is the external torque on the base (base axes, zero without
        the effect) and the restoring and damping force on the slosh joints (:meth:`SloshBody.joint_force`).
        """
        assert self.slosh is not None
        twist, p, mass = self._slosh_kinematics(t_s, rot_wb, x_slosh, dx_slosh, q_rad, dq_rad_s)
        nle = pin.nonLinearEffects(self.model, self.data, self._q_full, np.concatenate((twist, dq_rad_s, dx_slosh)))
        torque_base = np.zeros(3) if self._torque is None else rot_wb.T @ self._torque_world(t_s)
        force = self.slosh.joint_force(x_slosh, dx_slosh)
        acc = slosh_acceleration(mass, nle, torque_base, force, ddq_rad_s2)
        return twist, acc, p

    def _momentum_at(self, t_s: float) -> FloatArray:
        """System momentum ``[P; L]`` about the inertial origin at time ``t_s`` (6,): constant without external torque."""
        if self._torque is None:
            return self.momentum_world
        tau0, tau1 = self._torque
        out = self.momentum_world.copy()
        out[3:] += tau0 * t_s + tau1 * (0.5 * t_s * t_s)
        return out

    def _torque_world(self, t_s: float) -> FloatArray:
        """External torque at ``t_s``, inertial frame (3,), N m."""
        assert self._torque is not None
        return self._torque[0] + self._torque[1] * t_s

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


def _rk4_sum(h: float, k: list[FloatArray]) -> FloatArray:
    """``h/6 (k1 + 2 k2 + 2 k3 + k4)``."""
    return (h / 6.0) * (k[0] + 2.0 * k[1] + 2.0 * k[2] + k[3])
