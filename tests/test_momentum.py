"""The momentum map and its analytic parameter sensitivity, against pinocchio and finite differences."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from spaceid_gym.physics.fuel import base_after_fuel, base_params10_fuel_jacobian
from spaceid_gym.physics.momentum import (
    base_parameter_directions,
    momentum_world_to_base,
    twist_parameter_jacobian,
)
from spaceid_gym.robots import Robot
from spaceid_gym.sim.simulator import FreeFloatingSimulator


def test_momentum_frame_change_matches_pinocchio_action() -> None:
    rng = np.random.default_rng(1)
    placement = pin.SE3.Random()
    h_world = rng.normal(size=6)
    h_base = momentum_world_to_base(h_world, placement.rotation, placement.translation)
    expected = placement.actInv(pin.Force(h_world[:3], h_world[3:]))
    np.testing.assert_allclose(h_base, np.concatenate((expected.linear, expected.angular)), atol=1e-12)


def test_base_rate_sensitivity_to_fuel_matches_finite_differences(paper6: Robot) -> None:
    theta = np.array([45.0, 0.3, -0.2, 0.25])
    q = np.array([0.3, -0.4, 0.9, 0.2, -0.5, 0.7])
    dq = np.array([0.05, -0.08, 0.1, 0.12, -0.1, 0.15])

    def twist(th: np.ndarray) -> np.ndarray:
        sim = FreeFloatingSimulator(paper6, base_after_fuel(paper6.base_full, th[0], th[1:]))
        return sim.base_twist(q, dq, np.eye(3))

    sim = FreeFloatingSimulator(paper6, base_after_fuel(paper6.base_full, theta[0], theta[1:]))
    sim.reset(q0_rad=q)
    v = twist(theta)
    sim._q_full[7:] = q
    pin.crba(sim.model, sim.data, sim._q_full)
    directions = base_parameter_directions(base_params10_fuel_jacobian(paper6.base_full.com_m, theta))
    jac = twist_parameter_jacobian(sim.data.Ycrb[1].inverse(), v, directions)
    for k, step in enumerate([1e-3, 1e-5, 1e-5, 1e-5]):
        e = np.zeros(4)
        e[k] = step
        fd = (twist(theta + e) - twist(theta - e)) / (2 * step)
        np.testing.assert_allclose(jac[:, k], fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())
