"""Hand-designed excitation: band-limited multi-sine joint-rate commands."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spaceid_gym.errors import SpaceIdInputError

FloatArray = NDArray[np.float64]


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
