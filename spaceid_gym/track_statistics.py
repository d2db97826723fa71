"""The consistency statistics of ``spaceid track`` (:mod:`spaceid_gym.tracking`) and ``benchmarks/track_summary.py``:
the bounds of a mean of chi-square values, Bar-Shalom's N-run average NEES, the mean over runs with its intervals
and the lag correlation of a run's windows with its shuffled null."""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2
from scipy.stats import t as t_dist

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: the confidence of the consistency bounds
LEVEL = 0.95


def mean_bounds(dof_each: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Two-sided ``level`` bounds of the mean of ``n`` independent chi-square(``dof_each``) values."""
    tail = 0.5 * (1.0 - level)
    return float(chi2.ppf(tail, dof_each * n) / n), float(chi2.ppf(1.0 - tail, dof_each * n) / n)


def _runs_by_windows(values: FloatArray, name: str) -> FloatArray:
    """``values`` as a finite (runs, windows) array with at least two runs; raises naming ``name`` otherwise."""
    array = np.asarray(values, dtype=float)
    if array.ndim != 2 or array.shape[0] < 2 or array.shape[1] < 1:
        raise SpaceIdInputError(f"{name}: expected a (runs, windows) array with at least 2 runs, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise SpaceIdInputError(f"{name}: expected finite values")
    return array


def run_average_nees(nees: FloatArray, dof: int, level: float = LEVEL) -> tuple[FloatArray, float, float]:
    """Bar-Shalom's Monte Carlo NEES test (Estimation with Applications to Tracking and Navigation, 2001, 5.4.2).

    ``nees[i, k]``: run ``i``'s NEES after window ``k``, the runs independent. Returns the ``N``-run average at each
    ``k`` and the two-sided ``level`` bounds it lies within for a consistent filter (``N`` times it is
    chi-square(``N dof``)). The windows of one run may be correlated: the test never averages over ``k``."""
    array = _runs_by_windows(nees, "nees")
    low, high = mean_bounds(dof, array.shape[0], level)
    return array.mean(axis=0), low, high


def runs_mean_interval(
    run_means: FloatArray, rng: np.random.Generator, level: float = LEVEL, resamples: int = 10000
) -> tuple[float, tuple[float, float], tuple[float, float]]:
    """The mean over independent runs of a per-run figure, with the runs as the unit: its Student-t interval and the
    percentile interval of ``resamples`` bootstrap resamples of the runs drawn from ``rng``, both at ``level``.

    A run's mean over its windows is one draw whatever their correlation, so both intervals hold for correlated
    windows (the t-interval asks the runs' means to be near normal, the bootstrap enough runs)."""
    values = _runs_by_windows(np.asarray(run_means, dtype=float)[:, None], "run_means")[:, 0]
    n = values.size
    mean = float(values.mean())
    half = float(t_dist.ppf(0.5 * (1.0 + level), n - 1) * values.std(ddof=1) / math.sqrt(n))
    boot = values[rng.integers(0, n, size=(resamples, n))].mean(axis=1)
    tail = 0.5 * (1.0 - level)
    low, high = np.quantile(boot, [tail, 1.0 - tail])
    return mean, (mean - half, mean + half), (float(low), float(high))


def lag_correlation(values: FloatArray, lag: int) -> float:
    """The correlation between a run's window ``k`` and window ``k + lag``, pooled over the runs of ``values[i, k]``;
    each window index centred and scaled over the runs, so a drift with ``k`` shared by all runs does not count."""
    array = _runs_by_windows(values, "values")
    if not 1 <= lag < array.shape[1]:
        raise SpaceIdInputError(f"lag: expected 1 to {array.shape[1] - 1}, got {lag}")
    std = array.std(axis=0)
    scaled = (array - array.mean(axis=0)) / np.where(std > 0.0, std, 1.0)
    return float(np.mean(scaled[:, :-lag] * scaled[:, lag:]))


def lag_correlation_null(values: FloatArray, lag: int, rng: np.random.Generator, draws: int = 2000) -> FloatArray:
    """:func:`lag_correlation` of ``draws`` copies of ``values`` whose runs are shuffled independently at each window
    index (from ``rng``): its spread when a run's windows are independent, with each window's values kept."""
    array = _runs_by_windows(values, "values")
    n_runs, n_windows = array.shape
    order = np.argsort(rng.random((draws, n_runs, n_windows)), axis=1)
    return np.array([lag_correlation(np.take_along_axis(array, o, axis=0), lag) for o in order])
