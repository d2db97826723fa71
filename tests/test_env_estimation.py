"""The estimator hook of FreeFloatingID-v0: the wrapper, the entry point, and a streaming estimator's running estimate."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from estimators.problem import IdentificationModel
from estimators.registry import make_estimator
from estimators.streaming import is_streaming
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.envs.estimation import EstimatorWrapper
from spaceid_gym.errors import SpaceIdInputError

STEPS = 60


def _run(env: gym.Env, seed: int, steps: int = STEPS) -> list[dict]:
    """Reset with ``seed`` and step a smooth multi-sine; the reset's info then each step's."""
    _, info = env.reset(seed=seed)
    infos = [info]
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    for k in range(steps):
        action[:] = np.sin(0.1 * k * np.arange(1, action.size + 1))
        infos.append(env.step(action)[4])
    return infos


def test_make_without_an_estimator_gives_the_physics_env_alone() -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3", max_episode_steps=5)
    assert isinstance(env.unwrapped, FreeFloatingIDEnv)
    wrapped = env
    while isinstance(wrapped, gym.Wrapper):
        assert not isinstance(wrapped, EstimatorWrapper)
        wrapped = wrapped.env
    infos = _run(env, seed=0, steps=5)
    assert not any("running_estimate" in info or "estimate" in info for info in infos)


def test_a_batch_estimator_reports_at_the_window_end_only() -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3", estimator="lm", max_episode_steps=STEPS, identify_after_steps=STEPS)
    infos = _run(env, seed=2)
    assert [("estimate" in info) for info in infos] == [False] * STEPS + [True]
    assert not any("running_estimate" in info for info in infos)
    assert infos[-1]["estimate"]["estimator"] == "lm"


def test_ukf_running_estimate_is_the_filter_over_the_window_so_far() -> None:
    """Each step's running estimate is the UKF's one pass over the window's samples so far, fed one sample at a time:
    the same numbers as its tracker run over the whole log at once (the paper's model predicts a sample from that
    sample alone, so a one-sample log per step loses nothing)."""
    env = gym.make("FreeFloatingID-v0", robot="quick3", estimator="ukf", max_episode_steps=STEPS, identify_after_steps=STEPS)
    infos = _run(env, seed=1)
    physics = env.unwrapped
    names = ("fuel_consumed_kg", "tank_x_m", "tank_y_m", "tank_z_m")
    for info in infos:
        assert tuple(info["running_estimate"]) == names and tuple(info["running_estimate_std"]) == names
    model = IdentificationModel(physics.robot, "fuel", noise_std_rad_s=physics.gyro_std_rad_s)
    log = physics.measurement_log()
    for upto in (1, 20, STEPS + 1):  # the reset's sample, a middle step, the last step
        tracker = make_estimator("ukf").tracker(model.problem(log if upto == log.n_samples else _first(log, upto)))
        tracker.run()
        theta, covariance = tracker.estimate()
        info = infos[upto - 1]
        np.testing.assert_allclose(list(info["running_estimate"].values()), theta, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(list(info["running_estimate_std"].values()), np.sqrt(np.diag(covariance)), rtol=1e-9)
    # the window's-end fit is the estimator's own (tempered passes), next to the running estimate
    assert infos[-1]["estimate"]["estimator"] == "ukf" and "running_estimate" in infos[-1]
    # the data inform the fuel mass: its std shrinks from the prior's over the window
    stds = [info["running_estimate_std"]["fuel_consumed_kg"] for info in infos]
    assert stds[-1] < 0.5 * stds[0]


def _first(log, count: int):
    """The first ``count`` samples of ``log`` (``count`` >= 1)."""
    return type(log)(
        t_s=log.t_s[:count],
        q_rad=log.q_rad[:count],
        dq_rad_s=log.dq_rad_s[:count],
        omega_base_body_rad_s=log.omega_base_body_rad_s[:count],
        quat_base_to_inertial_wxyz=None if log.quat_base_to_inertial_wxyz is None else log.quat_base_to_inertial_wxyz[:count],
    )


def test_streaming_only_for_streaming_estimators_and_without_effects() -> None:
    assert is_streaming(make_estimator("ukf")) and not is_streaming(make_estimator("hybrid"))
    with pytest.raises(SpaceIdInputError, match="estimator_effects: the running estimate"):
        EstimatorWrapper(FreeFloatingIDEnv("quick3"), "ukf", estimator_effects="initial_momentum")
    wrapper = EstimatorWrapper(FreeFloatingIDEnv("quick3"), "ukf", estimator_effects="initial_momentum", stream=False)
    assert not wrapper.streaming
    with pytest.raises(SpaceIdInputError, match="stream: expected True or False"):
        EstimatorWrapper(FreeFloatingIDEnv("quick3"), "ukf", stream="yes")
    with pytest.raises(SpaceIdInputError, match="env: expected a FreeFloatingIDEnv"):
        EstimatorWrapper(gym.make("ManipulatorID-v0"), "lm")
    with pytest.raises(SpaceIdInputError, match="no_such_effect"):
        EstimatorWrapper(FreeFloatingIDEnv("quick3"), "lm", estimator_effects="no_such_effect")


def test_the_recorder_gives_the_newest_samples() -> None:
    env = FreeFloatingIDEnv("quick3")
    env.reset(seed=0)
    for _ in range(4):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    whole, newest = env.measurement_log(), env.measurement_log(last=2)
    assert newest.n_samples == 2 and np.array_equal(newest.t_s, whole.t_s[-2:])
    assert env.measurement_log(last=100).n_samples == whole.n_samples == 5
    with pytest.raises(SpaceIdInputError, match="last: expected a positive number"):
        env.measurement_log(last=0)
