"""Pool the figures of several ``spaceid track`` missions (one folder each, its ``track.json``).

Per mission: the fuel RMS errors and their ratio, the mean NEES and NIS and whether each lies within its 95 %
bounds. The per-mission NEES test takes a mission's windows as independent chi-square(4) draws; they are not
(the tank has no process noise, so the filter carries its error from window to window), and the script measures
that correlation: the lag-1..3 correlation of a mission's window NEES, log NEES and fuel ``z = error / std``
pooled over the missions, against its spread when the missions are shuffled at each window index (seeded), and the
spread of the mission means against chi-square(40)/10's.

Then the NEES tests that hold for correlated windows, with the missions (independent runs) as the unit:

* Bar-Shalom's Monte Carlo test (2001, sec. 5.4.2): at each window index k the N-mission average NEES against the
  95 % bounds of chi-square(4 N)/N; a consistent filter has it inside at about 95 % of the k;
* the mean over the missions of the mission-mean NEES, with its Student-t and bootstrap (over missions, seeded)
  95 % intervals: a consistent filter's is 4. On synthetic consistent filters (AR(1) errors, lag-1 correlation 0.8,
  400 sets) the t-interval held 4 in 93.5 % of 10-mission sets and 93 % of 30-mission sets, the percentile
  bootstrap in 88 % and 92 %: with few missions read the t-interval.

A window whose NEES passes chi-square(4)'s 99.9 % point is counted: a consistent filter has 0.1 % of them, whatever
the correlation (each window's NEES is chi-square(4) on its own).

The re-initialisations on a high window NIS (``spaceid_gym.tracking``), their count and where; the last window
each mission kept the exact posterior before handing over to the filter, and how many windows were sampled afresh
under the kernel prior.

Pooled as before: the missions meeting the 1.5 x target, the missions consistent in NEES and NIS, the mean NIS
over every streamed update against its 95 % bounds (innovations are white, so that test stands), and the mean
NEES over every window against bounds that assume independent windows (kept for comparison: too narrow).

Usage::

    for s in 0 1 2 3 4 5 6 7 8 9; do spaceid track --robot paper6 --windows 10 --seed $s --out mission$s; done
    python benchmarks/track_summary.py mission*
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from spaceid_gym.arrays import FloatArray
from spaceid_gym.track_statistics import lag_correlation, lag_correlation_null, mean_bounds, run_average_nees, runs_mean_interval

#: unknowns of the fuel problem (fuel consumed, tank x, y, z): each window's NEES is chi-square(4) when consistent
UNKNOWNS = 4


def print_missions(runs: list[dict[str, Any]]) -> None:
    """One line per mission; its NEES test assumes independent windows."""
    print("seed | ukf RMS kg | hybrid RMS kg | ratio | NEES mean (ok, assuming independent windows) | NIS mean (ok)")
    for run in runs:
        s = run["summary"]
        print(
            f"{run['info']['seed']:4d} | {s['fuel_rms_error_ukf_kg']:10.2f} | {s['fuel_rms_error_hybrid_kg']:13.2f} | "
            f"{s['fuel_rms_ratio_ukf_over_hybrid']:5.2f} | {s['nees_mean']:6.2f} ({'yes' if s['nees_consistent'] else 'no'}) | "
            f"{s['nis_mean']:.4f} ({'yes' if s['nis_consistent'] else 'no'})"
        )


def print_correlation(nees: FloatArray, z_fuel: FloatArray, rng: np.random.Generator) -> None:
    """The evidence that a mission's windows are correlated: lag correlations against their shuffled spread."""
    print("correlation between a mission's windows k and k+lag, pooled over missions [95 % range if independent]:")
    for name, values in (("NEES", nees), ("log NEES", np.log(nees)), ("fuel z", z_fuel)):
        cells = []
        for lag in (1, 2, 3):
            null = lag_correlation_null(values, lag, rng, draws=1000)
            low, high = np.quantile(null, [0.025, 0.975])
            cells.append(f"lag {lag} {lag_correlation(values, lag):+.2f} [{low:+.2f}, {high:+.2f}]")
        print(f"  {name:8s}: " + "; ".join(cells))
    means = nees.mean(axis=1)
    print(
        f"  spread of the mission-mean NEES: std {means.std(ddof=1):.2f} over {len(means)} missions; independent "
        f"chi-square(4) windows give {np.sqrt(2 * UNKNOWNS / nees.shape[1]):.2f}; mission-mean fuel z^2 has std "
        f"{(z_fuel**2).mean(axis=1).std(ddof=1):.2f} (independent: {np.sqrt(2 / nees.shape[1]):.2f})"
    )


def print_nees_tests(nees: FloatArray, seeds: list[int], rng: np.random.Generator) -> None:
    """The NEES tests with the missions as the unit (valid for correlated windows)."""
    n, k = nees.shape
    average, low, high = run_average_nees(nees, UNKNOWNS)
    inside = (average >= low) & (average <= high)
    print(f"N-run average NEES per window index (Bar-Shalom 5.4.2; {n} missions, 95 % bounds {low:.2f}-{high:.2f}):")
    print("  " + " ".join(f"{value:.2f}{'' if ok else '*'}" for value, ok in zip(average, inside, strict=True)))
    print(
        f"  inside at {int(inside.sum())} of {k} window indices ({int((average > high).sum())} above, "
        f"{int((average < low).sum())} below; * outside); a consistent filter: about {0.95 * k:.1f}"
    )
    mean, t_interval, boot = runs_mean_interval(nees.mean(axis=1), rng)
    inside_t = "inside" if t_interval[0] <= UNKNOWNS <= t_interval[1] else "OUTSIDE"
    print(
        f"mean over missions of the mission-mean NEES (missions as the unit): {mean:.2f}; 95 % t-interval "
        f"{t_interval[0]:.2f}-{t_interval[1]:.2f} ({UNKNOWNS}, a consistent filter's, {inside_t}), bootstrap over "
        f"missions {boot[0]:.2f}-{boot[1]:.2f} (too narrow with few missions)"
    )
    far = nees > chi2.ppf(0.999, UNKNOWNS)
    print(
        f"windows with NEES above chi-square({UNKNOWNS})'s 99.9 % point {chi2.ppf(0.999, UNKNOWNS):.1f}: "
        f"{int(far.sum())} of {far.size} (expected {0.001 * far.size:.1f} whatever the correlation), in "
        f"{int(far.any(axis=1).sum())} missions: "
        + (", ".join(f"seed {seeds[i]}" for i in np.flatnonzero(far.any(axis=1))) or "none")
    )


def print_handover(runs: list[dict[str, Any]]) -> None:
    """How long each mission kept the exact posterior before handing over to the filter (``spaceid_gym.tracking``)."""
    last = {}
    regularised = 0
    for run in runs:
        exact = [w["window"] for w in run["windows"] if w.get("exact_posterior", 0)]
        last[run["info"]["seed"]] = max(exact) if exact else None
        regularised += sum(int(w.get("exact_regularised", 0)) for w in run["windows"])
    if all(v is None for v in last.values()):
        return
    counts = {k: sum(1 for v in last.values() if v == k) for k in sorted({v for v in last.values() if v is not None})}
    late = ", ".join(f"seed {seed} ({k})" for seed, k in last.items() if k is not None and k >= 2) or "none"
    print(
        "last window on the exact posterior (then the filter alone): "
        + ", ".join(f"window {k}: {n} missions" for k, n in counts.items())
        + f"; after window 1: {late}; windows sampled afresh under the kernel prior: {regularised}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", type=Path, nargs="+", help="output folders of spaceid track")
    parser.add_argument("--seed", type=int, default=0, help="seed of the shuffles and bootstrap resamples (default 0)")
    args = parser.parse_args()
    runs = [json.loads((folder / "track.json").read_text()) for folder in args.folders]
    print_missions(runs)
    n = len(runs)
    summaries = [r["summary"] for r in runs]
    windows = [w for r in runs for w in r["windows"]]
    error_ukf = np.array([w["ukf_fuel_consumed_kg"] - w["true_fuel_consumed_kg"] for w in windows])
    error_hybrid = np.array([w["hybrid_fuel_consumed_kg"] - w["true_fuel_consumed_kg"] for w in windows])
    rms_ukf, rms_hybrid = np.sqrt(np.mean(error_ukf**2)), np.sqrt(np.mean(error_hybrid**2))
    streamed = [w for w in windows if w["ukf_updates"] > 0]
    updates = sum(w["ukf_updates"] for w in streamed)
    nis = sum(w["ukf_nis_mean"] * w["ukf_updates"] for w in streamed) / updates
    print(f"{n} missions, {len(windows)} windows, {updates} streamed updates")
    print(
        f"fuel RMS within 1.5 x hybrid: {sum(s['fuel_within_1_5x_hybrid'] for s in summaries)}/{n}; pooled RMS ukf "
        f"{rms_ukf:.2f} kg, hybrid {rms_hybrid:.2f} kg, ratio {rms_ukf / rms_hybrid:.2f}"
    )
    low, high = mean_bounds(3, updates)
    print(
        f"NIS consistent in {sum(s['nis_consistent'] for s in summaries)}/{n} missions; pooled mean {nis:.4f} "
        f"(95 % bounds {low:.4f}-{high:.4f})"
    )
    print_handover(runs)
    fired = {r["info"]["seed"]: r["summary"].get("reinitialised_windows", []) for r in runs}
    where = "; ".join(f"seed {seed}: windows {ws}" for seed, ws in fired.items() if ws) or "none"
    print(f"re-initialisations on a high window NIS: {sum(len(ws) for ws in fired.values())} ({where})")
    nees_all = np.array([w["ukf_nees"] for w in windows])
    low, high = mean_bounds(UNKNOWNS, len(nees_all))
    print(
        f"assuming independent windows (too narrow, see below): NEES consistent in "
        f"{sum(s['nees_consistent'] for s in summaries)}/{n} missions; pooled mean {nees_all.mean():.2f} "
        f"(95 % bounds {low:.2f}-{high:.2f}), median {np.median(nees_all):.2f}"
    )
    if len({len(r["windows"]) for r in runs}) != 1 or n < 2:
        print("the per-window tests need at least 2 missions of the same number of windows")
        return
    nees = np.array([[w["ukf_nees"] for w in r["windows"]] for r in runs])
    z_fuel = np.array(
        [[(w["ukf_fuel_consumed_kg"] - w["true_fuel_consumed_kg"]) / w["ukf_fuel_std_kg"] for w in r["windows"]] for r in runs]
    )
    rng = np.random.default_rng(args.seed)
    print_correlation(nees, z_fuel, rng)
    print_nees_tests(nees, [r["info"]["seed"] for r in runs], rng)


if __name__ == "__main__":
    main()
