"""All the residual tests in one :class:`ResidualAnalysis` (:func:`analyse_residuals`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import butter, sosfiltfilt

from estimators.diagnostics.residuals._checks import _array, _check_lag, _check_probability, _check_same_rows, _columns
from estimators.diagnostics.residuals.correlation import (
    _autocorrelation_columns,
    _cross_correlation_columns,
    _ljung_box_from_acf,
    white_noise_band,
)
from estimators.diagnostics.residuals.noise import fit_percent, noise_floor_dof, noise_floor_std
from estimators.diagnostics.residuals.segments import Segment, failing_segments
from estimators.diagnostics.residuals.spectrum import SpectralPeak, dominant_frequencies
from estimators.models.effect_models import DELAY_BAND_HZ
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import jsonable

#: cutoff (Hz) of the low-pass on the cross-correlation's inputs: the band of the motions and of the effects'
#: signatures, where the delay term's band starts too (one number for both)
INPUT_BAND_HZ = DELAY_BAND_HZ[0]
#: the cutoff is at most this fraction of the sample rate
INPUT_BAND_FRACTION_OF_RATE = 0.2


def band_limited_inputs(dq_rad_s: FloatArray, t_s: FloatArray, dt_s: float, cutoff_hz: float | None) -> FloatArray:
    """The cross-correlation's inputs (T, 2n): joint rates and accelerations (second-order ``numpy.gradient`` of
    ``dq_rad_s`` (T, n) over ``t_s``), low-passed below ``min(cutoff_hz, 0.2 / dt_s)`` by a zero-phase fourth-order
    Butterworth filter (``scipy.signal.sosfiltfilt``, so no lag is added); ``None``: unfiltered.

    Why: the model's prediction is computed from the same measured rates, so their sensor noise is in the residual;
    differentiated, it dominates ``ddq`` at high sample rates, and the two correlate one sample apart on a log
    whose model is exact (seen: a clean 100 Hz ``orbit7`` log, ``ddq2`` at ccf 0.10, p = 8e-13, at the true
    parameters). A missing effect's signature lies in the motion's band, which the filter keeps.
    """
    ddq = np.gradient(dq_rad_s, t_s, axis=0, edge_order=2)
    inputs = np.hstack([dq_rad_s, ddq])
    if cutoff_hz is None:
        return inputs
    if not cutoff_hz > 0.0:
        raise SpaceIdInputError(f"analyse_residuals: input_band_hz must be > 0 Hz or None, got {cutoff_hz!r}")
    cutoff = min(cutoff_hz, INPUT_BAND_FRACTION_OF_RATE / dt_s)
    sos = butter(4, cutoff, fs=1.0 / dt_s, output="sos")
    return sosfiltfilt(sos, inputs, axis=0)


@dataclass
class ResidualAnalysis:
    """Everything :func:`analyse_residuals` found about ``residual = measured - predicted``.

    Per channel c (C channels, names ``channel_names``): ``fit_percent``, ``residual_rms`` (unit of the
    channel), ``noise_std`` (given or estimated: ``noise_source``), ``rms_over_noise``, Ljung-Box
    ``ljung_box_q``/``ljung_box_p`` over ``max_lag`` lags, ``acf`` (C, L+1) with the pointwise band
    ``acf_band`` and the lags outside it ``significant_acf_lags`` (pointwise: about ``alpha L`` lags of
    white noise fall outside by chance), ``ccf`` (C, m, 2L+1) with the m inputs ``input_names`` (lags in
    samples, see :class:`CrossCorrelation`) and its per-input ``ccf_p_value``/``ccf_peak``/``ccf_peak_lag``
    (C, m), ``correlated_inputs`` (per channel, the significant inputs ranked by |peak ccf|), and
    ``dominant_frequencies`` (per channel, list of :class:`SpectralPeak`). ``segments``: the failing
    time segments (all channels together).

    Verdicts at ``confidence`` (alpha = 1 - confidence), family-wise over channels and inputs:
    ``white`` (no channel's Ljung-Box p below alpha / C), ``uncorrelated_with_inputs`` (no ccf test
    p below alpha / (C m)), ``consistent_with_noise`` (both, and no failing segment).
    """

    channel_names: list[str]
    input_names: list[str]
    joint_names: list[str]
    confidence: float
    n_samples: int
    dt_s: float
    t_start_s: float
    t_end_s: float
    max_lag: int
    fit_percent: FloatArray
    residual_rms: FloatArray
    noise_std: FloatArray
    noise_source: str
    noise_dof: float | None
    rms_over_noise: FloatArray
    ljung_box_q: FloatArray
    ljung_box_p: FloatArray
    acf: FloatArray
    acf_band: float
    significant_acf_lags: list[list[int]]
    ccf: FloatArray
    ccf_band: float
    ccf_variance_factor: FloatArray
    ccf_p_value: FloatArray
    ccf_peak: FloatArray
    ccf_peak_lag: NDArray[np.int64]
    correlated_inputs: list[list[dict[str, Any]]]
    dominant_frequencies: list[list[SpectralPeak]]
    segments: list[Segment]
    notes: list[str] = field(default_factory=list)

    @property
    def alpha(self) -> float:
        return 1.0 - self.confidence

    @property
    def white(self) -> bool:
        """Every channel passes Ljung-Box at alpha / C (Bonferroni over channels)."""
        return bool(np.all(self.ljung_box_p >= self.alpha / len(self.channel_names)))

    @property
    def uncorrelated_with_inputs(self) -> bool:
        """No channel correlates significantly with any input (Bonferroni over channels and inputs)."""
        return not any(self.correlated_inputs)

    @property
    def consistent_with_noise(self) -> bool:
        """White, uncorrelated with the inputs and no failing time segment."""
        return self.white and self.uncorrelated_with_inputs and not self.segments

    def channel_rows(self) -> list[dict[str, Any]]:
        """One table row per channel (for a report): fit, RMS, noise, whiteness, strongest input and line."""
        rows = []
        for c, name in enumerate(self.channel_names):
            best = self.correlated_inputs[c][0] if self.correlated_inputs[c] else None
            line = self.dominant_frequencies[c][0] if self.dominant_frequencies[c] else None
            rows.append(
                {
                    "channel": name,
                    "fit %": float(self.fit_percent[c]),
                    "residual RMS": float(self.residual_rms[c]),
                    f"noise std ({self.noise_source})": float(self.noise_std[c]),
                    "RMS / noise": float(self.rms_over_noise[c]),
                    "Ljung-Box p": float(self.ljung_box_p[c]),
                    "white": bool(self.ljung_box_p[c] >= self.alpha / len(self.channel_names)),
                    "most correlated input": ""
                    if best is None
                    else f"{best['input']} ({best['peak_ccf']:+.2f} at {best['lag_s']:+.2f} s)",
                    "dominant line": "" if line is None else f"{line.frequency_hz:.3g} Hz (amp. {line.amplitude:.3g})",
                }
            )
        return rows

    def segment_rows(self) -> list[dict[str, Any]]:
        """One table row per failing segment, ranked."""
        return [
            {
                "rank": i + 1,
                "t start [s]": s.t_start_s,
                "t end [s]": s.t_end_s,
                "RMS / noise": s.rms_over_noise,
                "worst channel": self.channel_names[int(np.argmax(s.channel_rms_over_noise))],
                "p (Holm)": s.p_value,
                "moving joints": ", ".join(s.moving_joints) or "none",
                "max |dq| [rad/s]": float(np.max(s.max_abs_dq_rad_s)) if s.max_abs_dq_rad_s.size else 0.0,
            }
            for i, s in enumerate(self.segments)
        ]

    def structure_description(self) -> str:
        """A few plain sentences: whiteness, dominant frequencies, correlated inputs, where in time."""
        if not np.any(self.residual_rms > 0.0):
            return "The residual is exactly zero on every channel: the model reproduces the measurement."
        level = f"{100 * self.confidence:g} %"
        ratio = f"{np.nanmin(self.rms_over_noise):.2f}-{np.nanmax(self.rms_over_noise):.2f}"
        if self.consistent_with_noise:
            return (
                f"The residuals are consistent with white noise at {level} confidence on every channel: Ljung-Box over "
                f"{self.max_lag} lags passes, they do not correlate with any input and no time segment exceeds the noise; "
                f"residual RMS is {ratio} x the noise floor ({self.noise_source})."
            )
        sentences = []
        structured = [c for c in range(len(self.channel_names)) if self.ljung_box_p[c] < self.alpha / len(self.channel_names)]
        if structured:
            parts = ", ".join(f"{self.channel_names[c]} (Ljung-Box p = {self.ljung_box_p[c]:.2g})" for c in structured)
            sentences.append(
                f"The residuals are not white at {level} confidence on {parts}; RMS {ratio} x the noise floor ({self.noise_source})."
            )
        else:
            sentences.append(
                f"The residuals pass the Ljung-Box whiteness test at {level} confidence; RMS {ratio} x the noise floor ({self.noise_source})."
            )
        lines = [
            f"{self.channel_names[c]} at " + ", ".join(f"{p.frequency_hz:.3g} Hz (amplitude {p.amplitude:.3g})" for p in peaks)
            for c, peaks in enumerate(self.dominant_frequencies)
            if peaks
        ]
        sentences.append(
            ("Dominant frequencies: " + "; ".join(lines) + ".")
            if lines
            else "No significant spectral line (the structure is broadband or absent)."
        )
        correlated = [(self.channel_names[c], entry) for c, entries in enumerate(self.correlated_inputs) for entry in entries[:2]]
        if correlated:
            correlated.sort(key=lambda item: -abs(item[1]["peak_ccf"]))
            text = "; ".join(
                f"{channel} with {e['input']} (ccf {e['peak_ccf']:+.2f} at lag {e['lag_s']:+.2f} s)"
                for channel, e in correlated[:4]
            )
            sentences.append(f"It correlates most with the inputs: {text}.")
        else:
            sentences.append("It does not correlate significantly with any input (joint rates, accelerations).")
        if self.segments:
            worst = "; ".join(s.describe(self.channel_names) for s in self.segments[:3])
            sentences.append(f"It exceeds the noise in {len(self.segments)} time segment(s), largest first: {worst}.")
        else:
            sentences.append("No time segment exceeds the noise.")
        return " ".join(sentences + self.notes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dictionary of all fields (arrays as lists, non-finite numbers as None) and the verdicts."""
        out = {name: getattr(self, name) for name in self.__dataclass_fields__ if name != "segments"}
        out["segments"] = [
            {name: getattr(s, name) for name in s.__dataclass_fields__} | {"description": s.describe(self.channel_names)}
            for s in self.segments
        ]
        out |= {
            "white": self.white,
            "uncorrelated_with_inputs": self.uncorrelated_with_inputs,
            "consistent_with_noise": self.consistent_with_noise,
            "structure_description": self.structure_description(),
        }
        return jsonable(out)


def analyse_residuals(
    t_s: ArrayLike,
    measured: ArrayLike,
    predicted: ArrayLike,
    q: ArrayLike,
    dq: ArrayLike,
    noise_std: ArrayLike | None = None,
    channel_names: tuple[str, ...] | list[str] = ("wx", "wy", "wz"),
    input_names: tuple[str, ...] | list[str] | None = None,
    confidence: float = 0.99,
    max_lag: int = 50,
    window_s: float = 2.0,
    n_frequencies: int = 3,
    joint_names: tuple[str, ...] | list[str] | None = None,
    input_band_hz: float | None = INPUT_BAND_HZ,
) -> ResidualAnalysis:
    """All residual tests of ``measured - predicted`` in one :class:`ResidualAnalysis`.

    Inputs for the cross-correlation are the joint rates ``dq`` and the joint accelerations
    ``ddq = d(dq)/dt`` (``numpy.gradient``, second order), named ``dq1..dqn, ddq1..ddqn``, both
    low-passed to the motion's band (:func:`band_limited_inputs`): the measured rates' noise enters the
    model's prediction too, and the differentiated noise of ``ddq`` would otherwise correlate with the
    residual one sample apart on a log whose model is exact.
    Spectra and correlations treat the samples as equally spaced at the median sample period (a
    note is added if the spacing varies by more than 1 %). ``max_lag`` is reduced to T // 4 for
    short logs (noted).

    Args:
        t_s: (T,) time, s, strictly increasing.
        measured, predicted: (T, C), unit of the channel (e.g. rad/s for ``omega_base_body``).
        q: (T, n) joint angles, rad; dq: (T, n) joint rates, rad/s.
        noise_std: (C,) or scalar known white-noise std per channel; None estimates it with
            :func:`noise_floor_std` (tests then account for the estimate's uncertainty).
        channel_names: (C,) names. input_names: (2n,) names of dq and ddq columns.
        confidence: confidence of every verdict (family-wise per question).
        max_lag: L for autocorrelation, Ljung-Box and cross-correlation.
        window_s: window of :func:`failing_segments`. n_frequencies: lines per channel.
        joint_names: (n,) names for the segments; default ``q1``..``qn``.
        input_band_hz: cutoff of the inputs' low-pass, Hz (:func:`band_limited_inputs`); ``None``: unfiltered.
    """
    t = _array(t_s, "analyse_residuals: t_s", (1,), min_rows=16)
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        raise SpaceIdInputError(f"analyse_residuals: t_s must be strictly increasing (row {int(np.argmax(dt <= 0)) + 1})")
    y, _ = _columns(measured, "analyse_residuals: measured")
    yhat, _ = _columns(predicted, "analyse_residuals: predicted")
    q_arr, _ = _columns(q, "analyse_residuals: q")
    dq_arr, _ = _columns(dq, "analyse_residuals: dq")
    n_samples = t.shape[0]
    _check_same_rows(
        n_samples, **{"analyse_residuals: measured": y, "analyse_residuals: q": q_arr, "analyse_residuals: dq": dq_arr}
    )
    if yhat.shape != y.shape:
        raise SpaceIdInputError(f"analyse_residuals: predicted must have the shape of measured {y.shape}, got {yhat.shape}")
    if q_arr.shape != dq_arr.shape:
        raise SpaceIdInputError(f"analyse_residuals: q {q_arr.shape} and dq {dq_arr.shape} must have the same shape (T, n)")
    n_channels, n_joints = y.shape[1], dq_arr.shape[1]
    channels = list(channel_names)
    if len(channels) != n_channels:
        raise SpaceIdInputError(f"analyse_residuals: channel_names must name the {n_channels} channels, got {channels}")
    inputs_named = (
        list(input_names)
        if input_names is not None
        else [f"dq{i + 1}" for i in range(n_joints)] + [f"ddq{i + 1}" for i in range(n_joints)]
    )
    if len(inputs_named) != 2 * n_joints:
        raise SpaceIdInputError(
            f"analyse_residuals: input_names must name the {2 * n_joints} inputs (dq then ddq), got {len(inputs_named)}"
        )
    joints = list(joint_names) if joint_names is not None else [f"q{i + 1}" for i in range(n_joints)]
    alpha = 1.0 - _check_probability(confidence, "analyse_residuals: confidence")
    notes = []
    dt_s = float(np.median(dt))
    if np.max(np.abs(dt - dt_s)) > 0.01 * dt_s:
        notes.append(
            f"Note: the sampling is not uniform (steps {dt.min():.4g}-{dt.max():.4g} s); correlations and spectra treat samples as equally spaced at {dt_s:.4g} s."
        )
    lags = _check_lag(max_lag, n_samples, "analyse_residuals: max_lag")
    if lags > n_samples // 4:
        lags = n_samples // 4
        notes.append(f"Note: max_lag reduced from {max_lag} to {lags} (a quarter of the {n_samples} samples).")

    residual = y - yhat
    if noise_std is None:
        sigma, source, dof = noise_floor_std(residual), "estimated", n_channels * noise_floor_dof(n_samples)
    else:
        sigma = np.broadcast_to(_array(np.atleast_1d(noise_std), "analyse_residuals: noise_std", (1,)), (n_channels,)).copy()
        if np.any(sigma <= 0.0) or np.asarray(noise_std).size not in (1, n_channels):
            raise SpaceIdInputError(
                f"analyse_residuals: noise_std must be > 0, scalar or one per channel ({n_channels}), got {noise_std!r}"
            )
        source, dof = "given", None
    rms = np.sqrt(np.mean(residual**2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(sigma > 0.0, rms / np.where(sigma > 0.0, sigma, 1.0), np.where(rms > 0.0, np.inf, np.nan))

    acf = _autocorrelation_columns(residual, lags)  # (L+1, C)
    lb_q, lb_p = _ljung_box_from_acf(acf, n_samples)
    acf_band = white_noise_band(n_samples, alpha)
    inputs = band_limited_inputs(dq_arr, t, dt_s, input_band_hz)
    ccfs = _cross_correlation_columns(residual, inputs, lags, alpha)
    threshold = alpha / (n_channels * inputs.shape[1])
    correlated = []
    for cc in ccfs:
        significant = np.flatnonzero(cc.p_value < threshold)
        significant = significant[np.argsort(-np.abs(cc.peak_ccf[significant]), kind="stable")]
        correlated.append(
            [
                {
                    "input": inputs_named[j],
                    "peak_ccf": float(cc.peak_ccf[j]),
                    "lag_samples": int(cc.peak_lag[j]),
                    "lag_s": float(cc.peak_lag[j] * dt_s),
                    "p_value": float(cc.p_value[j]),
                }
                for j in significant
            ]
        )
    lines = [dominant_frequencies(residual[:, c], dt_s, n=n_frequencies, alpha=alpha) for c in range(n_channels)]
    segments = failing_segments(
        t, residual, sigma, q_arr, dq_arr, window_s=window_s, confidence=confidence, noise_dof=dof, joint_names=joints
    )
    return ResidualAnalysis(
        channel_names=channels,
        input_names=inputs_named,
        joint_names=joints,
        confidence=float(confidence),
        n_samples=n_samples,
        dt_s=dt_s,
        t_start_s=float(t[0]),
        t_end_s=float(t[-1]),
        max_lag=lags,
        fit_percent=fit_percent(y, yhat),
        residual_rms=rms,
        noise_std=np.asarray(sigma, dtype=np.float64),
        noise_source=source,
        noise_dof=dof,
        rms_over_noise=ratio,
        ljung_box_q=lb_q,
        ljung_box_p=lb_p,
        acf=acf.T.copy(),
        acf_band=acf_band,
        significant_acf_lags=[(np.flatnonzero(np.abs(acf[1:, c]) > acf_band) + 1).tolist() for c in range(n_channels)],
        ccf=np.stack([cc.ccf for cc in ccfs]),
        ccf_band=acf_band,
        ccf_variance_factor=np.stack([cc.variance_factor for cc in ccfs]),
        ccf_p_value=np.stack([cc.p_value for cc in ccfs]),
        ccf_peak=np.stack([cc.peak_ccf for cc in ccfs]),
        ccf_peak_lag=np.stack([cc.peak_lag for cc in ccfs]),
        correlated_inputs=correlated,
        dominant_frequencies=lines,
        segments=segments,
        notes=notes,
    )
