"""Hand-designed excitation: band-limited multi-sine joint-rate commands."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


class FourierExcitation:
    """Joint-rate commands as a sum of sinusoids, one random multi-sine per joint.

    ``a_j(t) = sum_h A_jh sin(2 pi h f0 t + phi_jh)``, normalised action in [-1, 1] (fraction of
    the joint's rate limit). Amplitudes are drawn so that ``sum_h |A_jh| = amplitude`` and phases
    uniformly, from ``numpy.random.default_rng(seed)``. With zero-mean rates the joint angles
    oscillate about their start by at most ``amplitude * rate_limit / (2 pi f0)``.

    Args:
        n_joints: number of arm joints.
        seed: seed of the amplitudes and phases.
        n_harmonics: harmonics per joint (default 5).
        base_frequency_hz: fundamental ``f0`` (default 0.025 Hz, a 40 s period).
        amplitude: peak normalised rate command, in (0, 1] (default 0.9).
    """

    def __init__(
        self, n_joints: int, seed: int, n_harmonics: int = 5, base_frequency_hz: float = 0.025, amplitude: float = 0.9
    ) -> None:
        if n_joints < 1 or n_harmonics < 1:
            raise SpaceIdInputError(f"excitation: n_joints and n_harmonics must be >= 1, got {n_joints}, {n_harmonics}")
        if not 0.0 < amplitude <= 1.0 or not base_frequency_hz > 0.0:
            raise SpaceIdInputError(
                f"excitation: expected 0 < amplitude <= 1 and base_frequency_hz > 0, got {amplitude}, {base_frequency_hz}"
            )
        rng = np.random.default_rng(seed)
        weights = rng.uniform(0.2, 1.0, size=(n_joints, n_harmonics))
        self.amplitudes = amplitude * weights / weights.sum(axis=1, keepdims=True)
        self.phases = rng.uniform(0.0, 2.0 * np.pi, size=(n_joints, n_harmonics))
        self.angular_frequencies = 2.0 * np.pi * base_frequency_hz * np.arange(1, n_harmonics + 1)
        self.seed = seed

    def __call__(self, t_s: float) -> NDArray[np.float32]:
        """Normalised joint-rate command at time ``t_s``, shape (n,), in [-1, 1]."""
        return np.sum(self.amplitudes * np.sin(self.angular_frequencies * t_s + self.phases), axis=1).astype(np.float32)


class SmoothRandomExcitation:
    """A smooth random joint-rate command per joint: the derivative of a random cubic spline of the joint's excursion.

    Per joint, knots at ``t_0 = 0 < t_1 < ... < t_K`` with spacings drawn uniformly in ``knot_spacing_s``
    (default 2-5 s) until ``t_K >= duration_s``, values uniform in [-1, 1] (0 at the first and last knot), joined by a
    cubic spline with zero slope at both ends (``scipy.interpolate.CubicSpline``, clamped). The command is the
    spline's derivative scaled so that its peak over the window is ``amplitude``: it starts and ends at rest, its
    rate of change is continuous, and each joint's angle stays within ``amplitude * rate_limit * max|p| / max|p'|``
    of where it started instead of drifting as the integral of a random rate would. After ``t_K`` (and before 0)
    the command is zero. Everything is drawn from ``numpy.random.default_rng(seed)``.

    Args:
        n_joints: number of arm joints.
        seed: seed of the knots.
        duration_s: the window the command must cover, s (> 0).
        knot_spacing_s: ``(low, high)`` range of the knot spacings, s, ``0 < low <= high``.
        amplitude: peak normalised rate command of each joint, in (0, 1] (default 0.9).
    """

    def __init__(
        self,
        n_joints: int,
        seed: int,
        duration_s: float,
        knot_spacing_s: tuple[float, float] = (2.0, 5.0),
        amplitude: float = 0.9,
    ) -> None:
        low, high = knot_spacing_s
        if n_joints < 1:
            raise SpaceIdInputError(f"excitation: n_joints must be >= 1, got {n_joints}")
        if not (np.isfinite(duration_s) and duration_s > 0.0):
            raise SpaceIdInputError(f"excitation: duration_s expected a finite time > 0 s, got {duration_s!r}")
        if not (np.isfinite(high) and 0.0 < low <= high):
            raise SpaceIdInputError(f"excitation: knot_spacing_s expected 0 < low <= high s, got {knot_spacing_s!r}")
        if not 0.0 < amplitude <= 1.0:
            raise SpaceIdInputError(f"excitation: expected 0 < amplitude <= 1, got {amplitude}")
        rng = np.random.default_rng(seed)
        spacings = [rng.uniform(low, high)]
        while sum(spacings) < duration_s:
            spacings.append(rng.uniform(low, high))
        self.knots_s = np.concatenate(([0.0], np.cumsum(spacings)))
        values = rng.uniform(-1.0, 1.0, size=(len(self.knots_s), n_joints))
        values[[0, -1]] = 0.0
        self._excursion = CubicSpline(self.knots_s, values, bc_type="clamped")
        self.scale = amplitude / _peak_slope(self._excursion.c, np.diff(self.knots_s))
        self.seed = seed

    def __call__(self, t_s: float) -> NDArray[np.float32]:
        """Normalised joint-rate command at time ``t_s``, shape (n,), in [-1, 1] (zero outside the knots)."""
        if not 0.0 <= t_s <= self.knots_s[-1]:
            return np.zeros(len(self.scale), dtype=np.float32)
        return np.clip(self.scale * self._excursion(t_s, 1), -1.0, 1.0).astype(np.float32)


def _peak_slope(coefficients: FloatArray, widths_s: FloatArray) -> FloatArray:
    """``max |p'|`` per column (n,) of a piecewise cubic ``p = c0 s^3 + c1 s^2 + c2 s + c3`` on pieces ``s in [0, h]``:
    ``coefficients`` (4, pieces, n) as ``scipy``'s ``PPoly.c``, ``widths_s`` (pieces,). The slope's extremes lie at
    the pieces' ends and where ``p'' = 0`` inside one."""
    c0, c1, c2 = coefficients[0], coefficients[1], coefficients[2]
    h = widths_s[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(c0 != 0.0, np.clip(-c1 / (3.0 * c0), 0.0, h), 0.0)
    slopes = [3.0 * c0 * s * s + 2.0 * c1 * s + c2 for s in (np.zeros_like(h), h, vertex)]
    peak = np.max(np.abs(slopes), axis=(0, 1))
    return np.where(peak > 0.0, peak, 1.0)
