"""Compare an identified model with the measurements: overlay, fit %, residual against the noise floor, where it fails.

:func:`compare` evaluates a model at its parameters over a log and runs the residual analysis
(:func:`~estimators.diagnostics.residuals.analyse_residuals`). :func:`model_from_estimate` rebuilds the
model of an estimate file (its parameterisation and effects) so that ``spaceid compare`` needs only the
robot, the log and the estimate.

The noise floor is the gyro's white-noise level: given (``noise_std_rad_s``), or estimated from the data
alone by differencing the residual (:func:`~estimators.diagnostics.residuals.noise_floor_std`), which
does not need a model that fits.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimators.diagnostics.residuals import ResidualAnalysis, analyse_residuals
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.robots import Robot


@dataclass
class Comparison:
    """A model against one log.

    Attributes:
        label: what was compared (e.g. ``"fuel"`` or ``"fuel+initial_momentum"``).
        t_s: sample times (T,), s; ``measured``/``predicted``: gyro rate (T, 3), rad/s, base body frame.
        names, theta: the model's unknowns and their values (k,).
        physical: the model's physical quantities at ``theta``.
        analysis: the residual analysis (``measured - predicted``).
    """

    label: str
    t_s: FloatArray
    measured: FloatArray
    predicted: FloatArray
    names: tuple[str, ...]
    theta: FloatArray
    physical: dict[str, Any]
    analysis: ResidualAnalysis

    @property
    def residual(self) -> FloatArray:
        """``measured - predicted`` (T, 3), rad/s."""
        return self.measured - self.predicted

    def summary(self) -> str:
        """A few lines for the terminal: fit %, RMS against the noise floor, whiteness, where it fails."""
        a = self.analysis
        lines = [f"model {self.label}:"]
        for row in a.channel_rows():
            lines.append(
                f"  {row['channel']}: fit {row['fit %']:6.2f} %, residual RMS {row['residual RMS']:.3g} rad/s = "
                f"{row['RMS / noise']:.2f} x noise floor, Ljung-Box p {row['Ljung-Box p']:.2g}"
            )
        if a.segments:
            lines.append(f"  where it fails ({len(a.segments)} segment(s), worst first):")
            lines.extend(f"    {s.describe(a.channel_names)}" for s in a.segments[:5])
        else:
            lines.append("  no time segment exceeds the noise")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able (the ``compare --out`` file)."""
        return {
            "model": self.label,
            "parameters": {n: float(v) for n, v in zip(self.names, self.theta, strict=True)},
            "physical": {k: np.asarray(v).tolist() if v is not None else None for k, v in self.physical.items()},
            "residual_analysis": self.analysis.to_dict(),
        }


def compare(
    model: IdentificationModel,
    log: MeasurementLog,
    theta: FloatArray,
    noise_std_rad_s: float | None = None,
    label: str | None = None,
    gyro_correction_rad_s: FloatArray | None = None,
) -> Comparison:
    """Evaluate ``model`` at ``theta`` (k,) over ``log`` and analyse the residual. ``gyro_correction_rad_s`` (T, 3) is
    added to the prediction: what a fit held beyond it (a delayed gyro's reading between samples,
    :attr:`~estimators.diagnostics.model_fit.ModelFit.gyro_correction_rad_s`)."""
    problem = model.problem(log)
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (problem.n_params,):
        raise SpaceIdInputError(
            f"theta: expected {problem.n_params} values ({', '.join(problem.parameters.names)}), got {theta.size}"
        )
    predicted = problem.predict(theta[None], count=False)[0]
    if gyro_correction_rad_s is not None:
        correction = np.asarray(gyro_correction_rad_s, dtype=float)
        if correction.shape != predicted.shape:
            raise SpaceIdInputError(f"gyro_correction_rad_s: expected shape {predicted.shape}, got {correction.shape}")
        predicted = predicted + correction
    measured = np.asarray(log.omega_base_body_rad_s, dtype=float)
    analysis = analyse_residuals(log.t_s, measured, predicted, log.q_rad, log.dq_rad_s, noise_std=noise_std_rad_s)
    return Comparison(
        label or problem.parameters.name,
        np.asarray(log.t_s, dtype=float),
        measured,
        predicted,
        tuple(problem.parameters.names),
        theta,
        problem.parameters.physical(theta),
        analysis,
    )


def model_from_estimate(robot: Robot, estimate: dict[str, Any] | str | Path) -> tuple[IdentificationModel, FloatArray]:
    """The model of an estimate file (parameterisation ``"fuel"``, ``"fuel+initial_momentum"``, ...) and its ``theta``."""
    source = "estimate"
    if not isinstance(estimate, dict):
        source = str(estimate)
        try:
            estimate = json.loads(Path(estimate).read_text())
        except OSError as exc:
            raise SpaceIdInputError(f"{source}: cannot read the estimate file ({exc.strerror})") from None
        except json.JSONDecodeError as exc:
            raise SpaceIdInputError(f"{source}: not a JSON estimate file ({exc.msg} at line {exc.lineno})") from None
    try:
        kind = str(estimate["parameterisation"])
        parameters = estimate["parameters"]
    except (KeyError, TypeError):
        raise SpaceIdInputError(f"{source}: expected an estimate file with 'parameterisation' and 'parameters'") from None
    base, *effects = kind.split("+")
    model = IdentificationModel(robot, base, effects=effects or None)
    names = model.parameters.names
    missing = [n for n in names if n not in parameters]
    if missing:
        raise SpaceIdInputError(f"{source}: parameters {missing} of the model {kind!r} are missing")
    theta = np.array([_value(parameters[n], source, n) for n in names])
    return model, theta


def _value(entry: Any, source: str, name: str) -> float:
    value = entry.get("value") if isinstance(entry, dict) else entry
    if not isinstance(value, int | float) or not np.isfinite(value):
        raise SpaceIdInputError(f"{source}: parameter {name!r} has no finite value ({entry!r})")
    return float(value)
