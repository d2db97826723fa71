"""Environment throughput: FreeFloatingID-v0 and ManipulatorID-v0 steps per second next to MuJoCo's Hopper-v5 and
Gymnasium's Pendulum-v1, measured in one run.

Every environment is made with ``gym.make`` (default wrappers) and stepped with pre-sampled random actions in one
process. The repeats are interleaved (repeat 1 of every env, then repeat 2, ...) so that a shared machine's load
falls on all of them alike; the figure printed is the median of ``--repeats`` timed runs of ``--steps`` steps.
Resets are excluded from the time: Hopper-v5 falls over (terminates) every few hundred random steps and is reset
then, outside the clock. The ratios to Hopper-v5 are the figures to quote (absolute rates move with the load).
Hopper-v5 needs MuJoCo (``pip install -e .[bench]``); without it the benchmark says so and compares with
Pendulum-v1 only. Usage::

    python benchmarks/env_steps.py [--steps 3000] [--repeats 7] [--robot paper6]
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import time

import gymnasium as gym
import numpy as np

import spaceid_gym  # noqa: F401  (registers FreeFloatingID-v0 and ManipulatorID-v0)

REFERENCE = "Hopper-v5"


def timed_steps(env: gym.Env, actions: np.ndarray, seed: int) -> float:
    """Seconds spent in ``env.step`` over ``actions``, resets (after termination or truncation) excluded."""
    env.reset(seed=seed)
    elapsed, start = 0.0, time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            elapsed += time.perf_counter() - start
            env.reset()
            start = time.perf_counter()
    return elapsed + time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--robot", default="paper6", help="the free-floating robot")
    args = parser.parse_args()
    envs = {
        "FreeFloatingID-v0": gym.make("FreeFloatingID-v0", robot=args.robot, max_episode_steps=args.steps + 1),
        "ManipulatorID-v0": gym.make("ManipulatorID-v0", max_episode_steps=args.steps + 1),
        "Pendulum-v1": gym.make("Pendulum-v1", max_episode_steps=args.steps + 1),
    }
    if importlib.util.find_spec("mujoco") is not None:
        envs[REFERENCE] = gym.make(REFERENCE, max_episode_steps=args.steps + 1)
    else:
        print(f"MuJoCo is not installed: no {REFERENCE} reference (pip install -e .[bench]); ratios to Pendulum-v1 only")
    rng = np.random.default_rng(0)
    actions = {
        name: rng.uniform(env.action_space.low, env.action_space.high, size=(args.steps, *env.action_space.shape)).astype(
            env.action_space.dtype
        )
        for name, env in envs.items()
    }
    for name, env in envs.items():  # warm-up: compilation and caches outside the clock
        timed_steps(env, actions[name][:50], seed=0)
    seconds: dict[str, list[float]] = {name: [] for name in envs}
    for r in range(args.repeats):
        for name, env in envs.items():
            seconds[name].append(timed_steps(env, actions[name], seed=r))
    rate = {name: args.steps / statistics.median(times) for name, times in seconds.items()}
    references = [name for name in (REFERENCE, "Pendulum-v1") if name in rate]
    header = f"{'environment':<20} {'steps/s':>10}" + "".join(f" {'/ ' + name:>16}" for name in references)
    print(f"median of {args.repeats} interleaved runs of {args.steps} random steps each")
    print(header)
    for name in envs:
        print(f"{name:<20} {rate[name]:10.0f}" + "".join(f" {rate[name] / rate[ref]:16.3f}" for ref in references))
    for name in ("FreeFloatingID-v0", "ManipulatorID-v0"):
        period = envs[name].unwrapped.control_period_s
        print(f"{name}: control period {period} s, {rate[name] * period:.1f} simulated s per wall second")


if __name__ == "__main__":
    main()
