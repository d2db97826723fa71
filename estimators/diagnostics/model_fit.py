"""Fitting one model on a log and scoring the fit: the gyro's residual, the star tracker's channel, plausibility.

Part of the diagnosis (:mod:`estimators.diagnostics.diagnose`): :func:`fit_model` fits a model (both channels
together when the log has attitude), :class:`ModelFit` holds its figures.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import least_squares, minimize_scalar
from scipy.special import expit
from scipy.special import logit as logit_of
from scipy.stats import chi2, norm

from estimators.attitude_channel import (
    AttitudeChannel,
    ErrorModel,
    GyroCoupling,
    choose_gyro_coupling,
    first_order_coupling,
    min_coupling_samples,
)
from estimators.base import Estimator
from estimators.estimate import Estimate
from estimators.gyro_between_samples import DELAY_NAME, between_samples_correction
from estimators.least_squares import LevenbergMarquardt
from estimators.parameters import WithEffects
from estimators.problem import IdentificationModel, IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import jsonable
from spaceid_gym.log import MeasurementLog

#: a candidate is named only if it explains at least this fraction of the baseline's excess over the noise
EXPLAINED_FRACTION = 0.3


def explained_fraction(lr_statistic: float, excess: float) -> float:
    """Share of the baseline's ``excess`` chi-square over the noise (``X_baseline - (n - k)``) that a candidate's
    likelihood ratio ``lr_statistic`` removes, capped at 1: a candidate that brings the fit down to the noise
    or below explains all of it, including when the baseline is already at the noise in aggregate
    (``excess <= 0``: a weak effect that only the directed likelihood-ratio test sees)."""
    if lr_statistic <= 0.0:
        return 0.0
    return 1.0 if excess <= lr_statistic else lr_statistic / excess


@dataclass(kw_only=True)
class CandidateScores:
    """A candidate fit's scores against the baseline (filled in once every model is fitted; ``nan`` until then):
    ``bic``, ``delta_bic`` (to the baseline), ``lr_statistic`` (the profile likelihood ratio: each fit's attitude
    error model refitted at it), ``held_lr_statistic`` (the same with the attitude error model held at the
    baseline's, the null's estimate: never more than ``lr_statistic``; equal without attitude), ``p_value`` (of
    ``held_lr_statistic``, :func:`~estimators.diagnostics.verdict._score`), ``significant``,
    ``explained_fraction`` (of the baseline's excess over the noise, :func:`explained_fraction`) and
    ``attitude_p_value`` (of the star tracker's chi-square against its count, chi-square with that many degrees
    of freedom; ``nan`` without attitude)."""

    bic: float = math.nan
    delta_bic: float = math.nan
    lr_statistic: float = math.nan
    held_lr_statistic: float = math.nan
    p_value: float = math.nan
    significant: bool = False
    explained_fraction: float = math.nan
    attitude_p_value: float = math.nan

    def scores(self) -> dict[str, Any]:
        """The scores as a JSON-able dict."""
        return {
            "bic": self.bic,
            "delta_bic": self.delta_bic,
            "lr_statistic": self.lr_statistic,
            "held_lr_statistic": self.held_lr_statistic,
            "p_value": self.p_value,
            "significant": self.significant,
            "explained_fraction": self.explained_fraction,
            "attitude_p_value": self.attitude_p_value,
        }


@dataclass(frozen=True)
class ChannelWeights:
    """The noise of the two channels, which weights them in a joint fit: the gyro's per-sample std (rad/s, per
    axis) and the attitude residual's error model (:data:`~estimators.attitude_channel.ErrorModel`)."""

    gyro_std_rad_s: float
    attitude: ErrorModel
    coupling: GyroCoupling | None = None  # the attitude's response to the gyro (a fused attitude), or None
    #: the unknowns at which the channel takes its integration error out and finds its noise axes (the baseline's fit;
    #: :meth:`~estimators.attitude_channel.AttitudeChannel.of`), or None (the nominal)
    reference: FloatArray | None = None
    #: the channel's noise axes (3, 3), columns in the first sample's frame, along which a stationary ``attitude`` gives
    #: its stds and in which a propagated one whitens (:func:`~estimators.attitude_channel.noise_axes`; reported, the
    #: channels find them again from ``reference``)
    axes: FloatArray | None = None

    def to_dict(self) -> dict[str, Any]:
        coupling = None if self.coupling is None else self.coupling.to_dict()
        reference = None if self.reference is None else [float(v) for v in self.reference]
        axes = None if self.axes is None else np.asarray(self.axes, dtype=float).T.tolist()
        return {
            "gyro_std_rad_s": self.gyro_std_rad_s,
            **self.attitude.to_dict(),
            "attitude_noise_axes": axes,  # one row per noise axis, first sample's frame
            "attitude_coupling": coupling,
            "attitude_reference": reference,
        }


@dataclass
class ModelFit(CandidateScores):
    """One model fitted to the log and its scores.

    Attributes:
        effects: the model's effects (the baseline's plus the candidate).
        effect: the candidate added (``None`` for the baseline).
        theta: the fitted unknowns (k,); ``names`` their names.
        rss: sum of squared gyro residuals, (rad/s)^2; ``n_residuals`` 3T; ``n_params`` k.
        attitude_chi2: the attitude channel's ``-2 log L`` at the fit under the error model refitted there
            (``attitude_noise``), less the log-determinant of the error model of the channel's weights
            (:meth:`~estimators.attitude_channel.AttitudeChannel.profile_chi2`): a chi-square over
            ``n_attitude_values`` values whose differences between fits are profile likelihood ratios (``None``
            without attitude in the log).
        attitude_chi2_held: the attitude channel's chi-square at the fit under the weights' error model (the
            baseline's, held): differences to the baseline's are likelihood ratios with the error model fixed at the
            null's estimate (``None`` without attitude).
        physical: the fitted quantities (base and effects), as in the estimate file.
        implausible: reasons why the fitted effect is not physical (empty if plausible).
        wall_time_s: time of the fit.
        chi2: both channels' chi-square (:func:`_score`); ``residual_consistent``: whether the fit's gyro residual
            passes every test of :func:`~estimators.diagnostics.residuals.analyse_residuals` (``None``: not analysed).
        attitude_white_p: p-value of the attitude residual, whitened by its error model, against unit white noise in
            the effects' band (:func:`low_frequency_p_value`): small when the attitude source's errors are not what
            the model assumes (``nan``: no attitude).
        gyro_correction_rad_s: what the fit took off the log's gyro reading (T, 3), rad/s: a delayed gyro's reading
            between samples held at a fit (:func:`refine_between_samples`); its ``rss`` is against the reading less it.
            ``None``: the reading as logged.
    """

    effects: tuple[str, ...]
    effect: str | None
    theta: FloatArray
    names: tuple[str, ...]
    rss: float
    n_residuals: int
    n_params: int
    attitude_chi2: float | None
    n_attitude_values: int
    physical: dict[str, Any]
    implausible: list[str]
    wall_time_s: float
    chi2: float = math.nan  # filled in by :func:`diagnose` once every model is fitted
    residual_consistent: bool | None = None  # filled in by :func:`diagnose` for the significant and plausible ones
    attitude_white_p: float = math.nan  # the whitened attitude residual's low-frequency test (:func:`low_frequency_p_value`)
    attitude_noise: ErrorModel | None = None  # the attitude error model refitted at this fit
    attitude_chi2_held: float | None = None  # the attitude chi-square under the weights' error model, held
    gyro_correction_rad_s: FloatArray | None = None  # taken off the gyro's reading (:func:`refine_between_samples`)

    @property
    def residual_rms_rad_s(self) -> float:
        """RMS of the gyro residual (rad/s)."""
        return math.sqrt(self.rss / self.n_residuals)

    @property
    def plausible(self) -> bool:
        return not self.implausible

    @property
    def spec(self) -> str:
        """The candidate's effect with its options as the model has it (``"slosh[model=pendulum]"``)."""
        return next(s for s in reversed(self.effects) if s.partition("[")[0] == self.effect)

    @property
    def nameable(self) -> bool:
        """Significant and plausible: a candidate the verdict may name (scores from :func:`_score`)."""
        return self.significant and self.plausible

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary."""
        return {
            "effect": self.effect,
            "effects": list(self.effects),
            "n_params": self.n_params,
            "residual_rms_rad_s": self.residual_rms_rad_s,
            "rss": self.rss,
            "attitude_chi2": self.attitude_chi2,
            "attitude_chi2_held": self.attitude_chi2_held,
            "chi2": self.chi2,
            "residual_consistent": self.residual_consistent,
            "attitude_white_p": self.attitude_white_p,
            **self.scores(),
            "plausible": self.plausible,
            "implausible": list(self.implausible),
            "parameters": {n: float(v) for n, v in zip(self.names, self.theta, strict=True)},
            "physical": jsonable(self.physical),
            "wall_time_s": self.wall_time_s,
            "gyro_correction_rms_rad_s": None
            if self.gyro_correction_rad_s is None
            else float(np.sqrt(np.mean(self.gyro_correction_rad_s**2))),
            # a refit with the gyro's reading between samples keeps the scores of the fit the tests named
            "scores_of": "this fit" if self.gyro_correction_rad_s is None else "the fit before the between-samples refit",
        }


def gyro_log(log: MeasurementLog, fit: ModelFit) -> MeasurementLog:
    """``log`` with ``fit``'s correction taken off its gyro reading (:attr:`ModelFit.gyro_correction_rad_s`; ``log``
    itself without one): the log its gyro residual is against."""
    return log if fit.gyro_correction_rad_s is None else _gyro_less(log, fit.gyro_correction_rad_s)


def _gyro_less(log: MeasurementLog, correction_rad_s: FloatArray) -> MeasurementLog:
    """``log`` with ``correction_rad_s`` (T, 3) taken off its gyro reading."""
    return replace(log, omega_base_body_rad_s=np.asarray(log.omega_base_body_rad_s, dtype=float) - correction_rad_s)


#: the rounds of :func:`refine_between_samples` at most, and the change of the delay (s) at which it stops
BETWEEN_SAMPLES_ROUNDS, BETWEEN_SAMPLES_TOLERANCE_S = 5, 1e-5


def refine_between_samples(
    model: IdentificationModel, log: MeasurementLog, fit: ModelFit, weights: ChannelWeights | None
) -> tuple[ModelFit, float]:
    """``fit`` (of ``model``, which has the ``delay`` effect, on ``log``, as :func:`fit_model` made it under
    ``weights``) fitted again with the gyro's reading between samples held
    (:func:`~estimators.gyro_between_samples.between_samples_correction` at the last fit, taken off the reading), until
    the delay moves by less than :data:`BETWEEN_SAMPLES_TOLERANCE_S` (at most :data:`BETWEEN_SAMPLES_ROUNDS` rounds; two
    to four on the design logs at 20 Hz, from 1.6-3.1 ms short to within 0.11 ms of the truth with the other unknowns
    there). The attitude channel compares the attitude with the model's own rate, which no gyro delay moves, as before.
    The scores (:class:`CandidateScores`, ``chi2``, ``residual_consistent``: the tests that named the delay) are
    ``fit``'s; the unknowns, the residual and the attitude's chi-square are the refined fit's. Returns the refined fit
    and the delay's change in the last round, s (below the tolerance once it settled).

    Raises:
        SpaceIdInputError: a model without the delay (:func:`~estimators.gyro_between_samples.between_samples_correction`).
    """
    if DELAY_NAME not in model.parameters.names:
        raise SpaceIdInputError(
            f"refine_between_samples: the model has no {DELAY_NAME!r} (its unknowns: {model.parameters.names})"
        )
    index = model.parameters.names.index(DELAY_NAME)
    channel = None if weights is None else AttitudeChannel.of(model, log, weights.coupling, weights.reference)
    current, spent = fit, 0.0
    for _ in range(BETWEEN_SAMPLES_ROUNDS):
        correction = between_samples_correction(model, log, current.theta)
        refit = fit_model(
            model,
            log,
            starts=[current.theta],
            effect=fit.effect,
            weights=weights,
            channel=channel,
            problem=model.problem(_gyro_less(log, correction)),
            profile_noise=weights is not None,
        )[0]
        refit.gyro_correction_rad_s = correction
        spent += refit.wall_time_s
        moved = abs(float(refit.theta[index] - current.theta[index]))
        current = refit
        if moved < BETWEEN_SAMPLES_TOLERANCE_S:
            break
    scores = {name: getattr(fit, name) for name in ("chi2", "residual_consistent", *CandidateScores().scores())}
    return replace(current, **scores, wall_time_s=fit.wall_time_s + spent), moved


def fit_model(
    model: IdentificationModel,
    log: MeasurementLog,
    estimator: Estimator | None = None,
    starts: list[FloatArray] | None = None,
    effect: str | None = None,
    weights: ChannelWeights | None = None,
    channel: AttitudeChannel | None = None,
    problem: IdentificationProblem | None = None,
    profile_noise: bool = False,
    each_basin: bool = False,
    noise_start: ErrorModel | None = None,
) -> tuple[ModelFit, Estimate | None]:
    """Fit ``model`` to ``log``: with ``estimator`` (returns its estimate), or by least squares from each of ``starts``.

    From ``starts``: least squares on the gyro residuals from each start. With ``weights`` and a log with attitude,
    the result that is best on both channels is then refined on the likelihood of both,
    ``|gyro residual|^2 / sigma_gyro^2 + |attitude residual|^2 / sigma_st^2`` (at most :data:`MAX_ITERATIONS`
    residual evaluations); otherwise the best on the gyro is kept. ``channel``: ``model``'s attitude channel on
    ``log`` if the caller has built it already (else built here when ``weights`` are given); ``problem``: ``model``'s
    problem on ``log``, likewise. ``profile_noise``: the attitude error model is a nuisance refitted at this model's
    fit (and the fit refined under it), so that the fits' ``attitude_chi2`` differ by profile likelihood ratios
    (:meth:`~estimators.attitude_channel.AttitudeChannel.profile_chi2`); else ``weights``' error model is
    taken as known. ``each_basin``: with attitude, each distinct gyro minimum the starts reach (:func:`distinct_minima`)
    is refined on both channels, and the fit best by ``rss / sigma_gyro^2`` plus the attitude's chi-square is kept;
    without it only the best of them by both channels at the weights' error model is. The two channels' optima can
    lie far apart within a basin: on held-out log 9709 (orbit7, an exact attitude at 100 Hz, a 127 kg pendulum slosh)
    the gyro's minimum with the tank mirrored scored 459 units better at the baseline's error model than the true
    basin's, and 781 units worse once each was refined on both channels. ``noise_start``: with ``profile_noise``, the
    error model the starts are scored and refined under and its refit starts from, instead of ``weights``' (which stays
    the reference of the profile chi-square); unused without ``weights`` or with an ``estimator``.
    """
    begin = time.perf_counter()
    problem = model.problem(log) if problem is None else problem
    if weights is None:
        channel = None
    elif channel is None:
        channel = AttitudeChannel.of(model, log, weights.coupling, weights.reference)
    estimate = None
    if estimator is not None:
        estimate = estimator.fit_problem(problem)
        theta = estimate.theta
    else:
        if not starts:
            raise SpaceIdInputError("fit_model: give an estimator or at least one start")
        polish = LevenbergMarquardt(max_iterations=MAX_ITERATIONS, ftol=step_ftol(3 * problem.n_samples))
        starts = distinct_starts(starts)
        results = [polish.polish(problem, start).theta for start in starts]
        basins = distinct_minima(problem, results) if each_basin and channel is not None else []
        if len(basins) > 1:
            fits = [
                fit_model(
                    model,
                    log,
                    starts=[b],
                    effect=effect,
                    weights=weights,
                    channel=channel,
                    problem=problem,
                    profile_noise=profile_noise,
                    noise_start=noise_start,
                )[0]
                for b in basins
            ]
            assert weights is not None
            best = min(fits, key=lambda f: joint_objective(f, weights))
            best.wall_time_s = time.perf_counter() - begin
            return best, None
        if channel is not None:
            assert weights is not None
            # the gyro's minimum nearest each start, the best of them by both channels, refined on both; then the
            # attitude error model refitted at this model's fit and the fit refined under it (profile likelihood)
            search = weights if noise_start is None or not profile_noise else replace(weights, attitude=noise_start)
            theta = _refined_on_both(problem, channel, search, results, starts)
            if profile_noise:
                # the error model polished from the search's to weigh the refinement (the score's own comes after it)
                own = replace(weights, attitude=channel.estimate_noise(theta, search.attitude, only_from_start=True))
                theta = _joint_fit(problem, channel, own, theta)
        else:
            scores = [float(r @ r) for r in (problem.residuals(x, count=False) for x in results)]
            theta = results[int(np.argmin(scores))]
    # the same prediction within what the effects can physically move (a slosh mass beyond the liquid left is that
    # liquid: the prediction is flat beyond it, so a fit may stop anywhere there)
    theta = problem.parameters.equivalent(theta)
    attitude_chi2, attitude_information, attitude_white_p, noise = None, None, math.nan, None
    if channel is not None:
        assert weights is not None
        if not profile_noise:
            noise = weights.attitude
        elif estimator is None:
            # refitted at the final fit from every start: the profile likelihood at it. The error model of the refined
            # fit's start, kept, left the baseline up to 17 units of -2 log L above its own profile, which candidates
            # then gained; a polish alone at this point stuck the baseline of 9615 at a wander of zero (where its
            # correlation is flat) while candidates found 3.6e-9 rad, and a clean log was named a delay (LR 12.7)
            noise = channel.estimate_noise(theta, own.attitude)
        else:
            noise = channel.estimate_noise(theta, weights.attitude)
        whitened = channel.residuals(theta, noise)
        attitude_chi2 = channel.profile_chi2(theta, noise, weights.attitude)
        # the plausibility's covariance with the error model held at the weights' (the baseline's), as the test holds
        # it: a candidate's own refit can take the wander to zero and overstate the attitude's information (payload
        # log 10434: a physical payload 0.03 attitude units from the fit judged 5.6 std unphysical; the Fisher form
        # to it was 90.8 under the candidate's error model, 0.07 under the baseline's)
        attitude_information = channel.fisher(theta, weights.attitude)
        attitude_white_p = low_frequency_p_value(whitened.reshape(-1, 3), ATTITUDE_BLOCK_S / float(np.mean(np.diff(log.t_s))))
    n_attitude = 0 if channel is None else channel.n_values
    fit = _scored(problem, theta, model, effect, (attitude_chi2, n_attitude), attitude_information, weights)
    fit.wall_time_s = time.perf_counter() - begin
    fit.attitude_white_p = attitude_white_p
    fit.attitude_noise = noise
    if channel is not None:
        assert weights is not None
        # under the weights' error model already when it was not refitted
        fit.attitude_chi2_held = channel.chi2(theta, weights.attitude) if profile_noise else attitude_chi2
    return fit, estimate


#: the half-width of the filter gain's profile (:func:`profile_filter_gain`), in logits of the gain about its estimate:
#: the gain times 0.37-2.7 near a small gain; the regression estimates it to 10-20 % (0.101-0.134 for 0.112 on held-out
#: fused logs)
GAIN_PROFILE_LOGITS = 1.0

#: the tolerance of that search, logits (1 % of the gain)
GAIN_PROFILE_TOLERANCE = 0.01


def profile_filter_gain(
    model: IdentificationModel, log: MeasurementLog, fit: ModelFit, weights: ChannelWeights, effect: str | None
) -> tuple[ModelFit, ChannelWeights]:
    """``fit`` (of ``model`` on ``log`` under ``weights``) refitted with the fused attitude's filter gain a nuisance of
    the joint likelihood: the gain minimising ``rss / sigma_gyro^2`` plus the attitude's profile chi-square, each gain's
    fit refined from the best so far (a bounded search within :data:`GAIN_PROFILE_LOGITS` of the regression's gain, once
    more about the best gain if the search stopped at its edge);
    ``fit`` and ``weights`` as they are unless the coupling is a first-order filter's
    (:func:`~estimators.attitude_channel.choose_gyro_coupling`).

    Why: a large gyro error (a delay of tens of ms) passes through the filter's response into the attitude residual, so
    the fuel unknowns follow the gain's error. The regression's gain is good to 10-20 %, and 10 % moved the fuel by 2-3
    Cramer-Rao std after naming a delay on held-out fused logs (10529: z 3.8 at 0.1015, 1.5 at the filter's 0.1119;
    10546: 3.3 at 0.133, 0.8 at 0.112). The joint likelihood pins the gain far better (on 10529 it rises by 126 units
    from 0.1117 to 0.1015; its minimum lies within 0.3 % of the filter's gain on both logs)."""
    coupling = weights.coupling
    if coupling is None or coupling.filter_gain is None or log.quat_base_to_inertial_wxyz is None:
        return fit, weights
    dt_s = float(np.median(np.diff(log.t_s)))
    problem = model.problem(gyro_log(log, fit))
    tried: dict[float, tuple[float, ModelFit, ChannelWeights]] = {}

    def refit(logit: float) -> float:
        gain_weights = replace(weights, coupling=first_order_coupling(float(expit(logit)), dt_s))
        start = min(tried.values(), key=lambda entry: entry[0])[1].theta if tried else fit.theta
        refitted = fit_model(
            model, log, starts=[start], effect=effect, weights=gain_weights, problem=problem, profile_noise=True
        )[0]
        refitted.gyro_correction_rad_s = fit.gyro_correction_rad_s
        tried[logit] = (joint_objective(refitted, gain_weights), refitted, gain_weights)
        return tried[logit][0]

    center = float(logit_of(coupling.filter_gain))
    for _ in range(2):  # once more about the best gain if the first search stopped at its edge
        minimize_scalar(
            refit,
            bounds=(center - GAIN_PROFILE_LOGITS, center + GAIN_PROFILE_LOGITS),
            method="bounded",
            options={"xatol": GAIN_PROFILE_TOLERANCE},
        )
        best_logit = min(tried, key=lambda logit: tried[logit][0])
        if abs(abs(best_logit - center) - GAIN_PROFILE_LOGITS) > 2.0 * GAIN_PROFILE_TOLERANCE:
            break
        center = best_logit
    best = tried[best_logit]
    return (best[1], best[2]) if best[0] < joint_objective(fit, weights) else (fit, weights)


def joint_objective(fit: ModelFit, weights: ChannelWeights) -> float:
    """``-2 log L`` of ``fit`` on both channels up to a constant: ``rss / sigma_gyro^2`` plus the attitude's (profile)
    chi-square (none without attitude), the score :func:`fit_model` and :func:`profile_filter_gain` compare fits by."""
    return fit.rss / weights.gyro_std_rad_s**2 + (fit.attitude_chi2 or 0.0)


#: two least-squares minima are one when every unknown agrees to this fraction of its search width
#: (:func:`distinct_minima`). Set on design log 9709: the mirror images that fell back into one basin agreed to
#: 0.01 % of the width, the two basins differed by 85 % in the tank's x; a looser value merges what the restart is
#: for, a tighter one refines the same basin again (each refinement costs a joint fit)
SAME_MINIMUM_WIDTH = 0.02


def distinct_starts(starts: list[FloatArray]) -> list[FloatArray]:
    """``starts`` (each (k,)) without exact repeats, in their order: a polish is deterministic, so a repeated start
    reaches the same point again (a candidate whose grid is its nominal alone offers the baseline twice)."""
    kept: list[FloatArray] = []
    for start in starts:
        if not any(np.array_equal(start, k) for k in kept):
            kept.append(start)
    return kept


def distinct_minima(problem: IdentificationProblem, minima: list[FloatArray]) -> list[FloatArray]:
    """``minima`` (each (k,)) without repeats, best gyro cost first: a point is dropped when a better one agrees with it
    on every unknown to :data:`SAME_MINIMUM_WIDTH` of the unknown's search width."""
    order = np.argsort(problem.cost(np.array(minima), count=False))
    width = problem.parameters.width
    kept: list[FloatArray] = []
    for i in order:
        if all(np.any(np.abs(minima[i] - k) > SAME_MINIMUM_WIDTH * width) for k in kept):
            kept.append(minima[i])
    return kept


#: accepted least-squares steps per start of a candidate fit
MAX_ITERATIONS = 30

#: a candidate's least-squares fits stop at a step that lowers the chi-square by less than this many units (at the
#: fit's own residual level; :func:`step_ftol`): a fit that only fits noise (a slosh oscillator on a clean log) crawls
#: along a flat valley for all of :data:`MAX_ITERATIONS` at a few hundredths of a unit per step, while the
#: likelihood-ratio tests it feeds have thresholds of several units
MIN_STEP_GAIN_CHI2 = 0.05


def step_ftol(n_values: int) -> float:
    """scipy's relative ``ftol`` for fits of ``n_values`` residuals that stops at a step gaining less than
    :data:`MIN_STEP_GAIN_CHI2` (a cost relative to its value; the chi-square at the residual's own level is the
    number of values)."""
    return MIN_STEP_GAIN_CHI2 / max(n_values, 1)


#: block length (s) of the low-frequency test of the whitened attitude residual (:func:`low_frequency_p_value`):
#: the band below ~0.5 Hz where the effects act
ATTITUDE_BLOCK_S = 1.0


def low_frequency_p_value(whitened: FloatArray, block_samples: float) -> float:
    """p-value of the whitened residual (n, c) having no more power in its block sums than unit white noise.

    Blocks of ``round(block_samples)`` samples (at least 1); each block's sum over the square root of its length
    is standard normal under the error model, so their squares add up to a chi-square with one degree of freedom
    per block and column. Only the upper tail counts: what matters is power the model does not expect where the
    effects act (slow), not a misfit at short lags (the midpoint rule against a servo's motion between samples)."""
    size = max(round(block_samples), 1)
    n_blocks = whitened.shape[0] // size
    if n_blocks < 1:
        return 1.0
    sums = whitened[: n_blocks * size].reshape(n_blocks, size, -1).sum(axis=1) / math.sqrt(size)
    return float(chi2.sf(float(np.sum(sums * sums)), sums.size))


def _joint_residuals(
    problem: IdentificationProblem, channel: AttitudeChannel, weights: ChannelWeights, theta: FloatArray
) -> FloatArray:
    """``[gyro residual / sigma_gyro; attitude residual / sigma_st]`` (6T,) at ``theta`` (k,)."""
    return np.concatenate((problem.residuals(theta) / weights.gyro_std_rad_s, channel.residuals(theta, weights.attitude)))


def joint_chi2(problem: IdentificationProblem, channel: AttitudeChannel, weights: ChannelWeights, theta: FloatArray) -> float:
    """The chi-square of both channels at ``theta`` (k,): what :func:`_joint_fit` minimises."""
    r = _joint_residuals(problem, channel, weights, theta)
    return float(r @ r)


def _joint_fit(
    problem: IdentificationProblem, channel: AttitudeChannel, weights: ChannelWeights, start: FloatArray
) -> FloatArray:
    """Least squares on both channels (:func:`_joint_residuals`) from ``start`` (k,), analytic Jacobians, in the box."""
    params = problem.parameters

    def jacobian(x: FloatArray) -> FloatArray:
        return np.vstack((problem.jacobian(x) / weights.gyro_std_rad_s, channel.jacobian(x, weights.attitude)))

    result = least_squares(
        lambda x: _joint_residuals(problem, channel, weights, x),
        np.clip(start, params.lower, params.upper),
        jac=jacobian,
        bounds=(params.lower, params.upper),
        x_scale=params.scale,
        method="trf",
        ftol=step_ftol(3 * problem.n_samples + channel.n_values),
        max_nfev=MAX_ITERATIONS,
    )
    return np.asarray(result.x, dtype=float)


def _refined_on_both(
    problem: IdentificationProblem,
    channel: AttitudeChannel,
    weights: ChannelWeights,
    minima: list[FloatArray],
    starts: list[FloatArray],
) -> FloatArray:
    """The fit on both channels (:func:`_joint_fit`) from the best by both channels of the gyro's ``minima`` and the
    ``starts`` themselves that have every effect on; from a point with an effect switched off
    (:meth:`~estimators.parameters.WithEffects.switched_off`: a slosh without mass, whose other unknowns then move
    nothing) only if none is on, or if the fit from the best of those ends above it.

    From a point with the effect off the refinement cannot switch it on, and such a point (the nested model's fit,
    among the starts so that a candidate never fits worse than the model without it) can score best before any
    refinement. On fresh log 11713 (``paper6``, 50 Hz, an exact attitude, an 8.9 kg pendulum slosh on a rod near the
    base's x) the nested model's point scored 17,918 and every gyro minimum 17,989-19,112; refined from it the pendulum
    stayed without mass, refined from the best minimum it reached 17,280, the truth's value. The slosh had been fitted
    by its spring-mass model only, the attitude fitted its error model at no candidate (whiteness p 1e-32; 0.09 at the
    pendulum's fit), and the verdict, on the gyro alone, was ``none``. On 11775 (``orbit7``, 100 Hz, an exact
    attitude, 32 kg on a pendulum of 35 s) likewise: 35,830 at the nested point, refined to 0.26 kg of slosh at
    35,830; from the best scanned start 35,514, the truth's 35,518."""
    params = problem.parameters
    tried = [*minima, *(np.clip(x, params.lower, params.upper) for x in starts)]
    scores = [joint_chi2(problem, channel, weights, x) for x in tried]
    off = [isinstance(params, WithEffects) and params.switched_off(x) for x in tried]
    on = [i for i in range(len(tried)) if not off[i]]
    if not on or len(on) == len(tried):
        return _joint_fit(problem, channel, weights, tried[int(np.argmin(scores))])
    theta = _joint_fit(problem, channel, weights, tried[min(on, key=lambda i: scores[i])])
    value = joint_chi2(problem, channel, weights, theta)
    best_off = min((i for i in range(len(tried)) if off[i]), key=lambda i: scores[i])
    if value <= scores[best_off]:
        return theta
    other = _joint_fit(problem, channel, weights, tried[best_off])
    return other if joint_chi2(problem, channel, weights, other) < value else theta


def _scored(
    problem: IdentificationProblem,
    theta: FloatArray,
    model: IdentificationModel,
    effect: str | None,
    attitude: tuple[float | None, int],
    attitude_information: FloatArray | None,
    weights: ChannelWeights | None,
) -> ModelFit:
    """The fit at ``theta``: gyro residual, plausibility, and ``attitude`` (its chi-square or ``None``, its values).

    Plausibility allows for the Cramér-Rao covariance of the channels fitted: the gyro's (at ``weights``' gyro
    noise when given) plus ``attitude_information`` (k, k), the star tracker's Fisher information under the weights'
    (the baseline's) error model, when given."""
    residual = problem.residuals(theta, count=False)
    params = problem.parameters
    implausible: list[str] = []
    if effect is not None:
        assert isinstance(params, WithEffects)
        term = next(t for t in params.terms if t.name == effect)
        part = np.arange(params.n_params)[params.term_parts(np.arange(params.n_params))[term].astype(int)]
        information = problem.fisher(theta, None if weights is None else weights.gyro_std_rad_s)
        if attitude_information is not None:
            information = information + attitude_information
        covariance = np.linalg.pinv(information, rcond=1e-12, hermitian=True)[np.ix_(part, part)]
        implausible = term.implausible(params.term_parts(theta)[term], covariance, params.base_part(theta))
    return ModelFit(
        effects=model.effects,
        effect=effect,
        theta=np.asarray(theta, dtype=float),
        names=tuple(params.names),
        rss=float(residual @ residual),
        n_residuals=residual.size,
        n_params=params.n_params,
        attitude_chi2=attitude[0],
        n_attitude_values=attitude[1],
        physical=params.physical(theta),
        implausible=implausible,
        wall_time_s=0.0,
    )


def attitude_gyro_dependence(differences: FloatArray, gyro_residual: FloatArray, dt_s: FloatArray) -> tuple[float, float]:
    """Whether the attitude residual's steps carry the gyro's own noise: ``(rho, p)``, the correlation of their
    high-frequency parts and its two-sided p-value against independence.

    ``differences`` (T-1, 3), rad: the attitude residual's steps (:meth:`AttitudeChannel.differences`); ``gyro_residual``
    (T, 3), rad/s; ``dt_s`` (T-1,). The gyro's residual is taken to the same steps (mean of the step's two samples
    times its length), then both are differenced once more: that removes what a missing effect puts in both
    channels (slow), and leaves the noise. An independent attitude source (a star tracker, an exact attitude) gives
    ``rho`` near 0 (``sqrt(n) rho`` standard normal); an on-board estimate fused with this gyro follows the gyro
    between star-tracker updates, and its steps are the gyro's noise times the step: ``|rho|`` near 1.
    """
    gyro_steps = 0.5 * (gyro_residual[1:] + gyro_residual[:-1]) * dt_s[:, None]
    a = np.diff(differences, axis=0).ravel()
    b = np.diff(gyro_steps, axis=0).ravel()
    denominator = math.sqrt(float(a @ a) * float(b @ b))
    if denominator == 0.0:
        return 0.0, 1.0
    rho = float(a @ b) / denominator
    return rho, float(2.0 * norm.sf(abs(rho) * math.sqrt(a.size)))


@dataclass(frozen=True)
class AttitudeIndependence:
    """What :func:`independent_attitude_channel` found: the channel to use (``None``: the log has no attitude) and the
    dependence ``(rho, p)`` of the attitude's steps on the gyro's before (``raw``) and after (``coupled``) the
    coupling was taken out (``coupled`` is ``None`` when the attitude was independent as it came)."""

    channel: AttitudeChannel | None
    raw: tuple[float, float]
    coupled: tuple[float, float] | None = None
    too_short: bool = False  # dependent, but the log is too short to fit the coupling: the gyro alone

    def describe(self) -> str:
        """A sentence for the diagnosis's reason ("" when the attitude was independent of the gyro)."""
        if self.too_short:
            return (
                f"the attitude's steps follow the gyro's own noise (correlation {self.raw[0]:+.2f} of their high-frequency "
                f"parts, p = {self.raw[1]:.2g}): an attitude estimate fused with this gyro, and the log is too short to fit "
                f"its response to the gyro, so the verdict rests on the gyro alone"
            )
        if self.coupled is None:
            return ""
        return (
            f"the attitude's steps follow the gyro's own noise (correlation {self.raw[0]:+.2f} of their high-frequency "
            f"parts, p = {self.raw[1]:.2g}): an attitude estimate fused with this gyro, so the attitude is compared given "
            f"the gyro (its response to the gyro's error taken out; correlation left {self.coupled[0]:+.2f})"
        )


def _residual_steps(
    model: IdentificationModel, log: MeasurementLog, theta: FloatArray
) -> tuple[AttitudeChannel, IdentificationProblem, FloatArray, FloatArray] | None:
    """``model``'s attitude channel on ``log`` referenced at ``theta`` (k,), its problem, the gyro residual (T, 3) and
    the attitude residual's steps (T-1, 3) there; ``None`` without attitude in the log."""
    channel = AttitudeChannel.of(model, log, reference=theta)
    if channel is None:
        return None
    problem = model.problem(log)
    return channel, problem, problem.residuals(theta, count=False).reshape(-1, 3), channel.differences(theta)


def attitude_dependence(model: IdentificationModel, log: MeasurementLog, theta: FloatArray) -> tuple[float, float] | None:
    """:func:`attitude_gyro_dependence` ``(rho, p)`` of the attitude's residual steps and the gyro's at ``theta`` (k)
    of ``model`` on ``log``, the attitude as it comes (no coupling fitted); ``None`` without attitude in the log."""
    steps = _residual_steps(model, log, theta)
    return None if steps is None else attitude_gyro_dependence(steps[3], steps[2], np.diff(log.t_s))


def independent_attitude_channel(
    model: IdentificationModel, log: MeasurementLog, theta: FloatArray, alpha: float
) -> AttitudeIndependence:
    """The attitude channel of ``model`` on ``log`` that measures what the gyro does not: as it comes when its residual
    steps at ``theta`` (k,) do not follow the gyro's noise (:func:`attitude_gyro_dependence` p-value >= ``alpha``),
    else given the gyro, with the :class:`~estimators.attitude_channel.GyroCoupling` fitted at ``theta``
    (:func:`~estimators.attitude_channel.choose_gyro_coupling`).

    An attitude fused on board with this gyro follows the gyro between star-tracker corrections, so its steps carry
    the gyro's noise; counting them as a second measurement counted that noise twice (clean logs named gyro_scale or
    slosh), and dropping them lost what the star tracker inside the fusion measures (a gyro bias on a heavy base was
    named initial_momentum: on the gyro alone the two fit within 2 chi-square units)."""
    steps = _residual_steps(model, log, theta)
    if steps is None:
        return AttitudeIndependence(None, (0.0, 1.0))
    channel, problem, gyro_residual, differences = steps
    dt_s = np.diff(log.t_s)
    raw = attitude_gyro_dependence(differences, gyro_residual, dt_s)
    if raw[1] >= alpha:
        return AttitudeIndependence(channel, raw)
    if log.n_samples < min_coupling_samples(float(np.median(dt_s))):
        return AttitudeIndependence(None, raw, too_short=True)
    # the gyro's error against the midpoint prediction (whose encoder noise the attitude residual shares) and against the
    # gyro channel's own (the joint-rate sensors), the instrument (AttitudeChannel.sensor_gyro_steps)
    gyro_steps = channel.gyro_steps(channel.problem.base_rate(np.atleast_2d(theta), count=False))[0]
    sensor_steps = channel.sensor_gyro_steps(problem.base_rate(np.atleast_2d(theta), count=False)[0])
    coupling = choose_gyro_coupling(differences, gyro_steps, sensor_steps, float(np.median(dt_s)))
    coupled = AttitudeChannel.of(model, log, coupling, reference=theta)
    assert coupled is not None
    return AttitudeIndependence(coupled, raw, attitude_gyro_dependence(coupled.differences(theta), gyro_residual, dt_s))


#: how many of a term's grid candidates (:meth:`~estimators.models.effect_models.EffectTerm.grid`) start local fits
GRID_STARTS = 3

#: candidates per batched evaluation of a grid (:func:`best_of_grid`): measured with the pendulum's scan of 412: all
#: at once, on a 60 s log at 50 Hz, they allocated arrays of 100 MB and cost 1.5 times as much as in batches of 64;
#: batches of 32 cost 0.61-0.74 times what batches of 64 did
#: (on the benchmark's log, ``benchmarks/diagnose_speed.py``), of 16 about as much as 32. The scores do not depend on
#: the batch with one BLAS thread, as :func:`~estimators.diagnostics.diagnose.diagnose` runs (with more, the
#: projection's product may differ in its last bit)
GRID_BATCH = 32


def best_of_grid(
    problem: IdentificationProblem,
    candidates: list[FloatArray],
    channel: AttitudeChannel | None = None,
    weights: ChannelWeights | None = None,
    nuisance: FloatArray | None = None,
) -> list[FloatArray]:
    """The :data:`GRID_STARTS` candidates (each (k,)) of lowest score, scored in batched evaluations of
    :data:`GRID_BATCH` candidates: the gyro's chi-square, plus the attitude channel's with ``channel`` and ``weights``
    (an effect may show in one channel only).

    With ``nuisance`` (:func:`nuisance_basis`: an orthonormal basis of the whitened residual's Jacobian columns in the
    model's own unknowns, which the fits from these starts refit, at the fit without the candidate's effect), the score
    is profiled over those unknowns to first order: each candidate's residual (both channels, whitened) less its
    projection on the basis. Scored at the baseline's own unknowns instead, a candidate is judged where the missing effect
    has dragged them: held-out log 9705's slow slosh (a 34 s pendulum) had pulled the fuel 34 std off, and there the true
    pendulum scored worse than the baseline, so no start was near it (the fit ended at 92 kg and 1.6 Hz, a likelihood
    ratio of 111 against about 1670 from the truth). Profiled, the scan ranks the true frequency first."""
    if len(candidates) <= GRID_STARTS:
        return candidates
    points = np.clip(np.array(candidates), problem.parameters.lower, problem.parameters.upper)
    attitude = channel is not None and weights is not None
    sigma = weights.gyro_std_rad_s if weights is not None else 1.0
    scores = []
    for i in range(0, len(points), GRID_BATCH):
        batch = points[i : i + GRID_BATCH]
        rows = ((problem.predict(batch, count=False) - problem.measured) / sigma).reshape(len(batch), -1)
        if attitude:
            assert channel is not None and weights is not None
            rows = np.hstack((rows, channel.residual_rows(batch, weights.attitude)))
        score = np.sum(rows * rows, axis=1)
        if nuisance is not None:
            projected = rows @ nuisance
            score -= np.sum(projected * projected, axis=1)
        scores.append(score)
    order = np.argsort(np.concatenate(scores))
    return [points[i] for i in order[:GRID_STARTS]]


def nuisance_basis(
    problem: IdentificationProblem, theta: FloatArray, channel: AttitudeChannel | None, weights: ChannelWeights | None
) -> FloatArray:
    """An orthonormal basis (rows, k) of the residual's Jacobian columns at ``theta`` (k,), both channels whitened and
    stacked as :func:`best_of_grid` scores them (the gyro's alone without ``channel`` and ``weights``). A candidate
    effect at its nominal (off) predicts what the model without it does, so the model's own basis serves every
    candidate's scan."""
    sigma = weights.gyro_std_rad_s if weights is not None else 1.0
    jac = problem.jacobian(theta, count=False) / sigma
    if channel is not None and weights is not None:
        jac = np.vstack((jac, channel.jacobian(theta, weights.attitude)))
    u, s, _ = np.linalg.svd(jac, full_matrices=False)
    return u[:, s > s[0] * np.sqrt(np.finfo(float).eps)]


def difference_noise_std(residual: FloatArray) -> float:
    """The white part of a residual's noise (T, c): ``sqrt(mean(diff^2) / 2)``, blind to slow structure (an effect's
    residual changes little from one sample to the next, white noise fully)."""
    steps = np.diff(np.asarray(residual, dtype=float), axis=0)
    return float(np.sqrt(np.mean(steps * steps) / 2.0))
