"""PNG plots of a model-vs-measurement comparison and its residual analysis.

Every function draws on its own :class:`matplotlib.figure.Figure` with the Agg canvas (no pyplot,
no window, no global matplotlib state), writes the PNG atomically to ``path`` and returns the path.
Channels are generic (C of them: base rates wx, wy, wz in rad/s; joint torques in N m; ...); their
unit is a parameter (one string for all channels or one per channel).
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import ArrayLike
from scipy import stats

from estimators.diagnostics.report import PathLike
from estimators.diagnostics.residuals import (
    ResidualAnalysis,
    Segment,
    SpectralPeak,
    periodogram,
    white_spectrum_level,
)
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import write_bytes_atomic

_SEGMENT_COLOUR = "tab:red"
_DPI = 100


def _save(fig: Figure, path: PathLike) -> Path:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=_DPI)
    return write_bytes_atomic(path, buffer.getvalue())


def _figure(
    width_in: float,
    height_in: float,
    left_in: float = 0.95,
    right_in: float = 0.25,
    top_in: float = 0.55,
    bottom_in: float = 0.55,
) -> Figure:
    """A figure with fixed margins in inches (no layout engine: constrained layout costs seconds per plot)."""
    fig = Figure(figsize=(width_in, height_in))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(
        left=left_in / width_in,
        right=1.0 - right_in / width_in,
        top=1.0 - top_in / height_in,
        bottom=bottom_in / height_in,
        hspace=0.35,
        wspace=0.25,
    )
    return fig


def _series(name: str, x: ArrayLike, n_samples: int, n_channels: int | None = None) -> FloatArray:
    """``x`` as (T, C) floats; checks T (and C if given)."""
    a = np.asarray(x, dtype=np.float64)
    a = a[:, None] if a.ndim == 1 else a
    if a.ndim != 2 or a.shape[0] != n_samples or (n_channels is not None and a.shape[1] != n_channels):
        expected = f"({n_samples}, {n_channels if n_channels is not None else 'C'})"
        raise SpaceIdInputError(f"{name}: expected shape {expected}, got {np.shape(x)}")
    return a


def _per_channel(name: str, value: ArrayLike, n_channels: int) -> FloatArray:
    """A scalar or (C,) value as (C,) floats."""
    a = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if a.ndim != 1 or a.size not in (1, n_channels):
        raise SpaceIdInputError(f"{name}: expected a scalar or one value per channel ({n_channels}), got shape {a.shape}")
    return np.broadcast_to(a, (n_channels,))


def _names_and_units(
    function: str, n_channels: int, channel_names: Sequence[str] | None, units: str | Sequence[str]
) -> tuple[list[str], list[str]]:
    names = list(channel_names) if channel_names is not None else [f"ch{c + 1}" for c in range(n_channels)]
    unit_list = [units] * n_channels if isinstance(units, str) else list(units)
    if len(names) != n_channels or len(unit_list) != n_channels:
        raise SpaceIdInputError(f"{function}: expected {n_channels} channel names and units, got {names} and {unit_list}")
    return names, unit_list


def _finish_rows(fig: Figure, axes: Sequence[Axes], title: str, xlabel: str) -> None:
    """Common finish of a one-row-per-channel figure: title top left, one legend top right, x label."""
    for ax in axes:
        ax.grid(alpha=0.3)
        if ax.get_yscale() == "linear":
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper right", ncol=min(len(labels), 4), fontsize=8, frameon=False)
    fig.suptitle(title, x=0.01, ha="left")
    axes[-1].set_xlabel(xlabel)


def _shade_segments(axes: Sequence[Axes], segments: Sequence[Segment]) -> None:
    """Shade the failing segments on every axis and number them (rank) on the first."""
    for rank, segment in enumerate(segments, start=1):
        for i, ax in enumerate(axes):
            ax.axvspan(
                segment.t_start_s,
                segment.t_end_s,
                color=_SEGMENT_COLOUR,
                alpha=0.13,
                lw=0,
                label="failing segment" if rank == 1 else None,
            )
            if i == 0:
                ax.annotate(
                    f"#{rank}",
                    xy=(segment.t_start_s, 0.97),
                    xycoords=("data", "axes fraction"),
                    xytext=(2, 0),
                    textcoords="offset points",
                    va="top",
                    fontsize=8,
                    color=_SEGMENT_COLOUR,
                )


def plot_overlay(
    path: PathLike,
    t_s: ArrayLike,
    measured: ArrayLike,
    predicted: ArrayLike,
    segments: Sequence[Segment] = (),
    channel_names: Sequence[str] | None = ("wx", "wy", "wz"),
    title: str = "Model vs measurement",
    predicted_after: ArrayLike | None = None,
    units: str | Sequence[str] = "rad/s",
    labels: tuple[str, str, str] = ("measured", "model", "model after"),
) -> Path:
    """Per channel (one row each): measured vs predicted (and optionally a second, "after" prediction),
    with the failing segments shaded and numbered by rank.

    Args:
        path: PNG file to write.
        t_s: (T,) time, s. measured, predicted, predicted_after: (T, C).
        segments: from :func:`~estimators.diagnostics.residuals.failing_segments` (ranked).
        channel_names: (C,) names; units: unit of all channels or one per channel.
        labels: legend labels of measured, predicted and predicted_after.
    """
    t = np.asarray(t_s, dtype=np.float64).ravel()
    y = _series("plot_overlay: measured", measured, t.size)
    n_channels = y.shape[1]
    yhat = _series("plot_overlay: predicted", predicted, t.size, n_channels)
    after = None if predicted_after is None else _series("plot_overlay: predicted_after", predicted_after, t.size, n_channels)
    names, unit_list = _names_and_units("plot_overlay", n_channels, channel_names, units)
    fig = _figure(12, 1.2 + 2.2 * n_channels, left_in=1.0, top_in=0.75)
    axes = fig.subplots(n_channels, 1, sharex=True, squeeze=False)[:, 0]
    for c, ax in enumerate(axes):
        ax.plot(t, y[:, c], color="0.55", lw=0.8, label=labels[0])
        ax.plot(t, yhat[:, c], color="tab:blue", lw=1.0, label=labels[1])
        if after is not None:
            ax.plot(t, after[:, c], color="tab:green", lw=1.0, ls="--", label=labels[2])
        ax.set_ylabel(f"{names[c]} [{unit_list[c]}]")
    _shade_segments(axes, segments)
    _finish_rows(fig, axes, title, "t [s]")
    return _save(fig, path)


def plot_residuals(
    path: PathLike,
    t_s: ArrayLike,
    residual: ArrayLike,
    noise_std: ArrayLike,
    segments: Sequence[Segment] = (),
    channel_names: Sequence[str] | None = ("wx", "wy", "wz"),
    title: str = "Residual (measured - model)",
    units: str | Sequence[str] = "rad/s",
    smooth_s: float | None = 1.0,
    residual_after: ArrayLike | None = None,
) -> Path:
    """Per channel: the residual with its +-2 sigma noise band, its moving average over ``smooth_s``
    (with the band +-2 sigma / sqrt(w) of averaged white noise: structure at the noise level shows
    there) and the failing segments shaded.

    Args:
        path: PNG file. t_s: (T,) s. residual, residual_after: (T, C). noise_std: (C,) or scalar.
        smooth_s: moving-average window, s (None: no average).
    """
    t = np.asarray(t_s, dtype=np.float64).ravel()
    r = _series("plot_residuals: residual", residual, t.size)
    n_channels = r.shape[1]
    sigma = _per_channel("plot_residuals: noise_std", noise_std, n_channels)
    r_after = None if residual_after is None else _series("plot_residuals: residual_after", residual_after, t.size, n_channels)
    names, unit_list = _names_and_units("plot_residuals", n_channels, channel_names, units)
    width = 1
    if smooth_s is not None and t.size > 1:
        width = max(1, min(t.size, round(smooth_s / float(np.median(np.diff(t))))))
    kernel = np.ones(width) / width
    t_avg = np.convolve(t, kernel, mode="valid")
    fig = _figure(12, 1.2 + 2.2 * n_channels, left_in=1.0, top_in=0.75)
    axes = fig.subplots(n_channels, 1, sharex=True, squeeze=False)[:, 0]
    for c, ax in enumerate(axes):
        ax.plot(t, r[:, c], color="0.6", lw=0.6, label="residual")
        ax.axhspan(-2 * sigma[c], 2 * sigma[c], color="tab:blue", alpha=0.12, lw=0, label="noise, +-2 sigma")
        if width > 1:
            ax.plot(t_avg, np.convolve(r[:, c], kernel, mode="valid"), color="k", lw=1.1, label=f"{smooth_s:g} s average")
            band = 2 * sigma[c] / math.sqrt(width)
            for sign in (-1, 1):
                ax.axhline(sign * band, color="k", ls=":", lw=0.8, label="averaged noise, +-2 sigma" if sign > 0 else None)
        if r_after is not None:
            after = np.convolve(r_after[:, c], kernel, mode="valid") if width > 1 else r_after[:, c]
            ax.plot(
                t_avg if width > 1 else t,
                after,
                color="tab:green",
                lw=1.1,
                label="after" + (f", {smooth_s:g} s average" if width > 1 else ""),
            )
        ax.set_ylabel(f"{names[c]} [{unit_list[c]}]")
    _shade_segments(axes, segments)
    _finish_rows(fig, axes, title, "t [s]")
    return _save(fig, path)


def plot_correlations(path: PathLike, analysis: ResidualAnalysis, n_inputs: int = 3, title: str | None = None) -> Path:
    """Per channel: left, the residual autocorrelation with the pointwise white-noise band; right, the
    cross-correlation with the ``n_inputs`` inputs of largest |ccf| with the white-noise band (dashed)
    and, dotted in the input's colour, the threshold the test actually uses (Bonferroni over lags,
    inputs and channels, Bartlett-corrected for the residual's own autocorrelation).
    Lags in seconds; at a positive lag the residual follows the input."""
    n_channels = len(analysis.channel_names)
    n_inputs_all = len(analysis.input_names)
    dt = analysis.dt_s
    lags_acf = np.arange(analysis.max_lag + 1) * dt
    lags_ccf = np.arange(-analysis.max_lag, analysis.max_lag + 1) * dt
    z_family = stats.norm.isf(analysis.alpha / (n_channels * n_inputs_all) / (2 * (2 * analysis.max_lag + 1)))
    fig = _figure(12, 1.0 + 2.3 * n_channels)
    axes = fig.subplots(n_channels, 2, sharex="col", squeeze=False)
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink"]
    for c, name in enumerate(analysis.channel_names):
        left, right = axes[c]
        left.vlines(lags_acf[1:], 0.0, analysis.acf[c, 1:], color="k", lw=1.2)
        left.axhline(0.0, color="0.4", lw=0.6)
        left.axhspan(
            -analysis.acf_band,
            analysis.acf_band,
            color="tab:blue",
            alpha=0.15,
            lw=0,
            label=f"white noise, {100 * analysis.confidence:g} %",
        )
        left.set_ylabel(f"ACF {name}")
        left.set_title(f"{name}: Ljung-Box p = {analysis.ljung_box_p[c]:.2g}", fontsize=9)
        order = np.argsort(-np.abs(analysis.ccf_peak[c]), kind="stable")[:n_inputs]
        for colour, j in zip(colours, order, strict=False):
            right.plot(
                lags_ccf,
                analysis.ccf[c, j],
                color=colour,
                lw=1.1,
                label=f"{analysis.input_names[j]} (p = {analysis.ccf_p_value[c, j]:.2g})",
            )
            threshold = z_family * math.sqrt(analysis.ccf_variance_factor[c, j] / analysis.n_samples)
            for sign in (-1, 1):
                right.axhline(sign * threshold, color=colour, ls=":", lw=0.9)
        for sign in (-1, 1):
            right.axhline(
                sign * analysis.ccf_band, color="0.3", ls="--", lw=0.8, label="white noise, pointwise" if sign > 0 else None
            )
        right.set_ylabel(f"CCF {name}")
        right.legend(loc="upper right", fontsize=7)
        for ax in (left, right):
            ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("lag [s]")
    axes[-1, 1].set_xlabel("lag [s] (> 0: residual follows the input)")
    fig.suptitle(title or "Residual autocorrelation (whiteness) and cross-correlation with the inputs")
    return _save(fig, path)


def plot_spectrum(
    path: PathLike,
    t_s: ArrayLike,
    residual: ArrayLike,
    channel_names: Sequence[str] | None = ("wx", "wy", "wz"),
    dominant: Sequence[Sequence[SpectralPeak]] | None = None,
    noise_std: ArrayLike | None = None,
    units: str | Sequence[str] = "rad/s",
    alpha: float = 0.01,
    title: str = "Residual spectrum",
) -> Path:
    """Per channel: the Hann-windowed periodogram (PSD, log-log), the white level estimated from its
    median and the line-detection threshold at ``alpha`` (Bonferroni), the known white level
    ``2 sigma^2 dt`` if ``noise_std`` is given, and the ``dominant`` lines (per channel) marked."""
    t = np.asarray(t_s, dtype=np.float64).ravel()
    r = _series("plot_spectrum: residual", residual, t.size)
    n_channels = r.shape[1]
    names, unit_list = _names_and_units("plot_spectrum", n_channels, channel_names, units)
    dt = float(np.median(np.diff(t)))
    frequency, psd = periodogram(r, dt)
    level, threshold = white_spectrum_level(psd, t.size, alpha)
    fig = _figure(12, 1.2 + 2.2 * n_channels, left_in=1.0, top_in=0.75)
    axes = fig.subplots(n_channels, 1, sharex=True, squeeze=False)[:, 0]
    for c, ax in enumerate(axes):
        ax.loglog(frequency[1:], psd[1:, c], color="0.35", lw=0.7, label="periodogram (Hann)")
        ax.axhline(level[c], color="tab:blue", ls="--", lw=0.9, label="white level (median)")
        ax.axhline(threshold[c], color="tab:red", ls=":", lw=0.9, label=f"line threshold, {100 * (1 - alpha):g} %")
        if noise_std is not None:
            sigma = _per_channel("plot_residuals: noise_std", noise_std, n_channels)
            ax.axhline(2 * sigma[c] ** 2 * dt, color="tab:green", ls="-.", lw=0.9, label="noise floor 2 sigma^2 dt")
        for k, peak in enumerate(dominant[c] if dominant is not None else ()):
            ax.axvline(peak.frequency_hz, color="tab:orange", lw=1.0, alpha=0.8, label="dominant line" if k == 0 else None)
        ax.set_ylabel(f"PSD {names[c]} [({unit_list[c]})^2/Hz]")
    _finish_rows(fig, axes, title, "frequency [Hz]")
    return _save(fig, path)


def plot_ranking(
    path: PathLike,
    candidates: Sequence[Mapping[str, Any]],
    score_key: str = "bic_improvement",
    xlabel: str = "BIC improvement (larger: better explains the residual)",
    title: str = "Candidate effects, ranked",
    higher_is_better: bool = True,
) -> Path:
    """Horizontal bar chart of ``candidate[score_key]`` (a number or numeric string) per candidate, named
    by ``candidate["effect"]``, best on top (largest score, or smallest with ``higher_is_better=False``,
    e.g. for a BIC difference), values annotated; bars on the good side of zero are coloured."""
    if not candidates:
        raise SpaceIdInputError("plot_ranking: no candidates to plot")
    names, scores = [], []
    for i, candidate in enumerate(candidates):
        if "effect" not in candidate or score_key not in candidate:
            raise SpaceIdInputError(
                f"plot_ranking: candidate {i} needs the keys 'effect' and {score_key!r}, has {sorted(candidate)}"
            )
        try:
            scores.append(float(candidate[score_key]))
        except (TypeError, ValueError) as exc:
            raise SpaceIdInputError(
                f"plot_ranking: candidate {i} {score_key!r} must be a number, got {candidate[score_key]!r}"
            ) from exc
        names.append(str(candidate["effect"]))
    sign = 1.0 if higher_is_better else -1.0
    order = np.argsort(sign * np.asarray(scores), kind="stable")  # worst first: the best ends on top of a barh chart
    values = np.asarray(scores)[order]
    fig = _figure(9, 1.3 + 0.45 * len(names), left_in=0.3 + 0.075 * max(len(name) for name in names))
    ax = fig.subplots()
    bars = ax.barh(np.arange(len(names)), values, color=np.where(sign * values > 0, "tab:blue", "0.6"))
    ax.set_yticks(np.arange(len(names)), [names[i] for i in order])
    ax.bar_label(bars, labels=[f"{v:.4g}" for v in values], fontsize=8, padding=3)
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_xlabel(xlabel)
    ax.grid(alpha=0.3, axis="x")
    ax.set_title(title)
    return _save(fig, path)


def plot_before_after(
    path: PathLike,
    labels: Sequence[str],
    values_before: ArrayLike,
    values_after: ArrayLike,
    ylabel: str,
    title: str = "Before and after",
    names: tuple[str, str] = ("before", "after"),
    log_scale: bool = False,
) -> Path:
    """Grouped bars of a quantity per label (e.g. residual RMS / noise per channel) before and after a change."""
    before = np.asarray(values_before, dtype=np.float64).ravel()
    after = np.asarray(values_after, dtype=np.float64).ravel()
    if not len(labels) == before.size == after.size:
        raise SpaceIdInputError(
            f"plot_before_after: expected one value before and after per label ({len(labels)}), got {before.size} and {after.size}"
        )
    x = np.arange(len(labels))
    fig = _figure(max(6.0, 1.2 + 0.9 * len(labels)), 4.5)
    ax = fig.subplots()
    for offset, values, name, colour in ((-0.2, before, names[0], "tab:red"), (0.2, after, names[1], "tab:green")):
        bars = ax.bar(x + offset, values, width=0.4, color=colour, label=name)
        ax.bar_label(bars, labels=[f"{v:.3g}" for v in values], fontsize=8, padding=2)
    ax.set_xticks(x, [str(label) for label in labels])
    if log_scale:
        ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.legend()
    ax.grid(alpha=0.3, axis="y")
    ax.set_title(title)
    return _save(fig, path)
