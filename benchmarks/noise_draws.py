"""One log of the variation matrix, its motion measured with many noise draws: how often the verdict is right, and the
fuel unknowns' errors after the verdict in Cramér-Rao std at the truth (their RMS over the draws is 1 for a calibrated
bound). Each draw is diagnosed as a matrix row is (:func:`~estimators.diagnostics.suite.diagnosed_cells`); the draws
that are wrong are listed with their z. The figures of a single log's noise draws in docs/results.md (Variation
matrix) come from here. Usage::

    python benchmarks/noise_draws.py none 10565 --first-draw 1000 --draws 100 --jobs 2
    python benchmarks/noise_draws.py none 10713 --fix rate_hz=50 --draws 8 --jobs 2

``--fix`` pins axes of the case as the matrix's ``--fix`` does (the rest drawn from the seed as before, so
``--fix rate_hz=50`` is the same motion sampled at 50 Hz).
"""

from __future__ import annotations

import argparse
from functools import partial
from typing import Any

import numpy as np

from estimators.diagnostics.suite import diagnosed_cells
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.executors import add_executor_arguments, executor_from_arguments, run_jobs
from spaceid_gym.variations import VariationCase, draw_variation, parse_fixed, simulate_variation

#: the fuel unknowns, as the matrix's z columns name them
UNKNOWNS = ("mdf", "bx", "by", "bz")


def diagnosed_draw(case: VariationCase, duration_s: float, noise_seed: int) -> dict[str, Any]:
    """The matrix row's verdict, residual and fuel z after the verdict for ``case``'s motion measured with the noise
    of ``noise_seed``."""
    row = diagnosed_cells(simulate_variation(case, duration_s, noise_seed=noise_seed), case.effect)
    return {
        "draw": noise_seed,
        "verdict": row["verdict"],
        "correct": row["correct"],
        "rms_over_noise": row["rms_over_noise_after"],
        "z": [row[f"z_{name}_after"] for name in UNKNOWNS],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("effect", help="the hidden effect of the matrix row (none: a clean log)")
    parser.add_argument("seed", type=int, help="the matrix row's seed (its motion and axes)")
    parser.add_argument("--first-draw", type=int, default=1000, help="the first noise seed")
    parser.add_argument("--draws", type=int, default=20, help="how many noise seeds, from --first-draw on")
    parser.add_argument("--seconds", type=float, default=60.0, help="the log's length (the matrix's: 60 s)")
    parser.add_argument("--fix", default=None, help="pin axes of the case, e.g. 'rate_hz=50,noise_scale=1.0'")
    add_executor_arguments(parser)
    args = parser.parse_args()
    if args.draws < 1:
        parser.error(f"--draws: expected at least 1, got {args.draws}")
    try:
        case = draw_variation(args.effect, args.seed, parse_fixed(args.fix))
    except SpaceIdInputError as error:
        parser.error(str(error))
    print(f"{args.effect} {args.seed}: {case.axes()}")
    draws = range(args.first_draw, args.first_draw + args.draws)
    rows = run_jobs(partial(diagnosed_draw, case, args.seconds), draws, executor_from_arguments(args, 64), desc="draws")
    z = np.array([r["z"] for r in rows], dtype=float)
    right = sum(r["correct"] for r in rows)
    print(f"verdict right on {right}/{len(rows)} draws ({draws.start}-{draws.stop - 1})")
    print(f"residual after the verdict over the noise: max {max(r['rms_over_noise'] for r in rows):.3f}")
    rms = np.sqrt(np.nanmean(z**2, axis=0))
    print("fuel z RMS over the draws: " + ", ".join(f"{n} {v:.2f}" for n, v in zip(UNKNOWNS, rms, strict=True)))
    print(f"  all {float(np.sqrt(np.nanmean(z**2))):.2f}, largest |z| {float(np.nanmax(np.abs(z))):.2f}")
    for r in rows:
        if not r["correct"]:
            print(f"  draw {r['draw']}: {r['verdict']}, z " + " ".join(f"{v:+.2f}" for v in r["z"]))


if __name__ == "__main__":
    main()
