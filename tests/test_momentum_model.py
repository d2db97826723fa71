"""The batched identification model against the simulator and pinocchio's centroidal map."""

from __future__ import annotations

import numpy as np

from estimators.models import MomentumModel
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.physics.fuel import base_after_fuel
from spaceid_gym.physics.momentum import base_rate_from_joint_motion
from spaceid_gym.robots import Robot

THETA = np.array([40.0, 0.3, -0.1, 0.2])


def _noise_free_log(robot: Robot, steps: int = 600):
    env = FreeFloatingIDEnv(robot, sensors="noise_free", tank_position_m=THETA[1:])
    env.reset(seed=0, options={"fuel_consumed_kg": THETA[0]})
    rng = np.random.default_rng(1)
    for _ in range(steps):
        env.step(rng.uniform(-1, 1, robot.n_joints).astype(np.float32))
    return env.measurement_log()


def test_true_parameters_reproduce_the_simulated_log(paper6: Robot) -> None:
    log = _noise_free_log(paper6)
    predicted = MomentumModel(paper6, log).predict_fuel(THETA)
    assert np.abs(log.omega_base_body_rad_s).max() > 1e-3
    assert np.abs(predicted - log.omega_base_body_rad_s).max() < 1e-8


def test_batch_matches_pinocchio_for_every_particle(paper6: Robot) -> None:
    log = _noise_free_log(paper6, steps=100)
    model = MomentumModel(paper6, log)
    rng = np.random.default_rng(2)
    thetas = np.column_stack((rng.uniform(0, 130, 5), rng.uniform(-0.4, 0.4, (5, 3))))
    batch = model.predict_fuel(thetas)
    assert batch.shape == (5, log.n_samples, 3)
    for theta, predicted in zip(thetas, batch, strict=True):
        base = base_after_fuel(paper6.base_full, theta[0], theta[1:])
        reference = base_rate_from_joint_motion(paper6.model_with_base(base), log.q_rad, log.dq_rad_s)
        np.testing.assert_allclose(predicted, reference, rtol=1e-9, atol=1e-14)
    sub = model.predict_fuel(thetas, samples=np.arange(10, 20))
    np.testing.assert_array_equal(sub, batch[:, 10:20])
