"""``spaceid excite ...``: optimise a Fourier excitation, train an excitation agent, compare excitations; and the
``--excitation`` source of ``spaceid simulate``.

stable-baselines3 and torch (the ``agents`` extra) take seconds to import: :mod:`agents.policy` and
:mod:`agents.comparison` are imported only by the commands that need them.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from agents.arm_comparison import optimise_arm_designs, run_arm_comparison, write_arm_comparison
from agents.comparison import run_comparison, write_comparison
from agents.policy import ExcitationPolicy, train_excitation
from spaceid_gym.datasets import Excitation, FeedbackExcitation
from spaceid_gym.envs.manipulator import ManipulatorIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.fuel_excitation_design import load_fourier_excitation, optimise_fourier_excitation, write_fourier_design
from spaceid_gym.limits import check_count, max_jobs
from spaceid_gym.robots import Robot, load_robot

#: where the shipped policies live: ``agents/policies/<robot>/``
SHIPPED_POLICIES = Path(__file__).parent / "policies"


def add_excite_arguments(sub: Any) -> None:
    """The ``excite`` command and its subcommands ``fourier``, ``train``, ``compare``, ``compare-arm``."""
    excite = sub.add_parser("excite", help="design excitations: optimised Fourier series, a learnt policy, their comparison")
    commands = excite.add_subparsers(dest="excite_command", required=True)

    fourier = commands.add_parser("fourier", help="optimise a finite Fourier series per joint for D-optimality")
    fourier.add_argument("--robot", default="paper6", help="shipped robot name or URDF path (default paper6)")
    fourier.add_argument("--duration", type=float, default=60.0, help="window = the series' period, s (default 60)")
    fourier.add_argument("--params", default="fuel", choices=["fuel"], help="parameters whose information is maximised")
    fourier.add_argument("--harmonics", type=int, default=10, help="harmonics per joint (default 10)")
    fourier.add_argument("--starts", type=int, default=4, help="seeded random starts (default 4)")
    fourier.add_argument("--seed", type=int, default=0, help="seed of the random starts")
    fourier.add_argument("--out", type=Path, required=True, help="JSON file to write")

    train = commands.add_parser(
        "train", help="train an excitation policy (stable-baselines3) on FreeFloatingID-v0, or ManipulatorID-v0 for an arm"
    )
    train.add_argument(
        "--robot", default="paper6", help="shipped robot name (default paper6), or a shipped arm (ur5: ManipulatorID-v0)"
    )
    train.add_argument(
        "--params", default=None, help="parameters whose information is rewarded (fuel for a satellite, base for an arm)"
    )
    train.add_argument(
        "--timesteps", type=int, default=None, help="agent decisions (0.5 s each) to train for (default 200000; ur5 60000)"
    )
    train.add_argument("--algorithm", default="ppo", choices=["ppo", "sac"], help="ppo (default) or sac")
    train.add_argument(
        "--attitude-weight",
        type=float,
        default=None,
        help="nats per degree of peak base attitude excursion (satellites only; default 0.05)",
    )
    train.add_argument("--envs", type=int, default=2, help="parallel envs (default 2)")
    train.add_argument("--vec-env", default="dummy", choices=["dummy", "subproc"], help="DummyVecEnv (default) or SubprocVecEnv")
    train.add_argument("--seed", type=int, default=0, help="seed of the agent and its envs")
    train.add_argument("--out", type=Path, required=True, help="policy folder to write")

    compare = commands.add_parser(
        "compare", help="random, one joint at a time, optimised Fourier and a policy on held-out windows"
    )
    compare.add_argument("--robot", default="paper6", help="shipped robot name (default paper6)")
    compare.add_argument("--policy", type=Path, default=None, help="policy folder (default: the shipped one for the robot)")
    compare.add_argument("--fourier", type=Path, default=None, help="optimised Fourier JSON (default: optimise one, seed 0)")
    compare.add_argument("--episodes", type=int, default=50, help="held-out windows (default 50)")
    compare.add_argument(
        "--first-window", type=int, default=0, help="index of the first held-out window (default 0): a fresh set for a figure"
    )
    compare.add_argument("--duration", type=float, default=60.0, help="window, s (default 60)")
    compare.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    compare.add_argument("--out", type=Path, required=True, help="output folder")

    arm = commands.add_parser(
        "compare-arm",
        help="the arm (ManipulatorID-v0): random, one joint at a time, optimised Fourier and a policy on the same windows",
    )
    arm.add_argument("--episodes", type=int, default=20, help="windows (default 20)")
    arm.add_argument("--first-window", type=int, default=0, help="index of the first window (default 0)")
    arm.add_argument("--duration", type=float, default=30.0, help="window, s (default 30, the env's)")
    arm.add_argument("--seed", type=int, default=0, help="seed of the optimised trajectories' random starts")
    arm.add_argument(
        "--policy", type=Path, default=None, help="policy folder for the arm (default: the shipped one, agents/policies/ur5)"
    )
    arm.add_argument("--no-policy", action="store_true", help="leave out the policy and random_targets rows")
    arm.add_argument("--out", type=Path, required=True, help="output folder")


def run_excite(args: argparse.Namespace) -> None:
    """Run ``spaceid excite <command>``."""
    {"fourier": _fourier, "train": _train, "compare": _compare, "compare-arm": _compare_arm}[args.excite_command](args)


def excitation_source(spec: Path | None, robot: Robot, seed: int) -> tuple[Excitation | FeedbackExcitation, dict[str, Any]]:
    """What ``spaceid simulate --excitation`` drives the arm with, and its description for truth.json.

    ``None``: the random multi-sine of ``seed``; a JSON file: an optimised Fourier excitation
    (``spaceid excite fourier``); a folder: a policy (``spaceid excite train``).
    """
    if spec is None:
        return FourierExcitation(robot.n_joints, seed=seed), {"kind": "fourier", "seed": seed}
    if spec.is_dir():
        return ExcitationPolicy.load(spec, robot=robot.name, params="fuel"), {"kind": "policy", "folder": str(spec)}
    if not spec.is_file():
        raise SpaceIdInputError(f"--excitation: {spec} is neither a Fourier JSON file nor a policy folder")
    return load_fourier_excitation(spec, robot), {"kind": "fourier_rate", "file": str(spec)}


def _fourier(args: argparse.Namespace) -> None:
    robot = load_robot(args.robot)
    for option, value in (("--harmonics", args.harmonics), ("--starts", args.starts)):
        check_count(value, option, 1000)
    design = optimise_fourier_excitation(robot, args.duration, seed=args.seed, n_harmonics=args.harmonics, n_starts=args.starts)
    path = write_fourier_design(args.out, design, robot, args.params)
    before, after = design.measures_start, design.measures_optimised
    print(
        f"wrote {path} ({design.wall_time_s:.0f} s): D-optimality {before.d_optimality:.2f} (random start) -> "
        f"{after.d_optimality:.2f}; largest CR std {before.max_cramer_rao_std:.4f} -> {after.max_cramer_rao_std:.4f} "
        f"(prior ranges); peak use of the limits {json.dumps({k: round(v, 3) for k, v in design.peak_ratios.items()})}"
    )


def _train(args: argparse.Namespace) -> None:
    policy = train_excitation(
        args.robot, args.params, args.timesteps, args.out, algorithm=args.algorithm, seed=args.seed, n_envs=args.envs,
        vec_env=args.vec_env, attitude_weight=args.attitude_weight,
    )  # fmt: skip
    meta = policy.metadata
    print(f"wrote {args.out}/ (policy.json, model.zip): {meta['timesteps']} steps in {meta['training_wall_time_s']:.0f} s")


def _compare(args: argparse.Namespace) -> None:
    robot = load_robot(args.robot)
    check_count(args.episodes, "--episodes", 100_000)
    if args.first_window < 0:
        raise SpaceIdInputError(f"--first-window: expected an index >= 0, got {args.first_window}")
    check_count(args.jobs, "--jobs", max_jobs())
    folder = args.policy if args.policy is not None else SHIPPED_POLICIES / robot.name
    if args.policy is None and not folder.is_dir():
        raise SpaceIdInputError(f"--policy: no shipped policy for {robot.name!r}; train one with 'spaceid excite train'")
    policy = ExcitationPolicy.load(folder, robot=robot.name, params="fuel")  # checks it before the long run
    started = time.perf_counter()
    if args.fourier is not None:
        fourier = load_fourier_excitation(args.fourier, robot)
    else:
        print("optimising the Fourier baseline (seed 0; pass --fourier to reuse one) ...")
        design = optimise_fourier_excitation(robot, args.duration, seed=0)
        write_fourier_design(args.out / "fourier.json", design, robot)
        fourier = design.excitation
    rows = run_comparison(robot.name, args.episodes, fourier, folder, args.duration, args.jobs, args.first_window)
    info = {"robot": robot.name, "policy": str(folder), "policy_timesteps": policy.metadata.get("timesteps"), "episodes": args.episodes, "first_window": args.first_window,
            "duration_s": args.duration, "wall_time_s": round(time.perf_counter() - started, 1)}  # fmt: skip
    paths = write_comparison(args.out, rows, info)
    print(paths["table"].read_text())
    n_methods = len({r["method"] for r in rows})
    written = ", ".join(p.name for p in paths.values())
    print(f"{args.episodes} held-out windows x {n_methods} methods in {info['wall_time_s']:.0f} s; wrote {written}")


def _compare_arm(args: argparse.Namespace) -> None:
    check_count(args.episodes, "--episodes", 100_000)
    if args.first_window < 0:
        raise SpaceIdInputError(f"--first-window: expected an index >= 0, got {args.first_window}")
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise SpaceIdInputError(f"--duration: expected a window > 0 s, got {args.duration}")
    if args.no_policy and args.policy is not None:
        raise SpaceIdInputError("--policy and --no-policy: give one of them")
    started = time.perf_counter()
    env = ManipulatorIDEnv()
    policy, folder = None, None
    if not args.no_policy:
        folder = args.policy if args.policy is not None else SHIPPED_POLICIES / env.robot.name
        policy = ExcitationPolicy.load(folder, robot=env.robot.name, params="base")  # checks it before the long run
    print(f"optimising the arm's Fourier trajectories (seed {args.seed}) ...")
    designs = optimise_arm_designs(env, seed=args.seed)
    rows = run_arm_comparison(args.episodes, args.duration, args.first_window, designs, env, policy)
    info = {"robot": env.robot.name, "episodes": args.episodes, "first_window": args.first_window, "duration_s": args.duration,
            "design_seed": args.seed, "policy": None if folder is None else str(folder),
            "wall_time_s": round(time.perf_counter() - started, 1)}  # fmt: skip
    paths = write_arm_comparison(args.out, rows, info)
    print(paths["table"].read_text())
    print(
        f"{args.episodes} windows x {len({r['method'] for r in rows})} methods in {info['wall_time_s']:.0f} s; wrote {', '.join(p.name for p in paths.values())}"
    )
