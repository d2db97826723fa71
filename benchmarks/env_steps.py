"""Environment throughput: FreeFloatingID-v0 steps per second next to Gymnasium's Pendulum-v1.

Both environments are made with ``gym.make`` (default wrappers) and stepped with the same
pre-sampled random actions in one process; the figure printed is the median of ``--repeats``
timed runs of ``--steps`` steps (resets excluded). Usage::

    python benchmarks/env_steps.py [--steps 3000] [--repeats 5] [--robot paper6]
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import spaceid_gym  # noqa: F401  (registers FreeFloatingID-v0)


def steps_per_second(env: gym.Env, steps: int, repeats: int, seed: int = 0) -> float:
    """Median steps/s over ``repeats`` runs of ``steps`` steps with random actions."""
    rng = np.random.default_rng(seed)
    low, high = env.action_space.low, env.action_space.high
    actions = rng.uniform(low, high, size=(steps, *env.action_space.shape)).astype(env.action_space.dtype)
    rates = []
    for r in range(repeats):
        env.reset(seed=seed + r)
        start = time.perf_counter()
        for action in actions:
            env.step(action)
        rates.append(steps / (time.perf_counter() - start))
    return statistics.median(rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--robot", default="paper6")
    args = parser.parse_args()
    ours = gym.make("FreeFloatingID-v0", robot=args.robot, max_episode_steps=args.steps + 1)
    reference = gym.make("Pendulum-v1", max_episode_steps=args.steps + 1)
    sps_ours = steps_per_second(ours, args.steps, args.repeats)
    sps_ref = steps_per_second(reference, args.steps, args.repeats)
    period = ours.unwrapped.control_period_s
    print(f"FreeFloatingID-v0 ({args.robot}, control period {period} s): {sps_ours:10.0f} steps/s")
    print(f"Pendulum-v1 (reference)                        : {sps_ref:10.0f} steps/s")
    print(f"ratio FreeFloatingID-v0 / Pendulum-v1          : {sps_ours / sps_ref:10.3f}")
    print(f"simulated time per wall second                 : {sps_ours * period:10.1f} s/s")


if __name__ == "__main__":
    main()
