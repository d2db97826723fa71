"""Quick start: run FreeFloatingID-v0 with an excitation, read its log, check the momentum model.

    python examples/quickstart.py [--robot paper6] [--duration 30] [--seed 0]

Prints the true fuel state (from ``info``), what the log holds, the Cramér-Rao bound the window
leaves on the fuel parameters, and how well eq. 8 with the true and the nominal base predicts
the measured base rate.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import spaceid_gym  # noqa: F401  (registers FreeFloatingID-v0)
from agents import FourierExcitation
from spaceid_gym.physics.fuel import base_after_fuel
from spaceid_gym.physics.momentum import base_rate_from_joint_motion


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="paper6")
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    env = gym.make("FreeFloatingID-v0", robot=args.robot)
    period = env.unwrapped.control_period_s
    _, info = env.reset(seed=args.seed)
    truth = info["truth"]
    print(f"true fuel consumed {truth['fuel_consumed_kg']:.2f} kg, tank at {np.round(truth['tank_position_m'], 3)} m")

    excitation = FourierExcitation(env.action_space.shape[0], seed=args.seed)
    total_reward = 0.0
    for k in range(round(args.duration / period)):
        _, reward, terminated, truncated, info = env.step(excitation(k * period))
        total_reward += float(reward)
        if terminated or truncated:
            break
    log = env.unwrapped.measurement_log()
    print(f"log: {log.n_samples} samples over {log.duration_s:.1f} s; return {total_reward:.2f}")
    std = env.unwrapped.cramer_rao_std()
    print(f"Cramér-Rao bound: std(mdf) {std[0]:.2f} kg, std(bf) {np.round(std[1:], 4)} m")

    robot = env.unwrapped.robot
    true_base = base_after_fuel(robot.base_full, truth["fuel_consumed_kg"], np.array(truth["tank_position_m"]))
    for label, model in (("true base", robot.model_with_base(true_base)), ("nominal full tank", robot.model)):
        residual = log.omega_base_body_rad_s - base_rate_from_joint_motion(model, log.q_rad, log.dq_rad_s)
        print(f"eq. 8 with the {label:17s}: residual RMS {np.sqrt(np.mean(residual**2)):.3e} rad/s")


if __name__ == "__main__":
    main()
