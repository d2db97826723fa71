"""The mission tracker carries the exact posterior (importance-sampled paths) through the windows where the unscented
filter's Gaussian update would be over-confident, and hands the mission to the filter once the two agree
(:mod:`spaceid_gym.tracking`, :class:`estimators.fuel_posterior.FuelPaths`)."""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from estimators.fuel_posterior import FuelPosterior, expected_nees
from spaceid_gym.tracking import HANDOVER_NEES, UNKNOWNS, simulate_mission, track_mission

#: chi-square(4)'s 99.9 % point: a consistent covariance puts the truth beyond it once in a thousand windows
NEES_999 = float(chi2.ppf(0.999, UNKNOWNS))


def test_the_second_window_keeps_the_exact_posterior_where_the_filter_over_counts() -> None:
    # mission 241: the first window's posterior is wide and curved (10.5 +- 7.1 kg, truth 27.5 kg); the filter's
    # plain pass over window 1 from it ended at 20.3 +- 5.1 kg against the true 44.3 kg (NEES 125, the tracker before);
    # the exact posterior of window 1 is 29.2 +- 7.5 kg (NEES 7.3), and the filter's Gaussian would average a NEES of
    # 22.6 under it, so the tracker keeps the posterior and does not hand over yet
    rows, _ = track_mission(simulate_mission("paper6", 2, 241), "paper6", seed=241)
    second = rows[1]
    assert second["exact_posterior"] == 1
    assert second["handover_nees"] > HANDOVER_NEES
    assert second["ukf_nees"] < NEES_999
    assert abs(second["ukf_fuel_consumed_kg"] - second["true_fuel_consumed_kg"]) < 3.0 * second["ukf_fuel_std_kg"]


def test_the_expected_nees_is_the_dimension_when_the_gaussians_agree() -> None:
    rng = np.random.default_rng(0)
    root = rng.standard_normal((4, 4))
    cov = root @ root.T + 4.0 * np.eye(4)
    posterior = FuelPosterior(np.arange(4.0), cov, 1000, 1000.0)
    assert np.isclose(expected_nees(posterior, posterior.mean, cov), 4.0, rtol=1e-12)
    # a filter half as wide and one std off along the first unknown: tr(2 I) + 2 d^T C^-1 d, above the bound
    d = np.sqrt(cov[0, 0]) * np.eye(4)[0]
    shifted = expected_nees(posterior, posterior.mean + d, 0.5 * cov)
    assert np.isclose(shifted, 8.0 + 2.0 * d @ np.linalg.solve(cov, d), rtol=1e-12)
    assert shifted > HANDOVER_NEES
