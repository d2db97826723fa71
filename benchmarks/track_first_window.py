"""Where the mission tracker's first-window NEES comes from: hybrid's fit of each mission's first window against the
truth, in its Cramér-Rao covariance and in the posterior covariance under the physical prior.

Per mission seed (paper6, the first window of ``spaceid track``'s mission, 27.5 kg consumed): ``z = error / std``
per unknown and the NEES against the Cramér-Rao covariance at the fit; the NEES against the bound evaluated at the
truth instead; the likelihood ratio of the truth ``(RSS(truth) - RSS(fit)) / sigma^2`` (chi-square(4) for a
Gaussian likelihood, whatever the curvature: if it is near 4 while the NEES is not, the covariance, not the fit, is
wrong); how far a local polish started at the truth ends from the fit, in std (0: the fit is the minimum the truth
lies in, not a local basin); then the NEES against the posterior mean and covariance the tracker now starts from
(:func:`estimators.fuel_posterior.fuel_posterior`, seeded by the mission seed) and its effective sample size.
Over the seeds: the mean ``z^2`` per unknown and the mean and median of each statistic.

Usage::

    python benchmarks/track_first_window.py 230 259
"""

from __future__ import annotations

import argparse

import numpy as np

from estimators.evaluation import estimator_from_spec
from estimators.fuel_posterior import fuel_posterior
from estimators.least_squares import LevenbergMarquardt
from estimators.problem import IdentificationModel
from spaceid_gym.robots import load_robot
from spaceid_gym.tracking import simulate_mission


def _nees(error: np.ndarray, cov: np.ndarray) -> float:
    return float(error @ np.linalg.solve(cov, error))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("first", type=int, help="first mission seed")
    parser.add_argument("last", type=int, help="last mission seed (inclusive)")
    args = parser.parse_args()
    model = IdentificationModel(load_robot("paper6"), "fuel")
    rows = []
    print(
        "seed | z fuel, tank x, y, z (bound at the fit) | NEES bound | NEES bound at truth | LR truth | polish from truth (std) | NEES posterior | ESS"
    )
    for seed in range(args.first, args.last + 1):
        window = simulate_mission("paper6", 1, seed)[0]
        problem = model.problem(window.log)
        theta = estimator_from_spec("hybrid", seed=seed).fit_problem(problem).theta
        truth = window.theta_true
        noise = problem.noise_std(theta)[0]
        bound = np.linalg.inv(problem.fisher(theta, noise))
        std = np.sqrt(np.diag(bound))
        z = (theta - truth) / std
        at_truth = np.linalg.inv(problem.fisher(truth, noise))
        costs = problem.cost(np.array([truth, theta]), count=False)
        ratio = float((costs[0] - costs[1]) * 3 * problem.n_samples / noise**2)
        polished = LevenbergMarquardt().polish(problem, truth).theta
        posterior = fuel_posterior(problem, theta, noise, np.random.default_rng(seed))
        row = [*z, _nees(theta - truth, bound), _nees(theta - truth, at_truth), ratio]
        row += [float(np.max(np.abs(polished - theta) / std)), _nees(posterior.mean - truth, posterior.covariance)]
        rows.append(row)
        print(
            f"{seed:4d} | {' '.join(f'{v:+5.2f}' for v in z)} | {row[4]:7.2f} | {row[5]:7.2f} | {ratio:6.2f} | "
            f"{row[7]:.1e} | {row[8]:6.2f} | {posterior.effective_samples:5.0f}",
            flush=True,
        )
    table = np.array(rows)
    print(
        f"{len(rows)} first windows; mean z^2 per unknown (fuel, tank x, y, z): {np.round(np.mean(table[:, :4] ** 2, axis=0), 2)}"
    )
    for name, column in (("NEES bound", 4), ("NEES bound at truth", 5), ("likelihood ratio", 6), ("NEES posterior", 8)):
        print(
            f"{name:20s}: mean {table[:, column].mean():6.2f}, median {np.median(table[:, column]):5.2f} (chi-square(4): 4, 3.36)"
        )
    print(f"polish from the truth: at most {table[:, 7].max():.1e} std from the fit")


if __name__ == "__main__":
    main()
