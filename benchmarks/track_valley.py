"""The valley of a mission's first window along the fuel consumed, and where its posterior's mass lies.

Per mission seed (paper6, the first window of ``spaceid track``'s mission): ``hybrid``'s fit polished again from its
mirror images (the lowest minimum), then the slices of :func:`estimators.fuel_posterior.valley_slices`: at each fuel
on the grid the tank polished inside the physical box, the cost above the minimum in chi-square units
``Delta RSS / sigma^2``, the tank's conditional Cramér-Rao std and the slice's share of the posterior's mass by
Laplace's estimate (the marginal in the fuel, integrated over each cell); then the posterior's mean and std from the
importance sampler (:class:`estimators.fuel_posterior.FuelPaths`) with ``--repeats`` generator seeds, its draws and
effective sample size, and the weighted fraction of its draws per band of fuel.

Usage::

    python benchmarks/track_valley.py 322 --repeats 3
"""

from __future__ import annotations

import argparse

import numpy as np

from estimators.evaluation import estimator_from_spec
from estimators.fuel_posterior import FuelPaths, basin_minima, physical_prior_box, valley_slices
from estimators.problem import IdentificationModel
from spaceid_gym.robots import load_robot
from spaceid_gym.tracking import simulate_mission


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", type=int, nargs="+", help="mission seeds")
    parser.add_argument("--repeats", type=int, default=3, help="generator seeds of the sampler per mission")
    args = parser.parse_args()
    model = IdentificationModel(load_robot("paper6"), "fuel")
    for seed in args.seeds:
        window = simulate_mission("paper6", 1, seed)[0]
        problem = model.problem(window.log)
        fitted = estimator_from_spec("hybrid", seed=seed).fit_problem(problem).theta
        best, *others = basin_minima(problem, fitted)
        noise = problem.noise_std(best)[0]
        scale = 3 * problem.n_samples / noise**2
        lower, upper = physical_prior_box(problem)
        slices, log_mass = valley_slices(problem, best, noise, lower, upper)
        share = np.exp(log_mass - np.logaddexp.reduce(log_mass))
        print(
            f"seed {seed}: truth {np.round(window.theta_true, 3)}, hybrid {np.round(fitted, 3)}, lowest minimum {np.round(best, 3)}"
        )
        print("  fuel kg | chi-square above the minimum | tank m | tank conditional std m | Laplace share of the mass")
        for (theta, cov), part in zip(slices, share, strict=True):
            chi = float((problem.cost(theta[None], count=False)[0] - problem.cost(best[None], count=False)[0]) * scale)
            std = np.sqrt(np.diag(cov)[1:] - cov[0, 1:] ** 2 / cov[0, 0])
            print(f"  {theta[0]:7.2f} | {chi:7.2f} | {np.round(theta[1:], 3)} | {np.round(std, 3)} | {part:.3f}")
        for repeat in range(args.repeats):
            paths = FuelPaths(problem, best, noise, np.random.default_rng(seed + repeat), basins=others)
            posterior = paths.posterior()
            weights = np.exp(paths.log_weights - paths.log_weights.max())
            weights /= weights.sum()
            bands = np.histogram(paths.theta[:, 0], bins=[0, 3, 6, 12, 24, 48, 96, upper[0]], weights=weights)[0]
            error = posterior.mean - window.theta_true
            print(
                f"  sampler seed {seed + repeat}: {np.round(posterior.mean, 3)} +- {np.round(np.sqrt(np.diag(posterior.covariance)), 3)}, "
                f"{posterior.effective_samples:.0f} effective in {posterior.draws} draws, NEES "
                f"{float(error @ np.linalg.solve(posterior.covariance, error)):.2f}; mass in fuel 0-3-6-12-24-48-96-"
                f"{upper[0]:.1f} kg: {' '.join(f'{b:.2f}' for b in bands)}"
            )


if __name__ == "__main__":
    main()
