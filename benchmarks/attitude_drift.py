"""The attitude channel's residual at the truth on one matrix log's motion, noise-free and with noise: how much of it
the model's own prediction makes (the integration rule, the joints' motion between samples) against what the
encoders' noise makes. Prints, per sample rate, the RMS of the residual's steps and the largest axis of their sum
over the log (the accumulated attitude error, rad) with every noise at ``--noise-scales`` times the defaults (0.001:
next to noise-free; the matrix's axis spans 0.3-3). The figures for the `quick3` 20 Hz exact-attitude cell in
docs/results.md (Variation matrix) come from here.

With ``--momentum``, per rate and noise scale also what that residual is worth to a momentum: the likelihood ratio of
an initial momentum at the truth (the base's unknowns held there, the error model fitted to the residual there, the
momentum's best value by generalised least squares; the momentum enters the base rate linearly), as logged and with
the residual of a noise-free copy of the same motion (noise x1e-6) taken out: the share the prediction's own
systematic error (the simulator's integrator, the joints' path between samples) has in it. Usage::

    python benchmarks/attitude_drift.py none 10713 --attitude exact --rates 20,50
    python benchmarks/attitude_drift.py none 20001 --fix robot=quick3 --rates 20
    python benchmarks/attitude_drift.py none 10713 --rates 20,50 --noise-scales 0.3,1,2.14 --momentum
    python benchmarks/attitude_drift.py none 10713 --rates 20 --noise-scales 1e-6,2.14 --momentum --substeps 8

``--substeps`` simulates with that many integration steps per sample (default: the env's, no step longer than
0.02 s: one at 50 and 100 Hz, three at 20 Hz; ``--substeps 1`` is the simulator before that bound); with many, what
is left is the channel's own error, the joints' path between samples.

``--fix`` pins further axes as the matrix's ``--fix`` does (a seed of a run with pinned axes draws its motion with
them pinned).
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any

import numpy as np

from estimators.attitude_channel import AttitudeChannel
from estimators.diagnostics.diagnose import candidate_model
from estimators.diagnostics.workflow import true_parameters
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.sim.simulator import integration_substeps_for
from spaceid_gym.variations import AXIS_VALUES, draw_variation, parse_fixed, simulate_variation, truth_of

#: the noise scale of the noise-free copy whose residual ``--momentum`` takes out
NOISE_FREE_SCALE = 1e-6


def truth_residual(
    effect: str, seed: int, fixed: dict[str, Any], noise_scale: float, seconds: float, substeps: int | None = None
) -> tuple[IdentificationModel, MeasurementLog, FloatArray, FloatArray]:
    """The model, log, true unknowns and the attitude residual's steps (T-1, 3), rad, at the truth of the motion of the
    case drawn with the axes ``fixed``, measured with every noise at ``noise_scale`` times the defaults, simulated with
    ``substeps`` integration steps per sample."""
    case = dataclasses.replace(draw_variation(effect, seed, fixed), noise_scale=noise_scale)
    env = simulate_variation(case, seconds, integration_substeps=substeps)
    model, log = IdentificationModel(env.robot, "fuel"), env.measurement_log()
    theta = true_parameters(model, truth_of(env))
    channel = AttitudeChannel.of(model, log, None, theta)
    if theta is None or channel is None:
        raise SpaceIdInputError(f"{effect} {seed}: the case has no fuel truth or no attitude ({fixed})")
    return model, log, theta, channel.differences(theta)


def momentum_ratio(model: IdentificationModel, log: MeasurementLog, theta: FloatArray, removed: FloatArray | None) -> float:
    """The likelihood ratio of an initial momentum on the attitude channel at the truth ``theta`` (the base's unknowns
    held there; the error model fitted to the residual there as logged, so that with the steps ``removed`` (T-1, 3)
    taken out of the residual the error model still holds what its wander absorbed of them)."""
    extended = candidate_model(model, "initial_momentum")
    at_truth = np.concatenate((theta, np.zeros(extended.parameters.n_params - len(theta))))
    channel = AttitudeChannel.of(extended, log, None, theta)
    assert channel is not None
    noise = channel.estimate_noise(at_truth)
    steps = channel.differences(at_truth)
    residual = channel.whitened_steps(steps if removed is None else steps - removed, noise)
    jacobian = channel.whitened_steps(channel.difference_jacobian(at_truth)[:, :, len(theta) :], noise)
    explained = jacobian @ np.linalg.lstsq(jacobian, residual, rcond=None)[0]
    return float(explained @ explained)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("effect", help="the matrix row's hidden effect (none: a clean log)")
    parser.add_argument("seed", type=int, help="the matrix row's seed (its motion and axes)")
    parser.add_argument("--attitude", default="exact", choices=[a for a in AXIS_VALUES["attitude"] if a != "none"])
    parser.add_argument("--rates", default="20,50", help="sample rates, Hz, comma-separated")
    parser.add_argument("--noise-scales", default="0.001,1.0", help="noise scales, comma-separated")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fix", default=None, help="pin further axes, e.g. 'robot=quick3'")
    parser.add_argument("--momentum", action="store_true", help="also a momentum's likelihood ratio at the truth")
    parser.add_argument(
        "--substeps", type=int, default=None, help="the simulator's integration steps per sample (default: the env's)"
    )
    args = parser.parse_args()
    try:
        fixed = parse_fixed(args.fix)
    except SpaceIdInputError as error:
        parser.error(str(error))
    if args.substeps is not None and args.substeps < 1:
        parser.error(f"--substeps: expected an integer >= 1, got {args.substeps}")
    try:
        rates = [int(r) for r in args.rates.split(",")]
        scales = [float(x) for x in args.noise_scales.split(",")]
    except ValueError:
        parser.error(f"--rates / --noise-scales: expected comma-separated numbers, got {args.rates!r}, {args.noise_scales!r}")
    if any(r not in AXIS_VALUES["rate_hz"] for r in rates) or any(x <= 0.0 for x in scales):
        parser.error(f"--rates: each one of {AXIS_VALUES['rate_hz']}; --noise-scales: each positive")
    for rate in rates:
        axes = {**fixed, "rate_hz": rate, "attitude": args.attitude}
        noise_free = (
            truth_residual(args.effect, args.seed, axes, NOISE_FREE_SCALE, args.seconds, args.substeps)[3]
            if args.momentum
            else None
        )
        cells = []
        for scale in scales:
            model, log, theta, steps = truth_residual(args.effect, args.seed, axes, scale, args.seconds, args.substeps)
            cell = f"noise x{scale:g}: step RMS {np.sqrt(np.mean(steps**2)):.2e} rad, summed {np.abs(steps.sum(axis=0)).max():.2e} rad"
            if noise_free is not None:
                logged, without = (momentum_ratio(model, log, theta, removed) for removed in (None, noise_free))
                cell += f", momentum LR at the truth {logged:.1f} ({without:.1f} without the noise-free residual)"
            cells.append(cell)
        steps_a_sample = args.substeps or integration_substeps_for(1.0 / rate)
        head = f"{args.effect} {args.seed}, {rate} Hz, {args.attitude}, {steps_a_sample} integration step(s) a sample"
        print(f"{head}: " + "; ".join(cells), flush=True)


if __name__ == "__main__":
    main()
