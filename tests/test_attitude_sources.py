"""Attitude sources (star tracker, exact, fused on-board filter, none) and the noise scale of the sensor model."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.cli import main
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog, load_dataset
from spaceid_gym.robots import Robot
from spaceid_gym.sim.attitude_filter import filter_gain, filter_time_constant_s, steady_state_error_std_rad
from spaceid_gym.sim.lie import matrix_from_quat, quat_from_matrix
from spaceid_gym.sim.sensors import ARCSEC_RAD, ATTITUDE_SOURCES, Measurement, SensorModel
from spaceid_gym.sim.simulator import FreeFloatingSimulator
from spaceid_gym.sim.state import FreeFloatingState

DT_S = 0.02


def _attitude_error_body_rad(states: list[FreeFloatingState], samples: list[Measurement]) -> np.ndarray:
    """Measured attitude relative to the true one, as a rotation vector in the base body frame, (T, 3), rad."""
    return np.array(
        [pin.log3(s.rot_wb.T @ matrix_from_quat(m.quat_base_to_inertial_wxyz)) for s, m in zip(states, samples, strict=True)]
    )


def _lag1_autocorrelation(x: np.ndarray) -> np.ndarray:
    """Lag-1 autocorrelation of each column of ``x`` (T, k)."""
    x = x - x.mean(axis=0)
    return np.sum(x[1:] * x[:-1], axis=0) / np.sum(x * x, axis=0)


def _trajectory(
    robot: Robot, duration_s: float, seed: int, momentum_world: np.ndarray | None = None, arm_moving: bool = True
) -> list[FreeFloatingState]:
    """States every DT_S under random joint-rate commands held 1 s each (the base rotates in reaction), or with the arm still."""
    rng = np.random.default_rng(seed)
    sim = FreeFloatingSimulator(robot, robot.base_full)
    states = [sim.reset(momentum_world=momentum_world)]
    steps = round(duration_s / DT_S)
    levels = rng.uniform(-1.0, 1.0, size=(steps // 50 + 1, robot.n_joints)) * robot.rate_limit_rad_s * arm_moving
    states += [sim.step(levels[k // 50], DT_S) for k in range(steps)]
    return states


def _measure(sensors: SensorModel, states: list[FreeFloatingState], seed: int) -> list[Measurement]:
    """One sampler (one window) measuring ``states`` in order, noise from a generator seeded with ``seed``."""
    sample = sensors.sampler(states[0].q_rad.shape[0], DT_S)
    rng = np.random.default_rng(seed)
    return [sample(state, rng) for state in states]


@pytest.fixture(scope="module")
def trajectory_60s(paper6: Robot) -> list[FreeFloatingState]:
    """60 s of paper6 (3001 states) with the arm moving and the base reacting."""
    return _trajectory(paper6, 60.0, seed=11)


# ------------------------------------------------------------------------------------------ exact
def test_exact_source_is_the_true_attitude_and_leaves_the_other_noise_unchanged(trajectory_60s: list[FreeFloatingState]) -> None:
    states = trajectory_60s[::10]
    exact = _measure(SensorModel(attitude_source="exact"), states, seed=3)
    for state, m in zip(states, exact, strict=True):
        assert m.quat_base_to_inertial_wxyz is not None
        np.testing.assert_array_equal(m.quat_base_to_inertial_wxyz, quat_from_matrix(state.rot_wb))
    # the same seed draws the same gyro, encoder and joint-rate noise whatever the attitude source
    default = _measure(SensorModel(), states, seed=3)
    for a, b in zip(exact, default, strict=True):
        np.testing.assert_array_equal(a.omega_base_body_rad_s, b.omega_base_body_rad_s)
        np.testing.assert_array_equal(a.q_rad, b.q_rad)
        np.testing.assert_array_equal(a.dq_rad_s, b.dq_rad_s)
    assert np.any(
        [
            not np.array_equal(a.quat_base_to_inertial_wxyz, b.quat_base_to_inertial_wxyz)
            for a, b in zip(exact, default, strict=True)
        ]
    )


# ----------------------------------------------------------------------------------- star tracker
@pytest.mark.parametrize("arcsec", [1.0, 5.0, 20.0])
def test_star_tracker_has_the_configured_std_per_axis(paper6: Robot, arcsec: float) -> None:
    """N = 20000 samples: a sample std's relative standard error is 1/sqrt(2 N) = 0.5 %; 5 of them is the tolerance."""
    state = _trajectory(paper6, 1.0, seed=2)[-1]
    state.rot_wb = pin.exp3(np.array([0.4, -0.3, 1.1]))  # any attitude: the noise is a rotation in the body frame
    sensors = SensorModel(attitude_noise_rad=arcsec * ARCSEC_RAD)
    n = 20000
    errors = _attitude_error_body_rad([state] * n, _measure(sensors, [state] * n, seed=4))
    np.testing.assert_allclose(errors.mean(axis=0), 0.0, atol=5.0 * arcsec * ARCSEC_RAD / np.sqrt(n))
    np.testing.assert_allclose(errors.std(axis=0), arcsec * ARCSEC_RAD, rtol=5.0 / np.sqrt(2 * n))
    assert sensors.star_tracker_std_rad() == pytest.approx(arcsec * np.pi / 180 / 3600)
    assert np.all(np.abs(_lag1_autocorrelation(errors)) < 5.0 / np.sqrt(n))  # white


# ------------------------------------------------------------------------------------------ fused
def test_fused_error_is_smaller_than_the_star_trackers_correlated_and_bounded_over_60_s(
    trajectory_60s: list[FreeFloatingState],
) -> None:
    sensors = SensorModel(attitude_source="fused")
    error = _attitude_error_body_rad(trajectory_60s, _measure(sensors, trajectory_60s, seed=5))
    raw = _attitude_error_body_rad(trajectory_60s, _measure(SensorModel(), trajectory_60s, seed=5))
    star_tracker_std = sensors.star_tracker_std_rad()
    predicted = steady_state_error_std_rad(
        sensors.attitude_filter_gain(DT_S), DT_S, sensors.gyro_arw_rad_sqrt_s, star_tracker_std
    )
    steady = error[50:]  # after 1 s: the filter starts at the star tracker's first sample and settles in 0.2 s
    std = steady.std(axis=0)
    # (i) smaller than the raw star tracker's per-axis std, about as predicted (a third of it)
    assert np.all(std < 0.5 * star_tracker_std), (std, star_tracker_std)
    np.testing.assert_allclose(raw[50:].std(axis=0), star_tracker_std, rtol=0.1)
    np.testing.assert_allclose(std, predicted, rtol=0.25)
    # (ii) correlated in time: lag-1 autocorrelation near 1 - K = 0.89 (the raw star tracker's is near 0)
    assert np.all(_lag1_autocorrelation(steady) > 0.8), _lag1_autocorrelation(steady)
    assert np.all(np.abs(_lag1_autocorrelation(raw)) < 0.1)
    # bounded: no drift from the first 20 s to the last 20 s, no excursion beyond 6 predicted stds
    np.testing.assert_allclose(steady[-1000:].std(axis=0), steady[:1000].std(axis=0), rtol=0.5)
    assert np.abs(steady).max() < 6.0 * predicted
    assert np.abs(error).max() < 5.0 * star_tracker_std  # the first second included


def test_fused_filter_propagates_with_the_body_rate_of_a_tumbling_base(paper6: Robot) -> None:
    """Exact gyro, nearly no correction (time constant 1e7 s): the first sample's error keeps its size over 60 s of tumbling.

    The arm is still, so the body rate changes smoothly (torque-free tumbling of an asymmetric body) and
    the trapezoid rule integrates it to 1e-9 rad; integrating it in the wrong frame or with the wrong
    sign would grow the error by the order of the rotation (more than 1 rad).
    """
    states = _trajectory(paper6, 60.0, seed=6, momentum_world=np.array([0.0, 0.0, 0.0, 4.0, -6.0, 5.0]), arm_moving=False)
    assert np.linalg.norm(pin.log3(states[0].rot_wb.T @ states[-1].rot_wb)) > 1.0
    omega = np.array([s.omega_base_body for s in states])
    assert np.linalg.norm(omega[-1] - omega[0]) > 1e-3  # the rate turns in the body frame
    sensors = SensorModel(gyro_arw_rad_sqrt_s=0.0, attitude_source="fused", attitude_filter_time_constant_s=1e7)
    angle = np.linalg.norm(_attitude_error_body_rad(states, _measure(sensors, states, seed=7)), axis=1)
    assert angle[0] > 1e-5  # the star tracker's first sample
    np.testing.assert_allclose(angle, angle[0], rtol=1e-3)


def test_fused_filter_gain_and_its_truth_entries() -> None:
    sensors = SensorModel(attitude_source="fused")
    gain = sensors.attitude_filter_gain(DT_S)
    assert 0.10 < gain < 0.12 and filter_time_constant_s(gain, DT_S) == pytest.approx(0.168, abs=1e-3)
    noise = sensors.as_dict(DT_S)
    assert noise["attitude_source"] == "fused" and noise["attitude_filter_gain"] == gain
    assert noise["attitude_filter_error_std_rad"] == pytest.approx(8.11e-6, rel=1e-3)
    slow = SensorModel(attitude_source="fused", attitude_filter_time_constant_s=10.0)
    assert slow.attitude_filter_gain(DT_S) == pytest.approx(1.0 - np.exp(-DT_S / 10.0))
    assert slow.as_dict(DT_S)["attitude_filter_time_constant_s"] == pytest.approx(10.0)
    assert filter_gain(DT_S, 1e-5, 0.0) == 1.0 and filter_gain(DT_S, 0.0, 1e-5) == 0.0
    assert "attitude_filter_gain" not in SensorModel().as_dict(DT_S)
    # an exact gyro never corrects by default (time constant None in truth.json); exact sensors give the truth
    assert SensorModel(gyro_arw_rad_sqrt_s=0.0, attitude_source="fused").as_dict(DT_S)["attitude_filter_time_constant_s"] is None
    exact = dataclasses.replace(SensorModel.noise_free(), attitude_source="fused")
    assert exact.attitude_filter_gain(DT_S) == 1.0


# ------------------------------------------------------------------------------------------- none
def test_none_source_writes_a_log_without_quaternion_columns(tmp_path: Path, quick3: Robot) -> None:
    out = tmp_path / "none"
    assert main(["simulate", "--robot", "quick3", "--duration", "1", "--seed", "2", "--attitude", "none", "--out", str(out)]) == 0
    header = (out / "log.csv").read_text().splitlines()[0]
    assert header == "t,q1,q2,q3,dq1,dq2,dq3,wx,wy,wz"
    assert MeasurementLog.from_csv(out / "log.csv", n_joints=3).quat_base_to_inertial_wxyz is None
    dataset = load_dataset(out, n_joints=3)
    assert dataset.log.quat_base_to_inertial_wxyz is None and dataset.log.n_samples == 51
    noise = json.loads((out / "truth.json").read_text())["noise"]
    assert noise["attitude_source"] == "none" and "star_tracker_std_rad" not in noise
    # the env: no attitude in the log, zeros in the observation's quaternion slots
    env = FreeFloatingIDEnv(quick3, sensors=SensorModel(attitude_source="none"))
    observation, _ = env.reset(seed=1)
    observation, *_ = env.step(np.ones(3, dtype=np.float32))
    np.testing.assert_array_equal(observation[-4:], 0.0)
    assert env.measurement_log().quat_base_to_inertial_wxyz is None


# ------------------------------------------------------------------------------------ noise scale
@pytest.mark.parametrize("factor", [0.3, 3.0])
def test_noise_scale_multiplies_every_noise_std(trajectory_60s: list[FreeFloatingState], factor: float) -> None:
    """Same seed: every noise sample is ``factor`` times the default one (gyro, encoders, joint rates, star tracker)."""
    states = trajectory_60s[::6]
    scaled = SensorModel(noise_scale=factor)
    default, measured = _measure(SensorModel(), states, seed=8), _measure(scaled, states, seed=8)
    for field in ("q_rad", "dq_rad_s"):
        truth = np.array([getattr(s, field) for s in states])
        noise_default = np.array([getattr(m, field) for m in default]) - truth
        np.testing.assert_allclose(
            np.array([getattr(m, field) for m in measured]) - truth, factor * noise_default, rtol=1e-6, atol=1e-15
        )
    omega = np.array([s.omega_base_body for s in states])
    gyro_default = np.array([m.omega_base_body_rad_s for m in default]) - omega
    np.testing.assert_allclose(
        np.array([m.omega_base_body_rad_s for m in measured]) - omega, factor * gyro_default, rtol=1e-6, atol=1e-15
    )
    np.testing.assert_allclose(
        _attitude_error_body_rad(states, measured), factor * _attitude_error_body_rad(states, default), rtol=1e-6, atol=1e-14
    )
    # the documented stds and the truth.json entries follow
    base, noise = SensorModel(), scaled.as_dict(DT_S)
    assert noise["noise_scale"] == factor
    assert noise["gyro_std_rad_s"] == pytest.approx(factor * base.gyro_std_rad_s(DT_S))
    assert noise["joint_angle_std_rad"] == pytest.approx(factor * base.joint_angle_noise_rad)
    assert noise["joint_rate_std_rad_s"] == pytest.approx(factor * base.joint_rate_std_rad_s(DT_S))
    assert noise["star_tracker_std_rad"] == pytest.approx(factor * base.attitude_noise_rad)
    assert noise["gyro_arw_rad_sqrt_s"] == base.gyro_arw_rad_sqrt_s  # the configured values stay as configured


def test_noise_scale_leaves_a_gyro_bias_alone(trajectory_60s: list[FreeFloatingState]) -> None:
    """Same seed, with a bias: ``measured - truth - bias`` scales with the factor, the bias does not."""
    states = trajectory_60s[::30]
    bias = (1e-4, -2e-4, 3e-4)
    omega = np.array([s.omega_base_body for s in states])

    def gyro_noise(factor: float) -> np.ndarray:
        measured = _measure(SensorModel(gyro_bias_rad_s=bias, noise_scale=factor), states, seed=1)
        return np.array([m.omega_base_body_rad_s for m in measured]) - omega - np.array(bias)

    np.testing.assert_allclose(gyro_noise(3.0), 3.0 * gyro_noise(1.0), rtol=1e-6, atol=1e-15)


# ------------------------------------------------------------------------------ CLI and determinism
def test_same_seed_same_log_for_every_option(tmp_path: Path) -> None:
    args = ["simulate", "--robot", "quick3", "--duration", "2", "--attitude", "fused", "--star-tracker-arcsec", "20"]
    args += ["--noise-scale", "2.5"]
    assert main([*args, "--seed", "4", "--out", str(tmp_path / "a")]) == 0
    assert main([*args, "--seed", "4", "--out", str(tmp_path / "b")]) == 0
    assert main([*args, "--seed", "5", "--out", str(tmp_path / "c")]) == 0
    log_a = (tmp_path / "a" / "log.csv").read_text()
    assert log_a == (tmp_path / "b" / "log.csv").read_text()
    assert log_a != (tmp_path / "c" / "log.csv").read_text()
    noise = json.loads((tmp_path / "a" / "truth.json").read_text())["noise"]
    assert noise["attitude_source"] == "fused" and noise["noise_scale"] == 2.5
    assert noise["star_tracker_std_rad"] == pytest.approx(2.5 * 20 * ARCSEC_RAD)
    assert noise["attitude_noise_rad"] == pytest.approx(20 * ARCSEC_RAD)


def test_default_options_write_the_default_sensors(tmp_path: Path) -> None:
    """No sensor option: the log is the one of ``SensorModel()`` with star tracker 5 arcsec (unchanged defaults)."""
    explicit = ["--attitude", "star_tracker", "--star-tracker-arcsec", "5", "--noise-scale", "1"]
    base = ["simulate", "--robot", "quick3", "--duration", "1", "--seed", "9"]
    assert main([*base, "--out", str(tmp_path / "default")]) == 0
    assert main([*base, *explicit, "--out", str(tmp_path / "explicit")]) == 0
    assert (tmp_path / "default" / "log.csv").read_text() == (tmp_path / "explicit" / "log.csv").read_text()
    noise = json.loads((tmp_path / "default" / "truth.json").read_text())["noise"]
    assert noise["attitude_source"] == "star_tracker" and noise["noise_scale"] == 1.0
    assert SensorModel().as_dict(DT_S) == noise


def test_help_documents_the_sensor_options(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["simulate", "--help"])
    assert exit_info.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for option in ("--attitude {none,star_tracker,exact,fused}", "--star-tracker-arcsec ARCSEC", "--noise-scale FACTOR"):
        assert option in text
    assert "--attitude-time-constant SECONDS" in text and "(default 5" in text and "(default 1" in text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--noise-scale", "-1"], "--noise-scale: expected a finite factor > 0, got -1.0"),
        (["--noise-scale", "0"], "--noise-scale"),
        (["--noise-scale", "nan"], "--noise-scale"),
        (["--star-tracker-arcsec", "-5"], "--star-tracker-arcsec: expected a finite number of arcseconds >= 0"),
        (["--star-tracker-arcsec", "inf"], "--star-tracker-arcsec"),
        (["--attitude-time-constant", "0"], "--attitude-time-constant"),
    ],
)
def test_bad_sensor_values_exit_non_zero_naming_the_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    code = main(["simulate", "--robot", "quick3", "--duration", "1", *args, "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("spaceid: error: ") and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--attitude", "gps"], "argument --attitude: invalid choice: 'gps'"),
        (["--noise-scale", "big"], "argument --noise-scale: invalid float value"),
    ],
)
def test_unknown_attitude_source_or_non_number_is_a_usage_error(
    capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["simulate", "--out", "unused", *args])
    assert exit_info.value.code == 2 and message in capsys.readouterr().err


def test_bad_sensor_value_from_the_command_line_has_no_traceback(tmp_path: Path) -> None:
    command = [sys.executable, "-m", "spaceid_gym.cli", "simulate", "--robot", "quick3", "--noise-scale", "-0.5"]
    result = subprocess.run([*command, "--out", str(tmp_path / "x")], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip() == "spaceid: error: --noise-scale: expected a finite factor > 0, got -0.5"


def test_sensor_model_names_its_bad_settings() -> None:
    assert ATTITUDE_SOURCES == ("none", "star_tracker", "exact", "fused")
    with pytest.raises(SpaceIdInputError, match=r"attitude_source.*star_tracker"):
        SensorModel(attitude_source="gps")
    for bad in (-1.0, 0.0, float("inf")):
        with pytest.raises(SpaceIdInputError, match="noise_scale"):
            SensorModel(noise_scale=bad)
    with pytest.raises(SpaceIdInputError, match="attitude_filter_time_constant_s"):
        SensorModel(attitude_source="fused", attitude_filter_time_constant_s=-2.0)
