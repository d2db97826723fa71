"""A delayed gyro's reading between samples: what the band-limited delay of the prediction misses, from the joints'
own samples.

The ``delay`` term (:class:`~estimators.models.effect_models.Delay`) reads the model's base rate at ``t - d`` by an
all-pass phase ramp on its samples (:func:`~estimators.models.fractional_delay.delay_samples`): exact for a
band-limited series, and it keeps the prediction's noise as it is, so that a fit cannot find a delay in the noise.
The base rate is not band-limited where the joints' servos change their acceleration at every sample (a new command)
and within it (a saturation ends): at 20 Hz, on noise-free copies of four delay logs, the ramp's reading is off by
0.53-1.04 times the gyro's noise of the log as drawn, and the delay fitted with the other unknowns at the truth is
1.6-3.1 ms short.

The joints' samples say more than the ramp uses: the encoders ``q_k`` and the rate sensors ``dq_k`` bound each joint's
motion within a step. A cubic Hermite per step, through the encoder samples with the rate sensors' readings as
tangents (:func:`joint_state_at`: its rate is the quadratic that meets both rate samples and moves the joint as far as
the encoders say), puts the model's base rate at ``t - d`` within 0.002-0.034 of the gyro's noise on those copies.

It cannot replace the ramp inside a fit, though: its reading mixes the sensors' noise differently at each fraction of
a sample (at a step's middle the encoder difference over the step carries a weight of 1.5), so the prediction's noise
changes with the delay and a fit trades one for the other: on 5 of 20 clean 20 Hz logs it fitted delays of 0.6-2.6 ms
with likelihood gains of 7.5-23.4 (the ramp: at most 5.6, 1.2 on average; ``benchmarks/delay_between_samples.py``). :func:`between_samples_correction` therefore holds it: at one delay and set of unknowns (a
fit's), the Hermite reading less the ramp's, kept below :data:`BETWEEN_SAMPLES_BAND_HZ` (where the excitation and the
effects put the base rate; above it the difference is mostly the sensors' noise), is taken off the gyro's reading, and
the delay is fitted again with the ramp; the diagnosis does so after naming a delay until the delay settles
(:func:`~estimators.diagnostics.model_fit.refine_between_samples`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.fft import irfft, rfft, rfftfreq
from scipy.spatial.transform import Rotation, Slerp

from estimators.attitude_integration import hermite_step
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog

#: the band the correction is kept in, Hz: all of it below the first value, none above the second, a raised cosine
#: between (the simulator's joint servos' response, 10 rad/s, and the excitations lie below it). Chosen on four design
#: logs at 20 Hz and fixed, not taken from a log's noise: at the lowest noise the ramp's error above it shows (held-out
#: 11643, noise x0.32: 1.107 times the noise after naming)
BETWEEN_SAMPLES_BAND_HZ = (2.5, 5.0)

#: the delay's unknown in a model with the ``delay`` effect
DELAY_NAME = "delay_s"


def joint_state_at(log: MeasurementLog, delay_s: float) -> MeasurementLog:
    """``log`` with its joint angles and rates, and its attitude, read ``delay_s`` earlier (a negative delay reads later),
    the times and the gyro as logged: within each step a cubic Hermite through the two encoder samples with the joint-rate
    sensors' two readings as its tangents (the rate is its derivative), the attitude interpolated on SO(3); before the
    first sample (after the last) the first (last) sample's state, as a log that starts (ends) at rest.

    Raises:
        SpaceIdInputError: a log of fewer than 2 samples, or a delay that is not a finite number.
    """
    if log.n_samples < 2:
        raise SpaceIdInputError(f"joint_state_at: the log has {log.n_samples} sample(s), at least 2 are needed")
    if not np.isfinite(delay_s):
        raise SpaceIdInputError(f"joint_state_at: expected a finite delay, s, got {delay_s!r}")
    t = np.asarray(log.t_s, dtype=float)
    q, dq = np.asarray(log.q_rad, dtype=float), np.asarray(log.dq_rad_s, dtype=float)
    times = np.clip(t - delay_s, t[0], t[-1])
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
    dt = (t[k + 1] - t[k])[:, None]
    s = (times - t[k])[:, None] / dt
    q_at, dq_at = hermite_step(q[k], q[k + 1], dq[k], dq[k + 1], dt, s)
    quat = log.quat_base_to_inertial_wxyz
    if quat is not None:
        rotations = Rotation.from_quat(np.asarray(quat, dtype=float), scalar_first=True)
        quat = Slerp(t, rotations)(times).as_quat(scalar_first=True)
    return dataclasses.replace(log, q_rad=q_at, dq_rad_s=dq_at, quat_base_to_inertial_wxyz=quat)


def low_passed(series: FloatArray, dt_s: float, band_hz: tuple[float, float] = BETWEEN_SAMPLES_BAND_HZ) -> FloatArray:
    """``series`` (T, C), sampled every ``dt_s``, with its content above ``band_hz[1]`` removed and a raised cosine to
    all of it below ``band_hz[0]``; filtered as its even extension (the series, then the series reversed), so that its
    two ends do not meet in a jump."""
    if not (np.isfinite(dt_s) and dt_s > 0.0):
        raise SpaceIdInputError(f"low_passed: dt_s expected a sample period > 0, s, got {dt_s!r}")
    if not 0.0 < band_hz[0] < band_hz[1]:
        raise SpaceIdInputError(f"low_passed: band_hz expected 0 < f1 < f2, Hz, got {band_hz!r}")
    series = np.asarray(series, dtype=float)
    extended = np.concatenate((series, series[::-1]))
    frequency_hz = rfftfreq(len(extended), dt_s)
    blend = np.clip((frequency_hz - band_hz[0]) / (band_hz[1] - band_hz[0]), 0.0, 1.0)
    weight = 0.5 * (1.0 + np.cos(np.pi * blend))
    return irfft(rfft(extended, axis=0) * weight[:, None], n=len(extended), axis=0)[: len(series)]


def between_samples_correction(model: IdentificationModel, log: MeasurementLog, theta: FloatArray) -> FloatArray:
    """What the gyro of ``model`` (with the ``delay`` effect) reads at ``theta`` (k,) beyond the band-limited delay of
    its prediction (T, 3), rad/s: the model's reading at the joint state ``delay_s`` earlier (:func:`joint_state_at`,
    the delay itself at 0 there) less its reading at the samples delayed by the phase ramp, kept below
    :data:`BETWEEN_SAMPLES_BAND_HZ` (:func:`low_passed`). Effects that carry a state in time (a slosh) see the whole
    joint motion read earlier, which delays their response alike; only an explicit time (a torque's ramp) is read at
    the sample time, off by the delay, and on a log without attitude the base's attitude (integrated from the gyro,
    which is not read earlier) is off by the rotation over the delay: both matter only for effects in inertial axes.

    Raises:
        SpaceIdInputError: a model without the delay, a ``theta`` of another length, or a log that is not sampled
            uniformly (the phase ramp's own condition).
    """
    names = model.parameters.names
    if DELAY_NAME not in names:
        raise SpaceIdInputError(f"between-samples correction: the model has no {DELAY_NAME!r} (its unknowns: {names})")
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (len(names),):
        raise SpaceIdInputError(f"between-samples correction: expected theta of {len(names)} values, got {theta.shape}")
    steps = np.diff(np.asarray(log.t_s, dtype=float))
    if not np.allclose(steps, steps[0], rtol=1e-6, atol=0.0):
        raise SpaceIdInputError(
            f"between-samples correction: the log's t_s is not evenly spaced (steps {steps.min():.6g}-{steps.max():.6g} s); "
            "the phase ramp needs a uniformly sampled log"
        )
    index = names.index(DELAY_NAME)
    undelayed = theta.copy()
    undelayed[index] = 0.0
    at_earlier_state = model.problem(joint_state_at(log, float(theta[index]))).predict(undelayed[None], count=False)[0]
    ramp = model.problem(log).predict(theta[None], count=False)[0]
    return low_passed(at_earlier_state - ramp, float(steps[0]))
