"""Fisher information: one routine for the env's reward, the Cramér-Rao bound and excitation checks.

For measurements ``y_t = f_t(theta) + e_t`` with white Gaussian noise of std ``sigma`` per
component, the Fisher information is ``F = sum_t J_t^T J_t / sigma^2`` with ``J_t = df_t/dtheta``.
The Cramér-Rao bound on any unbiased estimate is ``cov >= F^{-1}``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def fisher_information(jacobians: FloatArray, noise_std: float) -> FloatArray:
    """Fisher information ``sum_t J_t^T J_t / sigma^2``.

    Args:
        jacobians: ``df/dtheta`` stacked over samples, shape (T, m, k) or (m, k).
        noise_std: measurement noise std per component (> 0), same units as ``f``.

    Returns:
        shape (k, k).
    """
    jac = np.asarray(jacobians, dtype=float)
    jac = jac.reshape(-1, jac.shape[-1])
    return (jac.T @ jac) / (noise_std * noise_std)


def log_det(information: FloatArray) -> float:
    """``log det F`` for a symmetric positive-definite ``F`` (via Cholesky; raises if not PD)."""
    chol = np.linalg.cholesky(information)
    return float(2.0 * np.sum(np.log(np.diag(chol))))


def information_gain_nats(before: FloatArray, after: FloatArray) -> float:
    """Information added going from ``before`` to ``after``: ``0.5 (log det after - log det before)``.

    For Gaussian posteriors this is the entropy reduction in nats.
    """
    return 0.5 * (log_det(after) - log_det(before))


def cramer_rao_std(information: FloatArray) -> FloatArray:
    """Standard deviations of the Cramér-Rao bound, ``sqrt(diag(F^{-1}))``, shape (k,)."""
    return np.sqrt(np.diag(np.linalg.inv(information)))
