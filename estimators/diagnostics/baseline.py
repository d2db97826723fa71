"""The baseline of a diagnosis with attitude: the model as given, started from the better of the gyro's fit and a
scan of its base's box on both channels (:func:`scanned_baseline`), fitted on the gyro and the attitude at its profile
likelihood's optimum (:func:`profiled_baseline`), with the attitude channel's integration error taken out at that
fit (:func:`rereferenced`). Every candidate of :func:`~estimators.diagnostics.diagnose.diagnose` starts from it and
is scored against it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.stats import qmc

from estimators.attitude_channel import AttitudeChannel
from estimators.diagnostics.model_fit import (
    MIN_STEP_GAIN_CHI2,
    ChannelWeights,
    ModelFit,
    best_of_grid,
    fit_model,
    joint_chi2,
    joint_objective,
)
from estimators.parameters import WithEffects
from estimators.problem import IdentificationModel, IdentificationProblem
from spaceid_gym.log import MeasurementLog

#: the change of the baseline's whitened attitude residual (chi-square units) from moving the channel's reference, at
#: or above which the channel is re-referenced (:func:`rereferenced`): below it the baseline's fit moves by less than
#: ``sqrt(0.05)`` = 0.22 of its standard deviations. Clean logs 9737, 9762 and 9780 gave 1e-4, delay log 9762 109
REREFERENCE_CHI2 = 0.05

#: at most this many passes of :func:`profiled_baseline`
MAX_BASELINE_PASSES = 8

#: the points of :func:`scanned_baseline`'s scan of the model's box (a scrambled Sobol set, a power of two)
SCAN_POINTS = 128

#: the seed of that set's scrambling: the same points for every log of a model (they depend on its number of
#: unknowns), so that a diagnosis is reproducible
SCAN_SEED = 0


def scanned_baseline(
    model: IdentificationModel,
    log: MeasurementLog,
    baseline: ModelFit,
    weights: ChannelWeights,
    channel: AttitudeChannel,
    problem: IdentificationProblem,
) -> ModelFit:
    """The better on both channels (under ``weights``) of two refits: the ``baseline`` (the gyro's fit) refined on
    both channels, and the points of a scan of the model's box that fit both channels better than it does, refined
    likewise; the ``baseline`` itself, unrefined, if no scanned point does. ``problem``: ``model``'s problem on
    ``log``.

    The scan: :data:`SCAN_POINTS` points of a scrambled Sobol set over the base's unknowns (a model's effects held
    at the ``baseline``'s values), scored on both channels as a candidate's grid is
    (:func:`~estimators.diagnostics.model_fit.best_of_grid`, the gyro's chi-square plus the attitude's). Where some of
    its best :data:`~estimators.diagnostics.model_fit.GRID_STARTS` beat the baseline, the baseline is refined on
    both channels on its own, and those points are starts of a second refinement
    (:func:`~estimators.diagnostics.model_fit.fit_model`: each polished on the gyro, the best on both channels of
    the polished and the raw points refined on both, the attitude error model refitted); the fit of lowest
    ``-2 log L`` on both channels is kept, so the scan never ends worse than the baseline's own refinement (before,
    one refinement started from the best of the baseline and the points, and a point that scored better unrefined
    could end worse than the baseline refined). :func:`profiled_baseline` then keeps the fit unless a pass improves
    on it.

    Why: the gyro's likelihood in the fuel's unknowns can have several basins within a unit or two of chi-square, or
    none near the truth, where the attitude tells them apart by thousands of units; the two-channel refinement of the
    gyro's fit stays in its basin. On a clean log of ``paper6`` (20 Hz, a 1" star tracker, the noise 2.8 times the
    defaults; design draws of the motion of seed 10565) the estimator's global search on the gyro stopped in a basin
    at 17.6 kg for 35.4 kg (the gyro's best basin, at 40.9 kg, was 1.3 units lower); the baseline refined from it
    ended at 2.5 kg with the tank on its bound, and the log was called ``unexplained`` (another draw: ``slosh``, fuel
    z -78). The scan's best start, refitted, reached the truth's basin (z within 1.1) and the log was ``none``."""
    params = problem.parameters
    # the base's unknowns only: the model as given holds its effects where its gyro fit put them, and their search
    # ranges are physically wide (a momentum that spins the satellite at degrees a second, a payload's 10 unknowns)
    k = params.base.n_params if isinstance(params, WithEffects) else params.n_params
    sobol = qmc.Sobol(d=k, scramble=True, rng=np.random.default_rng(SCAN_SEED))
    points = np.tile(baseline.theta, (SCAN_POINTS, 1))
    points[:, :k] = qmc.scale(sobol.random(SCAN_POINTS), params.lower[:k], params.upper[:k])
    reference = joint_chi2(problem, channel, weights, baseline.theta)
    better = [
        p for p in best_of_grid(problem, list(points), channel, weights) if joint_chi2(problem, channel, weights, p) < reference
    ]
    if not better:
        return baseline
    # the baseline refined on its own, as it would be without the scan, and each basin the scan's points reach:
    # the best of them on both channels, so the scan never ends worse than the baseline's own refinement
    fits = [
        fit_model(model, log, starts=starts, weights=weights, channel=channel, problem=problem, profile_noise=True)[0]
        for starts in ([baseline.theta], better)
    ]
    return min(fits, key=lambda f: joint_objective(f, weights))


def profiled_baseline(
    model: IdentificationModel,
    log: MeasurementLog,
    baseline: ModelFit,
    weights: ChannelWeights,
    channel: AttitudeChannel,
    refined: bool = False,
) -> tuple[ModelFit, ChannelWeights]:
    """The ``baseline`` refitted on both channels at its profile likelihood's optimum, with the ``weights`` of its own
    attitude error model. ``refined``: the ``baseline`` is a fit on both channels under ``channel`` already, its error
    model refitted (:func:`scanned_baseline`'s), and is kept unless a pass improves on it; else the first pass is.

    Each pass is what every candidate gets from the baseline's state: a fit under the error model of ``weights``, the
    error model refitted at it, the fit refined (:func:`fit_model` with ``profile_noise``). The passes go on until one
    lowers ``-2 log L`` of both channels (gyro at ``weights``' white noise, attitude under its refitted error model)
    by less than :data:`MIN_STEP_GAIN_CHI2`, at most :data:`MAX_BASELINE_PASSES`, and the best pass is kept. A
    baseline stopped short of its optimum hands every candidate the difference, since each candidate starts from it
    with its effect off: on held-out clean log 9737 (``paper6``, an exact attitude at 100 Hz) the two passes made
    before left the baseline 26 units above its optimum, every candidate gained 26-46 units in the attitude channel
    alone, and a delay was named (likelihood ratio 26.4); with the passes until none gains, its ratio is 0.3."""
    sigma2 = weights.gyro_std_rad_s**2
    reference = weights.attitude  # any fixed error model: the log-determinant it subtracts cancels between passes

    def value(fit: ModelFit) -> float:
        """``-2 log L`` of ``fit`` on both channels, the attitude under its own refitted error model."""
        assert fit.attitude_noise is not None
        return fit.rss / sigma2 + channel.profile_chi2(fit.theta, fit.attitude_noise, reference)

    best, best_weights, best_value = baseline, weights, math.inf
    if refined:
        best_value = value(baseline)  # asserts the error model refitted
        best_weights = replace(weights, attitude=baseline.attitude_noise)
    for _ in range(MAX_BASELINE_PASSES):
        fit = fit_model(model, log, starts=[best.theta], weights=best_weights, channel=channel, profile_noise=True)[0]
        assert fit.attitude_noise is not None
        fit_value = value(fit)
        gain = best_value - fit_value
        if gain > 0.0:
            best, best_value = fit, fit_value
            best_weights = replace(weights, attitude=fit.attitude_noise)
        if gain < MIN_STEP_GAIN_CHI2:
            break
    return best, best_weights


def rereferenced(
    model: IdentificationModel, log: MeasurementLog, baseline: ModelFit, weights: ChannelWeights, channel: AttitudeChannel
) -> tuple[AttitudeChannel, ModelFit, ChannelWeights]:
    """The attitude channel with its integration error taken out at the two-channel ``baseline``'s unknowns (the
    channel comes referenced at the gyro-alone fit), and the baseline profiled again under it
    (:func:`profiled_baseline`); as they are if the baseline sits at the channel's reference already.

    The midpoint rule's error is carried to first order about the reference, and what is left grows with the square
    of the distance. A gyro measurement effect pulls the gyro-alone fit far off: on held-out log 9762 (``quick3``, an
    exact attitude at 50 Hz, an 18.6 ms delay) the gyro alone put the fuel at 9.85 kg for 15.74 kg, the two-channel
    fits sat near the truth, and the error left from 6 kg away moved the delay's fuel by 1.9 g, 7.7 of its Cramér-Rao
    std (0.25 g with that attitude); re-referenced at the two-channel baseline, the error is 0.07 g (z -0.34,
    ``benchmarks/diagnose_case.py delay 9762``).

    The channel is kept when moving its reference changes the baseline's whitened residual by less than
    :data:`REREFERENCE_CHI2` (:meth:`~estimators.attitude_channel.AttitudeChannel.moved_chi2`): the baseline's fit
    of both channels could then move by at most ``sqrt(0.05)`` = 0.22 of its standard deviations, to first order
    with the error model held. The change grows with a fit's distance from the baseline, so the bound does not cover
    a candidate's fit far from it. The gyro coupling of a fused attitude is kept as it was fitted, at the gyro-alone
    fit."""
    if weights.reference is not None and np.array_equal(baseline.theta, weights.reference):
        return channel, baseline, weights
    moved = AttitudeChannel.of(model, log, channel.coupling, baseline.theta)
    assert moved is not None
    if channel.moved_chi2(moved, baseline.theta, weights.attitude) < REREFERENCE_CHI2:
        return channel, baseline, weights  # the baseline could not move by a quarter of its std (a clean log's)
    weights = replace(weights, reference=moved.reference, axes=moved.axes)
    baseline, weights = profiled_baseline(model, log, baseline, weights, moved)
    return moved, baseline, weights
