"""Simulated UR5 with friction and sensor noise: held-out torque error, base-parameter error in Cramér-Rao units,
physical consistency, for WLS and the bee colonies at equal evaluations.

Per seed: the true robot is drawn around the URDF (``ParameterPrior``, Coulomb + viscous friction), a training log
(``--duration`` s on an optimised Fourier excitation) and a held-out log (a random Fourier excitation, fresh noise) of
that same robot are simulated at 125 Hz with the default sensor noise, and both go through the identification chain
(:class:`~estimators.arm.identification.Preparation`: 4 Hz zero-phase low-pass, ddq by differentiation, the
regressor filtered in parallel with the torque, 25 Hz).

Figures per estimator (mean over seeds, and the worst seed):

* held-out error in noise units: residual RMS over the processed noise floor, over all joints (1 = the floor);
* base-parameter error: ``sqrt(mean_i ((beta_i - beta_true_i) / crlb_i)^2)`` with the experiment's Cramér-Rao bound
  (the raw 125 Hz training samples at the true states with the simulator's white torque noise: what any estimator
  using those samples can reach);
* whether every link is physically consistent and every friction coefficient non-negative.

Run: ``.venv/bin/python benchmarks/ur5_simulated.py --seeds 5`` (about 40 s per seed on this machine).
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from estimators.arm.identification import Preparation, fit, physically_consistent, prediction_error, processed_noise_floor
from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.arm.model import ArmIdentificationModel
from estimators.evaluation import estimator_from_spec
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.simulated_arm_datasets import simulate_train_and_held_out

FRICTION = ("coulomb", "viscous")


def run_seed(seed: int, duration_s: float, budget: int, preparation: Preparation) -> list[dict[str, object]]:
    """Simulate, identify with every estimator and score; one row per estimator."""
    robot = load_arm("ur5")
    model = ArmIdentificationModel.build(robot, FRICTION)
    with tempfile.TemporaryDirectory() as folder:
        train, held = simulate_train_and_held_out(
            robot, FRICTION, (duration_s, seed, "optimised"), (20.0, seed + 10_000, "fourier"), folder
        )
    p_true = np.array(list(train.truth["parameters"].values()))
    noise = np.asarray(train.truth["noise"]["torque_std_Nm"])
    clean = train.simulation.clean
    raw_rows = model.log_regressor(clean).reshape(-1, model.n_params)
    beta_true = model.base.to_base(p_true)
    bound_problem = LinearIdentificationProblem(
        raw_rows,
        raw_rows @ beta_true,
        model.base.names,
        beta_true - 1.0,
        beta_true + 1.0,
        row_std=np.tile(noise, clean.n_samples),
    )
    crlb = bound_problem.crlb_std(beta_true)
    train_rows = preparation.rows(model, train.simulation.log)
    held_rows = preparation.rows(model, held.simulation.log)
    floor = processed_noise_floor(preparation, noise, held.simulation.log)
    specs = {
        "wls": "wls",
        "sdp": "sdp",
        "improved-abc (consistent)": f"improved-abc[consistent=true,max_evaluations={budget}]",
        "abc (consistent)": f"abc[consistent=true,max_evaluations={budget}]",
        "improved-abc (consistent, polished)": f"improved-abc[consistent=true,polish=true,max_evaluations={budget}]",
    }
    rows = []
    for label, spec in specs.items():
        estimate = fit(model, {"train": train_rows}, estimator_from_spec(spec, seed=seed))
        error = prediction_error(model, estimate.theta, held_rows, floor)
        z = (estimate.theta - beta_true) / crlb
        rows.append(
            {
                "estimator": label,
                "held_out_x_noise": error.overall_noise_ratio,
                "parameter_error_crlb": float(np.sqrt(np.mean(z**2))),
                "consistent": physically_consistent(estimate),
                "evaluations": estimate.n_evaluations,
                "wall_s": estimate.wall_time_s,
            }
        )
    return rows


def main() -> None:
    """Print one line per seed and estimator, then the summary table (markdown)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--duration", type=float, default=30.0, help="training log length, s (default 30)")
    parser.add_argument("--budget", type=int, default=100_000, help="colony evaluations (default 100000)")
    args = parser.parse_args()
    preparation = Preparation()
    start = time.perf_counter()
    all_rows: list[dict[str, object]] = []
    for seed in range(args.seeds):
        for row in run_seed(seed, args.duration, args.budget, preparation):
            row["seed"] = seed
            all_rows.append(row)
            print(
                f"seed {seed} {row['estimator']:<38} held-out {row['held_out_x_noise']:.3f} x noise, "
                f"parameters {row['parameter_error_crlb']:.2f} x CRLB, consistent {row['consistent']}, "
                f"{row['evaluations']:.0f} evaluations, {row['wall_s']:.1f} s",
                flush=True,
            )
    print(f"\n{args.seeds} seeds, {args.duration:g} s training logs, {time.perf_counter() - start:.0f} s\n")
    print(
        "| estimator | held-out error / noise floor (mean, worst) | base-parameter error / CRLB (mean, worst) | physically consistent |"
    )
    print("|---|---|---|---|")
    for label in dict.fromkeys(str(r["estimator"]) for r in all_rows):
        rows = [r for r in all_rows if r["estimator"] == label]
        held = np.array([r["held_out_x_noise"] for r in rows], dtype=float)
        params = np.array([r["parameter_error_crlb"] for r in rows], dtype=float)
        consistent = [r["consistent"] for r in rows]
        verdict = "n/a" if None in consistent else f"{sum(bool(c) for c in consistent)}/{len(consistent)}"
        print(f"| {label} | {held.mean():.3f}, {held.max():.3f} | {params.mean():.2f}, {params.max():.2f} | {verdict} |")


if __name__ == "__main__":
    main()
