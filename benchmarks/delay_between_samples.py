"""A delayed gyro at a low sample rate: how far the band-limited delay (the phase ramp) misreads the base rate between
samples, what the joints' own samples give instead, and why that reading is held rather than fitted. The figures of
docs/results.md (A named delay refitted with the gyro read between samples) come from here.

Per delay log (``--delay-seeds``, the matrix's draw with ``--rate`` pinned), the other unknowns at the truth:

* the RMS error, over the log's gyro noise, of the noise-free copy's reading at the true delay by the ramp and by the
  model at the joint state read earlier (:func:`~estimators.gyro_between_samples.joint_state_at`);
* the delay fitted by the ramp, and with the correction held at the last delay until it settles (the rounds and tolerance of the diagnosis's refit)
  (:func:`~estimators.gyro_between_samples.between_samples_correction`), on the log as drawn.

Per clean log (``--clean-seeds``): the likelihood gain of the best delay near zero with the ramp, and with the
correction inside the fit (recomputed at every delay), the fake delays that holding it avoids. Usage::

    python benchmarks/delay_between_samples.py --delay-seeds 11302,11465,11299,11476 --clean-seeds 11600-11619
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from estimators.diagnostics.diagnose import candidate_model
from estimators.diagnostics.model_fit import BETWEEN_SAMPLES_ROUNDS, BETWEEN_SAMPLES_TOLERANCE_S
from estimators.diagnostics.workflow import true_parameters
from estimators.gyro_between_samples import DELAY_NAME, between_samples_correction, joint_state_at
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.variations import draw_variation, simulate_variation, truth_of

#: the noise scale of the noise-free copies
NOISE_FREE_SCALE = 1e-6


def _seeds(text: str) -> list[int]:
    """``"1,2,5-7"`` -> ``[1, 2, 5, 6, 7]``."""
    out: list[int] = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        first, _, last = part.partition("-")
        out += list(range(int(first), int(last or first) + 1))
    return out


def _delayed_model(
    effect: str, seed: int, rate_hz: int, noise_scale: float | None
) -> tuple[IdentificationModel, MeasurementLog, FloatArray, float]:
    """The fuel model with a delay, the log of the matrix's draw at ``rate_hz`` (noise scaled to ``noise_scale`` if
    given), the true unknowns (delay 0 on a clean log) and the log's gyro noise std as drawn."""
    case = draw_variation(effect, seed, {"rate_hz": rate_hz})
    drawn = case.noise_scale
    if noise_scale is not None:
        case = dataclasses.replace(case, noise_scale=noise_scale)
    env = simulate_variation(case, 60.0)
    base = IdentificationModel(env.robot, "fuel")
    extended = candidate_model(base, "delay")
    truth = truth_of(env)
    theta_base = true_parameters(base, truth)
    if theta_base is None:
        raise SpaceIdInputError(f"{effect} {seed}: no fuel truth")
    theta = np.append(theta_base, truth["hidden_effects"].get("delay_s", 0.0) if truth.get("hidden_effects") else 0.0)
    noise = env.sensors.gyro_std_rad_s(env.control_period_s) / case.noise_scale * drawn
    return extended, env.measurement_log(), theta, noise


def _fit_delay(cost: Callable[[float], float], centre_s: float, dt_s: float) -> tuple[float, float]:
    """The delay minimising ``cost`` within a sample of ``centre_s`` (a grid of 41, then a bounded search about its
    best), and its cost."""
    grid = centre_s + dt_s * np.linspace(-1.0, 1.0, 41)
    j = int(np.argmin([cost(float(d)) for d in grid]))
    bounds = (float(grid[max(j - 1, 0)]), float(grid[min(j + 1, 40)]))
    best = minimize_scalar(cost, bounds=bounds, method="bounded", options={"xatol": 1e-7})
    return float(best.x), float(best.fun)


def delay_log(seed: int, rate_hz: int) -> str:
    """The delay log's line (see the module docstring)."""
    model, log, theta, noise = _delayed_model("delay", seed, rate_hz, NOISE_FREE_SCALE)
    index = model.parameters.names.index(DELAY_NAME)
    problem = model.problem(log)
    measured = np.asarray(log.omega_base_body_rad_s, dtype=float)
    ramp = problem.predict(theta[None], count=False)[0] - measured
    undelayed = theta.copy()
    undelayed[index] = 0.0
    earlier = model.problem(joint_state_at(log, float(theta[index]))).predict(undelayed[None], count=False)[0] - measured
    errors = [float(np.sqrt(np.mean(x * x))) / noise for x in (ramp, earlier)]
    model, log, theta, noise = _delayed_model("delay", seed, rate_hz, None)
    problem, measured = model.problem(log), np.asarray(log.omega_base_body_rad_s, dtype=float)
    dt = float(log.t_s[1] - log.t_s[0])
    correction = np.zeros_like(measured)

    def cost(delay_s: float) -> float:
        residual = problem.predict(np.r_[theta[:index], delay_s][None], count=False)[0] + correction - measured
        return float(np.sum(residual * residual))

    fitted = [_fit_delay(cost, float(theta[index]), dt)[0]]
    for _ in range(BETWEEN_SAMPLES_ROUNDS):
        correction = between_samples_correction(model, log, np.r_[theta[:index], fitted[-1]])
        fitted.append(_fit_delay(cost, fitted[-1], dt)[0])
        if abs(fitted[-1] - fitted[-2]) < BETWEEN_SAMPLES_TOLERANCE_S:
            break
    return (
        f"delay {seed} ({rate_hz} Hz, true {1e3 * theta[index]:.2f} ms): noise-free error / noise: ramp {errors[0]:.3f}, "
        f"joint state read earlier {errors[1]:.3f}; fitted delay: ramp {1e3 * fitted[0]:.2f} ms, held correction "
        + " -> ".join(f"{1e3 * d:.2f}" for d in fitted[1:])
        + " ms"
    )


def clean_log(seed: int, rate_hz: int) -> str:
    """The clean log's line (see the module docstring)."""
    model, log, theta, noise = _delayed_model("none", seed, rate_hz, None)
    problem, measured = model.problem(log), np.asarray(log.omega_base_body_rad_s, dtype=float)
    dt = float(log.t_s[1] - log.t_s[0])

    def ramp(delay_s: float) -> float:
        residual = problem.predict(np.r_[theta[:-1], delay_s][None], count=False)[0] - measured
        return float(np.sum(residual * residual))

    def inside(delay_s: float) -> float:
        at = np.r_[theta[:-1], delay_s]
        residual = problem.predict(at[None], count=False)[0] + between_samples_correction(model, log, at) - measured
        return float(np.sum(residual * residual))

    at_zero = ramp(0.0)
    fits = [_fit_delay(cost, 0.0, dt) for cost in (ramp, inside)]
    ramp_text, inside_text = (f"{1e3 * d:.2f} ms, gain {(at_zero - value) / noise**2:.1f}" for d, value in fits)
    return f"clean {seed} ({rate_hz} Hz): best delay by the ramp {ramp_text}; with the correction inside the fit {inside_text}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--delay-seeds", default="", help="delay seeds of the matrix, e.g. '11302,11465'")
    parser.add_argument("--clean-seeds", default="", help="clean seeds of the matrix, e.g. '11600-11619'")
    parser.add_argument("--rate", type=int, default=20, help="the sample rate pinned, Hz")
    args = parser.parse_args()
    try:
        delays, cleans = _seeds(args.delay_seeds), _seeds(args.clean_seeds)
    except ValueError:
        parser.error(
            f"--delay-seeds / --clean-seeds: expected integers and ranges, got {args.delay_seeds!r}, {args.clean_seeds!r}"
        )
    for seed in delays:
        print(delay_log(seed, args.rate), flush=True)
    for seed in cleans:
        print(clean_log(seed, args.rate), flush=True)


if __name__ == "__main__":
    main()
