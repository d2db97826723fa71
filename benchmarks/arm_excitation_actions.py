"""The arm's learnt excitation: which action space, measured with random actions (nothing learnt).

On ``--windows`` validation windows of ``ManipulatorID-v0`` (seeds drawn from 900,000 - 999,999 as the evaluation
callback's, at 125 Hz, 30 s), prints each window's return (the env's information gain minus its limit penalties)
for uniform random actions held 0.5 s read as:

* ``targets``: target angles followed at up to the rate limit (the policy's action space, :mod:`agents.arm_policy`);
* ``targets_half``: the same with half the reach (targets within half the allowed travel);
* ``rates``: joint-rate commands held 0.5 s (the env's own action, as the satellite's first design had).

Usage::

    python benchmarks/arm_excitation_actions.py [--windows 3]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np

from agents.arm_policy import ARM_TASK, ArmExcitationEnv
from agents.excitation_task import VALIDATION_FIRST_SEED


def window_return(wrapper: ArmExcitationEnv, seed: int, command: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> float:
    """One window's return: every 0.5 s a uniform random action, turned into the env's command every step."""
    wrapper.reset(seed=seed)
    env, rng, total = wrapper.env, np.random.default_rng(seed), 0.0
    observation = wrapper._last
    for _ in range(wrapper.decisions):
        action = rng.uniform(-1.0, 1.0, env.robot.n_joints).astype(np.float32)
        for _ in range(wrapper.hold_steps):
            observation, reward, *_ = env.step(command(action, observation))
            total += reward
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--windows", type=int, default=3)
    args = parser.parse_args()
    wrapper = ArmExcitationEnv(first_seed=VALIDATION_FIRST_SEED, n_seeds=100_000)
    robot, n = wrapper.env.robot, wrapper.env.robot.n_joints
    commands = {
        "targets": lambda a, obs: ARM_TASK.rate_command(a, obs[:n], robot),
        "targets_half": lambda a, obs: ARM_TASK.rate_command(0.5 * a, obs[:n], robot),
        "rates": lambda a, obs: a,
    }
    for name, command in commands.items():
        returns = [window_return(wrapper, seed, command) for seed in range(args.windows)]
        print(f"{name:13s} returns per window: {', '.join(f'{r:.1f}' for r in returns)}")


if __name__ == "__main__":
    main()
