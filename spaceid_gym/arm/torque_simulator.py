"""Torque-level simulation of a fixed-base arm with friction, a tracking controller and joint sensors.

Plant
-----
``M(q) ddq + C(q, dq) dq + g(q) = u - tau_f(dq)`` with the **true** rigid-body parameters (a
pinocchio model from :meth:`ArmRegressor.model_with_parameters`, solved by the ABA of
:mod:`spaceid_gym.arm.chain_dynamics`, equal to pinocchio's to round-off, or by pinocchio's) and
the true friction ``tau_f`` of :class:`~spaceid_gym.arm.friction.FrictionModel` (Coulomb with the
model's smooth sign ``tanh(dq / v_eps)``, viscous, optional Stribeck and offset terms). ``u`` is
the motor torque referred to the joint (gear ratio included): what ``k_t`` times the motor current
measures, friction included (a torque sensor behind the gearbox would measure ``u - tau_f``). No rotor inertia (armature) and no joint elasticity: the plant is exactly the
identification model ``u = Y(q, dq, ddq) p`` of :class:`~spaceid_gym.arm.regressor.ArmRegressor`.

Controller
----------
A continuous-time computed-torque tracking controller (:class:`TrackingController`): with a
reference ``(q_r, dq_r, ddq_r)(t)``,

    v   = ddq_r + Kp (q_r - q) + Kd (dq_r - dq),    Kp = w^2, Kd = 2 zeta w   (per joint, 1/s^2, 1/s)
    u   = RNEA_c(q, dq, v) + tau_f(dq)

``RNEA_c`` is the controller's rigid-body model (default: the robot's URDF, the *nominal*
parameters, not the true ones, so tracking is imperfect and the error is a test). The friction
compensation ``tau_f(dq)`` is the plant's own (documented simplification): with the smoothed
Coulomb term the friction's slope ``fc / v_eps`` (100 N m s/rad per N m of ``fc``) acting on the
UR5's last link (smallest eigenvalue of ``M``: 1.3e-4 kg m^2, no rotor inertia in the model)
makes any uncompensated friction an ODE with eigenvalues near -1e6 1/s, which no explicit
integrator at a kHz rate can follow. Compensated, the closed loop is
``ddq = M^-1 (M_c v + h_c - h)``: smooth and non-stiff, integrated by RK4. It drives the rigid
body with ``u - tau_f(dq) = RNEA_c(q, dq, v)``; the logged motor torque ``u`` contains the friction.
The controller sees the true state (no sensor noise in the loop) and is not saturated at the
torque limits (the largest ``|u| / limit`` is reported as ``max_torque_fraction``). With the
default bandwidth (2 pi 30 Hz) and a robot drawn from
:class:`~spaceid_gym.arm.parameter_prior.ParameterPrior` (10 %, 1 cm), the tracking error of a
Fourier excitation is about 3e-5 rad on joints 1-3 and up to 3e-3 rad on the light wrist joints,
whose CoM error (1 cm on links of 0.2 - 1.2 kg) the nominal model misses.

Integration and sampling
------------------------
Fixed-step classical RK4 at ``internal_rate_hz`` (default 1 kHz, rounded up so that a whole number
``m`` of steps fits into one sample period), the controller evaluated at every RK4 stage (a
continuous-time servo). The log is sampled every ``1 / sample_rate_hz`` (default 125 Hz, the
UR5 CB-series controller rate). At each sample the logged ``ddq`` is the plant's acceleration at
that state (ABA), so ``u = Y(q, dq, ddq) p`` holds at every sample to round-off whatever the
integration error; free motion (``controller=None``, no friction) conserves energy to RK4's
fourth order (tests).

Sensors: white noise on the joint angles, rates and motor current
(:class:`~spaceid_gym.arm.joint_sensors.ArmSensorModel`; its defaults and their basis there). True
parameters: drawn around the URDF and a default friction (:mod:`spaceid_gym.arm.parameter_prior`).

Frames and units: joint space only; rad, rad/s, rad/s^2, N m, A, s; gravity is the robot's
(``ArmRobot.gravity_m_s2``, base frame).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from spaceid_gym.arm.arm_robot import ArmRobot
from spaceid_gym.arm.chain_dynamics import (
    ChainArrays,
    SerialChain,
    chain_arrays,
    constant_acceleration_period,
    rk4_period,
    servo_sample,
)
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.arm.regressor import ArmRegressor
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: A reference trajectory: times (T,) s -> (q_r (T, n) rad, dq_r (T, n) rad/s, ddq_r (T, n) rad/s^2).
Reference = Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray]]

#: Default internal (integration) rate, Hz.
INTERNAL_RATE_HZ = 1000.0
#: Default sample rate of the log, Hz (the UR5 CB-series controller's 8 ms cycle).
SAMPLE_RATE_HZ = 125.0


# ---------------------------------------------------------------------- controller
@dataclass(frozen=True)
class TrackingController:
    """Gains and model of the computed-torque tracking controller (see the module docstring).

    Attributes:
        bandwidth_rad_s: ``w`` of the error dynamics ``e'' + 2 zeta w e' + w^2 e = 0`` (default 2 pi 30 Hz).
        damping_ratio: ``zeta`` (default 1, critically damped).
        inertial_parameters: the controller's rigid-body model, the 10 n inertial parameters in
            regressor order; ``None`` = the robot's URDF values (nominal).
    """

    bandwidth_rad_s: float = 2.0 * math.pi * 30.0
    damping_ratio: float = 1.0
    inertial_parameters: FloatArray | None = None

    def __post_init__(self) -> None:
        for name in ("bandwidth_rad_s", "damping_ratio"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise SpaceIdInputError(f"controller: {name} must be a finite number > 0, got {value!r}")

    def as_dict(self) -> dict[str, Any]:
        """The settings for ``truth.json``."""
        return {
            "kind": "computed_torque",
            "bandwidth_rad_s": float(self.bandwidth_rad_s),
            "damping_ratio": float(self.damping_ratio),
            "model": "nominal (URDF)" if self.inertial_parameters is None else "given",
        }


@dataclass(frozen=True)
class ArmState:
    """The simulator's true state: time ``t_s`` (s), ``q_rad`` (n,) rad, ``dq_rad_s`` (n,) rad/s."""

    t_s: float
    q_rad: FloatArray
    dq_rad_s: FloatArray


@dataclass(frozen=True, eq=False)
class ArmSimulation:
    """The result of :meth:`ArmSimulator.run`.

    Attributes:
        log: the measured log (sensor noise), ``ddq_rad_s2`` the plant's true acceleration (not a
            measurement; :func:`~spaceid_gym.arm.signal.prepare_for_identification` replaces it).
        clean: the same samples without sensor noise (true q, dq, ddq, effort).
        motor_torque_Nm: the true motor torque ``u`` at the samples, shape (T, n), N m.
        q_ref_rad: the reference at the samples, shape (T, n), rad.
        truth: true parameters and settings (see :meth:`ArmSimulator.truth`) plus tracking and torque figures.
    """

    log: ArmLog
    clean: ArmLog
    motor_torque_Nm: FloatArray
    q_ref_rad: FloatArray
    truth: dict[str, Any]


# ---------------------------------------------------------------------- simulator
class ArmSimulator:
    """Forward dynamics of a fixed-base arm with friction under a tracking controller (module docstring).

    Args:
        robot: the arm.
        parameters: true parameters ``p`` in :class:`ArmRegressor` order (10 n inertial, then friction), shape (p,).
        friction: the friction model of ``parameters`` (:class:`FrictionModel` or term names; ``None`` = none).
        sensors: :class:`ArmSensorModel` (default settings if ``None``), or ``"noise_free"``.
        controller: :class:`TrackingController` (default gains if not given); ``None`` = no control,
            ``u = 0`` (free motion, for physics checks; needs zero friction).
        internal_rate_hz: RK4 rate, Hz (rounded up to a whole number of steps per sample).
        sample_rate_hz: log rate, Hz.

    Attributes:
        regressor: the :class:`ArmRegressor` of ``robot`` and ``friction`` (parameter names, order).
        parameters: ``p`` (read-only copy).
        steps_per_sample: ``m``; ``step_s = 1 / (sample_rate_hz m)`` is the RK4 step, s.
    """

    def __init__(
        self,
        robot: ArmRobot,
        parameters: FloatArray,
        friction: FrictionModel | Sequence[str] | None = ("coulomb", "viscous"),
        sensors: ArmSensorModel | str | None = None,
        controller: TrackingController | None = TrackingController(),
        internal_rate_hz: float = INTERNAL_RATE_HZ,
        sample_rate_hz: float = SAMPLE_RATE_HZ,
    ) -> None:
        self.robot = robot
        self.regressor = ArmRegressor(robot, friction)
        n, n_inertial = robot.n_joints, self.regressor.n_inertial
        p = np.array(parameters, dtype=float)
        if p.shape != (self.regressor.n_parameters,) or not np.isfinite(p).all():
            raise SpaceIdInputError(
                f"simulator: parameters must be {self.regressor.n_parameters} finite numbers "
                f"(10 per body, then friction {list(self.regressor.friction.terms)} per joint), got shape {p.shape}"
            )
        p.flags.writeable = False
        self.parameters = p
        self.sensors = ArmSensorModel.coerce(sensors)
        self.sensors.check(n)
        for name, rate in (("internal_rate_hz", internal_rate_hz), ("sample_rate_hz", sample_rate_hz)):
            if not (np.isfinite(rate) and rate > 0):
                raise SpaceIdInputError(f"simulator: {name} must be a positive rate in Hz, got {rate!r}")
        self.sample_rate_hz = float(sample_rate_hz)
        self.steps_per_sample = max(1, math.ceil(internal_rate_hz / sample_rate_hz - 1e-9))
        self.step_s = 1.0 / (self.sample_rate_hz * self.steps_per_sample)
        self.friction_coefficients = p[n_inertial:].reshape(n, self.regressor.friction.n_terms)
        self.controller = controller
        if controller is None and np.any(self.friction_coefficients != 0):
            raise SpaceIdInputError(
                "simulator: controller=None (free motion) needs zero friction coefficients: uncompensated smoothed "
                "Coulomb friction makes the ODE stiff (see the module docstring)"
            )
        self._model = self.regressor.model_with_parameters(p)
        self._data = self._model.createData()
        if controller is not None:
            controller_p = self.regressor.nominal_parameters()
            if controller.inertial_parameters is not None:
                given = np.asarray(controller.inertial_parameters, dtype=float)
                if given.shape != (n_inertial,) or not np.isfinite(given).all():
                    raise SpaceIdInputError(
                        f"controller: inertial_parameters must be {n_inertial} finite numbers (10 per body), got shape {given.shape}"
                    )
                controller_p[:n_inertial] = given
            self._controller_model = self.regressor.model_with_parameters(controller_p)
            self._controller_data = self._controller_model.createData()
            w, zeta = controller.bandwidth_rad_s, controller.damping_ratio
            self._kp, self._kd = w * w, 2.0 * zeta * w
        # the compiled dynamics of a serial revolute chain (pinocchio's functions otherwise; the same to round-off);
        # they need the controller's model to differ from the plant's in its inertias only
        self._compiled: tuple[ChainArrays, ChainArrays] | None = None
        plant_chain = SerialChain.from_pinocchio(self._model)
        if controller is not None and plant_chain is not None:
            controller_chain = SerialChain.from_pinocchio(self._controller_model)
            if controller_chain is not None and plant_chain.same_geometry(controller_chain):
                self._compiled = (chain_arrays(plant_chain), chain_arrays(controller_chain))
        self.reset(np.zeros(n))

    # ------------------------------------------------------------------ state
    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return self.robot.n_joints

    @property
    def state(self) -> ArmState:
        """The current true state (copies)."""
        return ArmState(self._t, self._q.copy(), self._dq.copy())

    def reset(self, q_rad: FloatArray, dq_rad_s: FloatArray | None = None, t_s: float = 0.0) -> None:
        """Set the state: joint angles (n,) rad, rates (n,) rad/s (default zero), time s."""
        n = self.n_joints
        q = np.array(q_rad, dtype=float).reshape(-1)
        dq = np.zeros(n) if dq_rad_s is None else np.array(dq_rad_s, dtype=float).reshape(-1)
        if q.shape != (n,) or dq.shape != (n,) or not (np.isfinite(q).all() and np.isfinite(dq).all()):
            raise SpaceIdInputError(
                f"simulator reset: q_rad and dq_rad_s must be {n} finite numbers each, got {q_rad!r}, {dq_rad_s!r}"
            )
        self._q, self._dq, self._t = q, dq, float(t_s)

    def stage_times(self, n_samples: int = 1) -> FloatArray:
        """Times of the RK4 stages over the next ``n_samples`` sample periods: ``t + i step_s / 2``, shape (2 m n_samples + 1,)."""
        return self._t + 0.5 * self.step_s * np.arange(2 * self.steps_per_sample * n_samples + 1)

    # ------------------------------------------------------------------ dynamics
    def _rigid_body_torque(self, q: FloatArray, dq: FloatArray, feedforward: FloatArray) -> FloatArray:
        """``u - tau_f(dq) = RNEA_c(q, dq, v)``, (n,) N m: the torque driving the rigid body (friction compensated).

        ``feedforward = ddq_r + Kp q_r + Kd dq_r`` (n,), so that ``v = feedforward - Kp q - Kd dq``.
        The result may be pinocchio's internal buffer: use it before the next controller call.
        """
        if self.controller is None:
            return np.zeros(self.n_joints)
        return pin.rnea(self._controller_model, self._controller_data, q, dq, feedforward - self._kp * q - self._kd * dq)

    def _feedforward(self, q_ref: FloatArray, dq_ref: FloatArray, ddq_ref: FloatArray) -> FloatArray:
        """``ddq_r + Kp q_r + Kd dq_r``, same shape as the reference (the state-independent part of ``v``)."""
        if self.controller is None:
            return np.zeros_like(q_ref)
        return ddq_ref + self._kp * q_ref + self._kd * dq_ref

    def advance(self, q_ref: FloatArray, dq_ref: FloatArray, ddq_ref: FloatArray) -> None:
        """Integrate one sample period (``m`` RK4 steps) tracking the reference given at :meth:`stage_times` (2 m + 1, n).

        ``ddq_ref`` may also be one row (n,), an acceleration constant over the period.
        """
        m, h = self.steps_per_sample, self.step_s
        if q_ref.shape[0] != 2 * m + 1:
            raise SpaceIdInputError(
                f"simulator advance: the reference needs {2 * m + 1} rows (stage_times()), got {q_ref.shape[0]}"
            )
        w = self._feedforward(q_ref, dq_ref, ddq_ref)
        if self._compiled is not None:
            self._q, self._dq = rk4_period(*self._compiled, self._q, self._dq, w, self._kp, self._kd, h)
            self._t += m * h
            return
        aba, model, data, torque = pin.aba, self._model, self._data, self._rigid_body_torque

        def acceleration(q: FloatArray, dq: FloatArray, row: int) -> FloatArray:
            return aba(model, data, q, dq, torque(q, dq, w[row])).copy()

        q, dq, half, sixth = self._q, self._dq, 0.5 * h, h / 6.0
        for s in range(0, 2 * m, 2):
            a1 = acceleration(q, dq, s)
            q2, dq2 = q + half * dq, dq + half * a1
            a2 = acceleration(q2, dq2, s + 1)
            q3, dq3 = q + half * dq2, dq + half * a2
            a3 = acceleration(q3, dq3, s + 1)
            q4, dq4 = q + h * dq3, dq + h * a3
            a4 = acceleration(q4, dq4, s + 2)
            q = q + sixth * (dq + 2.0 * (dq2 + dq3) + dq4)
            dq = dq + sixth * (a1 + 2.0 * (a2 + a3) + a4)
        self._q, self._dq = q, dq
        self._t += m * h

    def sample(self, q_ref: FloatArray, dq_ref: FloatArray, ddq_ref: FloatArray) -> tuple[FloatArray, FloatArray]:
        """At the current state with the reference (n,) each: motor torque ``u`` (n,) N m and acceleration ``ddq`` (n,) rad/s^2."""
        q, dq = self._q, self._dq
        if self._compiled is not None:
            rigid, ddq = servo_sample(self._compiled, q, dq, self._feedforward(q_ref, dq_ref, ddq_ref), (self._kp, self._kd))
            return rigid + self.friction_torque(dq), ddq
        rigid = self._rigid_body_torque(q, dq, self._feedforward(q_ref, dq_ref, ddq_ref)).copy()
        ddq = pin.aba(self._model, self._data, q, dq, rigid).copy()
        return rigid + self.friction_torque(dq), ddq

    def track_constant_acceleration(
        self, q_ref: FloatArray, dq_ref: FloatArray, ddq_ref: FloatArray, stage_offsets_s: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """:meth:`advance` then :meth:`sample` for a reference of constant acceleration over the period.

        The reference is ``q_r(t + tau) = q_ref + dq_ref tau + ddq_ref tau^2 / 2`` (n,) each, ``tau`` the offsets
        ``stage_offsets_s`` (2 m + 1,) s of :meth:`stage_times` from the current time. Returns the motor torque ``u``
        (n,) N m and acceleration ``ddq`` (n,) rad/s^2 at the period's end (as :meth:`sample`), and the reference's
        angles and rates there (n,) each.
        """
        if self._compiled is None:
            tau = stage_offsets_s[:, None]
            q_stage, dq_stage = q_ref + dq_ref * tau + 0.5 * ddq_ref * tau**2, dq_ref + ddq_ref * tau
            self.advance(q_stage, dq_stage, ddq_ref)
            return (*self.sample(q_stage[-1], dq_stage[-1], ddq_ref), q_stage[-1], dq_stage[-1])
        m, h = self.steps_per_sample, self.step_s
        if stage_offsets_s.shape != (2 * m + 1,):
            raise SpaceIdInputError(
                f"simulator: the reference needs {2 * m + 1} stage offsets (stage_times()), got {stage_offsets_s.shape}"
            )
        self._q, self._dq, rigid, ddq, q_end, dq_end = constant_acceleration_period(
            *self._compiled, self._q, self._dq, q_ref, dq_ref, ddq_ref, stage_offsets_s, self._kp, self._kd, h
        )
        self._t += m * h
        return rigid + self.friction_torque(self._dq), ddq, q_end, dq_end

    def friction_torque(self, dq_rad_s: FloatArray) -> FloatArray:
        """True friction torque for rates of shape (n,) or (T, n), N m, same shape."""
        return (self.regressor.friction.features(dq_rad_s) * self.friction_coefficients).sum(axis=-1)

    # ------------------------------------------------------------------ whole runs
    def run(
        self,
        reference: Reference,
        duration_s: float,
        rng: np.random.Generator,
        *,
        start_on_reference: bool = True,
        name: str = "arm-sim",
    ) -> ArmSimulation:
        """Track ``reference`` for ``duration_s`` and log it at ``sample_rate_hz``.

        Args:
            reference: times (T,) -> (q, dq, ddq) each (T, n) (e.g. a
                :class:`~spaceid_gym.arm.excitation_design.FourierTrajectory`), evaluated once at all stage times.
            duration_s: length, s; ``floor(duration * rate)`` sample periods (samples at 0 .. that time).
            rng: the generator of the sensor noise (one draw of shape (T, 3, n)).
            start_on_reference: start at ``t = 0`` on the reference's state (default), else from
                the current state and time (set by :meth:`reset` or left by an earlier run).
            name: the log's name.
        """
        if not (np.isfinite(duration_s) and duration_s > 0):
            raise SpaceIdInputError(f"simulator: duration_s must be a positive number of seconds, got {duration_s!r}")
        n_periods = math.floor(duration_s * self.sample_rate_hz + 1e-9)
        if n_periods < 1:
            raise SpaceIdInputError(f"simulator: duration_s = {duration_s!r} s is shorter than one sample period")
        if start_on_reference:
            self._t = 0.0
        stage_t = self.stage_times(n_periods)
        q_ref, dq_ref, ddq_ref = (np.asarray(x, dtype=float) for x in reference(stage_t))
        if q_ref.shape != (stage_t.size, self.n_joints) or dq_ref.shape != q_ref.shape or ddq_ref.shape != q_ref.shape:
            raise SpaceIdInputError(f"simulator: the reference must return three arrays of shape (T, {self.n_joints})")
        if start_on_reference:
            self.reset(q_ref[0], dq_ref[0], self._t)
        T, n, stride = n_periods + 1, self.n_joints, 2 * self.steps_per_sample
        t, q, dq, ddq, u = np.empty(T), np.empty((T, n)), np.empty((T, n)), np.empty((T, n)), np.empty((T, n))
        for k in range(T):
            i = k * stride
            t[k], q[k], dq[k] = self._t, self._q, self._dq
            u[k], ddq[k] = self.sample(q_ref[i], dq_ref[i], ddq_ref[i])
            if k < n_periods:
                window = slice(i, i + stride + 1)
                self.advance(q_ref[window], dq_ref[window], ddq_ref[window])
        q_m, dq_m, effort = self.sensors.measure(q, dq, u, rng)
        kind = self.sensors.effort_kind
        log = ArmLog(t, q_m, dq_m, ddq, effort, kind, name)
        clean = ArmLog(t, q, dq, ddq, self.sensors.effort_from_torque(u), kind, name)
        q_ref_samples = q_ref[::stride][:T]
        truth = self.truth()
        truth.update(
            tracking_error_max_rad=float(np.abs(q - q_ref_samples).max()),
            max_torque_fraction=float((np.abs(u) / self.robot.torque_limit_Nm).max()),
            duration_s=float(t[-1] - t[0]),
        )
        return ArmSimulation(log, clean, u, q_ref_samples, truth)

    def truth(self) -> dict[str, Any]:
        """True parameters (name -> value), friction model, noise, controller and rates, for ``truth.json``."""
        return {
            "robot": self.robot.name,
            "parameters": dict(zip(self.regressor.parameter_names, self.parameters.tolist(), strict=True)),
            "friction": {
                "terms": list(self.regressor.friction.terms),
                "coulomb_smoothing_rad_s": self.regressor.friction.coulomb_smoothing_rad_s,
                "stribeck_velocity_rad_s": self.regressor.friction.stribeck_velocity_rad_s,
            },
            "noise": self.sensors.as_dict(),
            "controller": None if self.controller is None else self.controller.as_dict(),
            "sample_rate_hz": self.sample_rate_hz,
            "internal_rate_hz": self.sample_rate_hz * self.steps_per_sample,
            "integrator": "rk4",
        }
