"""The first window's posterior sampler covers a posterior whose mass lies along the cost's valley in the fuel, far
from the fit (:func:`estimators.fuel_posterior.valley_slices`; issue 23, mission 322)."""

from __future__ import annotations

import numpy as np

from estimators.fuel_posterior import MIN_EFFECTIVE_SAMPLES, FuelPaths, physical_prior_box, valley_slices
from estimators.least_squares import LevenbergMarquardt
from estimators.problem import IdentificationModel
from spaceid_gym.robots import load_robot
from spaceid_gym.tracking import burn_rms_kg, simulate_mission

#: mission 322's first window, the posterior's mean and std (fuel kg, tank x, y, z m) by plain importance sampling from
#: the uniform physical prior (weights the likelihood alone, no proposal to design): 3 000 000 draws, 906 effective
#: (/tmp script of the change's commit: ``lower + (upper - lower) * rng.random``, ``default_rng(12345)``)
REFERENCE_MEAN = np.array([18.80, -0.1995, -0.0419, -0.2276])
REFERENCE_STD = np.array([15.43, 0.0631, 0.0424, 0.0814])
REFERENCE_EFFECTIVE = 906.0


def test_a_posterior_along_the_valley_far_from_the_fit_is_sampled_and_matches_plain_prior_sampling() -> None:
    # the cost's minimum is at 47.5 kg (truth 27.5, Cramér-Rao std 21 kg) on a valley floor that rises 3.1
    # chi-square units down to 3.9 kg while the tank's conditional volume grows as ~mdf^-3: the posterior is
    # 18.8 +- 15.4 kg; a proposal around the fit alone reached 70-91 effective draws in 64 000 and raised
    window = simulate_mission("paper6", 1, 322)[0]
    problem = IdentificationModel(load_robot("paper6"), "fuel").problem(window.log)
    fit = LevenbergMarquardt().polish(problem, window.theta_true).theta
    assert abs(fit[0] - 47.5) < 0.5
    noise = problem.noise_std(fit)[0]
    lower, upper = physical_prior_box(problem)
    slices, log_mass = valley_slices(problem, fit, noise, lower, upper)
    heaviest = slices[int(np.argmax(log_mass))][0]
    assert heaviest[0] < 0.5 * fit[0]  # the valley's mass per cell peaks at low fuel, far from the fit
    posterior = FuelPaths(problem, fit, noise, np.random.default_rng(0)).posterior()
    assert posterior.effective_samples >= MIN_EFFECTIVE_SAMPLES
    # Monte Carlo error of a mean: std / sqrt(effective draws), the reference's and the sampler's; 4 of their
    # combined std (20 generator seeds: the sampler's fuel mean 18.13 with a run-to-run std of 0.33 kg)
    tolerance = 4.0 * REFERENCE_STD * np.sqrt(1.0 / REFERENCE_EFFECTIVE + 1.0 / posterior.effective_samples)
    assert np.all(np.abs(posterior.mean - REFERENCE_MEAN) < tolerance)
    # a std's relative error ~ sqrt((kurtosis - 1) / 4n), 0.03 for the reference with a kurtosis up to 4: 15 % is
    # about 4 of the combined (the sampler's fuel std over 20 seeds: 14.99 with a run-to-run std of 0.18 kg)
    np.testing.assert_allclose(np.sqrt(np.diag(posterior.covariance)), REFERENCE_STD, rtol=0.15)


def test_a_window_sampled_afresh_draws_from_its_own_valley_whatever_the_guess() -> None:
    # mission 322's window 1 (truth 49.6 kg, the window's own least-squares minimum 51.0 kg): the first window's
    # posterior pushed over the gap keeps under 200 effective paths, so the window is sampled afresh; the filter's guess
    # was 17.8 +- 2.8 kg (its Gaussian update of a wide, curved prior over-counts), and a proposal from that guess and
    # the kernel prior reached 154 effective draws in 64 000 and raised. The exact push of 200 000 first-window paths
    # (30 000 effective; 80 effective after window 1) gives 40.5 +- 9.5 kg; the kernel prior's smoothing of the first
    # posterior moves the fresh sample's mean by a fraction of a std (0.31 std on mission 241's window 1)
    windows = simulate_mission("paper6", 2, 322)
    model = IdentificationModel(load_robot("paper6"), "fuel")
    first, second = (model.problem(window.log) for window in windows)
    fit = LevenbergMarquardt().polish(first, windows[0].theta_true).theta
    noise = first.noise_std(fit)[0]
    paths = FuelPaths(first, fit, noise, np.random.default_rng(0))
    guess = np.array([17.84, -0.212, -0.062, -0.300]), np.diag([2.84, 0.0165, 0.0166, 0.0252]) ** 2
    paths.extend(second, noise, burn_rms_kg("paper6"), guess)
    posterior = paths.posterior()
    assert paths.regularised and posterior.effective_samples >= MIN_EFFECTIVE_SAMPLES
    exact_mean_kg, exact_std_kg = 40.5, 9.5
    assert abs(posterior.mean[0] - exact_mean_kg) < 0.5 * exact_std_kg
    assert abs(np.sqrt(posterior.covariance[0, 0]) - exact_std_kg) < 0.25 * exact_std_kg
