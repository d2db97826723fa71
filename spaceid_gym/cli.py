"""The ``spaceid`` command: simulate datasets and run the demonstration.

Every bad input ends in a one-line ``spaceid: error: ...`` message and exit code 2, without a
traceback. The command sits at the top of the package graph: nothing imports it.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from spaceid_gym.errors import SpaceIdInputError


def _vector3(text: str) -> np.ndarray:
    """Parse ``"x,y,z"`` (metres) for --tank."""
    try:
        values = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers 'x,y,z' in metres, got {text!r}") from None
    if values.shape != (3,) or not np.all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"expected three finite numbers 'x,y,z' in metres, got {text!r}")
    return values


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="spaceid", description="Identify robot inertial parameters from motion data.")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="simulate a free-floating robot and write a dataset folder")
    sim.add_argument("--robot", default="paper6", help="shipped robot name or URDF path (default paper6)")
    sim.add_argument("--duration", type=float, default=60.0, help="window length, s (default 60)")
    sim.add_argument("--fuel-consumed", type=float, default=40.0, help="fuel consumed mdf, kg (default 40)")
    sim.add_argument(
        "--tank", type=_vector3, default=None, help="tank position bf 'x,y,z', m, base frame, from the full-tank CoM"
    )
    sim.add_argument("--seed", type=int, default=0, help="seed of noise, initial pose, excitation and tank draw")
    sim.add_argument("--rate", type=float, default=50.0, help="sample/control rate, Hz (default 50)")
    sim.add_argument("--noise-free", action="store_true", help="exact measurements")
    sim.add_argument("--out", type=Path, required=True, help="dataset folder to write")

    demo = sub.add_parser("demo", help="the whole loop available so far on the built-in robot")
    demo.add_argument("--out", type=Path, default=Path("demo-output"), help="output folder (default demo-output)")
    demo.add_argument("--robot", default="paper6")
    demo.add_argument("--seed", type=int, default=3)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``spaceid``; returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "simulate":
            _simulate(args)
        elif args.command == "demo":
            from spaceid_gym.demo import run_demo

            run_demo(args.out, args.robot, args.seed)
    except (SpaceIdInputError, OSError) as exc:
        print(f"spaceid: error: {exc}", file=sys.stderr)
        return 2
    return 0


def _simulate(args: argparse.Namespace) -> None:
    from agents.excitation import FourierExcitation
    from spaceid_gym.datasets import simulate_episode, write_episode_dataset
    from spaceid_gym.robots import load_robot
    from spaceid_gym.sim.mission import FuelSchedule
    from spaceid_gym.sim.sensors import SensorModel

    if not (np.isfinite(args.rate) and args.rate > 0):
        raise SpaceIdInputError(f"--rate: expected a positive rate in Hz, got {args.rate!r}")
    robot = load_robot(args.robot)
    tank = (
        args.tank
        if args.tank is not None
        else FuelSchedule().draw_tank_position(robot.base_full, np.random.default_rng(args.seed))
    )
    excitation = FourierExcitation(robot.n_joints, seed=args.seed)
    start = time.perf_counter()
    env = simulate_episode(
        robot,
        duration_s=args.duration,
        fuel_consumed_kg=args.fuel_consumed,
        tank_position_m=tank,
        excitation=excitation,
        seed=args.seed,
        sensors=SensorModel.noise_free() if args.noise_free else None,
        control_period_s=1.0 / args.rate,
    )
    dataset = write_episode_dataset(args.out, env, {"seed": args.seed, "excitation": {"kind": "fourier", "seed": args.seed}})
    truth = dataset.truth or {}
    print(
        f"wrote {dataset.path}/ ({dataset.log.n_samples} samples, {dataset.log.duration_s:.1f} s, "
        f"{time.perf_counter() - start:.2f} s wall): base mass {truth['base_mass_kg']:.2f} kg, "
        f"fuel consumed {truth['fuel_consumed_kg']:.2f} kg, tank {json.dumps([round(x, 4) for x in truth['tank_position_m']])} m"
    )


if __name__ == "__main__":
    raise SystemExit(main())
