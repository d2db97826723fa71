"""A learnt excitation: a stable-baselines3 agent that moves the arm so that the gyro data identify the fuel state.

**What the agent sees and does** (:class:`ExcitationEnv`, built on ``FreeFloatingID-v0``): every
:data:`DECISION_PERIOD_S` (0.5 s) it picks a **target angle** per joint, action ``a`` in [-1, 1] meaning
``mid + a (0.9 half range - 0.3 rad)`` (the env starts within 0.3 rad of the middle), held for the decision period;
every control period the env gets the rate command ``clip((target - q) / (rate limit x 0.5 s), -1, 1)`` from the
measured angle (:func:`rate_command`). Targets keep the joints inside their ranges whatever the policy does (rate
actions held for 0.5 s drove joints into their limits early in training) and make the most informative motion, at
full rate from one end to the other, a simple function of the observation.
Its observation (:func:`policy_features`, 29 values for a 6-joint arm) is the env's measured joint angles and rates
(normalised by the ranges and rate limits), the gyro (per 0.02 rad/s), the attitude quaternion's vector part, the
elapsed fraction of the window and the **uncertainty so far**: ``log10`` of the Cramér-Rao stds of the four fuel
parameters in prior-range units (the env's accumulated information, prior included) and their six correlations.
So the policy can adapt to the satellite in front of it, which one fixed trajectory cannot.

**Reward** per decision: the env's reward summed over the held steps (information gain in nats, minus its
joint-limit and base-rate penalties), minus ``attitude_weight`` times the growth of the **peak base attitude
excursion** (the true base's rotation angle from its initial attitude, degrees) in that decision. Summed over a
window the last term is ``attitude_weight x peak excursion``: with the default :data:`DEFAULT_ATTITUDE_WEIGHT` =
0.05 nats per degree, a trajectory that turns the satellite 10 degrees further must gain 0.5 nats more information
(``0.5 log det F`` up by 0.5: the Cramér-Rao ellipsoid's volume shrinks by ``e^0.5 = 1.65``) to be worth it.
Operators who do not want the satellite to tumble raise it (0.2 turned paper6's base 4.9 degrees instead of 21.5, for
1.5x the fuel error; docs/results.md); 0 ignores the attitude.

**True settings**: each training episode draws a new satellite (tank position uniform in its box) with a seed below
:data:`VALIDATION_FIRST_SEED` and fuel consumed uniform in the prior range; the evaluation callback uses seeds from
:data:`VALIDATION_FIRST_SEED`; comparisons (:mod:`agents.comparison`) use seeds from :data:`HELD_OUT_FIRST_SEED`,
never seen in training.

**Training** (:func:`train_excitation`): PPO (default) or SAC, ``VecNormalize`` on observations and rewards, a
progress bar, an evaluation callback and checkpoints, fixed seed. Training runs the env at
:data:`TRAIN_CONTROL_PERIOD_S` (10 Hz, five env steps per decision) to be fast; the policy then drives the env at
any rate (the gyro's information per second does not depend on the rate: its noise is an angle random walk).

**The policy folder** (:meth:`ExcitationPolicy.save`): ``policy.json`` (robot, parameterisation, algorithm,
decision period, attitude weight, observation normalisation, training facts) and ``model.zip`` (stable-baselines3).
"""

from __future__ import annotations

import json
import math
import time
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from numpy.typing import NDArray
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback, EvalCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

from agents.arm_policy import ARM_TASK
from agents.excitation_task import (
    DECISION_PERIOD_S,
    HELD_OUT_FIRST_SEED,
    VALIDATION_FIRST_SEED,
    ExcitationTask,
    HeldTargetsEnv,
    target_rate_command,
)
from agents.progress import ProgressBar
from spaceid_gym.arm.arm_robot import available_arms
from spaceid_gym.arrays import FloatArray
from spaceid_gym.envs.free_floating import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.robots import Robot, load_robot

#: the env's control period while training, s (10 Hz)
TRAIN_CONTROL_PERIOD_S = 0.1
#: the simulator's steps per control period while training: one, as the shipped policies were trained (the reward
#: reads the attitude to a fraction of a degree; one 0.1 s RKMK4 step errs by about 1e-6 rad), five times cheaper
#: than the env's default at 10 Hz (no step longer than ``MAX_INTEGRATION_STEP_S``)
TRAIN_INTEGRATION_SUBSTEPS = 1
#: the identification window, s
WINDOW_S = 60.0
#: nats of reward lost per degree of peak base attitude excursion (module docstring)
DEFAULT_ATTITUDE_WEIGHT = 0.05
#: parameterisations the agent can be trained for (the env's reward is the fuel parameters' information)
PARAMETERISATIONS = ("fuel",)
#: algorithms of stable-baselines3 offered
ALGORITHMS = {"ppo": PPO, "sac": SAC}
#: format of policy.json
POLICY_FORMAT = 1
#: default training length, decisions (see docs/results.md for its wall time)
DEFAULT_TIMESTEPS = 200_000


def policy_features(observation: NDArray[np.float32], env: FreeFloatingIDEnv, elapsed_fraction: float) -> FloatArray:
    """The policy's observation (module docstring): shape (2n + 17,) for an n-joint arm."""
    robot = env.robot
    n = robot.n_joints
    mid = 0.5 * (robot.q_lower_rad + robot.q_upper_rad)
    half = 0.5 * (robot.q_upper_rad - robot.q_lower_rad)
    obs = np.asarray(observation, dtype=float)
    covariance = np.linalg.inv(env.fisher_information)  # prior included: always positive definite
    std = np.sqrt(np.diag(covariance))
    correlation = covariance / np.outer(std, std)
    upper = np.triu_indices(len(std), 1)
    return np.concatenate(
        (
            (obs[:n] - mid) / half,
            obs[n : 2 * n] / robot.rate_limit_rad_s,
            obs[2 * n : 2 * n + 3] / 0.02,
            obs[2 * n + 4 : 2 * n + 7],
            [elapsed_fraction],
            np.log10(std),
            correlation[upper],
        )
    )


def rate_command(action: NDArray[np.float32], q_rad: NDArray[np.float32], robot: Robot) -> NDArray[np.float32]:
    """The normalised rate command (n,) that moves the measured angles ``q_rad`` towards the action's targets."""
    return target_rate_command(action, q_rad, robot.q_lower_rad, robot.q_upper_rad, robot.rate_limit_rad_s)


def attitude_excursion_deg(env: FreeFloatingIDEnv) -> float:
    """The true base's rotation angle from its initial attitude (identity), degrees."""
    rotation = env.simulator.state.rot_wb
    return math.degrees(math.acos(min(1.0, max(-1.0, 0.5 * (float(np.trace(rotation)) - 1.0)))))


def satellite_joint_limits(robot: Robot) -> tuple[FloatArray, FloatArray, FloatArray]:
    return robot.q_lower_rad, robot.q_upper_rad, robot.rate_limit_rad_s


class ExcitationEnv(HeldTargetsEnv):
    """``FreeFloatingID-v0`` as the agent sees it: decisions, features and the attitude term (module docstring).

    Args:
        robot: shipped robot name or :class:`Robot`.
        control_period_s: the env's control period, s (a divisor of the decision period).
        attitude_weight: nats per degree of peak attitude excursion (>= 0).
        first_seed, n_seeds: the satellites' seeds are drawn from ``[first_seed, first_seed + n_seeds)``.
        window_s: the window, s.
    """

    def __init__(
        self,
        robot: str | Robot = "paper6",
        control_period_s: float = TRAIN_CONTROL_PERIOD_S,
        attitude_weight: float = DEFAULT_ATTITUDE_WEIGHT,
        first_seed: int = 0,
        n_seeds: int = VALIDATION_FIRST_SEED,
        window_s: float = WINDOW_S,
    ) -> None:
        env = FreeFloatingIDEnv(robot, control_period_s=control_period_s, integration_substeps=TRAIN_INTEGRATION_SUBSTEPS)
        limits = satellite_joint_limits(env.robot)
        super().__init__(env, policy_features, limits, 2 * env.robot.n_joints + 17, window_s, first_seed, n_seeds)
        self.attitude_weight = check_attitude_weight(attitude_weight)
        self._schedule = FuelSchedule()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        satellite = int(options.pop("satellite_seed", self._draw_seed()))
        mass = self.env.robot.base_full.mass_kg
        fuel = options.pop("fuel_consumed_kg", None)
        if fuel is None:
            fuel = self.np_random.uniform(self._schedule.initial_fraction, self._schedule.usable_fraction) * mass
        options["fuel_consumed_kg"] = float(fuel)
        observation, info = self.env.reset(seed=satellite, options=options)
        self._peak_deg = 0.0
        return self._begin(observation), info

    def step(self, action: NDArray[np.float32]) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        reward, info = self._hold(action)
        peak = max(self._peak_deg, attitude_excursion_deg(self.env))
        reward -= self.attitude_weight * (peak - self._peak_deg)
        self._peak_deg = peak
        info["peak_attitude_excursion_deg"] = peak
        return self._features(), float(reward), False, self._decision >= self.decisions, info


def check_attitude_weight(weight: float) -> float:
    if not (math.isfinite(weight) and weight >= 0.0):
        raise SpaceIdInputError(f"attitude weight: expected a finite number >= 0 (nats per degree), got {weight!r}")
    return float(weight)


def make_satellite_env(robot: str, first_seed: int, n_seeds: int, attitude_weight: float | None) -> gym.Env:
    weight = DEFAULT_ATTITUDE_WEIGHT if attitude_weight is None else attitude_weight
    return ExcitationEnv(robot, attitude_weight=weight, first_seed=first_seed, n_seeds=n_seeds)


#: the satellite's learnt excitation (``FreeFloatingID-v0``)
SATELLITE_TASK = ExcitationTask(
    env_id="FreeFloatingID-v0",
    env_type=FreeFloatingIDEnv,
    params=PARAMETERISATIONS,
    window_s=WINDOW_S,
    train_control_period_s=TRAIN_CONTROL_PERIOD_S,
    default_attitude_weight=DEFAULT_ATTITUDE_WEIGHT,
    default_timesteps=DEFAULT_TIMESTEPS,
    log_std_init=0.0,
    make_env=make_satellite_env,
    features=policy_features,
    joint_limits=satellite_joint_limits,
)
#: the learnt excitations by env name (``policy.json``'s ``env``; absent in the first format's files: the satellite)
TASKS = {task.env_id: task for task in (SATELLITE_TASK, ARM_TASK)}


def task_for_robot(robot: str) -> ExcitationTask:
    """The arm's task for a shipped arm's name (``"ur5"``), else the satellite's."""
    return ARM_TASK if robot in available_arms() else SATELLITE_TASK


def task_of_env(env: gym.Env) -> ExcitationTask:
    """The task whose env ``env`` (unwrapped) is; a clear error for any other env."""
    for task in TASKS.values():
        if isinstance(env.unwrapped, task.env_type):
            return task
    raise SpaceIdInputError(f"excitation: drives {' or '.join(TASKS)}, got {type(env.unwrapped).__name__}")


class ExcitationPolicy:
    """A trained excitation policy: the action source of ``FreeFloatingID-v0`` or ``ManipulatorID-v0`` (whichever it
    was trained on; a :class:`~spaceid_gym.datasets.FeedbackExcitation`).

    Use it with :func:`spaceid_gym.datasets.simulate_episode`, or by hand: ``policy.start(env)`` after
    ``env.reset(...)``, then ``env.step(policy.act(observation))`` every control period.
    """

    def __init__(self, model: BaseAlgorithm, metadata: dict[str, Any]) -> None:
        self.model, self.metadata = model, metadata
        self.task = TASKS[str(metadata.get("env", SATELLITE_TASK.env_id))]
        self._mean = np.asarray(metadata["observation_mean"], dtype=float)
        self._std = np.sqrt(np.asarray(metadata["observation_var"], dtype=float) + metadata["observation_epsilon"])
        self._clip = float(metadata["observation_clip"])
        self._env: Any = None

    @property
    def robot_name(self) -> str:
        return str(self.metadata["robot"])

    def start(self, env: gym.Env) -> None:
        """Begin a window of ``env`` (right after its reset)."""
        unwrapped = env.unwrapped
        if not isinstance(unwrapped, self.task.env_type):
            raise SpaceIdInputError(f"policy: drives {self.task.env_id}, got {type(unwrapped).__name__}")
        if unwrapped.robot.name != self.robot_name:
            raise SpaceIdInputError(f"policy: trained for robot {self.robot_name!r}, the env has {unwrapped.robot.name!r}")
        self._env = unwrapped
        self._hold = max(1, round(DECISION_PERIOD_S / unwrapped.control_period_s))
        self._step, self._action = 0, np.zeros(unwrapped.robot.n_joints, dtype=np.float32)

    def act(self, observation: NDArray[np.float32]) -> NDArray[np.float32]:
        """The rate command for this control period: a new target every :data:`DECISION_PERIOD_S`, held in between,
        followed from the measured angles (:func:`~agents.excitation_task.target_rate_command`)."""
        if self._env is None:
            raise SpaceIdInputError("policy: call start(env) after the env's reset, before act()")
        if self._step % self._hold == 0:
            decision, decisions = self._step // self._hold, self.task.decisions
            features = self.task.features(observation, self._env, min(decision, decisions) / decisions)
            normalised = np.clip((features - self._mean) / self._std, -self._clip, self._clip).astype(np.float32)
            self._action = np.asarray(self.model.predict(normalised, deterministic=True)[0], dtype=np.float32)
        self._step += 1
        return self.task.rate_command(self._action, observation[: self._env.robot.n_joints], self._env.robot)

    def save(self, folder: str | Path) -> Path:
        """Write ``policy.json`` and ``model.zip`` into ``folder``."""
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        self.model.save(out / "model.zip")
        (out / "policy.json").write_text(json.dumps(self.metadata, indent=2))
        return out

    @classmethod
    def load(cls, folder: str | Path, robot: str | None = None, params: str | None = None) -> ExcitationPolicy:
        """The policy saved in ``folder``; ``robot``/``params``, when given, must be what it was trained for.

        Raises:
            SpaceIdInputError: naming the folder and what is wrong (missing or corrupt files, another robot or
                parameterisation).
        """
        path = Path(folder)
        meta_path, zip_path = path / "policy.json", path / "model.zip"
        if not meta_path.is_file() or not zip_path.is_file():
            raise SpaceIdInputError(
                f"{path}: not a policy folder (expected policy.json and model.zip, written by 'spaceid excite train')"
            )
        try:
            metadata = json.loads(meta_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise SpaceIdInputError(f"{meta_path}: not valid JSON ({exc})") from None
        if not isinstance(metadata, dict) or metadata.get("format") != POLICY_FORMAT:
            raise SpaceIdInputError(f"{meta_path}: not a policy description of format {POLICY_FORMAT}")
        env_id = metadata.get("env", SATELLITE_TASK.env_id)
        if env_id not in TASKS:
            raise SpaceIdInputError(f"{meta_path}: unknown env {env_id!r}; expected one of {sorted(TASKS)}")
        if robot is not None and metadata.get("robot") != robot:
            raise SpaceIdInputError(f"{path}: policy trained for robot {metadata.get('robot')!r} ({env_id}), not {robot!r}")
        if params is not None and metadata.get("params") != params:
            raise SpaceIdInputError(f"{path}: policy trained for parameterisation {metadata.get('params')!r}, not {params!r}")
        algorithm = ALGORITHMS.get(str(metadata.get("algorithm")))
        if algorithm is None:
            raise SpaceIdInputError(
                f"{meta_path}: unknown algorithm {metadata.get('algorithm')!r}; expected one of {sorted(ALGORITHMS)}"
            )
        try:
            model = algorithm.load(zip_path, device="cpu")
        except (zipfile.BadZipFile, ValueError, KeyError, EOFError, RuntimeError, OSError) as exc:
            raise SpaceIdInputError(f"{zip_path}: corrupt or unreadable policy model ({type(exc).__name__}: {exc})") from None
        size = len(metadata.get("observation_mean", []))
        if model.observation_space.shape != (size,):
            raise SpaceIdInputError(f"{path}: model.zip and policy.json disagree on the observation size")
        return cls(model, metadata)


class RandomTargets:
    """The policy's action space without the learning: uniform random targets every :data:`DECISION_PERIOD_S`,
    followed like the policy's (:func:`~agents.excitation_task.target_rate_command`); a
    :class:`~spaceid_gym.datasets.FeedbackExcitation` of either env.

    It tells what the learnt policy adds to its action space. Draws from ``numpy.random.default_rng(seed)``.
    """

    def __init__(self, seed: int) -> None:
        self.seed = seed
        self._env: Any = None

    def start(self, env: gym.Env) -> None:
        self._task = task_of_env(env)
        self._env = env.unwrapped
        self._hold = max(1, round(DECISION_PERIOD_S / self._env.control_period_s))
        self._rng, self._step = np.random.default_rng(self.seed), 0
        self._target = np.zeros(self._env.robot.n_joints, dtype=np.float32)

    def act(self, observation: NDArray[np.float32]) -> NDArray[np.float32]:
        if self._env is None:
            raise SpaceIdInputError("random targets: call start(env) after the env's reset, before act()")
        if self._step % self._hold == 0:
            self._target = self._rng.uniform(-1.0, 1.0, size=self._target.shape).astype(np.float32)
        self._step += 1
        return self._task.rate_command(self._target, observation[: self._env.robot.n_joints], self._env.robot)


def make_vec_env(
    robot: str, n_envs: int, kind: str, attitude_weight: float | None, first_seed: int, n_seeds: int, seed: int
) -> VecEnv:
    """``n_envs`` training wrappers of ``robot``'s task (:func:`task_for_robot`) in a ``DummyVecEnv`` (one process)
    or ``SubprocVecEnv`` (one each); ``attitude_weight`` ``None``: the task's default."""
    task = task_for_robot(robot)

    def factory(rank: int) -> Any:
        def make() -> gym.Env:
            env = Monitor(task.make_env(robot, first_seed, n_seeds, attitude_weight))
            env.reset(seed=seed + rank)
            return env

        return make

    if kind not in ("dummy", "subproc"):
        raise SpaceIdInputError(f"vec env: expected 'dummy' or 'subproc', got {kind!r}")
    factories = [factory(i) for i in range(n_envs)]
    vec: VecEnv = DummyVecEnv(factories) if kind == "dummy" else SubprocVecEnv(factories, start_method="fork")
    vec.seed(seed)
    return vec


def train_excitation(
    robot: str = "paper6",
    params: str | None = None,
    timesteps: int | None = None,
    out: str | Path | None = None,
    *,
    algorithm: str = "ppo",
    seed: int = 0,
    n_envs: int = 2,
    vec_env: str = "dummy",
    attitude_weight: float | None = None,
    eval_episodes: int = 4,
    n_evaluations: int = 5,
    progress_bar: bool = True,
    log_std_init: float | None = None,
) -> ExcitationPolicy:
    """Train an excitation policy for ``robot`` (module docstring; a shipped arm such as ``"ur5"``:
    :mod:`agents.arm_policy`) and save it to ``out`` if given.

    Args:
        robot: shipped robot or arm name.
        params: the parameterisation whose information is rewarded (``"fuel"`` for a satellite, ``"base"`` for an
            arm; ``None``: that).
        timesteps: agent decisions to train for (> 0; ``None``: the task's default, :data:`DEFAULT_TIMESTEPS` for a
            satellite, :data:`~agents.arm_policy.ARM_DEFAULT_TIMESTEPS` for an arm).
        out: the policy folder (with ``checkpoints/`` and ``eval/``); ``None`` keeps it in memory.
        algorithm: ``"ppo"`` (default) or ``"sac"``.
        seed: seed of the algorithm, the envs and their draws.
        n_envs: parallel envs.
        vec_env: ``"dummy"`` (default: faster on 2 cores for the satellite, see docs/results.md) or ``"subproc"``.
        attitude_weight: nats per degree of peak base attitude excursion (satellites only; ``None``: 0.05).
        eval_episodes, n_evaluations: the evaluation callback's episodes per evaluation and evaluations per run.
        progress_bar: show a progress bar.
        log_std_init: PPO's initial log std of its Gaussian actions (the training's exploration; the saved policy
            acts with the mean); ``None``: the task's (0 for a satellite, -1 for an arm).
    """
    task = task_for_robot(robot)
    timesteps = task.default_timesteps if timesteps is None else timesteps
    params = task.params[0] if params is None else params
    if isinstance(timesteps, bool) or not isinstance(timesteps, int) or timesteps <= 0:
        raise SpaceIdInputError(f"timesteps: expected a positive integer, got {timesteps!r}")
    if params not in task.params:
        raise SpaceIdInputError(f"params: the agent for {robot!r} is trained for {list(task.params)}, got {params!r}")
    if algorithm not in ALGORITHMS:
        raise SpaceIdInputError(f"algorithm: expected one of {sorted(ALGORITHMS)}, got {algorithm!r}")
    log_std_init = task.log_std_init if log_std_init is None else log_std_init
    if not math.isfinite(log_std_init):
        raise SpaceIdInputError(f"log_std_init: expected a finite number, got {log_std_init!r}")
    if isinstance(n_envs, bool) or not isinstance(n_envs, int) or not 1 <= n_envs <= 64:
        raise SpaceIdInputError(f"n_envs: expected an integer from 1 to 64, got {n_envs!r}")
    if attitude_weight is not None:
        check_attitude_weight(attitude_weight)
    if task is SATELLITE_TASK:
        robot_name = load_robot(robot).name  # a clear error for an unknown robot before anything starts
        attitude_weight = DEFAULT_ATTITUDE_WEIGHT if attitude_weight is None else attitude_weight
    else:
        task.make_env(robot, 0, 1, attitude_weight)  # refuses an attitude weight for a fixed base
        robot_name = robot
    started = time.perf_counter()
    torch.manual_seed(seed)
    torch.set_num_threads(1)  # small networks: threads only contend with the envs on 2 cores
    train = VecNormalize(make_vec_env(robot, n_envs, vec_env, attitude_weight, 0, VALIDATION_FIRST_SEED, seed), gamma=0.99)
    evaluation = VecNormalize(
        make_vec_env(
            robot, 1, "dummy", attitude_weight, VALIDATION_FIRST_SEED, HELD_OUT_FIRST_SEED - VALIDATION_FIRST_SEED, seed + 10_000
        ),
        training=False,
        norm_reward=False,
    )
    evaluation.obs_rms = train.obs_rms  # the same normalisation as the policy sees
    decisions = train.get_attr("decisions")[0]
    if algorithm == "ppo":  # rollouts of two windows per env, minibatches of one window
        n_steps = max(8, min(2 * decisions, timesteps // n_envs))
        model: BaseAlgorithm = PPO(
            "MlpPolicy", train, n_steps=n_steps, batch_size=max(8, n_steps // 2), learning_rate=3e-4, gamma=0.99,
            gae_lambda=0.95, n_epochs=10, seed=seed, device="cpu", verbose=0,
            policy_kwargs={"net_arch": [64, 64], "log_std_init": log_std_init},
        )  # fmt: skip
    else:
        model = SAC(
            "MlpPolicy", train, learning_starts=min(1000, timesteps // 2), seed=seed, device="cpu", verbose=0,
            policy_kwargs={"net_arch": [64, 64]},
        )  # fmt: skip
    callbacks: list[BaseCallback] = []
    if progress_bar:
        callbacks.append(ProgressBar(timesteps))
    if out is not None:
        folder = Path(out)
        every = max(1, timesteps // (n_evaluations * n_envs))
        callbacks.append(CheckpointCallback(every, str(folder / "checkpoints"), name_prefix="policy"))
        callbacks.append(
            EvalCallback(
                evaluation,
                n_eval_episodes=eval_episodes,
                eval_freq=every,
                log_path=str(folder / "eval"),
                deterministic=True,
                verbose=0,
            )
        )
    model.learn(total_timesteps=timesteps, callback=CallbackList(callbacks))
    wall = time.perf_counter() - started
    metadata = {
        "format": POLICY_FORMAT,
        "env": task.env_id,
        "robot": robot_name,
        "params": params,
        "algorithm": algorithm,
        "decision_period_s": DECISION_PERIOD_S,
        "window_s": task.window_s,
        "attitude_weight_nats_per_deg": attitude_weight,
        "log_std_init": log_std_init if algorithm == "ppo" else None,
        "observation_mean": train.obs_rms.mean.tolist(),
        "observation_var": train.obs_rms.var.tolist(),
        "observation_epsilon": float(train.epsilon),
        "observation_clip": float(train.clip_obs),
        "timesteps": timesteps,
        "n_envs": n_envs,
        "vec_env": vec_env,
        "seed": seed,
        "train_seeds": [0, VALIDATION_FIRST_SEED],
        "train_control_period_s": task.train_control_period_s,
        "training_wall_time_s": wall,
    }
    train.close()
    evaluation.close()
    policy = ExcitationPolicy(model, metadata)
    if out is not None:
        policy.save(out)
    return policy
