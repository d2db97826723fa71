"""Simulated datasets: run the environment with an excitation and write a dataset folder.

A dataset folder holds ``log.csv`` (the measurements), ``robot.urdf`` (the robot as given to the
estimators: full-tank base) and, for simulated data, ``truth.json`` (the true fuel state and base
mass properties, noise settings and seed). See :mod:`spaceid_gym.log`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.settings import HiddenEffects
from spaceid_gym.envs.free_floating import FreeFloatingIDEnv
from spaceid_gym.limits import check_log_size
from spaceid_gym.log import Dataset, load_dataset, write_dataset
from spaceid_gym.robots import Robot
from spaceid_gym.sim.sensors import SensorModel

#: an excitation: time (s) -> normalised joint-rate command (n,) in [-1, 1]
Excitation = Callable[[float], NDArray[np.float32]]


@runtime_checkable
class FeedbackExcitation(Protocol):
    """An excitation that chooses each command from what it sees (e.g. a learnt policy, :mod:`agents.policy`).

    :func:`simulate_episode` calls ``start(env)`` after the env's reset, then ``act(observation)`` every control
    period with the env's latest observation; ``act`` returns the normalised joint-rate command (n,).
    """

    def start(self, env: FreeFloatingIDEnv) -> None: ...

    def act(self, observation: NDArray[np.float32]) -> NDArray[np.float32]: ...


def simulate_episode(
    robot: Robot,
    duration_s: float,
    fuel_consumed_kg: float,
    tank_position_m: FloatArray,
    excitation: Excitation | FeedbackExcitation,
    seed: int,
    sensors: SensorModel | None = None,
    control_period_s: float = 0.02,
    hidden_effects: HiddenEffects | str | None = None,
    noise_seed: int | None = None,
    integration_substeps: int | None = None,
) -> FreeFloatingIDEnv:
    """Run one identification window in :class:`FreeFloatingIDEnv` and return the env after it.

    The env's :meth:`~FreeFloatingIDEnv.measurement_log` and ``fisher_information`` then describe
    the window. All noise comes from the env's generator seeded with ``seed`` (unless ``noise_seed``). ``excitation``: a function of time
    or a :class:`FeedbackExcitation`. ``hidden_effects``:
    a :class:`~spaceid_gym.effects.HiddenEffects` or a spec string (drawn from the seed), see the
    env; :func:`write_episode_dataset` then writes them to truth.json (``hidden_effects``). ``noise_seed``: the
    measurement noise from a generator of its own (the env's reset option): the same motion with new noise for an
    excitation that is a function of time (a :class:`FeedbackExcitation` acts on the noisy measurements, so its
    motion changes with them). ``integration_substeps``: the env's (the simulator's steps per control period).
    """
    n_steps = check_log_size(duration_s, control_period_s, robot.n_joints)
    env = FreeFloatingIDEnv(
        robot,
        control_period_s=control_period_s,
        sensors=sensors,
        tank_position_m=tank_position_m,
        hidden_effects=hidden_effects,
        integration_substeps=integration_substeps,
    )
    options: dict[str, Any] = {"fuel_consumed_kg": fuel_consumed_kg}
    if noise_seed is not None:
        options["noise_seed"] = noise_seed
    observation, _ = env.reset(seed=seed, options=options)
    if isinstance(excitation, FeedbackExcitation):
        excitation.start(env)
        for _ in range(n_steps):
            observation = env.step(excitation.act(observation))[0]
        return env
    for k in range(n_steps):
        env.step(excitation(k * control_period_s))
    return env


def write_episode_dataset(out_dir: str | Path, env: FreeFloatingIDEnv, extra_truth: dict[str, Any] | None = None) -> Dataset:
    """Write the env's current window as a dataset folder ``out_dir``; return it as loaded back.

    ``truth.json`` holds the episode's true parameters (with ``hidden_effects`` when any is set),
    the noise settings, the simulator's ``integration_substeps`` and ``extra_truth`` (e.g. the seed and the
    excitation used).
    """
    truth: dict[str, Any] = env.truth()
    truth.update(
        robot=env.robot.name,
        duration_s=env.measurement_log().duration_s,
        control_period_s=env.control_period_s,
        integration_substeps=env.integration_substeps,
        noise=env.sensors.as_dict(env.control_period_s),
        **(extra_truth or {}),
    )
    write_dataset(out_dir, env.measurement_log(), env.robot.urdf_text, truth)
    return load_dataset(out_dir, n_joints=env.robot.n_joints)
