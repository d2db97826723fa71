"""Streaming cost of the unscented Kalman filter (``ukf``) per gyro sample, next to one ``lm`` fit of the same window.

The window: paper6, ``--seconds`` at 50 Hz (Fourier excitation, nominal sensors, mdf 60 kg, tank (0.25, -0.2, 0.1)
m), model ``fuel`` with the sensors' gyro noise. Figures (medians over ``--repeats`` runs after one warm-up run
of each, every run on a fresh problem):

* the streaming filter, one pass (:meth:`~estimators.ukf.UKFTracker.update` sample by sample): cost per sample
  and how many times faster than real time the log's sample rate it runs (the per-log set-up of the arm's terms,
  one composite-inertia computation per sample, included, as in the fits);
* ``ukf`` ``fit`` on the window (the global start, then ``passes`` tempered passes, default 6);
* the reference: one ``lm`` fit of the same window (least squares from the default start, analytic Jacobian),
  and the ratios of both ``ukf`` figures to it;
* the streaming pass again with filterpy's own ``predict`` and ``cross_variance`` (the filter's class set back to
  filterpy's :class:`~filterpy.kalman.UnscentedKalmanFilter`), the ratio of the two and the largest difference of
  their final states in the unknowns' scales (:class:`~estimators.ukf.RandomWalkUKF` computes the same in closed
  form).

Usage::

    python benchmarks/ukf_speed.py [--seconds 60] [--repeats 3] [--passes 6]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np
from filterpy.kalman import UnscentedKalmanFilter

from estimators.problem import IdentificationModel
from estimators.registry import make_estimator
from estimators.ukf import UKFTracker, UnscentedKalman
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.log import MeasurementLog
from spaceid_gym.robots import load_robot


def _median_time(run: Callable[[], object], repeats: int) -> float:
    """Median wall time (s) of ``run`` over ``repeats`` calls, after one warm-up call."""
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="window length, s (50 Hz)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--passes", type=int, default=6, help="tempered passes of the ukf fit")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats: expected at least 1, got {args.repeats}")
    robot = load_robot("paper6")
    theta = np.array([60.0, 0.25, -0.2, 0.1])
    env = simulate_episode(
        robot, args.seconds, theta[0], theta[1:], FourierExcitation(robot.n_joints, seed=args.seed), seed=args.seed
    )
    log = env.measurement_log()
    model = IdentificationModel(robot, "fuel", noise_std_rad_s=env.sensors.gyro_std_rad_s(env.control_period_s))
    ukf = UnscentedKalman(passes=args.passes)

    def fresh() -> MeasurementLog:
        return log.window(float(log.t_s[0]), float(log.t_s[-1]) + 1.0)

    def stream(plain: bool = False) -> UKFTracker:
        tracker = ukf.tracker(model.problem(fresh()))
        if plain:
            tracker.filter.__class__ = UnscentedKalmanFilter  # filterpy's own predict and cross variance
        for index in range(log.n_samples):
            tracker.update(index)
        return tracker

    stream_s = _median_time(stream, args.repeats)
    plain_s = _median_time(lambda: stream(plain=True), args.repeats)
    scale = np.asarray(model.problem(log).parameters.scale, dtype=float)
    state_difference = float(np.max(np.abs(stream().estimate()[0] - stream(plain=True).estimate()[0]) / scale))
    fit_s = _median_time(lambda: ukf.fit(model, fresh()), args.repeats)
    lm_s = _median_time(lambda: make_estimator("lm").fit(model, fresh()), args.repeats)
    per_sample_us = 1e6 * stream_s / log.n_samples
    sample_period_s = float(np.median(np.diff(log.t_s)))
    print(f"window: {log.n_samples} samples, {args.seconds:g} s at {1.0 / sample_period_s:.0f} Hz (paper6, fuel)")
    print(f"ukf streaming, one pass:      {stream_s:8.3f} s  = {per_sample_us:7.1f} us per sample")
    print(f"                              {sample_period_s / (stream_s / log.n_samples):8.0f} x faster than real time")
    print(f"ukf fit, {args.passes} tempered passes:  {fit_s:8.3f} s")
    print(f"reference: one lm fit:        {lm_s:8.3f} s")
    print(f"ratio ukf streaming / lm fit: {stream_s / lm_s:8.2f}")
    print(f"ratio ukf fit / lm fit:       {fit_s / lm_s:8.2f}")
    print(f"reference: the streaming pass with filterpy's predict and cross variance: {plain_s:8.3f} s")
    print(f"ratio ukf streaming / filterpy's steps: {stream_s / plain_s:8.2f}")
    print(f"largest difference of the final states, in the unknowns' scales: {state_difference:.1e}")


if __name__ == "__main__":
    main()
