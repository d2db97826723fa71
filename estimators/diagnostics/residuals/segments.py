"""Where in time the residual exceeds the noise (Holm-adjusted windows), and what the arm was doing there."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from estimators.diagnostics.residuals._checks import _array, _check_probability, _check_same_rows, _columns
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: a joint "moves" in a segment if its largest |dq| there exceeds this (rad/s): 0.57 deg/s, far
#: above joint-rate sensor noise (1e-4 rad/s) and far below commanded excitation rates (0.1-1 rad/s)
MOVING_THRESHOLD_RAD_S = 0.01


@dataclass
class Segment:
    """A time segment where the residual exceeds the noise, and what the arm did there.

    Attributes:
        t_start_s, t_end_s: the segment's window edges (s).
        n_samples: samples in it.
        rms_over_noise: ``sqrt(mean over samples and channels of (r / sigma)^2)``; 1 for noise.
        channel_rms_over_noise: (C,) the same per channel.
        statistic: ``sum (r / sigma)^2`` over the segment.
        p_value: smallest Holm-adjusted p-value of its windows (family-wise over all windows).
        joint_names: (n,) names, ``q1``..``qn`` by default.
        moving_joints: names of the joints whose max |dq| exceeds ``moving_threshold_rad_s``, fastest first.
        max_abs_dq_rad_s: (n,) largest |dq| per joint, rad/s.
        rms_ddq_rad_s2: (n,) RMS joint acceleration per joint (dq differentiated), rad/s^2.
        q_span_rad: (n,) range of motion (max - min of q) per joint, rad.
        moving_threshold_rad_s: the threshold used.
    """

    t_start_s: float
    t_end_s: float
    n_samples: int
    rms_over_noise: float
    channel_rms_over_noise: FloatArray
    statistic: float
    p_value: float
    joint_names: list[str]
    moving_joints: list[str]
    max_abs_dq_rad_s: FloatArray
    rms_ddq_rad_s2: FloatArray
    q_span_rad: FloatArray
    moving_threshold_rad_s: float = MOVING_THRESHOLD_RAD_S

    def describe(self, channel_names: tuple[str, ...] | list[str] | None = None, max_joints: int = 3) -> str:
        """One line: when, how far above the noise, on which channel, which joints moved (fastest first) how fast."""
        n_channels = len(self.channel_rms_over_noise)
        names = list(channel_names) if channel_names is not None else [f"ch{c + 1}" for c in range(n_channels)]
        worst = int(np.argmax(self.channel_rms_over_noise))
        text = (
            f"t = {self.t_start_s:.2f}-{self.t_end_s:.2f} s: residual {self.rms_over_noise:.2f} x noise "
            f"(largest on {names[worst]}: {self.channel_rms_over_noise[worst]:.2f} x; p = {self.p_value:.2g}); "
        )
        if not self.moving_joints:
            return text + f"arm at rest (all |dq| < {self.moving_threshold_rad_s:g} rad/s)"
        index = {name: i for i, name in enumerate(self.joint_names)}
        moves = ", ".join(
            f"{name} (|dq| up to {self.max_abs_dq_rad_s[index[name]]:.3g} rad/s, RMS ddq {self.rms_ddq_rad_s2[index[name]]:.3g} rad/s^2)"
            for name in self.moving_joints[:max_joints]
        )
        more = len(self.moving_joints) - max_joints
        return text + f"moving {moves}" + (f" and {more} more joint(s)" if more > 0 else "")


def _normalised_square(residual: FloatArray, noise_std: FloatArray) -> FloatArray:
    """(r / sigma)^2 per sample and channel; a channel with sigma = 0 gives 0 where r = 0, inf elsewhere."""
    square = residual**2
    variance = noise_std**2
    return np.divide(square, variance, out=np.where(square > 0.0, np.inf, 0.0), where=variance > 0.0)


def _holm_adjusted(p_values: FloatArray) -> FloatArray:
    """Holm step-down adjusted p-values (family-wise error control over all entries)."""
    m = p_values.size
    order = np.argsort(p_values)
    adjusted_sorted = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p_values[order]))
    adjusted = np.empty_like(p_values)
    adjusted[order] = adjusted_sorted
    return adjusted


def _window_index(t_s: FloatArray, window_s: float) -> FloatArray:
    """Window number of each sample (windows of ``window_s`` from t[0]); a last window shorter than half is merged."""
    index = np.floor((t_s - t_s[0]) / window_s + 1e-9).astype(np.int64)
    last = index[-1]
    if last > 0 and t_s[-1] - (t_s[0] + last * window_s) < 0.5 * window_s:
        index[index == last] = last - 1
    return index


def failing_segments(
    t_s: ArrayLike,
    residual: ArrayLike,
    noise_std: ArrayLike,
    q: ArrayLike,
    dq: ArrayLike,
    window_s: float = 2.0,
    confidence: float = 0.99,
    max_segments: int = 10,
    noise_dof: float | None = None,
    joint_names: list[str] | tuple[str, ...] | None = None,
    moving_threshold_rad_s: float = MOVING_THRESHOLD_RAD_S,
) -> list[Segment]:
    """The time segments whose residual exceeds the noise, ranked by excess (RMS / noise).

    The log is partitioned into windows of ``window_s`` (from ``t_s[0]``; a last window shorter than
    half is merged into the previous one). In each window, ``S = sum (r / sigma)^2`` over its samples
    and the C channels is chi2(n_w C) under "noise only" with a known sigma; with an *estimated* sigma
    (``noise_dof`` = its effective degrees of freedom summed over channels, e.g.
    ``C * noise_floor_dof(T)``) ``S / (n_w C)`` is tested against F(n_w C, noise_dof) instead. Windows
    whose Holm-adjusted p-value is below ``1 - confidence`` are flagged (family-wise over the windows),
    consecutive flagged windows merge into a segment, and segments are ranked by ``rms_over_noise``.

    Args:
        t_s: (T,) time, s, strictly increasing.
        residual: (T, C) measured - predicted.
        noise_std: (C,) or scalar white-noise std per channel (unit of residual), >= 0.
        q: (T, n) joint angles, rad. dq: (T, n) joint rates, rad/s (differentiated for ddq).
        window_s: window length, s (> 0).
        confidence: e.g. 0.99.
        max_segments: at most this many segments are returned.
        noise_dof: None if ``noise_std`` is known; else the effective degrees of freedom of its estimate.
        joint_names: (n,) names; default ``q1``..``qn``.
        moving_threshold_rad_s: a joint moves in a segment if its max |dq| there exceeds this.

    Returns:
        Up to ``max_segments`` :class:`Segment`, largest ``rms_over_noise`` first; empty if none fails.
    """
    t = _array(t_s, "failing_segments: t_s", (1,), min_rows=2)
    if np.any(np.diff(t) <= 0.0):
        raise SpaceIdInputError("failing_segments: t_s must be strictly increasing")
    r, _ = _columns(residual, "failing_segments: residual")
    q_arr, _ = _columns(q, "failing_segments: q")
    dq_arr, _ = _columns(dq, "failing_segments: dq")
    _check_same_rows(
        t.shape[0], **{"failing_segments: residual": r, "failing_segments: q": q_arr, "failing_segments: dq": dq_arr}
    )
    if q_arr.shape != dq_arr.shape:
        raise SpaceIdInputError(f"failing_segments: q {q_arr.shape} and dq {dq_arr.shape} must have the same shape (T, n)")
    sigma = np.broadcast_to(_array(np.atleast_1d(noise_std), "failing_segments: noise_std", (1,)), (r.shape[1],))
    if np.any(sigma < 0.0) or np.asarray(noise_std).size not in (1, r.shape[1]):
        raise SpaceIdInputError(
            f"failing_segments: noise_std must be >= 0, scalar or one per channel ({r.shape[1]}), got {noise_std!r}"
        )
    if not window_s > 0.0:
        raise SpaceIdInputError(f"failing_segments: window_s must be > 0 s, got {window_s!r}")
    if noise_dof is not None and not noise_dof > 0.0:
        raise SpaceIdInputError(f"failing_segments: noise_dof must be > 0 or None, got {noise_dof!r}")
    alpha = 1.0 - _check_probability(confidence, "failing_segments: confidence")
    n_joints = q_arr.shape[1]
    names = list(joint_names) if joint_names is not None else [f"q{i + 1}" for i in range(n_joints)]
    if len(names) != n_joints:
        raise SpaceIdInputError(f"failing_segments: joint_names must name the {n_joints} joints, got {len(names)}")

    z2 = _normalised_square(r, sigma)  # (T, C)
    index = _window_index(t, window_s)
    n_windows = int(index[-1]) + 1
    per_window = np.bincount(index, weights=z2.sum(axis=1), minlength=n_windows)
    counts = np.bincount(index, minlength=n_windows)
    present = counts > 0
    dof = counts[present] * r.shape[1]
    with np.errstate(invalid="ignore"):
        if noise_dof is None:
            raw_p = stats.chi2.sf(per_window[present], dof)
        else:
            raw_p = stats.f.sf(per_window[present] / dof, dof, noise_dof)
    raw_p = np.where(np.isnan(raw_p), 0.0, raw_p)  # inf / inf: a noiseless channel with residual
    adjusted = np.ones(n_windows)
    adjusted[present] = _holm_adjusted(raw_p)
    flagged = present & (adjusted < alpha)

    ddq = np.gradient(dq_arr, t, axis=0, edge_order=2) if t.shape[0] > 2 else np.zeros_like(dq_arr)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flagged.astype(np.int8), [0]])))
    segments = []
    for first, stop in zip(edges[::2], edges[1::2], strict=True):
        mask = (index >= first) & (index < stop)
        seg_z2 = z2[mask]
        max_dq = np.max(np.abs(dq_arr[mask]), axis=0)
        moving = [names[j] for j in np.argsort(-max_dq, kind="stable") if max_dq[j] > moving_threshold_rad_s]
        segments.append(
            Segment(
                t_start_s=float(max(t[0], t[0] + first * window_s)),
                t_end_s=float(t[-1] if stop == n_windows else t[0] + stop * window_s),
                n_samples=int(mask.sum()),
                rms_over_noise=float(np.sqrt(seg_z2.mean())),
                channel_rms_over_noise=np.sqrt(seg_z2.mean(axis=0)),
                statistic=float(seg_z2.sum()),
                p_value=float(adjusted[first:stop].min()),
                joint_names=names,
                moving_joints=moving,
                max_abs_dq_rad_s=max_dq,
                rms_ddq_rad_s2=np.sqrt(np.mean(ddq[mask] ** 2, axis=0)),
                q_span_rad=np.ptp(q_arr[mask], axis=0),
                moving_threshold_rad_s=moving_threshold_rad_s,
            )
        )
    segments.sort(key=lambda s: -s.rms_over_noise)
    return segments[:max_segments]
