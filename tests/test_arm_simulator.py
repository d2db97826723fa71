"""The arm simulator: consistency with inverse dynamics, energy, tracking, sensors, the parameter prior, datasets.

Independent references: pinocchio's RNEA, kinetic and potential energy on a model built here from
the parameter vector; the friction formulas written out; finite differences of the logged rates;
Monte-Carlo statistics of the parameter draw and of the sensor noise.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.arm import ArmLog, ArmRegressor, load_arm
from spaceid_gym.arm.excitation_design import FourierTrajectory, random_fourier_trajectory
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.arm.parameter_prior import ParameterPrior, default_friction_coefficients
from spaceid_gym.arm.real_logs import UR5_TORQUE_CONSTANTS_NM_A
from spaceid_gym.arm.simulated_arm_datasets import simulate_arm_dataset
from spaceid_gym.arm.torque_simulator import ArmSimulator, TrackingController
from spaceid_gym.arm_cli import add_arm_simulate_arguments, parse_friction, run_arm_simulate
from spaceid_gym.errors import SpaceIdInputError


@pytest.fixture(scope="module")
def ur5():
    return load_arm("ur5")


@pytest.fixture(scope="module")
def trajectory(ur5) -> FourierTrajectory:
    return random_fourier_trajectory(ur5, np.random.default_rng(5))


def _model_from_parameters(robot, p: np.ndarray) -> pin.Model:
    """The true pinocchio model built here, body by body, from the first 10 n entries of p."""
    model = pin.Model(robot.model)
    for k in range(1, model.njoints):
        model.inertias[k] = pin.Inertia.FromDynamicParameters(np.array(p[10 * (k - 1) : 10 * k]))
    return model


def _rnea(model: pin.Model, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
    data = model.createData()
    return np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])


def test_logged_torque_equals_rnea_without_friction(ur5, trajectory) -> None:
    regressor = ArmRegressor(ur5, None)
    p = ParameterPrior().draw(regressor, np.random.default_rng(0))
    sim = ArmSimulator(ur5, p, None, "noise_free")
    out = sim.run(trajectory, 2.0, np.random.default_rng(1))
    log = out.log
    assert log.n_samples == 251 and log.effort_kind == "torque_Nm"
    expected = _rnea(_model_from_parameters(ur5, p), log.q_rad, log.dq_rad_s, log.ddq_rad_s2)
    assert np.abs(expected).max() > 10.0  # gravity and motion load the arm
    np.testing.assert_allclose(log.effort, expected, rtol=0, atol=1e-9)


def test_logged_torque_with_friction_is_rnea_plus_the_friction_formula(ur5, trajectory) -> None:
    terms = ("coulomb", "viscous", "offset")
    regressor = ArmRegressor(ur5, terms)
    p = ParameterPrior().draw(regressor, np.random.default_rng(2))
    p[-6 * 3 + 2 :: 3] = np.linspace(-1.0, 1.0, 6)  # offsets (default 0) made non-zero
    sim = ArmSimulator(ur5, p, terms, "noise_free")
    log = sim.run(trajectory, 2.0, np.random.default_rng(3)).log
    f = p[60:].reshape(6, 3)
    friction = f[:, 0] * np.tanh(log.dq_rad_s / 0.01) + f[:, 1] * log.dq_rad_s + f[:, 2]
    assert np.abs(friction).max() > 1.0
    expected = _rnea(_model_from_parameters(ur5, p), log.q_rad, log.dq_rad_s, log.ddq_rad_s2) + friction
    np.testing.assert_allclose(log.effort, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(regressor.torque(log.q_rad, log.dq_rad_s, log.ddq_rad_s2, p), expected, rtol=0, atol=1e-9)


def _energy_drift(robot, p, q0, dq0, rate_hz: float) -> tuple[float, float]:
    """Largest |E(t) - E(0)| of free motion and E(0), energy from pinocchio on the model built here."""
    sim = ArmSimulator(robot, p, None, "noise_free", controller=None, internal_rate_hz=rate_hz, sample_rate_hz=50.0)
    sim.reset(q0, dq0)

    def rest(t: np.ndarray) -> tuple[np.ndarray, ...]:
        return (np.zeros((t.size, 6)),) * 3

    log = sim.run(rest, 1.0, np.random.default_rng(0), start_on_reference=False).clean
    model = _model_from_parameters(robot, p)
    data = model.createData()
    energy = np.array(
        [
            pin.computeKineticEnergy(model, data, q, v) + pin.computePotentialEnergy(model, data, q)
            for q, v in zip(log.q_rad, log.dq_rad_s, strict=True)
        ]
    )
    return float(np.abs(energy - energy[0]).max()), float(energy[0])


def test_free_motion_conserves_energy_to_fourth_order() -> None:
    rng = np.random.default_rng(3)
    q0, dq0 = rng.uniform(-2.0, 2.0, 6), rng.uniform(-1.0, 1.0, 6)
    weightless = load_arm("ur5", gravity_m_s2=(0.0, 0.0, 0.0))
    p = ParameterPrior().draw(ArmRegressor(weightless, None), rng)
    drift, energy = _energy_drift(weightless, p, q0, dq0, 1000.0)
    assert energy > 0.1 and drift < 1e-12 * energy  # kinetic energy alone
    # falling under gravity (the unactuated wrist whips up to ~100 rad/s): the drift falls as h^4
    heavy = load_arm("ur5")
    (drift_coarse, _), (drift, energy), (drift_fine, _) = (
        _energy_drift(heavy, p, q0, dq0, rate) for rate in (500.0, 1000.0, 2000.0)
    )
    ratios = [drift_coarse / drift, drift / drift_fine]
    assert all(12.0 < r < 24.0 for r in ratios), ratios  # 16 for a fourth-order method
    assert drift < 1e-5 * energy


def test_controller_tracks_with_a_nominal_model_and_integration_is_converged(ur5, trajectory) -> None:
    regressor = ArmRegressor(ur5)
    p = ParameterPrior().draw(regressor, np.random.default_rng(4))  # the controller uses the URDF, not p
    runs = [
        ArmSimulator(ur5, p, sensors="noise_free", internal_rate_hz=rate).run(trajectory, 3.0, np.random.default_rng(0))
        for rate in (1000.0, 4000.0)
    ]
    error = np.abs(runs[0].clean.q_rad - runs[0].q_ref_rad).max(axis=0)
    assert error[:3].max() < 2e-4 and error[3:].max() < 5e-3, error  # light wrist links carry the model mismatch
    assert runs[0].truth["tracking_error_max_rad"] == pytest.approx(error.max())
    assert 0.05 < runs[0].truth["max_torque_fraction"] < 1.0
    np.testing.assert_allclose(runs[0].clean.q_rad, runs[1].clean.q_rad, rtol=0, atol=1e-7)
    # a stiffer controller tracks better, error ~ 1 / w^2
    stiff = ArmSimulator(ur5, p, sensors="noise_free", controller=TrackingController(bandwidth_rad_s=2 * np.pi * 60))
    error_stiff = np.abs((out := stiff.run(trajectory, 3.0, np.random.default_rng(0))).clean.q_rad - out.q_ref_rad).max()
    assert error_stiff < 0.4 * error.max()


def test_logged_acceleration_is_the_derivative_of_the_logged_rate(ur5, trajectory) -> None:
    regressor = ArmRegressor(ur5)
    p = ParameterPrior().draw(regressor, np.random.default_rng(6))
    log = ArmSimulator(ur5, p, sensors="noise_free", sample_rate_hz=1000.0).run(trajectory, 1.0, np.random.default_rng(0)).log
    central = (log.dq_rad_s[2:] - log.dq_rad_s[:-2]) / (2e-3)
    settled = slice(100, None)  # after the first 0.1 s (the start-up transient of the mismatched controller)
    scale = np.abs(log.ddq_rad_s2[1:-1][settled]).max(axis=0)
    assert np.all(np.abs(central[settled] - log.ddq_rad_s2[1:-1][settled]).max(axis=0) < 2e-3 * scale)


def test_sensor_noise_statistics_and_current_conversion(ur5, trajectory) -> None:
    regressor = ArmRegressor(ur5)
    p = ParameterPrior().draw(regressor, np.random.default_rng(7))
    sensors = ArmSensorModel(effort_kind="current_A")
    out = ArmSimulator(ur5, p, sensors=sensors).run(trajectory, 8.0, np.random.default_rng(8))
    k_t = np.array(UR5_TORQUE_CONSTANTS_NM_A)
    np.testing.assert_allclose(out.clean.effort, out.motor_torque_Nm / k_t, rtol=1e-14)
    for measured, clean, std in (
        (out.log.q_rad, out.clean.q_rad, 1e-5),
        (out.log.dq_rad_s, out.clean.dq_rad_s, 2e-3),
        (out.log.effort, out.clean.effort, 0.07),
    ):
        z = (measured - clean) / std
        assert abs(z.mean()) < 0.1 and abs(z.std() - 1.0) < 0.05  # 6006 draws: std error 1 %
    np.testing.assert_allclose(sensors.torque_std_Nm(), 0.07 * k_t)
    assert out.log.effort_kind == "current_A"


def test_same_seed_same_log_other_seed_other_noise(ur5, trajectory) -> None:
    regressor = ArmRegressor(ur5)
    p = ParameterPrior().draw(regressor, np.random.default_rng(9))
    sim = ArmSimulator(ur5, p)
    a, b, c = (sim.run(trajectory, 0.5, np.random.default_rng(seed)).log for seed in (1, 1, 2))
    np.testing.assert_array_equal(a.table(), b.table())
    assert not np.array_equal(a.effort, c.effort)


def test_parameter_prior_draws_consistent_bodies_with_the_stated_spread(ur5) -> None:
    regressor = ArmRegressor(ur5)
    prior = ParameterPrior()
    rng = np.random.default_rng(10)
    draws = np.array([prior.draw(regressor, rng) for _ in range(3000)])
    for p in draws[:50]:
        for k in range(6):
            body = pin.Inertia.FromDynamicParameters(p[10 * k : 10 * (k + 1)])
            principal = np.linalg.eigvalsh(body.inertia)
            assert body.mass > 0 and principal[0] > 0 and principal[0] + principal[1] >= principal[2] * (1 - 1e-12)
    nominal = ur5.torque_limit_Nm * 0.05
    np.testing.assert_allclose(default_friction_coefficients(ur5, ("coulomb", "viscous"))[:, 0], nominal)
    std = prior.parameter_std(regressor)
    empirical = draws.std(axis=0)
    informative = std > 1e-6 * std.max()
    np.testing.assert_allclose(empirical[informative], std[informative], rtol=0.06)  # exact vs Monte Carlo (1.3 % std error)
    np.testing.assert_allclose(draws.mean(axis=0)[:10], ur5.model.inertias[1].toDynamicParameters(), rtol=0.05, atol=1e-3)


def test_bad_simulator_inputs_are_named(ur5, trajectory) -> None:
    regressor = ArmRegressor(ur5)
    p = ParameterPrior().draw(regressor, np.random.default_rng(0))
    with pytest.raises(SpaceIdInputError, match="parameters must be 72"):
        ArmSimulator(ur5, p[:60])
    with pytest.raises(SpaceIdInputError, match="controller=None"):
        ArmSimulator(ur5, p, controller=None)
    with pytest.raises(SpaceIdInputError, match="sample_rate_hz"):
        ArmSimulator(ur5, p, sample_rate_hz=0.0)
    with pytest.raises(SpaceIdInputError, match="torque_constants_Nm_A has 2"):
        ArmSimulator(ur5, p, sensors=ArmSensorModel(torque_constants_Nm_A=(1.0, 2.0)))
    with pytest.raises(SpaceIdInputError, match="effort_kind"):
        ArmSensorModel(effort_kind="voltage")
    with pytest.raises(SpaceIdInputError, match="bandwidth_rad_s"):
        TrackingController(bandwidth_rad_s=-1.0)
    with pytest.raises(SpaceIdInputError, match="duration_s"):
        ArmSimulator(ur5, p).run(trajectory, 0.0, np.random.default_rng(0))


def test_dataset_folder_and_cli(ur5, tmp_path, capsys) -> None:
    dataset = simulate_arm_dataset("ur5", 1.0, ("coulomb", "viscous"), 3, "fourier", tmp_path / "a")
    log = ArmLog.from_csv(tmp_path / "a" / "log.csv")
    np.testing.assert_array_equal(log.table(), dataset.simulation.log.table())
    truth = json.loads((tmp_path / "a" / "truth.json").read_text())
    assert truth["seed"] == 3 and len(truth["parameters"]) == 72 and len(truth["base_parameters"]) == 48
    assert truth["noise"]["torque_std_Nm"][0] == pytest.approx(0.07 * 7.5)
    assert load_arm(tmp_path / "a" / "robot.urdf").n_joints == 6
    # the torque model holds on the written log up to the noise: residual std ~ the torque noise
    regressor = ArmRegressor(ur5)
    p = np.array([truth["parameters"][name] for name in regressor.parameter_names])
    clean = dataset.simulation.clean
    np.testing.assert_allclose(regressor.torque(clean.q_rad, clean.dq_rad_s, clean.ddq_rad_s2, p), clean.effort, atol=1e-9)

    parser = argparse.ArgumentParser()
    add_arm_simulate_arguments(parser)
    args = parser.parse_args(
        [
            "--duration",
            "0.5",
            "--friction",
            "none",
            "--seed",
            "1",
            "--effort",
            "current",
            "--noise-free",
            "--out",
            str(tmp_path / "b"),
        ]
    )
    run_arm_simulate(args)
    assert "wrote" in capsys.readouterr().out
    log_b = ArmLog.from_csv(tmp_path / "b" / "log.csv")
    assert log_b.effort_kind == "current_A" and log_b.n_samples == 63
    assert parse_friction("coulomb, viscous") == ("coulomb", "viscous")
    with pytest.raises(SpaceIdInputError, match="--friction"):
        parse_friction("coulomb,stiction")
    with pytest.raises(SpaceIdInputError, match="trajectory"):
        simulate_arm_dataset("ur5", 1.0, None, 3, "chirp", tmp_path / "c")
