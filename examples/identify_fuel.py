"""Identify a satellite's fuel state from one window, with several estimators, in Python and in the env loop.

    python examples/identify_fuel.py [--robot paper6] [--duration 60] [--seed 0]

1. Simulate a window (Fourier excitation, documented sensor noise) with a known fuel state.
2. Fit ``improved-pso``, ``lm`` and the default ``hybrid`` on its log (scikit-learn style:
   ``make_estimator(name).fit(model, log)``) and print each estimate against the truth in units of
   the Cramér-Rao standard deviation it reports.
3. Run ``FreeFloatingID-v0`` with ``estimator="hybrid"``: the window's last ``info`` holds the
   estimate and its errors.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import spaceid_gym  # noqa: F401  (registers FreeFloatingID-v0)
from agents import FourierExcitation
from estimators.problem import IdentificationModel
from estimators.registry import make_estimator
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.robots import load_robot


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="paper6")
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    robot = load_robot(args.robot)
    fuel_kg = 0.15 * robot.base_full.mass_kg
    tank_m = np.array([0.6, -0.4, 0.3]) * (
        0.6 * np.sqrt(np.trace(robot.base_full.inertia_com_kgm2) / (2 * robot.base_full.mass_kg))
    )
    env = simulate_episode(robot, args.duration, fuel_kg, tank_m, FourierExcitation(robot.n_joints, args.seed), args.seed)
    log = env.measurement_log()
    truth = np.concatenate(([fuel_kg], tank_m))
    print(
        f"window: {log.n_samples} samples over {log.duration_s:.0f} s; true fuel consumed {fuel_kg:.2f} kg, tank {tank_m.round(4)} m"
    )

    model = IdentificationModel(robot, "fuel")
    for name in ("improved-pso", "lm", "hybrid"):
        estimate = make_estimator(name, seed=args.seed).fit(model, log)
        in_std = (estimate.theta - truth) / estimate.theta_std
        print(
            f"{name:>13}: mdf {estimate.theta[0]:8.3f} +- {estimate.theta_std[0]:.3f} kg, tank {estimate.theta[1:].round(4)} m; "
            f"error {in_std.round(2)} std; {estimate.n_evaluations:.0f} evaluations, {estimate.wall_time_s:.2f} s"
        )
        for message in estimate.insufficient_excitation:
            print("               " + message)

    steps = round(args.duration / 0.02)
    env_loop = gym.make(
        "FreeFloatingID-v0", robot=args.robot, estimator="hybrid", max_episode_steps=steps, identify_after_steps=steps
    )
    env_loop.reset(seed=args.seed)
    excitation = FourierExcitation(robot.n_joints, args.seed)
    for k in range(steps):
        *_, info = env_loop.step(excitation(0.02 * k))
    errors = info["estimate_errors"]
    print(
        f"env loop (hybrid): fuel consumed {info['estimate']['fuel_consumed_kg']:.2f} kg (true {info['truth']['fuel_consumed_kg']:.2f}); "
        f"errors M {errors['M']:.3f} %, r {errors['r']:.2f} %, Ixx {errors['Ixx']:.3f} %, Iyy {errors['Iyy']:.3f} %, Izz {errors['Izz']:.3f} %"
    )


if __name__ == "__main__":
    main()
