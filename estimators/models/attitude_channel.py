"""The star tracker as a second channel of the identification model: the base rotation the model predicts.

The paper's model predicts the base rate and compares it with the gyro. A log with attitude quaternions
(a star tracker) also measures how far the base has turned, with an error that does not grow with time:
5 arcsec per sample against the ~2e-4 rad the gyro's angle random walk accumulates in a minute. An effect
that changes the base rate slowly (an external torque ramps the system momentum, a momentum adds a nearly
constant rate) moves the attitude by its *integral*, which the star tracker pins far more tightly than the
gyro's samples pin the rate; a gyro error (bias, scale, delay) does not rotate the base at all.

The channel compares rotation vectors accumulated from the first sample, in the axes of the base at the
first sample (``A_k = R_0^T R_k``, ``R`` base to inertial):

* measured: ``Phi_k = sum_{j<=k} log(A_j A_{j-1}^T)``, the star tracker's rotation increments summed. With the
  star tracker's error a small rotation ``n_k`` of each attitude, ``Phi_k = Phi_true_k + A_k n_k - A_0 n_0``:
  the errors telescope, each sample keeps one independent error;
* predicted: ``Phi_hat_k = sum_{j<=k} (A_{j-1} + A_j) / 2 omega_j dt_j``, with ``omega_j`` the model's base rate
  (without the gyro's measurement effects) at the step's midpoint, from the encoders: joint angles
  ``(q_{j-1} + q_j) / 2`` and rates ``(q_j - q_{j-1}) / dt_j``. Encoder differences rather than the logged
  joint rates: their noise telescopes too, where the rate sensors' noise would integrate into a random walk
  of the predicted attitude. Midpoint rule: its error per step is O(dt^3) (tests hold the whole channel to
  1e-7 rad on a noise-free log);
* residual ``Phi_hat - Phi`` minus its mean over the log (per axis): the mean absorbs ``A_0 n_0``, 3 of the
  3T values; what is left is white with the star tracker's per-axis std ``sigma_st``.

``sigma_st`` is estimated from the data (:meth:`AttitudeChannel.noise_std`): the first differences of the
residual are ``A_k n_k - A_{k-1} n_{k-1}`` plus the model's error over one step (far below the noise for any
fit near the data), so their mean square is ``2 sigma_st^2``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog

if TYPE_CHECKING:
    from estimators.problem import IdentificationModel

FloatArray = NDArray[np.float64]


class BaseRateProblem(Protocol):
    """What :class:`AttitudeChannel` needs of a problem (:class:`~estimators.problem.IdentificationProblem` has it)."""

    def base_rate(self, theta: FloatArray, count: bool = True) -> FloatArray: ...

    def base_rate_jacobian(self, theta: FloatArray, count: bool = True) -> FloatArray: ...


def midpoint_log(log: MeasurementLog) -> MeasurementLog:
    """The log's steps as samples: sample 0 as logged, then sample ``j`` (1..T-1) at the midpoint of step ``j``.

    Midpoint samples carry ``t = (t_{j-1} + t_j) / 2``, joint angles ``(q_{j-1} + q_j) / 2``, joint rates from the
    encoders ``(q_j - q_{j-1}) / dt_j``, the attitude interpolated on SO(3) and the mean gyro rate. Sample 0 keeps
    the first sample's time and attitude, the reference of the effect terms (momentum in the first sample's axes).
    """
    quat = log.quat_base_to_inertial_wxyz
    if quat is None:
        raise SpaceIdInputError("attitude channel: the log has no attitude quaternions (no star tracker)")
    t = np.asarray(log.t_s, dtype=float)
    q = np.asarray(log.q_rad, dtype=float)
    dt = np.diff(t)
    mid_t = 0.5 * (t[:-1] + t[1:])
    rotations = Rotation.from_quat(np.asarray(quat, dtype=float), scalar_first=True)
    mid_quat = Slerp(t, rotations)(mid_t).as_quat(scalar_first=True)
    omega = np.asarray(log.omega_base_body_rad_s, dtype=float)
    return MeasurementLog(
        t_s=np.concatenate(([t[0]], mid_t)),
        q_rad=np.concatenate((q[:1], 0.5 * (q[:-1] + q[1:]))),
        dq_rad_s=np.concatenate((log.dq_rad_s[:1], np.diff(q, axis=0) / dt[:, None])),
        omega_base_body_rad_s=np.concatenate((omega[:1], 0.5 * (omega[:-1] + omega[1:]))),
        quat_base_to_inertial_wxyz=np.concatenate((np.asarray(quat[:1], dtype=float), mid_quat)),
    )


class AttitudeChannel:
    """The star tracker's rotation against the model's on one log (see the module docstring).

    Args:
        problem: the model bound to the log's midpoint samples (:func:`midpoint_log`), any object with
            ``base_rate(theta (P, k)) -> (P, T, 3)`` and ``base_rate_jacobian(theta (k,)) -> (3T, k)``.
        log: the log itself, with attitude quaternions.

    Attributes:
        measured: ``Phi`` (T, 3), rad, the star tracker's accumulated rotation, first sample's base axes.
        n_values: ``3T - 3``, the residual's degrees of freedom (the mean is removed).
    """

    def __init__(self, problem: BaseRateProblem, log: MeasurementLog) -> None:
        quat = log.quat_base_to_inertial_wxyz
        if quat is None:
            raise SpaceIdInputError("attitude channel: the log has no attitude quaternions (no star tracker)")
        rot = Rotation.from_quat(np.asarray(quat, dtype=float), scalar_first=True).as_matrix()
        relative = np.einsum("ji,tjk->tik", rot[0], rot)  # A_k = R_0^T R_k
        steps = np.einsum("tij,tkj->tik", relative[1:], relative[:-1])  # A_j A_{j-1}^T
        increments = Rotation.from_matrix(steps).as_rotvec()
        self.problem = problem
        self.measured = np.concatenate((np.zeros((1, 3)), np.cumsum(increments, axis=0)))
        #: ``(A_{j-1} + A_j) / 2 * dt_j`` (T-1, 3, 3): maps the step's midpoint rate to its rotation increment
        self._step_map = 0.5 * (relative[:-1] + relative[1:]) * np.diff(np.asarray(log.t_s, dtype=float))[:, None, None]
        self.n_values = 3 * log.n_samples - 3

    @classmethod
    def of(cls, model: IdentificationModel, log: MeasurementLog) -> AttitudeChannel | None:
        """The channel of ``model`` on ``log``; ``None`` when the log has no attitude or fewer than 3 samples."""
        if log.quat_base_to_inertial_wxyz is None or log.n_samples < 3:
            return None
        return cls(model.problem(midpoint_log(log)), log)

    def predicted(self, theta: FloatArray) -> FloatArray:
        """``Phi_hat`` (P, T, 3), rad, for ``theta`` (P, k)."""
        omega = self.problem.base_rate(np.atleast_2d(theta))[:, 1:]  # midpoint rates (P, T-1, 3)
        steps = np.einsum("tij,ptj->pti", self._step_map, omega)
        return np.concatenate((np.zeros((len(steps), 1, 3)), np.cumsum(steps, axis=1)), axis=1)

    def residuals(self, theta: FloatArray) -> FloatArray:
        """``Phi_hat - Phi`` minus its mean per axis (3T,), rad, at ``theta`` (k,)."""
        error = self.predicted(theta)[0] - self.measured
        return (error - error.mean(axis=0)).ravel()

    def jacobian(self, theta: FloatArray) -> FloatArray:
        """``d residuals / d theta`` (3T, k) at ``theta`` (k,)."""
        n_t = len(self.measured)
        rates = self.problem.base_rate_jacobian(np.asarray(theta, dtype=float)).reshape(n_t, 3, -1)[1:]
        steps = np.einsum("tij,tjk->tik", self._step_map, rates)
        accumulated = np.concatenate((np.zeros((1, 3, steps.shape[2])), np.cumsum(steps, axis=0)))
        return (accumulated - accumulated.mean(axis=0)).reshape(3 * n_t, -1)

    def fisher(self, theta: FloatArray, noise_std_rad: float) -> FloatArray:
        """Fisher information (k, k) of the star tracker about ``theta`` (k,), for its per-axis noise std (rad)."""
        jac = self.jacobian(theta)
        return (jac.T @ jac) / (noise_std_rad * noise_std_rad)

    def noise_std(self, theta: FloatArray) -> float:
        """The star tracker's per-axis noise std (rad), from the first differences of the residual at ``theta`` (k,)."""
        steps = np.diff(self.residuals(theta).reshape(-1, 3), axis=0)
        return float(np.sqrt(np.mean(steps * steps) / 2.0))
