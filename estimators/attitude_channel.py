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
* residual ``e_k = Phi_hat_k - Phi_k``, compared through its first differences ``d_k = e_k - e_{k-1}``
  (the constant ``A_0 n_0`` drops out).

The residual's error model (:class:`~estimators.attitude_noise.AttitudeNoise`: the attitude source's white error and
the model's own wander, fitted by maximum likelihood per axis) whitens it into a chi-square. A precise attitude source
(noise-free or filtered) therefore no longer makes the model's wander look like a missing effect; how well the model
describes a log's attitude errors is checked by the whiteness of the whitened residual (``diagnose`` falls back to the
gyro alone where it is not white). An attitude fused on board with the same gyro is compared given the gyro
(:class:`GyroCoupling`).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from estimators.attitude_noise import AttitudeNoise, fit_attitude_noise
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog


class BaseRateProblem(Protocol):
    """What :class:`AttitudeChannel` needs of a problem (:class:`~estimators.problem.IdentificationProblem` has it)."""

    def base_rate(self, theta: FloatArray, count: bool = True) -> FloatArray: ...

    def base_rate_jacobian(self, theta: FloatArray, count: bool = True) -> FloatArray: ...

    @property
    def measured(self) -> FloatArray: ...


@dataclass(frozen=True)
class GyroCoupling:
    """How an attitude source's residual steps follow the gyro's error (its reading less the base's own rate, integrated
    over each step, :meth:`AttitudeChannel.gyro_steps`): per axis, a filter of the gyro's error steps
    over lags ``-1 .. n_lags - 2`` samples (``coefficients`` (n_lags, 3), lag -1 first), fitted by least squares
    (:func:`estimate_gyro_coupling`). An attitude fused on board with the gyro integrates the gyro's noise between
    star-tracker corrections and forgets it over the filter's time constant: at high frequency its steps are the gyro's
    (a coefficient near -1 at lag 0 for this channel's sign, ``predicted - measured`` in both), at low frequency the
    star tracker's. Subtracting the filter's response leaves what the attitude measures beyond the gyro: the
    conditional distribution of the attitude given the gyro, the second factor of their joint likelihood."""

    coefficients: FloatArray

    def response(self, gyro_steps: FloatArray) -> FloatArray:
        """The filter's output (P, n, 3) for gyro error steps (P, n, 3), rad: ``sum_l c_l g_{k-l}``, zero before the
        first and after the last step."""
        out = np.zeros_like(gyro_steps)
        n = gyro_steps.shape[1]
        for index, c in enumerate(self.coefficients):
            lag = index - 1
            if lag >= 0:
                out[:, lag:] += c * gyro_steps[:, : n - lag]
            else:
                out[:, : n + lag] += c * gyro_steps[:, -lag:]
        return out

    def to_dict(self) -> dict[str, list[list[float]]]:
        return {"coefficients": np.asarray(self.coefficients, dtype=float).tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GyroCoupling:
        return cls(np.asarray(data["coefficients"], dtype=float))


#: the span (s) of the lags :func:`estimate_gyro_coupling` fits: several time constants of an on-board attitude filter
#: (0.1-0.3 s for a navigation gyro fused with a 5 arcsec star tracker at 20-100 Hz)
COUPLING_SPAN_S = 1.0


def coupling_lags(dt_s: float) -> int:
    """The lags :func:`estimate_gyro_coupling` fits at sample period ``dt_s`` (s): -1 .. ``COUPLING_SPAN_S / dt_s``."""
    return math.ceil(COUPLING_SPAN_S / dt_s) + 2


def min_coupling_samples(dt_s: float) -> int:
    """The fewest samples of a log whose :class:`GyroCoupling` can be fitted: four per coefficient."""
    return 4 * coupling_lags(dt_s) + 2


def estimate_gyro_coupling(differences: FloatArray, gyro_steps: FloatArray, dt_s: float) -> GyroCoupling:
    """:class:`GyroCoupling` of attitude residual steps ``differences`` (n, 3) on the gyro's error steps ``gyro_steps``
    (n, 3), both rad, from a fit of the model (the baseline's), lags -1 .. ``COUPLING_SPAN_S / dt_s``, their sum held
    at zero: an attitude fused with an absolute sensor (a star tracker) follows it at low frequency, not the gyro,
    and a free sum, fitted from the noise, let a candidate that shifts the gyro's error slowly (a momentum, whose
    base rate differs) move the attitude residual through it (clean fused logs were named external_torque or gyro_bias).

    Least squares per axis on the first differences of both: a missing effect's slow signature, in both channels
    at that fit, must not be taken for the filter's response (the dependence test,
    :func:`~estimators.diagnostics.model_fit.attitude_gyro_dependence`, differences for the same reason)."""
    n_lags = coupling_lags(dt_s)
    a = np.diff(np.asarray(differences, dtype=float), axis=0)
    g = np.diff(np.asarray(gyro_steps, dtype=float), axis=0)
    n = len(a)
    if n + 2 < min_coupling_samples(dt_s):
        raise SpaceIdInputError(
            f"gyro coupling: {n + 2} samples are too few for {n_lags} lags (need {min_coupling_samples(dt_s)})"
        )
    coefficients = np.empty((n_lags, 3))
    for axis in range(3):
        design = np.zeros((n, n_lags))
        for index in range(n_lags):
            lag = index - 1
            if lag >= 0:
                design[lag:, index] = g[: n - lag, axis]
            else:
                design[: n + lag, index] = g[-lag:, axis]
        # sum of the coefficients zero (the last one minus the others): a constant gyro error moves a fused attitude
        # by a bounded amount, its steps by nothing, so a slow gyro error (a bias, a slow rate misfit) passes nothing
        free = np.linalg.lstsq(design[:, :-1] - design[:, -1:], a[:, axis], rcond=None)[0]
        coefficients[:, axis] = np.append(free, -free.sum())
    return GyroCoupling(coefficients)


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


#: the midpoint log of each log (:func:`midpoint_log`), made once and shared by every model's channel on it
_MIDPOINT_LOGS: weakref.WeakKeyDictionary[MeasurementLog, MeasurementLog] = weakref.WeakKeyDictionary()


def _shared_midpoint_log(log: MeasurementLog) -> MeasurementLog:
    """:func:`midpoint_log` of ``log``, made once per log (logs are read-only)."""
    midpoint = _MIDPOINT_LOGS.get(log)
    if midpoint is None:
        midpoint = _MIDPOINT_LOGS[log] = midpoint_log(log)
    return midpoint


#: the fewest samples for which the channel takes its integration error's shape out (:func:`truncation_shape`)
MIN_SAMPLES_FOR_TRUNCATION = 9


def truncation_shape(model: IdentificationModel, log: MeasurementLog, channel: AttitudeChannel) -> FloatArray:
    """The shape (T, 3), rad, of the error the channel's midpoint integration makes on ``log`` (Richardson): the
    model's accumulated rotation at the model's nominal parameters (effects off) integrated over the log's steps,
    less the same integrated over double steps (every other sample), at the even samples, linear between them.

    The midpoint rule's error per step is of order ``h^3`` and systematic where the base wobbles about two axes and
    the joints sweep an area in joint space (the rotation a free-floating base gets from a closed joint path): at
    20 Hz on paper6 ~2e-6 rad over 60 s, more than a noise-free attitude's error, and a constant momentum or a
    payload fits part of it. The double-step integration makes four times that error (``h^2`` per unit time), so
    the difference has the error's shape; its size per axis is left free (:meth:`AttitudeChannel.set_truncation`)."""
    theta = np.asarray(model.parameters.nominal, dtype=float)
    fine = channel.predicted(theta)[0]
    quat = log.quat_base_to_inertial_wxyz
    assert quat is not None
    coarse_log = MeasurementLog(
        t_s=log.t_s[::2],
        q_rad=log.q_rad[::2],
        dq_rad_s=log.dq_rad_s[::2],
        omega_base_body_rad_s=log.omega_base_body_rad_s[::2],
        quat_base_to_inertial_wxyz=quat[::2],
    )
    coarse = AttitudeChannel(model.problem(midpoint_log(coarse_log)), coarse_log).predicted(theta)[0]
    even = fine[::2] - coarse
    t = np.asarray(log.t_s, dtype=float)
    return np.stack([np.interp(t, t[::2], even[:, axis]) for axis in range(3)], axis=1)


#: the truncation shape of each log per robot (:func:`truncation_shape`), made once and shared by every model's channel
_TRUNCATIONS: weakref.WeakKeyDictionary[MeasurementLog, dict[str, FloatArray]] = weakref.WeakKeyDictionary()


def _shared_truncation(model: IdentificationModel, log: MeasurementLog, channel: AttitudeChannel) -> FloatArray:
    """:func:`truncation_shape` of ``log`` for ``model``'s robot, made once per log and robot (effects off, so the same
    for every model of the robot)."""
    shapes = _TRUNCATIONS.setdefault(log, {})
    key = f"{model.robot.name}:{model.parameters.base.name if hasattr(model.parameters, 'base') else model.parameters.name}"
    if key not in shapes:
        shapes[key] = truncation_shape(model, log, channel)
    return shapes[key]


class AttitudeChannel:
    """The star tracker's rotation against the model's on one log (see the module docstring).

    Args:
        problem: the model bound to the log's midpoint samples (:func:`midpoint_log`), any object with
            ``base_rate(theta (P, k)) -> (P, T, 3)`` and ``base_rate_jacobian(theta (k,)) -> (3T, k)``.
        log: the log itself, with attitude quaternions.
        coupling: the attitude's response to the gyro's residual (:class:`GyroCoupling`), or
            ``None`` (an attitude source independent of this gyro). With it the channel compares the attitude given
            the gyro: each step's residual less the coupling's filter of the gyro's error steps at the same
            ``theta``, so that an attitude fused on board with this gyro no longer counts the gyro's noise twice.

    Attributes:
        measured: ``Phi`` (T, 3), rad, the star tracker's accumulated rotation, first sample's base axes.
        n_values: ``3T - 6``, the whitened residual's values (:meth:`residuals`).
    """

    def __init__(self, problem: BaseRateProblem, log: MeasurementLog, coupling: GyroCoupling | None = None) -> None:
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
        self.coupling = coupling
        self._dt_s = np.diff(np.asarray(log.t_s, dtype=float))
        self._measured_steps = increments
        self._cached: tuple[AttitudeNoise, list[FloatArray], FloatArray | None] | None = None
        self._truncation: FloatArray | None = None
        self.n_values = 3 * log.n_samples - 6

    @classmethod
    def of(cls, model: IdentificationModel, log: MeasurementLog, coupling: GyroCoupling | None = None) -> AttitudeChannel | None:
        """The channel of ``model`` on ``log`` (given the gyro with ``coupling``); ``None`` when the log has no attitude
        or fewer than 3 samples."""
        if log.quat_base_to_inertial_wxyz is None or log.n_samples < 3:
            return None
        channel = cls(model.problem(_shared_midpoint_log(log)), log, coupling)
        if log.n_samples >= MIN_SAMPLES_FOR_TRUNCATION:
            channel.set_truncation(_shared_truncation(model, log, channel))
        return channel

    def set_truncation(self, shape: FloatArray) -> None:
        """Project the steps of ``shape`` (T, 3), rad, the shape of the model's own integration error
        (:func:`truncation_shape`), out of the residual, one free size per axis (3 fewer values)."""
        shape = np.asarray(shape, dtype=float)
        if shape.shape != self.measured.shape or not np.all(np.isfinite(shape)):
            raise SpaceIdInputError(
                f"attitude channel: truncation shape expected {self.measured.shape} finite, got {shape.shape}"
            )
        self._truncation = np.diff(shape, axis=0)
        self._cached = None
        self.n_values = 3 * len(self.measured) - 6 - 3

    def predicted(self, theta: FloatArray) -> FloatArray:
        """``Phi_hat`` (P, T, 3), rad, for ``theta`` (P, k)."""
        omega = self.problem.base_rate(np.atleast_2d(theta))[:, 1:]  # midpoint rates (P, T-1, 3)
        steps = np.einsum("tij,ptj->pti", self._step_map, omega)
        return np.concatenate((np.zeros((len(steps), 1, 3)), np.cumsum(steps, axis=1)), axis=1)

    def differences(self, theta: FloatArray) -> FloatArray:
        """``d_k = e_k - e_{k-1}`` (T-1, 3), rad, of the residual ``e = Phi_hat - Phi`` at ``theta`` (k,) (less the
        coupling's response to the gyro's error, with a coupling)."""
        base = self.problem.base_rate(np.atleast_2d(theta))
        if self.coupling is not None:
            return self._coupled(base)[0]
        return np.einsum("tij,tj->ti", self._step_map, base[0, 1:]) - self._measured_steps

    def gyro_steps(self, base: FloatArray) -> FloatArray:
        """The gyro's error integrated over each step, (P, T-1, 3), rad, against the base's own rate ``base`` (P, T, 3)
        at the midpoint samples: ``(base - measured) dt``, the mean of the step's two gyro samples measured.

        Against the base's rate, not the gyro's predicted reading: an attitude fused on board integrates the gyro as it
        reads, so its error follows the gyro's whole error, the reading's measurement effects (a delay, a scale, a
        bias) included; a model with such an effect explains the gyro's reading, not the fused attitude's error.
        Against the reading, a delay fitted on a fused log left the filter's response to the delay in the attitude
        residual, and the fuel unknowns bent to absorb it (fuel errors of 8-42 Cramer-Rao std after naming
        the delay on design logs at 100 Hz)."""
        return (base[:, 1:] - self.problem.measured[1:]) * self._dt_s[:, None]

    def _coupled(self, base: FloatArray) -> FloatArray:
        """Residual steps given the gyro (P, T-1, 3) from the model's base rate (P, T, 3) (see ``coupling``)."""
        assert self.coupling is not None
        steps = np.einsum("tij,ptj->pti", self._step_map, base[:, 1:]) - self._measured_steps
        return steps - self.coupling.response(self.gyro_steps(base))

    def residuals(self, theta: FloatArray, noise: AttitudeNoise) -> FloatArray:
        """The whitened differences (3T-6,) at ``theta`` (k,): unit variance and independent under ``noise``."""
        return self._project(noise.whiten(self.differences(theta), self._factors(noise)), noise).ravel()

    def difference_jacobian(self, theta: FloatArray) -> FloatArray:
        """``d differences / d theta`` (T-1, 3, k) at ``theta`` (k,)."""
        n_t = len(self.measured)
        rates = self.problem.base_rate_jacobian(np.asarray(theta, dtype=float)).reshape(n_t, 3, -1)[1:]
        steps = np.einsum("tij,tjk->tik", self._step_map, rates)
        if self.coupling is None:
            return steps
        response = self.coupling.response(np.moveaxis(rates * self._dt_s[:, None, None], 2, 0))  # (k, T-1, 3)
        return steps - np.moveaxis(response, 0, 2)

    def jacobian(self, theta: FloatArray, noise: AttitudeNoise) -> FloatArray:
        """``d residuals / d theta`` (3T-6, k) at ``theta`` (k,)."""
        jac = self.difference_jacobian(theta)
        return self._project(noise.whiten(jac, self._factors(noise)), noise).reshape(-1, jac.shape[2])

    def chi2(self, theta: FloatArray, noise: AttitudeNoise) -> float:
        """The channel's chi-square at ``theta`` (k,) under ``noise`` (``n_values`` degrees of freedom at the truth)."""
        r = self.residuals(theta, noise)
        return float(r @ r)

    def chi2s(self, thetas: FloatArray, noise: AttitudeNoise) -> FloatArray:
        """:meth:`chi2` of each row of ``thetas`` (P, k), the model evaluated once for all: (P,)."""
        if self.coupling is not None:
            differences = self._coupled(self.problem.base_rate(np.atleast_2d(thetas)))
        else:
            omega = self.problem.base_rate(np.atleast_2d(thetas))[:, 1:]
            differences = np.einsum("tij,ptj->pti", self._step_map, omega) - self._measured_steps
        factors = self._factors(noise)
        return np.array([float(np.sum(self._project(noise.whiten(d, factors), noise) ** 2)) for d in differences])

    def fisher(self, theta: FloatArray, noise: AttitudeNoise) -> FloatArray:
        """Fisher information (k, k) of the attitude source about ``theta`` (k,) under ``noise``."""
        jac = self.jacobian(theta, noise)
        return jac.T @ jac

    def estimate_noise(self, theta: FloatArray, start: AttitudeNoise | None = None) -> AttitudeNoise:
        """The error model fitted to the residual at ``theta`` (k,) by maximum likelihood (:func:`fit_attitude_noise`;
        ``start``: a nearby fit's error model, tried as one more start)."""
        differences = self.differences(theta)
        if self._truncation is not None:  # the integration error's shape taken out first (least squares per axis)
            x = self._truncation
            differences = differences - x * (np.sum(x * differences, axis=0) / np.maximum(np.sum(x * x, axis=0), 1e-300))
        return fit_attitude_noise(differences, start)

    def profile_chi2(self, theta: FloatArray, noise: AttitudeNoise, reference: AttitudeNoise) -> float:
        """``-2 log L`` of the residual at ``theta`` (k,) under ``noise``, less that of a white residual under
        ``reference``'s covariance: ``chi2(theta, noise) + log det(noise) - log det(reference)``. With ``noise`` fitted
        at ``theta`` (:meth:`estimate_noise`), differences of it between models are profile likelihood ratios: the
        error model is a nuisance refitted under each model, so a model that explains structure the error model had
        absorbed as the model's own wander gains its log-determinant, and one that explains nothing gains nothing."""
        n_steps = len(self.measured)
        return self.chi2(theta, noise) + noise.log_det(n_steps) - reference.log_det(n_steps)

    def _factors(self, noise: AttitudeNoise) -> list[FloatArray]:
        """The whitening factors of ``noise``, cached for the last noise model asked (with the whitened truncation)."""
        if self._cached is None or self._cached[0] != noise:
            factors = noise.factors(len(self._measured_steps))
            shape = None if self._truncation is None else noise.whiten(self._truncation, factors)
            self._cached = (noise, factors, shape)
        return self._cached[1]

    def _project(self, whitened: FloatArray, noise: AttitudeNoise) -> FloatArray:
        """``whitened`` (T-2, 3[, k]) less its projection on the whitened truncation shape, axis by axis."""
        self._factors(noise)
        assert self._cached is not None
        x = self._cached[2]
        if x is None:
            return whitened
        x = x if whitened.ndim == 2 else x[:, :, None]
        return whitened - x * (np.sum(x * whitened, axis=0) / np.maximum(np.sum(x * x, axis=0), 1e-300))
