"""FreeFloatingID-v0: Gymnasium/SB3 API conformance, determinism, reward bookkeeping, bad input."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import spaceid_gym  # noqa: F401  (registers the env)
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.information import log_det
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.sim.simulator import MAX_INTEGRATION_STEP_S, integration_substeps_for


def _rollout(env: gym.Env, seed: int, steps: int) -> tuple[np.ndarray, list[float]]:
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    observations, rewards = [obs], []
    for _ in range(steps):
        obs, reward, _, _, _ = env.step(env.action_space.sample())
        observations.append(obs)
        rewards.append(reward)
    return np.array(observations), rewards


def test_gymnasium_env_checker_passes() -> None:
    check_env(gym.make("FreeFloatingID-v0", robot="quick3").unwrapped, skip_render_check=False)


def test_stable_baselines3_env_checker_passes() -> None:
    sb3_env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3_env_checker.check_env(gym.make("FreeFloatingID-v0", robot="quick3").unwrapped, warn=True)


def test_registered_with_default_time_limit() -> None:
    env = gym.make("FreeFloatingID-v0")
    assert env.spec is not None and env.spec.max_episode_steps == 3000
    short = gym.make("FreeFloatingID-v0", robot="quick3", max_episode_steps=5)
    short.reset(seed=0)
    truncated = [short.step(short.action_space.sample())[3] for _ in range(5)]
    assert truncated == [False, False, False, False, True]


def test_make_vec_runs() -> None:
    envs = gym.make_vec("FreeFloatingID-v0", num_envs=2, vectorization_mode="sync", robot="quick3")
    obs, _infos = envs.reset(seed=[1, 2])
    assert obs.shape == (2, 13)
    obs, rewards, _, _, _ = envs.step(envs.action_space.sample())
    assert obs.shape == (2, 13) and rewards.shape == (2,)
    envs.close()


def test_same_seed_same_episode_different_seed_different_satellite() -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3")
    obs_a, rew_a = _rollout(env, seed=7, steps=50)
    log_a = env.unwrapped.measurement_log()
    obs_b, rew_b = _rollout(env, seed=7, steps=50)
    log_b = env.unwrapped.measurement_log()
    np.testing.assert_array_equal(obs_a, obs_b)
    assert rew_a == rew_b
    np.testing.assert_array_equal(log_a.omega_base_body_rad_s, log_b.omega_base_body_rad_s)
    _, info_7 = env.reset(seed=7)
    _, info_8 = env.reset(seed=8)
    assert info_7["truth"]["tank_position_m"] != info_8["truth"]["tank_position_m"]


def test_observation_holds_measurements_and_info_holds_truth() -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3", sensors="noise_free")
    obs, info = env.reset(seed=3)
    truth = info["truth"]
    assert set(truth) >= {"fuel_consumed_kg", "tank_position_m", "base_mass_kg", "base_com_m", "base_inertia_kgm2"}
    assert truth["base_mass_kg"] == pytest.approx(120.0 - truth["fuel_consumed_kg"])
    for _ in range(20):
        obs, _, _, _, info = env.step(np.ones(3, dtype=np.float32))
    state = env.unwrapped.simulator.state
    np.testing.assert_allclose(obs[:3], state.q_rad, rtol=1e-6)
    np.testing.assert_allclose(obs[6:9], state.omega_base_body, rtol=1e-5, atol=1e-9)
    assert obs.shape == (13,)  # q, dq, omega, quaternion; no parameters
    assert info["truth"] == truth


def test_fuel_grows_between_windows_and_seed_starts_a_new_satellite() -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3")
    _, info = env.reset(seed=11)
    fuel = [info["truth"]["fuel_consumed_kg"]]
    tanks = {tuple(info["truth"]["tank_position_m"])}
    for _ in range(5):
        _, info = env.reset()
        fuel.append(info["truth"]["fuel_consumed_kg"])
        tanks.add(tuple(info["truth"]["tank_position_m"]))
    assert np.all(np.diff(fuel) > 0) and len(tanks) == 1
    assert fuel[-1] <= FuelSchedule().usable_fraction * 120.0
    _, info = env.reset(seed=11)
    assert info["truth"]["fuel_consumed_kg"] == fuel[0]
    _, info = env.reset(options={"fuel_consumed_kg": 30.0, "tank_position_m": [0.1, 0.0, -0.1]})
    assert info["truth"]["fuel_consumed_kg"] == 30.0 and info["truth"]["tank_position_m"] == (0.1, 0.0, -0.1)


def test_reward_information_terms_sum_to_the_episode_information() -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3")
    env.reset(seed=5)
    gains = []
    for _ in range(200):
        *_, info = env.step(env.action_space.sample())
        gains.append(info["information_gain"])
    fisher = env.unwrapped.fisher_information
    _, _info0 = env.reset(seed=5)  # the reset sample's information is part of F as well
    assert sum(gains) > 1.0
    assert sum(gains) == pytest.approx(0.5 * log_det(fisher) - 0.5 * log_det(env.unwrapped.fisher_information), rel=1e-9)


def test_measurement_log_available_at_any_time() -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3")
    env.reset(seed=0)
    assert env.unwrapped.measurement_log().n_samples == 1
    for _ in range(10):
        env.step(env.action_space.sample())
    log = env.unwrapped.measurement_log()
    assert log.n_samples == 11 and log.sample_period_s == pytest.approx(0.02)


@pytest.mark.parametrize(
    ("action", "message"),
    [([np.nan, 0.0, 0.0], "finite"), ([np.inf, 0.0, 0.0], "finite"), ([0.0, 0.0], "shape")],
)
def test_bad_actions_raise(action: list[float], message: str) -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3", disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=f"action: .*{message}"):
        env.step(np.array(action, dtype=np.float32))


def test_bad_constructor_options_are_named() -> None:
    with pytest.raises(ValueError, match="control_period_s"):
        FreeFloatingIDEnv(robot="quick3", control_period_s=0.0)
    with pytest.raises(ValueError, match="render_mode"):
        FreeFloatingIDEnv(robot="quick3", render_mode="human")
    with pytest.raises(ValueError, match="sensors"):
        FreeFloatingIDEnv(robot="quick3", sensors="loud")
    env = FreeFloatingIDEnv(robot="quick3")
    with pytest.raises(ValueError, match="unknown keys"):
        env.reset(seed=0, options={"fuel": 3})
    with pytest.raises(ValueError, match="not below the full-tank base mass"):
        env.reset(seed=0, options={"fuel_consumed_kg": 500.0})
    for bad in (-1, 1.5, "3", True):
        with pytest.raises(ValueError, match="noise_seed"):
            env.reset(seed=0, options={"noise_seed": bad})
    for bad in (0, 1.5, "3", True):
        with pytest.raises(ValueError, match="integration_substeps"):
            FreeFloatingIDEnv(robot="quick3", integration_substeps=bad)


def test_integration_substeps_reach_the_simulator_and_refine_the_attitude() -> None:
    """``integration_substeps``: the simulator's RKMK4 steps per control period; at 20 Hz the attitude after 2 s of a
    brisk motion comes closer to a 32-step reference by more than a factor 1000 from 1 to 8 steps (fourth order: 4096)."""

    def final_attitude(substeps: int) -> np.ndarray:
        env = FreeFloatingIDEnv(robot="quick3", control_period_s=0.05, sensors="noise_free", integration_substeps=substeps)
        env.reset(seed=3)
        assert env.simulator.substeps == substeps
        for k in range(40):
            env.step(np.full(env.robot.n_joints, math.sin(0.7 * k), dtype=np.float32))
        return env.simulator.state.rot_wb.copy()

    reference = final_attitude(32)
    one, eight = (np.linalg.norm(final_attitude(n) - reference) for n in (1, 8))
    assert one > 1000.0 * eight, (one, eight)


def test_by_default_no_integration_step_is_longer_than_the_bound() -> None:
    """Without ``integration_substeps`` the env cuts a control period into steps of at most
    ``MAX_INTEGRATION_STEP_S``: one at 100 and 50 Hz, three at 20 Hz, five at 10 Hz; a number given is kept; and at
    20 Hz the default's attitude is closer to a 32-step reference than one step's by more than 50 (fourth order: 81)."""
    for period, expected in ((0.01, 1), (0.02, 1), (0.05, 3), (0.1, 5)):
        assert integration_substeps_for(period) == expected
        assert period / expected <= MAX_INTEGRATION_STEP_S + 1e-15
        assert FreeFloatingIDEnv(robot="quick3", control_period_s=period).integration_substeps == expected
    assert FreeFloatingIDEnv(robot="quick3", control_period_s=0.05, integration_substeps=1).integration_substeps == 1
    with pytest.raises(ValueError, match="control_period_s"):
        integration_substeps_for(0.0)

    def final_attitude(substeps: int | None) -> np.ndarray:
        env = FreeFloatingIDEnv(robot="quick3", control_period_s=0.05, sensors="noise_free", integration_substeps=substeps)
        env.reset(seed=3)
        for k in range(40):
            env.step(np.full(env.robot.n_joints, math.sin(0.7 * k), dtype=np.float32))
        return env.simulator.state.rot_wb.copy()

    reference = final_attitude(32)
    one, default = (np.linalg.norm(final_attitude(n) - reference) for n in (1, None))
    assert one > 50.0 * default, (one, default)


def test_a_noise_seed_measures_the_same_motion_with_new_noise() -> None:
    """``reset(options={"noise_seed": n})``: the same starting state and motion as the seed alone, the encoders and
    gyro with noise of their own; the same ``n`` gives the same noise."""
    runs = []
    for noise_seed in (None, 1, 1, 2):
        env = FreeFloatingIDEnv(robot="quick3")
        env.reset(seed=5, options={} if noise_seed is None else {"noise_seed": noise_seed})
        for k in range(40):
            env.step(np.full(env.robot.n_joints, 0.5 * math.sin(0.2 * k), dtype=np.float32))
        log = env.measurement_log()
        runs.append((env.simulator.state.q_rad.copy(), log.q_rad[1:].copy(), log.omega_base_body_rad_s[1:].copy()))
    assert all(np.array_equal(runs[0][0], r[0]) for r in runs)  # the same motion
    for measured in (1, 2):
        assert np.array_equal(runs[1][measured], runs[2][measured])  # the same noise seed, the same noise
        assert not np.allclose(runs[0][measured], runs[1][measured], rtol=0.0, atol=1e-12)
        assert not np.allclose(runs[1][measured], runs[3][measured], rtol=0.0, atol=1e-12)


def test_render_rgb_array() -> None:
    env = gym.make("FreeFloatingID-v0", robot="quick3", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
    for _ in range(25):
        env.step(np.ones(3, dtype=np.float32))
    assert not np.array_equal(frame, env.render())


def test_failed_reset_leaves_the_env_usable() -> None:
    env = FreeFloatingIDEnv(robot="quick3")
    _, info = env.reset(seed=1)
    with pytest.raises(ValueError, match=r"triangle|positive definite"):
        env.reset(options={"fuel_consumed_kg": 100.0, "tank_position_m": [3.0, 3.0, 3.0]})
    _, after = env.reset()  # the next window of the same satellite
    assert after["truth"]["tank_position_m"] == info["truth"]["tank_position_m"]
    assert after["truth"]["episode"] == 1


def test_cramer_rao_bound_is_infinite_without_excitation_and_finite_with_it() -> None:
    env = FreeFloatingIDEnv(robot="quick3")
    env.reset(seed=2)
    env.step(np.zeros(3, dtype=np.float32))
    assert np.all(np.isinf(env.cramer_rao_std()))  # one sample of a still arm: nothing to learn
    for k in range(500):
        env.step(np.sin(0.05 * k + np.arange(3)).astype(np.float32))
    std = env.cramer_rao_std()
    assert np.all(np.isfinite(std)) and std[0] < 50.0
    *_, info = env.step(np.zeros(3, dtype=np.float32))
    assert info["log_det_fisher"] > 0.0
