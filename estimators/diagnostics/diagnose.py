"""Which physical effect is the model missing? Re-identify with each candidate effect and rank them.

For a model (robot, parameterisation, effects already in it) and a log, :func:`diagnose`:

1. fits the model as it is (the *baseline*, by default with the ``hybrid`` estimator);
2. for each candidate effect of the catalogue (:mod:`estimators.models.effect_models`) not yet in the model,
   fits the model with that effect added, by least squares from the baseline (and from the term's own
   starting points: several slosh frequencies, a light payload), keeping the best;
3. scores every fit on the whole likelihood: the gyro residuals, ``RSS / sigma^2`` with ``sigma`` the
   residual std of the best-fitting model (``sqrt(RSS / (3T - k))``), plus, when the log has attitude,
   the star tracker's rotation against the model's (:mod:`estimators.attitude_channel`), which
   sees the integral of the base rate (a slow torque, a momentum) far more sharply than the gyro and
   is blind to gyro errors (bias, scale, delay), so it also tells a biased gyro from a real rotation. With
   attitude, every fit (the baseline refitted from the estimator's result) minimises both channels
   together, weighted by their noise (:class:`ChannelWeights`: the gyro's from the baseline's residual, the
   star tracker's from the data). For a candidate:

   * ``lr_statistic = X_baseline - X_candidate``, chi-square with ``k_e`` degrees of freedom when the
     effect is absent (nested models): ``p_value``; *significant* below ``alpha / (number of
     candidates)`` (Bonferroni);
   * ``bic = X + k ln(n)`` (Schwarz), ``delta_bic`` relative to the baseline (negative is better);
   * *plausible*: no reason from :meth:`~estimators.models.effect_models.EffectTerm.implausible` (on a search
     bound, unphysical payload, no slosh mass);
   * residual reduction, residual RMS and fit % (gyro channel);

4. gives a verdict: the candidate with the lowest BIC among the significant and plausible ones, the *leader*,
   replaced

   * by a candidate that contains it as a special case (e.g. ``external_torque`` for ``initial_momentum``)
     when that one is significantly better by its own likelihood-ratio test, at ``alpha`` divided by the
     number of such containers compared (:func:`_prefer_nesting`);
   * else by a candidate that *encompasses* it (:func:`_prefer_encompassing`): a significant and plausible
     candidate that fits better than the leader but pays more unknowns in the BIC is fitted together with the
     leader; if adding it to the leader lowers the chi-square significantly and adding the leader to it does
     not (each at ``alpha`` over the number of such challengers), it explains what the leader explains and
     more. (A MEMS gyro's scale and misalignment, 9 unknowns, lowered the chi-square by 74 where a delay, 1
     unknown, lowered it by 19: BIC named the delay; with both, the delay added nothing.)

   The verdict names it if it explains at least :data:`EXPLAINED_FRACTION` of the baseline's excess over the
   noise (``X_baseline - (n - k)``, :func:`explained_fraction`) or if what it leaves is consistent with the
   noise: its gyro residual passes every test of :func:`~estimators.diagnostics.residuals.analyse_residuals`
   (white, uncorrelated with the inputs, no failing segment) and, with attitude, the star tracker's
   chi-square is below the ``1 - alpha`` quantile of its count (``attitude_p_value >= alpha``). The excess
   itself varies by about ±134 from log to log through the star tracker's part (the gyro's chi-square is
   scaled to the best fit's residual, so the gyro's part is at its count by construction), so a share of it
   is no test when it is that small. ``"none"`` when no candidate is significant and the
   baseline residual is white (:func:`~estimators.diagnostics.residuals.analyse_residuals`); ``"unexplained"``
   otherwise, with the residual structure described (dominant frequencies, correlated inputs, where in time).

``Diagnosis.to_dict()`` is the ``diagnose --out`` JSON: ``verdict`` (a catalogue name, ``none`` or
``unexplained``), ``candidates`` (the named one first, then by BIC; each with ``effect`` and its figures) and
``combined`` (the joint fits of the encompassing test).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2, norm
from threadpoolctl import threadpool_limits

from estimators.attitude_channel import AttitudeChannel, AttitudeNoise
from estimators.base import Estimator
from estimators.diagnostics.residuals import ResidualAnalysis, analyse_residuals
from estimators.estimate import Estimate
from estimators.least_squares import LevenbergMarquardt, interior_start
from estimators.models.effect_models import EFFECT_TERMS
from estimators.parameters import WithEffects
from estimators.problem import IdentificationModel, IdentificationProblem
from estimators.registry import make_estimator
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import jsonable
from spaceid_gym.log import MeasurementLog

#: the candidates tried by default: the whole catalogue
DEFAULT_CANDIDATES: tuple[str, ...] = tuple(EFFECT_TERMS)

#: a candidate is named only if it explains at least this fraction of the baseline's excess over the noise
EXPLAINED_FRACTION = 0.3

#: the verdicts besides a catalogue name
NO_MISSING_EFFECT = "none"
UNEXPLAINED = "unexplained"


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
    ``bic``, ``delta_bic`` (to the baseline), ``lr_statistic``, ``p_value``, ``significant``,
    ``explained_fraction`` (of the baseline's excess over the noise, :func:`explained_fraction`) and
    ``attitude_p_value`` (of the star tracker's chi-square against its count, chi-square with that many degrees
    of freedom; ``nan`` without attitude)."""

    bic: float = math.nan
    delta_bic: float = math.nan
    lr_statistic: float = math.nan
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
            "p_value": self.p_value,
            "significant": self.significant,
            "explained_fraction": self.explained_fraction,
            "attitude_p_value": self.attitude_p_value,
        }


@dataclass(frozen=True)
class ChannelWeights:
    """The noise of the two channels, which weights them in a joint fit: the gyro's per-sample std (rad/s, per
    axis) and the attitude residual's error model (:class:`~estimators.attitude_channel.AttitudeNoise`)."""

    gyro_std_rad_s: float
    attitude: AttitudeNoise

    def to_dict(self) -> dict[str, Any]:
        return {"gyro_std_rad_s": self.gyro_std_rad_s, **self.attitude.to_dict()}


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
        physical: the fitted quantities (base and effects), as in the estimate file.
        implausible: reasons why the fitted effect is not physical (empty if plausible).
        wall_time_s: time of the fit.
        chi2: both channels' chi-square (:func:`_score`); ``residual_consistent``: whether the fit's gyro residual
            passes every test of :func:`~estimators.diagnostics.residuals.analyse_residuals` (``None``: not analysed).
        attitude_white_p: p-value of the attitude residual, whitened by its error model, against unit white noise in
            the effects' band (:func:`low_frequency_p_value`): small when the attitude source's errors are not what
            the model assumes (``nan``: no attitude).
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
    attitude_noise: AttitudeNoise | None = None  # the attitude error model refitted at this fit

    @property
    def residual_rms_rad_s(self) -> float:
        """RMS of the gyro residual (rad/s)."""
        return math.sqrt(self.rss / self.n_residuals)

    @property
    def plausible(self) -> bool:
        return not self.implausible

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
            "chi2": self.chi2,
            "residual_consistent": self.residual_consistent,
            "attitude_white_p": self.attitude_white_p,
            **self.scores(),
            "plausible": self.plausible,
            "implausible": list(self.implausible),
            "parameters": {n: float(v) for n, v in zip(self.names, self.theta, strict=True)},
            "physical": jsonable(self.physical),
            "wall_time_s": self.wall_time_s,
        }


@dataclass
class Diagnosis:
    """What :func:`diagnose` found.

    Attributes:
        verdict: the missing effect's name, :data:`NO_MISSING_EFFECT` or :data:`UNEXPLAINED`.
        baseline: the model as given, fitted.
        candidates: one fit per candidate effect: the named one first, then by BIC (lowest first).
        analysis: residual analysis of the baseline fit.
        noise_std_rad_s: the gyro noise std used for the scores (residual std of the best model).
        alpha: the family-wise significance level; ``reason``: why this verdict, in a sentence.
        weights: the noise levels weighting the gyro and the attitude channel in every fit (``None``: the log has
            no attitude, the gyro alone was fitted).
        combined: the leader fitted together with each challenger (:func:`_prefer_encompassing`; often none).
        attitude_rejected: the log has attitude, but its residual fitted its error model at no candidate, so this
            diagnosis rests on the gyro alone (``weights`` is ``None``; the reason says so).
    """

    verdict: str
    baseline: ModelFit
    candidates: list[ModelFit]
    analysis: ResidualAnalysis
    noise_std_rad_s: float
    alpha: float
    reason: str
    weights: ChannelWeights | None
    baseline_estimate: Estimate | None = field(default=None, repr=False)
    combined: list[ModelFit] = field(default_factory=list)
    attitude_rejected: bool = False

    @property
    def attitude_consistent(self) -> bool:
        """Whether the attitude residual, whitened by its error model, is white at some fit (the baseline or a
        candidate) at level ``alpha``: if at none, the attitude source is not what the model assumes."""
        return any(f.attitude_white_p >= self.alpha for f in [self.baseline, *self.candidates])

    def fit_of(self, effect: str | None) -> ModelFit | None:
        """The candidate fit of ``effect``, if it was tried."""
        return next((c for c in self.candidates if c.effect == effect), None)

    @property
    def best(self) -> ModelFit | None:
        """The named candidate, if the verdict names one."""
        return self.fit_of(self.verdict)

    def to_dict(self) -> dict[str, Any]:
        """The ``diagnose --out`` JSON."""
        return {
            "verdict": self.verdict,
            "reason": self.reason,
            "alpha": self.alpha,
            "noise_std_rad_s": self.noise_std_rad_s,
            "attitude_channel": None if self.weights is None else self.weights.to_dict(),
            "attitude_rejected": self.attitude_rejected,
            "baseline": self.baseline.to_dict(),
            "candidates": [c.to_dict() for c in self.candidates],
            "combined": [c.to_dict() for c in self.combined],
            "residual_analysis": self.analysis.to_dict(),
            "structure": self.analysis.structure_description(),
        }

    def ranking_table(self) -> list[dict[str, Any]]:
        """One row per candidate (the named one first, then by BIC) for a report table."""
        return [
            {
                "effect": c.effect,
                "delta BIC": f"{c.delta_bic:.1f}",
                "LR statistic": f"{c.lr_statistic:.1f}",
                "p-value": f"{c.p_value:.2g}",
                "significant": "yes" if c.significant else "no",
                "plausible": "yes" if c.plausible else "no: " + "; ".join(c.implausible),
                "residual RMS (rad/s)": f"{c.residual_rms_rad_s:.3g}",
                "attitude chi-square / values": "no attitude"
                if c.attitude_chi2 is None
                else f"{c.attitude_chi2:.0f} / {c.n_attitude_values}",
                "explained": f"{100 * c.explained_fraction:.0f} %",
                "leaves noise (gyro tests)": {None: "not tested", True: "yes", False: "no"}[c.residual_consistent],
            }
            for c in self.candidates
        ]


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
    taken as known.
    """
    begin = time.perf_counter()
    problem = model.problem(log) if problem is None else problem
    if weights is None:
        channel = None
    elif channel is None:
        channel = AttitudeChannel.of(model, log)
    estimate = None
    if estimator is not None:
        estimate = estimator.fit_problem(problem)
        theta = estimate.theta
    else:
        if not starts:
            raise SpaceIdInputError("fit_model: give an estimator or at least one start")
        polish = LevenbergMarquardt(max_iterations=MAX_ITERATIONS)
        results = [polish.polish(problem, start).theta for start in starts]
        if channel is not None:
            assert weights is not None
            # the gyro's minimum nearest each start, the best of them by both channels, refined on both; then the
            # attitude error model refitted at this model's fit and the fit refined under it (profile likelihood)
            tried = [*results, *(np.clip(x, problem.parameters.lower, problem.parameters.upper) for x in starts)]
            scores = [_joint_chi2(problem, channel, weights, x) for x in tried]
            theta = _joint_fit(problem, channel, weights, tried[int(np.argmin(scores))])
            if profile_noise:
                own = ChannelWeights(weights.gyro_std_rad_s, channel.estimate_noise(theta, weights.attitude))
                theta = _joint_fit(problem, channel, own, theta)
        else:
            scores = [float(r @ r) for r in (problem.residuals(x, count=False) for x in results)]
            theta = results[int(np.argmin(scores))]
    attitude_chi2, attitude_information, attitude_white_p, noise = None, None, math.nan, None
    if channel is not None:
        assert weights is not None
        if not profile_noise:
            noise = weights.attitude
        elif estimator is None:
            noise = own.attitude
        else:
            noise = channel.estimate_noise(theta, weights.attitude)
        whitened = channel.residuals(theta, noise)
        attitude_chi2 = channel.profile_chi2(theta, noise, weights.attitude)
        attitude_information = channel.fisher(theta, noise)
        attitude_white_p = low_frequency_p_value(whitened.reshape(-1, 3), ATTITUDE_BLOCK_S / float(np.mean(np.diff(log.t_s))))
    n_attitude = 0 if channel is None else channel.n_values
    fit = _scored(problem, theta, model, effect, (attitude_chi2, n_attitude), attitude_information, weights)
    fit.wall_time_s = time.perf_counter() - begin
    fit.attitude_white_p = attitude_white_p
    fit.attitude_noise = noise
    return fit, estimate


#: accepted least-squares steps per start of a candidate fit
MAX_ITERATIONS = 30

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


def _joint_chi2(problem: IdentificationProblem, channel: AttitudeChannel, weights: ChannelWeights, theta: FloatArray) -> float:
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
        max_nfev=MAX_ITERATIONS,
    )
    return np.asarray(result.x, dtype=float)


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
    noise when given) plus ``attitude_information`` (k, k), the star tracker's Fisher information, when given."""
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


def candidate_model(model: IdentificationModel, effect: str) -> IdentificationModel:
    """``model`` with ``effect`` added (same robot, parameterisation and noise setting)."""
    params = model.parameters
    base = params.base if isinstance(params, WithEffects) else params
    return IdentificationModel(model.robot, base, model.noise_std_rad_s, effects=[*model.effects, effect])


@threadpool_limits.wrap(limits=1, user_api="blas")  # tall, thin Jacobians: BLAS threads only slow their SVDs down
def diagnose(
    model: IdentificationModel,
    log: MeasurementLog,
    candidates: tuple[str, ...] | list[str] | None = None,
    estimator: Estimator | None = None,
    alpha: float = 0.01,
) -> Diagnosis:
    """Rank the candidate effects for ``model`` on ``log``; see the module docstring.

    Args:
        model: the model as it is (its effects are kept in every candidate).
        log: the measurement window.
        candidates: effect names to try (default: every catalogue effect not in the model).
        estimator: fits the baseline (default ``hybrid`` with seed 0).
        alpha: family-wise significance level of the likelihood-ratio tests.
    """
    if not 0.0 < alpha < 1.0:
        raise SpaceIdInputError(f"alpha: expected a level in (0, 1), got {alpha!r}")
    present = {spec.partition("[")[0] for spec in model.effects}
    names = [c for c in (candidates if candidates is not None else DEFAULT_CANDIDATES) if c not in present]
    unknown = [c for c in names if c not in EFFECT_TERMS]
    if unknown:
        raise SpaceIdInputError(f"candidates: unknown effects {unknown}; expected names from {', '.join(EFFECT_TERMS)}")
    baseline, estimate = fit_model(model, log, estimator or make_estimator("hybrid"))
    channel = AttitudeChannel.of(model, log)
    dependence = None
    if channel is not None:
        gyro_residual = model.problem(log).residuals(baseline.theta, count=False).reshape(-1, 3)
        dependence = attitude_gyro_dependence(channel.differences(baseline.theta), gyro_residual, np.diff(log.t_s))
        if dependence[1] >= alpha:
            dependence = None
        else:
            channel = None
    diagnosis = _diagnose(model, log, names, baseline, alpha, channel)
    if dependence is not None:
        diagnosis.reason = (
            f"the attitude's steps follow the gyro's own noise (correlation {dependence[0]:+.2f} of their high-frequency "
            f"parts, p = {dependence[1]:.2g}): an attitude estimate fused with this gyro, not an independent measurement, "
            f"so the verdict rests on the gyro alone; {diagnosis.reason}"
        )
        diagnosis.attitude_rejected = True
    if channel is not None and not diagnosis.attitude_consistent:
        p_best = max(f.attitude_white_p for f in [diagnosis.baseline, *diagnosis.candidates])
        diagnosis = _diagnose(model, log, names, baseline, alpha, None)
        diagnosis.reason = (
            f"the attitude residual fits its error model at no candidate (whiteness p <= {p_best:.2g}): the attitude source "
            f"is not what the model assumes, so the verdict rests on the gyro alone; {diagnosis.reason}"
        )
        diagnosis.attitude_rejected = True
    diagnosis.baseline_estimate = estimate
    return diagnosis


def _diagnose(
    model: IdentificationModel,
    log: MeasurementLog,
    names: list[str],
    baseline: ModelFit,
    alpha: float,
    channel: AttitudeChannel | None,
) -> Diagnosis:
    """:func:`diagnose` from the estimator's ``baseline`` fit (gyro alone), with the attitude ``channel`` or without."""
    sigma0 = math.sqrt(baseline.rss / (baseline.n_residuals - baseline.n_params))
    weights = None
    if channel is not None:
        # both channels from here on; the star tracker's noise from the data, the baseline refitted to both
        weights = ChannelWeights(sigma0, channel.estimate_noise(baseline.theta))
        # the baseline refitted on both channels with its error model, twice: the second pass is what every candidate
        # gets from the baseline's state (a fit under its error model, the error model refitted, the fit refined), so
        # that no candidate gains from one more round of the alternation than the baseline had
        for _ in range(2):
            baseline = fit_model(model, log, starts=[baseline.theta], weights=weights, channel=channel, profile_noise=True)[0]
            assert baseline.attitude_noise is not None
            weights = ChannelWeights(sigma0, baseline.attitude_noise)
        # the baseline's own error model weights every candidate's fit and is the reference of the log-determinants
        baseline.attitude_chi2 = channel.chi2(baseline.theta, weights.attitude)
    fits = []
    for name in names:
        extended = candidate_model(model, name)
        params = extended.parameters
        assert isinstance(params, WithEffects)
        term = params.terms[-1]
        # from the baseline fit, and once from the default start (a missing effect can drag the baseline far off)
        restart = interior_start(params)[: len(baseline.theta)]
        k_base = params.base.n_params
        problem = extended.problem(log)
        grid = [np.concatenate((baseline.theta, s)) for s in term.grid(baseline.theta[:k_base])]
        starts = best_of_grid(problem, grid, None if channel is None else AttitudeChannel.of(extended, log), weights)
        starts.append(np.concatenate((restart, term.starts(restart[:k_base])[0])))
        starts.append(np.concatenate((baseline.theta, term.nominal)))  # the baseline itself: the nested model's fit
        fits.append(fit_model(extended, log, starts=starts, effect=name, weights=weights, problem=problem, profile_noise=True)[0])
    gyro_residual = model.problem(log).residuals(baseline.theta, count=False).reshape(-1, 3)
    sigma = _score(baseline, fits, alpha, difference_noise_std(gyro_residual))
    combined = _fit_challengers(model, log, baseline, fits, alpha, weights, sigma)
    for fit in fits:
        if fit.nameable:
            analysed = _analyse_fit(candidate_model(model, str(fit.effect)), log, fit.theta, sigma)
            fit.residual_consistent = analysed.consistent_with_noise
    analysis = _analyse_fit(model, log, baseline.theta, sigma)
    verdict, reason = _verdict(baseline, fits, analysis, alpha, combined)
    fits.sort(key=lambda f: (f.effect != verdict, f.bic))
    return Diagnosis(verdict, baseline, fits, analysis, sigma, alpha, reason, weights, combined=combined)


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


#: how many of a term's grid candidates (:meth:`~estimators.models.effect_models.EffectTerm.grid`) start local fits
GRID_STARTS = 3


def best_of_grid(
    problem: IdentificationProblem,
    candidates: list[FloatArray],
    channel: AttitudeChannel | None = None,
    weights: ChannelWeights | None = None,
) -> list[FloatArray]:
    """The :data:`GRID_STARTS` candidates (each (k,)) of lowest cost, scored in one batched evaluation: the gyro's
    chi-square, plus the attitude channel's with ``channel`` and ``weights`` (an effect may show in one channel only)."""
    if len(candidates) <= GRID_STARTS:
        return candidates
    points = np.clip(np.array(candidates), problem.parameters.lower, problem.parameters.upper)
    scores = problem.cost(points, count=False)
    if channel is not None and weights is not None:
        scores = scores * (3 * problem.n_samples) / weights.gyro_std_rad_s**2 + channel.chi2s(points, weights.attitude)
    order = np.argsort(scores)
    return [points[i] for i in order[:GRID_STARTS]]


def _analyse_fit(model: IdentificationModel, log: MeasurementLog, theta: FloatArray, sigma: float) -> ResidualAnalysis:
    """The residual tests of ``model`` at ``theta`` (k,) on ``log``'s gyro channel, with noise std ``sigma`` (rad/s)."""
    residual = model.problem(log).residuals(theta, count=False).reshape(-1, 3)
    return analyse_residuals(
        log.t_s,
        log.omega_base_body_rad_s,
        log.omega_base_body_rad_s + residual,
        log.q_rad,
        log.dq_rad_s,
        noise_std=np.full(3, sigma),
    )


def _fit_challengers(
    model: IdentificationModel,
    log: MeasurementLog,
    baseline: ModelFit,
    fits: list[ModelFit],
    alpha: float,
    weights: ChannelWeights | None,
    sigma: float,
) -> list[ModelFit]:
    """The leader (:func:`_leader`) fitted together with each of its challengers (:func:`_challengers`).

    Each joint fit starts from both fits and from each with the other effect at its nominal (off), and is scored
    with the gyro noise std ``sigma`` (rad/s) of the other fits: ``chi2``, and ``lr_statistic`` / ``p_value``
    against the leader (adding the challenger to it); its ``effect`` is the challenger."""
    named = [f for f in fits if f.nameable]
    if not named:
        return []
    leader = _leader(named, alpha)
    k0 = baseline.n_params
    combined = []
    for challenger in _challengers(leader, named):
        both = candidate_model(candidate_model(model, str(leader.effect)), str(challenger.effect))
        params = both.parameters
        assert isinstance(params, WithEffects)
        leader_off, challenger_off = (term.nominal for term in params.terms[-2:])
        leader_base, leader_term = leader.theta[:k0], leader.theta[k0:]
        challenger_base, challenger_term = challenger.theta[:k0], challenger.theta[k0:]
        starts = [
            np.concatenate((leader_base, leader_term, challenger_term)),
            np.concatenate((challenger_base, leader_term, challenger_term)),
            np.concatenate((leader_base, leader_term, challenger_off)),
            np.concatenate((challenger_base, leader_off, challenger_term)),
        ]
        fit = fit_model(both, log, starts=starts, effect=challenger.effect, weights=weights, profile_noise=True)[0]
        fit.chi2 = _chi2(fit, sigma * sigma)
        fit.lr_statistic = leader.chi2 - fit.chi2
        fit.p_value = nested_p_value(leader, fit)
        combined.append(fit)
    return combined


def difference_noise_std(residual: FloatArray) -> float:
    """The white part of a residual's noise (T, c): ``sqrt(mean(diff^2) / 2)``, blind to slow structure (an effect's
    residual changes little from one sample to the next, white noise fully)."""
    steps = np.diff(np.asarray(residual, dtype=float), axis=0)
    return float(np.sqrt(np.mean(steps * steps) / 2.0))


def _score(baseline: ModelFit, fits: list[ModelFit], alpha: float, white_std: float | None = None) -> float:
    """Fill in the scores of every fit; returns the gyro noise std used (rad/s).

    The likelihood-ratio tests scale the gyro's chi-square by the best fit's residual variance; the explained
    fractions by ``white_std`` (rad/s, :func:`difference_noise_std`; default the same variance), so that
    structure no candidate removes (a disturbance outside the catalogue) counts in the excess over the noise
    instead of being absorbed by it."""
    everything = [baseline, *fits]
    sigma2 = min(f.rss / (f.n_residuals - f.n_params) for f in everything)
    for f in everything:
        f.chi2 = _chi2(f, sigma2)
    n = baseline.n_residuals + baseline.n_attitude_values
    for f in everything:
        f.bic = f.chi2 + f.n_params * math.log(n)
        f.delta_bic = f.bic - baseline.bic
        if f.attitude_chi2 is not None:
            f.attitude_p_value = float(chi2.sf(f.attitude_chi2, f.n_attitude_values))
    white2 = sigma2 if white_std is None else max(white_std * white_std, sigma2 * 1e-6)
    excess = _chi2(baseline, white2) - (n - baseline.n_params)
    for f in fits:
        k = f.n_params - baseline.n_params
        f.lr_statistic = baseline.chi2 - f.chi2
        f.p_value = float(chi2.sf(max(f.lr_statistic, 0.0), k))
        f.significant = f.p_value < alpha / max(len(fits), 1)
        f.explained_fraction = explained_fraction(_chi2(baseline, white2) - _chi2(f, white2), excess)
    return math.sqrt(sigma2)


def _chi2(fit: ModelFit, sigma2: float) -> float:
    """The fit's chi-square: gyro residuals over the noise variance ``sigma2`` ((rad/s)^2), plus the attitude channel's."""
    return fit.rss / sigma2 + (fit.attitude_chi2 or 0.0)


def _verdict(
    baseline: ModelFit,
    fits: list[ModelFit],
    analysis: ResidualAnalysis,
    alpha: float,
    combined: list[ModelFit] | tuple[ModelFit, ...] = (),
) -> tuple[str, str]:
    """The verdict and its reason (see the module docstring); ``combined``: from :func:`_fit_challengers`."""
    named = [f for f in fits if f.nameable]
    if named:
        lowest = min(named, key=lambda f: f.bic)
        leader = _leader(named, alpha)
        best, encompassing = _prefer_encompassing(leader, named, combined, alpha)
        explains = best.explained_fraction >= EXPLAINED_FRACTION
        if explains or (best.residual_consistent and not best.attitude_p_value < alpha):
            why = [
                f"adding {best.effect} lowers the chi-square by {best.lr_statistic:.1f} (p = {best.p_value:.2g}, BIC "
                f"{best.delta_bic:+.1f}) and "
                + (
                    f"explains {100 * best.explained_fraction:.0f} % of the excess over the noise"
                    if explains
                    else "leaves a residual consistent with the noise (gyro: every residual test passes; star tracker: "
                    f"p = {best.attitude_p_value:.2g} against its count)"
                )
            ]
            if leader is not lowest and best is leader:
                why.append(
                    f"it contains {lowest.effect} (lower BIC) and fits significantly better (likelihood ratio "
                    f"{lowest.chi2 - leader.chi2:.1f}, p = {nested_p_value(lowest, leader):.2g})"
                )
            if encompassing:
                why.append(encompassing)
            return str(best.effect), "; ".join(why)
        left = "a structured gyro residual" if best.residual_consistent is False else "a residual"
        return UNEXPLAINED, (
            f"the best significant candidate ({best.effect}) explains only {100 * best.explained_fraction:.0f} % of the "
            f"excess over the noise and leaves {left} (star tracker: p = {best.attitude_p_value:.2g} against its "
            f"count); {analysis.structure_description()}"
        )
    significant = [f for f in fits if f.significant]
    if not significant and analysis.white:
        return NO_MISSING_EFFECT, "no candidate is significant and the residual is consistent with white noise"
    if significant:
        rejected = "; ".join(f"{f.effect}: {', '.join(f.implausible)}" for f in significant)
        return UNEXPLAINED, f"the significant candidates are not physical ({rejected}); {analysis.structure_description()}"
    return UNEXPLAINED, f"no candidate is significant but the residual is structured: {analysis.structure_description()}"


#: chi-square units a joint fit may end above the better of its two parts by rounding (see :func:`_prefer_encompassing`)
JOINT_FIT_SLACK = 0.01


def _leader(named: list[ModelFit], alpha: float) -> ModelFit:
    """Of the significant and plausible candidates, the lowest BIC, or a container of it (:func:`_prefer_nesting`)."""
    return _prefer_nesting(min(named, key=lambda f: f.bic), named, alpha)


def _challengers(leader: ModelFit, named: list[ModelFit]) -> list[ModelFit]:
    """The named candidates that fit better than ``leader`` (lower chi-square), neither containing the other."""

    def nested(a: ModelFit, b: ModelFit) -> bool:
        return str(a.effect) in EFFECT_TERMS[str(b.effect)].nests

    return [f for f in named if f.chi2 < leader.chi2 and not nested(leader, f) and not nested(f, leader)]


def _prefer_encompassing(
    leader: ModelFit, named: list[ModelFit], combined: list[ModelFit] | tuple[ModelFit, ...], alpha: float
) -> tuple[ModelFit, str]:
    """``leader``, or a challenger that encompasses it, and a sentence saying so ("" if none does).

    ``combined``: the leader fitted with each challenger (:func:`_fit_challengers`). A challenger encompasses the
    leader when, fitted together, adding the challenger to the leader lowers the chi-square significantly, at
    ``alpha / m`` with ``m`` the number of challengers, and adding the leader to the challenger does not, at
    ``alpha`` (not divided: more challengers must not make "adds nothing" easier to pass); each chi-square with
    the number of unknowns added. A joint fit that ends more than :data:`JOINT_FIT_SLACK` above the better of
    the two alone has not found the joint optimum and decides nothing. Of several, the lowest BIC.
    """
    challengers = _challengers(leader, named)
    level = alpha / max(len(challengers), 1)
    winners = []
    for challenger in challengers:
        pair = (str(leader.effect), str(challenger.effect))
        both = next((c for c in combined if c.effects[-2:] == pair), None)
        if both is None or not both.chi2 <= min(leader.chi2, challenger.chi2) + JOINT_FIT_SLACK:
            continue
        if nested_p_value(leader, both) < level and nested_p_value(challenger, both) >= alpha:
            winners.append((challenger, both))
    if not winners:
        return leader, ""
    best, both = min(winners, key=lambda w: w[0].bic)
    return best, (
        f"it encompasses {leader.effect}: fitted together, adding {best.effect} to {leader.effect} lowers "
        f"the chi-square by {leader.chi2 - both.chi2:.1f} (p = {nested_p_value(leader, both):.2g}) and adding "
        f"{leader.effect} to {best.effect} by {best.chi2 - both.chi2:.1f} (p = {nested_p_value(best, both):.2g})"
    )


def _prefer_nesting(best: ModelFit, named: list[ModelFit], alpha: float) -> ModelFit:
    """``best``, or a candidate that contains it as a special case (``external_torque`` contains ``initial_momentum``)
    and fits significantly better than it (the lowest BIC of those that do).

    Each container is compared with ``best`` by the likelihood ratio between the two, chi-square with the
    difference of their unknowns when ``best`` is the truth, at ``alpha / m`` with ``m`` the number of containers
    compared (Bonferroni over the tests made here; one in the catalogue). The other named candidates are not
    tested here, and the screening against the baseline (:func:`_score`) is another family with its own
    correction: dividing by them as well only cost power (``paper6`` diagnosis suite, 60 s ``external_torque``
    logs: 84 % expected power at ``alpha / 3``, 90 % at ``alpha``, from the Fisher information of the torque).
    """
    containers = [f for f in named if best.effect in EFFECT_TERMS[str(f.effect)].nests]
    better = [f for f in containers if nested_p_value(best, f) < alpha / len(containers)]
    return min(better, key=lambda f: f.bic) if better else best


def nested_p_value(inner: ModelFit, outer: ModelFit) -> float:
    """p-value of the likelihood ratio ``inner.chi2 - outer.chi2`` for ``inner`` nested in ``outer``: chi-square with
    ``outer.n_params - inner.n_params`` degrees of freedom when ``inner`` is the truth (scores from :func:`_score`)."""
    return float(chi2.sf(max(inner.chi2 - outer.chi2, 0.0), outer.n_params - inner.n_params))
