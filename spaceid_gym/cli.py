"""The ``spaceid`` command: simulate datasets, identify parameters, evaluate estimators, run the demonstration.

Every bad input ends in a one-line ``spaceid: error: ...`` message and exit code 2, without a
traceback. The command sits at the top of the package graph: nothing imports it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from agents.cli_commands import add_excite_arguments, excitation_source, run_excite
from estimators.diagnostics.compare import compare, model_from_estimate
from estimators.diagnostics.plots import plot_correlations, plot_overlay, plot_residuals
from estimators.diagnostics.suite import (
    DIAGNOSTIC_EXCITATION,
    SUITE_EFFECTS,
    code_version,
    failed_rows,
    parse_magnitudes,
    run_matrix,
    run_suite,
    write_matrix,
    write_suite,
)
from estimators.diagnostics.workflow import apply_effect, run_loop, write_report
from estimators.evaluation import (
    draw_settings,
    estimator_from_spec,
    parse_estimator_specs,
    run_evaluation,
    settings_info,
    write_results,
)
from estimators.problem import IdentificationModel
from spaceid_gym.arm_cli import (
    ARM_COMMANDS,
    add_arm_cross_validate_arguments,
    add_arm_diagnose_arguments,
    add_arm_identify_arguments,
    add_arm_simulate_arguments,
)
from spaceid_gym.datasets import simulate_episode, write_episode_dataset
from spaceid_gym.demo import run_demo
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.executors import ExecutorSpec, add_executor_arguments, executor_from_arguments
from spaceid_gym.files import write_json_atomic
from spaceid_gym.limits import check_count, check_log_size, max_jobs
from spaceid_gym.log import MeasurementLog
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.robots import load_robot
from spaceid_gym.sim.sensors import ARCSEC_RAD, ATTITUDE_SOURCES, SensorModel
from spaceid_gym.tracking import add_track_arguments, run_track
from spaceid_gym.variations import AXIS_RANGES, AXIS_VALUES, parse_fixed


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
            _simulate(args)
        elif args.command == "identify":
            _identify(args)
        elif args.command == "evaluate":
            _evaluate(args)
        elif args.command == "compare":
            _compare(args)
        elif args.command in ("diagnose", "report"):
            _diagnose_or_report(args)
        elif args.command == "diagnose-suite":
            return _diagnose_suite(args)
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


def _simulate(args: argparse.Namespace) -> None:
    if not (np.isfinite(args.rate) and args.rate > 0):
        raise SpaceIdInputError(f"--rate: expected a positive rate in Hz, got {args.rate!r}")
    sensors = _sensor_model(args)
    robot = load_robot(args.robot)
    check_log_size(args.duration, 1.0 / args.rate, robot.n_joints, "--duration")
    tank = (
        args.tank
        if args.tank is not None
        else FuelSchedule().draw_tank_position(robot.base_full, np.random.default_rng(args.seed))
    )
    excitation, excitation_info = excitation_source(args.excitation, robot, args.seed)
    start = time.perf_counter()
    env = simulate_episode(
        robot,
        duration_s=args.duration,
        fuel_consumed_kg=args.fuel_consumed,
        tank_position_m=tank,
        excitation=excitation,
        seed=args.seed,
        sensors=sensors,
        control_period_s=1.0 / args.rate,
        hidden_effects=args.hidden_effects,
    )
    dataset = write_episode_dataset(args.out, env, {"seed": args.seed, "excitation": excitation_info})
    truth = dataset.truth or {}
    effects = ", ".join(env.effects.names)
    print(
        f"wrote {dataset.path}/ ({dataset.log.n_samples} samples, {dataset.log.duration_s:.1f} s, "
        f"{time.perf_counter() - start:.2f} s wall): base mass {truth['base_mass_kg']:.2f} kg, "
        f"fuel consumed {truth['fuel_consumed_kg']:.2f} kg, tank {json.dumps([round(x, 4) for x in truth['tank_position_m']])} m"
        + (f", hidden effects: {effects}" if effects else "")
        + (f", attitude: {args.attitude}" if args.attitude != "star_tracker" else "")
    )


def _sensor_model(args: argparse.Namespace) -> SensorModel:
    """The sensors ``spaceid simulate`` asks for; a bad value of an option raises naming it.

    Options: --noise-free, --attitude, --star-tracker-arcsec, --noise-scale, --attitude-time-constant.
    """
    if not (np.isfinite(args.star_tracker_arcsec) and args.star_tracker_arcsec >= 0.0):
        raise SpaceIdInputError(
            f"--star-tracker-arcsec: expected a finite number of arcseconds >= 0, got {args.star_tracker_arcsec!r}"
        )
    if not (np.isfinite(args.noise_scale) and args.noise_scale > 0.0):
        raise SpaceIdInputError(f"--noise-scale: expected a finite factor > 0, got {args.noise_scale!r}")
    source, tau = args.attitude, args.attitude_time_constant
    if tau is not None and not (np.isfinite(tau) and tau > 0.0):
        raise SpaceIdInputError(f"--attitude-time-constant: expected a finite number of seconds > 0, got {tau!r}")
    if args.noise_free:
        return dataclasses.replace(SensorModel.noise_free(), attitude_source=source, attitude_filter_time_constant_s=tau)
    return SensorModel(
        attitude_noise_rad=args.star_tracker_arcsec * ARCSEC_RAD,
        noise_scale=args.noise_scale,
        attitude_source=source,
        attitude_filter_time_constant_s=tau,
    )


def _identify(args: argparse.Namespace) -> None:
    robot = load_robot(args.robot)
    estimator = estimator_from_spec(args.estimator, seed=args.seed)
    bounds = {k: v for k, v in (("lower", args.lower), ("upper", args.upper)) if v is not None}
    model = IdentificationModel(robot, args.params, noise_std_rad_s=args.noise_std, effects=args.effects, **bounds)
    log = MeasurementLog.from_csv(args.log, n_joints=robot.n_joints)
    estimate = estimator.fit(model, log)
    estimate.write_json(args.out)
    print(f"wrote {args.out} ({estimate.estimator}, {estimate.n_evaluations:.0f} evaluations, {estimate.wall_time_s:.2f} s)")
    for name, value, std, ok in zip(estimate.names, estimate.theta, estimate.theta_std, estimate.identifiable, strict=True):
        print(f"  {name:>18} = {value:.6g} +- {std:.3g}" if ok else f"  {name:>18}: not identifiable from this log")
    for message in estimate.insufficient_excitation:
        print(message)


def _compare(args: argparse.Namespace) -> None:
    robot = load_robot(args.robot)
    model, theta = model_from_estimate(robot, args.estimate)
    log = MeasurementLog.from_csv(args.log, n_joints=robot.n_joints)
    result = compare(model, log, theta, args.noise_std)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "comparison.json", result.to_dict())
    a = result.analysis
    plot_overlay(
        args.out / "overlay.png", result.t_s, result.measured, result.predicted, a.segments, title=f"Model {result.label}"
    )
    plot_residuals(args.out / "residuals.png", result.t_s, result.residual, a.noise_std, a.segments)
    plot_correlations(args.out / "correlations.png", a)
    print(result.summary())
    print(a.structure_description())
    print(f"wrote {args.out}/comparison.json, overlay.png, residuals.png, correlations.png")


def _diagnose_or_report(args: argparse.Namespace) -> None:
    robot = load_robot(args.robot)
    log = MeasurementLog.from_csv(args.log, n_joints=robot.n_joints)
    model = IdentificationModel(robot, args.params, effects=args.effects)
    estimator = estimator_from_spec(args.estimator, seed=args.seed)
    candidates = None if args.candidates is None else [c.strip() for c in args.candidates.split(",") if c.strip()]
    apply = None if args.apply in (None, "none") else args.apply
    truth = _truth_next_to(args.log) if getattr(args, "truth", None) is None else _read_json(args.truth)
    start = time.perf_counter()
    result = run_loop(model, log, truth=truth, apply=apply, estimator=estimator, candidates=candidates)
    print(result.summary())
    if args.command == "report":
        path = write_report(result, args.out)
        print(f"wrote {path} ({time.perf_counter() - start:.1f} s)")
        return
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "diagnosis.json", result.to_dict()["diagnosis"])
    written = ["diagnosis.json"]
    if result.applied is not None:
        _, estimate = apply_effect(model, log, result.applied, result.diagnosis)
        estimate.write_json(args.out / "estimate_after.json")
        written.append("estimate_after.json")
    print(f"wrote {', '.join(f'{args.out}/{w}' for w in written)} ({time.perf_counter() - start:.1f} s)")


def _diagnose_suite(args: argparse.Namespace) -> int:
    """Runs the suite (or with ``--matrix`` the variation matrix) and writes it; exit code 1 (after writing) if the
    diagnosis of any log raised."""
    executor = executor_from_arguments(args, max_jobs())
    check_count(args.seeds, "--seeds")
    if args.first_seed < 0:
        raise SpaceIdInputError(f"--first-seed: expected an integer >= 0, got {args.first_seed}")
    check_log_size(args.duration, 1.0 / max(AXIS_VALUES["rate_hz"]), 7, "--duration")  # the matrix's fastest, largest
    effects = SUITE_EFFECTS if args.effects is None else tuple(e.strip() for e in args.effects.split(",") if e.strip())
    unknown = [e for e in effects if e not in SUITE_EFFECTS]
    if unknown:
        raise SpaceIdInputError(f"--effects: unknown {unknown}; expected names from {', '.join(SUITE_EFFECTS)}")
    if not effects:
        raise SpaceIdInputError(f"--effects: expected at least one of {', '.join(SUITE_EFFECTS)}")
    runs = {"seeds": args.seeds, "first_seed": args.first_seed, "effects": list(effects), "duration_s": args.duration}
    runs["executor"] = executor.describe()
    if args.matrix:
        return _diagnose_matrix(args, effects, runs, executor)
    if args.fix is not None:
        raise SpaceIdInputError("--fix: pins axes of the variation matrix; give --matrix too")
    robot = args.robot or "paper6"
    magnitudes = parse_magnitudes(args.magnitude, effects, robot, range(args.first_seed, args.first_seed + args.seeds))
    info: dict[str, object] = {"robot": robot, **runs, "magnitudes": magnitudes, "excitation": DIAGNOSTIC_EXCITATION}
    rows = _timed_run(info, lambda: run_suite(robot, effects, args.seeds, args.first_seed, executor, args.duration, magnitudes))
    return _report_suite(rows, write_suite(args.out, rows, info), info)


def _timed_run(info: dict[str, object], run: Callable[[], list[dict[str, object]]]) -> list[dict[str, object]]:
    """``run()``'s rows; adds the code's version (read before it runs) and the wall time to ``info``."""
    start = time.perf_counter()
    info["code_version"] = code_version()
    rows = run()
    info["wall_time_s"] = time.perf_counter() - start
    return rows


def _diagnose_matrix(args: argparse.Namespace, effects: tuple[str, ...], runs: dict[str, object], executor: ExecutorSpec) -> int:
    """``diagnose-suite --matrix``: the variation matrix, written to ``--out`` (``runs``: the seeds, effects and
    duration, for ``summary.json``)."""
    if args.robot is not None or args.magnitude is not None:
        raise SpaceIdInputError("--robot and --magnitude: not with --matrix, whose logs draw them (pin with --fix robot=...)")
    try:
        fixed = parse_fixed(args.fix)
    except SpaceIdInputError as exc:
        raise SpaceIdInputError(f"--fix: {exc}") from None
    info: dict[str, object] = {"matrix": True, **runs, "fixed": fixed, "axis_values": AXIS_VALUES, "axis_ranges": AXIS_RANGES}
    rows = _timed_run(info, lambda: run_matrix(effects, args.seeds, args.first_seed, executor, args.duration, fixed))
    return _report_suite(rows, write_matrix(args.out, rows, info), info)


def _report_suite(rows: list[dict[str, object]], paths: dict[str, Path], info: dict[str, object]) -> int:
    """Print the table and the logs that failed; exit code 1 if any did."""
    print(paths["table"].read_text())
    print(
        f"{len(rows)} logs in {info['wall_time_s']:.1f} s ({info.get('executor', 'serial')}); wrote {', '.join(p.name for p in paths.values())}"
    )
    failed = failed_rows(rows)
    for row in failed:
        print(
            f"spaceid: error: diagnosis of the {row['effect']} log of seed {row['seed']} raised {row['error']}", file=sys.stderr
        )
    if failed:
        print(
            f"spaceid: error: {len(failed)} of {len(rows)} logs failed (verdict 'error' in {paths['csv'].name})", file=sys.stderr
        )
    return 1 if failed else 0


def _truth_next_to(log_path: Path) -> dict | None:
    """A simulated dataset's truth.json next to its log, if there is one."""
    path = log_path.parent / "truth.json"
    return _read_json(path) if path.is_file() else None


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise SpaceIdInputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None


def _evaluate(args: argparse.Namespace) -> None:
    check_count(args.settings, "--settings")
    executor = executor_from_arguments(args, max_jobs())
    robot = load_robot(args.robot)
    check_log_size(args.duration, 0.02, robot.n_joints, "--duration")
    specs = parse_estimator_specs(args.estimators)
    settings = draw_settings(robot, args.settings, args.seed)
    start = time.perf_counter()
    rows = run_evaluation(
        args.robot,
        specs,
        settings,
        budget_reference=args.budget_reference or None,
        duration_s=args.duration,
        executor=executor,
        seed=args.seed,
    )
    wall_s = time.perf_counter() - start
    info = settings_info(args.robot, settings, args.seed, args.duration, 0.02) | {
        "executor": executor.describe(),
        "wall_time_s": wall_s,
    }
    paths = write_results(args.out, rows, info)
    print(paths["table"].read_text())
    print(
        f"{len(settings)} settings x {len(specs)} estimators in {wall_s:.1f} s ({executor.describe()}); wrote {', '.join(p.name for p in paths.values())}"
    )


if __name__ == "__main__":
    raise SystemExit(main())
