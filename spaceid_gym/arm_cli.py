"""Bodies of the ``spaceid arm ...`` commands (wired into :mod:`spaceid_gym.cli`).

``spaceid arm simulate --robot ur5 --trajectory fourier --duration 30 --friction coulomb,viscous --seed 1 --out ur5sim/``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from estimators.arm.arm_diagnosis import diagnose_arm, where_it_fails
from estimators.arm.controller_model import (
    CONTROLLER_FRICTION,
    controller_estimator_label,
    controller_model_leave_one_out,
    load_controller_rows,
)
from estimators.arm.gains import identify_gains, scaled_rows
from estimators.arm.identification import (
    Preparation,
    cross_validation_markdown,
    fit,
    leave_one_out,
    load_movements,
    prediction_error,
    processed_noise_floor,
    raw_period,
    simulated_noise_std,
    summary_table,
)
from estimators.arm.model import ArmIdentificationModel
from estimators.arm.presliding_choice import (
    check_presliding_model,
    choose_for_rows,
    presliding_for_movements,
    with_presliding,
)
from estimators.diagnostics.plots import plot_overlay
from estimators.evaluation import estimator_from_spec, parse_estimator_specs
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.friction import FRICTION_TERMS, FrictionModel
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.arm.simulated_arm_datasets import simulate_arm_dataset  # the optimiser and simulator load only when used
from spaceid_gym.arm.torque_simulator import INTERNAL_RATE_HZ, SAMPLE_RATE_HZ
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.executors import add_executor_arguments, executor_from_arguments
from spaceid_gym.files import write_json_atomic, write_text_atomic
from spaceid_gym.limits import max_jobs

_EFFORTS = {"torque": "torque_Nm", "current": "current_A"}
#: the friction model's default velocities (those of ``--stribeck-velocity`` and ``--coulomb-smoothing``)
_DEFAULT_FRICTION = FrictionModel()


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


# ---------------------------------------------------------------------- identify, cross-validate, diagnose
def _add_data_arguments(parser: argparse.ArgumentParser) -> None:
    """Robot, data, model and signal-chain arguments shared by identify, cross-validate and diagnose."""
    parser.add_argument("--robot", default="ur5", help="shipped arm name or URDF path (default ur5)")
    parser.add_argument(
        "--data", type=Path, required=True, help="folder of real UR5 movements, of simulated datasets, or one simulated dataset"
    )
    parser.add_argument(
        "--friction",
        default="coulomb,viscous",
        help=f"friction terms of the model, comma-separated from {','.join(FRICTION_TERMS)}, or 'none' (default coulomb,viscous)",
    )
    parser.add_argument(
        "--stribeck-velocity",
        type=float,
        default=_DEFAULT_FRICTION.stribeck_velocity_rad_s,
        help=f"Stribeck velocity vs of the 'stribeck' term, rad/s, fixed (default {_DEFAULT_FRICTION.stribeck_velocity_rad_s:g})",
    )
    parser.add_argument(
        "--coulomb-smoothing",
        type=float,
        default=_DEFAULT_FRICTION.coulomb_smoothing_rad_s,
        help=f"width v_eps of the smooth sign tanh(dq / v_eps) of the friction terms, rad/s; 0 = the exact sign "
        f"(default {_DEFAULT_FRICTION.coulomb_smoothing_rad_s:g})",
    )
    parser.add_argument("--armature", action="store_true", help="add a rotor inertia per joint to the model")
    parser.add_argument("--cutoff", type=float, default=4.0, help="zero-phase low-pass cutoff, Hz (default 4)")
    parser.add_argument("--decimate", type=int, default=5, help="keep every k-th sample after filtering (default 5)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the estimators (default 0)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")


def _add_gain_arguments(parser: argparse.ArgumentParser) -> None:
    """``--identify-gains`` and its reference (identify and cross-validate)."""
    parser.add_argument(
        "--identify-gains", action="store_true", help="identify the motor torque constants with the parameters (current logs)"
    )
    parser.add_argument(
        "--gain-reference",
        default="gravity",
        help="what fixes the gains' scale: 'gravity' (the URDF's gravity torques) or 'joint:J[,J2...]' (these joints keep the model's constants) (default gravity)",
    )


def _add_presliding_argument(parser: argparse.ArgumentParser) -> None:
    """``--presliding`` (identify and cross-validate)."""
    parser.add_argument(
        "--presliding",
        action="store_true",
        help="presliding (Dahl) friction: per joint, the Coulomb level's onset follows the position over a presliding "
        "length, or keeps the rate's smooth sign, as the training movements' cost chooses (needs a Coulomb term)",
    )


def add_arm_identify_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``spaceid arm identify``."""
    _add_data_arguments(parser)
    _add_gain_arguments(parser)
    _add_presliding_argument(parser)
    parser.add_argument("--train", default=None, help="comma-separated training movements (default: all but --validate)")
    parser.add_argument("--validate", default=None, help="comma-separated held-out movements (default none)")
    parser.add_argument(
        "--estimator",
        default="wls",
        help="estimator spec, e.g. wls, improved-abc[consistent=true,polish=true,max_evaluations=100000] (default wls)",
    )


def add_arm_cross_validate_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``spaceid arm cross-validate``."""
    _add_data_arguments(parser)
    _add_gain_arguments(parser)
    _add_presliding_argument(parser)
    parser.add_argument("--movements", default=None, help="comma-separated movements (default all)")
    parser.add_argument(
        "--estimators",
        default="ols,wls,sdp,improved-abc[consistent=true,polish=true,max_evaluations=100000]",
        help="comma-separated estimator specs (default ols, wls, the convex consistent optimum sdp, the consistent improved ABC)",
    )
    parser.add_argument(
        "--compare-without-friction", action="store_true", help="also fit the model without friction (the error friction removes)"
    )
    parser.add_argument(
        "--ur-model-friction",
        default=",".join(CONTROLLER_FRICTION),
        help=f"friction terms of UR's refitted model (default {','.join(CONTROLLER_FRICTION)})",
    )
    parser.add_argument(
        "--compare-ur-model",
        action="store_true",
        help="also refit UR's own model on the same folds (real logs: per joint current ~ gain x m_target + friction)",
    )
    add_executor_arguments(parser)


def add_arm_diagnose_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``spaceid arm diagnose`` (its model default: no friction, the model to be diagnosed)."""
    _add_data_arguments(parser)
    parser.set_defaults(friction="none")
    parser.add_argument("--movements", default=None, help="comma-separated movements (default all)")
    parser.add_argument("--apply", action="store_true", help="add the named term, refit and report the error before and after")


def _names(text: str | None) -> list[str] | None:
    return None if text is None else [n.strip() for n in text.split(",") if n.strip()]


def _movements(args: argparse.Namespace, names: list[str] | None) -> tuple[Any, dict[str, Any], dict[str, Any]]:
    """The signal chain, the raw logs and their processed noise floors (simulated data) from the arguments."""
    if args.decimate < 1:
        raise SpaceIdInputError(f"--decimate: expected an integer >= 1, got {args.decimate}")
    friction_model(args, ())  # the velocity options are checked before the logs load
    preparation = Preparation(cutoff_hz=args.cutoff, decimate_factor=args.decimate)
    raw = load_movements(args.data, names)
    floors = {name: processed_noise_floor(preparation, simulated_noise_std(args.data, name), raw[name]) for name in raw}
    return preparation, raw, floors


def friction_model(args: argparse.Namespace, terms: tuple[str, ...]) -> FrictionModel:
    """The friction ``terms`` with the velocities of ``--stribeck-velocity`` and ``--coulomb-smoothing``."""
    stribeck, smoothing = args.stribeck_velocity, args.coulomb_smoothing
    if not (np.isfinite(stribeck) and stribeck > 0):
        raise SpaceIdInputError(f"--stribeck-velocity: expected a velocity > 0 rad/s, got {stribeck!r}")
    if not (np.isfinite(smoothing) and smoothing >= 0):
        raise SpaceIdInputError(f"--coulomb-smoothing: expected a width >= 0 rad/s (0 = the exact sign), got {smoothing!r}")
    return FrictionModel(terms, coulomb_smoothing_rad_s=smoothing, stribeck_velocity_rad_s=stribeck)


def _model(args: argparse.Namespace, friction: tuple[str, ...] | None = None) -> Any:
    terms = parse_friction(args.friction) if friction is None else friction
    return ArmIdentificationModel.build(load_arm(args.robot), friction_model(args, terms), args.armature)


def _error_line(error: Any) -> str:
    ratio = error.noise_ratio
    text = (
        f"  {error.movement:<40} " + " ".join(f"{v:6.1f}" for v in error.relative_percent) + f" | {error.overall_percent:6.1f} %"
    )
    return text + ("" if ratio is None else " | x noise: " + " ".join(f"{v:.3f}" for v in ratio))


def run_arm_identify(args: argparse.Namespace) -> None:
    """``spaceid arm identify``: fit on the training movements, validate on the held-out ones, write the results.

    Writes ``estimate.json`` (the base-parameter estimate), ``validation.json`` (per held-out movement the per-joint
    relative error, its overall figure and, for simulated data, the error in noise units) and one overlay per held-out
    movement (``overlay_<movement>.png``).
    """
    validate = _names(args.validate) or []
    train = _names(args.train)
    overlap = set(validate) & set(train or [])
    if overlap:
        raise SpaceIdInputError(f"--train and --validate: movements {sorted(overlap)} are in both")
    preparation, raw, floors = _movements(args, None if train is None else [*train, *validate])
    missing = [n for n in validate if n not in raw]
    if missing:
        raise SpaceIdInputError(f"--validate: no movement {missing} in {args.data}; available: {', '.join(raw)}")
    train = train or [n for n in raw if n not in validate]
    if not train:
        raise SpaceIdInputError("--train: no training movement left (every movement is in --validate)")
    model = _model(args)
    presliding = args.presliding
    if presliding:
        check_presliding_model(model)
        if args.identify_gains:
            raise SpaceIdInputError("--presliding and --identify-gains: not available together (the gains rescale the rows)")
    estimator = estimator_from_spec(args.estimator, seed=args.seed)
    rows = preparation.all_rows(model, raw)
    gains, choice = None, None
    if presliding:
        columns = presliding_for_movements(model, raw, preparation)
        choice = choose_for_rows(model, {n: rows[n] for n in train}, columns)
        rows = {name: with_presliding(model, item, columns[name], choice) for name, item in rows.items()}
        print(f"presliding length per joint (rad, chosen on the training movements): {choice.text()}")
    if args.identify_gains:
        kappa = max(preparation.correlation_factor(raw_period(raw[n])) for n in train)
        gains = identify_gains(model, {n: rows[n] for n in train}, args.gain_reference, kappa=kappa)
        rows = scaled_rows(rows, gains.correction)
        print(
            f"torque constants (N m/A, reference {args.gain_reference}, {gains.iterations} iterations, "
            f"converged {gains.converged}): " + " ".join(f"{k:.3f}" for k in gains.torque_constants_Nm_A)
        )
        if gains.gain_std_relative is not None:
            print(
                "  Cramér-Rao std of each (%, the filtered rows' correlation accounted for): "
                + " ".join(f"{100 * v:.1f}" for v in gains.gain_std_relative)
            )
    estimate = fit(model, {n: rows[n] for n in train}, estimator)
    args.out.mkdir(parents=True, exist_ok=True)
    described = model.describe() + (" + presliding" if choice is not None else "")
    estimate.extra.update(model=described, preparation=preparation.as_dict())
    if gains is not None:
        estimate.extra["gains"] = gains.to_dict()
    if choice is not None:
        estimate.extra["presliding_rad"] = choice.lengths_rad
    estimate.write_json(args.out / "estimate.json")
    errors = [prediction_error(model, estimate.theta, rows[name], floors[name]) for name in validate]
    write_json_atomic(
        args.out / "validation.json",
        {
            "model": described,
            "estimator": args.estimator,
            "training_movements": train,
            "held_out": [e.to_dict() for e in errors],
        },
    )
    unit = "A" if any(raw[n].effort_kind == "current_A" for n in validate) else "N m"
    for name, error in zip(validate, errors, strict=True):
        log = rows[name].log
        plot_overlay(
            args.out / f"overlay_{name}.png",
            log.t_s - log.t_s[0],
            log.effort,
            log.effort - error.residual,
            channel_names=[f"joint {j + 1}" for j in range(model.n_joints)],
            title=f"{name}: measured vs {args.estimator} ({described})",
            units=unit,
        )
    consistent = estimate.physical.get("links_physically_consistent")
    print(
        f"{described}; {estimate.estimator} on {len(train)} movement(s) in {estimate.wall_time_s:.1f} s "
        f"({estimate.n_evaluations:.0f} evaluations)"
        + ("" if consistent is None else f"; physically consistent links: {sum(consistent)}/{len(consistent)}")
    )
    excess = estimate.extra.get("cost_excess_over_sdp")
    if excess is not None:
        print(f"training cost {100.0 * excess:+.4f} % over the sdp optimum of the same cost")
    if errors:
        print("held-out relative error per joint (%) | overall")
        for error in errors:
            print(_error_line(error))
    print(f"wrote {args.out}/estimate.json, validation.json" + (", overlay_<movement>.png" if errors else ""))


def run_arm_cross_validate(args: argparse.Namespace) -> None:
    """``spaceid arm cross-validate``: leave one movement out, for each estimator (and without friction if asked);
    writes ``table.md`` and ``rows.json`` and prints the per-model, per-estimator means."""
    executor = executor_from_arguments(args, max_jobs())
    preparation, logs, floors = _movements(args, _names(args.movements))
    specs = parse_estimator_specs(args.estimators)
    estimators = {spec: estimator_from_spec(spec, seed=args.seed) for spec in specs}
    presliding = args.presliding
    label = (args.friction if parse_friction(args.friction) else "no friction") + (" + armature" if args.armature else "")
    label += " + presliding" if presliding else ""
    models = {f"with {label}": _model(args)}
    if presliding:
        check_presliding_model(models[f"with {label}"])
    if args.compare_without_friction:
        models["without friction"] = _model(args, ())
    start = time.perf_counter()
    gain_reference = args.gain_reference if args.identify_gains else None
    dahl = [f"with {label}"] if presliding else []
    rows = leave_one_out(models, logs, estimators, preparation, floors, executor, gain_reference, dahl)
    implied_gains = None
    if getattr(args, "compare_ur_model", False):
        terms = parse_friction(args.ur_model_friction)
        controller = load_controller_rows(args.data, logs, preparation, friction_model(args, terms))
        controller_rows, coefficients = controller_model_leave_one_out(controller, floors, controller_estimator_label(terms))
        rows += controller_rows
        implied_gains = {name: (1.0 / c[:, 0]).tolist() for name, c in coefficients.items()}
    joint_names = [f"joint {j + 1}" for j in range(next(iter(models.values())).n_joints)]
    args.out.mkdir(parents=True, exist_ok=True)
    summary = summary_table(rows)
    table = cross_validation_markdown(rows, joint_names)
    write_text_atomic(args.out / "table.md", table)
    write_json_atomic(
        args.out / "rows.json",
        {
            "models": {k: m.describe() for k, m in models.items()},
            "friction_velocities_rad_s": {
                "coulomb_smoothing": args.coulomb_smoothing,
                "stribeck": args.stribeck_velocity,
            },
            "summary": summary,
            "rows": [r.to_dict() for r in rows],
            "wall_time_s": time.perf_counter() - start,
            "executor": executor.describe(),
            "ur_model_torque_constants_Nm_A": implied_gains,
        },
    )
    print(
        f"leave one movement out over {len(logs)} movements in {time.perf_counter() - start:.1f} s ({executor.describe()}); "
        "mean held-out error (%):"
    )
    for entry in summary:
        cells = " ".join(f"{v:6.1f}" for v in entry["mean_relative_percent"])
        excess = entry["max_cost_excess_over_sdp"]
        print(
            f"  {entry['model']:<28} {entry['estimator']:<60} {cells} | {entry['mean_overall_percent']:6.1f} %"
            f" | consistent: {entry['all_consistent']} | {entry['mean_wall_time_s']:.2f} s/fit"
            + ("" if excess is None else f" | cost over sdp: {100.0 * excess:+.4f} % (largest)")
        )
    identified = [r.torque_constants_Nm_A for r in rows if r.torque_constants_Nm_A is not None]
    if identified:
        print(
            f"torque constants identified (N m/A, reference {gain_reference}, mean over folds): "
            + " ".join(f"{v:.2f}" for v in np.mean(identified, axis=0))
        )
    chosen = [(r.error.movement, r.presliding_rad) for r in rows if r.presliding_rad is not None]
    if chosen:
        print(
            "presliding length per joint (rad, each fold's training movements; coulomb = the smooth sign), by held-out movement:"
        )
        for movement, lengths in dict(chosen).items():
            print(f"  {movement:<40} " + " ".join("coulomb" if v is None else f"{v:.1e}" for v in lengths))
    if implied_gains:
        mean = np.mean(list(implied_gains.values()), axis=0)
        print(
            "torque constants UR's refitted model implies (1 / gain, N m/A, mean over folds): "
            + " ".join(f"{v:.2f}" for v in mean)
        )
    print(f"wrote {args.out}/table.md, rows.json")


def run_arm_diagnose(args: argparse.Namespace) -> None:
    """``spaceid arm diagnose``: which joint term is missing (friction, armature, offset), where the model fails;
    with ``--apply``, the error before and after adding it. Writes ``diagnosis.json``."""
    preparation, logs, floors = _movements(args, _names(args.movements))
    model = _model(args)
    diagnosis = diagnose_arm(model, logs, preparation)
    print(f"model: {model.describe()}")
    print(f"verdict: {diagnosis.verdict}" + (f" ({diagnosis.family})" if diagnosis.family else "") + f": {diagnosis.reason}")
    print("candidates (best BIC first): " + "; ".join(f"{f.label} dBIC {f.delta_bic:.0f}" for f in diagnosis.candidates))
    final = diagnosis.baseline
    if args.apply and diagnosis.best() is not None:
        best = diagnosis.best()
        assert best is not None
        before = {n: prediction_error(model, diagnosis.baseline.theta, diagnosis.baseline.rows[n], floors[n]) for n in logs}
        after = {n: prediction_error(best.model, best.theta, best.rows[n], floors[n]) for n in logs}
        diagnosis.extra["applied"] = {
            "model": best.model.describe(),
            "before": [e.to_dict() for e in before.values()],
            "after": [e.to_dict() for e in after.values()],
        }
        print(
            f"added {diagnosis.verdict}: fit error over all joints (all movements in the fit) before -> after"
            + (" (x noise floor)" if all(f is not None for f in floors.values()) else "")
        )
        for name in logs:
            b, a = before[name], after[name]
            line = f"  {name:<40} {b.overall_percent:6.1f} % -> {a.overall_percent:6.1f} %"
            if a.overall_noise_ratio is not None and b.overall_noise_ratio is not None:
                line += f" | {b.overall_noise_ratio:.2f} -> {a.overall_noise_ratio:.3f} x noise"
            print(line)
        final = best
    if len(logs) >= 2:
        failing = where_it_fails(final.model, final.rows)
        diagnosis.extra["where_it_fails"] = failing.to_dict()
        ranked = failing.ranked()
        print(f"where it fails ({final.model.describe()}, held-out residual vs the movement's typical level, worst first):")
        for name, segment in ranked[:8]:
            t0 = logs[name].t_s[0]
            print(
                f"  {name:<40} t = {segment.t_start_s - t0:5.1f}-{segment.t_end_s - t0:5.1f} s: {segment.rms_over_noise:.2f} x typical"
            )
        if not ranked:
            print("  no window stands out")
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "diagnosis.json", diagnosis.to_dict())
    print(f"wrote {args.out}/diagnosis.json")


#: ``spaceid arm <command>`` -> its body
ARM_COMMANDS: dict[str, Any] = {
    "simulate": run_arm_simulate,
    "identify": run_arm_identify,
    "cross-validate": run_arm_cross_validate,
    "diagnose": run_arm_diagnose,
}
