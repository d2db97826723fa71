"""The batched identification model against the simulator and pinocchio's centroidal map."""

from __future__ import annotations

import dataclasses

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


def test_a_log_with_other_joint_rates_on_the_same_angles_shares_the_arms_inertia(paper6: Robot) -> None:
    """A log whose joint rates alone differ (the same angle array) gets a model derived from the first log's (its
    composite inertia shared, its momentum recomputed): the same predictions, with a payload too, as one built from
    scratch; a log with other angles is built anew."""
    log = _noise_free_log(paper6, steps=100)
    first = MomentumModel.of(paper6, log)
    rng = np.random.default_rng(3)
    moved = dataclasses.replace(log, dq_rad_s=log.dq_rad_s + rng.normal(0.0, 0.01, log.dq_rad_s.shape))
    derived = MomentumModel.of(paper6, moved)
    assert derived is not first and derived._coupling is first._coupling  # derived, not built again
    scratch = MomentumModel(paper6, moved)
    base10 = paper6.base_full.to_params10()[None]
    payload10 = np.array([[2.0, 0.1, 0.0, 0.05, 0.01, 0.0, 0.01, 0.0, 0.0, 0.01]])
    np.testing.assert_allclose(derived.predict(base10), scratch.predict(base10), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(derived.predict(base10, payload10), scratch.predict(base10, payload10), rtol=1e-12, atol=1e-15)
    assert np.abs(derived.predict(base10) - first.predict(base10)).max() > 1e-4
    other_angles = dataclasses.replace(moved, q_rad=log.q_rad + 0.01)
    assert MomentumModel.of(paper6, other_angles)._coupling is not first._coupling
