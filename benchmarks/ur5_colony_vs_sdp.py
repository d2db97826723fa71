"""The consistent improved ABC with its polish against the convex ``sdp`` optimum, over colony seeds, on simulated UR5
data: the distribution of the colony's cost excess over the optimum of the same cost, the held-out error of both in
noise units, and the time per fit.

Per dataset seed ``d``: the true UR5 drawn around the URDF with Coulomb + viscous friction (``ParameterPrior``), a
training log (``--duration`` s, random Fourier excitation, seed ``d``) and a held-out log (20 s, seed ``d + 1``, the
same robot) at 125 Hz with the default sensor noise, through the identification chain
(:class:`~estimators.arm.identification.Preparation`); the problem is the joint-weighted cost the colonies minimise.
Then ``sdp`` once, and ``improved-abc[consistent=true,polish=true]`` with colony seeds ``0 .. --seeds - 1`` at each
budget of ``--budgets`` (``default`` is the estimator's own: 5000 cycles, 200 000 evaluations).

With ``--real FOLDER`` (the real UR5 logs, ``shared/data/ur5-real``): every fold of leave one movement out over the 7
undisturbed movements instead, the model with ``--friction`` (default Coulomb + viscous; the recommended real model:
``coulomb_asymmetric,viscous``) and, with ``--armature``, a rotor inertia per joint; then also a table per fold (the
fraction of colony seeds within 1 % of the fold's sdp cost, the largest excess, the time per fit of each).

Excess: ``(cost_colony - cost_sdp) / cost_sdp`` on the same training cost; slightly negative values are the sdp's
regulariser trade (:mod:`estimators.arm.sdp`). Held-out: residual RMS over the processed noise floor (1 = the floor) on
simulated data, the relative error over all joints (%) on real data.

Run: ``.venv/bin/python benchmarks/ur5_colony_vs_sdp.py --datasets 3 --seeds 20 --budgets 20000,default`` and
``.venv/bin/python benchmarks/ur5_colony_vs_sdp.py --real ur5-real/ --armature --seeds 20 --budgets default`` (add
``--friction coulomb_asymmetric,viscous`` for the recommended real model); the figures in ``docs/results.md``. Each
fit's line is printed as soon as it is done.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from estimators.arm.identification import (
    Preparation,
    fit,
    joint_weighted,
    load_movements,
    physically_consistent,
    prediction_error,
    processed_noise_floor,
)
from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from estimators.evaluation import estimator_from_spec
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.simulated_arm_datasets import simulate_train_and_held_out
from spaceid_gym.arm_cli import parse_friction
from spaceid_gym.errors import SpaceIdInputError

FRICTION = ("coulomb", "viscous")
#: the real UR5 movements without a person pushing the arm
UNDISTURBED = (
    "Movement_No1",
    "Movement_No2",
    "Movement_No3_Acc",
    "Movement_No4_Acc",
    "Movement_No5_Acc_slow_no_disturbance",
    "Movement_No8_Singularity_Free_1",
    "Movement_No9_Singularity_Free_NoDist",
)


def colony_spec(budget: str) -> str:
    """The polished consistent colony at ``budget`` evaluations (``default``: the estimator's own)."""
    options = "consistent=true,polish=true" + ("" if budget == "default" else f",max_evaluations={int(budget)}")
    return f"improved-abc[{options}]"


def compare(
    model: ArmIdentificationModel,
    train_rows: dict[str, IdentificationRows],
    held_rows: IdentificationRows,
    floor: np.ndarray | None,
    seeds: int,
    budgets: list[str],
    dataset: str,
) -> list[dict[str, object]]:
    """sdp once, then the colony per budget and seed, on the training rows' joint-weighted cost; held-out error in
    noise units when the noise ``floor`` is known (simulated data), else in % of the held-out effort (real data)."""
    problem = joint_weighted(model.problem(train_rows))
    sdp = fit(model, train_rows, estimator_from_spec("sdp"))
    sdp_cost = float(problem.cost(sdp.theta, count=False)[0])
    unit = "x noise" if floor is not None else "%"
    rows: list[dict[str, object]] = []
    for label, seed, spec in [("sdp", None, "")] + [(f"colony {b}", s, colony_spec(b)) for b in budgets for s in range(seeds)]:
        estimate = sdp if seed is None else fit(model, train_rows, estimator_from_spec(spec, seed=seed))
        error = prediction_error(model, estimate.theta, held_rows, floor)
        cost = float(problem.cost(estimate.theta, count=False)[0])
        rows.append(
            {
                "dataset": dataset,
                "estimator": label,
                "seed": seed,
                "excess": (cost - sdp_cost) / sdp_cost,
                "reported_excess": estimate.extra.get("cost_excess_over_sdp"),
                "held_out": error.overall_percent if floor is None else error.overall_noise_ratio,
                "consistent": physically_consistent(estimate),
                "wall_s": estimate.wall_time_s,
            }
        )
        print(row_line(rows[-1], unit), flush=True)
    return rows


def row_line(row: dict[str, object], unit: str) -> str:
    """One fit's line: fold or dataset, estimator, seed, excess, held-out error, consistency, time."""
    return (
        f"{row['dataset']} {row['estimator']:<16} seed {row['seed']}: excess {100 * float(str(row['excess'])):+.5f} %, "
        f"held-out {float(str(row['held_out'])):.3f} {unit}, consistent {row['consistent']}, {float(str(row['wall_s'])):.2f} s"
    )


def run_dataset(dataset: int, duration_s: float, seeds: int, budgets: list[str]) -> list[dict[str, object]]:
    """One simulated dataset (module docstring, Coulomb + viscous friction): :func:`compare` on it."""
    robot = load_arm("ur5")
    model = ArmIdentificationModel.build(robot, FRICTION)
    with tempfile.TemporaryDirectory() as folder:
        train, held = simulate_train_and_held_out(
            robot, FRICTION, (duration_s, dataset, "fourier"), (20.0, dataset + 1, "fourier"), folder
        )
    preparation = Preparation()
    train_rows = {"train": preparation.rows(model, train.simulation.log)}
    held_rows = preparation.rows(model, held.simulation.log)
    floor = processed_noise_floor(preparation, np.asarray(train.truth["noise"]["torque_std_Nm"]), held.simulation.log)
    return compare(model, train_rows, held_rows, floor, seeds, budgets, f"sim {dataset}")


def run_real(folder: str, friction: tuple[str, ...], armature: bool, seeds: int, budgets: list[str]) -> list[dict[str, object]]:
    """Real UR5 logs: every fold of leave one movement out over the undisturbed movements (:func:`compare` per fold),
    the model with the ``friction`` terms (and ``armature``)."""
    model = ArmIdentificationModel.build(load_arm("ur5"), friction, armature)
    rows = Preparation().all_rows(model, load_movements(folder, UNDISTURBED))
    return [
        row
        for held in UNDISTURBED
        for row in compare(model, {n: r for n, r in rows.items() if n != held}, rows[held], None, seeds, budgets, held)
    ]


def summary(rows: list[dict[str, object]], held_unit: str) -> str:
    """Per estimator (sdp, each budget): fits, how many within 1 % of sdp, the excess's quantiles, held-out error
    (mean, max, in ``held_unit``), time per fit."""
    groups: dict[str, list[dict[str, object]]] = {}
    for row in rows:
        groups.setdefault(str(row["estimator"]), []).append(row)
    lines = [
        f"| estimator | fits | within 1 % of sdp | excess % (min, median, 95th pct, max) | held-out {held_unit} (mean, max) | s/fit |",
        "|---|---:|---:|---|---|---:|",
    ]
    for label, group in groups.items():
        column = {key: np.array([r[key] for r in group], dtype=float) for key in ("excess", "held_out", "wall_s")}
        excess = 100.0 * column["excess"]
        quantiles = ", ".join(f"{v:+.5f}" for v in (excess.min(), np.median(excess), np.percentile(excess, 95), excess.max()))
        held = column["held_out"]
        lines.append(
            f"| {label} | {len(group)} | {int(np.sum(excess <= 1.0))}/{len(group)} | {quantiles} | "
            f"{held.mean():.3f}, {held.max():.3f} | {column['wall_s'].mean():.2f} |"
        )
    return "\n".join(lines)


def per_fold(rows: list[dict[str, object]]) -> str:
    """Per fold and colony budget: seeds within 1 % of the fold's sdp cost, the largest excess, the held-out error
    of sdp and the colonies' worst, the time per fit of sdp and the colonies' mean (markdown)."""
    lines = [
        "| fold (held out) | budget | within 1 % of sdp | largest excess % | held-out % sdp, colony worst | s/fit sdp | s/fit colony (mean, max) |",
        "|---|---|---:|---:|---|---:|---|",
    ]
    folds = list(dict.fromkeys(str(r["dataset"]) for r in rows))
    budgets = list(dict.fromkeys(str(r["estimator"]) for r in rows if r["seed"] is not None))
    for fold in folds:
        sdp = next(r for r in rows if r["dataset"] == fold and r["seed"] is None)
        for budget in budgets:
            group = [r for r in rows if r["dataset"] == fold and r["estimator"] == budget]
            excess = 100.0 * np.array([float(str(r["excess"])) for r in group])
            wall = np.array([float(str(r["wall_s"])) for r in group])
            held = max(float(str(r["held_out"])) for r in group)
            lines.append(
                f"| {fold} | {budget.removeprefix('colony ')} | {int(np.sum(excess <= 1.0))}/{len(group)} | {excess.max():+.5f} | "
                f"{float(str(sdp['held_out'])):.2f}, {held:.2f} | {float(str(sdp['wall_s'])):.2f} | {wall.mean():.1f}, {wall.max():.1f} |"
            )
    return "\n".join(lines)


def main() -> None:
    """Print one line per fit, then per budget the distribution of the excess (markdown)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--datasets", type=int, default=1, help="simulated datasets (seeds 3, 5, 7, ...; default 1)")
    parser.add_argument("--seeds", type=int, default=20, help="colony seeds per dataset and budget (default 20)")
    parser.add_argument("--duration", type=float, default=20.0, help="training log length, s (default 20)")
    parser.add_argument("--budgets", default="20000,default", help="comma-separated colony budgets (default 20000,default)")
    parser.add_argument("--real", default=None, help="folder of the real UR5 movements: their folds instead of simulated data")
    parser.add_argument("--armature", action="store_true", help="with --real: the model with a rotor inertia per joint")
    parser.add_argument(
        "--friction",
        default=",".join(FRICTION),
        help="with --real: the model's friction terms, comma-separated (default coulomb,viscous)",
    )
    args = parser.parse_args()
    budgets = [b.strip() for b in args.budgets.split(",") if b.strip()]
    try:
        friction = parse_friction(args.friction)
    except SpaceIdInputError as exc:
        parser.error(str(exc))
    start = time.perf_counter()
    if args.real is None:
        rows = [row for d in range(3, 3 + 2 * args.datasets, 2) for row in run_dataset(d, args.duration, args.seeds, budgets)]
        unit, what = "x noise", f"{args.datasets} simulated dataset(s)"
    else:
        rows = run_real(args.real, friction, args.armature, args.seeds, budgets)
        model = ",".join(friction) + (" + armature" if args.armature else "")
        unit, what = "%", f"{len(UNDISTURBED)} real folds ({model})"
    print(f"\n{what} x {args.seeds} colony seeds, {time.perf_counter() - start:.0f} s\n")
    print(summary(rows, unit))
    if args.real is not None:
        print()
        print(per_fold(rows))


if __name__ == "__main__":
    main()
