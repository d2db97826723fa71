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
undisturbed movements instead, the model with Coulomb + viscous friction (``--armature``: and a rotor inertia).

Excess: ``(cost_colony - cost_sdp) / cost_sdp`` on the same training cost; slightly negative values are the sdp's
regulariser trade (:mod:`estimators.arm.sdp`). Held-out: residual RMS over the processed noise floor (1 = the floor) on
simulated data, the relative error over all joints (%) on real data.

Run: ``.venv/bin/python benchmarks/ur5_colony_vs_sdp.py --datasets 3 --seeds 20 --budgets 20000,default`` and
``.venv/bin/python benchmarks/ur5_colony_vs_sdp.py --real ../shared/data/ur5-real --armature --seeds 5 --budgets
20000,100000`` (the figures in the report of issue 21; about 2 s per colony fit at 20 000 evaluations on a shared
2-core machine).
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
from spaceid_gym.arm.datasets import simulate_train_and_held_out
from spaceid_gym.arm.robot import load_arm

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
    fits = [("sdp", None, sdp)] + [
        (f"colony {budget}", seed, fit(model, train_rows, estimator_from_spec(colony_spec(budget), seed=seed)))
        for budget in budgets
        for seed in range(seeds)
    ]
    rows: list[dict[str, object]] = []
    for label, seed, estimate in fits:
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
    return rows


def run_dataset(dataset: int, duration_s: float, seeds: int, budgets: list[str]) -> list[dict[str, object]]:
    """One simulated dataset (module docstring): :func:`compare` on it."""
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


def run_real(folder: str, armature: bool, seeds: int, budgets: list[str]) -> list[dict[str, object]]:
    """Real UR5 logs: every fold of leave one movement out over the undisturbed movements (:func:`compare` per fold)."""
    model = ArmIdentificationModel.build(load_arm("ur5"), FRICTION, armature)
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


def main() -> None:
    """Print one line per fit, then per budget the distribution of the excess (markdown)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--datasets", type=int, default=1, help="simulated datasets (seeds 3, 5, 7, ...; default 1)")
    parser.add_argument("--seeds", type=int, default=20, help="colony seeds per dataset and budget (default 20)")
    parser.add_argument("--duration", type=float, default=20.0, help="training log length, s (default 20)")
    parser.add_argument("--budgets", default="20000,default", help="comma-separated colony budgets (default 20000,default)")
    parser.add_argument("--real", default=None, help="folder of the real UR5 movements: their folds instead of simulated data")
    parser.add_argument("--armature", action="store_true", help="with --real: the model with a rotor inertia per joint")
    args = parser.parse_args()
    budgets = [b.strip() for b in args.budgets.split(",") if b.strip()]
    start = time.perf_counter()
    if args.real is None:
        rows = [row for d in range(3, 3 + 2 * args.datasets, 2) for row in run_dataset(d, args.duration, args.seeds, budgets)]
        unit, what = "x noise", f"{args.datasets} simulated dataset(s)"
    else:
        rows = run_real(args.real, args.armature, args.seeds, budgets)
        unit, what = "%", f"{len(UNDISTURBED)} real folds" + (" (armature)" if args.armature else "")
    for r in rows:
        print(
            f"{r['dataset']} {r['estimator']:<16} seed {r['seed']}: excess {100 * float(str(r['excess'])):+.5f} %, "
            f"held-out {float(str(r['held_out'])):.3f} {unit}, consistent {r['consistent']}, {float(str(r['wall_s'])):.2f} s"
        )
    print(f"\n{what} x {args.seeds} colony seeds, {time.perf_counter() - start:.0f} s\n")
    print(summary(rows, unit))


if __name__ == "__main__":
    main()
