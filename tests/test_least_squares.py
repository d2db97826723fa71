"""Least squares (``lm``) and the hybrid estimator (global search, then least-squares polish)."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.hybrid import HybridEstimator
from estimators.least_squares import LevenbergMarquardt
from estimators.problem import IdentificationModel, IdentificationProblem
from estimators.reference import DifferentialEvolution
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.robots import Robot

TRUTH_NOISE_FREE = np.array([45.0, -0.15, 0.3, 0.2])


@pytest.fixture(scope="module")
def short_problem(short_fuel_episode) -> IdentificationProblem:
    episode = short_fuel_episode
    return IdentificationModel(episode.robot, "fuel", noise_std_rad_s=episode.noise_std_rad_s).problem(episode.log)


@pytest.fixture(scope="module")
def noise_free_problem(paper6: Robot) -> IdentificationProblem:
    env = FreeFloatingIDEnv(paper6, sensors="noise_free", tank_position_m=TRUTH_NOISE_FREE[1:])
    env.reset(seed=3, options={"fuel_consumed_kg": TRUTH_NOISE_FREE[0]})
    excitation = FourierExcitation(paper6.n_joints, seed=3)
    for k in range(500):  # 10 s
        env.step(excitation(k * env.control_period_s))
    return IdentificationModel(paper6, "fuel").problem(env.measurement_log())


def _gradient(problem: IdentificationProblem, theta: np.ndarray) -> np.ndarray:
    """``J^T r`` in range units (k,): the gradient of ``sum(r^2) / 2`` per unit of each parameter's search width."""
    return problem.jacobian(theta, count=False).T @ problem.residuals(theta, count=False) * problem.parameters.width


def test_lm_reaches_the_maximum_likelihood_estimate(short_fuel_episode, short_problem) -> None:
    lm = LevenbergMarquardt()
    estimate = lm.fit_problem(short_problem)
    bound = short_problem.crlb_std(short_fuel_episode.theta_true, short_fuel_episode.noise_std_rad_s)
    assert np.all(np.isfinite(bound))
    assert np.all(np.abs(estimate.theta - short_fuel_episode.theta_true) < 3.0 * bound)
    # a stationary point: the gradient has vanished relative to the start's
    start = lm.start(short_problem)
    assert start[0] > 0.0  # the default start is moved off mdf = 0, where the tank position has no effect
    assert np.abs(_gradient(short_problem, estimate.theta)).max() < 1e-4 * np.abs(_gradient(short_problem, start)).max()
    # and a minimum: no nearby point (+-0.1 Cramér-Rao std in any coordinate) is better
    steps = np.vstack([np.diag(bound), -np.diag(bound)]) * 0.1
    assert short_problem.cost(estimate.theta + steps, count=False).min() > estimate.cost


def test_lm_history_and_budget_follow_its_evaluations(short_problem) -> None:
    estimate = LevenbergMarquardt().fit_problem(short_problem)
    extra, history = estimate.extra, estimate.cost_history
    assert extra["status"] > 0 and extra["iterations"] == len(history) >= 2
    assert np.all(np.diff(history) <= 0.0)  # trust-region steps are only accepted if they reduce the cost
    assert history[-1] == pytest.approx(estimate.cost, rel=1e-12)
    # the problem counts every residual vector (T samples) and Jacobian (k x T)
    k = short_problem.n_params
    assert estimate.n_evaluations == extra["nfev"] + k * extra["njev"]


@pytest.mark.parametrize("method", ["trf", "dogbox", "lm"])
def test_lm_recovers_the_truth_from_a_noise_free_log(noise_free_problem, method: str) -> None:
    estimate = LevenbergMarquardt(method=method).fit_problem(noise_free_problem)
    np.testing.assert_allclose(estimate.theta, TRUTH_NOISE_FREE, rtol=1e-6, atol=0.0)


def test_lm_stops_after_max_iterations(short_problem) -> None:
    full = LevenbergMarquardt().fit_problem(short_problem)
    assert full.extra["iterations"] > 2
    stopped = LevenbergMarquardt(max_iterations=2).fit_problem(short_problem)
    assert stopped.extra["iterations"] == len(stopped.cost_history) == 2
    assert stopped.extra["status"] == -3
    np.testing.assert_array_equal(stopped.cost_history, full.cost_history[:2])
    assert stopped.cost == pytest.approx(full.cost_history[1], rel=1e-12)


def test_lm_starts_from_x0(short_problem) -> None:
    params = short_problem.parameters
    x0 = params.lower + 0.7 * params.width
    estimate = LevenbergMarquardt(x0=x0, max_iterations=1).fit_problem(short_problem)
    full = LevenbergMarquardt(x0=x0).fit_problem(short_problem)
    assert estimate.cost_history[0] == full.cost_history[0] < short_problem.cost(x0[None], count=False)[0]
    assert estimate.options["x0"] == x0.tolist()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"method": "newton"}, "method"),
        ({"ftol": 0.0}, "ftol"),
        ({"xtol": -1e-8}, "xtol"),
        ({"gtol": float("nan")}, "gtol"),
        ({"max_iterations": 0}, "max_iterations"),
        ({"max_iterations": 2.5}, "max_iterations"),
        ({"x0": [1.0, np.inf, 0.0, 0.0]}, "x0"),
    ],
)
def test_lm_rejects_bad_options(options: dict, message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message):
        LevenbergMarquardt(**options)


def test_lm_rejects_an_x0_that_does_not_fit_the_problem(short_problem) -> None:
    with pytest.raises(SpaceIdInputError, match="x0: expected 4 finite numbers"):
        LevenbergMarquardt(x0=[10.0, 0.0, 0.0]).fit_problem(short_problem)
    with pytest.raises(SpaceIdInputError, match="outside the search box"):
        LevenbergMarquardt(x0=[-5.0, 0.0, 0.0, 0.0]).fit_problem(short_problem)
    # the unbounded method may start anywhere
    assert LevenbergMarquardt(x0=[-5.0, 0.0, 0.0, 0.0], method="lm", max_iterations=1).fit_problem(short_problem).cost > 0


def test_hybrid_polishes_the_global_search_result(short_fuel_episode, short_problem) -> None:
    hybrid = HybridEstimator(global_search="de", global_options={"max_evaluations": 100}, seed=4)
    estimate = hybrid.fit_problem(short_problem)
    extra = estimate.extra
    stage_global, stage_polish = extra["global"], extra["polish"]
    assert stage_global["estimator"] == "de" and stage_global["evaluations"] == 100
    assert estimate.n_evaluations == pytest.approx(stage_global["evaluations"] + stage_polish["evaluations"])
    # the history is the search's, then the polish's
    assert len(estimate.cost_history) == stage_global["generations"] + stage_polish["iterations"]
    assert estimate.cost_history[-1] == pytest.approx(estimate.cost, rel=1e-12)
    # the polish is least squares from the search's result: the same minimum as lm started there
    direct = LevenbergMarquardt(x0=stage_global["theta"]).fit_problem(short_problem)
    np.testing.assert_array_equal(estimate.theta, direct.theta)
    bound = short_problem.crlb_std(short_fuel_episode.theta_true, short_fuel_episode.noise_std_rad_s)
    assert np.all(np.abs(estimate.theta - short_fuel_episode.theta_true) < 3.0 * bound)
    assert estimate.options["global_search"] == "de" and estimate.options["method"] == "trf"
    # determinism: the hybrid's seed fixes the global search
    again = HybridEstimator(global_search="de", global_options={"max_evaluations": 100}, seed=4).fit_problem(short_problem)
    np.testing.assert_array_equal(again.theta, estimate.theta)
    assert again.extra["global"]["theta"] == stage_global["theta"]


def test_hybrid_default_is_improved_pso_then_trf(short_fuel_episode, short_problem) -> None:
    estimate = HybridEstimator().fit_problem(short_problem)
    assert estimate.options["global_search"] == "improved-pso" and estimate.extra["global"]["estimator"] == "improved-pso"
    assert estimate.extra["polish"]["method"] == "trf" and estimate.extra["polish"]["status"] > 0
    bound = short_problem.crlb_std(short_fuel_episode.theta_true, short_fuel_episode.noise_std_rad_s)
    assert np.all(np.abs(estimate.theta - short_fuel_episode.theta_true) < 3.0 * bound)


def test_hybrid_accepts_an_estimator_instance(short_problem) -> None:
    search = DifferentialEvolution(population_size=10, max_evaluations=50)
    estimate = HybridEstimator(global_search=search, max_iterations=3).fit_problem(short_problem)
    assert estimate.options["global_search"]["estimator"] == "de"
    assert estimate.extra["polish"]["iterations"] <= 3


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"global_search": "nope"}, "unknown estimator"),
        ({"global_search": "de", "global_options": {"max_evaluations": -1}}, "max_evaluations"),
        ({"global_search": "de", "global_options": {"nope": 1}}, "bad options"),
        ({"global_search": "de", "global_options": [1]}, "global_options"),
        ({"global_search": DifferentialEvolution(), "global_options": {"max_evaluations": 50}}, "global_options"),
        ({"global_search": "de", "method": "newton"}, "method"),
    ],
)
def test_hybrid_rejects_bad_options(options: dict, message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message):
        HybridEstimator(**options)
