"""Excitation agent: DummyVecEnv against SubprocVecEnv, then the default training's wall time.

1. Steps ``--envs`` :class:`agents.policy.ExcitationEnv` with random actions in a ``DummyVecEnv`` (one process) and a
   ``SubprocVecEnv`` (one process per env), ``--decisions`` decisions each, and prints decisions per second.
2. Unless ``--no-train``: trains the default policy (PPO, ``--timesteps``, seed 0) into ``--out`` and prints the
   wall time (the issue's target: under 20 minutes on 2 CPU cores).

Usage::

    python benchmarks/excitation_training.py [--envs 2] [--decisions 600] [--timesteps 200000] [--out policy/]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from agents.policy import DEFAULT_ATTITUDE_WEIGHT, DEFAULT_TIMESTEPS, make_vec_env, train_excitation


def decisions_per_second(kind: str, n_envs: int, decisions: int) -> float:
    """Random-action decisions per second (all envs together) of one vectorised env kind."""
    vec = make_vec_env("paper6", n_envs, kind, DEFAULT_ATTITUDE_WEIGHT, 0, 900_000, 0)
    vec.reset()
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, size=(decisions, n_envs, vec.action_space.shape[0]))
    start = time.perf_counter()
    for action in actions.astype(np.float32):
        vec.step(action)
    elapsed = time.perf_counter() - start
    vec.close()
    return decisions * n_envs / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--decisions", type=int, default=600)
    parser.add_argument("--timesteps", type=int, default=DEFAULT_TIMESTEPS)
    parser.add_argument("--out", type=Path, default=Path("excitation-policy"))
    parser.add_argument("--no-train", action="store_true")
    args = parser.parse_args()
    print(f"cores: {os.cpu_count()}, load average before: {os.getloadavg()[0]:.1f}")
    for kind in ("dummy", "subproc"):
        print(f"{kind:8s} VecEnv, {args.envs} envs: {decisions_per_second(kind, args.envs, args.decisions):8.0f} decisions/s")
    if args.no_train:
        return
    start = time.perf_counter()
    train_excitation("paper6", timesteps=args.timesteps, out=args.out)
    print(f"default training ({args.timesteps} timesteps, PPO, 2 envs): {time.perf_counter() - start:.0f} s wall")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
