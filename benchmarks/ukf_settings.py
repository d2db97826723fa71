"""One-window ``ukf`` fits over random true settings: error against the Cramér-Rao bound and against ``hybrid``, NEES, NIS.

The settings: ``--settings`` fuel states drawn as the evaluation harness draws them
(:func:`estimators.evaluation.draw_settings` with ``--seed``: mdf 27.5-137.5 kg, tank anywhere in its +-0.40 m box
for paper6), a 60 s window at 50 Hz each with its own excitation and noise, the model ``fuel`` with the sensors'
gyro noise. Per setting: the ``ukf`` fit (``--ukf`` spec) and the ``hybrid`` fit (both with the setting's seed), the
errors over the Cramér-Rao std at the truth (``z``), the NEES ``e^T P^-1 e`` of the ``ukf`` estimate with its own
covariance ``P`` (chi-square with 4 degrees of freedom when consistent) and the mean NIS of its last pass (``3 /
passes`` when consistent: the passes are tempered).

Printed: per unknown the RMS of ``z`` for both (1 for an efficient estimator), the ratio of their RMS errors, the
count of settings with every ``|z| < 3``, the mean NEES with the two-sided 95 % bounds of the mean of N chi-square(4)
values, and the share of settings whose NEES lies below chi-square(4)'s 95 % point (95 % when consistent). A CSV
of every setting goes to ``--out`` if given.

Usage::

    python benchmarks/ukf_settings.py [--settings 30] [--seed 0] [--ukf ukf] [--jobs 2] [--out ukf_settings.csv]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from estimators.evaluation import Setting, draw_settings, estimator_from_spec
from estimators.problem import IdentificationModel
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.executors import ExecutorSpec, run_jobs
from spaceid_gym.log import write_csv_atomic
from spaceid_gym.robots import load_robot

NAMES = ("mdf", "bx", "by", "bz")


@dataclass(frozen=True)
class _Job:
    setting: Setting
    ukf_spec: str


def fit_setting(job: _Job) -> dict[str, Any]:
    """Simulate the setting's window; the ukf and hybrid fits' z-scores, the ukf's NEES and last-pass NIS."""
    robot = load_robot("paper6")
    s = job.setting
    theta = np.array([s.fuel_consumed_kg, *s.tank_position_m])
    env = simulate_episode(robot, 60.0, theta[0], theta[1:], FourierExcitation(robot.n_joints, seed=s.seed), seed=s.seed)
    sigma = env.sensors.gyro_std_rad_s(env.control_period_s)
    model = IdentificationModel(robot, "fuel", noise_std_rad_s=sigma)
    problem = model.problem(env.measurement_log())
    crlb = problem.crlb_std(theta)
    ukf = estimator_from_spec(job.ukf_spec, seed=s.seed).fit_problem(problem)
    hybrid = estimator_from_spec("hybrid", seed=s.seed).fit_problem(problem)
    error = ukf.theta - theta
    cov = np.asarray(ukf.extra["covariance"])
    row: dict[str, Any] = {
        "setting": s.index,
        "seed": s.seed,
        **{f"true_{n}": float(v) for n, v in zip(NAMES, theta, strict=True)},
    }
    row.update({f"crlb_{n}": float(v) for n, v in zip(NAMES, crlb, strict=True)})
    row.update({f"z_ukf_{n}": float(v) for n, v in zip(NAMES, error / crlb, strict=True)})
    row.update({f"z_hybrid_{n}": float(v) for n, v in zip(NAMES, (hybrid.theta - theta) / crlb, strict=True)})
    row.update({f"std_ukf_over_crlb_{n}": float(v) for n, v in zip(NAMES, np.sqrt(np.diag(cov)) / crlb, strict=True)})
    row["nees_ukf"] = float(error @ np.linalg.solve(cov, error))
    row["nis_mean_last_pass"] = float(ukf.extra["nis_mean_last_pass"])
    row["ukf_wall_time_s"] = ukf.wall_time_s
    row["hybrid_wall_time_s"] = hybrid.wall_time_s
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--settings", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--ukf", default="ukf", help="the ukf spec, e.g. ukf[passes=3] (default ukf)")
    parser.add_argument("--jobs", type=int, default=1, help="local worker processes (default 1: in this process)")
    parser.add_argument("--out", type=Path, default=None, help="CSV of every setting")
    args = parser.parse_args()
    settings = draw_settings(load_robot("paper6"), args.settings, args.seed)
    executor = ExecutorSpec("serial") if args.jobs == 1 else ExecutorSpec("processes", args.jobs)
    rows = run_jobs(fit_setting, [_Job(s, args.ukf) for s in settings], executor, desc="settings", unit="setting")
    n = len(rows)
    print(f"{n} settings (draw seed {args.seed}), {args.ukf} vs hybrid, 60 s windows of paper6 at 50 Hz")
    for name in NAMES:
        zu = np.array([r[f"z_ukf_{name}"] for r in rows])
        zh = np.array([r[f"z_hybrid_{name}"] for r in rows])
        rms_u, rms_h = np.sqrt(np.mean(zu**2)), np.sqrt(np.mean(zh**2))
        med = np.median([r[f"std_ukf_over_crlb_{name}"] for r in rows])
        print(
            f"  {name}: RMS error / CRLB ukf {rms_u:6.2f}, hybrid {rms_h:6.2f}; ukf / hybrid {rms_u / rms_h:5.2f}; "
            f"median ukf std / CRLB {med:.2f}"
        )
    within = sum(all(abs(r[f"z_ukf_{n}"]) < 3 for n in NAMES) for r in rows)
    within_h = sum(all(abs(r[f"z_hybrid_{n}"]) < 3 for n in NAMES) for r in rows)
    nees = np.array([r["nees_ukf"] for r in rows])
    low, high = chi2.ppf(0.025, 4 * n) / n, chi2.ppf(0.975, 4 * n) / n
    print(f"  every |z| < 3: ukf {within}/{n}, hybrid {within_h}/{n}")
    print(
        f"  NEES: mean {nees.mean():.2f} (95 % bounds of the mean [{low:.2f}, {high:.2f}]), median {np.median(nees):.2f}; "
        f"below chi2(4) 95 % point {chi2.ppf(0.95, 4):.2f}: {np.sum(nees < chi2.ppf(0.95, 4))}/{n}"
    )
    nis = np.array([r["nis_mean_last_pass"] for r in rows])
    print(f"  mean NIS of the last pass: {nis.mean():.4f} (x passes: per-sample NIS, 3 when consistent)")
    print(
        f"  time per fit: ukf {np.mean([r['ukf_wall_time_s'] for r in rows]):.2f} s, "
        f"hybrid {np.mean([r['hybrid_wall_time_s'] for r in rows]):.2f} s"
    )
    if args.out is not None:
        write_csv_atomic(args.out, rows)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
