"""The demonstration run by ``spaceid demo``: simulate, reload, compare the model, rank excitations.

1. Simulate a 60 s identification window of the built-in robot with a Fourier excitation and
   write the dataset folder (``run1/``: log.csv, robot.urdf, truth.json).
2. Load it back as a user would and compare the measured base rate with the momentum model
   (eq. 8) evaluated with the nominal full-tank base and with the true base: the residual of the
   true base sits at the gyro noise floor, the nominal one does not. That gap is what the
   estimators identify.
3. Identify the fuel state (mdf, tank position) from the reloaded log with the default estimator
   (``hybrid``: improved PSO, then Levenberg-Marquardt), write ``run1/estimate.json`` and compare it
   with ``truth.json`` key by key, in units of the estimate's own Cramér-Rao standard deviation.
4. The user's loop on a second window that hides a physical effect the paper's model leaves out (a residual
   system angular momentum): compare the model with the measurements, diagnose which effect is missing, add it and
   watch the residual fall to the noise and the fuel estimate come back within its Cramér-Rao bound; the whole of
   it as one HTML page (``loop-report.html``).
5. Compare excitations by the Cramér-Rao bound they leave on the fuel parameters.
6. Save an overlay plot, a rendered frame and ``summary.json``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from estimators.diagnostics.suite import DIAGNOSTIC_EXCITATION
from estimators.diagnostics.workflow import run_loop, write_report
from estimators.problem import IdentificationModel
from estimators.registry import make_estimator
from spaceid_gym.datasets import simulate_episode, write_episode_dataset
from spaceid_gym.effects.draws import draw_effect
from spaceid_gym.envs.render import RobotRenderer, base_half_extents_from_inertia
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.log import Dataset, MeasurementLog
from spaceid_gym.physics.inertia import RigidBodyInertia
from spaceid_gym.physics.momentum import base_rate_from_joint_motion
from spaceid_gym.robots import load_robot, robot_from_urdf_text

FUEL_CONSUMED_KG = 40.0
TANK_POSITION_M = np.array([0.30, -0.10, 0.20])
DURATION_S = 60.0
AVERAGE_S = 1.0  # moving-average window that separates structured residuals from white noise
HIDDEN_EFFECT = "initial_momentum"  # the effect hidden in the loop's window (step 4), at its catalogue size


def run_demo(out: Path, robot_name: str = "paper6", seed: int = 3) -> dict[str, Any]:
    """Run the demonstration, write its files under ``out`` and return the summary."""
    out.mkdir(parents=True, exist_ok=True)
    robot = load_robot(robot_name)
    print(f"[1/6] simulating {DURATION_S:.0f} s of {robot.name} (fuel consumed {FUEL_CONSUMED_KG} kg, tank {TANK_POSITION_M} m)")
    env = simulate_episode(robot, DURATION_S, FUEL_CONSUMED_KG, TANK_POSITION_M, FourierExcitation(robot.n_joints, seed), seed)
    dataset = write_episode_dataset(out / "run1", env, {"seed": seed, "excitation": {"kind": "fourier", "seed": seed}})
    assert dataset.truth is not None
    print(f"      wrote {dataset.path}/log.csv, robot.urdf, truth.json ({dataset.log.n_samples} samples)")

    print("[2/6] model vs measurement: base rate predicted from joint motion (eq. 8)")
    comparison = _compare_with_model(dataset.log, dataset.robot_urdf_path.read_text(), dataset.truth)
    sigma = comparison["gyro_noise_std_rad_s"]
    print(
        f"      gyro noise {sigma:.3e} rad/s per sample; after a {AVERAGE_S:.0f} s moving average it should be "
        f"{comparison['averaged_noise_std_rad_s']:.2e}"
    )
    for name in ("nominal_full_tank", "true_base"):
        rms, averaged = comparison[name]["residual_rms_rad_s"], comparison[name]["averaged_residual_rms_rad_s"]
        print(
            f"      {name:18s} residual RMS {rms:.3e} rad/s ({rms / sigma:5.3f} x noise); "
            f"averaged {averaged:.2e} rad/s ({averaged / comparison['averaged_noise_std_rad_s']:5.2f} x averaged noise)"
        )
    _plot_overlay(out / "overlay.png", dataset.log, comparison.pop("_predictions"), comparison["averaged_noise_std_rad_s"])

    print("[3/6] identification: fuel state from the reloaded log (estimator 'hybrid')")
    identification = _identify(dataset)
    print(f"[4/6] the loop on a window hiding an effect the model leaves out ({HIDDEN_EFFECT}): compare, diagnose, add")
    loop = _loop(robot, seed, out / "loop-report.html")
    print("[5/6] excitation: Cramér-Rao bound on the fuel parameters after one window")
    excitations = {
        "fourier (5 harmonics)": FourierExcitation(robot.n_joints, seed),
        "one joint (joint 2)": _single_joint(robot.n_joints, 1),
        "random actions": _random_actions(robot.n_joints, seed),
    }
    information = {}
    for label, excitation in excitations.items():
        env = simulate_episode(robot, DURATION_S, FUEL_CONSUMED_KG, TANK_POSITION_M, excitation, seed)
        std = env.cramer_rao_std()
        information[label] = {"fuel_consumed_std_kg": float(std[0]), "tank_position_std_m": std[1:].tolist()}
        print(f"      {label:22s} std(mdf) {std[0]:8.3f} kg   std(bf) {np.array2string(std[1:], precision=4)} m")

    print("[6/6] rendering the final pose")
    renderer = RobotRenderer(
        env.simulator.model, base_half_extents_from_inertia(robot.base_full.mass_kg, robot.base_full.inertia_com_kgm2)
    )
    frame = renderer.render(env.simulator.state.pinocchio_configuration(), info_text=f"{robot.name}: end of the window")
    _save_png(out / "frame.png", frame)
    summary = {
        "dataset": str(dataset.path),
        "comparison": comparison,
        "identification": identification,
        "loop": loop,
        "cramer_rao": information,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"done: {out}/overlay.png, {out}/frame.png, {out}/summary.json")
    return summary


def _identify(dataset: Dataset) -> dict[str, Any]:
    """Fit the default estimator on the dataset as a user would (URDF + log only) and hold it against the truth."""
    robot = robot_from_urdf_text(dataset.robot_urdf_path.read_text(), "robot.urdf")
    estimate = make_estimator("hybrid", seed=0).fit(IdentificationModel(robot, "fuel"), dataset.log)
    estimate.write_json(dataset.path / "estimate.json")
    print(f"      wrote {dataset.path}/estimate.json ({estimate.n_evaluations:.0f} evaluations, {estimate.wall_time_s:.2f} s)")
    assert dataset.truth is not None
    doc = estimate.to_dict()
    result: dict[str, Any] = {
        "estimate": str(dataset.path / "estimate.json"),
        "wall_time_s": estimate.wall_time_s,
        "errors_in_std": {},
    }
    for key in ("fuel_consumed_kg", "tank_position_m", "base_mass_kg", "base_com_m"):
        value, std, true = np.asarray(doc[key]), np.asarray(doc[f"{key}_std"]), np.asarray(dataset.truth[key])
        in_std = (value - true) / std
        result["errors_in_std"][key] = in_std.tolist()
        print(
            f"      {key:17s} estimate {np.array2string(value, precision=4)} +- {np.array2string(std, formatter={'float_kind': '{:.2g}'.format})}, "
            f"true {np.array2string(true, precision=4)} ({np.array2string(in_std, precision=2)} std)"
        )
    return result


def _loop(robot: Any, seed: int, report: Path) -> dict[str, Any]:
    """Simulate a window whose truth hides :data:`HIDDEN_EFFECT`, run compare -> diagnose -> add -> compare on it and
    write the HTML report; the verdict and the figures before and after."""
    hidden = draw_effect(HIDDEN_EFFECT, np.random.default_rng(seed), robot, FUEL_CONSUMED_KG)
    excitation = FourierExcitation(robot.n_joints, seed=seed, **DIAGNOSTIC_EXCITATION)
    env = simulate_episode(robot, DURATION_S, FUEL_CONSUMED_KG, TANK_POSITION_M, excitation, seed, hidden_effects=hidden)
    result = run_loop(IdentificationModel(robot, "fuel"), env.measurement_log(), truth=env.truth())
    for line in result.summary().splitlines():
        print(f"      {line}")
    write_report(result, report)
    print(f"      wrote {report}")
    return {
        "hidden": HIDDEN_EFFECT,
        "verdict": result.diagnosis.verdict,
        "before_after": result.before_after_rows(),
        "report": str(report),
    }


def _compare_with_model(log: MeasurementLog, urdf_text: str, truth: dict[str, Any]) -> dict[str, Any]:
    robot = robot_from_urdf_text(urdf_text, "robot.urdf")
    true_base = RigidBodyInertia(truth["base_mass_kg"], np.array(truth["base_com_m"]), np.array(truth["base_inertia_kgm2"]))
    predictions = {
        "nominal_full_tank": base_rate_from_joint_motion(robot.model, log.q_rad, log.dq_rad_s),
        "true_base": base_rate_from_joint_motion(robot.model_with_base(true_base), log.q_rad, log.dq_rad_s),
    }
    sigma = truth["noise"]["gyro_std_rad_s"]
    width = max(1, round(AVERAGE_S / log.sample_period_s))
    result: dict[str, Any] = {
        "gyro_noise_std_rad_s": sigma,
        "averaged_noise_std_rad_s": sigma / np.sqrt(width),
        "_predictions": predictions,
    }
    kernel = np.ones(width) / width
    for name, predicted in predictions.items():
        residual = log.omega_base_body_rad_s - predicted
        averaged = np.stack([np.convolve(residual[:, i], kernel, mode="valid") for i in range(3)], axis=1)
        result[name] = {
            "residual_rms_rad_s": float(np.sqrt(np.mean(residual**2))),
            "residual_rms_per_axis_rad_s": np.sqrt(np.mean(residual**2, axis=0)).tolist(),
            "averaged_residual_rms_rad_s": float(np.sqrt(np.mean(averaged**2))),
        }
    return result


def _single_joint(n_joints: int, joint: int) -> FourierExcitation:
    excitation = FourierExcitation(n_joints, seed=0, n_harmonics=1)
    mask = np.zeros((n_joints, 1))
    mask[joint] = 1.0
    excitation.amplitudes = 0.9 * mask
    return excitation


def _random_actions(n_joints: int, seed: int) -> Any:
    rng = np.random.default_rng(seed)
    return lambda _t: rng.uniform(-1.0, 1.0, n_joints).astype(np.float32)


def _plot_overlay(path: Path, log: MeasurementLog, predictions: dict[str, np.ndarray], averaged_noise_std: float) -> None:
    """Left: measured vs predicted base rate; right: residuals averaged over AVERAGE_S with a 2-sigma band."""
    fig = Figure(figsize=(13, 7))
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 2, sharex=True)
    width = max(1, round(AVERAGE_S / log.sample_period_s))
    kernel = np.ones(width) / width
    t_avg = np.convolve(log.t_s, kernel, mode="valid")
    styles = {"nominal_full_tank": ("r", "model, nominal full tank"), "true_base": ("b", "model, true base")}
    for i, axis in enumerate("xyz"):
        left, right = axes[i]
        left.plot(log.t_s, log.omega_base_body_rad_s[:, i], color="0.6", lw=1.0, label="measured (gyro)")
        for name, (color, label) in styles.items():
            left.plot(log.t_s, predictions[name][:, i], color=color, lw=0.8, label=label)
            residual = np.convolve(log.omega_base_body_rad_s[:, i] - predictions[name][:, i], kernel, mode="valid")
            right.plot(t_avg, residual, color=color, lw=0.8, label=label)
        right.axhspan(-2 * averaged_noise_std, 2 * averaged_noise_std, color="0.85", label="noise, 2 sigma")
        left.set_ylabel(f"omega_{axis} [rad/s]")
        right.set_ylabel(f"residual_{axis} [rad/s]")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[0, 1].legend(loc="upper right", fontsize=8)
    axes[0, 0].set_title("measured vs momentum model (eq. 8)")
    axes[0, 1].set_title(f"residual, {AVERAGE_S:g} s moving average")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle("Base angular rate, body frame: the true base leaves noise, the nominal base leaves structure")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def _save_png(path: Path, frame: np.ndarray) -> None:
    fig = Figure(figsize=(frame.shape[1] / 100, frame.shape[0] / 100), dpi=100)
    FigureCanvasAgg(fig)
    fig.figimage(frame)
    fig.savefig(path, dpi=100)
