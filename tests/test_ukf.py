"""The unscented Kalman filter estimator (``ukf``): consistency against the truth (NEES) and of its innovations (NIS),
accuracy against the Cramér-Rao bound, the streaming interface, determinism and bad input."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from filterpy.kalman import UnscentedKalmanFilter
from scipy.stats import chi2

from estimators.evaluation import draw_settings, estimator_from_spec
from estimators.problem import IdentificationModel
from estimators.registry import available_estimators, make_estimator
from estimators.ukf import FilterDivergedError, RandomWalkUKF, UnscentedKalman, difference_noise_std
from spaceid_gym.cli import main
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.robots import Robot

#: simulated 60 s windows (50 Hz) of the consistency test, seeds 0..N-1 (all of them, none left out)
N_SEEDS = 8
THETA_TRUE = np.array([60.0, 0.25, -0.2, 0.1])  # mdf kg, tank position bf m (base frame)


def _chi2_mean_bounds(dof_each: int, n: int, level: float = 0.99) -> tuple[float, float]:
    """Two-sided ``level`` bounds of the mean of ``n`` independent chi-square(``dof_each``) values."""
    tail = (1.0 - level) / 2.0
    return chi2.ppf(tail, dof_each * n) / n, chi2.ppf(1.0 - tail, dof_each * n) / n


@pytest.fixture(scope="module")
def fits(paper6: Robot) -> list[dict[str, np.ndarray]]:
    """The UKF's fit of each seed's 60 s window (known gyro noise), with the Cramér-Rao std at the truth."""
    out = []
    for seed in range(N_SEEDS):
        env = simulate_episode(
            paper6, 60.0, THETA_TRUE[0], THETA_TRUE[1:], FourierExcitation(paper6.n_joints, seed=seed), seed=seed
        )
        model = IdentificationModel(paper6, "fuel", noise_std_rad_s=env.sensors.gyro_std_rad_s(env.control_period_s))
        log = env.measurement_log()
        estimate = make_estimator("ukf").fit(model, log)
        out.append(
            {
                "theta": estimate.theta,
                "cov": np.asarray(estimate.extra["covariance"]),
                "crlb": model.problem(log).crlb_std(THETA_TRUE),
            }
        )
    return out


#: random true settings of the robustness test, drawn as the evaluation harness draws them (seed 123: not the seed
#: of benchmarks/ukf_settings.py, whose 30 settings served the design)
N_RANDOM_SETTINGS = 8


@pytest.fixture(scope="module")
def random_setting_fits(paper6: Robot) -> list[dict[str, np.ndarray]]:
    """The ukf and hybrid fits of 60 s windows of random true settings, with the Cramér-Rao std at the truth."""
    out = []
    for setting in draw_settings(paper6, N_RANDOM_SETTINGS, 123):
        theta = np.array([setting.fuel_consumed_kg, *setting.tank_position_m])
        excitation = FourierExcitation(paper6.n_joints, seed=setting.seed)
        env = simulate_episode(paper6, 60.0, theta[0], theta[1:], excitation, seed=setting.seed)
        model = IdentificationModel(paper6, "fuel", noise_std_rad_s=env.sensors.gyro_std_rad_s(env.control_period_s))
        problem = model.problem(env.measurement_log())
        crlb = problem.crlb_std(theta)
        ukf = make_estimator("ukf", seed=setting.seed).fit_problem(problem)
        hybrid = make_estimator("hybrid", seed=setting.seed).fit_problem(problem)
        out.append({"z_ukf": (ukf.theta - theta) / crlb, "z_hybrid": (hybrid.theta - theta) / crlb})
    return out


def test_on_random_settings_the_fit_stays_in_the_global_basin_within_twice_the_bound(
    random_setting_fits: list[dict[str, np.ndarray]],
) -> None:
    # where the shared global search found the truth's basin (hybrid within 4 std; it missed 1 of 30 settings of the
    # design run), the filter stays there: every unknown within 4 Cramér-Rao std (a 6e-5 event per unknown for an
    # efficient estimator), and the RMS fuel error over those settings within 2 std (for 8 efficient estimates the
    # RMS exceeds 2 with probability 1e-4); before the global start 8 of 10 such windows ended far from the truth
    found = [f for f in random_setting_fits if np.all(np.abs(f["z_hybrid"]) < 4.0)]
    assert len(found) >= N_RANDOM_SETTINGS - 1
    z_ukf = np.array([f["z_ukf"] for f in found])
    assert np.all(np.abs(z_ukf) < 4.0), z_ukf
    assert np.sqrt(np.mean(z_ukf[:, 0] ** 2)) < 2.0, z_ukf[:, 0]


def test_nees_over_seeds_is_within_its_chi_square_bounds(fits: list[dict[str, np.ndarray]]) -> None:
    # NEES = e^T P^-1 e of the 4 unknowns is chi-square(4) for a consistent filter; the mean over the seeds
    # lies within the 99 % bounds of chi-square(4 N) / N
    nees = [(f["theta"] - THETA_TRUE) @ np.linalg.solve(f["cov"], f["theta"] - THETA_TRUE) for f in fits]
    low, high = _chi2_mean_bounds(4, N_SEEDS)
    assert low < np.mean(nees) < high, nees


def test_fuel_is_near_the_truth_in_its_own_std_and_in_the_cramer_rao_std(fits: list[dict[str, np.ndarray]]) -> None:
    error = np.array([f["theta"][0] - THETA_TRUE[0] for f in fits])
    own_std = np.array([np.sqrt(f["cov"][0, 0]) for f in fits])
    crlb = np.array([f["crlb"][0] for f in fits])
    # each seed within 4 of its own std (a 6e-5 event for a consistent filter); 3 sigma is met on all but one
    # seed of 8 (3.15 sigma), as expected of 8 draws only at the 2 % level: a small overconfidence remains
    assert np.all(np.abs(error) < 4.0 * own_std), error / own_std
    assert np.mean(np.abs(error) < 3.0 * own_std) >= 0.75, error / own_std
    # the RMS error over the seeds within 2 Cramér-Rao std, and the filter's std close to the bound
    assert np.sqrt(np.mean((error / crlb) ** 2)) < 2.0, error / crlb
    assert np.all((own_std > 0.5 * crlb) & (own_std < 2.0 * crlb)), own_std / crlb


def test_nis_of_the_streaming_filter_is_within_its_chi_square_bounds(fuel_episode: Any) -> None:
    # the simulated gyro's residual at the maximum-likelihood fit is ~4 % above the sensor's nominal variance, so
    # the filter here uses the residual noise level of the batch (lm) fit, the noise a user measures
    model = IdentificationModel(fuel_episode.robot, "fuel")
    problem = model.problem(fuel_episode.log)
    sigma = problem.noise_std(make_estimator("lm").fit(model, fuel_episode.log).theta)[0]
    tracker = UnscentedKalman(noise_std_rad_s=sigma).tracker(problem)
    tracker.run()
    nis = np.array(tracker.nis)
    low, high = _chi2_mean_bounds(3, len(nis))
    assert low < nis.mean() < high, nis.mean()
    assert len(tracker.innovations) == len(tracker.samples) == problem.n_samples


def test_streaming_updates_equal_a_single_pass_fit_and_the_fit_is_deterministic(short_fuel_episode: Any) -> None:
    model = IdentificationModel(short_fuel_episode.robot, "fuel", noise_std_rad_s=short_fuel_episode.noise_std_rad_s)
    problem = model.problem(short_fuel_episode.log)
    tracker = make_estimator("ukf").tracker(problem)  # the streaming tracker starts as start="interior"
    for index in range(problem.n_samples):
        innovation = tracker.update(index)
        assert innovation.shape == (3,)
    theta, cov = tracker.estimate()
    single = make_estimator("ukf", passes=1, start="interior").fit(model, short_fuel_episode.log)
    np.testing.assert_array_equal(single.theta, theta)
    np.testing.assert_array_equal(np.asarray(single.extra["covariance"]), cov)
    np.testing.assert_array_equal(cov, cov.T)
    first, second = (make_estimator("ukf", passes=2, start="interior").fit(model, short_fuel_episode.log) for _ in range(2))
    np.testing.assert_array_equal(first.theta, second.theta)
    assert first.extra["covariance"] == second.extra["covariance"]
    # all sigma points of a sample go through one batched prediction: (2k + 1) model samples per update and pass
    assert first.n_model_samples == 2 * (2 * 4 + 1) * problem.n_samples
    # the global start is seeded: the same seed, the same fit
    seeded = [make_estimator("ukf", passes=1, seed=4).fit(model, short_fuel_episode.log) for _ in range(2)]
    np.testing.assert_array_equal(seeded[0].theta, seeded[1].theta)
    assert seeded[0].extra["start_theta"] == seeded[1].extra["start_theta"]


def test_the_random_walk_steps_in_closed_form_are_filterpys_own(short_fuel_episode: Any) -> None:
    """:class:`RandomWalkUKF`'s predict (``P + Q``, no transform through the identity) and vectorised cross variance
    against filterpy's own steps over 20 s with a walk 100 times the default (so that ``Q`` counts): the same state,
    covariance and innovations to rounding, a streamed wide prior included."""
    model = IdentificationModel(short_fuel_episode.robot, "fuel", noise_std_rad_s=short_fuel_episode.noise_std_rad_s)
    problem = model.problem(short_fuel_episode.log)
    for merwe in ({}, {"alpha": 0.3, "kappa": 1.0}):  # the default spread, and one where the centre point has weight
        trackers = [make_estimator("ukf", random_walk=1e-3, **merwe).tracker(problem) for _ in range(2)]
        assert isinstance(trackers[0].filter, RandomWalkUKF)
        trackers[1].filter.__class__ = UnscentedKalmanFilter  # filterpy's own predict and cross variance
        for tracker in trackers:
            tracker.run()
        (theta, cov), (theta_ref, cov_ref) = (t.estimate() for t in trackers)
        scale = np.asarray(problem.parameters.scale)
        np.testing.assert_allclose(theta / scale, theta_ref / scale, rtol=0, atol=1e-12)
        np.testing.assert_allclose(cov, cov_ref, rtol=1e-9, atol=1e-12 * float(np.max(np.abs(cov_ref))))
        np.testing.assert_allclose(trackers[0].nis, trackers[1].nis, rtol=1e-9)
    with pytest.raises(ValueError, match="identity"):
        trackers[0].filter.predict(fx=lambda x, dt: 2 * x)


def test_random_walk_grows_the_covariance_between_windows(short_fuel_episode: Any) -> None:
    model = IdentificationModel(short_fuel_episode.robot, "fuel", noise_std_rad_s=short_fuel_episode.noise_std_rad_s)
    problem = model.problem(short_fuel_episode.log)
    tracker = make_estimator("ukf", random_walk=[1e-3, 0.0, 0.0, 0.0]).tracker(problem)
    tracker.run(range(100))
    before = tracker.estimate()[1]
    tracker.advance(100.0)
    grown = tracker.estimate()[1] - before
    expected = (1e-3 * problem.parameters.width[0]) ** 2 * 100.0  # (fraction x width)^2 per second, kg^2
    np.testing.assert_allclose(np.diag(grown), [expected, 0.0, 0.0, 0.0], rtol=1e-12, atol=1e-18)
    tracker.bind(model.problem(short_fuel_episode.log))  # the next window: samples start again
    tracker.update(0)


def test_the_noise_is_estimated_from_the_log_without_a_given_one(short_fuel_episode: Any) -> None:
    measured = short_fuel_episode.log.omega_base_body_rad_s
    assert difference_noise_std(measured) == pytest.approx(short_fuel_episode.noise_std_rad_s, rel=0.1)
    estimate = make_estimator("ukf", passes=1).fit(IdentificationModel(short_fuel_episode.robot, "fuel"), short_fuel_episode.log)
    assert estimate.extra["filter_noise_source"] == "differences"


def test_registered_in_the_registry_the_spec_parser_and_the_cli(tmp_path: Path) -> None:
    assert "ukf" in available_estimators()
    from_spec = estimator_from_spec("ukf[passes=2,random_walk=1e-4]", seed=3)
    assert isinstance(from_spec, UnscentedKalman) and from_spec.passes == 2 and from_spec.random_walk == 1e-4
    data = tmp_path / "run1"
    assert main(["simulate", "--duration", "10", "--fuel-consumed", "70", "--seed", "2", "--out", str(data)]) == 0
    out = tmp_path / "ukf.json"
    args = ["identify", "--robot", str(data / "robot.urdf"), "--log", str(data / "log.csv"), "--params", "fuel"]
    assert main([*args, "--estimator", "ukf[passes=1]", "--out", str(out)]) == 0
    written = json.loads(out.read_text())
    assert written["estimator"] == "ukf" and np.shape(written["covariance"]) == (4, 4)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"random_walk": -1e-5}, "random_walk"),
        ({"random_walk": [1e-5, -1.0, 0.0, 0.0]}, "random_walk"),
        ({"passes": 0}, "passes"),
        ({"alpha": 0.0}, "alpha"),
        ({"initial_std_fraction": -0.1}, "initial_std_fraction"),
        ({"noise_std_rad_s": 0.0}, "noise_std_rad_s"),
        ({"clip": "yes"}, "clip"),
        ({"start": "middle"}, "start"),
        ({"prior_inflation": 0.0}, "prior_inflation"),
    ],
)
def test_bad_options_are_rejected(options: dict[str, object], message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message):
        make_estimator("ukf", **options)


def test_bad_streaming_input_and_a_lost_covariance_raise_clear_errors(short_fuel_episode: Any) -> None:
    model = IdentificationModel(short_fuel_episode.robot, "fuel", noise_std_rad_s=short_fuel_episode.noise_std_rad_s)
    problem = model.problem(short_fuel_episode.log)
    with pytest.raises(SpaceIdInputError, match="random_walk: expected 1 or 4"):
        make_estimator("ukf", random_walk=[1e-5, 1e-5]).tracker(problem)
    tracker = make_estimator("ukf").tracker(problem)
    with pytest.raises(SpaceIdInputError, match="sample_index"):
        tracker.update(problem.n_samples)
    tracker.update(5)
    with pytest.raises(SpaceIdInputError, match="not after the previous"):
        tracker.update(5)
    with pytest.raises(SpaceIdInputError, match="gap_s"):
        tracker.advance(-1.0)
    tracker.filter.P = -np.eye(4)
    with pytest.raises(FilterDivergedError, match="not positive definite at sample 6"):
        tracker.update(6)


def test_effect_unknowns_join_the_state(short_fuel_episode: Any) -> None:
    # a gyro bias in the model of a log without one: the filter estimates it near zero, within 4 of its own std
    model = IdentificationModel(
        short_fuel_episode.robot, "fuel", noise_std_rad_s=short_fuel_episode.noise_std_rad_s, effects="gyro_bias"
    )
    estimate = make_estimator("ukf", start="interior").fit(model, short_fuel_episode.log)  # (2 passes: a mirrored basin)
    cov = np.asarray(estimate.extra["covariance"])
    assert estimate.names[4:] == ("bias_x_rad_s", "bias_y_rad_s", "bias_z_rad_s") and cov.shape == (7, 7)
    assert np.all(np.abs(estimate.theta[4:]) < 4.0 * np.sqrt(np.diag(cov)[4:]))
    assert estimate.n_model_samples == 6 * (2 * 7 + 1) * short_fuel_episode.log.n_samples
