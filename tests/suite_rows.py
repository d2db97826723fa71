"""A diagnosed log's row as the diagnosis suite writes it, for the tests of its bookkeeping (no simulation)."""

from __future__ import annotations

from typing import Any


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
