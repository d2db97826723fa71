"""How well the attitude channel's stationary error model describes a clean log's attitude residual, against the
encoders' noise propagated sample by sample (estimators/attitude_propagation.py).

For clean logs of the variation matrix (``--attitudes``, each axis else drawn from the seed; seeds from
``--first-seed``), at the true unknowns:

* ``stationary``: the error model the diagnosis uses (:class:`~estimators.attitude_noise.AttitudeNoise`, white error
  plus wander per noise axis, fitted by maximum likelihood: 9 numbers);
* ``propagated``: the encoders' noise carried through the momentum map step by step, a block-tridiagonal covariance
  that changes with the configuration, plus the attitude source's white error and a wander: four numbers
  (:class:`~estimators.attitude_propagation.PropagatedNoise`), fitted by maximum likelihood.

Printed per log: ``-2 log L`` of the propagated model less the stationary one's on the same 3(T-2) values (negative:
the propagated model describes the residual better, by that many units of likelihood ratio, with 5 numbers fewer),
the fitted encoder std over the simulated one, the whitened residual's variance over 5 s windows (min-max; 1 under a
right model, the sampling spread of 5 s windows aside), and the fuel mass's Cramér-Rao std from both channels under
each model (gyro at its white noise). Usage::

    python benchmarks/attitude_error_model.py [--logs 4] [--first-seed 11000] [--attitudes exact,star_tracker_1arcsec]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from estimators.attitude_channel import AttitudeChannel
from estimators.attitude_noise import fit_attitude_noise
from estimators.attitude_propagation import (
    EncoderPropagation,
    encoder_propagation,
    fit_propagated_noise,
    propagated_log_likelihood,
    whiten_propagated,
)
from estimators.diagnostics.workflow import true_parameters
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.variations import AXIS_VALUES, draw_variation, simulate_variation, truth_of

#: the window (s) over which the whitened residual's variance is taken
WINDOW_S = 5.0


def propagated_fit(d: FloatArray, propagation: EncoderPropagation) -> tuple[float, float, float, FloatArray]:
    """The propagated error model fitted to steps ``d`` (m, 3): ``(-2 log L up to the constant, encoder std, white std,
    whitened (m, 3))``."""
    noise = fit_propagated_noise(d, propagation)
    whitened, _ = whiten_propagated(d, propagation, noise)
    return propagated_log_likelihood(d, propagation, noise), noise.encoder_std_rad, noise.white_std_rad, whitened


def window_range(whitened: FloatArray, samples: int) -> tuple[float, float]:
    """The whitened residual's variance over consecutive windows of ``samples`` steps: (min, max)."""
    values = [float(np.mean(whitened[j : j + samples] ** 2)) for j in range(0, len(whitened) - samples + 1, samples)]
    return min(values), max(values)


def mass_std(fisher: FloatArray) -> float:
    """The fuel mass's Cramér-Rao std (kg; the first unknown) from ``fisher``."""
    return float(math.sqrt(np.linalg.inv(fisher)[0, 0]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=4, help="logs per attitude source")
    parser.add_argument("--first-seed", type=int, default=11000)
    parser.add_argument("--attitudes", default="exact,star_tracker_1arcsec,star_tracker_5arcsec")
    parser.add_argument("--duration", type=float, default=60.0, help="log length, s")
    args = parser.parse_args()
    attitudes = [a.strip() for a in args.attitudes.split(",") if a.strip()]
    unknown = [a for a in attitudes if a not in AXIS_VALUES["attitude"] or a in ("none", "fused")]
    if unknown or args.logs < 1:
        parser.error(f"--attitudes: expected sources with an attitude, not fused (its coupling to the gyro), got {unknown}")
    print(
        "attitude               seed  robot   Hz  -2logL prop-stat  enc std fit/sim  windows stat   windows prop   mass std stat/prop"
    )
    for attitude in attitudes:
        for seed in range(args.first_seed, args.first_seed + args.logs):
            env = simulate_variation(draw_variation("none", seed, {"attitude": attitude}), args.duration)
            model = IdentificationModel(env.robot, "fuel")
            log = env.measurement_log()
            theta = true_parameters(model, truth_of(env))
            channel = AttitudeChannel.of(model, log, reference=theta)
            assert theta is not None and channel is not None
            d = channel.differences(theta)
            noise = fit_attitude_noise(d @ channel.axes)  # the stationary model (the channel would choose between the two)
            stationary = channel.residuals(theta, noise).reshape(-1, 3)
            stationary_value = float(np.sum(stationary**2)) + noise.log_det(len(d))
            propagation = encoder_propagation(model, log, theta)
            value, encoder_std, _, whitened = propagated_fit(d, propagation)
            samples = round(WINDOW_S / float(np.mean(np.diff(log.t_s))))
            gyro_std = env.sensors.gyro_std_rad_s(env.control_period_s)
            gyro = model.problem(log).fisher(theta, gyro_std)
            jac = channel.difference_jacobian(theta)
            prop_jac, _ = whiten_propagated(jac, propagation, fit_propagated_noise(d, propagation))
            prop_info = prop_jac.reshape(-1, jac.shape[2])
            ratio = mass_std(gyro + channel.fisher(theta, noise)) / mass_std(gyro + prop_info.T @ prop_info)
            low, high = window_range(stationary, samples)
            low_p, high_p = window_range(whitened, samples)
            print(
                f"{attitude:22s} {seed:5d}  {env.robot.name:6s} {round(1 / env.control_period_s):3d}  "
                f"{value - stationary_value:15.1f}  {encoder_std / env.sensors.joint_angle_std_rad():14.3f}  "
                f"{low:5.2f}-{high:5.2f}     {low_p:5.2f}-{high_p:5.2f}     {ratio:8.2f}"
            )


if __name__ == "__main__":
    main()
