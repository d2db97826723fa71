"""A diagnosed log's row as the diagnosis suite and the variation matrix write it, for the tests of their bookkeeping
(no simulation)."""

from __future__ import annotations

import math
from typing import Any

from estimators.diagnostics.suite import ERROR_VERDICT
from spaceid_gym.variations import draw_variation


def diagnosed_row(effect: str, seed: int, verdict: str | None = None) -> dict[str, Any]:
    """The row of a diagnosed log (:func:`estimators.diagnostics.suite.diagnosed_cells`' columns): the verdict
    (``effect`` unless given), the residual at 1.5 x the noise before and 1.02 x after, every z-score 1."""
    verdict = effect if verdict is None else verdict
    row: dict[str, Any] = {"effect": effect, "seed": seed, "verdict": verdict, "correct": verdict == effect, "runner_up": ""}
    row.update(rms_over_noise_before=1.5, rms_over_noise_after=1.02, wall_time_s=0.1)
    for name in ("mdf", "bx", "by", "bz"):
        for when in ("before", "after"):
            row[f"z_{name}_{when}"] = row[f"z_{name}_{when}_at_estimate"] = 1.0
    return row


def matrix_row(effect: str, seed: int, duration_s: float = 60.0, fixed: dict[str, Any] | None = None) -> dict[str, Any]:
    """A row as :func:`estimators.diagnostics.matrix.guarded_variation` returns it, without the simulation: the drawn
    case's cells, a power of 0.95 on even seeds (0.5 on odd), the verdict right except on seed 2, an error on seed 3."""
    case = draw_variation(effect, seed, fixed)
    row = {"effect": effect, "seed": seed, **case.axes(), "magnitude": case.magnitude or math.nan, "fuel_consumed_kg": 1.0}
    if seed == 3:
        return {**row, "verdict": ERROR_VERDICT, "correct": False, "error": "ValueError: broken (x.py:1 in f)"}
    row.update(diagnosed_row(effect, seed, "payload" if seed == 2 else None), rms_over_noise_after=1.0)
    row["expected_power"] = 0.95 if seed % 2 == 0 else 0.5
    return row
