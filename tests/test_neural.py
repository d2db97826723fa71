"""The neural-network estimator ``nn``: determinism, bounds, accuracy on a short log, options, budget."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import estimators.neural as neural
from estimators.neural import NeuralNetworkEstimator, simulated_window_means, window_edges, window_means
from estimators.problem import IdentificationModel, IdentificationProblem
from estimators.registry import make_estimator
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.sim.sensors import SensorModel

#: a small network set-up for the tests that check the protocol, not the accuracy
QUICK = {"n_train": 200, "max_iter": 50}


@pytest.fixture(scope="module")
def short_problem(short_fuel_episode) -> IdentificationProblem:
    return IdentificationModel(short_fuel_episode.robot).problem(short_fuel_episode.log)


@pytest.fixture(scope="module")
def default_fit(short_problem):
    """The default estimator on the 20 s episode (one fit shared by the accuracy checks)."""
    return NeuralNetworkEstimator(seed=0).fit_problem(short_problem)


def test_registered_as_nn() -> None:
    estimator = make_estimator("nn", n_windows=10, seed=3)
    assert isinstance(estimator, NeuralNetworkEstimator)
    assert estimator.get_params()["n_windows"] == 10
    assert estimator.get_params()["hidden_layer_sizes"] == (35, 45)


def test_same_seed_same_estimate_other_seed_other_estimate(short_problem) -> None:
    first = NeuralNetworkEstimator(seed=7, **QUICK).fit_problem(short_problem)
    again = NeuralNetworkEstimator(seed=7, **QUICK).fit_problem(short_problem)
    other = NeuralNetworkEstimator(seed=8, **QUICK).fit_problem(short_problem)
    np.testing.assert_array_equal(first.theta, again.theta)
    assert first.extra["training"]["loss_curve"] == again.extra["training"]["loss_curve"]
    assert not np.array_equal(first.theta, other.theta)


def test_estimate_closer_to_truth_than_nominal_and_within_bounds(short_fuel_episode, short_problem, default_fit) -> None:
    params = short_problem.parameters
    theta = default_fit.theta
    assert np.all(theta >= params.lower) and np.all(theta <= params.upper)
    # errors in units of the search range; the nominal (no fuel used) is 0.49 range units from the truth
    error = np.linalg.norm((theta - short_fuel_episode.theta_true) / params.width)
    nominal_error = np.linalg.norm((params.nominal - short_fuel_episode.theta_true) / params.width)
    assert error < 0.5 * nominal_error
    assert default_fit.cost < short_problem.cost(params.nominal[None], count=False)[0]


def test_estimate_stays_in_bounds_when_the_log_is_outside_the_training_range(short_problem) -> None:
    """A log no training vector resembles (a constant offset on the gyro) still gives an in-bounds estimate."""
    estimator = NeuralNetworkEstimator(seed=0, **QUICK)
    problem = IdentificationModel(short_problem.model.robot).problem(short_problem.log)
    problem.measured = problem.measured + 0.05  # rad/s, far beyond any base rate the arm can cause
    theta = estimator.fit_problem(problem).theta
    params = problem.parameters
    assert np.all(theta >= params.lower) and np.all(theta <= params.upper)
    assert np.any(theta == params.lower) or np.any(theta == params.upper)  # the output was clipped


def test_budget_history_and_training_record(short_problem, default_fit) -> None:
    assert default_fit.n_evaluations == 1000  # one whole-log prediction per training vector, nothing else
    assert default_fit.cost_history.shape == (1,)
    assert default_fit.cost_history[0] == pytest.approx(default_fit.cost, rel=1e-12)
    training = default_fit.extra["training"]
    assert training["n_features"] == 3 * 20
    assert training["noise_source"] == "sensor default"
    assert training["noise_std_rad_s"] == pytest.approx(SensorModel().gyro_std_rad_s(short_problem.log.sample_period_s))
    curve = training["loss_curve"]
    assert len(curve) >= training["n_iter"]  # L-BFGS: at least one loss evaluation per iteration
    assert min(curve) == pytest.approx(training["final_loss"]) and curve[-1] < 0.1 * curve[0]
    assert set(training["train_rms_error"]) == set(short_problem.parameters.names)


def test_noise_level_from_option_then_model(short_fuel_episode) -> None:
    log = short_fuel_episode.log
    model = IdentificationModel(short_fuel_episode.robot, noise_std_rad_s=3e-4)
    from_model = NeuralNetworkEstimator(**QUICK).fit(model, log).extra["training"]
    assert (from_model["noise_source"], from_model["noise_std_rad_s"]) == ("model", 3e-4)
    from_option = NeuralNetworkEstimator(noise_std_rad_s=0.0, **QUICK).fit(model, log).extra["training"]
    assert (from_option["noise_source"], from_option["noise_std_rad_s"]) == ("option", 0.0)


def test_adam_solver_records_its_epoch_losses(short_problem) -> None:
    fit = NeuralNetworkEstimator(solver="adam", **QUICK).fit_problem(short_problem)
    training = fit.extra["training"]
    assert len(training["loss_curve"]) == training["n_iter"] <= QUICK["max_iter"]
    assert np.all(np.isfinite(fit.theta))


def test_window_features_are_the_mean_base_rate_of_each_window() -> None:
    edges = window_edges(10, 3)
    np.testing.assert_array_equal(edges, [0, 3, 7, 10])
    omega = np.arange(2 * 10 * 3, dtype=float).reshape(2, 10, 3)
    features = window_means(omega, edges)
    assert features.shape == (2, 9)
    for w, (start, end) in enumerate(itertools.pairwise(edges)):
        np.testing.assert_allclose(features[:, 3 * w : 3 * w + 3], omega[:, start:end].mean(axis=1))


def test_training_predictions_in_batches_match_one_call_and_are_counted(short_problem, monkeypatch) -> None:
    theta = short_problem.parameters.lower + np.random.default_rng(0).uniform(size=(7, 4)) * short_problem.parameters.width
    edges = window_edges(short_problem.n_samples, 20)
    short_problem.n_model_samples = 0
    whole = simulated_window_means(short_problem, theta, edges)
    monkeypatch.setattr(neural, "MAX_PREDICT_SAMPLES", 3 * short_problem.n_samples)  # batches of 3, 3, 1
    batched = simulated_window_means(short_problem, theta, edges)
    np.testing.assert_allclose(batched, whole, rtol=0, atol=1e-15)
    np.testing.assert_allclose(whole, window_means(short_problem.predict(theta, count=False), edges), rtol=0, atol=1e-15)
    assert short_problem.n_model_samples == 2 * 7 * short_problem.n_samples


@pytest.mark.parametrize(
    "options",
    [
        {"n_train": 5},
        {"n_train": 100.0},
        {"n_train": True},
        {"n_windows": 0},
        {"hidden_layer_sizes": ()},
        {"hidden_layer_sizes": (35, 0)},
        {"hidden_layer_sizes": 35},
        {"solver": "sgd"},
        {"max_iter": 0},
        {"alpha": -1e-4},
        {"alpha": float("nan")},
        {"noise_std_rad_s": -1e-4},
        {"noise_std_rad_s": float("inf")},
    ],
)
def test_bad_options_raise_input_error_naming_the_option(options) -> None:
    name = next(iter(options))
    with pytest.raises(SpaceIdInputError, match=name):
        NeuralNetworkEstimator(**options)


def test_too_short_log_raises_input_error(short_fuel_episode) -> None:
    log = short_fuel_episode.log
    model = IdentificationModel(short_fuel_episode.robot)
    short = log.window(log.t_s[0], log.t_s[30])  # 30 samples: fewer than 2 per window for 20 windows
    assert short.n_samples == 30
    with pytest.raises(SpaceIdInputError, match="40 samples"):
        NeuralNetworkEstimator(**QUICK).fit(model, short)
    assert NeuralNetworkEstimator(n_windows=15, **QUICK).min_samples(model.problem(short)) == 30
