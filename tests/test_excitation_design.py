"""Excitation design: the one-joint motion, the optimised Fourier series (limits, rest at both ends, D-optimality)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spaceid_gym.datasets import simulate_episode
from spaceid_gym.envs.free_floating import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.fuel_excitation_design import (
    FourierDesign,
    FuelInformation,
    OneJointExcitation,
    load_fourier_excitation,
    optimise_fourier_excitation,
    write_fourier_design,
)
from spaceid_gym.robots import Robot, load_robot

DURATION_S = 20.0


@pytest.fixture(scope="module")
def quick3() -> Robot:
    return load_robot("quick3")


@pytest.fixture(scope="module")
def design(quick3: Robot) -> FourierDesign:
    return optimise_fourier_excitation(
        quick3, DURATION_S, seed=0, n_harmonics=4, n_starts=2, n_grid=60, n_constraint_grid=100, max_iterations=20
    )


def test_fuel_information_matches_the_env_reward(quick3: Robot) -> None:
    """The design's information of a logged trajectory equals what the env accumulated (noise-free, same theta)."""
    env = FreeFloatingIDEnv(quick3, sensors="noise_free", tank_position_m=np.zeros(3))
    information = FuelInformation(quick3)
    env.reset(seed=0, options={"fuel_consumed_kg": float(information.theta0[0])})
    excitation = FourierExcitation(quick3.n_joints, seed=1)
    for k in range(300):
        env.step(excitation(0.02 * k))
    log = env.measurement_log()
    np.testing.assert_allclose(
        information.information(log.q_rad, log.dq_rad_s), env.fisher_information - np.eye(4), rtol=1e-8, atol=1e-8
    )


def test_one_joint_at_a_time_moves_one_joint_and_rests_between_slots() -> None:
    excitation = OneJointExcitation(3, 30.0)
    commands = np.array([excitation(t) for t in np.arange(0.0, 30.0, 0.02)])
    assert ((commands != 0.0).sum(axis=1) <= 1).all()
    assert np.abs(commands).max() == pytest.approx(0.9, rel=1e-3)
    np.testing.assert_allclose(commands.astype(float).sum(axis=0) * 0.02, 0.0, atol=1e-6)  # each joint returns to its start
    assert not excitation(30.5).any() and not excitation(-1.0).any()


def test_optimised_fourier_respects_limits_and_rests_at_both_ends(design: FourierDesign, quick3: Robot) -> None:
    excitation = design.excitation
    assert max(design.peak_ratios.values()) <= 1.0 + 1e-9
    t = np.linspace(0.0, DURATION_S, 4001)
    rates = excitation.rates(t)
    np.testing.assert_allclose(rates[[0, -1]], 0.0, atol=1e-9)
    acceleration = np.gradient(rates, t, axis=0)
    np.testing.assert_allclose(acceleration[[0, -1]], 0.0, atol=2e-3 * np.abs(acceleration).max())
    assert np.abs(rates).max() <= 0.9 + 1e-9
    assert not excitation(DURATION_S + 0.1).any()


def test_optimised_fourier_beats_the_random_multisine_on_d_optimality(design: FourierDesign, quick3: Robot) -> None:
    """In the env, on the same windows: deterministic (seeded optimisation, seeded windows)."""
    tank = np.array([0.1, -0.05, 0.05])
    optimised, random = [], []
    for seed in range(4):
        optimised.append(simulate_episode(quick3, DURATION_S, 10.0, tank, design.excitation, seed).excitation_measures())
        random.append(simulate_episode(quick3, DURATION_S, 10.0, tank, FourierExcitation(3, seed), seed).excitation_measures())
    assert min(m.d_optimality for m in optimised) > max(m.d_optimality for m in random)
    assert design.measures_optimised.d_optimality > design.measures_start.d_optimality


def test_design_file_round_trip_and_bad_files(design: FourierDesign, quick3: Robot, tmp_path: Path) -> None:
    path = write_fourier_design(tmp_path / "traj.json", design, quick3)
    loaded = load_fourier_excitation(path, quick3)
    np.testing.assert_array_equal(loaded.coefficients, design.excitation.coefficients)
    with pytest.raises(SpaceIdInputError, match="optimised for robot 'quick3', not 'paper6'"):
        load_fourier_excitation(path, load_robot("paper6"))
    with pytest.raises(SpaceIdInputError, match="parameterisation 'fuel', not 'base'"):
        load_fourier_excitation(path, quick3, params="base")
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(SpaceIdInputError, match=r"broken\.json: not valid JSON"):
        load_fourier_excitation(broken, quick3)
    doc = json.loads(path.read_text())
    del doc["coefficients"]
    broken.write_text(json.dumps(doc))
    with pytest.raises(SpaceIdInputError, match="missing or malformed"):
        load_fourier_excitation(broken, quick3)
    with pytest.raises(SpaceIdInputError, match="n_starts"):
        optimise_fourier_excitation(quick3, DURATION_S, n_starts=0)
