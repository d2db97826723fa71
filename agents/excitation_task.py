"""What a learnt excitation shares between the two envs, and what it must know of each (an :class:`ExcitationTask`).

Shared: the agent decides every :data:`DECISION_PERIOD_S`; its action is a **target angle** per joint,
``a`` in [-1, 1] meaning ``mid + a (0.9 half range - 0.3 rad)``, followed every control period with the rate command
``clip((target - q) / (rate limit x 0.5 s), -1, 1)`` from the measured angle (:func:`target_rate_command`); the
seeds of training (below :data:`VALIDATION_FIRST_SEED`), of the evaluation callback and of the held-out comparisons
(from :data:`HELD_OUT_FIRST_SEED`).

Per env (:class:`ExcitationTask`): the env class, the parameterisation whose information is rewarded, the window,
the training's control period, the wrapper the agent trains in, and the policy's observation (features).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray

#: the agent decides this often, s
DECISION_PERIOD_S = 0.5
#: training draws its robots with seeds below this; the evaluation callback from it
VALIDATION_FIRST_SEED = 900_000
#: comparisons draw their robots with seeds from this one (never trained on)
HELD_OUT_FIRST_SEED = 1_000_000
#: the position loop's time constant, s: further than rate limit x this from the target the joint runs at full rate
TARGET_TIME_CONSTANT_S = 0.5


def target_rate_command(
    action: NDArray[np.float32],
    q_rad: NDArray[np.float32],
    lower_rad: FloatArray,
    upper_rad: FloatArray,
    rate_limit_rad_s: FloatArray,
) -> NDArray[np.float32]:
    """The normalised rate command (n,) that moves the measured angles ``q_rad`` towards the action's targets
    (module docstring); ``lower_rad``, ``upper_rad``, ``rate_limit_rad_s``: the joints' ranges and rate limits."""
    mid = 0.5 * (lower_rad + upper_rad)
    reach = 0.9 * 0.5 * (upper_rad - lower_rad) - 0.3
    target = mid + np.clip(np.asarray(action, dtype=float), -1.0, 1.0) * reach
    u = (target - np.asarray(q_rad, dtype=float)) / (rate_limit_rad_s * TARGET_TIME_CONSTANT_S)
    return np.clip(u, -1.0, 1.0).astype(np.float32)


#: ``features(observation, unwrapped env, elapsed fraction of the window)`` -> the policy's observation
Features = Callable[[NDArray[np.float32], Any, float], FloatArray]
#: ``make_env(robot, first_seed, n_seeds, attitude_weight)`` -> the wrapper the agent trains in
MakeEnv = Callable[[str, int, int, "float | None"], gym.Env]


@dataclass(frozen=True)
class ExcitationTask:
    """What a learnt excitation must know of one env.

    Attributes:
        env_id: the env's registered name (``policy.json``'s ``env``).
        env_type: the unwrapped env's class (a policy drives only this).
        params: the parameterisations whose information the env rewards (the first is the default).
        window_s: the identification window, s (the policy's elapsed-time feature counts in it).
        train_control_period_s: the env's control period while training, s (a divisor of the decision period).
        default_attitude_weight: nats per degree of peak base attitude excursion, ``None`` for a fixed base.
        default_timesteps: the default training's length, decisions.
        log_std_init: PPO's initial log std of its Gaussian actions (how widely the training explores).
        make_env: the training wrapper.
        features: the policy's observation.
        joint_limits: ``robot -> (lower_rad, upper_rad, rate_limit_rad_s)``.
    """

    env_id: str
    env_type: type
    params: tuple[str, ...]
    window_s: float
    train_control_period_s: float
    default_attitude_weight: float | None
    default_timesteps: int
    log_std_init: float
    make_env: MakeEnv
    features: Features
    joint_limits: Callable[[Any], tuple[FloatArray, FloatArray, FloatArray]]

    def rate_command(self, action: NDArray[np.float32], q_rad: NDArray[np.float32], robot: Any) -> NDArray[np.float32]:
        """:func:`target_rate_command` with ``robot``'s ranges and rate limits."""
        return target_rate_command(action, q_rad, *self.joint_limits(robot))

    @property
    def decisions(self) -> int:
        """Decisions per window."""
        return max(1, round(self.window_s / DECISION_PERIOD_S))


class HeldTargetsEnv(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """The common part of the training wrappers: an env (``self.env``) driven by targets held for a decision.

    Subclasses reset ``self.env``, then call :meth:`_begin`; their ``step`` calls :meth:`_hold`.

    Args:
        env: the unwrapped env.
        features: the policy's observation.
        limits: the joints' ``(lower_rad, upper_rad, rate_limit_rad_s)``.
        n_features: the observation's size.
        window_s: the window, s.
        first_seed, n_seeds: the robots' seeds are drawn from ``[first_seed, first_seed + n_seeds)``.
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 (gymnasium's convention)

    def __init__(
        self,
        env: Any,
        features: Features,
        limits: tuple[FloatArray, FloatArray, FloatArray],
        n_features: int,
        window_s: float,
        first_seed: int,
        n_seeds: int,
    ) -> None:
        self.env, self._feature_map, self._limits = env, features, limits
        self.hold_steps = max(1, round(DECISION_PERIOD_S / env.control_period_s))
        self.decisions = max(1, round(window_s / DECISION_PERIOD_S))
        self.first_seed, self.n_seeds = int(first_seed), int(n_seeds)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(env.robot.n_joints,), dtype=np.float32)
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(n_features,), dtype=np.float32)

    def _draw_seed(self) -> int:
        """The next robot's seed (from the wrapper's own generator, seeded by ``reset(seed=...)``)."""
        return int(self.first_seed + self.np_random.integers(self.n_seeds))

    def _begin(self, observation: NDArray[np.float32]) -> NDArray[np.float32]:
        self._decision, self._last = 0, observation
        return self._features()

    def _hold(self, action: NDArray[np.float32]) -> tuple[float, dict[str, Any]]:
        """Follow the action's targets for one decision: the env's summed reward and its last info."""
        reward, info = 0.0, {}
        n = self.env.robot.n_joints
        for _ in range(self.hold_steps):
            self._last, r, _, _, info = self.env.step(target_rate_command(action, self._last[:n], *self._limits))
            reward += r
        self._decision += 1
        return reward, info

    def _features(self) -> NDArray[np.float32]:
        return self._feature_map(self._last, self.env, self._decision / self.decisions).astype(np.float32)
