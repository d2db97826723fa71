"""Bodies of the free-floating commands on one log: ``spaceid simulate``, ``identify``, ``compare``, ``diagnose`` and
``report`` (wired into :mod:`spaceid_gym.cli`, which defines their arguments).

Each takes the parsed arguments, writes its files and prints a summary; a bad input raises
:class:`~spaceid_gym.errors.SpaceIdInputError` naming the option, which the command line turns into a one-line error.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from agents.cli_commands import excitation_source
from estimators.diagnostics.compare import compare, model_from_estimate
from estimators.diagnostics.plots import plot_correlations, plot_overlay, plot_residuals
from estimators.diagnostics.workflow import apply_effect, run_loop, write_report
from estimators.evaluation import estimator_from_spec
from estimators.problem import IdentificationModel
from spaceid_gym.datasets import simulate_episode, write_episode_dataset
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import write_json_atomic
from spaceid_gym.limits import check_log_size
from spaceid_gym.log import MeasurementLog
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.robots import load_robot
from spaceid_gym.sim.sensors import ARCSEC_RAD, SensorModel


def run_simulate(args: argparse.Namespace) -> None:
    """``spaceid simulate``: simulate one window of the free-floating robot and write its dataset folder."""
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


def run_identify(args: argparse.Namespace) -> None:
    """``spaceid identify``: fit the model to a log and write the estimate JSON."""
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


def run_compare(args: argparse.Namespace) -> None:
    """``spaceid compare``: an identified model against the measurements; writes comparison.json and three plots."""
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


def run_diagnose_or_report(args: argparse.Namespace) -> None:
    """``spaceid diagnose`` (diagnosis.json, with ``--apply`` the estimate after) or ``spaceid report`` (one HTML page)."""
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


def _truth_next_to(log_path: Path) -> dict | None:
    """A simulated dataset's truth.json next to its log, if there is one."""
    path = log_path.parent / "truth.json"
    return _read_json(path) if path.is_file() else None


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise SpaceIdInputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
