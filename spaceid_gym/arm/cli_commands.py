"""Bodies of the ``spaceid arm ...`` commands (wired into :mod:`spaceid_gym.cli`).

``spaceid arm simulate --robot ur5 --trajectory fourier --duration 30 --friction coulomb,viscous --seed 1 --out ur5sim/``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from spaceid_gym.arm.friction import FRICTION_TERMS
from spaceid_gym.arm.simulator import INTERNAL_RATE_HZ, SAMPLE_RATE_HZ, ArmSensorModel
from spaceid_gym.errors import SpaceIdInputError

_EFFORTS = {"torque": "torque_Nm", "current": "current_A"}


def add_arm_simulate_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``spaceid arm simulate`` (what :func:`run_arm_simulate` reads)."""
    parser.add_argument("--robot", default="ur5", help="shipped arm name or URDF path (default ur5)")
    parser.add_argument(
        "--trajectory",
        default="fourier",
        choices=["fourier", "optimised"],
        help="random Fourier excitation, or one optimised for the regressor's condition number (default fourier)",
    )
    parser.add_argument("--duration", type=float, default=30.0, help="log length, s (default 30)")
    parser.add_argument(
        "--friction",
        default="coulomb,viscous",
        help=f"friction terms of the true robot, comma-separated from {','.join(FRICTION_TERMS)}, or 'none' (default coulomb,viscous)",
    )
    parser.add_argument("--seed", type=int, default=1, help="seed of the true parameters, trajectory and noise (default 1)")
    parser.add_argument("--rate", type=float, default=SAMPLE_RATE_HZ, help=f"sample rate, Hz (default {SAMPLE_RATE_HZ:g})")
    parser.add_argument(
        "--effort", default="torque", choices=sorted(_EFFORTS), help="log joint torque or motor current (default torque)"
    )
    parser.add_argument("--noise-free", action="store_true", help="exact measurements")
    parser.add_argument("--out", type=Path, required=True, help="dataset folder to write")


def parse_friction(text: str) -> tuple[str, ...]:
    """``"coulomb,viscous"`` -> ``("coulomb", "viscous")``; ``"none"`` or ``""`` -> ``()``."""
    terms = tuple(term.strip() for term in text.split(",") if term.strip())
    if terms in ((), ("none",)):
        return ()
    unknown = [term for term in terms if term not in FRICTION_TERMS]
    if unknown:
        raise SpaceIdInputError(
            f"--friction: unknown term(s) {unknown}; expected a comma-separated subset of {list(FRICTION_TERMS)} or 'none'"
        )
    return terms


def run_arm_simulate(args: argparse.Namespace) -> None:
    """``spaceid arm simulate``: write a simulated arm dataset folder and print a one-line summary.

    Reads ``args.robot, trajectory, duration, friction, seed, rate, noise_free, out`` and, if
    present, ``args.effort`` (``"torque"`` or ``"current"``, default torque).
    """
    from spaceid_gym.arm.datasets import simulate_arm_dataset  # the optimiser and simulator load only when used

    if not (args.rate > 0 and args.rate < float("inf")):
        raise SpaceIdInputError(f"--rate: expected a positive rate in Hz, got {args.rate!r}")
    effort = _EFFORTS.get(getattr(args, "effort", "torque") or "torque")
    if effort is None:
        raise SpaceIdInputError(f"--effort: expected one of {sorted(_EFFORTS)}, got {args.effort!r}")
    sensors = ArmSensorModel.noise_free(effort) if args.noise_free else ArmSensorModel(effort_kind=effort)
    start = time.perf_counter()
    dataset = simulate_arm_dataset(
        args.robot,
        args.duration,
        parse_friction(args.friction),
        args.seed,
        args.trajectory,
        args.out,
        sample_rate_hz=args.rate,
        internal_rate_hz=max(INTERNAL_RATE_HZ, args.rate),
        sensors=sensors,
    )
    truth, log = dataset.truth, dataset.simulation.log
    print(
        f"wrote {dataset.path}/ ({log.n_samples} samples, {truth['duration_s']:.1f} s, {time.perf_counter() - start:.2f} s wall): "
        f"trajectory {args.trajectory} (regressor condition number {truth['trajectory']['condition_number']:.1f}), "
        f"friction {args.friction}, tracking error max {truth['tracking_error_max_rad']:.2e} rad, "
        f"max torque {100 * truth['max_torque_fraction']:.0f} % of the limit"
    )
