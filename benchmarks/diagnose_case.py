"""One log of the variation matrix diagnosed, with what explains its verdict: the figures quoted for single held-out
logs in docs/results.md (Variation matrix).

Prints the log's axes, the verdict and its reason, per candidate the likelihood ratio split into the gyro's and
the attitude channel's gains, the tested one (the attitude error model held at the baseline's) with its p-value and
any reason it was judged implausible, and the fuel unknowns' errors (and z, in
Cramér-Rao std at the truth) of the gyro-alone fit, of the model as given fitted by the diagnosis and of the named
effect's fit. With ``--delay-at-truth`` (a ``delay`` log):
the delay that fits best with every other unknown at the truth, and the residual at the true delay over the noise, at
the log's own rate and at 50 and 100 Hz (the same draw, the rate changed). With ``--held-noise`` (a log with attitude):
each candidate's attitude gain again, its fit refined with the attitude error model held at the baseline's instead of
refitted (profiled) at the candidate. With ``--noise-seed``: the same motion measured with new noise. With
``--from-truth``: for the model of the hidden effect that made the log (the pendulum or the spring-mass), the
diagnosis's fit (when it kept that model) against the refit from the true values (the diagnosis's weights, the
attitude's error model profiled; on the gyro alone where the diagnosis set the attitude aside), their effect
unknowns, the fuel consumed's error and the attitude residual's whiteness p. ``--fix`` pins further axes, as the
suite's (``--fix slosh_model=pendulum``).

    python benchmarks/diagnose_case.py none 9737
    python benchmarks/diagnose_case.py delay 9759 --delay-at-truth
    python benchmarks/diagnose_case.py none 9821 --rate 50
    python benchmarks/diagnose_case.py none 9821 --held-noise
    python benchmarks/diagnose_case.py none 10229 --attitude exact
    python benchmarks/diagnose_case.py none 10238 --attitude exact --noise-seed 1
    python benchmarks/diagnose_case.py initial_momentum 10834 --substeps 8
    python benchmarks/diagnose_case.py slosh 11082 --from-truth
    python benchmarks/diagnose_case.py slosh 11987 --fix slosh_model=pendulum

``--substeps`` simulates with that many integration steps per sample (default: the env's, no step longer than 0.02 s:
one at 50 and 100 Hz, three at 20 Hz; ``--substeps 1`` is the simulator before that bound).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from estimators.attitude_channel import AttitudeChannel
from estimators.diagnostics.diagnose import Diagnosis, candidate_model, diagnose, fit_model, simulated_variant
from estimators.diagnostics.model_fit import ModelFit, gyro_log, joint_objective
from estimators.diagnostics.workflow import ParameterErrors, apply_effect, baseline_estimate, parameter_errors, true_parameters
from estimators.problem import IdentificationModel
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.variations import draw_variation, parse_fixed, simulate_variation, truth_of


def delay_at_truth(seed: int, fixed: dict[str, Any], duration_s: float) -> str:
    """The best delay (others at the truth) and the residual RMS at the true delay over the gyro's noise, of the case
    drawn with the axes ``fixed``."""
    case = draw_variation("delay", seed, fixed or None)
    env = simulate_variation(case, duration_s)
    extended = candidate_model(IdentificationModel(env.robot, "fuel"), "delay")
    theta = true_parameters(extended, truth_of(env))
    assert theta is not None
    problem = extended.problem(env.measurement_log())
    noise = env.sensors.gyro_std_rad_s(env.control_period_s)

    def rms(delay_s: float) -> float:
        residual = problem.residuals(np.r_[theta[:-1], delay_s], count=False)
        return float(np.sqrt(np.mean(residual * residual)))

    best = minimize_scalar(rms, bounds=(0.0, 2.0 * theta[-1]), method="bounded", options={"xatol": 1e-6})
    return (
        f"{case.rate_hz:>3} Hz: true delay {1e3 * theta[-1]:.2f} ms, best {1e3 * best.x:.2f} ms; "
        f"RMS / noise at the true delay {rms(theta[-1]) / noise:.2f}, at the best {best.fun / noise:.2f}"
    )


def held_noise_gains(model: IdentificationModel, log: MeasurementLog, d: Diagnosis) -> list[str]:
    """Per candidate, the attitude gain of its fit refined with the error model held at the baseline's (no profile)."""
    weights = d.weights
    if weights is None:
        return ["no attitude channel"]
    base_channel = AttitudeChannel.of(model, log, weights.coupling, weights.reference)
    assert base_channel is not None
    base = base_channel.chi2(d.baseline.theta, weights.attitude)
    lines = [f"  the baseline's error model: {weights.attitude}"]
    for c in sorted(d.candidates, key=lambda f: -f.lr_statistic):
        extended = candidate_model(model, c.spec)
        channel = AttitudeChannel.of(extended, log, weights.coupling, weights.reference)
        problem = extended.problem(gyro_log(log, c))  # the reading the fit was made with
        held = fit_model(extended, log, starts=[c.theta], effect=c.effect, weights=weights, channel=channel, problem=problem)[0]
        assert channel is not None
        profiled = (d.baseline.attitude_chi2 or 0.0) - (c.attitude_chi2 or 0.0)
        lines.append(
            f"  {c.effect:17s} attitude gain held {base - channel.chi2(held.theta, weights.attitude):8.1f}  "
            f"profiled {profiled:8.1f}  (its error model: {c.attitude_noise})"
        )
    return lines


def refit_from_truth(
    model: IdentificationModel, log: MeasurementLog, d: Diagnosis, truth: dict[str, Any], effect: str
) -> list[str]:
    """The model of ``effect`` that made the log (:func:`simulated_variant`, e.g. the pendulum): the diagnosis's fit of
    it (when that variant was the one kept) and its refit from the true values (the diagnosis's weights: both channels,
    the attitude error model profiled, or the gyro alone where the diagnosis set the attitude aside), their effect
    unknowns, the gyro residual's RMS over the simulated gyro noise, the fuel consumed's error (kg), the attitude residual's whiteness
    p and, with attitude, the chi-square
    the fits are ranked by (:func:`~estimators.diagnostics.model_fit.joint_objective`)."""
    spec = simulated_variant(model.robot, effect, truth.get("hidden_effects") or {})
    extended = None if spec is None else candidate_model(model, spec)
    theta = None if extended is None else true_parameters(extended, truth)
    if spec is None or extended is None or theta is None:
        return [f"  no true values of {effect} for the fuel model"]
    problem = extended.problem(log)
    noise = float(truth["noise"]["gyro_std_rad_s"])  # the simulated gyro's, per sample (as the matrix's figures)
    refit = fit_model(extended, log, starts=[theta], effect=effect, weights=d.weights, problem=problem, profile_noise=True)[0]
    kept = next((c for c in d.candidates if c.effect == effect), None)
    k = len(model.parameters.nominal)  # the model's own unknowns come first
    fits: list[tuple[str, ModelFit | None]] = [("truth", None)]
    if kept is not None and kept.spec == spec:
        fits.append(("diagnosis", kept))
    lines = [] if len(fits) > 1 else [f"  the diagnosis kept {kept.spec if kept else 'no fit'} of {effect}, not {spec}"]
    if d.attitude_rejected:
        lines.append("  the attitude was set aside: the refit is on the gyro alone")
    for label, fit in [*fits, ("from truth", refit)]:
        values = theta if fit is None else fit.theta
        gyro = problem.residuals(values, count=False)
        tail = f"  gyro residual {math.sqrt(float(np.mean(gyro * gyro))) / noise:.3f} x noise"
        if fit is not None:
            tail += f"  fuel {values[0] - theta[0]:+.3g} kg  whiteness p {fit.attitude_white_p:.2g}"
        if fit is not None and d.weights is not None:
            tail += f"  chi-square {joint_objective(fit, d.weights):.1f}"
        lines.append(f"  {spec:22s} {label:10s} {np.array2string(values[k:], precision=4)}{tail}")
    return lines


def _errors_text(label: str, errors: ParameterErrors | None) -> str:
    if errors is None:
        return f"{label}: no fuel unknowns"
    pairs = ", ".join(f"{n} {e:+.4g} (z {z:+.2f})" for n, e, z in zip(errors.names, errors.error, errors.z, strict=True))
    return f"{label}: {pairs}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("effect", help="the hidden effect of the matrix row (none: a clean log)")
    parser.add_argument("seed", type=int)
    parser.add_argument("--seconds", type=float, default=60.0, help="the log's length (the matrix's: 60 s)")
    parser.add_argument("--delay-at-truth", action="store_true", help="a delay log: the delay that fits best at the truth")
    parser.add_argument("--rate", type=int, default=None, help="the sample rate pinned (Hz; the draw's otherwise)")
    parser.add_argument("--attitude", default=None, help="the attitude source pinned (as the suite's --fix attitude=...)")
    parser.add_argument("--held-noise", action="store_true", help="attitude gains with the baseline's error model held")
    parser.add_argument("--from-truth", action="store_true", help="the hidden effect's fit against its refit from the truth")
    parser.add_argument("--fix", default=None, help="further axes pinned, as the suite's --fix (e.g. slosh_model=pendulum)")
    parser.add_argument(
        "--noise-seed", type=int, default=None, help="the same motion measured with new noise (the env's noise_seed)"
    )
    parser.add_argument(
        "--substeps", type=int, default=None, help="the simulator's integration steps per sample (default: the env's)"
    )
    args = parser.parse_args()
    try:
        fixed = parse_fixed(args.fix)
    except SpaceIdInputError as exc:
        parser.error(f"--fix: {exc}")
    for axis, value in (("rate_hz", args.rate), ("attitude", args.attitude)):
        if value is not None and axis in fixed:
            parser.error(f"--fix: {axis} given there and by its own option; give it once")
        if value is not None:
            fixed[axis] = value
    if args.from_truth and args.effect == "none":
        parser.error("--from-truth: a clean log has no hidden effect to refit")
    case = draw_variation(args.effect, args.seed, fixed or None)
    redrawn = "" if args.noise_seed is None else f", noise seed {args.noise_seed}"
    print(f"{args.effect} {args.seed}: {case.robot}, {case.rate_hz} Hz, {case.attitude}, noise x{case.noise_scale:.2f}{redrawn}")
    if args.substeps is not None and args.substeps < 1:
        parser.error(f"--substeps: expected an integer >= 1, got {args.substeps}")
    env = simulate_variation(case, args.seconds, noise_seed=args.noise_seed, integration_substeps=args.substeps)
    model, log, truth = IdentificationModel(env.robot, "fuel"), env.measurement_log(), truth_of(env)
    d = diagnose(model, log)
    print(f"verdict {d.verdict}: {d.reason}")
    b, sigma2 = d.baseline, d.noise_std_rad_s**2
    for c in sorted(d.candidates, key=lambda f: -f.lr_statistic):
        gyro = (b.rss - c.rss) / sigma2
        attitude = (b.attitude_chi2 or 0.0) - (c.attitude_chi2 or 0.0)
        why = "; ".join(c.implausible)
        if c.gyro_correction_rad_s is not None:  # its gyro gain is against the reading less the correction
            why = "; ".join(filter(None, (why, "gyro gain of the refit with the reading between samples held")))
        print(
            f"  {c.effect:17s} LR {c.lr_statistic:9.1f}  gyro {gyro:9.1f}  attitude {attitude:8.1f}  "
            f"held {c.held_lr_statistic:9.1f} (p {c.p_value:.2g})  {why}"
        )
    assert d.gyro_alone_estimate is not None
    print(_errors_text("gyro-alone fit", parameter_errors(model, log, d.gyro_alone_estimate, truth)))
    print(_errors_text("model as given", parameter_errors(model, log, baseline_estimate(model, log, d), truth)))
    if d.best is not None and d.best.effect is not None:
        extended, estimate = apply_effect(model, log, d.best.effect, d)
        print(_errors_text(f"with {d.best.effect}", parameter_errors(extended, log, estimate, truth)))
    if args.held_noise:
        print("\n".join(held_noise_gains(model, log, d)))
    if args.from_truth:
        print("\n".join(refit_from_truth(model, log, d, truth, args.effect)))
    if args.delay_at_truth:
        for rate in (None, 50, 100):
            print(delay_at_truth(args.seed, fixed if rate is None else {**fixed, "rate_hz": rate}, args.seconds))


if __name__ == "__main__":
    main()
