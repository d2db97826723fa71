"""Episode-by-episode evaluation of estimators against the truth and the Cramér-Rao bound.

For each of ``n_settings`` true fuel states (fuel consumed and tank position drawn from the
documented ranges below) one identification window is simulated with the default excitation and
documented sensor noise; every estimator is fitted on the same window. Errors are reported in the
paper's form (Table 1 of source 1):

* ``M``: base mass, ``|m^ - m| / m`` (%);
* ``r``: base CoM position, ``|r^ - r| / |r|`` (%), ``r`` the CoM in the base link frame;
* ``Ixx``, ``Iyy``, ``Izz``: principal-axis entries of the inertia about the CoM, ``|I^ - I| / I`` (%);
* ``mdf`` (kg) and ``bf`` (``|bf^ - bf|``, mm): the fuel unknowns.

Each is summarised by its mean, median and 95th percentile, and by the ratio of the RMS error to
the RMS Cramér-Rao standard deviation (bound at the true parameters with the true gyro noise; for
``r`` and ``bf`` the root of the summed variances). ``bound_mean`` is the mean absolute error an
efficient unbiased estimator would have (``sqrt(2/pi)`` times the bound, in the same units), the
figure to hold against the paper's Table 1 when the bound lies above it.

Settings: fuel consumed ``mdf ~ U(initial, usable)`` of :class:`~spaceid_gym.mission.FuelSchedule`
(5-25 % of the wet base mass, 27.5-137.5 kg for ``paper6``), tank position uniform in its box
(+-0.40 m per axis for ``paper6``, from the full-tank CoM); a 60 s window at 50 Hz; excitation
:class:`~spaceid_gym.excitation.FourierExcitation` seeded per setting; the default
:class:`~spaceid_gym.sim.sensors.SensorModel` noise.

Seeds: setting ``i``'s estimators run with the seed ``job_seeds(seed, n_settings)[i]``
(:func:`spaceid_gym.executors.job_seeds`, ``numpy.random.SeedSequence(seed).spawn``), every estimator of the
setting with the same one; its window's noise, initial pose and excitation with the setting's own ``seed``. The
settings run as independent jobs on an :class:`~spaceid_gym.executors.ExecutorSpec` (in-process, local processes,
Dask), with bit-identical results whichever.

Equal budgets: with ``budget_reference`` (default ``"improved-pso"``), every other estimator with
a ``max_evaluations`` option gets, per setting, the evaluations the reference used on that window.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimators.base import Estimator
from estimators.problem import IdentificationModel, IdentificationProblem
from estimators.registry import make_estimator
from spaceid_gym.arrays import FloatArray
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.executors import ExecutorSpec, job_seeds, run_jobs
from spaceid_gym.files import write_csv_atomic, write_text_atomic
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.robots import Robot, load_robot
from spaceid_gym.specs import parse_setting, split_outside_brackets

#: the paper's Table 1 (improved PSO, % errors)
PAPER_TABLE1 = {"M": 0.60, "r": 2.79, "Ixx": 0.61, "Iyy": 0.63, "Izz": 0.93}
#: reported quantities: name -> unit of the error
QUANTITIES = {"M": "%", "r": "%", "Ixx": "%", "Iyy": "%", "Izz": "%", "mdf": "kg", "bf": "mm"}


@dataclass(frozen=True)
class Setting:
    """One true fuel state and the seed of its window (noise, initial pose, excitation)."""

    index: int
    seed: int
    fuel_consumed_kg: float
    tank_position_m: tuple[float, float, float]


def draw_settings(robot: Robot, n_settings: int, seed: int, schedule: FuelSchedule | None = None) -> list[Setting]:
    """``n_settings`` true fuel states drawn with ``default_rng(seed)`` from the documented ranges."""
    if n_settings < 1:
        raise SpaceIdInputError(f"settings: expected at least 1, got {n_settings}")
    schedule = schedule or FuelSchedule()
    rng = np.random.default_rng(seed)
    mass = robot.base_full.mass_kg
    out = []
    for i in range(n_settings):
        fuel = rng.uniform(schedule.initial_fraction, schedule.usable_fraction) * mass
        tank = schedule.draw_tank_position(robot.base_full, rng)
        out.append(Setting(i, int(rng.integers(2**31)), float(fuel), (float(tank[0]), float(tank[1]), float(tank[2]))))
    return out


def parse_estimator_specs(text: str) -> list[str]:
    """Split ``"improved-pso,pso[topology=ring,n_particles=20],lm"`` at the commas outside brackets."""
    specs = split_outside_brackets(text, "estimators")
    if not specs:
        raise SpaceIdInputError("estimators: expected a comma-separated list of estimator names")
    return specs


def estimator_from_spec(spec: str, **overrides: Any) -> Estimator:
    """``name[key=value,...]`` -> the registered estimator with those options (values parsed as JSON where
    possible, so ``inertia=[0.9,0.4]`` is a pair); ``overrides`` (e.g. ``seed``, ``max_evaluations``) replace
    options of the same name."""
    name, items = parse_setting(spec, f"estimator spec {spec!r}")
    options: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        if not sep:
            raise SpaceIdInputError(f"estimator spec {spec!r}: option {item!r} is not key=value (list values: key=[a,b])")
        try:
            options[key.strip()] = json.loads(raw.strip())
        except json.JSONDecodeError:
            options[key.strip()] = raw.strip()
    return make_estimator(name, **{**options, **overrides})


@dataclass(frozen=True)
class _Job:
    robot_spec: str
    setting: Setting
    specs: tuple[str, ...]
    budget_reference: str | None
    duration_s: float
    control_period_s: float
    estimator_seed: int = 0


def evaluate_setting(job: _Job) -> list[dict[str, Any]]:
    """Simulate one setting's window and fit every estimator on it; one row per estimator."""
    robot = load_robot(job.robot_spec)
    s = job.setting
    theta_true = np.array([s.fuel_consumed_kg, *s.tank_position_m])
    env = simulate_episode(
        robot,
        job.duration_s,
        s.fuel_consumed_kg,
        np.array(s.tank_position_m),
        FourierExcitation(robot.n_joints, seed=s.seed),
        seed=s.seed,
        control_period_s=job.control_period_s,
    )
    sigma_true = env.sensors.gyro_std_rad_s(job.control_period_s)
    problem = IdentificationModel(robot, "fuel").problem(env.measurement_log())
    truth = problem.parameters.physical(theta_true)
    bound = _quantity_bounds(problem, theta_true, sigma_true, truth)
    order = sorted(job.specs, key=lambda spec: spec != job.budget_reference)  # the budget reference first
    budget: float | None = None
    rows = []
    for spec in order:
        estimator = estimator_from_spec(spec, seed=job.estimator_seed)
        if budget is not None and "max_evaluations" in estimator.get_params():
            estimator = estimator_from_spec(
                spec, seed=job.estimator_seed, max_evaluations=budget
            )  # built again so the option is validated
        estimate = estimator.fit_problem(problem)
        if spec == job.budget_reference:
            budget = estimate.n_evaluations
        identified = problem.parameters.physical(estimate.theta)
        errors = quantity_errors(identified, truth)
        rows.append(
            {
                "setting": s.index,
                "seed": s.seed,
                "estimator": spec,
                "estimator_seed": job.estimator_seed,
                "true_fuel_consumed_kg": s.fuel_consumed_kg,
                "true_tank_x_m": s.tank_position_m[0],
                "true_tank_y_m": s.tank_position_m[1],
                "true_tank_z_m": s.tank_position_m[2],
                "true_base_mass_kg": float(truth["base_mass_kg"]),
                "estimated_base_mass_kg": float(identified["base_mass_kg"]),
                **{f"error_{q}": v for q, v in errors.items()},
                **{f"bound_{q}": v for q, v in bound.items()},
                "n_evaluations": estimate.n_evaluations,
                "wall_time_s": estimate.wall_time_s,
                "cost_over_noise_variance": estimate.cost / sigma_true**2,
                "n_residuals": 3 * problem.n_samples,
                "cost_history": [c / sigma_true**2 for c in estimate.cost_history],
            }
        )
    return rows


def quantity_errors(estimate: dict[str, Any], truth: dict[str, Any]) -> dict[str, float]:
    """Errors of the Table 1 quantities (see the module docstring)."""
    inertia_hat, inertia = np.diag(estimate["base_inertia_kgm2"]), np.diag(truth["base_inertia_kgm2"])
    com = np.asarray(truth["base_com_m"])
    return {
        "M": 100.0 * abs(estimate["base_mass_kg"] - truth["base_mass_kg"]) / truth["base_mass_kg"],
        "r": 100.0 * float(np.linalg.norm(np.asarray(estimate["base_com_m"]) - com) / np.linalg.norm(com)),
        "Ixx": 100.0 * abs(inertia_hat[0] - inertia[0]) / inertia[0],
        "Iyy": 100.0 * abs(inertia_hat[1] - inertia[1]) / inertia[1],
        "Izz": 100.0 * abs(inertia_hat[2] - inertia[2]) / inertia[2],
        "mdf": abs(estimate["fuel_consumed_kg"] - truth["fuel_consumed_kg"]),
        "bf": 1000.0 * float(np.linalg.norm(np.asarray(estimate["tank_position_m"]) - np.asarray(truth["tank_position_m"]))),
    }


def _quantity_bounds(problem: IdentificationProblem, theta: FloatArray, sigma: float, truth: dict[str, Any]) -> dict[str, float]:
    """Cramér-Rao std of the same quantities, in the same units (vectors: root of the summed variances)."""
    std = problem.crlb_physical_std(theta, sigma)
    inertia_std, inertia = np.diag(std["base_inertia_kgm2"]), np.diag(truth["base_inertia_kgm2"])
    return {
        "M": 100.0 * std["base_mass_kg"] / truth["base_mass_kg"],
        "r": 100.0 * float(np.linalg.norm(std["base_com_m"]) / np.linalg.norm(truth["base_com_m"])),
        "Ixx": 100.0 * inertia_std[0] / inertia[0],
        "Iyy": 100.0 * inertia_std[1] / inertia[1],
        "Izz": 100.0 * inertia_std[2] / inertia[2],
        "mdf": std["fuel_consumed_kg"],
        "bf": 1000.0 * float(np.linalg.norm(std["tank_position_m"])),
    }


def run_evaluation(
    robot: str,
    specs: Sequence[str],
    settings: Sequence[Setting],
    *,
    budget_reference: str | None = "improved-pso",
    duration_s: float = 60.0,
    control_period_s: float = 0.02,
    executor: ExecutorSpec | None = None,
    seed: int = 0,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Rows (one per setting and estimator, in the settings' order) of :func:`evaluate_setting` over ``settings``,
    run on ``executor`` (default: serial), with a progress bar; ``seed`` gives the estimators' per-setting seeds
    (see the module docstring)."""
    for spec in specs:
        estimator_from_spec(spec)  # bad names and options fail before any simulation
    load_robot(robot)
    reference = budget_reference if budget_reference in specs else None
    seeds = job_seeds(seed, len(settings))
    work = [
        _Job(robot, s, tuple(specs), reference, duration_s, control_period_s, estimator_seed)
        for s, estimator_seed in zip(settings, seeds, strict=True)
    ]
    results = run_jobs(
        evaluate_setting, work, executor or ExecutorSpec("serial"), desc="evaluate", unit="setting", progress=progress
    )
    return [row for rows in results for row in rows]


def summarise(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per estimator and quantity: mean, median, p95 of the error, RMS/bound ratio, the bound's mean; evaluations and time."""
    out = []
    for spec in dict.fromkeys(r["estimator"] for r in rows):
        mine = [r for r in rows if r["estimator"] == spec]
        for q, unit in QUANTITIES.items():
            err = np.array([r[f"error_{q}"] for r in mine])
            bound = np.array([r[f"bound_{q}"] for r in mine])
            out.append(
                {
                    "estimator": spec,
                    "quantity": q,
                    "unit": unit,
                    "mean": float(err.mean()),
                    "median": float(np.median(err)),
                    "p95": float(np.percentile(err, 95)),
                    "rms_over_bound": float(np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(bound**2))),
                    "bound_mean": float(math.sqrt(2.0 / math.pi) * bound.mean()),
                    "paper_table1": PAPER_TABLE1.get(q),
                    "evaluations_mean": float(np.mean([r["n_evaluations"] for r in mine])),
                    "wall_time_s_mean": float(np.mean([r["wall_time_s"] for r in mine])),
                    "n_settings": len(mine),
                }
            )
    return out


def markdown_table(summary: Sequence[dict[str, Any]], quantities: Sequence[str] = tuple(QUANTITIES)) -> str:
    """The summary as a Markdown table: one row per estimator; per quantity ``mean / p95 (RMS/bound)``."""
    head = "| estimator | " + " | ".join(f"{q} ({QUANTITIES[q]})" for q in quantities) + " | evals | time/fit (s) |"
    lines = [head, "|" + "---|" * (len(quantities) + 3)]
    bound_row = {s["quantity"]: s for s in summary if s["estimator"] == summary[0]["estimator"]}
    lines.append(
        "| Cramér-Rao bound (mean abs) | " + " | ".join(f"{bound_row[q]['bound_mean']:.3g}" for q in quantities) + " | | |"
    )
    lines.append(
        "| paper Table 1 | " + " | ".join(f"{PAPER_TABLE1[q]:.2f}" if q in PAPER_TABLE1 else "" for q in quantities) + " | | |"
    )
    for spec in dict.fromkeys(s["estimator"] for s in summary):
        by_q = {s["quantity"]: s for s in summary if s["estimator"] == spec}
        cells = [f"{by_q[q]['mean']:.3g} / {by_q[q]['p95']:.3g} ({by_q[q]['rms_over_bound']:.2f}x)" for q in quantities]
        first = by_q[quantities[0]]
        lines.append(
            f"| {spec} | " + " | ".join(cells) + f" | {first['evaluations_mean']:.0f} | {first['wall_time_s_mean']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def write_results(out_dir: str | Path, rows: Sequence[dict[str, Any]], settings_info: dict[str, Any]) -> dict[str, Path]:
    """Write ``episodes.csv``, ``summary.csv``, ``summary.json``, ``table.md`` and the plots to ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = summarise(rows)
    paths = {
        "episodes": write_csv_atomic(out / "episodes.csv", [{k: v for k, v in r.items() if k != "cost_history"} for r in rows]),
        "histories": _atomic_text(
            out / "histories.json", json.dumps([{k: r[k] for k in ("setting", "estimator", "cost_history")} for r in rows])
        ),
        "summary_csv": write_csv_atomic(out / "summary.csv", summary),
        "summary_json": _atomic_text(out / "summary.json", json.dumps({"settings": settings_info, "summary": summary}, indent=2)),
        "table": _atomic_text(out / "table.md", markdown_table(summary)),
    }
    paths.update(_plots(out, rows))
    return paths


def _atomic_text(path: Path, text: str) -> Path:
    return write_text_atomic(path, text if text.endswith("\n") else text + "\n")


def _plots(out: Path, rows: Sequence[dict[str, Any]]) -> dict[str, Path]:
    """Convergence (Figs. 4-5), identified vs true mass (Figs. 6-7) and the bound against the tank distance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    specs = list(dict.fromkeys(r["estimator"] for r in rows))
    paths = {}
    # convergence in chi-square units above the best fit any estimator found on the same window
    best = {}
    for r in rows:
        best[r["setting"]] = min(best.get(r["setting"], np.inf), r["cost_over_noise_variance"], *r["cost_history"])
    fig, ax = plt.subplots(figsize=(8, 5))
    for spec in specs:
        mine = [r for r in rows if r["estimator"] == spec and len(r["cost_history"]) > 1]
        if not mine:
            continue
        length = min(len(r["cost_history"]) for r in mine)
        curves = np.array([(np.asarray(r["cost_history"][:length]) - best[r["setting"]]) * r["n_residuals"] for r in mine])
        curves = np.maximum(curves, 1e-3)
        generations = np.arange(1, length + 1)
        ax.plot(generations, np.median(curves, axis=0), label=f"{spec} (median)")
        ax.plot(generations, np.percentile(curves, 90, axis=0), ls=":", color=ax.lines[-1].get_color(), lw=0.8)
    ax.set_yscale("log")
    ax.set_xlim(1, 60)
    ax.set_xlabel("iteration / generation")
    ax.set_ylabel("best whole-log cost above the window's best fit\n(chi-square units; dotted: 90th percentile)")
    ax.set_title("Convergence over all settings (1 unit ~ 1 Cramér-Rao std from the optimum)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    paths["convergence"] = out / "convergence.png"
    fig.savefig(paths["convergence"], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for spec in [s for s in ("pso", "improved-pso", "nn", "hybrid") if s in specs] or specs[:4]:  # the paper's comparison
        mine = [r for r in rows if r["estimator"] == spec]
        true = np.array([r["true_base_mass_kg"] for r in mine])
        est = np.array([r["estimated_base_mass_kg"] for r in mine])
        axes[0].plot(true, est, ".", ms=4, label=spec)
        axes[1].plot([r["setting"] for r in mine], 100.0 * (est - true) / true, ".", ms=4, label=spec)
    lims = axes[0].get_xlim()
    axes[0].plot(lims, lims, "k-", lw=0.8)
    axes[0].set_xlabel("true base mass (kg)")
    axes[0].set_ylabel("identified base mass (kg)")
    axes[1].set_xlabel("setting")
    axes[1].set_ylabel("mass error (% of base mass)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    paths["mass"] = out / "mass.png"
    fig.savefig(paths["mass"], dpi=110)
    plt.close(fig)

    first = [r for r in rows if r["estimator"] == specs[0]]
    fig, ax = plt.subplots(figsize=(6, 4))
    distance = [np.linalg.norm([r["true_tank_x_m"], r["true_tank_y_m"], r["true_tank_z_m"]]) for r in first]
    ax.semilogy(distance, [r["bound_mdf"] for r in first], ".")
    ax.set_xlabel("tank distance from the full-tank CoM (m)")
    ax.set_ylabel("Cramér-Rao std of the fuel mass (kg)")
    fig.tight_layout()
    paths["bound"] = out / "bound_vs_tank.png"
    fig.savefig(paths["bound"], dpi=110)
    plt.close(fig)
    return paths


def settings_info(
    robot: str, settings: Sequence[Setting], seed: int, duration_s: float, control_period_s: float
) -> dict[str, Any]:
    """What the evaluation ran on, for ``summary.json``."""
    return {
        "robot": robot,
        "n_settings": len(settings),
        "seed": seed,
        "duration_s": duration_s,
        "control_period_s": control_period_s,
        "excitation": "FourierExcitation (5 harmonics, 0.025 Hz base, amplitude 0.9), seeded per setting",
        "noise": "SensorModel defaults (gyro ARW 0.07 deg/sqrt(h))",
        "settings": [asdict(s) for s in settings],
    }
