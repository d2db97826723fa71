"""The whole loop: compare, diagnose, add the missing effect, watch the error fall, and report it.

:func:`apply_effect` re-identifies with an effect added (from the diagnosis's fit of that candidate, or
from scratch with an estimator); :func:`run_loop` chains compare -> diagnose -> apply -> compare and,
when the truth is known (a simulated dataset's ``truth.json``), the parameter errors before and after
against their Cramér-Rao bounds (at the true parameters, :func:`parameter_errors`); :func:`write_report` writes it all as one self-contained HTML page
(plots embedded) next to the PNG files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimators.attitude_channel import AttitudeChannel, GyroCoupling, noise_from_dict
from estimators.base import Estimator
from estimators.diagnostics.compare import Comparison, compare
from estimators.diagnostics.diagnose import Diagnosis, candidate_model, diagnose, simulated_variant
from estimators.diagnostics.model_fit import ChannelWeights, ModelFit, gyro_log, profile_filter_gain
from estimators.diagnostics.plots import plot_before_after, plot_correlations, plot_overlay, plot_ranking, plot_residuals
from estimators.diagnostics.report import HtmlReport
from estimators.estimate import Estimate
from estimators.parameters import WithEffects
from estimators.problem import IdentificationModel
from estimators.registry import make_estimator
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.physics.fuel import FUEL_PARAMETER_NAMES


def apply_effect(
    model: IdentificationModel,
    log: MeasurementLog,
    effect: str,
    diagnosis: Diagnosis | None = None,
    estimator: Estimator | None = None,
) -> tuple[IdentificationModel, Estimate]:
    """``model`` with ``effect`` added, identified on ``log``.

    With a ``diagnosis`` that fitted this candidate, its fit (least squares from the baseline) is the
    estimate; otherwise ``estimator`` (default ``hybrid``) identifies the extended model from scratch. On a fused
    attitude whose response to the gyro is a first-order filter's, the fit is refined with the filter's gain profiled
    (:func:`~estimators.diagnostics.model_fit.profile_filter_gain`, 10-15 joint fits); the estimate's options record
    the gain used (``attitude_coupling``) and the regression's (``attitude_filter_gain_regression``). Its bound takes
    the profiled gain as known.
    """
    fit = None if diagnosis is None else diagnosis.fit_of(effect)
    extended = candidate_model(model, effect if fit is None else fit.spec)  # the variant the diagnosis chose (slosh)
    if fit is None or diagnosis is None:
        return extended, (estimator or make_estimator("hybrid")).fit(extended, log)
    # a fused attitude's filter gain profiled with the effect in the model (the regression's gain, fitted at the baseline,
    # is good to 10-20 %, and the fuel follows its error where the effect moves the gyro much)
    weights = diagnosis.weights
    regression_gain = None if weights is None or weights.coupling is None else weights.coupling.filter_gain
    if weights is not None:
        fit, weights = profile_filter_gain(extended, log, fit, weights, fit.effect)
    estimate = fit_estimate(extended, log, fit, weights, "the candidate's least-squares fit in the diagnosis")
    if regression_gain is not None:
        estimate.options["attitude_filter_gain_regression"] = regression_gain
    return extended, estimate


def baseline_estimate(model: IdentificationModel, log: MeasurementLog, diagnosis: Diagnosis) -> Estimate:
    """``model`` as given, as the ``diagnosis`` of it on ``log`` fitted it: to the gyro and the attitude where the
    diagnosis weighed both (its baseline, the fit every candidate is scored against), else to the gyro alone."""
    return fit_estimate(model, log, diagnosis.baseline, diagnosis.weights, "the baseline's fit in the diagnosis")


def fit_estimate(
    model: IdentificationModel, log: MeasurementLog, fit: ModelFit, weights: ChannelWeights | None, origin: str
) -> Estimate:
    """The estimate of ``model``'s ``fit`` on ``log`` (a fit of :func:`~estimators.diagnostics.diagnose.diagnose`),
    with the bound of both channels under ``weights`` (``None``: the gyro's alone); ``origin`` says which fit. The
    gyro's noise and residual are against the reading the fit was made with (less its
    :attr:`~estimators.diagnostics.model_fit.ModelFit.gyro_correction_rad_s`, :func:`~estimators.diagnostics.model_fit.gyro_log`)."""
    problem = model.problem(gyro_log(log, fit))
    options: dict[str, Any] = {"from": origin}
    extra_information = None
    channel = None if weights is None else AttitudeChannel.of(model, log, weights.coupling, weights.reference)
    if channel is not None and weights is not None:
        # fitted to the gyro and the star tracker: the bound is that of both
        options["attitude_noise"] = weights.attitude.to_dict()
        if weights.coupling is not None:
            options["attitude_coupling"] = weights.coupling.to_dict()
        if weights.reference is not None:
            options["attitude_reference"] = [float(v) for v in weights.reference]
        extra_information = channel.fisher(fit.theta, weights.attitude)
    return problem.make_estimate(
        fit.theta,
        estimator="diagnose",
        options=options,
        seed=None,
        cost_history=[fit.rss / fit.n_residuals],
        wall_time_s=fit.wall_time_s,
        extra_information=extra_information,
    )


@dataclass
class ParameterErrors:
    """Errors of the fuel unknowns against the truth, also in Cramér-Rao standard deviations.

    Attributes:
        names: the unknowns (``fuel_consumed_kg`` kg, ``tank_x_m`` m, ...).
        error: estimate - truth (k,); ``crlb_std`` (k,) the bound at the true parameters, ``z = error / crlb_std``;
            ``crlb_std_at_estimate`` (k,) the estimate's own bound (its ``theta_std``, what a log without truth reports).
    """

    names: tuple[str, ...]
    error: FloatArray
    crlb_std: FloatArray
    crlb_std_at_estimate: FloatArray

    @property
    def z(self) -> FloatArray:
        """``error / crlb_std`` (k,); NaN where the bound is infinite (the log, with the model that made it, does not
        inform the unknown at the truth): there is no bound to hold the error against, and ``error / inf`` = 0 read as
        a perfect estimate (payload logs of ``quick3``, whose 10 payload unknowns the arm's 3 joints do not all
        separate from the tank's position, counted as z 0 in the variation matrix's fuel z RMS)."""
        bounded = np.isfinite(self.crlb_std)
        return np.divide(self.error, self.crlb_std, out=np.full(self.error.shape, np.nan), where=bounded)

    def rows(self) -> list[dict[str, Any]]:
        return [
            {
                "parameter": n,
                "error": float(e),
                "Cramér-Rao std": float(s),
                "|error| / std": float(abs(e / s)) if np.isfinite(s) else None,  # no bound: see ``z``
                "Cramér-Rao std at the estimate": float(s_hat),
            }
            for n, e, s, s_hat in zip(self.names, self.error, self.crlb_std, self.crlb_std_at_estimate, strict=True)
        ]


def true_parameters(model: IdentificationModel, truth: dict[str, Any]) -> FloatArray | None:
    """``model``'s unknowns (k,) in a simulated truth (``truth.json`` keys): the fuel unknowns, then each effect
    term's (:meth:`~estimators.models.effect_models.EffectTerm.from_truth`, off when not hidden); ``None`` unless the
    model's base parameterisation is the fuel one and the truth has it."""
    params = model.parameters
    base = params.base if isinstance(params, WithEffects) else params
    if base.names != FUEL_PARAMETER_NAMES or "fuel_consumed_kg" not in truth or "tank_position_m" not in truth:
        return None
    hidden = truth.get("hidden_effects") or {}
    terms = params.terms if isinstance(params, WithEffects) else []
    return np.concatenate(
        [np.array([truth["fuel_consumed_kg"], *truth["tank_position_m"]], dtype=float), *(t.from_truth(hidden) for t in terms)]
    )


def bound_model(model: IdentificationModel, truth: dict[str, Any]) -> IdentificationModel:
    """The model whose Cramér-Rao bound at ``truth`` (``truth.json`` keys) measures a fit of ``model``: ``model``,
    with each effect term that stands for a simulated effect without being the model that made it (a slosh pendulum
    fitted to a spring-mass's log, a constant torque to a drifting one: :meth:`~estimators.models.effect_base.EffectTerm.describes`)
    replaced by the variant of :data:`~estimators.diagnostics.diagnose.CANDIDATE_VARIANTS` that made it
    (:func:`~estimators.diagnostics.diagnose.simulated_variant`; a term whose effect the truth lacks is kept).

    The truth read into the other variant's unknowns is no point of the simulated system (a spring-mass is a pendulum
    with a straight rod along the pole of its angles, where the azimuth has no information), and the bound there is
    not the data's: on a spring slosh of 47 s in a 60 s window (orbit7, exact attitude, design log 10503) the
    pendulum's bound of the fuel mass at that point was 0.38 kg, the spring's 3.3 kg."""
    params = model.parameters
    if not isinstance(params, WithEffects):
        return model
    hidden = truth.get("hidden_effects") or {}
    specs = []
    for term in params.terms:
        variant = None if term.describes(hidden) else simulated_variant(model.robot, term.name, hidden)
        specs.append(term.spec if variant is None else variant)
    if specs == [term.spec for term in params.terms]:
        return model
    return IdentificationModel(model.robot, params.base, model.noise_std_rad_s, effects=specs)


def parameter_errors(
    model: IdentificationModel, log: MeasurementLog, estimate: Estimate, truth: dict[str, Any]
) -> ParameterErrors | None:
    """Errors of the fuel unknowns of ``estimate`` (of ``model`` on ``log``) against ``truth`` (``truth.json`` keys),
    in Cramér-Rao std at the true parameters; ``None`` if the model or the truth lacks the fuel unknowns.

    The bound is the Cramér-Rao bound's own point, the truth (with the estimate's noise level; with the star
    tracker's too for an estimate fitted to both, whose options hold ``attitude_noise``), as in
    :mod:`estimators.evaluation`, of the model that made the data (:func:`bound_model`: ``model`` unless an effect of
    it is another variant of the simulated one); the estimate's ``theta_std`` is the bound at the estimate and is kept
    beside it.
    The two differ where the information changes fast with the unknowns: the tank position's bound scales roughly
    as ``1 / mdf``, and with a payload's 10 unknowns mdf and the tank position can be correlated beyond 0.95, so an
    estimate 2-3 std high in mdf can carry a tank bound many times too small (``paper6``, payload log of seed 3:
    ``tank_y`` bound 0.135 m at the truth, 0.0145 m at the least-squares minimum, where mdf is 102 kg for 37 kg).
    """
    if tuple(estimate.names) != tuple(model.parameters.names):
        raise SpaceIdInputError(
            f"parameter_errors: the estimate's unknowns {estimate.parameterisation!r} are not the model's "
            f"{model.parameters.name!r}"
        )
    fitted_index = [model.parameters.names.index(n) for n in FUEL_PARAMETER_NAMES]
    model = bound_model(model, truth)
    theta_true = true_parameters(model, truth)
    if theta_true is None:
        return None
    index = [model.parameters.names.index(n) for n in FUEL_PARAMETER_NAMES]
    attitude_noise = estimate.options.get("attitude_noise")
    coupling = estimate.options.get("attitude_coupling")
    reference = estimate.options.get("attitude_reference")
    channel = (
        None
        if attitude_noise is None
        else AttitudeChannel.of(
            model,
            log,
            None if coupling is None else GyroCoupling.from_dict(coupling),
            None if reference is None else np.asarray(reference, dtype=float),
        )
    )
    extra_information = None if channel is None else channel.fisher(theta_true, noise_from_dict(attitude_noise))
    std = model.problem(log).crlb_std(theta_true, estimate.noise_std_rad_s, extra_information)
    return ParameterErrors(
        FUEL_PARAMETER_NAMES, estimate.theta[fitted_index] - theta_true[index], std[index], estimate.theta_std[fitted_index]
    )


@dataclass
class LoopResult:
    """Compare, diagnose, apply, compare again (see :func:`run_loop`)."""

    model: IdentificationModel
    diagnosis: Diagnosis
    before: Comparison
    applied: str | None
    after: Comparison | None
    estimate_before: Estimate
    estimate_after: Estimate | None
    truth: dict[str, Any] | None
    errors_before: ParameterErrors | None
    errors_after: ParameterErrors | None

    def summary(self) -> str:
        """What happened, in a few lines."""
        lines = [self.before.summary(), f"diagnosis: {self.diagnosis.verdict} ({self.diagnosis.reason})"]
        if self.after is not None:
            lines.append(f"after adding {self.applied}:")
            lines.append(self.after.summary())
        if self.errors_before is not None:
            lines.append("fuel unknowns, |error| / Cramér-Rao std at the truth, before: " + _z_text(self.errors_before))
        if self.errors_after is not None:
            lines.append("fuel unknowns, |error| / Cramér-Rao std at the truth, after:  " + _z_text(self.errors_after))
        return "\n".join(lines)

    def before_after_rows(self) -> list[dict[str, Any]]:
        """Residual RMS / noise and fit % per axis, before and after (noise floor: the diagnosis's)."""
        if self.after is None:
            return []
        rows = []
        for c, name in enumerate(self.before.analysis.channel_names):
            rows.append(
                {
                    "axis": name,
                    "RMS / noise before": float(self.before.analysis.rms_over_noise[c]),
                    "RMS / noise after": float(self.after.analysis.rms_over_noise[c]),
                    "fit % before": float(self.before.analysis.fit_percent[c]),
                    "fit % after": float(self.after.analysis.fit_percent[c]),
                }
            )
        return rows

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "diagnosis": self.diagnosis.to_dict(),
            "before": self.before.to_dict(),
            "applied": self.applied,
            "after": None if self.after is None else self.after.to_dict(),
        }
        for key, errors in (("errors_before", self.errors_before), ("errors_after", self.errors_after)):
            out[key] = None if errors is None else errors.rows()
        return out


def _z_text(errors: ParameterErrors) -> str:
    return ", ".join(
        f"{n} {abs(z):.2f}" if np.isfinite(z) else f"{n} unbounded" for n, z in zip(errors.names, errors.z, strict=True)
    )


def run_loop(
    model: IdentificationModel,
    log: MeasurementLog,
    truth: dict[str, Any] | None = None,
    apply: str | None = "best",
    noise_std_rad_s: float | None = None,
    estimator: Estimator | None = None,
    candidates: tuple[str, ...] | list[str] | None = None,
) -> LoopResult:
    """Compare the model with ``log``, diagnose it, add an effect (``"best"``: the verdict's, or a name; ``None``: none) and compare again.

    The noise floor of both comparisons is ``noise_std_rad_s`` if given, else the diagnosis's (the residual
    std of the best-fitting candidate), so before and after are measured against the same floor.
    """
    diagnosis = diagnose(model, log, candidates=candidates, estimator=estimator)
    estimate_before = baseline_estimate(model, log, diagnosis)
    floor = noise_std_rad_s if noise_std_rad_s is not None else diagnosis.noise_std_rad_s
    before = compare(model, log, diagnosis.baseline.theta, floor, label=model.parameters.name)
    effect = diagnosis.best.effect if apply == "best" and diagnosis.best is not None else (None if apply == "best" else apply)
    after = estimate_after = None
    extended = model
    if effect is not None:
        extended, estimate_after = apply_effect(model, log, effect, diagnosis)
        fitted = diagnosis.fit_of(effect)
        correction = None if fitted is None else fitted.gyro_correction_rad_s
        after = compare(extended, log, estimate_after.theta, floor, extended.parameters.name, correction)
    errors = (None, None)
    if truth is not None:
        errors = (
            parameter_errors(model, log, estimate_before, truth),
            None if estimate_after is None else parameter_errors(extended, log, estimate_after, truth),
        )
    return LoopResult(model, diagnosis, before, effect, after, estimate_before, estimate_after, truth, errors[0], errors[1])


def write_report(result: LoopResult, path: str | Path, title: str = "Model against measurements") -> Path:
    """One self-contained HTML page (plots embedded) of ``result``; the PNGs are written next to it in ``<name>_figures/``."""
    path = Path(path)
    figures = path.parent / f"{path.stem}_figures"
    figures.mkdir(parents=True, exist_ok=True)
    d, before, after = result.diagnosis, result.before, result.after
    page = HtmlReport(title)
    page.add_paragraph(
        f"Model {before.label} on a log of {len(before.t_s)} samples ({before.t_s[-1] - before.t_s[0]:.1f} s). "
        f"Verdict: {d.verdict!r}. {d.reason}."
    )
    page.add_heading("1. Model against the measurements")
    overlay = plot_overlay(
        figures / "overlay.png",
        before.t_s,
        before.measured,
        before.predicted,
        before.analysis.segments,
        predicted_after=None if after is None else after.predicted,
        title=f"Gyro rate: measured, model {before.label}" + ("" if after is None else f" and {after.label}"),
    )
    page.add_image(
        overlay, "Measured base rate (base body frame) and the model's; shaded: where the model fails, numbered by rank."
    )
    page.add_table(before.analysis.channel_rows(), "Per axis: fit %, residual RMS against the noise floor, whiteness.")
    if before.analysis.segments:
        page.add_table(before.analysis.segment_rows(), "Where it fails: time segments whose residual exceeds the noise, ranked.")
    residuals = plot_residuals(
        figures / "residuals.png",
        before.t_s,
        before.residual,
        before.analysis.noise_std,
        before.analysis.segments,
        residual_after=None if after is None else after.residual,
    )
    page.add_image(residuals, "Residual with the +-2 sigma noise band and its 1 s moving average.")
    page.add_heading("2. Residual analysis")
    page.add_image(
        plot_correlations(figures / "correlations.png", before.analysis), "Autocorrelation and cross-correlation with the inputs."
    )
    page.add_paragraph(before.analysis.structure_description())
    page.add_heading("3. Which effect is missing")
    page.add_table(
        d.ranking_table(),
        "Candidate effects, the named one first, then by BIC (lower is better; significance Bonferroni-corrected).",
    )
    page.add_image(
        plot_ranking(figures / "ranking.png", [{"effect": c.effect, "bic_improvement": -c.delta_bic} for c in d.candidates]),
        "BIC improvement of each candidate over the model as it is.",
    )
    if after is not None:
        page.add_heading(f"4. After adding {result.applied}")
        page.add_table(result.before_after_rows(), "Residual RMS over the noise floor and fit %, before and after.")
        labels = list(before.analysis.channel_names)
        chart = plot_before_after(
            figures / "before_after.png",
            labels,
            before.analysis.rms_over_noise,
            after.analysis.rms_over_noise,
            "residual RMS / noise floor",
            title=f"Residual before and after adding {result.applied}",
        )
        page.add_image(chart, "Residual RMS over the noise floor per axis.")
        page.add_paragraph(after.analysis.structure_description())
        fitted = d.fit_of(result.applied)
        if fitted is not None:
            page.add_table(
                [{"quantity": k, "value": _text(v)} for k, v in fitted.physical.items() if k not in _base_keys()],
                f"The fitted {result.applied}.",
            )
    for label, errors in (("before", result.errors_before), ("after", result.errors_after)):
        if errors is not None:
            page.add_table(
                errors.rows(),
                f"Fuel unknowns against the truth, {label}: Cramér-Rao std at the true parameters, and the estimate's own.",
            )
    return page.write(path)


def _base_keys() -> set[str]:
    return {"fuel_consumed_kg", "tank_position_m", "base_mass_kg", "base_com_m", "base_inertia_kgm2"}


def _text(value: Any) -> str:
    array = np.asarray(value, dtype=float)
    return np.array2string(array, precision=4) if array.ndim else f"{float(array):.4g}"
