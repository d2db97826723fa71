"""The ``spaceid`` command: simulate datasets, identify parameters, evaluate estimators, run the demonstration.

Every bad input ends in a one-line ``spaceid: error: ...`` message and exit code 2, without a
traceback. The command sits at the top of the package graph: nothing imports it.

This module holds the arguments of every command and the dispatch; the commands' bodies are in
:mod:`spaceid_gym.free_floating_cli` (one log: simulate, identify, compare, diagnose, report),
:mod:`spaceid_gym.harness_cli` (many simulated logs: evaluate, diagnose-suite), :mod:`spaceid_gym.arm_cli`
(``spaceid arm ...``), :mod:`spaceid_gym.tracking` (track) and :mod:`agents.cli_commands` (excite).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agents.cli_commands import add_excite_arguments, run_excite
from spaceid_gym.arm_cli import (
    ARM_COMMANDS,
    add_arm_cross_validate_arguments,
    add_arm_diagnose_arguments,
    add_arm_identify_arguments,
    add_arm_simulate_arguments,
)
from spaceid_gym.demo import run_demo
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.executors import add_executor_arguments
from spaceid_gym.free_floating_cli import run_compare, run_diagnose_or_report, run_identify, run_simulate
from spaceid_gym.harness_cli import run_diagnose_suite, run_evaluate, run_pool_matrix
from spaceid_gym.sim.sensors import ATTITUDE_SOURCES
from spaceid_gym.tracking import add_track_arguments, run_track


def _vector3(text: str) -> np.ndarray:
    """Parse ``"x,y,z"`` (metres) for --tank."""
    try:
        values = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers 'x,y,z' in metres, got {text!r}") from None
    if values.shape != (3,) or not np.all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"expected three finite numbers 'x,y,z' in metres, got {text!r}")
    return values


def _numbers(text: str) -> np.ndarray:
    """Parse comma-separated numbers for --lower/--upper."""
    try:
        values = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None
    if not np.all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
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
    sim.add_argument(
        "--noise-free",
        action="store_true",
        help="exact measurements (no noise whatever --noise-scale and --star-tracker-arcsec; --attitude still applies)",
    )
    sim.add_argument(
        "--attitude",
        choices=ATTITUDE_SOURCES,
        default="star_tracker",
        help="what the log's attitude columns hold: star_tracker (default; white noise of --star-tracker-arcsec per axis), "
        "exact (the true attitude), fused (an on-board filter of the noisy gyro and star tracker, run sample by sample: "
        "its error is correlated in time), none (no quaternion columns)",
    )
    sim.add_argument(
        "--star-tracker-arcsec",
        type=float,
        default=5.0,
        metavar="ARCSEC",
        help="star-tracker noise per axis, arcsec (default 5; e.g. 1 to 20); used by --attitude star_tracker and fused",
    )
    sim.add_argument(
        "--noise-scale",
        type=float,
        default=1.0,
        metavar="FACTOR",
        help="factor > 0 on every sensor noise std: gyro, joint encoders, joint rates, star tracker "
        "(default 1; e.g. 0.3 to 3); not on a hidden gyro bias or scale factor",
    )
    sim.add_argument(
        "--attitude-time-constant",
        type=float,
        default=None,
        metavar="SECONDS",
        help="correction time constant of the fused attitude filter, s (default: the steady-state Kalman gain of "
        "the gyro and star-tracker noise, 0.17 s with the default sensors at 50 Hz)",
    )
    sim.add_argument(
        "--hidden-effects",
        default=None,
        metavar="SPEC",
        help="hidden physical effects, e.g. 'slosh,delay[delay_s=0.03],gyro_bias[magnitude=1e-4]' "
        "(initial_momentum, gyro_bias, payload, slosh, delay, external_torque, gyro_scale; see spaceid_gym.effects)",
    )
    sim.add_argument(
        "--excitation",
        type=Path,
        default=None,
        help="joint motion: an optimised Fourier JSON ('spaceid excite fourier') or a policy folder ('spaceid excite "
        "train'); default the random multi-sine of --seed",
    )
    sim.add_argument("--out", type=Path, required=True, help="dataset folder to write")

    ident = sub.add_parser("identify", help="identify parameters from a log and write an estimate file")
    ident.add_argument("--robot", required=True, help="URDF path (e.g. a dataset's robot.urdf) or shipped robot name")
    ident.add_argument("--log", type=Path, required=True, help="log.csv (t_s, q_*, dq_*, omega_* columns)")
    ident.add_argument("--params", default="fuel", help="unknowns: fuel (default), base or payload")
    ident.add_argument(
        "--estimator", default="hybrid", help="registered estimator, optionally name[key=value,...] (default hybrid)"
    )
    ident.add_argument("--seed", type=int, default=0, help="seed of the estimator's generator")
    ident.add_argument("--lower", type=_numbers, default=None, help="lower bounds, comma-separated, one per unknown")
    ident.add_argument("--upper", type=_numbers, default=None, help="upper bounds, comma-separated, one per unknown")
    ident.add_argument(
        "--noise-std", type=float, default=None, help="gyro noise std per sample, rad/s (default: from the residual)"
    )
    ident.add_argument(
        "--effects", default=None, help="effects added to the model, e.g. 'initial_momentum,gyro_bias' (see 'spaceid diagnose')"
    )
    ident.add_argument("--out", type=Path, required=True, help="estimate JSON file to write")

    cmp = sub.add_parser("compare", help="compare an identified model with the measurements: fit, residual, where it fails")
    cmp.add_argument("--robot", required=True, help="URDF path (e.g. a dataset's robot.urdf) or shipped robot name")
    cmp.add_argument("--log", type=Path, required=True, help="log.csv")
    cmp.add_argument("--estimate", type=Path, required=True, help="estimate JSON written by 'spaceid identify'")
    cmp.add_argument("--noise-std", type=float, default=None, help="gyro noise floor, rad/s (default: estimated from the data)")
    cmp.add_argument("--out", type=Path, required=True, help="output folder: comparison.json and plots")

    diag = sub.add_parser("diagnose", help="find the physical effect the model is missing")
    _loop_arguments(diag)
    diag.add_argument("--apply", default=None, help="'best' (the verdict's effect) or an effect name: add it and re-identify")
    diag.add_argument(
        "--out", type=Path, required=True, help="output folder: diagnosis.json (and estimate_after.json with --apply)"
    )

    rep = sub.add_parser("report", help="compare, diagnose, add the missing effect and write one self-contained HTML page")
    _loop_arguments(rep)
    rep.add_argument("--apply", default="best", help="'best' (default), an effect name, or 'none'")
    rep.add_argument(
        "--truth", type=Path, default=None, help="truth.json of a simulated dataset (default: next to the log, if any)"
    )
    rep.add_argument("--out", type=Path, required=True, help="HTML file to write (figures in <name>_figures/)")

    ev = sub.add_parser("evaluate", help="evaluate estimators episode by episode against the truth and the Cramér-Rao bound")
    ev.add_argument("--robot", default="paper6")
    ev.add_argument("--estimators", default="improved-pso,pso,lm,hybrid,nn", help="comma-separated specs name[key=value,...]")
    ev.add_argument("--settings", type=int, default=200, help="number of true settings (default 200)")
    ev.add_argument("--seed", type=int, default=0)
    ev.add_argument("--duration", type=float, default=60.0, help="window length, s (default 60)")
    add_executor_arguments(ev)
    ev.add_argument(
        "--budget-reference",
        default="improved-pso",
        help="estimators with max_evaluations get this one's evaluations ('' for none)",
    )
    ev.add_argument("--out", type=Path, required=True, help="output folder")

    suite = sub.add_parser("diagnose-suite", help="measure diagnose on simulated logs with each effect hidden, and on clean logs")
    suite.add_argument("--robot", default=None, help="robot of every log (default paper6; not with --matrix: --fix robot=...)")
    suite.add_argument("--seeds", type=int, default=20, help="logs per effect (default 20)")
    suite.add_argument("--first-seed", type=int, default=0)
    suite.add_argument("--effects", default=None, help="comma-separated hidden effects, 'none' for clean logs (default: all)")
    suite.add_argument(
        "--magnitude",
        default=None,
        help="sizes other than the defaults, e.g. 'gyro_scale=2.6e-3,payload=20' in the units of "
        "spaceid_gym.effects.MAGNITUDE_UNITS (slosh: kg, at most the liquid left); same seeds, same directions",
    )
    suite.add_argument("--duration", type=float, default=60.0, help="window length per log, s (default 60)")
    suite.add_argument(
        "--matrix",
        action="store_true",
        help="the variation matrix: each log draws its robot, rate, attitude source, noise scale, excitation and effect "
        "size from its seed (spaceid_gym.variations); writes matrix.csv, matrix.md and summary.json",
    )
    suite.add_argument(
        "--fix",
        default=None,
        help="with --matrix: pin axes, e.g. 'robot=paper6,rate_hz=50' (axes: robot, rate_hz, attitude, noise_scale, "
        "excitation, size_factor, slosh_model, slosh_period_s)",
    )
    add_executor_arguments(suite)
    suite.add_argument("--out", type=Path, required=True, help="output folder")

    pool = sub.add_parser(
        "pool-matrix",
        help="pool runs of 'diagnose-suite --matrix' (other seeds, machines or pinned axes) into one table per cell",
    )
    pool.add_argument("runs", nargs="+", type=Path, help="run folders (each with matrix.csv and summary.json)")
    pool.add_argument(
        "--mixed-code",
        action="store_true",
        help="pool runs made by different code versions (only where the diagnosis did not change between them)",
    )
    pool.add_argument("--out", type=Path, required=True, help="output folder")

    arm = sub.add_parser("arm", help="fixed-base manipulators (UR5): simulate, identify, cross-validate, diagnose")
    arm_sub = arm.add_subparsers(dest="arm_command", required=True)
    add_arm_simulate_arguments(arm_sub.add_parser("simulate", help="simulate an arm with friction and write a dataset folder"))
    add_arm_identify_arguments(arm_sub.add_parser("identify", help="identify on some movements, validate on held-out ones"))
    add_arm_cross_validate_arguments(
        arm_sub.add_parser("cross-validate", help="leave-one-movement-out table of held-out errors per joint and estimator")
    )
    add_arm_diagnose_arguments(
        arm_sub.add_parser("diagnose", help="find the missing joint term (friction, armature, offset) and where the model fails")
    )

    add_track_arguments(
        sub.add_parser("track", help="track the fuel through a multi-window mission with the ukf, against hybrid")
    )

    demo = sub.add_parser("demo", help="the whole loop available so far on the built-in robot")
    demo.add_argument("--out", type=Path, default=Path("demo-output"), help="output folder (default demo-output)")
    demo.add_argument("--robot", default="paper6")
    demo.add_argument("--seed", type=int, default=3)
    add_excite_arguments(sub)
    return parser


def _loop_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments shared by ``diagnose`` and ``report``."""
    parser.add_argument("--robot", required=True, help="URDF path (e.g. a dataset's robot.urdf) or shipped robot name")
    parser.add_argument("--log", type=Path, required=True, help="log.csv")
    parser.add_argument("--params", default="fuel", help="unknowns: fuel (default) or base")
    parser.add_argument("--effects", default=None, help="effects already in the model (kept in every candidate)")
    parser.add_argument("--candidates", default=None, help="comma-separated effects to try (default: the whole catalogue)")
    parser.add_argument("--estimator", default="hybrid", help="estimator of the model as it is (default hybrid)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the estimator")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``spaceid``; returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "simulate":
            run_simulate(args)
        elif args.command == "identify":
            run_identify(args)
        elif args.command == "evaluate":
            run_evaluate(args)
        elif args.command == "compare":
            run_compare(args)
        elif args.command in ("diagnose", "report"):
            run_diagnose_or_report(args)
        elif args.command == "diagnose-suite":
            return run_diagnose_suite(args)
        elif args.command == "pool-matrix":
            return run_pool_matrix(args)
        elif args.command == "excite":
            run_excite(args)
        elif args.command == "track":
            run_track(args)
        elif args.command == "arm":
            ARM_COMMANDS[args.arm_command](args)
        elif args.command == "demo":
            run_demo(args.out, args.robot, args.seed)
    except (SpaceIdInputError, OSError) as exc:
        print(f"spaceid: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("spaceid: interrupted; files are written whole at the end, so none was left half-written", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
