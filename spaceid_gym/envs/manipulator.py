"""``ManipulatorID-v0``: excite a fixed-base arm with friction so that its base parameters can be identified."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numba import njit
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from spaceid_gym.arm.arm_robot import ArmRobot, load_arm
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.arm.parameter_prior import ParameterPrior, nominal_parameters
from spaceid_gym.arm.regressor import ArmRegressor, BaseParameterSet
from spaceid_gym.arm.torque_simulator import ArmSimulator, TrackingController
from spaceid_gym.arrays import FloatArray
from spaceid_gym.envs.actions import checked_action
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.information import ExcitationMeasures, add_information, cramer_rao_std, excitation_measures

#: the default identification window: 3750 steps, 30 s at 125 Hz (the registered ``max_episode_steps``)
WINDOW_STEPS = 3750
#: default control period, s (125 Hz, the UR5 CB-series controller)
CONTROL_PERIOD_S = 0.008
#: default RK4 rate of the env's simulator, Hz (4 steps per control period; see the class docstring)
ENV_INTERNAL_RATE_HZ = 500.0
#: what an action means (see the class docstring)
ACTION_MODES = ("rate", "acceleration")
#: the reference keeps this fraction of each joint's range free at either end (braking envelope target)
_LIMIT_MARGIN_FRACTION = 0.02


@dataclass(frozen=True)
class ManipulatorRewardWeights:
    """Weights of the reward's penalty terms (see :class:`ManipulatorIDEnv`, *Rewards*).

    Attributes:
        joint_limit: per step, per joint, for a joint at its limit (quadratic over the last 10 % of the half-range).
        torque_limit: per step, per joint, for a motor torque at its limit (quadratic above 90 % of the limit).
    """

    joint_limit: float = 1.0
    torque_limit: float = 1.0


class ManipulatorIDEnv(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """A fixed-base arm (default the UR5) with joint friction whose dynamic parameters are unknown.

    ## Description
    The arm stands on a fixed base under gravity. The agent commands joint rates (or
    accelerations); a computed-torque controller makes the arm follow them (:mod:`spaceid_gym.arm.torque_simulator`), and
    the joint sensors measure angles, rates and the motor torque (or current). The torque is
    linear in the unknown parameters, ``tau = Y(q, dq, ddq) p`` (10 inertial parameters per link
    and Coulomb/viscous friction per joint); only the r base combinations ``beta = K p`` can be
    identified (:class:`~spaceid_gym.arm.regressor.BaseParameterSet`; 48 for the UR5 with
    Coulomb + viscous friction). Each episode is one identification window: the agent should move
    the arm so that the torque data carry as much information as possible about ``beta``.

    ## Action Space
    ``Box(-1, 1, (n,), float32)``, held for one control period, with ``action_mode``:

    * ``"rate"`` (default, the convention of ``FreeFloatingID-v0``, so
      :class:`spaceid_gym.excitation.FourierExcitation` drives both envs): joint-rate commands
      normalised by each joint's rate limit, followed by an acceleration-limited rate servo: the
      reference accelerates towards the commanded rate at most at the acceleration limit;
    * ``"acceleration"``: joint-acceleration commands normalised by each joint's acceleration limit.

    Either way the reference acceleration is then limited so that the reference rate stays within
    the rate limits and a braking envelope that stops each joint before its position limit (minus
    2 % of its range). Values outside [-1, 1] are clipped; NaN or infinite values raise
    ``SpaceIdInputError`` (a ``ValueError``).

    ## Observation Space
    ``Box(low, high, (3n,), float32)``, all *measured* (noisy) values, clipped to the bounds:

    | index      | observation                                        | unit      | bound             |
    |------------|----------------------------------------------------|-----------|-------------------|
    | 0 .. n-1   | joint angles q                                     | rad       | limits +- 0.5     |
    | n .. 2n-1  | joint rates dq                                     | rad/s     | +- 2 x rate limit |
    | 2n .. 3n-1 | motor torque (N m) or current (A), see ``sensors`` | N m or A  | +- 2 x torque limit (/ k_t) |

    The true parameters are never in the observation.

    ## Rewards
    ``r = information gain - joint-limit penalty - torque-limit penalty`` where

    * information gain = ``0.5 (log det F_t - log det F_{t-1})`` (nats), ``F`` the accumulated
      Fisher information of the torque measurements about the base parameters in units of their
      prior std (:class:`~spaceid_gym.arm.parameter_prior.ParameterPrior`), starting from the prior
      ``F_0 = I``: each step adds ``J^T J`` with ``J = Y_b(q, dq, ddq) S / sigma`` (rows divided by
      each joint's torque noise std, ``S = diag(prior std)``), at the true state of the sample.
      Summed over an episode it is ``0.5 log det F_T``. With ``sensors="noise_free"`` the default
      noise is used for the information. Noise on q and dq (which enters ``Y``) is neglected.
    * joint-limit penalty = ``joint_limit * sum_j max(0, (|q_j - mid_j| / half_j - 0.9) / 0.1)^2``.
    * torque-limit penalty = ``torque_limit * sum_j max(0, (|u_j| / limit_j - 0.9) / 0.1)^2``.

    ## Starting State
    Joint rates zero, joint angles uniformly within +-0.3 rad of the middle of each joint's range
    (the UR5's zero pose: arm stretched horizontally), clipped to the limits.

    ## Episode End
    Truncation by the ``TimeLimit`` wrapper: registered default 3750 steps (30 s at the default
    125 Hz); pass ``max_episode_steps`` to ``gym.make`` for another window. ``reset(seed=...)``
    draws a new robot (true parameters from the prior, with ``np_random``); ``reset()`` without a
    seed starts a new window of the same robot; ``reset(options={"parameters": p})`` sets them.

    ## Info
    ``truth``: ``parameters`` (p, :attr:`parameter_names` order), ``base_parameters`` (beta,
    :attr:`base_parameter_names` order), ``episode``; step infos add ``information_gain``,
    ``penalty_joint_limit``, ``penalty_torque_limit``, ``log_det_fisher``.

    ## Arguments
    ``robot`` (``"ur5"``, a URDF path or an :class:`~spaceid_gym.arm.arm_robot.ArmRobot`), ``action_mode``
    (``"rate"`` or ``"acceleration"``, see *Action Space*), ``friction``
    (terms, default Coulomb + viscous), ``control_period_s`` (0.008), ``internal_rate_hz`` (RK4
    rate, default 500 Hz, 14700 env steps/s of CPU time against 10900 at 1 kHz on the 2-core test machine; over
    12 s of random commands the joint angles differ from a 4 kHz run by 1.1e-6 rad, a tenth of the
    encoder noise (1 kHz: 5e-8 rad); at any rate every sample satisfies ``u = Y(q, dq, ddq) p``
    exactly; :mod:`spaceid_gym.arm.torque_simulator` uses 1 kHz for datasets),
    ``sensors`` (:class:`~spaceid_gym.arm.joint_sensors.ArmSensorModel`, ``None`` for defaults, or
    ``"noise_free"``), ``prior`` (:class:`~spaceid_gym.arm.parameter_prior.ParameterPrior`),
    ``controller`` (:class:`~spaceid_gym.arm.torque_simulator.TrackingController`), ``reward_weights``
    (:class:`ManipulatorRewardWeights`), ``base_parameters`` (a
    :class:`~spaceid_gym.arm.regressor.BaseParameterSet`; default computed from 300 random states
    of a generator seeded with 0: structure, not an episode draw). No rendering.
    The measurement log of the current episode: :meth:`measurement_log`.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [], "render_fps": 125}

    def __init__(
        self,
        robot: str | ArmRobot = "ur5",
        action_mode: str = "rate",
        friction: FrictionModel | tuple[str, ...] | None = ("coulomb", "viscous"),
        control_period_s: float = CONTROL_PERIOD_S,
        internal_rate_hz: float = ENV_INTERNAL_RATE_HZ,
        sensors: ArmSensorModel | str | None = None,
        prior: ParameterPrior | None = None,
        controller: TrackingController | None = None,
        reward_weights: ManipulatorRewardWeights | None = None,
        base_parameters: BaseParameterSet | None = None,
        render_mode: str | None = None,
    ) -> None:
        self.robot = robot if isinstance(robot, ArmRobot) else load_arm(robot)
        if not (np.isfinite(control_period_s) and control_period_s > 0.0):
            raise SpaceIdInputError(f"control_period_s: expected a positive number of seconds, got {control_period_s!r}")
        if render_mode is not None:
            raise SpaceIdInputError(f"render_mode: ManipulatorID-v0 does not render; expected None, got {render_mode!r}")
        if action_mode not in ACTION_MODES:
            raise SpaceIdInputError(f"action_mode: expected one of {list(ACTION_MODES)}, got {action_mode!r}")
        self.render_mode = render_mode
        self.action_mode = action_mode
        self.control_period_s = float(control_period_s)
        self.internal_rate_hz = float(internal_rate_hz)
        self.prior = prior if prior is not None else ParameterPrior()
        self.controller = controller if controller is not None else TrackingController()
        self.reward_weights = reward_weights if reward_weights is not None else ManipulatorRewardWeights()
        # a simulator of the nominal robot validates sensors, rates and friction before anything else
        probe = ArmSimulator(
            self.robot,
            nominal_parameters(ArmRegressor(self.robot, friction)),
            friction,
            sensors,
            self.controller,
            internal_rate_hz,
            1.0 / self.control_period_s,
        )
        self.regressor, self.sensors = probe.regressor, probe.sensors
        if base_parameters is None:
            with threadpool_limits(limits=1):  # small QR: BLAS threads only slow it down
                base_parameters = BaseParameterSet.from_regressor(self.regressor, np.random.default_rng(0))
        self.base = base_parameters
        if self.base.parameter_names != self.regressor.parameter_names:
            raise SpaceIdInputError("base_parameters: built for other parameters than this robot and friction model")
        n = self.robot.n_joints
        self.parameter_names: tuple[str, ...] = self.regressor.parameter_names
        self.base_parameter_names: tuple[str, ...] = self.base.names

        self.action_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        effort_high = 2.0 * self.robot.torque_limit_Nm
        if self.sensors.effort_kind == "current_A":
            effort_high = effort_high / self.sensors.k_t
        high = np.concatenate((self.robot.q_upper_rad + 0.5, 2.0 * self.robot.dq_limit_rad_s, effort_high))
        low = np.concatenate((self.robot.q_lower_rad - 0.5, -2.0 * self.robot.dq_limit_rad_s, -effort_high))
        self.observation_space = spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        self._obs_low, self._obs_high = low, high

        self._scale = self.prior.base_parameter_std(self.regressor, self.base)  # prior std of beta: F in these units
        information_sensors = self.sensors
        if not np.all(np.asarray(self.sensors.current_std_A) > 0):  # noise-free: the information of the default noise
            information_sensors = dataclasses.replace(self.sensors, current_std_A=ArmSensorModel.current_std_A)
        row_weight = 1.0 / np.broadcast_to(information_sensors.torque_std_Nm(), (n,))[:, None]  # 1 / sigma_j per row
        self._row_scale = self._scale * row_weight  # (n, r): J = Y_b S / sigma
        mid = 0.5 * (self.robot.q_lower_rad + self.robot.q_upper_rad)
        half = 0.5 * (self.robot.q_upper_rad - self.robot.q_lower_rad)
        self._joint_mid, self._inv_tenth_half = mid, 10.0 / half  # excess = (|q - mid| / half - 0.9) / 0.1
        margin = _LIMIT_MARGIN_FRACTION * 2.0 * half
        self._q_low, self._q_high = self.robot.q_lower_rad + margin, self.robot.q_upper_rad - margin
        self._friction = friction
        self._parameters: FloatArray | None = None
        self._episode = -1

    # ------------------------------------------------------------------ gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        if seed is not None or self._parameters is None:
            parameters, episode = self.prior.draw(self.regressor, self.np_random), 0
        else:
            parameters, episode = self._parameters, self._episode + 1
        if "parameters" in options:
            parameters = np.asarray(options.pop("parameters"), dtype=float)
        if options:
            raise SpaceIdInputError(f"reset options: unknown keys {sorted(options)}; expected parameters")
        simulator = ArmSimulator(
            self.robot,
            parameters,
            self._friction,
            self.sensors,
            self.controller,
            self.internal_rate_hz,
            1.0 / self.control_period_s,
        )  # validates the parameters before any state changes
        self.simulator, self._parameters, self._episode = simulator, simulator.parameters, episode
        n = self.robot.n_joints
        q0 = np.clip(self._joint_mid + self.np_random.uniform(-0.3, 0.3, size=n), self.robot.q_lower_rad, self.robot.q_upper_rad)
        simulator.reset(q0)
        self._q_ref, self._dq_ref, self._ddq_ref = q0.copy(), np.zeros(n), np.zeros(n)
        self._stage_tau = simulator.stage_times() - simulator.state.t_s  # (2m + 1,) offsets within a control period
        self._records: list[tuple[float, FloatArray, FloatArray, FloatArray, FloatArray]] = []
        self._fisher, self._log_det_fisher = np.eye(self.base.rank), 0.0
        self._truth = {
            "parameters": tuple(self._parameters.tolist()),
            "base_parameters": tuple(self.base.to_base(self._parameters).tolist()),
            "episode": episode,
        }
        torque, ddq = simulator.sample(q0, np.zeros(n), np.zeros(n))
        obs, *_ = self._measure_and_learn(torque, ddq)
        return obs, {"truth": self.truth()}

    def step(self, action: NDArray[np.float32]) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        a = checked_action(action, self.action_space)
        robot = self.robot
        ddq = _reference_acceleration(
            a,
            self.action_mode == "rate",
            self._q_ref,
            self._dq_ref,
            self.control_period_s,
            robot.dq_limit_rad_s,
            robot.ddq_limit_rad_s2,
            self._q_low,
            self._q_high,
        )
        torque, ddq_true, self._q_ref, self._dq_ref = self.simulator.track_constant_acceleration(
            self._q_ref, self._dq_ref, ddq, self._stage_tau
        )
        self._ddq_ref = ddq
        obs, gain, q = self._measure_and_learn(torque, ddq_true)
        weights = self.reward_weights
        excess_q, excess_u = _limit_excesses(q, self._joint_mid, self._inv_tenth_half, torque, self.robot.torque_limit_Nm)
        penalty_q, penalty_u = weights.joint_limit * excess_q, weights.torque_limit * excess_u
        info = {
            "truth": self.truth(),
            "information_gain": gain,
            "penalty_joint_limit": penalty_q,
            "penalty_torque_limit": penalty_u,
            "log_det_fisher": self._log_det_fisher,
        }
        return obs, gain - penalty_q - penalty_u, False, False, info

    # ------------------------------------------------------------------ extras
    def truth(self) -> dict[str, Any]:
        """The current episode's true parameters (the same as ``info["truth"]``)."""
        return dict(self._truth)

    def measurement_log(self) -> ArmLog:
        """The measurements of the current episode so far, one sample per control period.

        ``ddq_rad_s2`` is the simulator's true acceleration (not a measurement).
        """
        t, q, dq, ddq, effort = (np.array(column) for column in zip(*self._records, strict=True))
        return ArmLog(t, q, dq, ddq, effort, self.sensors.effort_kind, f"{self.robot.name}-episode{self._episode}")

    @property
    def fisher_information(self) -> FloatArray:
        """Accumulated Fisher information about the base parameters in prior-std units, prior included, (r, r)."""
        return self._fisher.copy()

    def cramer_rao_std(self) -> FloatArray:
        """Cramér-Rao bound of the episode's torque data on the base parameters (SI units of each), shape (r,).

        From the data alone (the prior taken out); ``inf`` where the data do not inform.
        """
        return cramer_rao_std(self._fisher - np.eye(self.base.rank)) * self._scale

    def excitation_measures(self) -> ExcitationMeasures:
        """The episode's excitation measures so far (:func:`spaceid_gym.information.excitation_measures`): the torque
        data's information about the base parameters in units of their prior std (the prior taken out)."""
        return excitation_measures(self._fisher - np.eye(self.base.rank), self._scale)

    # ------------------------------------------------------------------ internals
    def _measure_and_learn(self, torque: FloatArray, ddq: FloatArray) -> tuple[NDArray[np.float32], float, FloatArray]:
        """Measure, record and add the information of the simulator's sample (true motor torque and acceleration at the
        current state): ``(obs, gain, true q)``."""
        state = self.simulator.state
        q_m, dq_m, effort = self.sensors.measure(state.q_rad, state.dq_rad_s, torque, self.np_random)
        self._records.append((state.t_s, q_m, dq_m, ddq, effort))
        rows = self.regressor.state_regressor(state.q_rad, state.dq_rad_s, ddq)[:, self.base.independent]  # (n, r)
        before = self._log_det_fisher
        self._fisher, self._log_det_fisher = add_information(self._fisher, rows * self._row_scale, 1.0)
        obs = np.clip(np.concatenate((q_m, dq_m, effort)), self._obs_low, self._obs_high).astype(np.float32)
        return obs, 0.5 * (self._log_det_fisher - before), state.q_rad


@njit(cache=True)
def _reference_acceleration(
    action: FloatArray,
    rate_mode: bool,
    q_ref: FloatArray,
    dq_ref: FloatArray,
    period_s: float,
    dq_limit: FloatArray,
    ddq_limit: FloatArray,
    q_low: FloatArray,
    q_high: FloatArray,
) -> FloatArray:
    """The reference's constant acceleration over the next control period, (n,) rad/s^2.

    The action (clipped to [-1, 1]) commands a rate (towards it at most at the acceleration limit) or an
    acceleration; the acceleration is then limited so that the reference's next rate stays within the rate limits
    and the braking envelope ``sqrt(2 ddq_limit (q_high - q - dq T))`` (and its mirror at ``q_low``).
    """
    n = action.shape[0]
    ddq = np.empty(n)
    for j in range(n):
        a = min(max(action[j], -1.0), 1.0)
        q, dq, limit = q_ref[j], dq_ref[j], ddq_limit[j]
        command = (a * dq_limit[j] - dq) / period_s if rate_mode else a * limit
        v_high = min(dq_limit[j], np.sqrt(2.0 * limit * max(q_high[j] - q - dq * period_s, 0.0)))
        v_low = max(-dq_limit[j], -np.sqrt(2.0 * limit * max(q + dq * period_s - q_low[j], 0.0)))
        command = min(max(command, (v_low - dq) / period_s), (v_high - dq) / period_s)
        ddq[j] = min(max(command, -limit), limit)
    return ddq


@njit(cache=True)
def _limit_excesses(
    q: FloatArray, joint_mid: FloatArray, inv_tenth_half: FloatArray, torque: FloatArray, torque_limit: FloatArray
) -> tuple[float, float]:
    """The penalties' sums of squares: ``sum_j max(0, (|q_j - mid_j| / half_j - 0.9) / 0.1)^2`` and the same of
    ``|u_j| / limit_j`` (see the class docstring, *Rewards*)."""
    joints, torques = 0.0, 0.0
    for j in range(q.shape[0]):
        excess = max(abs(q[j] - joint_mid[j]) * inv_tenth_half[j] - 9.0, 0.0)
        joints += excess * excess
        excess = max(abs(torque[j]) / torque_limit[j] * 10.0 - 9.0, 0.0)
        torques += excess * excess
    return joints, torques
