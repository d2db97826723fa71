"""``FreeFloatingID-v0``: excite a free-floating space robot so that its fuel state can be identified."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.settings import HiddenEffects
from spaceid_gym.effects.spec_strings import parse_effect_spec, parse_hidden_effects
from spaceid_gym.envs.actions import checked_action
from spaceid_gym.envs.render import RobotRenderer, base_half_extents_from_inertia
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.information import ExcitationMeasures, add_information, cramer_rao_std, excitation_measures
from spaceid_gym.log import MeasurementLog
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.physics.fuel import base_after_fuel, base_params10_fuel_jacobian, check_fuel
from spaceid_gym.physics.inertia import RigidBodyInertia
from spaceid_gym.physics.momentum import base_parameter_directions, twist_parameter_jacobian
from spaceid_gym.robots import Robot, load_robot
from spaceid_gym.sim.recorder import LogRecorder
from spaceid_gym.sim.sensors import Measurement, SensorModel
from spaceid_gym.sim.simulator import FreeFloatingSimulator, integration_substeps_for
from spaceid_gym.sim.state import FreeFloatingState

#: the default identification window: 3000 steps, 60 s at 50 Hz (the registered ``max_episode_steps``)
WINDOW_STEPS = 3000


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward's penalty terms (see :class:`FreeFloatingIDEnv`, *Rewards*).

    Attributes:
        joint_limit: penalty per step for a joint at its limit (quadratic over the last 10 % of
            the half-range).
        attitude_per_s: penalty per second of base rate at ``attitude_rate_ref_rad_s``.
        attitude_rate_ref_rad_s: base rate that costs ``attitude_per_s`` per second (rad/s).
    """

    joint_limit: float = 1.0
    attitude_per_s: float = 0.01
    attitude_rate_ref_rad_s: float = 0.02


class FreeFloatingIDEnv(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """Free-floating satellite with a robot arm whose fuel state (mass, tank position) is unknown.

    ## Description
    A satellite base carries an n-joint arm and floats freely (no gravity, no external torque).
    The agent commands joint rates; the base rotates in reaction (momentum conservation). How
    much it rotates depends on the base's mass properties, which change as fuel is consumed from
    a tank at an unknown position. Each episode is one identification window: the agent should
    move the arm so that the gyro and joint measurements carry as much information as possible
    about the fuel parameters ``theta = (mdf, bf_x, bf_y, bf_z)``. Between episodes fuel is
    consumed according to a :class:`~spaceid_gym.mission.FuelSchedule`.

    ## Action Space
    ``Box(-1, 1, (n,), float32)``: joint-rate commands normalised by each joint's rate limit. They
    are held for one control period and followed through an acceleration-limited rate servo.
    Values outside [-1, 1] are clipped; NaN or infinite values raise ``SpaceIdInputError`` (a ``ValueError``).

    ## Observation Space
    ``Box(low, high, (2n + 7,), float32)``, all *measured* (noisy) values; bounds: joint limits
    +-0.5 rad, +-2x the rate limits, +-pi rad/s, +-1:

    | index            | observation                                   | unit  |
    |------------------|-----------------------------------------------|-------|
    | 0 .. n-1         | joint angles q                                | rad   |
    | n .. 2n-1        | joint rates dq                                | rad/s |
    | 2n .. 2n+2       | base angular rate, base body frame (gyro)     | rad/s |
    | 2n+3 .. 2n+6     | base attitude quaternion w, x, y, z (base to inertial) | - |

    The attitude is what the sensors' attitude source gives (``SensorModel.attitude_source``:
    star tracker, exact, on-board filter), and zeros when they measure none (``"none"``). The true
    parameters are never in the observation.

    ## Rewards
    ``r = information gain - joint-limit penalty - attitude penalty`` where

    * information gain = ``0.5 (log det F_t - log det F_{t-1})`` (nats), ``F`` the accumulated
      Fisher information of the gyro measurements about the fuel parameters, in units scaled by
      the prior ranges (usable fuel mass, tank box half-width), starting from the prior ``F_0 = I``.
      Summed over an episode it is the total information gained, ``0.5 log det F_T``. With
      ``sensors="noise_free"`` the information is computed for the default gyro noise. Joint-rate
      noise, which also enters the prediction, is neglected (about 6 % of the variance for paper6).
    * joint-limit penalty = ``joint_limit * sum_j max(0, (|q_j - mid_j| / half_j - 0.9) / 0.1)^2``.
    * attitude penalty = ``attitude_per_s * dt * (|omega_base| / attitude_rate_ref_rad_s)^2``.

    ## Starting State
    Joint rates zero, joint angles uniformly within +-0.3 rad of the home configuration (clipped
    to the limits), base attitude identity, system momentum zero (unless the ``initial_momentum``
    hidden effect is set). Fuel state: see *Episode End*.

    ## Hidden effects
    ``hidden_effects`` adds physics the nominal model leaves out (:mod:`spaceid_gym.effects`):
    ``initial_momentum``, ``gyro_bias``, ``gyro_scale``, ``payload``, ``slosh``, ``delay``,
    ``external_torque``. Pass a :class:`~spaceid_gym.effects.HiddenEffects` (the same every
    episode) or a spec string such as ``"slosh,delay[delay_s=0.03],gyro_bias[magnitude=1e-4]"``,
    drawn anew at every reset (realistic default sizes, random directions) from a generator spawned
    from the env's ``np_random``, so the measurement noise of a seed is the same with and without
    effects. The gyro of a ``delay`` measures the true rate at ``t - delay_s`` (the star tracker and
    encoders are not delayed); bias and scale/misalignment apply to the gyro; the payload is held by
    the last link (``robot`` stays the description without it). ``info["truth"]["hidden_effects"]``
    holds the episode's settings (:meth:`HiddenEffects.to_dict`); the slosh displacement is in
    ``env.simulator.state.slosh_m`` (truth, never observed). Slosh makes steps several times slower.

    ## Episode End
    The episode is truncated by the ``TimeLimit`` wrapper (registered default 3000 steps, 60 s at
    the default 50 Hz); pass ``max_episode_steps`` to ``gym.make`` for another window length.
    ``reset(seed=...)`` starts a new satellite (new tank position, first fuel state); ``reset()``
    without a seed moves to the next identification window of the same satellite (more fuel
    consumed). ``reset(options={"fuel_consumed_kg": ..., "tank_position_m": ...})`` sets either;
    ``options={"noise_seed": n}`` draws the episode's measurement noise from a generator of its own seeded
    with ``n`` (the starting state, tank and hidden effects still from ``seed``): the same motion measured with
    new noise, for Monte Carlo over the noise alone (the env's own generator is then not advanced by the noise, so
    a later ``reset()`` without a seed draws differently than after the same episode without ``noise_seed``).

    ## Info
    ``truth``: ``fuel_consumed_kg``, ``tank_position_m``, ``base_mass_kg``, ``base_com_m``,
    ``base_inertia_kgm2``, ``episode`` (and ``hidden_effects`` when any is set); step infos add ``information_gain``, ``penalty_joint_limit``,
    ``penalty_attitude``, ``log_det_fisher``.

    ## Arguments
    ``robot`` (name or URDF path, default ``"paper6"``), ``control_period_s`` (0.02),
    ``sensors`` (:class:`~spaceid_gym.sim.sensors.SensorModel`, ``None`` for defaults, or
    ``"noise_free"``), ``fuel_schedule`` (:class:`~spaceid_gym.mission.FuelSchedule`),
    ``tank_position_m`` (fixed tank, default drawn per satellite), ``reward_weights``
    (:class:`RewardWeights`), ``render_mode`` (``"rgb_array"`` or ``None``), ``hidden_effects`` (see
    *Hidden effects*; default none), ``integration_substeps`` (RKMK4 steps of the base's attitude, and of a
    slosh, per smooth piece of a control period, the pieces between the servo's switch times; the joints' motion is
    exact. Default ``None``: no step longer than
    :data:`~spaceid_gym.sim.simulator.MAX_INTEGRATION_STEP_S`, so one at 50 and 100 Hz and three at 20 Hz. With one
    step at 20 Hz the noise-free attitude of clean matrix log 10713's motion (``quick3``) leaves the attitude channel's
    residual at the truth at 1.9e-9 rad a step, with eight at 8.1e-11: ``benchmarks/attitude_drift.py --substeps``). The measurement log of the current episode: :meth:`measurement_log`.

    ## Identification
    The env is the physics and the sensors only: it imports no estimator. ``gym.make("FreeFloatingID-v0",
    estimator=...)`` wraps it in :class:`~spaceid_gym.envs.estimation.EstimatorWrapper`, which fits the
    estimator on each window's log (and, for a streaming estimator such as ``ukf``, puts its running estimate
    in every step's ``info``); see that class for ``estimator``, ``identify_after_steps`` and
    ``estimator_effects``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(
        self,
        robot: str | Robot = "paper6",
        control_period_s: float = 0.02,
        sensors: SensorModel | str | None = None,
        fuel_schedule: FuelSchedule | None = None,
        tank_position_m: FloatArray | None = None,
        reward_weights: RewardWeights | None = None,
        render_mode: str | None = None,
        hidden_effects: HiddenEffects | str | None = None,
        integration_substeps: int | None = None,
    ) -> None:
        self.robot = robot if isinstance(robot, Robot) else load_robot(robot)
        if integration_substeps is None:
            integration_substeps = integration_substeps_for(control_period_s)  # validates the period
        whole = isinstance(integration_substeps, int | np.integer) and not isinstance(integration_substeps, bool)
        if not whole or integration_substeps < 1:
            raise SpaceIdInputError(f"integration_substeps: expected an integer >= 1 or None, got {integration_substeps!r}")
        self.integration_substeps = int(integration_substeps)
        if not (np.isfinite(control_period_s) and control_period_s > 0.0):
            raise SpaceIdInputError(f"control_period_s: expected a positive number of seconds, got {control_period_s!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise SpaceIdInputError(f"render_mode: expected one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.control_period_s = float(control_period_s)
        self.sensors = _sensor_model(sensors)
        self.fuel_schedule = fuel_schedule if fuel_schedule is not None else FuelSchedule()
        base_full = self.robot.base_full
        self._fixed_tank = None if tank_position_m is None else np.asarray(tank_position_m, dtype=float)
        if self._fixed_tank is not None:
            check_fuel(base_full, 0.0, self._fixed_tank)
        self.reward_weights = reward_weights if reward_weights is not None else RewardWeights()
        self.render_mode = render_mode
        n = self.robot.n_joints
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        rate = self.robot.rate_limit_rad_s
        high = np.concatenate((self.robot.q_upper_rad + 0.5, 2.0 * rate, [np.pi] * 3, [1.0] * 4))
        low = np.concatenate((self.robot.q_lower_rad - 0.5, -2.0 * rate, [-np.pi] * 3, [-1.0] * 4))
        self.observation_space = spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        # prior ranges: they scale the fuel parameters so that the Fisher information is unit-free
        self._param_scale = np.array(
            [self.fuel_schedule.usable_fraction * base_full.mass_kg] + [self.fuel_schedule.tank_half_width_m(base_full)] * 3
        )
        mid = 0.5 * (self.robot.q_lower_rad + self.robot.q_upper_rad)
        half = 0.5 * (self.robot.q_upper_rad - self.robot.q_lower_rad)
        self._joint_mid, self._inv_tenth_half = mid, 10.0 / half  # excess = (|q - mid| / half - 0.9) / 0.1
        #: the per-sample gyro noise std (rad/s) the information reward (and a streaming estimator) assumes: the
        #: sensor model's, or the default sensors' when it is noise-free
        self.gyro_std_rad_s = (
            self.sensors.gyro_std_rad_s(self.control_period_s)
            if self.sensors.gyro_arw_rad_sqrt_s > 0.0
            else SensorModel().gyro_std_rad_s(self.control_period_s)
        )
        self._gyro_inverse_variance = 1.0 / self.gyro_std_rad_s**2
        self._tank: FloatArray | None = None
        self._fuel_consumed_kg = 0.0
        self._episode = -1
        self._renderer: RobotRenderer | None = None
        if isinstance(hidden_effects, str):
            parse_effect_spec(hidden_effects)  # syntax errors now, not at the first reset
        elif hidden_effects is not None and not isinstance(hidden_effects, HiddenEffects):
            raise SpaceIdInputError(
                f"hidden_effects: expected a HiddenEffects, a spec string or None, got {type(hidden_effects).__name__}"
            )
        self.hidden_effects = hidden_effects
        self._effects = HiddenEffects()

    # ------------------------------------------------------------------ gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        base_full = self.robot.base_full
        new_satellite = seed is not None or self._tank is None
        if new_satellite:
            tank = (
                self._fixed_tank.copy()
                if self._fixed_tank is not None
                else self.fuel_schedule.draw_tank_position(base_full, self.np_random)
            )
            fuel, episode = self.fuel_schedule.first(base_full), 0
        else:
            assert self._tank is not None
            tank = self._tank
            fuel, episode = self.fuel_schedule.next(self._fuel_consumed_kg, base_full, self.np_random), self._episode + 1
        if "tank_position_m" in options:
            tank = np.asarray(options.pop("tank_position_m"), dtype=float)
        if "fuel_consumed_kg" in options:
            fuel = float(options.pop("fuel_consumed_kg"))
        noise_rng = self.np_random
        if "noise_seed" in options:
            noise_seed = options.pop("noise_seed")
            if isinstance(noise_seed, bool) or not isinstance(noise_seed, (int, np.integer)) or noise_seed < 0:
                raise SpaceIdInputError(f"reset option 'noise_seed': expected an integer >= 0, got {noise_seed!r}")
            noise_rng = np.random.default_rng(int(noise_seed))
        if options:
            raise SpaceIdInputError(
                f"reset options: unknown keys {sorted(options)}; expected fuel_consumed_kg, tank_position_m, noise_seed"
            )
        base = base_after_fuel(base_full, fuel, tank)  # validates before any state changes
        effects = self._draw_effects(fuel)
        simulator = FreeFloatingSimulator(
            self.robot,
            base,
            substeps=self.integration_substeps,
            effects=effects,
            tank_point_m=np.asarray(base_full.com_m) + tank,
        )
        self._tank, self._fuel_consumed_kg, self._episode = tank, fuel, episode
        self._effects, self.simulator = effects, simulator
        theta = np.concatenate(([self._fuel_consumed_kg], self._tank))
        self._directions = base_parameter_directions(base_params10_fuel_jacobian(base_full.com_m, theta) * self._param_scale)
        q0 = self.robot.home_configuration() + self.np_random.uniform(-0.3, 0.3, size=self.robot.n_joints)
        state = self.simulator.reset(q0_rad=np.clip(q0, self.robot.q_lower_rad, self.robot.q_upper_rad))
        self._recorder = LogRecorder(_sensors_with_effects(self.sensors, effects), self.control_period_s, noise_rng)
        self._gyro_delay_s = effects.delay_s or 0.0
        self._fisher, self._log_det_fisher = np.eye(4), 0.0  # prior information: one prior range per parameter
        self._fisher_update(state.composite_inertia, state.v_base_body)
        self._truth = _truth_info(self._fuel_consumed_kg, self._tank, base, self._episode)
        if effects:
            self._truth["hidden_effects"] = effects.to_dict()
        return self._observation(self._record(state)), {"truth": self.truth()}

    def step(self, action: NDArray[np.float32]) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        a = checked_action(action, self.action_space)
        # actions beyond [-1, 1] are clipped by the servo's rate limit
        state = self.simulator.step(a * self.robot.rate_limit_rad_s, self.control_period_s)
        sample = self._record(state)
        gain = self._fisher_update(state.composite_inertia, state.v_base_body)
        weights = self.reward_weights
        excess = np.maximum(np.abs(state.q_rad - self._joint_mid) * self._inv_tenth_half - 9.0, 0.0)
        penalty_limit = weights.joint_limit * float(excess @ excess)
        omega = state.v_base_body[3:]
        penalty_attitude = (
            weights.attitude_per_s * self.control_period_s * float(omega @ omega) / weights.attitude_rate_ref_rad_s**2
        )
        info = {
            "truth": self.truth(),
            "information_gain": gain,
            "penalty_joint_limit": penalty_limit,
            "penalty_attitude": penalty_attitude,
            "log_det_fisher": self._log_det_fisher,
        }
        return self._observation(sample), gain - penalty_limit - penalty_attitude, False, False, info

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            base = self.robot.base_full
            extents = base_half_extents_from_inertia(base.mass_kg, base.inertia_com_kgm2)
            self._renderer = RobotRenderer(self.simulator.arm_model, extents, 480, 480)
        state = self.simulator.state
        text = f"t = {state.t_s:6.2f} s   fuel consumed {self._fuel_consumed_kg:5.1f} kg   episode {self._episode}"
        return self._renderer.render(state.pinocchio_configuration()[: self.simulator.arm_model.nq], info_text=text)

    # ------------------------------------------------------------------ extras
    def measurement_log(self, last: int | None = None) -> MeasurementLog:
        """The measurements of the current episode so far (one sample per control period), hidden effects included.

        ``last``: only the last ``last`` samples (a streaming estimator's newest sample without copying the window).
        """
        return self._recorder.log(last)

    @property
    def effects(self) -> HiddenEffects:
        """The current episode's hidden effects (empty without any)."""
        return self._effects

    def truth(self) -> dict[str, Any]:
        """The current episode's true parameters (the same as ``info["truth"]``)."""
        truth = dict(self._truth)
        if "hidden_effects" in truth:  # the only nested mutable value: each caller gets its own
            truth["hidden_effects"] = self._effects.to_dict()
        return truth

    @property
    def fisher_information(self) -> FloatArray:
        """Accumulated Fisher information about ``theta`` scaled by the prior ranges, prior included, (4, 4)."""
        return self._fisher.copy()

    def cramer_rao_std(self) -> FloatArray:
        """Cramér-Rao bound of the episode's gyro data on ``(mdf [kg], bf [m] x3)``, shape (4,).

        From the data alone (the prior taken out); ``inf`` for a parameter in a direction the data
        do not inform (information below 1e-9 of the largest).
        """
        # rank decisions in the prior-scaled units (kg and m are not comparable), then back to SI
        return cramer_rao_std(self._fisher - np.eye(4)) * self._param_scale

    def excitation_measures(self) -> ExcitationMeasures:
        """The episode's excitation measures so far (:func:`spaceid_gym.information.excitation_measures`): the gyro
        data's information about the fuel parameters in units of their prior ranges (the prior taken out); the
        Cramér-Rao stds in kg and m."""
        return excitation_measures(self._fisher - np.eye(4), self._param_scale)

    # ------------------------------------------------------------------ internals
    def _draw_effects(self, fuel_consumed_kg: float) -> HiddenEffects:
        """This episode's hidden effects: the fixed ones, or a fresh draw of the spec string.

        The draw uses a generator spawned from ``np_random`` (spawning does not advance it), so the
        noise and initial pose of a seed do not depend on the effects.
        """
        if self.hidden_effects is None:
            return HiddenEffects()
        if isinstance(self.hidden_effects, HiddenEffects):
            return self.hidden_effects
        return parse_hidden_effects(self.hidden_effects, self.np_random.spawn(1)[0], self.robot, fuel_consumed_kg)

    def _record(self, state: FreeFloatingState) -> Measurement:
        """Measure ``state``; a delayed gyro measures the state ``delay_s`` earlier."""
        if self._gyro_delay_s > 0.0:
            return self._recorder.record(state, self.simulator.state_at(state.t_s - self._gyro_delay_s))
        return self._recorder.record(state)

    def _fisher_update(self, composite: Any, twist: FloatArray) -> float:
        """Add one gyro sample's information; return the gain ``0.5 (log det F_t - log det F_{t-1})``."""
        jac = twist_parameter_jacobian(composite.inverse(), twist, self._directions)[3:]  # d omega / d theta_scaled
        before = self._log_det_fisher
        self._fisher, self._log_det_fisher = add_information(self._fisher, jac, self._gyro_inverse_variance)
        return 0.5 * (self._log_det_fisher - before)

    def _observation(self, sample: Measurement) -> NDArray[np.float32]:
        quat = np.zeros(4) if sample.quat_base_to_inertial_wxyz is None else sample.quat_base_to_inertial_wxyz
        return np.concatenate((sample.q_rad, sample.dq_rad_s, sample.omega_base_body_rad_s, quat)).astype(np.float32)


def _sensor_model(sensors: SensorModel | str | None) -> SensorModel:
    if sensors is None:
        return SensorModel()
    if isinstance(sensors, SensorModel):
        return sensors
    if sensors == "noise_free":
        return SensorModel.noise_free()
    raise SpaceIdInputError(f"sensors: expected a SensorModel, None or 'noise_free', got {sensors!r}")


def _sensors_with_effects(sensors: SensorModel, effects: HiddenEffects) -> SensorModel:
    """``sensors`` with the gyro bias of ``effects`` added and its scale/misalignment set (replacing the sensors' own)."""
    bias, scale = effects.array("gyro_bias_rad_s"), effects.gyro_scale_misalignment
    if bias is None and scale is None:
        return sensors
    changes: dict[str, Any] = {}
    if bias is not None:
        changes["gyro_bias_rad_s"] = tuple((np.asarray(sensors.gyro_bias_rad_s, dtype=float) + bias).tolist())
    if scale is not None:
        changes["gyro_scale_misalignment"] = scale
    return dataclasses.replace(sensors, **changes)


def _truth_info(fuel_consumed_kg: float, tank_m: FloatArray, base: RigidBodyInertia, episode: int) -> dict[str, Any]:
    """The true parameters as immutable values (tuples), so infos can share them safely."""
    return {
        "fuel_consumed_kg": float(fuel_consumed_kg),
        "tank_position_m": tuple(tank_m.tolist()),
        "base_mass_kg": float(base.mass_kg),
        "base_com_m": tuple(np.asarray(base.com_m).tolist()),
        "base_inertia_kgm2": tuple(tuple(row) for row in np.asarray(base.inertia_com_kgm2).tolist()),
        "episode": episode,
    }
