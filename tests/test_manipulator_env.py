"""ManipulatorID-v0: Gymnasium/SB3 API conformance, determinism, the information reward, limits, bad input.

Independent reference for the reward: the Fisher information rebuilt in one batch from the
episode's noise-free log (regressor of all samples at once) against the env's per-step updates.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import spaceid_gym  # noqa: F401  (registers the env)
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.envs.manipulator import ManipulatorIDEnv
from spaceid_gym.information import log_det


@pytest.fixture(scope="module")
def env() -> ManipulatorIDEnv:
    return ManipulatorIDEnv()


@pytest.fixture(scope="module")
def quiet_env(env: ManipulatorIDEnv) -> ManipulatorIDEnv:
    return ManipulatorIDEnv(sensors="noise_free", base_parameters=env.base)


def _rollout(environment: gym.Env, seed: int, steps: int) -> tuple[np.ndarray, list[float]]:
    obs, _ = environment.reset(seed=seed)
    environment.action_space.seed(seed)
    observations, rewards = [obs], []
    for _ in range(steps):
        obs, reward, _, _, _ = environment.step(environment.action_space.sample())
        observations.append(obs)
        rewards.append(reward)
    return np.array(observations), rewards


def test_gymnasium_env_checker_passes(env: ManipulatorIDEnv) -> None:
    check_env(gym.make("ManipulatorID-v0", base_parameters=env.base).unwrapped, skip_render_check=True)


def test_stable_baselines3_env_checker_passes(env: ManipulatorIDEnv) -> None:
    sb3_env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3_env_checker.check_env(gym.make("ManipulatorID-v0", base_parameters=env.base).unwrapped, warn=True)


def test_registered_with_a_30_s_window(env: ManipulatorIDEnv) -> None:
    made = gym.make("ManipulatorID-v0", base_parameters=env.base)
    assert made.spec is not None and made.spec.max_episode_steps == 3750
    assert made.unwrapped.control_period_s * made.spec.max_episode_steps == pytest.approx(30.0)
    short = gym.make("ManipulatorID-v0", base_parameters=env.base, max_episode_steps=3)
    short.reset(seed=0)
    assert [short.step(short.action_space.sample())[3] for _ in range(3)] == [False, False, True]


def test_same_seed_same_episode_other_seed_other_robot(env: ManipulatorIDEnv) -> None:
    obs_a, rewards_a = _rollout(env, 7, 30)
    log_a = env.measurement_log()
    obs_b, rewards_b = _rollout(env, 7, 30)
    np.testing.assert_array_equal(obs_a, obs_b)
    assert rewards_a == rewards_b
    np.testing.assert_array_equal(log_a.table(), env.measurement_log().table())
    _, info_7 = env.reset(seed=7)
    _, info_next = env.reset()
    _, info_8 = env.reset(seed=8)
    assert info_next["truth"]["parameters"] == info_7["truth"]["parameters"] and info_next["truth"]["episode"] == 1
    assert info_8["truth"]["parameters"] != info_7["truth"]["parameters"]
    assert len(info_8["truth"]["base_parameters"]) == env.base.rank == 48


def test_reward_is_the_information_gain_of_the_logged_torques(quiet_env: ManipulatorIDEnv) -> None:
    quiet_env.reset(seed=5)
    fisher_reset = quiet_env.fisher_information  # the reset sample's information is part of F as well
    gains = []
    rng = np.random.default_rng(0)
    for _ in range(150):
        *_, info = quiet_env.step(rng.uniform(-1, 1, 6).astype(np.float32))
        gains.append(info["information_gain"])
    fisher = quiet_env.fisher_information
    assert sum(gains) == pytest.approx(0.5 * (log_det(fisher) - log_det(fisher_reset)), rel=1e-9)
    assert sum(gains) > 10.0
    # the same information in one batch from the (noise-free) log: J = Y_b S / sigma, F = I + J^T J
    log = quiet_env.measurement_log()
    rows = quiet_env.base.base_regressor(quiet_env.regressor.regressor(log.q_rad, log.dq_rad_s, log.ddq_rad_s2))
    sigma = ArmSensorModel().torque_std_Nm()
    J = (rows * quiet_env._scale / sigma[None, :, None]).reshape(-1, quiet_env.base.rank)
    np.testing.assert_allclose(fisher, np.eye(quiet_env.base.rank) + J.T @ J, rtol=1e-9, atol=1e-9)
    # the logged effort is the torque model of the true parameters (noise-free sensors)
    p = np.array(quiet_env.truth()["parameters"])
    np.testing.assert_allclose(quiet_env.regressor.torque(log.q_rad, log.dq_rad_s, log.ddq_rad_s2, p), log.effort, atol=1e-9)
    std = quiet_env.cramer_rao_std()
    assert std.shape == (48,) and np.all(std > 0)


def test_observation_is_measured_state_and_commands_are_followed(quiet_env: ManipulatorIDEnv) -> None:
    obs, info = quiet_env.reset(seed=3)
    q0 = quiet_env.simulator.state.q_rad
    assert obs.shape == (18,) and obs.dtype == np.float32
    np.testing.assert_allclose(obs[:6], q0, rtol=1e-6)
    command = np.array([0.2, -0.2, 0.1, -0.1, 0.05, 0.0], dtype=np.float32)
    rates = []
    for _ in range(25):
        obs, *_ = quiet_env.step(command)
        rates.append(quiet_env._dq_ref.copy())
    # rate mode: the reference ramps at the acceleration limit (0.12 rad/s per step) to the commanded rate
    target = command * quiet_env.robot.dq_limit_rad_s
    np.testing.assert_allclose(rates[0], np.clip(target, -0.12, 0.12), rtol=1e-9)
    np.testing.assert_allclose(obs[6:12], target, atol=2e-2)  # tracking error of the nominal-model controller
    np.testing.assert_allclose(obs[:6], quiet_env.simulator.state.q_rad, rtol=1e-6)
    assert set(info["truth"]) == {"parameters", "base_parameters", "episode"}
    accelerating = ManipulatorIDEnv(action_mode="acceleration", sensors="noise_free", base_parameters=quiet_env.base)
    accelerating.reset(seed=3)
    for _ in range(25):
        obs, *_ = accelerating.step(command)
    expected_rate = command * accelerating.robot.ddq_limit_rad_s2 * 25 * accelerating.control_period_s
    np.testing.assert_allclose(obs[6:12], expected_rate, atol=2e-2)


def test_reference_brakes_before_the_joint_limits() -> None:
    narrow = ManipulatorIDEnv(sensors="noise_free", control_period_s=0.02)  # full rate towards the upper limits
    narrow.reset(seed=0)
    q_high = narrow._q_high
    reference_rate, rate = 0.0, 0.0
    for _ in range(200):  # 4 s: 2 pi rad at pi rad/s, then braking
        narrow.step(np.ones(6, dtype=np.float32))
        reference_rate = max(reference_rate, float(np.abs(narrow._dq_ref).max()))
        rate = max(rate, float(np.abs(narrow.simulator.state.dq_rad_s).max()))
    q = narrow.simulator.state.q_rad
    assert np.all(q < narrow.robot.q_upper_rad) and np.all(q > q_high - 0.5)
    assert reference_rate <= np.pi * (1 + 1e-12) and rate <= np.pi * 1.05  # the light wrists overshoot the reference slightly


def test_current_effort_and_measurement_log(env: ManipulatorIDEnv) -> None:
    current = ManipulatorIDEnv(sensors=ArmSensorModel(effort_kind="current_A"), base_parameters=env.base)
    obs, _ = current.reset(seed=1)
    for _ in range(10):
        obs, *_ = current.step(current.action_space.sample())
    log = current.measurement_log()
    assert log.effort_kind == "current_A" and log.n_samples == 11
    assert np.diff(log.t_s) == pytest.approx(0.008)
    np.testing.assert_allclose(obs[12:], log.effort[-1], rtol=1e-6)


@pytest.mark.parametrize(
    ("action", "message"), [([np.nan] + [0.0] * 5, "finite"), ([np.inf] + [0.0] * 5, "finite"), ([0.0] * 3, "shape")]
)
def test_bad_actions_raise(env: ManipulatorIDEnv, action: list[float], message: str) -> None:
    env.reset(seed=0)
    with pytest.raises(ValueError, match=f"action: .*{message}"):
        env.step(np.array(action, dtype=np.float32))


def test_bad_constructor_options_are_named(env: ManipulatorIDEnv) -> None:
    with pytest.raises(ValueError, match="control_period_s"):
        ManipulatorIDEnv(control_period_s=0.0, base_parameters=env.base)
    with pytest.raises(ValueError, match="render_mode"):
        ManipulatorIDEnv(render_mode="human", base_parameters=env.base)
    with pytest.raises(ValueError, match="action_mode"):
        ManipulatorIDEnv(action_mode="torque", base_parameters=env.base)
    with pytest.raises(ValueError, match="sensors"):
        ManipulatorIDEnv(sensors="loud", base_parameters=env.base)
    with pytest.raises(ValueError, match="other parameters"):
        ManipulatorIDEnv(friction=("coulomb",), base_parameters=env.base)
    with pytest.raises(ValueError, match="unknown keys"):
        env.reset(seed=0, options={"fuel": 3})
    with pytest.raises(ValueError, match="parameters must be 72"):
        env.reset(seed=0, options={"parameters": np.zeros(5)})
