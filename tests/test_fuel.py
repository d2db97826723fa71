"""Fuel model (paper eqs. 10-12, corrected) against pinocchio's rigid-body inertia arithmetic."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.fuel import (
    base_after_fuel,
    base_params10_after_fuel,
    base_params10_fuel_jacobian,
)
from spaceid_gym.physics.inertia import RigidBodyInertia, spatial_inertia_matrix
from spaceid_gym.robots import Robot


def _pin(body: RigidBodyInertia) -> pin.Inertia:
    return pin.Inertia(body.mass_kg, np.asarray(body.com_m), np.asarray(body.inertia_com_kgm2))


@pytest.mark.parametrize("seed", range(5))
def test_remaining_base_plus_fuel_point_mass_is_the_full_base(paper6: Robot, seed: int) -> None:
    rng = np.random.default_rng(seed)
    full = paper6.base_full
    mdf = rng.uniform(1.0, 140.0)
    bf = rng.uniform(-0.4, 0.4, size=3)
    remaining = base_after_fuel(full, mdf, bf)
    fuel = pin.Inertia(mdf, np.asarray(full.com_m) + bf, np.zeros((3, 3)))
    recomposed = _pin(remaining) + fuel
    assert recomposed.mass == pytest.approx(full.mass_kg, abs=1e-12)
    np.testing.assert_allclose(recomposed.lever, full.com_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(recomposed.inertia, full.inertia_com_kgm2, rtol=0, atol=1e-12 * 400)


def test_com_moves_away_from_the_tank(paper6: Robot) -> None:
    """Eq. 11 corrected: removing fuel at +x moves the CoM towards -x."""
    full = paper6.base_full
    remaining = base_after_fuel(full, 50.0, np.array([0.3, 0.0, 0.0]))
    expected = np.asarray(full.com_m) - 50.0 / 500.0 * np.array([0.3, 0.0, 0.0])
    np.testing.assert_allclose(remaining.com_m, expected, atol=1e-15)


def test_params10_form_matches_closed_form_and_pinocchio(paper6: Robot) -> None:
    full = paper6.base_full
    theta = np.array([37.0, 0.2, -0.15, 0.33])
    remaining = base_after_fuel(full, theta[0], theta[1:])
    params = base_params10_after_fuel(full.to_params10(), full.com_m, theta)
    np.testing.assert_allclose(params, remaining.to_params10(), rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(params, _pin(remaining).toDynamicParameters(), rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(spatial_inertia_matrix(params), _pin(remaining).matrix(), rtol=1e-13, atol=1e-10)
    back = RigidBodyInertia.from_params10(params)
    np.testing.assert_allclose(back.inertia_com_kgm2, remaining.inertia_com_kgm2, atol=1e-10)


def test_fuel_jacobian_matches_central_differences(paper6: Robot) -> None:
    full = paper6.base_full
    theta = np.array([60.0, 0.25, -0.3, 0.1])
    jac = base_params10_fuel_jacobian(full.com_m, theta)
    steps = np.array([1e-3, 1e-6, 1e-6, 1e-6])
    for k in range(4):
        e = np.zeros(4)
        e[k] = steps[k]
        fd = (
            base_params10_after_fuel(full.to_params10(), full.com_m, theta + e)
            - base_params10_after_fuel(full.to_params10(), full.com_m, theta - e)
        ) / (2 * steps[k])
        np.testing.assert_allclose(jac[:, k], fd, rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize(
    ("mdf", "bf", "message"),
    [
        (550.0, [0.1, 0.0, 0.0], "not below the full-tank base mass"),
        (600.0, [0.1, 0.0, 0.0], "not below the full-tank base mass"),
        (-1.0, [0.1, 0.0, 0.0], "fuel_consumed_kg"),
        (float("nan"), [0.1, 0.0, 0.0], "fuel_consumed_kg"),
        (10.0, [0.1, float("inf"), 0.0], "tank_position_m"),
        (10.0, [0.1, 0.0], "tank_position_m"),
        (500.0, [3.0, 3.0, 3.0], "not positive definite|triangle"),
    ],
)
def test_bad_fuel_parameters_are_named(paper6: Robot, mdf: float, bf: list[float], message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message):
        base_after_fuel(paper6.base_full, mdf, np.array(bf))
