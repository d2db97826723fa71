"""The NEES tests for correlated windows (``spaceid_gym.tracking``): Bar-Shalom's N-run average per window, the
mean over runs with the runs as the unit, and the lag correlation between windows, on synthetic filters.

A synthetic run: 4-dimensional errors in the filter's own std, a Gaussian AR(1) across the windows with lag-1
correlation ``rho`` and stationary N(0, I), so each window's NEES is chi-square(4) exactly (a consistent filter)
however correlated the windows are; multiplied by 1.5, an over-confident one. Each statistic is judged over 400
seeded experiments of 10 runs x 10 windows, with bounds 3 standard errors or more from the rates measured on
seeds 0-4 of the same experiments (0.944-0.956 per window index, 0.705-0.723 for the independent-window test,
0.905-0.94 t-interval coverage, 0.507-0.518 per window index when over-confident; independent windows, seeds 0-2:
0.949-0.953 in both tests)."""

from __future__ import annotations

import numpy as np
import pytest

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.track_statistics import lag_correlation, lag_correlation_null, mean_bounds, run_average_nees, runs_mean_interval

EXPERIMENTS, RUNS, WINDOWS, UNKNOWNS = 400, 10, 10, 4


def correlated_errors(rng: np.random.Generator, rho: float) -> FloatArray:
    """Errors ``[experiment, run, window, unknown]``: AR(1) across windows, N(0, I) at every window."""
    errors = np.empty((EXPERIMENTS, RUNS, WINDOWS, UNKNOWNS))
    errors[:, :, 0] = rng.standard_normal((EXPERIMENTS, RUNS, UNKNOWNS))
    for k in range(1, WINDOWS):
        fresh = rng.standard_normal((EXPERIMENTS, RUNS, UNKNOWNS))
        errors[:, :, k] = rho * errors[:, :, k - 1] + np.sqrt(1.0 - rho**2) * fresh
    return errors


def pass_rates(nees: FloatArray, rng: np.random.Generator) -> tuple[float, float, float]:
    """Over the experiments: the fraction of window indices inside the N-run test's bounds, of runs whose mean
    NEES is inside the bounds that assume independent windows, and of t-intervals over runs that hold 4."""
    low_runs, high_runs = mean_bounds(UNKNOWNS, WINDOWS)
    per_window, independent, covered = [], [], []
    for experiment in nees:
        average, low, high = run_average_nees(experiment, UNKNOWNS)
        per_window.append(np.mean((average >= low) & (average <= high)))
        run_means = experiment.mean(axis=1)
        independent.append(np.mean((run_means >= low_runs) & (run_means <= high_runs)))
        _, (t_low, t_high), _ = runs_mean_interval(run_means, rng, resamples=200)
        covered.append(t_low <= UNKNOWNS <= t_high)
    return float(np.mean(per_window)), float(np.mean(independent)), float(np.mean(covered))


def test_correlated_windows_pass_the_per_window_test_and_fail_the_independent_one() -> None:
    rng = np.random.default_rng(7)
    nees = np.sum(correlated_errors(rng, 0.8) ** 2, axis=-1)
    per_window, independent, covered = pass_rates(nees, rng)
    assert 0.92 <= per_window <= 0.98
    assert independent < 0.8  # a consistent filter with correlated windows fails the per-run test often
    assert 0.87 <= covered <= 0.99
    over_confident, _, covered_over = pass_rates(1.5 * nees, rng)
    assert over_confident < 0.6 and covered_over < 0.5


def test_independent_windows_pass_both_tests() -> None:
    rng = np.random.default_rng(8)
    per_window, independent, _ = pass_rates(np.sum(correlated_errors(rng, 0.0) ** 2, axis=-1), rng)
    assert 0.92 <= per_window <= 0.98 and 0.92 <= independent <= 0.98


def test_the_lag_correlation_finds_the_ar1_and_its_null_range_holds_zero() -> None:
    rng = np.random.default_rng(9)
    errors = correlated_errors(rng, 0.8)
    # of z: rho (0.8) and rho^2 at lag 2; of the NEES, rho^2 (0.64); all a little low from centring 10 runs
    assert 0.74 <= np.mean([lag_correlation(e[:, :, 0], 1) for e in errors]) <= 0.82
    assert 0.58 <= np.mean([lag_correlation(e[:, :, 0], 2) for e in errors]) <= 0.66
    assert 0.55 <= np.mean([lag_correlation(np.sum(e**2, axis=-1), 1) for e in errors]) <= 0.66
    null = lag_correlation_null(errors[0, :, :, 0], 1, rng, draws=500)
    low, high = np.quantile(null, [0.025, 0.975])
    assert low < 0.0 < high and high < 0.5
    again = lag_correlation_null(errors[0, :, :, 0], 1, np.random.default_rng(3), draws=50)
    np.testing.assert_array_equal(again, lag_correlation_null(errors[0, :, :, 0], 1, np.random.default_rng(3), draws=50))


@pytest.mark.parametrize(
    ("values", "message"),
    [(np.ones(5), "nees: expected a (runs, windows) array"), (np.full((3, 2), np.nan), "nees: expected finite")],
)
def test_bad_arrays_are_refused_with_their_name(values: FloatArray, message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        run_average_nees(values, UNKNOWNS)
    with pytest.raises(SpaceIdInputError, match="lag: expected 1 to 1"):
        lag_correlation(np.ones((3, 2)), 2)
