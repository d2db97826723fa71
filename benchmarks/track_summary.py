"""Pool the figures of several ``spaceid track`` missions (one folder each, its ``track.json``).

Per mission: the fuel RMS errors and their ratio, the mean NEES and NIS and whether each lies within its 95 %
bounds. Pooled: the missions meeting the 1.5 x target, the missions consistent in NEES and in NIS (a consistent
filter passes each test in 95 % of missions), the mean NEES over every window of every mission and the mean NIS
over every streamed update against the 95 % bounds of those means, and the ratio of the pooled fuel RMS errors.

Usage::

    for s in 0 1 2 3 4 5 6 7 8 9; do spaceid track --robot paper6 --windows 10 --seed $s --out mission$s; done
    python benchmarks/track_summary.py mission*
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from spaceid_gym.tracking import mean_bounds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", type=Path, nargs="+", help="output folders of spaceid track")
    args = parser.parse_args()
    runs = [json.loads((folder / "track.json").read_text()) for folder in args.folders]
    print("seed | ukf RMS kg | hybrid RMS kg | ratio | NEES mean (ok) | NIS mean (ok)")
    for run in runs:
        s = run["summary"]
        print(
            f"{run['info']['seed']:4d} | {s['fuel_rms_error_ukf_kg']:10.2f} | {s['fuel_rms_error_hybrid_kg']:13.2f} | "
            f"{s['fuel_rms_ratio_ukf_over_hybrid']:5.2f} | {s['nees_mean']:6.2f} ({'yes' if s['nees_consistent'] else 'no'}) | "
            f"{s['nis_mean']:.4f} ({'yes' if s['nis_consistent'] else 'no'})"
        )
    n = len(runs)
    summaries = [r["summary"] for r in runs]
    windows = [w for r in runs for w in r["windows"]]
    error_ukf = np.array([w["ukf_fuel_consumed_kg"] - w["true_fuel_consumed_kg"] for w in windows])
    error_hybrid = np.array([w["hybrid_fuel_consumed_kg"] - w["true_fuel_consumed_kg"] for w in windows])
    rms_ukf, rms_hybrid = np.sqrt(np.mean(error_ukf**2)), np.sqrt(np.mean(error_hybrid**2))
    nees = np.array([w["ukf_nees"] for w in windows])
    streamed = [w for w in windows if w["ukf_updates"] > 0]
    updates = sum(w["ukf_updates"] for w in streamed)
    nis = sum(w["ukf_nis_mean"] * w["ukf_updates"] for w in streamed) / updates
    print(f"{n} missions, {len(windows)} windows, {updates} streamed updates")
    print(
        f"fuel RMS within 1.5 x hybrid: {sum(s['fuel_within_1_5x_hybrid'] for s in summaries)}/{n}; pooled RMS ukf "
        f"{rms_ukf:.2f} kg, hybrid {rms_hybrid:.2f} kg, ratio {rms_ukf / rms_hybrid:.2f}"
    )
    low, high = mean_bounds(4, len(nees))
    print(
        f"NEES consistent in {sum(s['nees_consistent'] for s in summaries)}/{n} missions; pooled mean {nees.mean():.2f} "
        f"(95 % bounds {low:.2f}-{high:.2f}), median {np.median(nees):.2f}"
    )
    low, high = mean_bounds(3, updates)
    print(
        f"NIS consistent in {sum(s['nis_consistent'] for s in summaries)}/{n} missions; pooled mean {nis:.4f} "
        f"(95 % bounds {low:.4f}-{high:.4f})"
    )


if __name__ == "__main__":
    main()
