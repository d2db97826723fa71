"""The variation matrix: every axis drawn from the seed, pinning, the smooth random excitation, the expected power,
the matrix's bookkeeping and its command."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from suite_rows import matrix_row

from estimators.diagnostics import matrix
from estimators.diagnostics.diagnose import candidate_model
from estimators.diagnostics.power import effect_dof, expected_power, non_centrality, power_of, separation, wins_bic
from estimators.least_squares import LevenbergMarquardt
from estimators.models.mass_effects import Slosh
from estimators.problem import IdentificationModel
from spaceid_gym.cli import main
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.effects.draws import DEFAULT_MAGNITUDES, remaining_liquid_kg
from spaceid_gym.effects.settings import HiddenEffects
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation, SmoothRandomExcitation
from spaceid_gym.log import MeasurementLog
from spaceid_gym.robots import Robot, load_robot
from spaceid_gym.sim.sensors import SensorModel
from spaceid_gym.variations import (
    AXES,
    AXIS_RANGES,
    AXIS_VALUES,
    axis_label,
    axis_labels,
    draw_variation,
    parse_fixed,
    simulate_variation,
    truth_of,
)


def test_every_axis_is_drawn_from_the_seed_over_its_whole_range() -> None:
    cases = [draw_variation("slosh", seed) for seed in range(300)]
    assert draw_variation("slosh", 17) == cases[17]
    for axis, values in AXIS_VALUES.items():
        assert {getattr(c, axis) for c in cases} == set(values), axis
    for axis, (low, high) in AXIS_RANGES.items():
        drawn = np.array([getattr(c, axis) for c in cases])
        assert drawn.min() >= low and drawn.max() <= high, axis
        # log-uniform: each end's decade-share of the range is reached
        assert drawn.min() < low * 1.2 and drawn.max() > high / 1.2, axis
    for case in cases:
        liquid = float(remaining_liquid_kg(load_robot(case.robot), case.fuel_consumed_kg))
        assert case.magnitude == pytest.approx(min(case.size_factor * DEFAULT_MAGNITUDES["slosh"] * liquid, liquid))
        assert case.hidden is not None and (case.hidden.slosh_model or "spring") == case.slosh_model


def test_pinning_an_axis_leaves_the_others_as_drawn_and_clean_logs_have_no_size() -> None:
    free = draw_variation("gyro_bias", 5)
    pinned = draw_variation("gyro_bias", 5, {"rate_hz": "100", "attitude": "exact"})
    assert (pinned.rate_hz, pinned.attitude) == (100, "exact")
    for axis in AXES:
        if axis not in ("rate_hz", "attitude"):
            assert getattr(pinned, axis) == getattr(free, axis), axis
    assert pinned.fuel_consumed_kg == free.fuel_consumed_kg
    clean = draw_variation("none", 5)
    assert clean.size_factor is None and clean.magnitude is None and clean.hidden is None
    assert clean.slosh_model is None and clean.slosh_period_s is None
    assert (clean.robot, clean.rate_hz, clean.noise_scale) == (free.robot, free.rate_hz, free.noise_scale)
    assert free.magnitude == pytest.approx(free.size_factor * DEFAULT_MAGNITUDES["gyro_bias"])


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("robot=ur5", "expected one of paper6, quick3, orbit7"),
        ("rate=50", "unknown; expected one of robot"),
        ("noise_scale=10", "expected a number in [0.3, 3]"),
        ("robot", "expected axis=value"),
        ("robot=paper6,robot=quick3", "given twice"),
        (",", "expected axis=value pairs"),
    ],
)
def test_bad_pins_are_refused_naming_the_axis(text: str, needle: str) -> None:
    with pytest.raises(SpaceIdInputError, match=None) as info:
        parse_fixed(text)
    assert needle in str(info.value)


def test_bad_effect_or_seed_is_refused() -> None:
    with pytest.raises(SpaceIdInputError, match="unknown"):
        draw_variation("wobble", 0)
    with pytest.raises(SpaceIdInputError, match="seed"):
        draw_variation("none", -1)


def test_the_tables_columns_cover_every_value() -> None:
    assert axis_labels("noise_scale") == ["0.3-0.65", "0.65-1.4", "1.4-3"]
    assert axis_label("noise_scale", 3.0) == "1.4-3" and axis_label("noise_scale", 0.3) == "0.3-0.65"
    assert axis_label("rate_hz", 50) == "50" and axis_label("slosh_model", None) is None
    case = draw_variation("slosh", 3)
    for axis in AXES:
        assert axis_label(axis, getattr(case, axis)) in axis_labels(axis)


def test_the_smooth_random_command_starts_and_ends_at_rest_and_keeps_the_joints_near_home() -> None:
    duration, dt = 60.0, 0.01
    command = SmoothRandomExcitation(4, seed=3, duration_s=duration)
    t = np.arange(0.0, command.knots_s[-1] + 5.0, dt)
    u = np.array([command(s) for s in t])
    assert command.knots_s[-1] >= duration
    assert np.abs(u).max() == pytest.approx(0.9, abs=1e-3)  # the peak is the amplitude: the peak slope is exact
    np.testing.assert_allclose(u[0], 0.0, atol=1e-6)
    assert np.all(u[t > command.knots_s[-1]] == 0.0)
    # continuous: the largest step between samples shrinks with the sample period (no jump anywhere)
    fine = np.array([command(s) for s in np.arange(0.0, 10.0, dt / 10.0)])
    assert np.max(np.abs(np.diff(fine, axis=0))) < 0.15 * np.max(np.abs(np.diff(u[t < 10.0], axis=0)))
    angle = np.cumsum(u, axis=0) * dt  # the excursion in units of rate limit x s: back home at the end
    np.testing.assert_allclose(angle[-1], 0.0, atol=0.02)
    np.testing.assert_array_equal(u, np.array([SmoothRandomExcitation(4, seed=3, duration_s=duration)(s) for s in t]))
    with pytest.raises(SpaceIdInputError, match="knot_spacing_s"):
        SmoothRandomExcitation(4, seed=3, duration_s=10.0, knot_spacing_s=(0.0, 1.0))


@pytest.mark.parametrize("attitude", ["none", "fused", "star_tracker_20arcsec"])
def test_a_case_simulates_at_its_rate_with_its_sensors(attitude: str) -> None:
    case = draw_variation("none", 2, {"robot": "quick3", "rate_hz": 20, "attitude": attitude, "noise_scale": 2.0})
    env = simulate_variation(case, duration_s=5.0)
    log = env.measurement_log()
    assert np.diff(log.t_s).mean() == pytest.approx(0.05)
    assert (log.quat_base_to_inertial_wxyz is None) == (attitude == "none")
    truth = truth_of(env)
    assert truth["noise"]["gyro_std_rad_s"] == pytest.approx(2.0 * SensorModel().gyro_std_rad_s(0.05))
    assert truth["fuel_consumed_kg"] == pytest.approx(case.fuel_consumed_kg)


def test_the_expected_power_rises_with_the_effect_and_is_alpha_without_it() -> None:
    assert power_of(0.0, 3, alpha=0.01, n_candidates=10) == pytest.approx(0.001)
    assert power_of(200.0, 3) > 0.999
    fixed = {"robot": "quick3", "rate_hz": 20, "attitude": "none", "excitation": "diagnostic"}
    powers = []
    for size in (0.3, 3.0):
        case = draw_variation("gyro_bias", 4, {**fixed, "size_factor": size})
        env = simulate_variation(case, duration_s=20.0)
        model = IdentificationModel(env.robot, "fuel")
        powers.append(expected_power(model, "gyro_bias", env.measurement_log(), truth_of(env)))
    assert powers[0] < powers[1] and powers[1] > 0.99


def _noise_free_log(
    robot: Robot, fuel: np.ndarray, hidden: HiddenEffects, seed: int, sigma: float
) -> tuple[MeasurementLog, dict[str, Any]]:
    """A noise-free 20 s log of ``robot`` (fuel ``[mdf kg, tank m]``, ``hidden`` effects, a Fourier excitation of
    ``seed``) without attitude, and its truth as truth.json gives it, the gyro's noise declared ``sigma`` rad/s."""
    excitation = FourierExcitation(robot.n_joints, seed=seed, base_frequency_hz=0.05, n_harmonics=10)
    env = simulate_episode(
        robot, 20.0, fuel[0], fuel[1:], excitation, seed=seed, sensors=SensorModel.noise_free(), hidden_effects=hidden
    )
    log = dataclasses.replace(env.measurement_log(), quat_base_to_inertial_wxyz=None)
    truth = {
        "fuel_consumed_kg": fuel[0],
        "tank_position_m": tuple(fuel[1:]),
        "hidden_effects": hidden.to_dict(),
        "noise": {"gyro_std_rad_s": sigma},
    }
    return log, truth


def test_the_expected_power_of_a_pendulum_slosh_is_that_of_the_pendulum() -> None:
    """On a noise-free log of a 2 kg pendulum slosh (0.2 m rod, tilted), the non-centrality is the chi-square left by
    the best fit without the effect (at a gyro std of 1e-5 rad/s; small enough an effect for the local approximation):
    the pendulum's term gives it to 5 %. Before, the pendulum's power was that of a spring-mass of the same size, 10
    times too large here (the spring's mass moves along the rod too)."""
    paper6 = load_robot("paper6")
    fuel = np.array([40.0, 0.2, -0.1, 0.1])  # mdf kg, tank m
    rod = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    hidden = HiddenEffects(
        slosh_mass_kg=2.0,
        slosh_frequency_hz=0.3,
        slosh_damping_ratio=0.05,
        slosh_model="pendulum",
        slosh_length_m=0.2,
        slosh_axis=tuple(rod),
    )
    sigma = 1e-5
    log, truth = _noise_free_log(paper6, fuel, hidden, seed=1, sigma=sigma)
    model = IdentificationModel(paper6, "fuel")
    problem = model.problem(log)
    residual = problem.residuals(LevenbergMarquardt(max_iterations=100).polish(problem, fuel).theta, count=False)
    exact = float(residual @ residual) / sigma**2
    assert exact > 10.0  # an effect the test can see
    assert non_centrality(model, "slosh", log, truth) == pytest.approx(exact, rel=0.05)
    spring = {**truth, "hidden_effects": {k: v for k, v in truth["hidden_effects"].items() if k in Slosh.names}}
    assert non_centrality(model, "slosh", log, spring) > 3.0 * exact
    assert effect_dof(model, "slosh", truth) == 6 and effect_dof(model, "slosh", spring) == 3


def test_the_separation_from_a_rival_is_what_the_rivals_best_fit_leaves() -> None:
    """On a noise-free log of a gyro bias without attitude, the non-centrality against ``initial_momentum`` is the
    chi-square the best fit of the fuel and a momentum (instead of the bias) leaves, to 5 %; against
    ``external_torque`` likewise. Equal unknowns and nothing to tell them apart: the effect wins half the time."""
    paper6 = load_robot("paper6")
    fuel = np.array([40.0, 0.2, -0.1, 0.1])  # mdf kg, tank m
    hidden = HiddenEffects(gyro_bias_rad_s=(2e-5, -1e-5, 1.5e-5))
    sigma = 2e-6
    log, truth = _noise_free_log(paper6, fuel, hidden, seed=2, sigma=sigma)
    model = IdentificationModel(paper6, "fuel")
    rivals = ("initial_momentum", "external_torque")
    found = separation(model, "gyro_bias", log, truth, rivals=rivals)
    for rival in rivals:
        problem = candidate_model(model, rival).problem(log)
        start = np.concatenate((fuel, problem.parameters.terms[-1].nominal))
        residual = problem.residuals(LevenbergMarquardt(max_iterations=100).polish(problem, start).theta, count=False)
        exact = float(residual @ residual) / sigma**2
        assert exact > 5.0  # the rival cannot absorb the bias
        assert found[rival].non_centrality == pytest.approx(exact, rel=0.05)
    assert wins_bic(0.0, 3, 3, 3000) == pytest.approx(0.5, abs=1e-3)
    draws = np.random.default_rng(0)  # a Monte Carlo reference: a 4-unknown effect against a 3-unknown rival
    x, y = draws.noncentral_chisquare(4, 6.0, 200_000), draws.chisquare(3, 200_000)
    assert wins_bic(6.0, 4, 3, 3000) == pytest.approx(np.mean(x - y > np.log(3000)), abs=0.004)


def test_the_matrix_counts_eligible_logs_writes_every_row_and_fails_on_an_error(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(matrix, "guarded_variation", matrix_row)
    code = main(
        ["diagnose-suite", "--matrix", "--seeds", "4", "--effects", "gyro_bias", "--fix", "robot=paper6", "--out", str(tmp_path)]
    )
    assert code == 1
    assert "gyro_bias log of seed 3 raised ValueError: broken" in capsys.readouterr().err
    with (tmp_path / "matrix.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["seed"] for r in rows] == ["0", "1", "2", "3"] and {r["robot"] for r in rows} == {"paper6"}
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["info"]["fixed"] == {"robot": "paper6"}
    overall = next(s for s in summary["summary"] if s["axis"] == "all")
    # seeds 0 and 2 are eligible (power 0.95); seed 2's verdict is wrong
    assert (overall["logs"], overall["eligible"], overall["correct"]) == (4, 2, 1)
    assert overall["fuel_z_rms_after"] == pytest.approx(1.0)
    assert (overall["fuel_z_values_after"], overall["fuel_z_logs_after"]) == (4, 1)  # the right verdict's four z
    assert "| gyro_bias | 4 | 2 | 1/2 (50 %)" in (tmp_path / "matrix.md").read_text()


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--fix", "robot=paper6"], "--fix: pins axes of the variation matrix; give --matrix too"),
        (["--matrix", "--robot", "paper6"], "not with --matrix"),
        (["--matrix", "--fix", "excitation=chirp"], "--fix: variation axis 'excitation'"),
        (["--matrix", "--duration", "-1"], "--duration"),
    ],
)
def test_bad_matrix_options_exit_2_naming_the_option(
    argv: list[str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["diagnose-suite", *argv, "--out", str(tmp_path)]) == 2
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "matrix.csv").exists()
