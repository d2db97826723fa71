"""The excitation comparison: random multi-sine, one joint at a time, optimised Fourier series and a learnt policy.

Every method drives the same identification windows: for episode i the satellite seed is
``HELD_OUT_FIRST_SEED + i`` (never drawn in training, :mod:`agents.policy`), from which ``default_rng`` draws the fuel
consumed (uniform in the prior range) and the tank position (uniform in its box); the window is simulated by
:func:`spaceid_gym.datasets.simulate_episode` with that seed (same noise, same initial pose for every method), at the
env's default 50 Hz, default sensors, equal duration and the same rate, acceleration and joint limits (the env's).

Per window and method:

* the excitation measures of the gyro data (:meth:`FreeFloatingIDEnv.excitation_measures`, information at the true
  parameters, prior-range units): D-optimality ``log det F_s`` and the largest Cramér-Rao std (scaled);
* the default estimator's (``hybrid``, seed 0) actual errors on the log: fuel consumed ``mdf`` (kg), tank position
  ``|bf^ - bf|`` (mm) and base mass ``M`` (%), as in :mod:`estimators.evaluation`;
* the peak base attitude excursion: the largest rotation angle of the measured attitude (star tracker, 5 arcsec
  noise) from the initial one, degrees.

``random_targets`` drives the arm through the policy's action space without the learning (uniform random joint
targets every 0.5 s, :class:`~agents.policy.RandomTargets`): what the policy adds to its action space.
``fourier_equal_attitude`` holds the optimised Fourier series against the policy at equal attitude
excursion: on each window its amplitude is scaled by the policy's peak excursion over the full series' (at most 1,
:func:`fourier_doc_scaled`). It is the optimised series made gentler, not a series optimised under an attitude limit.

The summary gives per method the medians of the measures, the median and 95th percentile of the errors and the median
and largest peak excursion; plots: errors per method and the Pareto plot of D-optimality against peak excursion.
"""

from __future__ import annotations

import math
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import torch
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from agents.policy import HELD_OUT_FIRST_SEED, ExcitationPolicy, RandomTargets
from estimators.evaluation import quantity_errors
from estimators.problem import IdentificationModel
from estimators.registry import make_estimator
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.fuel_excitation_design import FourierRateExcitation, OneJointExcitation
from spaceid_gym.log import MeasurementLog, write_csv_atomic, write_text_atomic
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.robots import load_robot

#: the methods, in table order
METHODS = ("random", "one_joint", "fourier", "policy", "random_targets", "fourier_equal_attitude")
#: the error quantities reported (name -> unit)
ERRORS = {"mdf": "kg", "bf": "mm", "M": "%"}


def held_out_setting(robot_name: str, index: int) -> tuple[int, float, np.ndarray]:
    """The satellite seed, fuel consumed (kg) and tank position (m) of held-out window ``index``."""
    robot = load_robot(robot_name)
    seed = HELD_OUT_FIRST_SEED + index
    rng = np.random.default_rng(seed)
    schedule = FuelSchedule()
    fuel = float(rng.uniform(schedule.initial_fraction, schedule.usable_fraction) * robot.base_full.mass_kg)
    return seed, fuel, schedule.draw_tank_position(robot.base_full, rng)


def peak_attitude_excursion_deg(log: MeasurementLog) -> float:
    """The largest rotation angle of the logged attitude from its first sample, degrees (nan without attitude)."""
    quat = log.quat_base_to_inertial_wxyz
    if quat is None:
        return math.nan
    dot = np.abs(quat @ quat[0]) / (np.linalg.norm(quat, axis=1) * np.linalg.norm(quat[0]))
    return float(np.degrees(2.0 * np.arccos(np.clip(dot, -1.0, 1.0))).max())


def _episode(task: tuple[str, int, float, dict[str, Any] | None, str | None]) -> list[dict[str, Any]]:
    """All methods on held-out window ``index`` (run in a worker process)."""
    robot_name, index, duration_s, fourier_doc, policy_folder = task
    torch.set_num_threads(1)  # a 64 x 64 network: threads only contend with the other worker
    robot = load_robot(robot_name)
    seed, fuel, tank = held_out_setting(robot_name, index)
    methods: dict[str, Callable[[], Any]] = {
        "random": lambda: FourierExcitation(robot.n_joints, seed=seed),
        "one_joint": lambda: OneJointExcitation(robot.n_joints, duration_s),
    }
    if fourier_doc is not None:
        methods["fourier"] = lambda: FourierRateExcitation.from_dict(fourier_doc)
    if policy_folder is not None:
        methods["policy"] = lambda: ExcitationPolicy.load(policy_folder, robot=robot.name, params="fuel")
        methods["random_targets"] = lambda: RandomTargets(seed)
    model = IdentificationModel(robot, "fuel")
    rows: list[dict[str, Any]] = []
    if fourier_doc is not None and policy_folder is not None:  # after both: scaled to the policy's excursion
        methods["fourier_equal_attitude"] = lambda: FourierRateExcitation(fourier_doc_scaled(fourier_doc, rows), duration_s)
    for method, make in methods.items():
        env = simulate_episode(robot, duration_s, fuel, tank, make(), seed)
        measures = env.excitation_measures()
        log = env.measurement_log()
        estimate = make_estimator("hybrid", seed=0).fit(model, log)
        errors = quantity_errors(
            model.parameters.physical(estimate.theta), model.parameters.physical(np.concatenate(([fuel], tank)))
        )
        rows.append(
            {
                "method": method,
                "episode": index,
                "seed": seed,
                "fuel_consumed_kg": fuel,
                "d_optimality": measures.d_optimality,
                "max_cramer_rao_std_scaled": measures.max_cramer_rao_std,
                "condition_number": measures.condition_number,
                **{f"error_{name}_{unit.replace('%', 'pct')}": errors[name] for name, unit in ERRORS.items()},
                "peak_attitude_excursion_deg": peak_attitude_excursion_deg(log),
            }
        )
    return rows


def fourier_doc_scaled(fourier_doc: dict[str, Any], rows: list[dict[str, Any]]) -> np.ndarray:
    """The Fourier coefficients scaled by ``policy excursion / Fourier excursion`` of this window's rows (at most 1):
    the peak attitude excursion grows about linearly with the amplitude (0.2 x the amplitude: 0.20 x the excursion on
    paper6), so the scaled series turns the base about as far as the policy did."""
    excursion = {r["method"]: r["peak_attitude_excursion_deg"] for r in rows}
    scale = min(1.0, excursion["policy"] / excursion["fourier"]) if excursion["fourier"] > 0 else 1.0
    return np.asarray(fourier_doc["coefficients"], dtype=float) * scale


def run_comparison(
    robot: str,
    episodes: int,
    fourier: FourierRateExcitation | None,
    policy_folder: str | Path | None,
    duration_s: float = 60.0,
    jobs: int = 1,
    first_window: int = 0,
) -> list[dict[str, Any]]:
    """Rows (one per window and method) of the comparison (module docstring) on held-out windows ``first_window``
    onwards; ``jobs`` worker processes."""
    fourier_doc = None if fourier is None else fourier.to_dict()
    folder = None if policy_folder is None else str(policy_folder)
    tasks = [(robot, first_window + i, float(duration_s), fourier_doc, folder) for i in range(episodes)]
    if jobs <= 1:
        results = [_episode(t) for t in tasks]
    else:
        # spawned, not forked: the parent has torch loaded, and a fork of its threads deadlocks the workers
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            results = list(pool.map(_episode, tasks))
    return [row for rows in results for row in rows]


def summarise(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method: medians of the measures, median and 95th percentile of each error, median and largest excursion."""
    summary = []
    for method in METHODS:
        mine = [r for r in rows if r["method"] == method]
        if not mine:
            continue

        def column(key: str, rows_: list[dict[str, Any]] = mine) -> np.ndarray:
            return np.array([r[key] for r in rows_], dtype=float)

        entry: dict[str, Any] = {"method": method, "episodes": len(mine)}
        entry["d_optimality_median"] = float(np.median(column("d_optimality")))
        entry["max_cramer_rao_std_scaled_median"] = float(np.median(column("max_cramer_rao_std_scaled")))
        for name, unit in ERRORS.items():
            key = f"error_{name}_{unit.replace('%', 'pct')}"
            entry[f"{key}_median"] = float(np.median(column(key)))
            entry[f"{key}_p95"] = float(np.percentile(column(key), 95))
        entry["peak_attitude_excursion_deg_median"] = float(np.median(column("peak_attitude_excursion_deg")))
        entry["peak_attitude_excursion_deg_max"] = float(np.max(column("peak_attitude_excursion_deg")))
        summary.append(entry)
    return summary


def markdown_table(summary: Sequence[dict[str, Any]]) -> str:
    """The summary as a markdown table."""
    header = (
        "| method | D-optimality (median) | largest CR std (median, prior ranges) | mdf error kg (median / p95) "
        "| bf error mm (median / p95) | M error % (median / p95) | peak attitude excursion deg (median / max) |"
    )
    lines = [header, "|" + "---|" * 7]
    for s in summary:
        lines.append(
            f"| {s['method']} | {s['d_optimality_median']:.2f} | {s['max_cramer_rao_std_scaled_median']:.4f} "
            f"| {s['error_mdf_kg_median']:.2f} / {s['error_mdf_kg_p95']:.2f} | {s['error_bf_mm_median']:.1f} / {s['error_bf_mm_p95']:.1f} "
            f"| {s['error_M_pct_median']:.3f} / {s['error_M_pct_p95']:.3f} "
            f"| {s['peak_attitude_excursion_deg_median']:.1f} / {s['peak_attitude_excursion_deg_max']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def write_tables(
    folder: Path, rows: list[dict[str, Any]], summary: list[dict[str, Any]], table: str, info: dict[str, Any]
) -> dict[str, Path]:
    """Write ``episodes.csv`` (the rows), ``summary.csv`` and ``table.md`` (the settings in ``info`` as comments, then
    ``table``) to ``folder`` (created)."""
    folder.mkdir(parents=True, exist_ok=True)
    preamble = "".join(f"<!-- {k}: {v} -->\n" for k, v in info.items())
    return {
        "episodes": write_csv_atomic(folder / "episodes.csv", rows),
        "summary": write_csv_atomic(folder / "summary.csv", summary),
        "table": write_text_atomic(folder / "table.md", preamble + table),
    }


def write_comparison(out: str | Path, rows: list[dict[str, Any]], info: dict[str, Any]) -> dict[str, Path]:
    """Write ``episodes.csv``, ``summary.csv``, ``table.md``, ``errors.png`` and ``pareto.png`` to ``out``."""
    folder = Path(out)
    summary = summarise(rows)
    paths = write_tables(folder, rows, summary, markdown_table(summary), info)
    methods = [s["method"] for s in summary]
    figure = Figure(figsize=(10, 4))
    for i, (name, unit) in enumerate(ERRORS.items()):
        ax = figure.add_subplot(1, len(ERRORS), i + 1)
        key = f"error_{name}_{unit.replace('%', 'pct')}"
        ax.boxplot([[r[key] for r in rows if r["method"] == m] for m in methods], tick_labels=methods)
        ax.set_yscale("log")
        ax.set_title(f"{name} error ({unit})")
        ax.tick_params(axis="x", labelrotation=30)
    figure.tight_layout()
    FigureCanvasAgg(figure).print_png(str(folder / "errors.png"))
    paths["errors_plot"] = folder / "errors.png"
    figure = Figure(figsize=(6, 4.5))
    ax = figure.add_subplot(1, 1, 1)
    for m in methods:
        mine = [r for r in rows if r["method"] == m]
        ax.scatter([r["peak_attitude_excursion_deg"] for r in mine], [r["d_optimality"] for r in mine], label=m, s=12)
    ax.set_xlabel("peak base attitude excursion (deg)")
    ax.set_ylabel("D-optimality log det F (prior-range units)")
    ax.set_title("information vs attitude excursion (each point a window)")
    ax.legend()
    figure.tight_layout()
    FigureCanvasAgg(figure).print_png(str(folder / "pareto.png"))
    paths["pareto_plot"] = folder / "pareto.png"
    return paths


def default_jobs() -> int:
    """Worker processes by default: the machine's cores."""
    return os.cpu_count() or 1
