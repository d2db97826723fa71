"""The variation matrix's logs whose tank is nearly empty, diagnosed: a held-out check of what the diagnosis does where
the model as given can consume all the fuel (a missing slosh can drag it there, and no slosh can act at that fit).

Of the seeds from ``--first-seed`` on, the first ``--logs`` whose draw leaves less than ``--liquid-fraction`` of the
robot's usable fuel in the tank (the fuel fraction is drawn before the effect, so a seed's tank is the same for every
effect, with nothing pinned), each diagnosed for each of ``--effects`` as the matrix does
(:func:`~estimators.diagnostics.matrix.guarded_variation`). Prints one JSON object per log (:data:`CELLS` of the
matrix row; NaN as ``null``), then per effect the eligible logs named right on standard error; exits 1 if a log
raised (its row's ``error``). Usage::

    python benchmarks/near_empty_tanks.py --first-seed 12100 --logs 20 --effects slosh,none > rows.jsonl
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from estimators.diagnostics.matrix import ELIGIBLE_POWER, guarded_variation
from estimators.diagnostics.verdict import NO_MISSING_EFFECT
from spaceid_gym.effects.draws import remaining_liquid_kg
from spaceid_gym.effects.settings import EFFECT_NAMES
from spaceid_gym.robots import load_robot
from spaceid_gym.variations import AXES, draw_variation

#: the matrix row's cells printed per log
CELLS = (
    "effect",
    "seed",
    *AXES,
    "fuel_consumed_kg",
    "magnitude",
    "expected_power",
    "nearest_rival",
    "separation_power",
    "verdict",
    "correct",
    "rms_over_noise_after",
    "z_mdf_after",
    "z_bx_after",
    "z_by_after",
    "z_bz_after",
    "error",
    "wall_time_s",
)


def nearly_empty_seeds(first_seed: int, logs: int, liquid_fraction: float, scan: int) -> list[int]:
    """The first ``logs`` seeds from ``first_seed`` (within ``scan`` seeds) whose drawn tank holds less than
    ``liquid_fraction`` of the usable fuel."""
    seeds: list[int] = []
    for seed in range(first_seed, first_seed + scan):
        case = draw_variation("none", seed)
        robot = load_robot(case.robot)
        left = float(remaining_liquid_kg(robot, case.fuel_consumed_kg)) / float(remaining_liquid_kg(robot, 0.0))
        if left < liquid_fraction:
            seeds.append(seed)
            if len(seeds) == logs:
                break
    return seeds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first-seed", type=int, required=True)
    parser.add_argument("--logs", type=int, default=20, help="how many nearly empty tanks")
    parser.add_argument("--effects", default="slosh,none", help="comma-separated hidden effects, 'none' for clean logs")
    parser.add_argument(
        "--liquid-fraction", type=float, default=0.03, help="a tank counts as nearly empty below this share of the usable fuel"
    )
    parser.add_argument("--scan", type=int, default=2000, help="how many seeds to look through")
    args = parser.parse_args()
    if args.logs < 1 or args.scan < 1:
        parser.error(f"--logs and --scan: expected at least 1, got {args.logs} and {args.scan}")
    if not 0.0 < args.liquid_fraction <= 1.0:
        parser.error(f"--liquid-fraction: expected a share in (0, 1], got {args.liquid_fraction}")
    effects = [e.strip() for e in args.effects.split(",")]
    unknown = [e for e in effects if e not in (*EFFECT_NAMES, NO_MISSING_EFFECT)]
    if unknown:
        parser.error(f"--effects: unknown {unknown}; expected names from {', '.join((NO_MISSING_EFFECT, *EFFECT_NAMES))}")
    seeds = nearly_empty_seeds(args.first_seed, args.logs, args.liquid_fraction, args.scan)
    if not seeds:
        parser.error(f"no seed in {args.first_seed}-{args.first_seed + args.scan - 1} leaves less than {args.liquid_fraction}")
    rows: list[dict[str, Any]] = []
    for seed in seeds:
        for effect in effects:
            row = guarded_variation(effect, seed)
            rows.append({cell: _json_value(row.get(cell)) for cell in CELLS})
            print(json.dumps(rows[-1], default=str, allow_nan=False), flush=True)
    print(f"{len(seeds)} seeds ({seeds[0]}-{seeds[-1]}):", file=sys.stderr)
    for effect in effects:
        own = [r for r in rows if r["effect"] == effect]
        eligible = [r for r in own if effect == NO_MISSING_EFFECT or (r["expected_power"] or 0.0) >= ELIGIBLE_POWER]
        failed = sum(1 for r in own if r["error"])
        right = sum(bool(r["correct"]) for r in eligible)
        print(f"  {effect}: {right} of {len(eligible)} eligible logs right; {failed} raised", file=sys.stderr)
    if any(r["error"] for r in rows):
        sys.exit(1)


def _json_value(value: Any) -> Any:
    """``value`` for strict JSON: a NaN float as ``None``."""
    return None if isinstance(value, float) and math.isnan(value) else value


if __name__ == "__main__":
    main()
