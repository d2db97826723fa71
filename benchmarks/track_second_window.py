"""Where the mission tracker's second-window NEES comes from: the unscented filter's Gaussian after window 1 against
the exact posterior of window 1 (importance-sampled paths, :class:`estimators.fuel_posterior.FuelPaths`).

Per mission seed (paper6, the first two windows of ``spaceid track``'s mission): the filter as the tracker runs it
(started at window 0's posterior mean and covariance, the random walk over the gap, one plain pass over window 1);
the exact posterior of window 1, ``prior_1 x L_1`` with ``prior_1`` window 0's posterior paths pushed through the
gap's random walk (the same walk the filter assumes, the physical prior's box at both windows); and the posterior
of a Gaussian ``prior_1`` (window 0's posterior mean and covariance plus the walk, the filter's own prior) times the
exact ``L_1``, sampled from that Gaussian: if it agrees with the exact posterior, the prior's shape is not the
cause and the filter's update is; and the kernel prior the tracker falls back on when the exact paths degenerate
(:class:`~estimators.fuel_posterior.PredictedPrior`) times the exact ``L_1``, forced here to compare (where the
paths keep fewer than 200 effective draws through window 1 the tracker's posterior is that kernel step too, and the
line says so). For each: the fuel's mean and std, ``z = error / std`` per unknown (fuel, tank x, y, z) and the
NEES of the truth. Then the NEES the filter's Gaussian would have on average if the truth were drawn from the
tracker's posterior, ``tr(P_f^-1 P) + d^T P_f^-1 d`` (4 when they agree; the tracker's hand-over statistic), and
which unknowns carry the filter's NEES: its share along each axis of the filter's covariance, each axis given by
its 1-std step in each unknown's filter std (a small step in every unknown: a combination the filter holds much
tighter than each).

Usage::

    python benchmarks/track_second_window.py 241 244 233
"""

from __future__ import annotations

import argparse

import numpy as np

from estimators.evaluation import estimator_from_spec
from estimators.fuel_posterior import FuelPaths, physical_prior_box
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.robots import load_robot
from spaceid_gym.tracking import DEFAULT_GAP_S, _ukf, mission_random_walk, simulate_mission

#: draws from the Gaussian prior (its importance weights are window 1's likelihood alone)
GAUSSIAN_DRAWS = 40000


def _line(name: str, mean: FloatArray, cov: FloatArray, truth: FloatArray) -> str:
    std = np.sqrt(np.diag(cov))
    error = mean - truth
    nees = float(error @ np.linalg.solve(cov, error))
    z = " ".join(f"{v:+6.2f}" for v in error / std)
    return f"  {name:26s} fuel {mean[0]:6.2f} +- {std[0]:5.2f} kg | z {z} | NEES {nees:7.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", type=int, nargs="+", help="mission seeds")
    args = parser.parse_args()
    robot = load_robot("paper6")
    model = IdentificationModel(robot, "fuel")
    schedule = FuelSchedule()
    step_std_kg = float(np.hypot(schedule.mean_step_fraction, schedule.std_step_fraction) * robot.base_full.mass_kg)
    walk = mission_random_walk("paper6", DEFAULT_GAP_S)
    for seed in args.seeds:
        first, second = simulate_mission("paper6", 2, seed)
        problem0, problem1 = model.problem(first.log), model.problem(second.log)
        fitted = estimator_from_spec("hybrid", seed=seed).fit_problem(problem0)
        noise0 = problem0.noise_std(fitted.theta)[0]
        paths = FuelPaths(problem0, fitted.theta, noise0, np.random.default_rng(seed))
        before = paths.posterior()
        tracker = _ukf("ukf").tracker(problem0, before.mean, before.covariance)
        tracker.random_walk = walk.copy()
        noise1 = problem0.noise_std(before.mean)[0]
        tracker.advance(DEFAULT_GAP_S)
        prior_cov = tracker.filter.P.copy()
        tracker.bind(problem1)
        tracker.set_noise(noise1)
        tracker.run()
        x_f, p_f = tracker.estimate()
        paths.extend(problem1, noise1, step_std_kg, (x_f, p_f))
        exact = paths.posterior()
        pushed = "kernel (push < 200 ESS)" if paths.regularised else "exact push"
        paths = FuelPaths(problem0, fitted.theta, noise0, np.random.default_rng(seed))
        paths.extend(problem1, noise1, step_std_kg, (x_f, p_f), regularise=True)
        kernel = paths.posterior()
        # the filter's Gaussian prior times the exact likelihood, sampled from the prior (inside the box)
        rng = np.random.default_rng(seed + 1)
        lower, upper = physical_prior_box(problem1)
        draws = rng.multivariate_normal(before.mean, prior_cov, GAUSSIAN_DRAWS)
        draws = draws[np.all((draws > lower) & (draws < upper), axis=1)]
        cost = np.concatenate([problem1.cost(draws[i : i + 1000], count=False) for i in range(0, len(draws), 1000)])
        log_w = -(cost - cost.min()) * 3 * problem1.n_samples / (2.0 * noise1**2)
        w = np.exp(log_w - log_w.max())
        w /= w.sum()
        g_mean = w @ draws
        g_cov = (w[:, None] * (draws - g_mean)).T @ (draws - g_mean)
        truth = second.theta_true
        d = x_f - exact.mean
        expected = float(np.trace(np.linalg.solve(p_f, exact.covariance)) + d @ np.linalg.solve(p_f, d))
        values, vectors = np.linalg.eigh(p_f)
        share = (vectors.T @ (x_f - truth)) ** 2 / values  # the filter's NEES along its covariance's axes
        axes = "; ".join(
            f"{share[i]:.1f} along {np.round(vectors[:, i] * np.sqrt(values[i]) / np.sqrt(np.diag(p_f)), 2)}"
            for i in np.argsort(share)[::-1]
        )
        print(
            f"seed {seed}: window 0 fuel {first.theta_true[0]:.2f} kg, window 1 {truth[0]:.2f} kg (tank {np.round(truth[1:], 3)} m)"
        )
        print(_line("window 0 posterior", before.mean, before.covariance, first.theta_true))
        print(_line("filter prior of window 1", before.mean, prior_cov, truth))
        print(_line("filter after window 1", x_f, p_f, truth))
        print(_line(f"posterior, {pushed}", exact.mean, exact.covariance, truth) + f" | ESS {exact.effective_samples:.0f}")
        print(_line("kernel prior x exact L1", kernel.mean, kernel.covariance, truth) + f" | ESS {kernel.effective_samples:.0f}")
        print(_line("Gaussian prior x exact L1", g_mean, g_cov, truth) + f" | ESS {1.0 / np.sum(w * w):.0f}")
        print(
            f"  filter's expected NEES under the exact posterior {expected:.2f} (4 if they agree); filter's mean NIS "
            f"{np.mean(tracker.nis):.3f}\n  filter's NEES along each axis of its covariance (the axis's 1-std step in "
            f"each unknown's filter std: fuel, tank x, y, z): {axes}",
            flush=True,
        )


if __name__ == "__main__":
    main()
