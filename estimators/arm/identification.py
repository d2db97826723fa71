"""Identify a fixed-base arm from some movements, validate on others: the UR5 workflow end to end.

Data -> :func:`load_movements` (real UR5 movement folders, or simulated dataset folders) -> :meth:`Preparation.rows`
(uniform time, zero-phase low-pass of the states, acceleration by differentiation, the model's regressor filtered
with the effort's filter, decimation) -> :func:`fit` (an :class:`~estimators.arm.model.ArmIdentificationModel`
problem on the training movements, any registered estimator) -> :func:`prediction_error` on the validation movements
-> :func:`leave_one_out` tables.

Figures (the source's, per joint ``j`` of a held-out movement, over its samples):

* relative error ``100 ||tau_j - tau_pred_j|| / ||tau_j||`` (%), in the log's unit (torque or current: the ratio
  does not depend on the unit); the overall figure is the same over all joints at once;
* with a known noise floor (simulated data: the processed noise std, :meth:`Preparation.noise_gain`), the residual
  RMS in noise units: 1 is the floor.

Weights: least squares (``ols``, ``wls``) weigh as they are defined; every other estimator gets the source's
fitness ``sum_j k_j sum_t (tau - tau_pred)^2`` with ``k_j = 1 / s_j^2``, ``s_j`` each joint's noise std from an OLS
fit (Gautier's two-step weights, the same as WLS), so a 150 N m joint does not drown a 28 N m one.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from estimators.arm.gains import identify_gains, scaled_rows
from estimators.arm.linear_ls import group_weighted
from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from estimators.arm.presliding_choice import choose_for_rows, presliding_for_movements, with_presliding
from estimators.base import Estimator
from estimators.estimate import Estimate
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.real_logs import list_movements, load_ur5_movement
from spaceid_gym.arm.signal import lowpass_zero_phase, parallel_decimation, uniform_period
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.executors import ExecutorSpec, run_jobs

#: estimators that weigh the rows themselves (everything else gets the per-joint weights of the module docstring)
SELF_WEIGHTING = ("ols", "wls")


@dataclass(frozen=True)
class Preparation:
    """The signal chain of :func:`~spaceid_gym.arm.signal.prepare_for_identification` with its settings.

    Attributes:
        cutoff_hz: zero-phase Butterworth low-pass cutoff, Hz (default 4: the UR5 movements' joint motion lies
            below 2 Hz, the current's PWM and sensor noise above).
        decimate_factor: keep every k-th sample after filtering (default 5: 125 Hz -> 25 Hz).
        order: Butterworth order of one pass (default 4).
    """

    cutoff_hz: float = 4.0
    decimate_factor: int = 5
    order: int = 4

    def rows(self, model: ArmIdentificationModel, log: ArmLog) -> IdentificationRows:
        """The movement's identification rows for ``model``: :func:`~spaceid_gym.arm.signal.parallel_decimation` of the
        raw ``log`` with the model's base regressor."""

        def regressor(q: FloatArray, dq: FloatArray, ddq: FloatArray) -> FloatArray:
            return model.base_regressor(q, dq, ddq, log.effort_kind)

        prepared, Y = parallel_decimation(log, regressor, self.cutoff_hz, self.decimate_factor, self.order)
        return IdentificationRows(prepared, Y)

    def all_rows(self, model: ArmIdentificationModel, logs: Mapping[str, ArmLog]) -> dict[str, IdentificationRows]:
        """:meth:`rows` of every movement, by name."""
        return {name: self.rows(model, log) for name, log in logs.items()}

    def noise_gain(self, dt_s: float) -> float:
        """Std of white noise after the filter over its std before, for samples every ``dt_s`` s:
        ``sqrt(sum_k h_k^2)`` of the zero-phase filter's impulse response ``h`` (decimation keeps the variance)."""
        n = max(4096, int(40.0 / (self.cutoff_hz * dt_s)))
        impulse = np.zeros((n, 1))
        impulse[n // 2] = 1.0
        response = lowpass_zero_phase(impulse, dt_s, self.cutoff_hz, self.order)
        return float(np.sqrt(np.sum(response**2)))

    def correlation_factor(self, dt_s: float) -> float:
        """``kappa``: how many prepared samples carry the information of one independent sample, for a slowly varying
        regressor, with the raw samples every ``dt_s`` s: ``(1 / decimate_factor) / noise_gain^2``.

        The filtered noise keeps the raw noise's spectral density in the pass band; white noise at the decimated rate
        with that density would have ``kappa`` times the filtered variance. A chi-square of prepared rows weighted with
        the filtered noise std is therefore ``kappa`` times too large for a test about low-frequency columns
        (about 3.5 for 125 Hz, 4 Hz and 5).
        """
        return (1.0 / self.decimate_factor) / self.noise_gain(dt_s) ** 2

    def as_dict(self) -> dict[str, Any]:
        """The settings, for the output files."""
        return {"cutoff_hz": self.cutoff_hz, "decimate_factor": self.decimate_factor, "order": self.order}


# ---------------------------------------------------------------------- data
def _dataset_folders(data: Path) -> dict[str, Path]:
    """Movement name -> folder under ``data``: real UR5 movement folders, or simulated datasets (``log.csv``)."""
    if (data / "log.csv").is_file():
        return {data.name: data}
    real = list_movements(data)
    simulated = sorted(p.name for p in data.iterdir() if p.is_dir() and (p / "log.csv").is_file())
    return {name: data / name for name in [*real, *simulated]}


def load_movements(data: str | Path, names: Sequence[str] | None = None, effort: str = "i_actual") -> dict[str, ArmLog]:
    """Raw logs by movement name from ``data``: a folder of real UR5 movements (``<name>/q_actual.csv`` ...), a folder
    of simulated datasets (``<name>/log.csv``), or one simulated dataset folder.

    Args:
        data: the folder.
        names: movements to load, in that order (default all, sorted).
        effort: for real movements, which effort file (``i_actual`` measured current, default).

    Raises:
        SpaceIdInputError: no such folder, no movement in it, or an unknown name (listing the available ones).
    """
    data = Path(data)
    if not data.is_dir():
        raise SpaceIdInputError(f"--data {data}: no such folder")
    folders = _dataset_folders(data)
    if not folders:
        raise SpaceIdInputError(f"--data {data}: no movement folders (with q_actual.csv or log.csv) in it")
    wanted = list(folders) if names is None else list(names)
    unknown = [n for n in wanted if n not in folders]
    if unknown:
        raise SpaceIdInputError(f"--data {data}: no movement {unknown}; available: {', '.join(folders)}")
    logs = {}
    for name in wanted:
        folder = folders[name]
        if (folder / "log.csv").is_file():
            logs[name] = ArmLog.from_csv(folder / "log.csv", name=name)
        else:
            logs[name] = load_ur5_movement(folder, effort)[0]
    return logs


def simulated_noise_std(data: str | Path, name: str) -> FloatArray | None:
    """The raw effort noise std per joint (n,) of a simulated dataset (its ``truth.json``), or ``None`` for real data."""
    folder = _dataset_folders(Path(data)).get(name)
    path = None if folder is None else folder / "truth.json"
    if path is None or not path.is_file():
        return None
    try:
        noise = json.loads(path.read_text())["noise"]
    except (json.JSONDecodeError, KeyError) as exc:
        raise SpaceIdInputError(f"{path}: expected a truth file with a 'noise' entry ({exc})") from None
    key = "torque_std_Nm" if noise["effort_kind"] == "torque_Nm" else "current_std_A"
    return np.asarray(noise[key], dtype=float)


# ---------------------------------------------------------------------- fitting
def joint_weighted(problem: LinearIdentificationProblem) -> LinearIdentificationProblem:
    """``problem`` with each row weighted by its joint's noise std from an OLS fit (module docstring)."""
    return group_weighted(problem)


def fit(model: ArmIdentificationModel, train: Mapping[str, IdentificationRows], estimator: Estimator) -> Estimate:
    """Fit ``estimator`` to the training movements' rows; the estimate's ``theta`` are the base parameters (``model.base.names``)."""
    problem = model.problem(train)
    if getattr(estimator, "name", "") not in SELF_WEIGHTING:
        problem = joint_weighted(problem)
    estimate = estimator.fit_problem(problem)
    estimate.extra["training_movements"] = list(train)
    return estimate


# ---------------------------------------------------------------------- validation
@dataclass
class PredictionError:
    """Prediction error of one model on one prepared movement (held out, or in the fit).

    Attributes:
        movement: its name.
        relative_percent: (n,) ``100 ||e_j|| / ||tau_j||`` per joint.
        overall_percent: the same over all joints.
        rms: (n,) residual RMS per joint (the log's unit).
        noise_floor: (n,) the processed noise std per joint when known (simulated data), else ``None``.
        residual: (T, n) measured - predicted.
    """

    movement: str
    relative_percent: FloatArray
    overall_percent: float
    rms: FloatArray
    noise_floor: FloatArray | None = None
    residual: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)

    @property
    def noise_ratio(self) -> FloatArray | None:
        """(n,) residual RMS over the noise floor per joint (1 is the floor), or ``None``."""
        return None if self.noise_floor is None else self.rms / self.noise_floor

    @property
    def overall_noise_ratio(self) -> float | None:
        """``sqrt(mean_j ratio_j^2)``: the residual in noise units over all joints, or ``None``."""
        ratio = self.noise_ratio
        return None if ratio is None else float(np.sqrt(np.mean(ratio**2)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures (without the residual series)."""
        ratio = self.noise_ratio
        return {
            "movement": self.movement,
            "relative_percent": self.relative_percent.tolist(),
            "overall_percent": self.overall_percent,
            "rms": self.rms.tolist(),
            "noise_floor": None if self.noise_floor is None else self.noise_floor.tolist(),
            "noise_ratio": None if ratio is None else ratio.tolist(),
            "overall_noise_ratio": self.overall_noise_ratio,
        }


def prediction_error(
    model: ArmIdentificationModel, beta: FloatArray, rows: IdentificationRows, noise_floor: FloatArray | None = None
) -> PredictionError:
    """The figures of base parameters ``beta`` (r,) on one movement's rows (module docstring)."""
    return error_of_prediction(rows.log, model.predict(beta, rows), noise_floor)


def error_of_prediction(log: ArmLog, predicted: FloatArray, noise_floor: FloatArray | None = None) -> PredictionError:
    """The figures (module docstring) of any prediction (T, n) of a prepared log's effort, whatever model made it."""
    residual = log.effort - predicted
    relative = 100.0 * np.linalg.norm(residual, axis=0) / np.maximum(np.linalg.norm(log.effort, axis=0), 1e-300)
    overall = 100.0 * float(np.linalg.norm(residual) / max(np.linalg.norm(log.effort), 1e-300))
    rms = np.sqrt(np.mean(residual**2, axis=0))
    return PredictionError(log.name, relative, overall, rms, noise_floor, residual)


def raw_period(raw_log: ArmLog) -> float:
    """The raw log's sample period (s): its uniform step, or its median step when it jitters (what the chain resamples to)."""
    try:
        return uniform_period(raw_log)
    except SpaceIdInputError:
        return float(np.median(np.diff(raw_log.t_s)))


def processed_noise_floor(preparation: Preparation, raw_std: FloatArray | None, raw_log: ArmLog) -> FloatArray | None:
    """The noise std per joint (n,) of the prepared log when the raw effort noise ``raw_std`` (n,) is known, else ``None``."""
    if raw_std is None:
        return None
    return np.asarray(raw_std, dtype=float) * preparation.noise_gain(raw_period(raw_log))


# ---------------------------------------------------------------------- leave one movement out
@dataclass
class CrossValidationRow:
    """One held-out movement, one estimator, one model: the estimate's facts and its :class:`PredictionError`.

    ``cost_excess_over_sdp``: a consistent colony's training cost over the ``sdp`` optimum of the same cost, relative
    (``extra["cost_excess_over_sdp"]``), else ``None``. ``torque_constants_Nm_A``: the gains identified on the training
    movements (``gain_reference`` of :func:`leave_one_out`), else ``None``. ``presliding_rad``: per joint the presliding
    length chosen on the training movements (``None`` for a joint that keeps the smooth sign), with ``presliding``.
    """

    model: str
    estimator: str
    error: PredictionError
    consistent: bool | None
    wall_time_s: float
    n_evaluations: float
    cost_excess_over_sdp: float | None = None
    torque_constants_Nm_A: list[float] | None = None
    presliding_rad: list[float | None] | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "model": self.model,
            "estimator": self.estimator,
            "physically_consistent": self.consistent,
            "wall_time_s": self.wall_time_s,
            "n_evaluations": self.n_evaluations,
            "cost_excess_over_sdp": self.cost_excess_over_sdp,
            "torque_constants_Nm_A": self.torque_constants_Nm_A,
            "presliding_rad": self.presliding_rad,
            **self.error.to_dict(),
        }


def physically_consistent(estimate: Estimate) -> bool | None:
    """Whether every link is physically consistent and friction non-negative, if the estimate says (full parameters)."""
    links = estimate.physical.get("links_physically_consistent")
    if links is None:
        return None
    return bool(all(links) and estimate.physical.get("friction_non_negative", True))


def leave_one_out(
    models: Mapping[str, ArmIdentificationModel],
    logs: Mapping[str, ArmLog],
    estimators: Mapping[str, Estimator],
    preparation: Preparation,
    noise_floors: Mapping[str, FloatArray | None] | None = None,
    executor: ExecutorSpec | None = None,
    gain_reference: str | None = None,
    presliding: Sequence[str] = (),
) -> list[CrossValidationRow]:
    """For every movement, model and estimator: fit on the other movements, error on the held-out one.

    Each held-out movement is a job on ``executor`` (default: serial); the rows come in the movements' order and are
    the same whatever the executor (the estimators carry their seeds), bar the fits' wall times.

    Args:
        models: label -> model (e.g. ``{"with friction": ..., "without friction": ...}``).
        logs: raw logs by movement (at least two).
        estimators: label -> estimator (e.g. ``{"ols": ..., "improved-abc (consistent)": ...}``).
        preparation: the signal chain.
        noise_floors: movement -> processed noise std (n,) when known.
        executor: where the folds run (:mod:`spaceid_gym.executors`).
        gain_reference: identify the torque constants on each fold's training movements with this reference
            (:func:`estimators.arm.gains.identify_gains`), then fit with them; ``None``: the model's constants.
        presliding: labels of ``models`` given presliding friction: each fold chooses per joint a presliding length
            or the smooth sign on its training movements (:mod:`estimators.arm.presliding_choice`).
    """
    if len(logs) < 2:
        raise SpaceIdInputError(f"leave-one-out: needs at least two movements, got {list(logs)}")
    unknown = [label for label in presliding if label not in models]
    if unknown:
        raise SpaceIdInputError(f"leave-one-out: presliding for unknown model(s) {unknown}; models {list(models)}")
    if presliding and gain_reference is not None:
        raise SpaceIdInputError("--presliding and --identify-gains: not available together (the gains rescale the rows)")
    model_rows = {label: preparation.all_rows(model, logs) for label, model in models.items()}
    dahl = {label: presliding_for_movements(models[label], logs, preparation) for label in presliding}
    floors = noise_floors or {}
    folds = [_Fold(held, dict(models), model_rows, dict(estimators), floors.get(held), gain_reference, dahl) for held in logs]
    results = run_jobs(_run_fold, folds, executor or ExecutorSpec("serial"), desc="cross-validate", unit="fold")
    return [row for rows in results for row in rows]


@dataclass(frozen=True)
class _Fold:
    """One held-out movement of :func:`leave_one_out`: every model's processed rows and every estimator."""

    held: str
    models: dict[str, ArmIdentificationModel]
    model_rows: dict[str, dict[str, IdentificationRows]]
    estimators: dict[str, Estimator]
    noise_floor: FloatArray | None
    gain_reference: str | None = None
    presliding: dict[str, dict[str, FloatArray]] = field(default_factory=dict)


def _run_fold(fold: _Fold) -> list[CrossValidationRow]:
    """Fit every model and estimator on the movements but ``fold.held``; the held-out errors (a job of :func:`leave_one_out`)."""
    rows = []
    for model_label, model in fold.models.items():
        movements = fold.model_rows[model_label]
        train = {name: item for name, item in movements.items() if name != fold.held}
        held, gains, lengths = movements[fold.held], None, None
        if model_label in fold.presliding:
            columns = fold.presliding[model_label]
            choice = choose_for_rows(model, train, columns)
            train = {name: with_presliding(model, item, columns[name], choice) for name, item in train.items()}
            held, lengths = with_presliding(model, held, columns[fold.held], choice), choice.lengths_rad
        if fold.gain_reference is not None:
            found = identify_gains(model, train, fold.gain_reference)
            train, held = scaled_rows(train, found.correction), scaled_rows({fold.held: held}, found.correction)[fold.held]
            gains = found.torque_constants_Nm_A.tolist()
        for label, estimator in fold.estimators.items():
            estimate = fit(model, train, estimator)
            error = prediction_error(model, estimate.theta, held, fold.noise_floor)
            rows.append(
                CrossValidationRow(
                    model_label,
                    label,
                    error,
                    physically_consistent(estimate),
                    estimate.wall_time_s,
                    estimate.n_evaluations,
                    estimate.extra.get("cost_excess_over_sdp"),
                    gains,
                    lengths,
                )
            )
    return rows


def cross_validation_markdown(rows: Sequence[CrossValidationRow], joint_names: Sequence[str]) -> str:
    """The leave-one-movement-out table: one line per model, estimator and held-out movement, per-joint relative error
    (%), the overall figure, consistency, the training cost over the ``sdp`` optimum (%, consistent colonies) and the
    time of the fit (s), then per model and estimator the mean over the movements (the largest cost excess)."""
    header = (
        f"| model | estimator | held-out movement | {' | '.join(joint_names)} | overall % | consistent | "
        "cost over sdp % | fit s |\n"
        f"|---|---|---|{'---:|' * len(joint_names)}---:|---|---:|---:|\n"
    )
    lines = []
    for (model, estimator), members in _grouped(rows).items():
        for row in members:
            cells = " | ".join(f"{v:.1f}" for v in row.error.relative_percent)
            lines.append(
                f"| {model} | {estimator} | {row.error.movement} | {cells} | {row.error.overall_percent:.1f} | "
                f"{_yes_no(row.consistent)} | {_percent(row.cost_excess_over_sdp)} | {row.wall_time_s:.2f} |"
            )
        mean = np.mean([r.error.relative_percent for r in members], axis=0)
        overall = float(np.mean([r.error.overall_percent for r in members]))
        consistent = [r.consistent for r in members]
        summary = _yes_no(None if None in consistent else all(c for c in consistent if c is not None))
        time_s = float(np.mean([r.wall_time_s for r in members]))
        lines.append(
            f"| **{model}** | **{estimator}** | **mean of {len(members)}** | {' | '.join(f'**{v:.1f}**' for v in mean)} | "
            f"**{overall:.1f}** | {summary} | {_percent(_largest_excess(members), ' (largest)')} | {time_s:.2f} |"
        )
    return header + "\n".join(lines) + "\n"


def _largest_excess(rows: Sequence[CrossValidationRow]) -> float | None:
    """The largest ``cost_excess_over_sdp`` of the rows, or ``None`` if any lacks one."""
    excess = [r.cost_excess_over_sdp for r in rows]
    return None if not excess or any(e is None for e in excess) else max(e for e in excess if e is not None)


def _percent(value: float | None, suffix: str = "") -> str:
    return "" if value is None else f"{100.0 * value:+.4f}{suffix}"


def _grouped(rows: Sequence[CrossValidationRow]) -> dict[tuple[str, str], list[CrossValidationRow]]:
    """The rows by (model, estimator), in order of first appearance."""
    groups: dict[tuple[str, str], list[CrossValidationRow]] = {}
    for row in rows:
        groups.setdefault((row.model, row.estimator), []).append(row)
    return groups


def _yes_no(value: bool | None) -> str:
    return "n/a" if value is None else ("yes" if value else "**no**")


def summary_table(rows: Sequence[CrossValidationRow]) -> list[dict[str, Any]]:
    """Per model and estimator: mean per-joint and overall relative error (%) over the held-out movements."""
    return [
        {
            "model": model,
            "estimator": estimator,
            "mean_relative_percent": np.mean([r.error.relative_percent for r in members], axis=0).tolist(),
            "mean_overall_percent": float(np.mean([r.error.overall_percent for r in members])),
            "all_consistent": None if any(r.consistent is None for r in members) else all(bool(r.consistent) for r in members),
            "n_movements": len(members),
            "mean_wall_time_s": float(np.mean([r.wall_time_s for r in members])),
            "max_cost_excess_over_sdp": _largest_excess(members),
        }
        for (model, estimator), members in _grouped(rows).items()
    ]
