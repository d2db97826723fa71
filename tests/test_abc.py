"""Artificial bee colonies: classic ``abc``, ``improved-abc`` and the physically consistent variant."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.optimize import least_squares

from estimators.arm.consistency import is_physically_consistent
from estimators.arm.improved_abc import ArtificialBeeColony, Colony, ImprovedABC
from estimators.arm.linear_ls import OrdinaryLeastSquares, WeightedLeastSquares
from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.arm.synthetic import ArmBenchmark, arm_benchmark, last_link_problem
from estimators.problem import IdentificationModel
from spaceid_gym.errors import SpaceIdInputError

ESTIMATORS = [pytest.param(ArtificialBeeColony, id="abc"), pytest.param(ImprovedABC, id="improved-abc")]


@pytest.fixture(scope="module")
def bench() -> ArmBenchmark:
    """The documented 50-base-parameter arm problem with the true per-joint noise (weighted cost)."""
    return arm_benchmark(seed=1, known_noise=True)


@pytest.fixture(scope="module")
def small() -> LinearIdentificationProblem:
    """A well-conditioned 3-parameter problem (200 rows, noise 0.01)."""
    rng = np.random.default_rng(0)
    y = rng.normal(size=(200, 3))
    tau = y @ np.array([0.5, -1.0, 2.0]) + 0.01 * rng.normal(size=200)
    return LinearIdentificationProblem(y, tau, ["a", "b", "c"], [-3, -3, -3], [3, 3, 3])


# ---------------------------------------------------------------------- protocol
@pytest.mark.parametrize("cls", ESTIMATORS)
def test_same_seed_same_result(cls: type[ArtificialBeeColony], bench: ArmBenchmark) -> None:
    first = cls(max_evaluations=2000, seed=3).fit_problem(bench.problem)
    again = cls(max_evaluations=2000, seed=3).fit_problem(bench.problem)
    other = cls(max_evaluations=2000, seed=4).fit_problem(bench.problem)
    np.testing.assert_array_equal(first.theta, again.theta)
    np.testing.assert_array_equal(first.cost_history, again.cost_history)
    assert not np.array_equal(first.theta, other.theta)


@pytest.mark.parametrize("consistent", [False, True])
@pytest.mark.parametrize("cls", ESTIMATORS)
def test_budget_is_spent_exactly(cls: type[ArtificialBeeColony], consistent: bool, bench: ArmBenchmark) -> None:
    """max_evaluations: the last phase is cut to fit, so the count equals the budget (whole-objective evaluations)."""
    estimate = cls(max_evaluations=1234, consistent=consistent).fit_problem(bench.problem)
    assert estimate.n_evaluations == 1234
    assert estimate.n_model_samples == 1234 * bench.problem.n_samples


@pytest.mark.parametrize("cls", ESTIMATORS)
def test_cycles_cost_two_evaluations_per_source(cls: type[ArtificialBeeColony], small: LinearIdentificationProblem) -> None:
    """Without a budget: SN initial + 2 SN per cycle + one per scout; the history has one entry per cycle, non-increasing."""
    estimate = cls(colony_size=10, max_cycles=30, limit=1000).fit_problem(small)
    assert estimate.n_evaluations == 5 + 2 * 5 * 30
    assert len(estimate.cost_history) == 30 and estimate.extra["n_scouts"] == 0
    assert np.all(np.diff(estimate.cost_history) <= 0.0)
    scouted = cls(colony_size=10, max_cycles=30, limit=2).fit_problem(small)
    assert scouted.extra["n_scouts"] > 0
    assert scouted.n_evaluations == 5 + 2 * 5 * 30 + scouted.extra["n_scouts"]


@pytest.mark.parametrize("cls", ESTIMATORS)
def test_converges_to_least_squares_on_a_small_problem(
    cls: type[ArtificialBeeColony], small: LinearIdentificationProblem
) -> None:
    """3 well-conditioned parameters: the colony finds the OLS solution to a small fraction of its standard error."""
    ols = OrdinaryLeastSquares().fit_problem(small)
    estimate = cls(max_evaluations=6000).fit_problem(small)
    assert np.all(np.abs(estimate.theta - ols.theta) < 0.1 * ols.theta_std)
    assert estimate.identifiable.all()


def test_options_are_checked(bench: ArmBenchmark) -> None:
    with pytest.raises(SpaceIdInputError, match="colony_size"):
        ArtificialBeeColony(colony_size=7)
    with pytest.raises(SpaceIdInputError, match="max_evaluations"):
        ArtificialBeeColony(colony_size=40, max_evaluations=10)
    with pytest.raises(SpaceIdInputError, match="step_constant"):
        ImprovedABC(step_constant=0.0)
    with pytest.raises(SpaceIdInputError, match="principal_probability"):
        ImprovedABC(principal_probability=1.5)
    with pytest.raises(SpaceIdInputError, match="consistent"):
        ImprovedABC(consistent="yes")  # type: ignore[arg-type]
    rng = np.random.default_rng(0)
    plain = LinearIdentificationProblem(rng.normal(size=(30, 2)), rng.normal(size=30), ["a", "b"], [-1, -1], [1, 1])
    with pytest.raises(SpaceIdInputError, match="no PhysicalConsistency"):
        ImprovedABC(consistent=True, max_cycles=2).fit_problem(plain)
    assert ImprovedABC().get_params()["principal_probability"] == 0.3


# ---------------------------------------------------------------------- the improved ABC's parts
def test_all_changes_off_is_the_classic_colony(bench: ArmBenchmark) -> None:
    """The ablation baseline is exact: every change off reproduces ArtificialBeeColony draw for draw."""
    classic = ArtificialBeeColony(max_evaluations=3000, seed=2).fit_problem(bench.problem)
    off = ImprovedABC(max_evaluations=3000, seed=2, adaptive_step=False, principal_axes=False, scaled_fitness=False)
    np.testing.assert_array_equal(off.fit_problem(bench.problem).theta, classic.theta)


def test_step_coefficient_scales_with_the_excess_cost() -> None:
    """F_ij = 2 sqrt(e_i + eps) / (sqrt(e_i + eps) + sqrt(e_j + eps)): 1 for equal sources, < 1 for the better one."""
    estimator = ImprovedABC(step_constant=0.1)
    cost = np.array([1.0, 2.0, 5.0, 10.0])  # excess 0, 1, 4, 9; median 2.5, eps 0.25
    f = estimator.step_coefficient(cost, np.array([0, 3, 1, 2]), np.array([3, 0, 1, 2]))
    eps = 0.25
    expected_best = 2 * np.sqrt(eps) / (np.sqrt(eps) + np.sqrt(9 + eps))
    np.testing.assert_allclose(f, [expected_best, 2 - expected_best, 1.0, 1.0])
    assert np.all((f > 0) & (f < 2))
    np.testing.assert_array_equal(estimator.step_coefficient(np.ones(4), np.arange(4), np.arange(4)[::-1]), np.ones(4))


def test_scaled_fitness_does_not_depend_on_the_cost_unit() -> None:
    """Onlookers' weights: the scaled fitness is unit free; the classic 1 / (1 + f) flattens for small costs."""
    cost = np.array([1e-3, 2e-3, 4e-3, 8e-3])
    improved, classic = ImprovedABC(), ArtificialBeeColony()
    np.testing.assert_allclose(improved._fitness(cost), improved._fitness(1e6 * cost))
    assert improved._fitness(cost).max() / improved._fitness(cost).min() > 2.0
    assert classic._fitness(cost).max() / classic._fitness(cost).min() < 1.01


def test_principal_axis_moves_follow_the_colony() -> None:
    """principal_probability 1: every move lies in the span of the colony's SN - 1 principal axes (D = 10 > SN = 6)."""
    rng = np.random.default_rng(0)
    direction = rng.normal(size=10)
    direction /= np.linalg.norm(direction)
    unit = 0.5 + 0.1 * rng.normal(size=(6, 1)) * direction + 1e-3 * rng.normal(size=(6, 10))
    colony = Colony(unit, np.arange(6.0), np.zeros(6, dtype=np.intp))
    estimator = ImprovedABC(principal_probability=1.0, adaptive_step=False)
    estimator._prepare_cycle(colony)
    assert colony.axes is not None and colony.axes.shape == (10, 5)
    assert abs(colony.axes[:, 0] @ direction) > 0.99  # the colony's long axis first
    sources = np.array([0, 1, 2, 3, 4, 5, 0, 3])
    moves = estimator._candidates(colony, sources, rng) - unit[sources]
    centred = unit - unit.mean(axis=0)
    in_span = np.linalg.lstsq(centred.T, moves.T, rcond=None)[0]  # moves as combinations of the centred sources
    np.testing.assert_allclose(centred.T @ in_span, moves.T, atol=1e-12)
    assert np.all(np.linalg.norm(moves, axis=1) > 0.0)


def test_improved_abc_beats_classic_abc_at_equal_evaluations(bench: ArmBenchmark) -> None:
    """Arm problem (50 base parameters, 2400 rows), 50 000 evaluations, 3 seeds: the improved colony ends closer to the
    truth in Cramér-Rao units on every seed and lower in cost. Measured over colony seeds 0-11: lower error and cost on
    12 of 12, classic 3.9-20, improved 1.0-2.7 Cramér-Rao std, median ratio 0.15. At 20 000 evaluations both colonies
    are still far off (7.6-63) and the improved one is ahead on only 10 of 12 seeds, too few for "every seed"."""
    errors = []
    for seed in range(3):
        classic = ArtificialBeeColony(max_evaluations=50_000, seed=seed).fit_problem(bench.problem)
        improved = ImprovedABC(max_evaluations=50_000, seed=seed).fit_problem(bench.problem)
        errors.append((bench.parameter_error(classic.theta), bench.parameter_error(improved.theta)))
        assert improved.cost < classic.cost
    errors_array = np.array(errors)
    assert np.all(errors_array[:, 1] < errors_array[:, 0]), errors_array
    assert np.median(errors_array[:, 1]) < 0.5 * np.median(errors_array[:, 0]), errors_array


# ---------------------------------------------------------------------- the physically consistent variant
def test_consistent_variant_finds_a_consistent_body_where_ols_cannot() -> None:
    """Thin last link, 1 s of data: OLS is inconsistent; the consistent colony returns a consistent body whose cost is
    no worse than the truth's (the truth is one consistent candidate, so the consistent optimum is at least as good)."""
    for seed in range(3):
        problem, truth = last_link_problem(seed)
        ols = OrdinaryLeastSquares().fit_problem(problem)
        assert not is_physically_consistent(ols.theta)
        estimate = ImprovedABC(consistent=True, max_evaluations=20_000, seed=seed).fit_problem(problem)
        assert is_physically_consistent(estimate.theta)
        assert estimate.physical["links_physically_consistent"] == [True]
        np.testing.assert_allclose(estimate.extra["full_params"], estimate.theta)
        truth_cost = problem.cost(truth, count=False)[0]
        assert ols.cost <= estimate.cost <= truth_cost * (1 + 1e-3), (ols.cost, estimate.cost, truth_cost)


@pytest.mark.parametrize("cls", ESTIMATORS)
def test_consistent_variant_in_base_parameters(cls: type[ArtificialBeeColony], bench: ArmBenchmark) -> None:
    """Posed in base parameters: every visited body is consistent, the estimate is K x_full, friction >= 0."""
    estimate = cls(consistent=True, max_evaluations=5000).fit_problem(bench.problem)
    full = np.asarray(estimate.extra["full_params"])
    np.testing.assert_allclose(estimate.theta, bench.base_map @ full, rtol=1e-12, atol=1e-12)
    assert estimate.physical["links_physically_consistent"] == [True] * 6
    assert estimate.physical["friction_non_negative"]
    wls = WeightedLeastSquares().fit_problem(bench.problem)
    assert estimate.cost >= wls.cost  # WLS is the unconstrained minimum of the same weighted cost


def test_improved_abc_also_fits_the_free_floating_problem(short_fuel_episode: Any) -> None:
    """The colonies only need ``parameters`` and ``cost``: on the nonlinear 4-parameter fuel problem (20 s episode,
    2000 evaluations) the improved colony with ``F_ij`` ends within 16 chi-square units (4 std in the worst direction)
    of the maximum-likelihood fit. Measured over 12 seeds: median 2.6, max 13.4 with ``F_ij``; 4.6 and 54 without it;
    6.0 and 21.5 for the classic colony (``F_ij`` helps on this small problem, not on the 50-parameter arm)."""
    model = IdentificationModel(short_fuel_episode.robot, "fuel", noise_std_rad_s=short_fuel_episode.noise_std_rad_s)
    problem = model.problem(short_fuel_episode.log)
    params = problem.parameters
    ml = least_squares(
        lambda x: problem.residuals(x, count=False),
        short_fuel_episode.theta_true,
        jac=lambda x: problem.jacobian(x, count=False),
        bounds=(params.lower, params.upper),
        x_scale=params.width,
    ).x
    estimate = ImprovedABC(max_evaluations=2000, adaptive_step=True).fit_problem(problem)
    assert estimate.n_evaluations == 2000
    excess = estimate.cost - problem.cost(ml, count=False)[0]
    assert 0.0 <= excess * 3 * problem.n_samples / short_fuel_episode.noise_std_rad_s**2 < 16.0
