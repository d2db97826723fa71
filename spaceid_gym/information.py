"""Fisher information: one routine for the env's reward, the Cramér-Rao bound and excitation checks.

For measurements ``y_t = f_t(theta) + e_t`` with white Gaussian noise of std ``sigma`` per
component, the Fisher information is ``F = sum_t J_t^T J_t / sigma^2`` with ``J_t = df_t/dtheta``.
The Cramér-Rao bound on any unbiased estimate is ``cov >= F^{-1}``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from spaceid_gym.arrays import FloatArray


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


def cramer_rao_std(information: FloatArray, rank_tolerance: float = 1e-9) -> FloatArray:
    """Standard deviations of the Cramér-Rao bound, ``sqrt(diag(F^{-1}))``, shape (k,).

    Eigen-directions of ``F`` with information below ``rank_tolerance`` times the largest are not
    identifiable: every parameter that has a component along one gets ``inf``.
    """
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    informed = values > rank_tolerance * max(values.max(), 0.0)
    if not informed.any():
        return np.full(len(values), np.inf)
    variance = (vectors[:, informed] ** 2) @ (1.0 / values[informed])
    uninformed = (np.abs(vectors[:, ~informed]) > 1e-6).any(axis=1)
    return np.where(uninformed, np.inf, np.sqrt(variance))


@njit(cache=True)
def add_information(information: FloatArray, jacobian: FloatArray, inverse_variance: float) -> tuple[FloatArray, float]:
    """``F + J^T J / sigma^2`` for one sample and its ``log det`` (Cholesky; ``-inf`` if not PD).

    The incremental form of :func:`fisher_information` used in the env's reward; compiled with numba.
    """
    updated = information + (jacobian.T @ jacobian) * inverse_variance
    k = updated.shape[0]
    chol = np.zeros((k, k))
    total = 0.0
    for j in range(k):
        diag = updated[j, j] - np.sum(chol[j, :j] ** 2)
        if diag <= 0.0:
            return updated, -np.inf
        chol[j, j] = np.sqrt(diag)
        total += np.log(chol[j, j])
        for i in range(j + 1, k):
            chol[i, j] = (updated[i, j] - np.sum(chol[i, :j] * chol[j, :j])) / chol[j, j]
    return updated, 2.0 * total
