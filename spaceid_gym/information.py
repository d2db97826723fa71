"""Fisher information: one routine for the env's reward, the Cramér-Rao bound and excitation checks.

:func:`excitation_measures` gives the project's one set of excitation measures (D-optimality, the largest
Cramér-Rao std, the condition number of the scaled information) for a window and a parameterisation: the envs
(``excitation_measures()`` of both), the excitation optimiser, the comparison of excitations and the estimators'
"insufficient excitation" check (through :func:`cramer_rao_std`) all use it.

For measurements ``y_t = f_t(theta) + e_t`` with white Gaussian noise of std ``sigma`` per
component, the Fisher information is ``F = sum_t J_t^T J_t / sigma^2`` with ``J_t = df_t/dtheta``.
The Cramér-Rao bound on any unbiased estimate is ``cov >= F^{-1}``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


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

    The incremental form of :func:`fisher_information` used in the envs' rewards; compiled with numba (the
    factorisation is LAPACK's, through numba's ``np.linalg.cholesky``, which raises on a matrix that is not PD).
    """
    updated = information + (jacobian.T @ jacobian) * inverse_variance
    try:
        chol = np.linalg.cholesky(updated)
    except Exception:  # numba's LinAlgError: not positive definite
        return updated, -np.inf
    total = 0.0
    for j in range(chol.shape[0]):
        total += np.log(chol[j, j])
    return updated, 2.0 * total


@dataclass(frozen=True)
class ExcitationMeasures:
    """How well a window of data excites a parameterisation: the one set of measures of the project.

    Computed by :func:`excitation_measures` from the Fisher information in *scaled* units (each parameter divided by
    its scale, e.g. its prior range), so that the measures do not depend on the parameters' physical units.

    Attributes:
        d_optimality: ``log det F_s`` (nats; D-optimality, larger is better); ``-inf`` if ``F_s`` is singular.
        max_cramer_rao_std: the largest Cramér-Rao std in units of its scale, ``max_i sqrt((F_s^{-1})_ii)``
            (smaller is better; ``inf`` where a direction is not informed, see :func:`cramer_rao_std`).
        condition_number: ``lambda_max / lambda_min`` of ``F_s`` (1 is isotropic; ``inf`` if singular). This is the
            square of the condition number of the scaled, noise-weighted regressor (the arm's standard, ``cond(W_b)``).
        cramer_rao_std: per parameter, in the parameters' physical units (scaled std times the scale), shape (k,).
    """

    d_optimality: float
    max_cramer_rao_std: float
    condition_number: float
    cramer_rao_std: FloatArray

    def to_dict(self) -> dict[str, float | list[float]]:
        """JSON-ready values (``inf`` as ``float('inf')``; :mod:`json` writes it as ``Infinity``)."""
        return {
            "d_optimality": self.d_optimality,
            "max_cramer_rao_std": self.max_cramer_rao_std,
            "condition_number": self.condition_number,
            "cramer_rao_std": self.cramer_rao_std.tolist(),
        }


def excitation_measures(information_scaled: FloatArray, scale: FloatArray | None = None) -> ExcitationMeasures:
    """The excitation measures (:class:`ExcitationMeasures`) of a Fisher information in scaled units.

    Args:
        information_scaled: ``F_s = S F S`` (k, k), ``F`` the information about the physical parameters and ``S =
            diag(scale)``; the data's alone (no prior), symmetric positive semi-definite.
        scale: the parameters' scales (k,), e.g. prior ranges, in their physical units; default ones.
    """
    information = np.asarray(information_scaled, dtype=float)
    if information.ndim != 2 or information.shape[0] != information.shape[1] or not np.isfinite(information).all():
        raise SpaceIdInputError(f"information: expected a finite square matrix, got shape {information.shape}")
    k = information.shape[0]
    scale_array = np.ones(k) if scale is None else np.asarray(scale, dtype=float)
    if scale_array.shape != (k,) or not (scale_array > 0).all():
        raise SpaceIdInputError(f"scale: expected {k} positive scales, got {scale_array.tolist()}")
    symmetric = 0.5 * (information + information.T)
    eigenvalues = np.linalg.eigvalsh(symmetric)
    if eigenvalues[0] > 0.0:
        d_optimality = float(np.sum(np.log(eigenvalues)))
        condition = float(eigenvalues[-1] / eigenvalues[0])
    else:
        d_optimality, condition = -np.inf, np.inf
    std_scaled = cramer_rao_std(symmetric)
    return ExcitationMeasures(d_optimality, float(std_scaled.max()), condition, std_scaled * scale_array)
