"""The diagnosis suite: does ``diagnose`` name the hidden effect, and does adding it bring the error back down?

For each catalogue effect (and for clean logs), over many seeds: simulate a 60 s window of ``paper6`` with
the *diagnostic excitation* (:data:`DIAGNOSTIC_EXCITATION`: the multi-sine of the evaluation with its band
widened from 0.025-0.125 Hz to 0.05-0.5 Hz, so that it also shakes the 0.2-0.5 Hz slosh band: with the
evaluation's slow excitation a realistic slosh mass moves the base by less than a tenth of the gyro noise
and no method could see it), realistic gyro noise, a fuel state drawn as in the evaluation harness and
the effect hidden in the truth at its default magnitude (random direction, :func:`spaceid_gym.effects.draw_effect`);
run :func:`~estimators.diagnostics.diagnose.diagnose` on the paper's ``fuel`` model; when the verdict names
an effect, add it and measure the residual RMS against the simulated gyro noise and the fuel unknowns'
errors in Cramér-Rao standard deviations, before and after (the diagnosis's fits of the model as given and with the
named effect, each on the gyro and the attitude where the diagnosis weighed both; ``z_*``: the bound at the true parameters, as in
:mod:`estimators.evaluation`; ``z_*_at_estimate``: the estimate's own bound, see
:func:`~estimators.diagnostics.workflow.parameter_errors`).

``spaceid diagnose-suite`` runs it and writes ``suite.csv`` (a row per log), ``summary.json`` and
``table.md`` (per effect: verdicts, correct %, residual and parameter errors after). A log whose diagnosis
raises does not stop the others: its row has the verdict ``error`` and the exception in ``error`` (counted as
not correct), and the command exits non-zero after writing everything.
"""

from __future__ import annotations

import math
import subprocess
import time
import traceback
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from estimators.diagnostics.diagnose import NO_MISSING_EFFECT, diagnose
from estimators.diagnostics.workflow import ParameterErrors, apply_effect, baseline_estimate, parameter_errors
from estimators.evaluation import Setting, draw_settings
from estimators.problem import IdentificationModel
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.effects import MAGNITUDE_UNITS, HiddenEffects, draw_effect
from spaceid_gym.envs.free_floating import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.executors import ExecutorSpec, run_jobs
from spaceid_gym.files import write_csv_atomic, write_json_atomic, write_text_atomic
from spaceid_gym.robots import Robot, load_robot
from spaceid_gym.variations import DIAGNOSTIC_EXCITATION as VARIATION_DIAGNOSTIC_EXCITATION

#: options of :class:`~spaceid_gym.excitation.FourierExcitation` for the suite (see the module docstring); defined with the
#: variation matrix's excitations, whose ``diagnostic`` value it is
DIAGNOSTIC_EXCITATION: dict[str, Any] = VARIATION_DIAGNOSTIC_EXCITATION

#: the effects hidden one at a time (the issue's catalogue, with ``gyro_scale``, the scale-factor/misalignment
#: variant of ``gyro_bias``), and ``none`` for clean logs
SUITE_EFFECTS: tuple[str, ...] = (
    NO_MISSING_EFFECT,
    "initial_momentum",
    "gyro_bias",
    "payload",
    "slosh",
    "delay",
    "external_torque",
    "gyro_scale",
)


def draw_case(robot: Robot, effect: str, seed: int, magnitude: float | None = None) -> tuple[Setting, HiddenEffects | None]:
    """The fuel state and the hidden effect (``None`` for ``none``) of the suite's log of ``effect`` and ``seed``.

    ``magnitude``: the effect's size in the unit of :data:`spaceid_gym.effects.MAGNITUDE_UNITS` (``None``: the
    default of :data:`spaceid_gym.effects.DEFAULT_MAGNITUDES`); the direction drawn does not depend on it. Raises :class:`SpaceIdInputError` for a size the
    log cannot have (a slosh mass above the liquid left)."""
    setting = draw_settings(robot, 1, seed)[0]
    rng = np.random.default_rng([seed, 1])
    hidden = None if effect == NO_MISSING_EFFECT else draw_effect(effect, rng, robot, setting.fuel_consumed_kg, magnitude)
    return setting, hidden


def simulate_case(
    robot_name: str, effect: str, seed: int, duration_s: float = 60.0, magnitude: float | None = None
) -> FreeFloatingIDEnv:
    """The suite's log of ``effect`` (``none``: clean) and ``seed`` (:func:`draw_case`): the simulated env after the
    window (its ``measurement_log()``, ``truth()`` and ``hidden_effects``)."""
    robot = load_robot(robot_name)
    setting, hidden = draw_case(robot, effect, seed, magnitude)
    return simulate_episode(
        robot,
        duration_s,
        setting.fuel_consumed_kg,
        setting.tank_position_m,
        FourierExcitation(robot.n_joints, seed=seed, **DIAGNOSTIC_EXCITATION),
        seed=seed,
        hidden_effects=hidden,
    )


def run_case(robot_name: str, effect: str, seed: int, duration_s: float = 60.0, magnitude: float | None = None) -> dict[str, Any]:
    """Simulate one log with ``effect`` hidden (``none``: clean; ``magnitude``: see :func:`simulate_case`),
    diagnose it, apply the verdict; one result row."""
    start = time.perf_counter()
    env = simulate_case(robot_name, effect, seed, duration_s, magnitude)
    row: dict[str, Any] = {"effect": effect, "magnitude": _magnitude_cell(magnitude), "seed": seed}
    row.update(diagnosed_cells(env, effect))
    row["wall_time_s"] = time.perf_counter() - start
    return row


def diagnosed_cells(env: FreeFloatingIDEnv, effect: str) -> dict[str, Any]:
    """Diagnose the simulated log of ``env`` (``effect`` hidden, ``none``: clean) on the ``fuel`` model and apply
    the verdict: the verdict columns, the residual RMS over the log's per-sample gyro noise std and the z-scores of
    the fuel unknowns before and after."""
    log, truth = env.measurement_log(), env.truth()
    noise = env.sensors.gyro_std_rad_s(env.control_period_s)
    model = IdentificationModel(env.robot, "fuel")
    diagnosis = diagnose(model, log)
    row: dict[str, Any] = {
        "verdict": diagnosis.verdict,
        "correct": diagnosis.verdict == effect,
        "runner_up": next((c.effect for c in diagnosis.candidates if c.effect != diagnosis.verdict), ""),
        "rivals": ";".join(str(f.effect) for f, _ in diagnosis.rivals),
        "rms_over_noise_before": diagnosis.baseline.residual_rms_rad_s / noise,
    }
    before = parameter_errors(model, log, baseline_estimate(model, log, diagnosis), truth)
    row.update(_z_columns(before, "before"))
    if diagnosis.best is not None:
        extended, estimate = apply_effect(model, log, diagnosis.best.effect or "", diagnosis)
        row["rms_over_noise_after"] = diagnosis.best.residual_rms_rad_s / noise
        after = parameter_errors(extended, log, estimate, truth)
    else:
        row["rms_over_noise_after"] = row["rms_over_noise_before"]
        after = before
    row.update(_z_columns(after, "after"))
    return row


def _z_columns(errors: ParameterErrors | None, when: str) -> dict[str, float]:
    """``z_<unknown>_<when>`` (error / bound at the truth) and ``..._at_estimate`` (error / the estimate's bound); NaN without errors."""
    out = {}
    for i, name in enumerate(("mdf", "bx", "by", "bz")):
        out[f"z_{name}_{when}"] = math.nan if errors is None else float(errors.z[i])
        out[f"z_{name}_{when}_at_estimate"] = (
            math.nan if errors is None else float(errors.error[i] / errors.crlb_std_at_estimate[i])
        )
    return out


def _magnitude_cell(magnitude: float | None) -> float | str:
    """The ``magnitude`` column: the size given, or ``"default"``."""
    return "default" if magnitude is None else magnitude


def parse_magnitudes(text: str | None, effects: tuple[str, ...], robot_name: str, seeds: range) -> dict[str, float]:
    """``"gyro_scale=2.6e-3,payload=20"`` -> ``{"gyro_scale": 0.0026, "payload": 20.0}``, for effects of this run
    (units: :data:`spaceid_gym.effects.MAGNITUDE_UNITS`; ``None``: no sizes given), each drawn on every log of
    ``seeds`` (no simulation) so that a size a log cannot have is refused before the suite runs.

    Raises:
        SpaceIdInputError: an empty text, a pair that is not ``name=number``, an effect not among ``effects``
            (or ``none``), an effect given twice, a size that is not a finite number > 0, a size a log of
            ``seeds`` cannot have (a slosh mass above the liquid left in its tank; the message names the seed).
    """
    pairs = [] if text is None else [p.strip() for p in text.split(",") if p.strip()]
    if text is not None and not pairs:
        raise SpaceIdInputError(f"--magnitude: expected effect=size pairs such as 'gyro_scale=2.6e-3', got {text!r}")
    out: dict[str, float] = {}
    for pair in pairs:
        name, sep, value = (part.strip() for part in pair.partition("="))
        if not sep or name == NO_MISSING_EFFECT or name not in effects:
            allowed = ", ".join(e for e in effects if e != NO_MISSING_EFFECT)
            raise SpaceIdInputError(f"--magnitude: expected effect=size for an effect of this run ({allowed}), got {pair!r}")
        if name in out:
            raise SpaceIdInputError(f"--magnitude: effect '{name}' given twice")
        try:
            size = float(value)
        except ValueError:
            size = math.nan
        if not (math.isfinite(size) and size > 0.0):
            raise SpaceIdInputError(f"--magnitude: {name}: expected a finite size > 0, got {value!r}")
        out[name] = size
    _draw_every_log(robot_name, out, seeds)
    return out


def _draw_every_log(robot_name: str, magnitudes: dict[str, float], seeds: range) -> None:
    """Draw every log's effect at its given size; raises :class:`SpaceIdInputError` naming the seed of one it cannot have."""
    robot = load_robot(robot_name)
    for effect, size in magnitudes.items():
        for seed in seeds:
            try:
                draw_case(robot, effect, seed, size)
            except SpaceIdInputError as exc:
                raise SpaceIdInputError(f"--magnitude: {effect}={size:g} on the log of seed {seed}: {exc}") from None


def run_suite(
    robot_name: str = "paper6",
    effects: tuple[str, ...] = SUITE_EFFECTS,
    seeds: int = 20,
    first_seed: int = 0,
    executor: ExecutorSpec | None = None,
    duration_s: float = 60.0,
    magnitudes: dict[str, float] | None = None,
) -> list[dict[str, Any]]:
    """Every effect x ``seeds`` seeds, each log a job on ``executor`` (default: serial); rows in a fixed order
    (effect, seed), bit-identical whatever the executor (a log's seed is ``first_seed`` plus its index).

    ``magnitudes``: sizes replacing some effects' defaults (:func:`parse_magnitudes`); the same seeds draw
    the same directions and fuel states at any size."""
    sizes = magnitudes or {}
    cases = [(robot_name, effect, first_seed + s, duration_s, sizes.get(effect)) for effect in effects for s in range(seeds)]
    return run_jobs(_guarded_case_of, cases, executor or ExecutorSpec("serial"), desc="diagnose suite", unit="log")


def _guarded_case_of(case: tuple[Any, ...]) -> dict[str, Any]:
    """:func:`guarded_case` of one case's arguments (a job of :func:`run_suite`)."""
    return guarded_case(*case)


def code_version() -> str:
    """``git describe --always --dirty`` of the source tree the suite runs from, or ``"unknown"`` outside a git checkout
    (recorded in ``summary.json`` so each figure names the code that measured it)."""
    try:
        done = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    return done.stdout.strip() if done.returncode == 0 and done.stdout.strip() else "unknown"


#: the verdict of a log whose diagnosis raised
ERROR_VERDICT = "error"


def guarded_case(
    robot_name: str, effect: str, seed: int, duration_s: float = 60.0, magnitude: float | None = None
) -> dict[str, Any]:
    """:func:`run_case`, or, if it raises, a row with the verdict ``error`` and the exception and where it was
    raised in ``error`` (the suite goes on; :func:`failed_rows` lists these)."""
    try:
        return run_case(robot_name, effect, seed, duration_s, magnitude)
    except Exception as exc:  # recorded in the row and reported by the command, not hidden
        return {"effect": effect, "magnitude": _magnitude_cell(magnitude), "seed": seed, **error_cells(exc)}


def error_cells(exc: Exception) -> dict[str, Any]:
    """The cells of a log whose diagnosis raised ``exc``: the verdict ``error``, not correct, the exception and where."""
    frame = traceback.extract_tb(exc.__traceback__)[-1]
    where = f"{Path(frame.filename).name}:{frame.lineno} in {frame.name}"
    return {"verdict": ERROR_VERDICT, "correct": False, "error": f"{type(exc).__name__}: {exc} ({where})"}


def failed_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of logs whose diagnosis raised."""
    return [r for r in rows if r["verdict"] == ERROR_VERDICT]


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per hidden effect: logs, correct %, verdict counts, residual RMS / noise after, RMS of the z-scores before and
    after (bound at the truth; ``..._at_estimate``: the estimates' own bounds)."""
    out = []
    for effect, size in dict.fromkeys((r["effect"], r.get("magnitude", "default")) for r in rows):
        every = [r for r in rows if r["effect"] == effect and r.get("magnitude", "default") == size]
        group = [r for r in every if r["verdict"] != ERROR_VERDICT]  # the figures: logs that were diagnosed
        named = [r for r in group if r["correct"]]
        entry: dict[str, Any] = {
            "effect": effect,
            "magnitude": size,
            "logs": len(every),
            "correct_percent": 100.0 * len(named) / len(every),
            "verdicts": dict(Counter(r["verdict"] for r in every).most_common()),
            "rms_over_noise_before_mean": float(np.mean([r["rms_over_noise_before"] for r in group])) if group else math.nan,
            "rms_over_noise_after_mean": float(np.mean([r["rms_over_noise_after"] for r in named])) if named else math.nan,
            "rms_over_noise_after_max": float(np.max([r["rms_over_noise_after"] for r in named])) if named else math.nan,
            "wall_time_s_mean": float(np.mean([r["wall_time_s"] for r in group])) if group else math.nan,
        }
        for name in ("mdf", "bx", "by", "bz"):
            for bound in ("", "_at_estimate"):
                before = np.array([r[f"z_{name}_before{bound}"] for r in group] or [math.nan])
                after = np.array([r[f"z_{name}_after{bound}"] for r in named]) if named else np.array([math.nan])
                entry[f"z_rms_{name}_before{bound}"] = float(np.sqrt(np.mean(before**2)))
                entry[f"z_rms_{name}_after{bound}"] = float(np.sqrt(np.mean(after**2)))
        out.append(entry)
    return out


def _effect_label(entry: dict[str, Any]) -> str:
    """An effect's name in the table, with its size and unit when it is not the default."""
    size = entry.get("magnitude", "default")
    if size == "default":
        return str(entry["effect"])
    unit = MAGNITUDE_UNITS[entry["effect"]]
    return f"{entry['effect']} (magnitude {float(size):g}{' ' + unit if unit else ''})"


def markdown_table(summary: list[dict[str, Any]]) -> str:
    """The summary as a Markdown table."""
    lines = [
        "| hidden effect | logs | verdict correct | verdicts | RMS/noise before | RMS/noise after (mean / max) | "
        "RMS z after: mdf, bx, by, bz | RMS z before: mdf, bx, by, bz | s/log |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in summary:
        verdicts = ", ".join(f"{k} {v}" for k, v in s["verdicts"].items())
        z_after = ", ".join(f"{s[f'z_rms_{n}_after']:.2f}" for n in ("mdf", "bx", "by", "bz"))
        z_before = ", ".join(f"{s[f'z_rms_{n}_before']:.2f}" for n in ("mdf", "bx", "by", "bz"))
        lines.append(
            f"| {_effect_label(s)} | {s['logs']} | {s['correct_percent']:.0f} % | {verdicts} | {s['rms_over_noise_before_mean']:.3f} | "
            f"{s['rms_over_noise_after_mean']:.3f} / {s['rms_over_noise_after_max']:.3f} | {z_after} | {z_before} | "
            f"{s['wall_time_s_mean']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def write_suite(out: str | Path, rows: list[dict[str, Any]], info: dict[str, Any]) -> dict[str, Path]:
    """``suite.csv``, ``summary.json`` and ``table.md`` in ``out``."""
    summary = summarise(rows)
    return write_run(Path(out), ("suite.csv", "table.md"), rows, summary, info, markdown_table(summary))


def write_run(
    out: Path, names: tuple[str, str], rows: list[dict[str, Any]], summary: list[dict[str, Any]], info: dict[str, Any], table: str
) -> dict[str, Path]:
    """Write the rows (CSV, ``names[0]``), ``summary.json`` and the table (``names[1]``) in ``out``; their paths."""
    out.mkdir(parents=True, exist_ok=True)
    return {
        "csv": write_csv_atomic(out / names[0], _csv_rows(rows)),
        "json": write_json_atomic(out / "summary.json", {"info": info, "summary": summary}),
        "table": write_text_atomic(out / names[1], table),
    }


def _csv_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every row with every column (error rows have fewer, and an ``error``; empty where a row has none)."""
    columns = list(dict.fromkeys(key for row in rows for key in row))
    return [{c: row.get(c, "") for c in columns} for row in rows]
