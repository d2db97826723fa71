"""The encoders' noise carried, step by step, into the attitude channel's residual: its covariance in time.

The attitude channel (:mod:`estimators.attitude_channel`) predicts each step's rotation from the encoders alone: the
base rate at the step's midpoint, joint angles ``(q_{k-1} + q_k) / 2`` and rates ``(q_k - q_{k-1}) / dt_k``, through the
midpoint rule's map ``S_k = (A_{k-1} + A_k) / 2 dt_k`` (:func:`~estimators.attitude_integration.midpoint_step_map`).
An encoder error ``n_k`` (white, std ``sigma_e`` per joint) of sample ``k`` therefore enters steps ``k`` and ``k + 1``
only, and to first order the residual's step ``d_k`` gains ``P_k n_{k-1} + C_k n_k`` with

    ``P_k = S_k (W_k / 2 - V_k / dt_k)``,  ``C_k = S_k (W_k / 2 + V_k / dt_k)``   (3 x n each),

``W_k`` and ``V_k`` the derivatives of the model's base rate at step ``k``'s midpoint in the joint angles and the
joint rates. The steps' covariance is block-tridiagonal:

    ``Cov(d_k) = sigma_e^2 (P_k P_k^T + C_k C_k^T)``,  ``Cov(d_k, d_{k-1}) = sigma_e^2 P_k C_{k-1}^T``.

It changes with the arm's configuration, and at each sample it is nearly flat: the momentum map carries the joints'
noise into two directions of rotation far more than the third, and those directions turn as the arm moves. On a
noise-free attitude this is the whole residual (the midpoint rule's own error is taken out); a star tracker adds its
white error, ``s^2 (2 I)`` and ``-s^2 I`` on the two bands (:meth:`EncoderPropagation.covariance`).

The derivatives are taken where the base rate is computed, on the channel's midpoint samples: ``W`` by a forward
difference of each joint's angle over every sample at once (the base rate of a sample depends on that sample's joint
state alone in a model without state-carrying effects, which is checked), ``V`` likewise, where the base rate is
linear. :func:`whiten_block_tridiagonal` whitens a residual under such a covariance (a banded Cholesky factor, five
sub-diagonals), with its log-determinant.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cholesky_banded, solve_banded

from estimators.attitude_integration import midpoint_log, midpoint_step_map, relative_attitudes
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog

#: the forward-difference step of the joint angles (rad) and rates (rad/s) for the base rate's derivatives: the
#: base rate is smooth in the angles (a 1e-6 rad step leaves a relative error of order 1e-6) and linear in the rates
ANGLE_STEP_RAD, RATE_STEP_RAD_S = 1e-6, 1e-3


@dataclass(frozen=True)
class EncoderPropagation:
    """How each encoder sample's error moves the attitude residual's steps (see the module docstring).

    Attributes:
        previous: ``P`` (T-1, 3, n): step ``k``'s rotation (first sample's axes, rad) per rad of the encoders at sample
            ``k - 1`` (the array's row ``k - 1`` is step ``k``).
        current: ``C`` (T-1, 3, n): the same per rad of the encoders at sample ``k``.
    """

    previous: FloatArray
    current: FloatArray

    def covariance(self, encoder_std_rad: float, white_std_rad: float = 0.0) -> tuple[FloatArray, FloatArray]:
        """The steps' covariance (rad^2) for encoder noise ``encoder_std_rad`` per joint and an attitude source's white
        error ``white_std_rad`` per axis: the diagonal blocks ``Cov(d_k)`` (T-1, 3, 3) and the blocks below them
        ``Cov(d_k, d_{k-1})`` (T-2, 3, 3), step 1 first."""
        if not (np.isfinite(encoder_std_rad) and encoder_std_rad >= 0.0 and np.isfinite(white_std_rad) and white_std_rad >= 0.0):
            raise SpaceIdInputError(
                f"encoder propagation: expected noise stds >= 0, got encoder {encoder_std_rad!r}, white {white_std_rad!r}"
            )
        p, c = self.previous, self.current
        e2, w2 = encoder_std_rad**2, white_std_rad**2
        diagonal = e2 * (np.einsum("kin,kjn->kij", p, p) + np.einsum("kin,kjn->kij", c, c)) + 2.0 * w2 * np.eye(3)
        below = e2 * np.einsum("kin,kjn->kij", p[1:], c[:-1]) - w2 * np.eye(3)
        return diagonal, below


def encoder_propagation(model: IdentificationModel, log: MeasurementLog, theta: FloatArray) -> EncoderPropagation:
    """:class:`EncoderPropagation` of ``model`` at unknowns ``theta`` (k,) on ``log`` (with attitude quaternions).

    Raises:
        SpaceIdInputError: the log has no attitude, fewer than 3 samples, or ``model``'s base rate at a sample depends
            on other samples' joint state (an effect with a state carried in time), where this propagation does not
            hold."""
    if log.n_samples < 3:
        raise SpaceIdInputError(f"encoder propagation: expected a log of at least 3 samples, got {log.n_samples}")
    step_map = midpoint_step_map(relative_attitudes(log), log.t_s)
    mid = midpoint_log(log)
    theta = np.asarray(theta, dtype=float)[None]
    base = model.problem(mid).base_rate(theta, count=False)[0, 1:]
    n_joints = mid.q_rad.shape[1]
    angle, rate = np.empty((len(base), 3, n_joints)), np.empty((len(base), 3, n_joints))
    for joint in range(n_joints):
        for array, step, out in (("q_rad", ANGLE_STEP_RAD, angle), ("dq_rad_s", RATE_STEP_RAD_S, rate)):
            moved = np.array(getattr(mid, array), dtype=float)
            moved[1:, joint] += step
            shifted = model.problem(dataclasses.replace(mid, **{array: moved})).base_rate(theta, count=False)[0, 1:]
            out[:, :, joint] = (shifted - base) / step
    _check_pointwise(model, mid, theta, base)
    dt = np.diff(np.asarray(log.t_s, dtype=float))[:, None, None]
    previous = np.einsum("kij,kjn->kin", step_map, 0.5 * angle - rate / dt)
    current = np.einsum("kij,kjn->kin", step_map, 0.5 * angle + rate / dt)
    return EncoderPropagation(previous, current)


def _check_pointwise(model: IdentificationModel, mid: MeasurementLog, theta: FloatArray, base: FloatArray) -> None:
    """Raise unless a change of one midpoint sample's joint rates moves the base rate at that sample only (a model
    whose effects carry a state in time, such as slosh, propagates noise differently)."""
    sample = len(base) // 2 + 1
    moved = np.array(mid.dq_rad_s, dtype=float)
    moved[sample] += RATE_STEP_RAD_S
    shifted = model.problem(dataclasses.replace(mid, dq_rad_s=moved)).base_rate(theta, count=False)[0, 1:]
    change = np.abs(shifted - base)
    change[sample - 1] = 0.0
    if np.max(change) > 1e-12 * max(float(np.max(np.abs(base))), 1e-300):
        raise SpaceIdInputError(
            "encoder propagation: the model's base rate at one sample depends on other samples' joint state "
            f"({model.parameters.names[-1]!r} carries a state in time); the propagation holds for models without"
        )


def whiten_block_tridiagonal(values: FloatArray, diagonal: FloatArray, below: FloatArray) -> tuple[FloatArray, float]:
    """``values`` (m, 3) or (m, 3, k) whitened under the block-tridiagonal covariance of ``diagonal`` (m, 3, 3) and
    ``below`` (m-1, 3, 3) (:meth:`EncoderPropagation.covariance`): ``L^-1 values`` with ``L`` its lower Cholesky
    factor, rows in time then axis order, and ``log det`` of the covariance.

    Raises:
        SpaceIdInputError: shapes that do not match, or a covariance that is not positive definite."""
    m = diagonal.shape[0]
    if diagonal.shape != (m, 3, 3) or below.shape != (m - 1, 3, 3) or values.shape[:2] != (m, 3):
        raise SpaceIdInputError(
            f"whiten: expected values (m, 3[, k]), blocks (m, 3, 3) and (m-1, 3, 3); got {values.shape}, "
            f"{diagonal.shape}, {below.shape}"
        )
    n = 3 * m
    band = np.zeros((6, n))  # LAPACK lower band storage: band[r, j] = Cov[j + r, j]
    columns = 3 * np.arange(m)
    for a in range(3):
        for b in range(a + 1):
            band[a - b, columns + b] = diagonal[:, a, b]
        for b in range(3):
            band[3 + a - b, columns[:-1] + b] = below[:, a, b]
    try:
        factor = cholesky_banded(band, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        raise SpaceIdInputError("whiten: the covariance is not positive definite") from None
    flat = values.reshape(n, -1)
    whitened = solve_banded((5, 0), factor, flat, check_finite=False)
    return whitened.reshape(values.shape), float(2.0 * np.sum(np.log(factor[0])))
