"""The consistent improved ABC with its polish against the convex ``sdp`` optimum, over colony seeds, on simulated UR5
data: the distribution of the colony's cost excess over the optimum of the same cost, the held-out error of both in
noise units, and the time per fit.

Per dataset seed ``d``: the true UR5 drawn around the URDF with Coulomb + viscous friction (``ParameterPrior``), a
training log (``--duration`` s, random Fourier excitation, seed ``d``) and a held-out log (20 s, seed ``d + 1``, the
same robot) at 125 Hz with the default sensor noise, through the identification chain
(:class:`~estimators.arm_identification.Preparation`); the problem is the joint-weighted cost the colonies minimise.
Then ``sdp`` once, and ``improved-abc[consistent=true,polish=true]`` with colony seeds ``0 .. --seeds - 1`` at each
budget of ``--budgets`` (``default`` is the estimator's own: 5000 cycles, 200 000 evaluations).

Excess: ``(cost_colony - cost_sdp) / cost_sdp`` on the same training cost; slightly negative values are the sdp's
regulariser trade (:mod:`estimators.sdp`). Held-out: residual RMS over the processed noise floor (1 = the floor).

Run: ``.venv/bin/python benchmarks/ur5_colony_vs_sdp.py --datasets 3 --seeds 20 --budgets 20000,default``
(the figures in the report of issue 21; about 2 s per colony fit at 20 000 evaluations on a shared 2-core machine).
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from estimators.arm_identification import (
    Preparation,
    fit,
    joint_weighted,
    physically_consistent,
    prediction_error,
    processed_noise_floor,
)
from estimators.evaluation import estimator_from_spec
from estimators.models.arm_model import ArmIdentificationModel
from spaceid_gym.arm.datasets import simulate_train_and_held_out
from spaceid_gym.arm.robot import load_arm

FRICTION = ("coulomb", "viscous")


def colony_spec(budget: str) -> str:
    """The polished consistent colony at ``budget`` evaluations (``default``: the estimator's own)."""
    options = "consistent=true,polish=true" + ("" if budget == "default" else f",max_evaluations={int(budget)}")
    return f"improved-abc[{options}]"


def run_dataset(dataset: int, duration_s: float, seeds: int, budgets: list[str]) -> list[dict[str, object]]:
    """One simulated dataset: the sdp row, then one row per budget and colony seed."""
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
    problem = joint_weighted(model.problem(train_rows))
    sdp = fit(model, train_rows, estimator_from_spec("sdp"))
    sdp_cost = float(problem.cost(sdp.theta, count=False)[0])
    rows: list[dict[str, object]] = [
        {
            "dataset": dataset,
            "estimator": "sdp",
            "seed": None,
            "excess": 0.0,
            "held_out_x_noise": prediction_error(model, sdp.theta, held_rows, floor).overall_noise_ratio,
            "consistent": physically_consistent(sdp),
            "wall_s": sdp.wall_time_s,
            "wls_consistency_cost_percent": 100.0 * sdp.extra["consistency_cost_increase"] / sdp.extra["unconstrained_cost"],
        }
    ]
    for budget in budgets:
        for seed in range(seeds):
            estimate = fit(model, train_rows, estimator_from_spec(colony_spec(budget), seed=seed))
            cost = float(problem.cost(estimate.theta, count=False)[0])
            rows.append(
                {
                    "dataset": dataset,
                    "estimator": f"colony {budget}",
                    "seed": seed,
                    "excess": (cost - sdp_cost) / sdp_cost,
                    "reported_excess": estimate.extra.get("cost_excess_over_sdp"),
                    "colony_excess": (estimate.extra["colony_cost"] - sdp_cost) / sdp_cost,
                    "held_out_x_noise": prediction_error(model, estimate.theta, held_rows, floor).overall_noise_ratio,
                    "consistent": physically_consistent(estimate),
                    "wall_s": estimate.wall_time_s,
                }
            )
    return rows


def summary(rows: list[dict[str, object]]) -> str:
    """Per estimator (sdp, each budget): fits, how many within 1 % of sdp, the excess's quantiles, held-out error, time."""
    groups: dict[str, list[dict[str, object]]] = {}
    for row in rows:
        groups.setdefault(str(row["estimator"]), []).append(row)
    lines = [
        "| estimator | fits | within 1 % of sdp | excess % (min, median, 95th pct, max) | held-out x noise (mean, max) | s/fit |",
        "|---|---:|---:|---|---|---:|",
    ]
    for label, group in groups.items():
        column = {key: np.array([r[key] for r in group], dtype=float) for key in ("excess", "held_out_x_noise", "wall_s")}
        excess = 100.0 * column["excess"]
        quantiles = ", ".join(f"{v:+.5f}" for v in (excess.min(), np.median(excess), np.percentile(excess, 95), excess.max()))
        held = column["held_out_x_noise"]
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
    args = parser.parse_args()
    budgets = [b.strip() for b in args.budgets.split(",") if b.strip()]
    start = time.perf_counter()
    rows = [
        row for dataset in range(3, 3 + 2 * args.datasets, 2) for row in run_dataset(dataset, args.duration, args.seeds, budgets)
    ]
    print(
        "\n".join(
            f"dataset {r['dataset']} {r['estimator']:<16} seed {r['seed']}: excess {100 * float(str(r['excess'])):+.5f} %, "
            f"held-out {r['held_out_x_noise']:.3f} x noise, consistent {r['consistent']}, {r['wall_s']:.2f} s"
            for r in rows
        )
    )
    print(f"\n{args.datasets} dataset(s) x {args.seeds} colony seeds, {time.perf_counter() - start:.0f} s\n")
    print(summary(rows))


if __name__ == "__main__":
    main()
