"""Sensor noise: per-sample statistics and bias as documented, from the seeded generator."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.robots import Robot
from spaceid_gym.sim.lie import matrix_from_quat
from spaceid_gym.sim.sensors import SensorModel
from spaceid_gym.sim.simulator import FreeFloatingSimulator


def test_noise_statistics_and_bias(quick3: Robot) -> None:
    sim = FreeFloatingSimulator(quick3, quick3.base_full)
    state = sim.step(quick3.rate_limit_rad_s, 0.5)
    state.rot_wb = pin.exp3(np.array([0.3, 0.2, -0.5]))
    sensors = SensorModel(gyro_bias_rad_s=(1e-4, -2e-4, 3e-4))
    sample = sensors.sampler(3, 0.02)
    rng = np.random.default_rng(0)
    samples = [sample(state, rng) for _ in range(20000)]
    gyro = np.array([m.omega_base_body_rad_s for m in samples]) - state.omega_base_body
    np.testing.assert_allclose(gyro.mean(axis=0), sensors.gyro_bias_rad_s, atol=5 * sensors.gyro_std_rad_s(0.02) / np.sqrt(20000))
    np.testing.assert_allclose(gyro.std(axis=0), sensors.gyro_std_rad_s(0.02), rtol=0.03)
    assert sensors.gyro_std_rad_s(0.02) == pytest.approx(0.07 * np.pi / 180 / 60 / np.sqrt(0.02))
    q_err = np.array([m.q_rad for m in samples]) - state.q_rad
    np.testing.assert_allclose(q_err.std(axis=0), sensors.joint_angle_noise_rad, rtol=0.03)
    dq_err = np.array([m.dq_rad_s for m in samples]) - state.dq_rad_s
    np.testing.assert_allclose(dq_err.std(axis=0), sensors.joint_rate_std_rad_s(0.02), rtol=0.03)
    # star tracker: a small rotation in the body frame, std per axis as documented
    body_errors = np.array([pin.log3(state.rot_wb.T @ matrix_from_quat(m.quat_base_to_inertial_wxyz)) for m in samples])
    np.testing.assert_allclose(body_errors.std(axis=0), sensors.attitude_noise_rad, rtol=0.03)


def test_noise_free_is_exact_and_same_seed_same_noise(quick3: Robot) -> None:
    state = FreeFloatingSimulator(quick3, quick3.base_full).step(quick3.rate_limit_rad_s, 0.5)
    exact = SensorModel.noise_free().sampler(3, 0.02)(state, np.random.default_rng(0))
    np.testing.assert_array_equal(exact.omega_base_body_rad_s, state.omega_base_body)
    np.testing.assert_array_equal(exact.q_rad, state.q_rad)
    noisy = SensorModel().sampler(3, 0.02)
    a, b = noisy(state, np.random.default_rng(4)), noisy(state, np.random.default_rng(4))
    np.testing.assert_array_equal(a.omega_base_body_rad_s, b.omega_base_body_rad_s)


def test_bad_noise_settings_are_named() -> None:
    with pytest.raises(ValueError, match="joint_angle_noise_rad"):
        SensorModel(joint_angle_noise_rad=-1.0)
    with pytest.raises(ValueError, match="gyro_bias_rad_s"):
        SensorModel(gyro_bias_rad_s=(0.0, float("nan"), 0.0))
