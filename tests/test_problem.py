"""The identification problem: payload terms, analytic Jacobians, Cramér-Rao bound, identifiability, estimate file."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from estimators.base import Estimator, SearchResult
from estimators.least_squares import LevenbergMarquardt
from estimators.problem import IdentificationModel
from estimators.registry import available_estimators, make_estimator, register_estimator
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.log import MeasurementLog
from spaceid_gym.physics.inertia import RigidBodyInertia, transform_params10
from spaceid_gym.robots import Robot, load_robot
from spaceid_gym.sim.sensors import SensorModel

PAYLOAD = RigidBodyInertia(25.0, np.array([0.1, -0.05, 0.3]), np.diag([0.8, 0.6, 0.5]))


def _noise_free_log(robot: Robot, steps: int = 300, fuel_kg: float = 0.0, tank_m: tuple = (0.0, 0.0, 0.0)) -> MeasurementLog:
    env = FreeFloatingIDEnv(robot, sensors="noise_free", tank_position_m=np.array(tank_m))
    env.reset(seed=0, options={"fuel_consumed_kg": fuel_kg})
    excitation = FourierExcitation(robot.n_joints, seed=4)
    for k in range(steps):
        env.step(excitation(k * env.control_period_s))
    return env.measurement_log()


def test_parameter_frame_change_matches_pinocchio() -> None:
    rot, trans = pin.utils.rpyToMatrix(0.3, -0.2, 0.9), np.array([0.4, -1.0, 0.2])
    body = pin.Inertia(PAYLOAD.mass_kg, PAYLOAD.com_m, PAYLOAD.inertia_com_kgm2)
    expected = pin.SE3(rot, trans).act(body).toDynamicParameters()
    np.testing.assert_allclose(transform_params10(PAYLOAD.to_params10(), rot, trans), expected, rtol=0, atol=1e-12)


def test_parameter_frame_change_of_a_batch_of_frames_matches_pinocchio_frame_by_frame() -> None:
    rng = np.random.default_rng(7)
    rots = np.stack([pin.utils.rpyToMatrix(*rng.uniform(-3.0, 3.0, 3)) for _ in range(5)])
    trans = rng.uniform(-1.0, 1.0, (5, 3))
    body = pin.Inertia(PAYLOAD.mass_kg, PAYLOAD.com_m, PAYLOAD.inertia_com_kgm2)
    expected = np.stack([pin.SE3(r, t).act(body).toDynamicParameters() for r, t in zip(rots, trans, strict=True)])
    np.testing.assert_allclose(transform_params10(PAYLOAD.to_params10(), rots, trans), expected, rtol=0, atol=1e-12)
    # frames (5, 1) against two bodies (2,): one row per frame and body
    bodies = np.stack([PAYLOAD.to_params10(), 2.0 * PAYLOAD.to_params10()])
    both = transform_params10(bodies, rots[:, None], trans[:, None])
    np.testing.assert_allclose(both, np.stack([expected, 2.0 * expected], axis=1), rtol=0, atol=1e-12)


def test_payload_model_reproduces_a_simulated_log_with_a_payload(paper6: Robot) -> None:
    log = _noise_free_log(paper6.with_payload(PAYLOAD))
    problem = IdentificationModel(paper6, "payload").problem(log)
    predicted = problem.predict(PAYLOAD.to_params10())[0]
    assert np.abs(log.omega_base_body_rad_s).max() > 1e-3
    assert np.abs(predicted - log.omega_base_body_rad_s).max() < 1e-8
    # the payload is not negligible: without it the model misses by far more than the gyro noise
    assert np.abs(problem.predict(np.zeros(10))[0] - log.omega_base_body_rad_s).max() > 1e-3


def test_base_parameterisation_reproduces_the_log_at_the_true_base(paper6: Robot) -> None:
    log = _noise_free_log(paper6, fuel_kg=50.0, tank_m=(0.2, 0.1, -0.3))
    env_truth = IdentificationModel(paper6, "fuel").problem(log)
    base10 = env_truth.parameters.composite(np.array([50.0, 0.2, 0.1, -0.3]))[0][0]
    problem = IdentificationModel(paper6, "base").problem(log)
    assert np.abs(problem.predict(base10)[0] - log.omega_base_body_rad_s).max() < 1e-8


@pytest.mark.parametrize("params", ["fuel", "base", "payload"])
def test_analytic_jacobian_matches_central_differences(paper6: Robot, params: str) -> None:
    log = _noise_free_log(paper6, steps=150)
    problem = IdentificationModel(paper6, params).problem(log)
    p = problem.parameters
    theta = p.lower + np.linspace(0.3, 0.7, p.n_params) * p.width  # an interior point, every entry different
    if params == "payload":
        theta = PAYLOAD.to_params10()
    analytic = problem.jacobian(theta)
    for j in range(p.n_params):
        h = 1e-5 * p.width[j]
        step = np.zeros(p.n_params)
        step[j] = h
        numeric = (problem.residuals(theta + step) - problem.residuals(theta - step)) / (2 * h)
        scale = np.abs(analytic[:, j]).max()
        assert scale > 0
        assert np.abs(numeric - analytic[:, j]).max() < 1e-6 * scale, p.names[j]


def test_cramer_rao_bound_matches_the_env_reference(fuel_episode) -> None:
    # the env accumulates the information step by step from the simulator's composite inertia: an independent path
    env = simulate_episode(
        fuel_episode.robot, 20.0, 60.0, fuel_episode.theta_true[1:], FourierExcitation(6, seed=1), seed=1, sensors=None
    )
    problem = IdentificationModel(fuel_episode.robot, "fuel").problem(env.measurement_log())
    sigma = env.sensors.gyro_std_rad_s(env.control_period_s)
    bound = problem.crlb_std(fuel_episode.theta_true, sigma)
    # the env's bound is at the exact states, the problem's at the logged (noisy) joint states
    np.testing.assert_allclose(bound, env.cramer_rao_std(), rtol=2e-3)


def test_one_joint_log_reports_insufficient_excitation(paper6: Robot) -> None:
    env = FreeFloatingIDEnv(paper6, tank_position_m=np.array([0.25, -0.2, 0.1]))
    env.reset(seed=0, options={"fuel_consumed_kg": 60.0})
    action = np.zeros(6, dtype=np.float32)
    for k in range(500):
        action[1] = np.sin(0.2 * k * env.control_period_s)  # only the shoulder pitch joint moves
        env.step(action)
    problem = IdentificationModel(paper6, "fuel").problem(env.measurement_log())
    estimate = problem.make_estimate(
        np.array([60.0, 0.25, -0.2, 0.1]), estimator="x", options={}, seed=0, cost_history=[], wall_time_s=0
    )
    assert not estimate.identifiable.all()
    assert not estimate.identifiable[estimate.names.index("tank_y_m")]  # along the shoulder axis
    doc = estimate.to_dict()
    assert any(
        "insufficient excitation" in m and "is not identifiable from this log" in m for m in doc["insufficient_excitation"]
    )
    blind = [n for n, ok in zip(estimate.names, estimate.identifiable, strict=True) if not ok]
    assert all(doc["parameters"][n]["identifiable"] is False for n in blind)
    assert doc["base_com_m"] is None and doc["base_com_m_std"] is None  # the CoM depends on the tank position


def test_estimate_file_has_the_truth_keys(fuel_episode, tmp_path) -> None:
    problem = IdentificationModel(fuel_episode.robot, "fuel").problem(fuel_episode.log)
    estimate = problem.make_estimate(
        fuel_episode.theta_true, estimator="x", options={}, seed=3, cost_history=[1.0], wall_time_s=0.5
    )
    path = estimate.write_json(tmp_path / "estimate.json")
    doc = json.loads(path.read_text())
    for key in ("base_mass_kg", "base_com_m", "base_inertia_kgm2", "fuel_consumed_kg", "tank_position_m"):
        assert doc[key] is not None and doc[f"{key}_std"] is not None
    assert doc["base_mass_kg"] == pytest.approx(fuel_episode.robot.base_full.mass_kg - 60.0)
    assert doc["fuel_consumed_kg_std"] == pytest.approx(doc["base_mass_kg_std"], rel=1e-6)  # m0 = mI - mdf
    assert np.shape(doc["base_inertia_kgm2"]) == (3, 3)
    assert doc["noise_source"] == "residual"
    # the residual-based noise estimate is the gyro noise plus a little joint-rate noise
    assert 1.0 < doc["noise_std_rad_s"] / fuel_episode.noise_std_rad_s < 1.1


def test_bad_model_inputs_are_named(paper6: Robot, quick3: Robot, short_fuel_episode) -> None:
    with pytest.raises(SpaceIdInputError, match="bounds exclude the nominal"):
        IdentificationModel(paper6, "fuel", lower=np.array([10.0, -0.5, -0.5, -0.5]))
    with pytest.raises(SpaceIdInputError, match="unknown parameterisation 'mass'"):
        IdentificationModel(paper6, "mass")
    with pytest.raises(SpaceIdInputError, match="lower bound not below upper bound for tank_x_m"):
        IdentificationModel(paper6, "fuel", upper=np.array([100.0, -0.6, 0.5, 0.5]))
    with pytest.raises(SpaceIdInputError, match="log: has 6 joints, the robot 'quick3' has 3"):
        IdentificationModel(quick3, "fuel").problem(short_fuel_episode.log)


class _Nominal(Estimator):
    """A user's estimator: returns the nominal."""

    name = "nominal-test"

    def __init__(self, *, shift: float = 0.0, seed: int | None = 0) -> None:
        super().__init__(seed=seed)
        self.shift = shift

    def min_samples(self, problem) -> int:
        return 2000

    def _search(self, problem, rng) -> SearchResult:
        theta = problem.parameters.nominal + self.shift
        return SearchResult(theta, [float(problem.cost(theta[None])[0])])


def test_registry_and_protocol(short_fuel_episode) -> None:
    with pytest.raises(SpaceIdInputError, match=r"unknown estimator 'nope'; available: .*improved-pso"):
        make_estimator("nope")
    register_estimator("nominal-test", _Nominal, overwrite=True)
    assert "nominal-test" in available_estimators()
    with pytest.raises(SpaceIdInputError, match="already registered"):
        register_estimator("nominal-test", _Nominal)
    estimator = make_estimator("nominal-test", shift=1.0)
    assert estimator.get_params() == {"shift": 1.0}
    with pytest.raises(SpaceIdInputError, match="bad options"):
        make_estimator("nominal-test", nope=1)
    model = IdentificationModel(short_fuel_episode.robot, "fuel")
    with pytest.raises(SpaceIdInputError, match="1001 samples is shorter than the estimator 'nominal-test' needs"):
        estimator.fit(model, short_fuel_episode.log)


def test_a_fit_with_the_tank_mirrored_is_a_local_minimum_its_mirror_images_leave() -> None:
    """Noise-free paper6 log, tank at x = -0.3 m: a local fit started with the tank mirrored along x stops in another
    basin (tank at the box's x bound, the fuel a third of the truth's, cost far above zero); a local fit from one of
    that point's mirror images (:meth:`~estimators.parameters.FuelParameters.mirror_images`) reaches the truth."""
    robot = load_robot("paper6")
    fuel = np.array([20.0, -0.3, 0.1, 0.1])  # mdf kg, tank m
    excitation = FourierExcitation(robot.n_joints, seed=3, base_frequency_hz=0.05, n_harmonics=10)
    env = simulate_episode(robot, 20.0, fuel[0], fuel[1:], excitation, seed=3, sensors=SensorModel.noise_free())
    problem = IdentificationModel(robot, "fuel").problem(env.measurement_log())
    polish = LevenbergMarquardt(max_iterations=200)
    images = problem.parameters.mirror_images(fuel)
    assert len(images) == 7 and np.allclose(images[0], [20.0, 0.3, 0.1, 0.1])
    stuck = polish.polish(problem, images[0]).theta
    assert abs(stuck[0] - fuel[0]) > 5.0 and problem.cost(stuck, count=False)[0] > 1e-12
    refits = [polish.polish(problem, image).theta for image in problem.parameters.mirror_images(stuck)]
    best = min(refits, key=lambda theta: problem.cost(theta, count=False)[0])
    assert np.allclose(best, fuel, atol=1e-6)


def test_an_estimate_whose_payload_mass_sits_at_zero_reports_its_centre_without_a_std(paper6: Robot) -> None:
    """A fit with the payload's mass at its lower bound (a payload candidate restarted by a global search on a log
    without one, held-out seeds 9791-9809): the differences for the derived quantities step across zero mass, where a
    payload has no centre of mass. The estimate is made (it raised a KeyError), and the centre's std is ``None``
    rather than a number from an undefined quantity."""
    model = IdentificationModel(paper6, "fuel", effects=["payload"])
    problem = model.problem(_noise_free_log(paper6, steps=100, fuel_kg=20.0, tank_m=(0.1, 0.0, 0.0)))
    theta = np.concatenate(([20.0, 0.1, 0.0, 0.0], np.zeros(10)))
    theta[4] = 1e-9  # the payload's mass, kg, within one difference step of zero
    theta[[8, 10, 13]] = 1e-12
    estimate = problem.make_estimate(theta, estimator="test", options={}, seed=None, cost_history=[0.0], wall_time_s=0.0)
    assert "payload_com_m" in estimate.physical and estimate.physical_std["payload_com_m"] is None
