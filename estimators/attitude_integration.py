"""How the attitude channel turns the model's base rate into rotation increments, and the midpoint rule's own error.

The channel (:mod:`estimators.attitude_channel`) predicts each step's rotation with the midpoint rule: the base rate
at the step's midpoint (joint angles ``(q_{j-1} + q_j) / 2``, joint rates ``(q_j - q_{j-1}) / dt_j``, one model
evaluation per step, :func:`midpoint_log`) times ``dt_j``. Its error per step is of order ``dt^3`` and systematic: where
the base wobbles about two axes and the joints sweep an area in joint space (the rotation a free-floating base gets
from a closed joint path), it accumulates to ~2e-6 rad over 60 s at 20 Hz on orbit7, more than a noise-free or
filtered attitude's error, and a constant momentum fits part of it (clean logs were named ``initial_momentum``).

The channel takes that error out: at one set of unknowns it adds, to each step, the fourth-order increment
(:func:`fourth_order_increments`) less the midpoint rule's. The fourth-order increment interpolates the encoder samples with a cubic Hermite per step
(tangents from the neighbouring encoder differences, so that neither the joint-rate sensors' noise nor their timing
enters), evaluates the base rate at the step's two Gauss-Legendre nodes and composes them with the coning term of
the rotation vector (Bortz): ``phi = dt / 2 (w1 + w2) + sqrt(3) / 12 dt^2 w1 x w2``, exact to ``dt^5`` per step for a
rate that is smooth within the step. A joint servo's acceleration may jump at each sample (a new command): within a
step the motion is smooth, so the rule is applied step by step, never across a sample.

Against the simulator's exact attitude on noise-free logs (tests/test_diagnose_robustness.py), the midpoint rule's
accumulated error of 0.9-6.5e-6 rad RMS over 60 s at 20 Hz falls to 1.5-3.4e-8 rad with the correction at the true
unknowns, and that was mostly the simulator's own integrator at one RKMK4 step per sample (with 8 sub-steps the
correction leaves 2-37e-10 rad; the env now takes three at 20 Hz, :data:`~spaceid_gym.sim.simulator.MAX_INTEGRATION_STEP_S`). The error changes with the unknowns (by a tenth over 5 kg of fuel on quick3), so the
channel computes it once per log at a reference (the baseline's fit in a diagnosis) with its derivative in the base's
unknowns, and carries it to first order: from 20 kg off the reference it still leaves at most 9.5 %.
"""

from __future__ import annotations

import math
import weakref

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog

#: the two Gauss-Legendre nodes of a step, as fractions of it
GAUSS_NODES = (0.5 - math.sqrt(3.0) / 6.0, 0.5 + math.sqrt(3.0) / 6.0)


def _resampled(
    log: MeasurementLog, t_s: FloatArray, q_rad: FloatArray, dq_rad_s: FloatArray, omega_rad_s: FloatArray
) -> MeasurementLog:
    """The log's first sample as logged (the reference of the effect terms: momentum in the first sample's axes),
    then samples at ``t_s`` with the joint motion and gyro given and the attitude interpolated on SO(3)."""
    quat = log.quat_base_to_inertial_wxyz
    if quat is None:
        raise SpaceIdInputError("attitude channel: the log has no attitude quaternions (no star tracker)")
    rotations = Rotation.from_quat(np.asarray(quat, dtype=float), scalar_first=True)
    return MeasurementLog(
        t_s=np.concatenate(([log.t_s[0]], t_s)),
        q_rad=np.concatenate((log.q_rad[:1], q_rad)),
        dq_rad_s=np.concatenate((log.dq_rad_s[:1], dq_rad_s)),
        omega_base_body_rad_s=np.concatenate((log.omega_base_body_rad_s[:1], omega_rad_s)),
        quat_base_to_inertial_wxyz=np.concatenate(
            (np.asarray(quat[:1], dtype=float), Slerp(log.t_s, rotations)(t_s).as_quat(scalar_first=True))
        ),
    )


def relative_attitudes(log: MeasurementLog) -> FloatArray:
    """``A_k = R_0^T R_k`` (T, 3, 3): the base's attitude at each sample in the axes of the base at the first (``R``
    base to inertial, from the log's quaternions)."""
    quat = log.quat_base_to_inertial_wxyz
    if quat is None:
        raise SpaceIdInputError("attitude channel: the log has no attitude quaternions (no star tracker)")
    rot = Rotation.from_quat(np.asarray(quat, dtype=float), scalar_first=True).as_matrix()
    return np.einsum("ji,tjk->tik", rot[0], rot)


def midpoint_step_map(relative: FloatArray, t_s: FloatArray) -> FloatArray:
    """``(A_{j-1} + A_j) / 2 * dt_j`` (T-1, 3, 3) of :func:`relative_attitudes` ``relative`` (T, 3, 3) and the sample
    times ``t_s`` (T,), s: maps a step's midpoint base rate (body axes) to its rotation increment (first sample's axes),
    the midpoint rule."""
    return 0.5 * (relative[:-1] + relative[1:]) * np.diff(np.asarray(t_s, dtype=float))[:, None, None]


def midpoint_log(log: MeasurementLog) -> MeasurementLog:
    """The log's steps as samples: sample 0 as logged, then sample ``j`` (1..T-1) at the midpoint of step ``j``.

    Midpoint samples carry ``t = (t_{j-1} + t_j) / 2``, joint angles ``(q_{j-1} + q_j) / 2``, joint rates from the
    encoders ``(q_j - q_{j-1}) / dt_j``, the attitude interpolated on SO(3) and the mean gyro rate (:func:`_resampled`).
    """
    t = np.asarray(log.t_s, dtype=float)
    q = np.asarray(log.q_rad, dtype=float)
    omega = np.asarray(log.omega_base_body_rad_s, dtype=float)
    return _resampled(
        log,
        0.5 * (t[:-1] + t[1:]),
        0.5 * (q[:-1] + q[1:]),
        np.diff(q, axis=0) / np.diff(t)[:, None],
        0.5 * (omega[:-1] + omega[1:]),
    )


#: the midpoint log of each log (:func:`midpoint_log`), made once and shared by every model's attitude channel and the
#: encoders' noise propagation on it
_MIDPOINT_LOGS: weakref.WeakKeyDictionary[MeasurementLog, MeasurementLog] = weakref.WeakKeyDictionary()


def shared_midpoint_log(log: MeasurementLog) -> MeasurementLog:
    """:func:`midpoint_log` of ``log``, made once per log (logs are read-only), so that the momentum models built on it
    are shared too."""
    midpoint = _MIDPOINT_LOGS.get(log)
    if midpoint is None:
        midpoint = _MIDPOINT_LOGS[log] = midpoint_log(log)
    return midpoint


def encoder_tangents(t_s: FloatArray, q_rad: FloatArray) -> FloatArray:
    """The joint rates (T, n), rad/s, of a cubic Hermite through the encoder samples: the mean of the two neighbouring
    encoder differences (one-sided at the ends)."""
    slopes = np.diff(q_rad, axis=0) / np.diff(t_s)[:, None]
    if len(slopes) == 1:
        return np.concatenate((slopes, slopes))
    return np.concatenate((slopes[:1], 0.5 * (slopes[:-1] + slopes[1:]), slopes[-1:]))


def hermite_step(
    q0: FloatArray, q1: FloatArray, m0: FloatArray, m1: FloatArray, dt_s: FloatArray, s: FloatArray | float
) -> tuple[FloatArray, FloatArray]:
    """A cubic Hermite within a step and its rate at the fraction ``s`` (in [0, 1]) of the step: values ``q0``, ``q1``
    at its ends, tangents ``m0``, ``m1`` (per s), the step's length ``dt_s``; the arrays broadcast together."""
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, 3 * s**2 - 2 * s**3, s**3 - s**2
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, 6 * s - 6 * s**2, 3 * s**2 - 2 * s
    return h00 * q0 + h10 * dt_s * m0 + h01 * q1 + h11 * dt_s * m1, (d00 * q0 + d01 * q1) / dt_s + d10 * m0 + d11 * m1


def gauss_log(log: MeasurementLog) -> MeasurementLog:
    """The log's first sample as logged, then the joint motion at the two Gauss-Legendre nodes of each step (1 + 2(T-1)
    samples, node 1 then node 2 of each step): the cubic Hermite of the step through its two encoder samples with
    :func:`encoder_tangents`, the gyro linearly and the attitude on SO(3) (:func:`_resampled`)."""
    t = np.asarray(log.t_s, dtype=float)
    q = np.asarray(log.q_rad, dtype=float)
    omega = np.asarray(log.omega_base_body_rad_s, dtype=float)
    dt = np.diff(t)[:, None]
    m = encoder_tangents(t, q)
    n_steps, n_joints = len(dt), q.shape[1]
    t_out = np.empty(2 * n_steps)
    q_out = np.empty((2 * n_steps, n_joints))
    dq_out = np.empty((2 * n_steps, n_joints))
    omega_out = np.empty((2 * n_steps, 3))
    for node, s in enumerate(GAUSS_NODES):
        q_out[node::2], dq_out[node::2] = hermite_step(q[:-1], q[1:], m[:-1], m[1:], dt, s)
        omega_out[node::2] = (1.0 - s) * omega[:-1] + s * omega[1:]
        t_out[node::2] = t[:-1] + s * dt[:, 0]
    return _resampled(log, t_out, q_out, dq_out, omega_out)


#: the coning term's factor of ``dt^2 w1 x w2`` for the two Gauss-Legendre nodes' rates ``w1, w2``
CONING = math.sqrt(3.0) / 12.0


def fourth_order_increments(model: IdentificationModel, log: MeasurementLog, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The base's rotation over each step of ``log`` at ``theta`` (k,), (T-1, 3), rad, as a rotation vector in the base's
    axes at the step's start, to fourth order: the base rate at the step's Gauss-Legendre nodes (:func:`gauss_log`)
    composed with the coning term (see the module docstring); and its derivative (T-1, 3, k) in ``theta``.

    Raises:
        SpaceIdInputError: a log of fewer than 2 samples.
    """
    if log.n_samples < 2:
        raise SpaceIdInputError(f"attitude integration: the log has {log.n_samples} sample(s), at least 2 are needed")
    theta = np.asarray(theta, dtype=float)
    dt = np.diff(np.asarray(log.t_s, dtype=float))[:, None]
    problem = model.problem(gauss_log(log))
    nodes = problem.base_rate(theta[None], count=False)[0, 1:]
    w1, w2 = nodes[0::2], nodes[1::2]
    increments = 0.5 * dt * (w1 + w2) + CONING * dt**2 * np.cross(w1, w2)
    # d/dtheta: the nodes' rate Jacobians, the coning term's by the product rule
    jac = problem.base_rate_jacobian(theta, count=False).reshape(len(nodes) + 1, 3, -1)[1:]
    j1, j2 = jac[0::2], jac[1::2]
    coning = np.cross(j1, w2[:, :, None], axis=1) + np.cross(w1[:, :, None], j2, axis=1)
    return increments, 0.5 * dt[:, :, None] * (j1 + j2) + CONING * dt[:, :, None] ** 2 * coning
