"""A learnt excitation for the fixed-base arm (``ManipulatorID-v0``, the UR5 with Coulomb + viscous friction): the
env as the agent sees it (:class:`ArmExcitationEnv`) and the policy's observation (:func:`arm_policy_features`).

The design is the satellite's (:mod:`agents.policy`, :mod:`agents.excitation_task`): every 0.5 s a **target angle**
per joint, followed at up to the rate limit; PPO + ``VecNormalize`` trained by :func:`agents.policy.train_excitation`
(``robot="ur5"``); the policy folder says ``"env": "ManipulatorID-v0"``.

**Observation** (:func:`arm_policy_features`, 71 values for 6 joints): the measured joint angles (``(q - mid) / half
range``), rates (per rate limit) and motor torques (per torque limit), the elapsed fraction of the 30 s window, and
the **uncertainty so far** from the env's accumulated Fisher information ``F`` about the 48 base parameters in
prior-std units (prior included, so ``F >= I``): ``log10`` of each base parameter's Cramér-Rao std
(``sqrt(diag F^-1)``, 48 values, 0 = nothing learnt yet) and ``-0.5 log10`` of the :data:`WORST_DIRECTIONS` smallest
eigenvalues of ``F`` (the stds along the least-informed directions, which bound the D-optimality reward). Why these:
the reward is ``0.5 log det F``, whose gain from a motion is largest along the directions still poorly known; the
per-parameter stds say which parameters (and so which links' and joints' terms) those are, the worst directions how
poorly. Their correlations (1128 for 48 parameters) are left out: too many inputs for the training's length.

**Reward** per decision: the env's reward summed over the held steps: information gain (nats) minus its joint- and
torque-limit penalties. There is no attitude term (the base is fixed).

**Exploration**: PPO starts with the action std 0.37 (:data:`ARM_LOG_STD_INIT`), not stable-baselines3's 1. The
saved policy acts with its mean; with std 1 the training's samples, clipped to [-1, 1], swing the joints from end to
end like random targets whatever the mean, and the mean learnt targets too timid to be worth as much (evaluation
callback on 4 validation windows after 60,000 decisions: 119 nats against random targets' 127; with std 0.37: 128.5,
docs/results.md).

**Training** runs the env at its own 125 Hz (:data:`ARM_TRAIN_CONTROL_PERIOD_S`, which says why), as
``spaceid excite compare-arm`` does: a decision holds 62 control periods (0.496 s). Robots are drawn as in the satellite's training: seeds below 900,000 (each draws the
true parameters from the prior, the start pose and the noise), 900,000 - 999,999 for the evaluation callback,
comparisons from 1,000,000.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from agents.excitation_task import VALIDATION_FIRST_SEED, ExcitationTask, HeldTargetsEnv
from spaceid_gym.arm.arm_robot import ArmRobot
from spaceid_gym.arrays import FloatArray
from spaceid_gym.envs.manipulator import ManipulatorIDEnv
from spaceid_gym.errors import SpaceIdInputError

#: the arm's identification window, s (``ManipulatorID-v0``'s registered 3750 steps at 125 Hz)
ARM_WINDOW_S = 30.0
#: the env's control period while training, s: its own 125 Hz. The torque noise is white per sample, so the information
#: (and the uncertainty features) grow with the rate; at a lower rate the policy would learn on features it never meets
#: at 125 Hz (the satellite's gyro noise is an angle random walk, whose information per second does not depend on it)
ARM_TRAIN_CONTROL_PERIOD_S = 0.008
#: default training length, decisions (see docs/results.md for its wall time)
ARM_DEFAULT_TIMESTEPS = 60_000
#: PPO's initial log std of its actions (std 0.37, against stable-baselines3's 1): see the module docstring
ARM_LOG_STD_INIT = -1.0
#: the least-informed directions of F in the observation
WORST_DIRECTIONS = 4


def arm_policy_features(observation: NDArray[np.float32], env: ManipulatorIDEnv, elapsed_fraction: float) -> FloatArray:
    """The policy's observation (module docstring): shape (3n + 1 + r + :data:`WORST_DIRECTIONS`,), r base parameters."""
    robot = env.robot
    n = robot.n_joints
    mid = 0.5 * (robot.q_lower_rad + robot.q_upper_rad)
    half = 0.5 * (robot.q_upper_rad - robot.q_lower_rad)
    effort_scale = robot.torque_limit_Nm
    if env.sensors.effort_kind == "current_A":
        effort_scale = effort_scale / np.asarray(env.sensors.torque_constants_Nm_A)
    obs = np.asarray(observation, dtype=float)
    information = env.fisher_information  # prior included: eigenvalues >= 1
    std = np.sqrt(np.diag(np.linalg.inv(information)))
    worst = np.linalg.eigvalsh(information)[:WORST_DIRECTIONS]
    return np.concatenate(
        (
            (obs[:n] - mid) / half,
            obs[n : 2 * n] / robot.dq_limit_rad_s,
            obs[2 * n : 3 * n] / effort_scale,
            [elapsed_fraction],
            np.log10(std),
            -0.5 * np.log10(worst),
        )
    )


def arm_joint_limits(robot: ArmRobot) -> tuple[FloatArray, FloatArray, FloatArray]:
    return robot.q_lower_rad, robot.q_upper_rad, robot.dq_limit_rad_s


class ArmExcitationEnv(HeldTargetsEnv):
    """``ManipulatorID-v0`` as the agent sees it: decisions of target angles and the features (module docstring).

    Args:
        robot: shipped arm name (``"ur5"``) or :class:`ArmRobot`.
        control_period_s: the env's control period, s (a divisor of the decision period).
        first_seed, n_seeds: the robots' seeds are drawn from ``[first_seed, first_seed + n_seeds)``.
        window_s: the window, s.
    """

    def __init__(
        self,
        robot: str | ArmRobot = "ur5",
        control_period_s: float = ARM_TRAIN_CONTROL_PERIOD_S,
        first_seed: int = 0,
        n_seeds: int = VALIDATION_FIRST_SEED,
        window_s: float = ARM_WINDOW_S,
    ) -> None:
        env = ManipulatorIDEnv(robot, control_period_s=control_period_s)
        size = 3 * env.robot.n_joints + 1 + env.base.rank + WORST_DIRECTIONS
        super().__init__(env, arm_policy_features, arm_joint_limits(env.robot), size, window_s, first_seed, n_seeds)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        observation, info = self.env.reset(seed=self._draw_seed(), options=options)
        return self._begin(observation), info

    def step(self, action: NDArray[np.float32]) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        reward, info = self._hold(action)
        return self._features(), float(reward), False, self._decision >= self.decisions, info


def make_arm_env(robot: str, first_seed: int, n_seeds: int, attitude_weight: float | None) -> gym.Env:
    """The arm's training wrapper; an attitude weight is refused (the base is fixed)."""
    if attitude_weight is not None:
        raise SpaceIdInputError(f"attitude weight: {robot!r} stands on a fixed base; it has no attitude to weigh")
    return ArmExcitationEnv(robot, first_seed=first_seed, n_seeds=n_seeds)


#: the arm's learnt excitation (:class:`ExcitationTask`)
ARM_TASK = ExcitationTask(
    env_id="ManipulatorID-v0",
    env_type=ManipulatorIDEnv,
    params=("base",),
    window_s=ARM_WINDOW_S,
    train_control_period_s=ARM_TRAIN_CONTROL_PERIOD_S,
    default_attitude_weight=None,
    default_timesteps=ARM_DEFAULT_TIMESTEPS,
    log_std_init=ARM_LOG_STD_INIT,
    make_env=make_arm_env,
    features=arm_policy_features,
    joint_limits=arm_joint_limits,
)
