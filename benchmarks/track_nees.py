"""Where the tracking filter's NEES comes from: each window's error per unknown in the filter's own std.

For each mission seed: the mission of ``spaceid track`` (paper6, 10 windows, the first taken as ``--first-window``
says: ``posterior`` by default, ``batch`` for ``hybrid``'s fit with its Cramér-Rao covariance), then the filter
window by window with ``--passes`` tempered passes over each later window (1: the plain filter ``spaceid track``
runs; P: the noise variance times P, state and covariance carried, as the ``ukf`` estimator's fit does). Prints per window the NEES and ``z = error / std`` of the fuel consumed and of
the three tank coordinates, then the mission's mean NEES. A consistent filter has z ~ N(0, 1) in each unknown
and the mean NEES within the 95 % bounds of chi-square(4)'s mean (bounds that take the windows as independent).
Over two or more seeds: per unknown the mean ``z^2`` over every window and the correlation of a mission's window
``k`` and ``k + lag`` (lags 1-3) pooled over the seeds, against its 95 % range when the missions are shuffled at
each window index (seeded): how far the windows of a mission are from independent.

Usage::

    python benchmarks/track_nees.py --passes 1 --first-window batch 102 105 101
"""

from __future__ import annotations

import argparse

import numpy as np

from estimators.problem import IdentificationModel
from spaceid_gym.robots import load_robot
from spaceid_gym.track_statistics import lag_correlation, lag_correlation_null, mean_bounds
from spaceid_gym.tracking import DEFAULT_GAP_S, _ukf, first_window_tracker, mission_random_walk, simulate_mission

#: the fuel problem's unknowns, in the filter's order
UNKNOWNS = ("fuel", "tank x", "tank y", "tank z")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", type=int, nargs="+", help="mission seeds")
    parser.add_argument("--passes", type=int, default=1, help="tempered passes over each later window (default 1)")
    parser.add_argument("--first-window", choices=("posterior", "batch"), default="posterior", help="the first window's start")
    args = parser.parse_args()
    model = IdentificationModel(load_robot("paper6"), "fuel")
    low, high = mean_bounds(4, 10)
    z_all = []
    for seed in args.seeds:
        windows = simulate_mission("paper6", 10, seed)
        tracker, noise, nees, z_mission = None, 0.0, [], []
        for window in windows:
            problem = model.problem(window.log)
            if tracker is None:
                tracker = first_window_tracker(_ukf("ukf", seed), problem, args.first_window, seed)
                tracker.random_walk = mission_random_walk("paper6", DEFAULT_GAP_S)
                noise = tracker.noise_std_rad_s
            else:
                tracker.advance(DEFAULT_GAP_S)
                tracker.bind(problem)
                tracker.set_noise(noise)
                for _ in range(args.passes):
                    tracker.rewind()
                    for index in range(problem.n_samples):
                        tracker.update(index, weight=1.0 / args.passes)
            x, cov = tracker.estimate()
            noise = problem.noise_std(x)[0]
            error = x - window.theta_true
            nees.append(float(error @ np.linalg.solve(cov, error)))
            z = error / np.sqrt(np.diag(cov))
            z_mission.append(z)
            print(f"seed {seed} window {window.index}: NEES {nees[-1]:8.2f}  z fuel {z[0]:+6.2f}  z tank {np.round(z[1:], 2)}")
        print(f"seed {seed}: mean NEES {np.mean(nees):.2f} (95 % bounds {low:.2f}-{high:.2f})")
        z_all.append(z_mission)
    if len(z_all) > 1:
        print_z_correlation(np.array(z_all), np.random.default_rng(0))


def print_z_correlation(z: np.ndarray, rng: np.random.Generator) -> None:
    """Per unknown: mean ``z^2`` and the lag-1..3 correlation of ``z[mission, window, unknown]`` across windows."""
    print(f"per unknown over {z.shape[0]} missions [95 % range of the correlation if a mission's windows were independent]:")
    for index, name in enumerate(UNKNOWNS):
        values = z[:, :, index]
        cells = []
        for lag in (1, 2, 3):
            null_low, null_high = np.quantile(lag_correlation_null(values, lag, rng, draws=1000), [0.025, 0.975])
            cells.append(f"lag {lag} {lag_correlation(values, lag):+.2f} [{null_low:+.2f}, {null_high:+.2f}]")
        print(f"  z {name:6s}: mean z^2 {np.mean(values**2):5.2f}; " + "; ".join(cells))


if __name__ == "__main__":
    main()
