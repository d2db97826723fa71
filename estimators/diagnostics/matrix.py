"""The variation matrix: the diagnosis on logs whose every axis is drawn from the seed.

Each log of :func:`run_matrix` is a :class:`~spaceid_gym.variations.VariationCase` (robot, sample rate, attitude source,
noise, excitation, effect size, slosh model and period, drawn by :func:`~spaceid_gym.variations.draw_variation`),
simulated, diagnosed and scored as the suite's logs are (:func:`~estimators.diagnostics.suite.diagnosed_cells`), with
the expected power of its effect's test (:func:`~estimators.diagnostics.power.expected_power`). ``spaceid
diagnose-suite --matrix`` writes ``matrix.csv`` (a row per log), ``summary.json`` and ``matrix.md`` (per effect, then
per effect and axis value: the right verdicts among the eligible logs).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import beta, binom, chi2

from estimators.diagnostics.diagnose import NO_MISSING_EFFECT
from estimators.diagnostics.power import expected_power, separation
from estimators.diagnostics.suite import ERROR_VERDICT, SUITE_EFFECTS, diagnosed_cells, error_cells, write_run
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.executors import ExecutorSpec, run_jobs
from spaceid_gym.variations import (
    AXES,
    VariationCase,
    axis_label,
    axis_labels,
    checked_fixed,
    draw_variation,
    simulate_variation,
    truth_of,
)

#: a log is *eligible* (its verdict counted in the matrix's figures) when the expected power of ``diagnose``'s test of
#: its hidden effect is at least this (:func:`estimators.diagnostics.power.expected_power`); every clean log is
ELIGIBLE_POWER = 0.9

#: the targets of a cell (issue 19's 'done when'): the hidden effect named on at least ``TARGET_NAMED`` of the eligible
#: logs, a clean log ``none`` on at least ``TARGET_CLEAN``; after naming, the gyro residual's RMS at most
#: ``TARGET_RESIDUAL`` times the noise on every log, the fuel error's RMS at most ``TARGET_FUEL_Z`` Cramér-Rao std
TARGET_NAMED, TARGET_CLEAN, TARGET_RESIDUAL, TARGET_FUEL_Z = 0.90, 0.95, 1.1, 1.5

#: the confidence of the lower bound on a cell's share of right verdicts (``correct_lower_bound``, one-sided)
BOUND_CONFIDENCE = 0.95


def run_variation(case: VariationCase, duration_s: float = 60.0) -> dict[str, Any]:
    """Simulate the variation ``case`` (:func:`spaceid_gym.variations.simulate_variation`), compute the expected
    power of its effect's test, diagnose it as :func:`~estimators.diagnostics.suite.run_case` does; one row: the case's cells
    (:func:`_variation_cells`), ``expected_power`` (NaN for a clean log), ``nearest_rival`` and ``separation_power``
    (the rival candidate the effect is least likely to beat, and that probability: :func:`~estimators.diagnostics.power.separation`;
    empty and NaN for a clean log), the verdict columns of
    :func:`~estimators.diagnostics.suite.diagnosed_cells` and ``wall_time_s``. A log whose power or diagnosis raises gives a row with the verdict
    ``error`` (and the power when it was computed), as :func:`~estimators.diagnostics.suite.guarded_case`."""
    start = time.perf_counter()
    row = _variation_cells(case)
    try:
        env = simulate_variation(case, duration_s)
        model = IdentificationModel(env.robot, "fuel")
        clean = case.effect == NO_MISSING_EFFECT
        log, truth = env.measurement_log(), truth_of(env)
        row["expected_power"] = math.nan if clean else expected_power(model, case.effect, log, truth)
        row["nearest_rival"], row["separation_power"] = "", math.nan
        if not clean:
            separations = separation(model, case.effect, log, truth)
            row["nearest_rival"] = min(separations, key=lambda rival: separations[rival].probability)
            row["separation_power"] = separations[row["nearest_rival"]].probability
        row.update(diagnosed_cells(env, case.effect))
    except Exception as exc:  # recorded in the row and reported by the command, not hidden
        return {**row, **error_cells(exc)}
    row["wall_time_s"] = time.perf_counter() - start
    return row


def guarded_variation(effect: str, seed: int, duration_s: float = 60.0, fixed: dict[str, Any] | None = None) -> dict[str, Any]:
    """:func:`run_variation` of the case of ``effect`` and ``seed`` (:func:`spaceid_gym.variations.draw_variation`,
    ``fixed`` axes pinned); a draw that raises gives an ``error`` row too."""
    try:
        case = draw_variation(effect, seed, fixed)
    except Exception as exc:  # recorded in the row and reported by the command, not hidden
        return {"effect": effect, "seed": seed, **error_cells(exc)}
    return run_variation(case, duration_s)


def _variation_cells(case: VariationCase) -> dict[str, Any]:
    """A matrix row's first cells: the effect, the seed, every axis, the effect's size (its unit:
    :data:`spaceid_gym.effects.MAGNITUDE_UNITS`; NaN when clean) and the fuel consumed (kg)."""
    return {
        "effect": case.effect,
        "seed": case.seed,
        **case.axes(),
        "magnitude": math.nan if case.magnitude is None else case.magnitude,
        "fuel_consumed_kg": case.fuel_consumed_kg,
    }


def run_matrix(
    effects: tuple[str, ...] = SUITE_EFFECTS,
    seeds: int = 20,
    first_seed: int = 0,
    executor: ExecutorSpec | None = None,
    duration_s: float = 60.0,
    fixed: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """The variation matrix: every effect x ``seeds`` seeds, each log's axes drawn from its seed (``fixed``: pinned,
    checked before anything runs), each log a job on ``executor`` (default: serial); rows in a fixed order (effect,
    seed), bit-identical whatever the executor. The same seed draws
    the same axes and fuel state for every effect (paired logs)."""
    pinned = checked_fixed(fixed)
    cases = [(effect, first_seed + s, duration_s, pinned) for effect in effects for s in range(seeds)]
    return run_jobs(_guarded_variation_of, cases, executor or ExecutorSpec("serial"), desc="variation matrix", unit="log")


def summarise_matrix(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per effect, per axis (``all`` first: every log), per axis value (a continuous axis's bin,
    :func:`spaceid_gym.variations.axis_label`): ``logs``; ``eligible``: logs whose expected power is at least
    :data:`ELIGIBLE_POWER` (a clean log: every one; a log whose power is unknown, not); ``correct``: eligible logs whose
    verdict names the hidden effect (clean logs: ``none``), ``correct_percent`` of the eligible (NaN without any);
    ``correct_lower_bound``: the one-sided :data:`BOUND_CONFIDENCE` Clopper-Pearson lower bound on the share of right
    verdicts that ``correct`` of ``eligible`` shows (NaN without eligible logs; 0.74 for 10 of 10, 0.86 for 20 of 20);
    ``undecided``: eligible logs named wrongly but with the hidden effect among the verdict's rivals (the log hardly
    tells them apart, :func:`~estimators.diagnostics.verdict.rivals`); ``separable``: eligible logs whose
    ``separation_power`` is at least :data:`ELIGIBLE_POWER` too (clean logs: every one), ``separable_correct`` the
    correct among them; ``rms_over_noise_after_mean`` over the correct
    ones; ``wall_time_s_mean`` over the logs that ran."""
    out = []
    for effect in dict.fromkeys(r["effect"] for r in rows):
        group = [r for r in rows if r["effect"] == effect]
        out.append(_matrix_cell(effect, "all", "all", group))
        for axis in AXES:
            for value in axis_labels(axis):
                cell = [r for r in group if axis_label(axis, r.get(axis)) == value]
                if cell:
                    out.append(_matrix_cell(effect, axis, value, cell))
    return out


def _eligible(row: dict[str, Any]) -> bool:
    """Whether the row's verdict counts (see :func:`summarise_matrix`)."""
    power = row.get("expected_power")
    return row["effect"] == NO_MISSING_EFFECT or (power is not None and power >= ELIGIBLE_POWER)


def _separable(row: dict[str, Any]) -> bool:
    """Whether an eligible row's effect is told from its nearest rival with probability at least :data:`ELIGIBLE_POWER`
    (a clean log: always; an unknown separation: not)."""
    power = row.get("separation_power")
    return row["effect"] == NO_MISSING_EFFECT or (power is not None and power >= ELIGIBLE_POWER)


def _matrix_cell(effect: str, axis: str, value: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """One entry of :func:`summarise_matrix`."""
    eligible = [r for r in rows if _eligible(r)]
    correct = [r for r in eligible if r["correct"]]
    separable = [r for r in eligible if _separable(r)]
    ran = [r for r in rows if r["verdict"] != ERROR_VERDICT]
    finite_z = np.isfinite(_fuel_z(correct))
    return {
        "effect": effect,
        "axis": axis,
        "value": value,
        "logs": len(rows),
        "eligible": len(eligible),
        "correct": len(correct),
        "correct_percent": 100.0 * len(correct) / len(eligible) if eligible else math.nan,
        "correct_lower_bound": share_lower_bound(len(correct), len(eligible)),
        "undecided": sum(1 for r in eligible if not r["correct"] and r["effect"] in str(r.get("rivals", "")).split(";")),
        "separable": len(separable),
        "separable_correct": sum(1 for r in separable if r["correct"]),
        "rms_over_noise_after_mean": float(np.mean([r["rms_over_noise_after"] for r in correct])) if correct else math.nan,
        "rms_over_noise_after_max": float(np.max([r["rms_over_noise_after"] for r in correct])) if correct else math.nan,
        "fuel_z_rms_after": _fuel_z_rms(correct),
        "fuel_z_values_after": int(finite_z.sum()),
        "fuel_z_logs_after": int(finite_z.any(axis=1).sum()),
        "wall_time_s_mean": float(np.mean([r["wall_time_s"] for r in ran])) if ran else math.nan,
    }


def share_lower_bound(successes: int, trials: int, confidence: float = BOUND_CONFIDENCE) -> float:
    """The one-sided Clopper-Pearson lower bound on a binomial share at ``confidence``: the share below which
    ``successes`` of ``trials`` or more would have had probability at most ``1 - confidence``; 0 without a success,
    NaN without a trial."""
    if not 0 <= successes <= trials:
        raise ValueError(f"share_lower_bound: expected 0 <= successes <= trials, got {successes} of {trials}")
    if trials == 0:
        return math.nan
    return 0.0 if successes == 0 else float(beta.ppf(1.0 - confidence, successes, trials - successes + 1))


def short_of_targets(summary: list[dict[str, Any]]) -> list[str]:
    """Every cell of :func:`summarise_matrix` (every log of an effect, and each axis value) that misses a target
    (:data:`TARGET_NAMED` or :data:`TARGET_CLEAN` of the eligible logs named right, :data:`TARGET_RESIDUAL`,
    :data:`TARGET_FUEL_Z`), one line each: the cell, its counts and what it misses. A share below the target comes with
    the probability of so few right verdicts if the true share were the target (binomial): a small cell misses a
    target by chance often (4 of 5 at 90 %: 0.41). A cell without eligible logs misses nothing."""
    lines = []
    for s in summary:
        if not s["eligible"]:
            continue
        target = TARGET_CLEAN if s["effect"] == NO_MISSING_EFFECT else TARGET_NAMED
        misses = []
        if s["correct"] < target * s["eligible"]:
            chance = float(binom.cdf(s["correct"], s["eligible"], target))
            misses.append(
                f"named right {s['correct']}/{s['eligible']} (target {100 * target:.0f} %; as few has probability "
                f"{chance:.2g} at the target share)"
            )
        if s["rms_over_noise_after_max"] > TARGET_RESIDUAL:
            misses.append(f"residual after naming up to {s['rms_over_noise_after_max']:.3f} x noise (target {TARGET_RESIDUAL:g})")
        if s["fuel_z_rms_after"] > TARGET_FUEL_Z:
            misses.append(_fuel_z_miss(s["fuel_z_rms_after"], s["fuel_z_values_after"], s["fuel_z_logs_after"]))
        if misses:
            where = "every log" if s["axis"] == "all" else f"{s['axis']} {s['value']}"
            lines.append(f"{s['effect']}, {where} ({s['logs']} logs, {s['eligible']} eligible): {'; '.join(misses)}")
    return lines


def fuel_z_chance(z_rms: float, values: int, logs: int) -> tuple[float, float]:
    """The probability of a fuel z RMS at least ``z_rms`` over ``values`` finite z of ``logs`` logs if every z were a
    standard normal (the Cramér-Rao bound calibrated and the estimate unbiased), two ways: the z independent (the sum
    of squares a chi-square with ``values`` degrees of freedom), and a log's unknowns moving as one (each log's share
    ``values / logs`` times one chi-square degree: the sum ``values / logs`` times a chi-square with ``logs``). A
    log's fuel unknowns are correlated; in the upper tail, where a cell misses the target (an RMS of 1.5 and more),
    its chance lies between the two (a rank-one correlation within a log is the second; below an RMS of about 1.2
    other correlations can exceed it). ``(nan, nan)`` without values."""
    if values <= 0 or logs <= 0:
        return math.nan, math.nan
    squares = z_rms * z_rms * values
    return float(chi2.sf(squares, values)), float(chi2.sf(squares * logs / values, logs))


def _fuel_z_miss(z_rms: float, values: int, logs: int) -> str:
    """A cell's fuel z RMS above :data:`TARGET_FUEL_Z`, with the chance of as large at a calibrated bound
    (:func:`fuel_z_chance`)."""
    independent, as_one = fuel_z_chance(z_rms, values, logs)
    return (
        f"fuel z RMS {z_rms:.2f} (target {TARGET_FUEL_Z:g}; as large has probability {independent:.2g} at a "
        f"calibrated bound with the unknowns independent, {as_one:.2g} with a log's moving as one)"
    )


def _fuel_z(rows: list[dict[str, Any]]) -> FloatArray:
    """The error after the verdict over its Cramér-Rao std (``z_*_after``) of the four fuel unknowns, a row per log."""
    return np.array([[r[f"z_{name}_after"] for name in ("mdf", "bx", "by", "bz")] for r in rows], dtype=float).reshape(-1, 4)


def _fuel_z_rms(rows: list[dict[str, Any]]) -> float:
    """The RMS over ``rows`` and the four fuel unknowns of the error after the verdict over its Cramér-Rao std
    (``z_*_after``; 1 for an efficient, unbiased estimate), the unknowns without a finite bound left out (their z is
    NaN: :attr:`~estimators.diagnostics.workflow.ParameterErrors.z`); NaN without rows."""
    z = _fuel_z(rows)
    return float(np.sqrt(np.nanmean(z**2))) if z.size and np.isfinite(z).any() else math.nan


def _fraction_cell(entry: dict[str, Any] | None) -> str:
    """``"correct/eligible (%)"``; ``"0/0"`` without eligible logs, empty without logs."""
    if entry is None:
        return ""
    if not entry["eligible"]:
        return "0/0"
    return f"{entry['correct']}/{entry['eligible']} ({entry['correct_percent']:.0f} %)"


def matrix_markdown(summary: list[dict[str, Any]]) -> str:
    """The matrix summary as Markdown: every log per effect, then one block per axis (rows: the effects with logs
    there; columns: the axis's values; cells ``correct/eligible (%)``), then the cells short of a target
    (:func:`short_of_targets`)."""
    entries = {(s["effect"], s["axis"], s["value"]): s for s in summary}
    effects = list(dict.fromkeys(s["effect"] for s in summary))
    lines = [
        f"Eligible: expected power of the effect's test >= {ELIGIBLE_POWER:g} (clean logs: all); correct: the verdict "
        "names the hidden effect (clean logs: none). Separable: eligible, and the effect beats its nearest rival "
        f"candidate with probability >= {ELIGIBLE_POWER:g} (separation power).",
        "",
        f"Lower bound: the share of right verdicts is above it with confidence {BOUND_CONFIDENCE:g} (Clopper-Pearson).",
        "",
        "| hidden effect | logs | eligible | correct | lower bound | wrong, truth a rival | correct where separable "
        "| RMS/noise after: mean, max | fuel z RMS after | s/log |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for effect in effects:
        s = entries[(effect, "all", "all")]
        lines.append(
            f"| {effect} | {s['logs']} | {s['eligible']} | {_fraction_cell(s)} | {s['correct_lower_bound']:.2f} | {s['undecided']} | "
            f"{s['separable_correct']}/{s['separable']} | "
            f"{s['rms_over_noise_after_mean']:.3f}, "
            f"{s['rms_over_noise_after_max']:.3f} | {s['fuel_z_rms_after']:.2f} | {s['wall_time_s_mean']:.1f} |"
        )
    for axis in AXES:
        labels = axis_labels(axis)
        rows = [e for e in effects if any((e, axis, v) in entries for v in labels)]
        if not rows:
            continue
        lines += ["", f"**{axis}**", "", f"| hidden effect | {' | '.join(labels)} |", "|---" * (len(labels) + 1) + "|"]
        lines += [f"| {e} | {' | '.join(_fraction_cell(entries.get((e, axis, v))) for v in labels)} |" for e in rows]
    short = short_of_targets(summary)
    lines += [
        "",
        f"**Cells short of a target** ({len(short)}; targets: named right on {100 * TARGET_NAMED:.0f} % of the "
        f"eligible logs, clean logs `none` on {100 * TARGET_CLEAN:.0f} %, after naming the residual at most "
        f"{TARGET_RESIDUAL:g} x noise and the fuel z RMS at most {TARGET_FUEL_Z:g})",
        "",
    ]
    lines += [f"* {line}" for line in short] or ["none"]
    return "\n".join(lines) + "\n"


def write_matrix(out: str | Path, rows: list[dict[str, Any]], info: dict[str, Any]) -> dict[str, Path]:
    """``matrix.csv`` (a row per log), ``summary.json`` (``info`` and :func:`summarise_matrix`) and ``matrix.md`` in ``out``."""
    summary = summarise_matrix(rows)
    return write_run(Path(out), ("matrix.csv", "matrix.md"), rows, summary, info, matrix_markdown(summary))


def _guarded_variation_of(case: tuple[Any, ...]) -> dict[str, Any]:
    """:func:`guarded_variation` of one case's arguments (a job of :func:`run_matrix`)."""
    return guarded_variation(*case)
