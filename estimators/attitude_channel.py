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
  of the predicted attitude. The midpoint rule's own error (O(dt^3) per step, systematic where the joints sweep an
  area in joint space) is taken out at a reference set of unknowns (:mod:`estimators.attitude_integration`:
  a fourth-order rule less the midpoint rule, held fixed), so that the model's prediction is exact to ~1e-8 rad
  over a minute at 20 Hz;
* residual ``e_k = Phi_hat_k - Phi_k``, compared through its first differences ``d_k = e_k - e_{k-1}``
  (the constant ``A_0 n_0`` drops out).

The residual's error model whitens it into a chi-square, one of two kinds (:meth:`AttitudeChannel.estimate_noise`
fits both and keeps the one of lower BIC): the encoders' noise propagated through the momentum map step by step, with
the attitude source's white error and the model's own wander (:class:`~estimators.attitude_propagation.PropagatedNoise`,
four numbers; the covariance follows the arm's configuration, :mod:`estimators.attitude_propagation`), or a stationary
model per noise axis (:class:`~estimators.attitude_noise.AttitudeNoise`: the attitude source's white error and the
model's own wander, fitted by maximum likelihood per axis, nine numbers), in the residual's own principal axes
(:func:`noise_axes`). The first describes a precise attitude far better (a noise-free one by ~15,000 units of
``-2 log L`` on a 60 s, 100 Hz log); the second holds what it lacks, a smooth wander (another simulator's integrator),
and an attitude fused with the gyro, whose filter spreads the encoders' noise over many steps (a coupled channel has
no propagation). On the stationary model: the encoders' noise reaches the predicted attitude through the arm's momentum map,
a few directions of it, and with a precise attitude source it is most of the residual (two axes of the first
sample's frame were correlated at -0.94 on a noise-free attitude at 100 Hz); per axis of the frame, that correlation
was missed and a slosh candidate at its 2 Hz bound fitted the misdescribed noise (likelihood ratio 22). A precise attitude source
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
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation
from scipy.special import expit

from estimators.attitude_integration import (
    fourth_order_increments,
    midpoint_step_map,
    relative_attitudes,
    shared_midpoint_log,
)
from estimators.attitude_noise import AttitudeNoise, fit_attitude_noise
from estimators.attitude_propagation import (
    EncoderPropagation,
    PropagatedNoise,
    band_factor,
    encoder_propagation,
    filtered,
    fit_propagated_noise,
    propagated_log_likelihood,
    solve_with_factor,
)
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog

#: the attitude residual's error model: stationary per noise axis (:class:`~estimators.attitude_noise.AttitudeNoise`)
#: or the encoders' noise propagated step by step (:class:`~estimators.attitude_propagation.PropagatedNoise`)
ErrorModel = AttitudeNoise | PropagatedNoise


def noise_from_dict(data: dict[str, Any]) -> ErrorModel:
    """The error model of a ``to_dict`` (``attitude_error_model``: ``"propagated"``, else the stationary one)."""
    if data.get("attitude_error_model") == "propagated":
        return PropagatedNoise.from_dict(data)
    return AttitudeNoise.from_dict(data)


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
    (a coefficient near ``1 - K`` at lag 0, ``K`` the filter's gain per sample: ``predicted - measured`` in both), at low frequency the
    star tracker's. Subtracting the filter's response leaves what the attitude measures beyond the gyro: the
    conditional distribution of the attitude given the gyro, the second factor of their joint likelihood.

    ``filter_gain``: the gain ``K`` per sample when the response is that of a first-order complementary filter
    (:func:`first_order_coupling`), ``None`` for a free response."""

    coefficients: FloatArray
    filter_gain: float | None = None

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

    def to_dict(self) -> dict[str, Any]:
        return {"coefficients": np.asarray(self.coefficients, dtype=float).tolist(), "filter_gain": self.filter_gain}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GyroCoupling:
        gain = data.get("filter_gain")
        return cls(np.asarray(data["coefficients"], dtype=float), None if gain is None else float(gain))


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
    a, g = _differenced(differences, gyro_steps, dt_s)
    n_lags = coupling_lags(dt_s)
    coefficients = np.empty((n_lags, 3))
    for axis in range(3):
        # sum of the coefficients zero (the last one minus the others): a constant gyro error moves a fused attitude
        # by a bounded amount, its steps by nothing, so a slow gyro error (a bias, a slow rate misfit) passes nothing
        free = np.linalg.lstsq(_sum_free(_lagged(g[:, axis], n_lags)), a[:, axis], rcond=None)[0]
        coefficients[:, axis] = np.append(free, -free.sum())
    return GyroCoupling(coefficients)


def first_order_coupling(gain: float, dt_s: float) -> GyroCoupling:
    """The :class:`GyroCoupling` of a first-order complementary filter of gain ``gain`` (``0 < K < 1``) per sample:
    ``e_k = (1 - K)(e_{k-1} + g_k) + K n_k`` (``e`` the attitude error, ``g`` the gyro's error step, ``n`` the star
    tracker's) moves the steps of ``e`` by ``1 - K`` at lag 0 and ``-K (1 - K)^l`` at lag ``l >= 1``, the lags of
    :func:`coupling_lags` (the last one takes the tail, so that the sum is zero)."""
    if not 0.0 < gain < 1.0:
        raise SpaceIdInputError(f"gyro coupling: a filter gain must lie in (0, 1), got {gain!r}")
    n_lags = coupling_lags(dt_s)
    shape = np.zeros(n_lags)
    shape[1] = 1.0 - gain
    shape[2:] = -gain * (1.0 - gain) ** np.arange(1, n_lags - 1)
    shape[-1] -= shape.sum()
    return GyroCoupling(np.repeat(shape[:, None], 3, axis=1), gain)


#: the filter gains :func:`fit_first_order_coupling` scans (logits of ``K``) before its bounded refinement
GAIN_LOGITS = np.linspace(-8.0, 6.0, 57)


def fit_first_order_coupling(
    differences: FloatArray, gyro_steps: FloatArray, dt_s: float, instrument: FloatArray | None = None
) -> tuple[GyroCoupling, float]:
    """The :func:`first_order_coupling` (one gain for the three axes) that fits ``differences`` (n, 3) on ``gyro_steps``
    (n, 3) best on their first differences, as :func:`estimate_gyro_coupling` fits, and the objective there: the
    residual sum of squares (rad^2), or with an ``instrument`` (n, 3) the two-stage least-squares objective (the
    residual's squared projection on the instrument's lags). A scan of :data:`GAIN_LOGITS`, then a bounded search
    between the best one's neighbours.

    The instrument: the same gyro error measured with noise of its own (:meth:`AttitudeChannel.sensor_gyro_steps`)
    where ``gyro_steps`` carry noise the residual shares (:meth:`AttitudeChannel.gyro_steps`: the encoders'). Least
    squares on the shared-noise steps pulls the gain low (0.074-0.082 for the filter's 0.112 on held-out fused logs of
    ``orbit7`` and ``paper6`` at 50 Hz), on the instrument's own steps high (the errors in the regressor: 0.128-0.204);
    the instrumental-variable estimate is free of both (0.105-0.134)."""
    a, g = _differenced(differences, gyro_steps, dt_s)
    n_lags = coupling_lags(dt_s)
    designs = [_lagged(g[:, axis], n_lags) for axis in range(3)]
    if instrument is None:
        projections = None
    else:
        z = _differenced(differences, instrument, dt_s)[1]
        projections = [np.linalg.qr(_lagged(z[:, axis], n_lags))[0] for axis in range(3)]

    def objective(logit: float) -> float:
        shape = first_order_coupling(float(expit(logit)), dt_s).coefficients[:, 0]
        residuals = [a[:, axis] - designs[axis] @ shape for axis in range(3)]
        if projections is not None:
            residuals = [q.T @ r for q, r in zip(projections, residuals, strict=True)]
        return sum(float(r @ r) for r in residuals)

    scan = [objective(x) for x in GAIN_LOGITS]
    best = int(np.argmin(scan))
    low, high = GAIN_LOGITS[max(best - 1, 0)], GAIN_LOGITS[min(best + 1, len(GAIN_LOGITS) - 1)]
    logit = float(minimize_scalar(objective, bounds=(low, high), method="bounded").x)
    value = objective(logit)
    if value > scan[best]:
        logit, value = float(GAIN_LOGITS[best]), scan[best]
    return first_order_coupling(float(expit(logit)), dt_s), value


def choose_gyro_coupling(differences: FloatArray, gyro_steps: FloatArray, sensor_steps: FloatArray, dt_s: float) -> GyroCoupling:
    """The attitude's response to the gyro: a first-order complementary filter (one gain,
    :func:`fit_first_order_coupling`) or a free response per axis (:func:`estimate_gyro_coupling`), whichever has the
    lower BIC of the regression on ``sensor_steps`` (the gyro's error against the joint-rate sensors' prediction,
    :meth:`AttitudeChannel.sensor_gyro_steps`; ``n log(RSS / n) + p log n`` over the three axes' ``n`` values, ``p`` 1
    against ``3 (L - 1)``). The first-order gain is then the instrumental-variable estimate on ``gyro_steps``
    (:meth:`AttitudeChannel.gyro_steps`) with ``sensor_steps`` as the instrument; the free response stays the least
    squares on ``sensor_steps``.

    Why not always the free response: its ``3 (L - 1)`` coefficients (66 at 20 Hz, 306 at 100 Hz) carry noise, and a
    large gyro error (a delay's or a scale's, several times the gyro's noise at the excitation's frequencies) passes
    through their error into the attitude residual, where the fuel unknowns bend to absorb it. On fused delay logs
    (seeds 10529-10546, 20-100 Hz) the free response left fuel errors after naming the delay of up to 4-6 Cramer-Rao
    std, whichever gyro steps it was fitted on; the filter's own response (its gain known) at most 1.7. An on-board
    filter that estimates no gyro bias is first order in steady state; one that does (a second-order response) is
    fitted freely where the BIC tells them apart."""
    first_order_rss = fit_first_order_coupling(differences, sensor_steps, dt_s)[1]
    free = estimate_gyro_coupling(differences, sensor_steps, dt_s)
    a, g = _differenced(differences, sensor_steps, dt_s)
    free_rss = float(np.sum((a - free.response(g[None])[0]) ** 2))
    n_values, n_lags = a.size, coupling_lags(dt_s)

    def bic(rss: float, n_params: int) -> float:
        return n_values * math.log(max(rss, 1e-300) / n_values) + n_params * math.log(n_values)

    if bic(free_rss, 3 * (n_lags - 1)) < bic(first_order_rss, 1):
        return free
    return fit_first_order_coupling(differences, gyro_steps, dt_s, instrument=sensor_steps)[0]


def _differenced(differences: FloatArray, gyro_steps: FloatArray, dt_s: float) -> tuple[FloatArray, FloatArray]:
    """The first differences (n-1, 3) of the residual steps and of the gyro's error steps (each (n, 3)), checked."""
    a = np.diff(np.asarray(differences, dtype=float), axis=0)
    g = np.diff(np.asarray(gyro_steps, dtype=float), axis=0)
    n_lags = coupling_lags(dt_s)
    if len(a) + 2 < min_coupling_samples(dt_s):
        raise SpaceIdInputError(
            f"gyro coupling: {len(a) + 2} samples are too few for {n_lags} lags (need {min_coupling_samples(dt_s)})"
        )
    if g.shape != a.shape:
        raise SpaceIdInputError(f"gyro coupling: expected steps and gyro steps of one shape, got {a.shape} and {g.shape}")
    return a, g


def _lagged(series: FloatArray, n_lags: int) -> FloatArray:
    """The design (n, n_lags) of a series (n,) at lags -1 .. ``n_lags - 2``, zero beyond its ends."""
    n = len(series)
    design = np.zeros((n, n_lags))
    for index in range(n_lags):
        lag = index - 1
        if lag >= 0:
            design[lag:, index] = series[: n - lag]
        else:
            design[: n + lag, index] = series[-lag:]
    return design


def _sum_free(design: FloatArray) -> FloatArray:
    """A lag design (n, L) with its coefficients' sum held at zero: the last coefficient minus the others (n, L-1)."""
    return design[:, :-1] - design[:, -1:]


def reference_theta(model: IdentificationModel, reference: FloatArray | None) -> FloatArray:
    """The unknowns (k,) of ``model`` at which a channel takes its integration error out: ``reference`` (the first
    unknowns, e.g. a baseline's fit, whose model ``model`` extends) followed by ``model``'s nominal (its added effects
    off), or the nominal when ``reference`` is ``None``."""
    nominal = np.asarray(model.parameters.nominal, dtype=float)
    if reference is None:
        return nominal
    reference = np.asarray(reference, dtype=float)
    if reference.ndim != 1 or len(reference) > len(nominal) or not np.all(np.isfinite(reference)):
        raise SpaceIdInputError(
            f"attitude channel: reference expected at most {len(nominal)} finite unknowns, got shape {reference.shape}"
        )
    return np.concatenate((reference, nominal[len(reference) :]))


#: the midpoint rule's error on each log per robot and reference, with its Jacobian
#: (:meth:`AttitudeChannel.integration_error`), made once and shared by every model's channel on it (added effects off:
#: the same)
_ERRORS: weakref.WeakKeyDictionary[MeasurementLog, dict[tuple[Any, ...], tuple[FloatArray, FloatArray]]] = (
    weakref.WeakKeyDictionary()
)


#: the encoders' noise propagation of each log per robot and reference (:func:`encoder_propagation`), made once and
#: shared by every model's channel on it
_PROPAGATIONS: weakref.WeakKeyDictionary[MeasurementLog, dict[tuple[Any, ...], EncoderPropagation]] = weakref.WeakKeyDictionary()

#: the fewest samples of a log whose channel offers the propagated error model (its filtered steps' covariance needs
#: four steps)
MIN_PROPAGATED_SAMPLES = 6

#: the error models' numbers of free parameters, charged in their choice (:meth:`AttitudeChannel.estimate_noise`)
STATIONARY_PARAMETERS, PROPAGATED_PARAMETERS = 9, 4


def noise_axes(differences: FloatArray) -> FloatArray:
    """The principal axes (3, 3), columns, of a residual's white part: the eigenvectors of the covariance of the second
    differences of its steps ``differences`` (n, 3), which leave a slow misfit out and see the white error whole."""
    second = np.diff(np.asarray(differences, dtype=float), axis=0)
    if len(second) < 3:
        return np.eye(3)
    return np.linalg.eigh(second.T @ second)[1]


class AttitudeChannel:
    """The star tracker's rotation against the model's on one log (see the module docstring).

    Args:
        problem: the model bound to the log's midpoint samples (:func:`~estimators.attitude_integration.midpoint_log`), any object with
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
        relative = relative_attitudes(log)  # A_k = R_0^T R_k
        steps = np.einsum("tij,tkj->tik", relative[1:], relative[:-1])  # A_j A_{j-1}^T
        increments = Rotation.from_matrix(steps).as_rotvec()
        self.problem = problem
        self.measured = np.concatenate((np.zeros((1, 3)), np.cumsum(increments, axis=0)))
        #: ``(A_{j-1} + A_j) / 2 * dt_j`` (T-1, 3, 3): maps the step's midpoint rate to its rotation increment
        self._step_map = midpoint_step_map(relative, log.t_s)
        self.coupling = coupling
        #: the star tracker's increments, less (after :meth:`set_reference`) the midpoint rule's own error
        self._raw_steps = increments
        self._measured_steps = increments
        self._relative = relative
        #: the midpoint rule's error's derivative (T-1, 3, r) in the first r unknowns (:meth:`set_reference`)
        self._error_jacobian: FloatArray | None = None
        self._cached: tuple[AttitudeNoise, list[FloatArray]] | None = None
        self._cached_factor: tuple[PropagatedNoise, FloatArray, float] | None = None
        self._axes: FloatArray | None = None
        #: the encoders' noise propagation (first sample's axes; :meth:`of` sets it for a channel without coupling) and
        #: the same in the noise axes, as :class:`PropagatedNoise` whitens
        self._propagation: EncoderPropagation | None = None
        self._propagation_axes: EncoderPropagation | None = None
        self.reference: FloatArray | None = None
        self.n_values = 3 * log.n_samples - 6

    @classmethod
    def of(
        cls,
        model: IdentificationModel,
        log: MeasurementLog,
        coupling: GyroCoupling | None = None,
        reference: FloatArray | None = None,
    ) -> AttitudeChannel | None:
        """The channel of ``model`` on ``log`` (given the gyro with ``coupling``), its integration error taken out and
        its noise axes found at ``reference`` (:func:`reference_theta`: a baseline's unknowns, which ``model`` may extend;
        ``None``: the nominal); ``None`` when the log has no attitude or fewer than 3 samples. Channels of the same log
        and reference (whatever effects their models add) compare the attitude alike."""
        if log.quat_base_to_inertial_wxyz is None or log.n_samples < 3:
            return None
        channel = cls(model.problem(shared_midpoint_log(log)), log, coupling)
        theta = reference_theta(model, reference)
        n_reference = len(theta) if reference is None else len(reference)
        # carried to first order in the base's unknowns (the effects' at the reference as they are, added ones off)
        n_base = getattr(model.parameters, "base", model.parameters).n_params
        errors = _ERRORS.setdefault(log, {})
        key = (model.robot.name, model.parameters.names[:n_reference], theta[:n_reference].tobytes())
        if key not in errors:
            errors[key] = channel.integration_error(theta, *fourth_order_increments(model, log, theta), n_base)
        if coupling is None and log.n_samples >= MIN_PROPAGATED_SAMPLES:
            # through the model as given, its effects off (the propagation needs a base rate of each sample's joint
            # state alone, which a slosh's carried state breaks; the effects change the momentum map little)
            propagations = _PROPAGATIONS.setdefault(log, {})
            base_key = (model.robot.name, model.parameters.names[:n_base], theta[:n_base].tobytes())
            if base_key not in propagations:
                base_model = IdentificationModel(model.robot, getattr(model.parameters, "base", model.parameters))
                propagations[base_key] = encoder_propagation(base_model, log, theta[:n_base])
            channel._propagation = propagations[base_key]
        channel.set_reference(theta, *errors[key])
        channel.reference = theta[:n_reference].copy()
        return channel

    def integration_error(
        self, theta: FloatArray, increments: FloatArray, jacobian: FloatArray, n_params: int
    ) -> tuple[FloatArray, FloatArray]:
        """The midpoint rule's error on each step at ``theta`` (k,), (T-1, 3), rad, first sample's axes, and its
        derivative (T-1, 3, ``n_params``) in the first ``n_params`` unknowns: ``increments`` (T-1, 3) is the fourth-order
        rotation of each step there (body axes at the step's start,
        :func:`~estimators.attitude_integration.fourth_order_increments`), ``jacobian`` (T-1, 3, k) its derivative."""
        theta = np.asarray(theta, dtype=float)
        increments, jacobian = np.asarray(increments, dtype=float), np.asarray(jacobian, dtype=float)
        if (
            increments.shape != self._raw_steps.shape
            or jacobian.shape != (*increments.shape, len(theta))
            or not 0 < n_params <= len(theta)
            or not (np.all(np.isfinite(increments)) and np.all(np.isfinite(jacobian)))
        ):
            raise SpaceIdInputError(
                f"attitude channel: increments expected {self._raw_steps.shape} and their Jacobian "
                f"{(*self._raw_steps.shape, len(theta))}, finite; got {increments.shape}, {jacobian.shape}"
            )
        rates = self.problem.base_rate(theta[None], count=False)[0, 1:]
        rate_jacobian = self.problem.base_rate_jacobian(theta, count=False).reshape(len(self.measured), 3, -1)[1:]
        relative = self._relative[:-1]
        error = np.einsum("tij,tj->ti", relative, increments) - np.einsum("tij,tj->ti", self._step_map, rates)
        error_jacobian = np.einsum("tij,tjk->tik", relative, jacobian[:, :, :n_params]) - np.einsum(
            "tij,tjk->tik", self._step_map, rate_jacobian[:, :, :n_params]
        )
        return error, error_jacobian

    def set_reference(self, theta: FloatArray, error: FloatArray, error_jacobian: FloatArray) -> None:
        """Take the midpoint rule's error out of every prediction, to first order about ``theta`` (k,): ``error``
        (T-1, 3) there and its derivative ``error_jacobian`` (T-1, 3, r) in the first ``r`` unknowns (the rest, added
        effects, are off in it; :meth:`integration_error`). And whiten in the noise axes of the residual there
        (:func:`noise_axes`).

        The error changes with the unknowns (a tenth of it over 5 kg of fuel on quick3), so it is carried to first order
        in them: a fit far from the reference (a baseline that a missing effect pulled away) keeps it out."""
        theta = np.asarray(theta, dtype=float)
        n_ref = error_jacobian.shape[2]
        self._error_jacobian = error_jacobian
        # the error at theta folded into the target: raw - error(theta) + J theta[:r], so that the differences add
        # J theta[:r] at their own unknowns
        self._measured_steps = self._raw_steps - error + np.einsum("tik,k->ti", error_jacobian, theta[:n_ref])
        self._cached, self._cached_factor = None, None
        self._axes = noise_axes(self.differences(theta))
        if self._propagation is not None:
            self._propagation_axes = self._propagation.in_axes(self._axes)

    def _steps(self, thetas: FloatArray, base: FloatArray) -> FloatArray:
        """The residual's steps (P, T-1, 3) for ``thetas`` (P, k) from the model's base rate there (P, T, 3): the
        midpoint rule's increments, its own error to first order about the reference, less the star tracker's."""
        steps = np.einsum("tij,ptj->pti", self._step_map, base[:, 1:]) - self._measured_steps
        if self._error_jacobian is not None:
            steps = steps + np.einsum("tik,pk->pti", self._error_jacobian, thetas[:, : self._error_jacobian.shape[2]])
        return steps

    def differences(self, theta: FloatArray) -> FloatArray:
        """``d_k = e_k - e_{k-1}`` (T-1, 3), rad, of the residual ``e = Phi_hat - Phi`` at ``theta`` (k,) (less the
        coupling's response to the gyro's error, with a coupling)."""
        thetas = np.atleast_2d(np.asarray(theta, dtype=float))
        return self._differences(thetas, self.problem.base_rate(thetas))[0]

    def _differences(self, thetas: FloatArray, base: FloatArray) -> FloatArray:
        """:meth:`differences` (P, T-1, 3) of ``thetas`` (P, k) from the model's base rate there (P, T, 3)."""
        steps = self._steps(thetas, base)
        if self.coupling is None:
            return steps
        return steps - self.coupling.response(self.gyro_steps(base))

    def gyro_steps(self, base: FloatArray) -> FloatArray:
        """The gyro's error integrated over each step, (P, T-1, 3), rad, first sample's axes, against the base's own rate
        ``base`` (P, T, 3) at the midpoint samples: ``(A_{j-1} + A_j) / 2 (base - measured) dt``, the mean of the step's
        two gyro samples measured.

        Against the base's rate, not the gyro's predicted reading: an attitude fused on board integrates the gyro as it
        reads, so its error follows the gyro's whole error, the reading's measurement effects (a delay, a scale, a
        bias) included; a model with such an effect explains the gyro's reading, not the fused attitude's error.
        Against the reading, a delay fitted on a fused log left the filter's response to the delay in the attitude
        residual, and the fuel unknowns bent to absorb it (fuel errors of 8-42 Cramer-Rao std after naming
        the delay on design logs at 100 Hz). In the residual's axes (the first sample's), not the body's: the filter
        turns the body-axis error into an attitude error, which this channel sees rotated by the base's attitude since
        the first sample (2-4 deg over a minute on ``orbit7``, which leaked 3-7 % of one axis's response into
        another's)."""
        return self._frame_steps(base[:, 1:] - self.problem.measured[1:])

    def sensor_gyro_steps(self, sample_rates: FloatArray) -> FloatArray:
        """:meth:`gyro_steps` (T-1, 3) against the base rate ``sample_rates`` (T, 3), rad/s, that the gyro's own channel
        predicts at the log's samples (from the joint-rate sensors), each step's two samples averaged.

        The instrument of :func:`choose_gyro_coupling`: the midpoint rate of :meth:`gyro_steps` comes from encoder
        differences, whose noise is in this channel's residual too (its predicted increments), so regressing the
        residual on it pulled the fitted response toward that shared noise's (a lag-0 coefficient of 0.94-0.98 for the
        filter's 0.888 on held-out log 10529, ``orbit7`` at 50 Hz), and the fuel unknowns were 5-8 Cramer-Rao std off
        after naming its 52 ms delay. The joint-rate sensors' noise is independent of the encoders'."""
        rates = np.asarray(sample_rates, dtype=float)
        return self._frame_steps((0.5 * (rates[1:] + rates[:-1]) - self.problem.measured[1:])[None])[0]

    def _frame_steps(self, rate_errors: FloatArray) -> FloatArray:
        """Rate errors (P, T-1, 3), rad/s, body axes at the steps' midpoints, integrated over each step in the first
        sample's axes (P, T-1, 3), rad: the midpoint rule's map."""
        return np.einsum("tij,ptj->pti", self._step_map, rate_errors)

    def residuals(self, theta: FloatArray, noise: ErrorModel) -> FloatArray:
        """The whitened differences (3T-6,) at ``theta`` (k,), in the noise axes: unit variance and independent under
        ``noise``."""
        return self.whitened_steps(self.differences(theta), noise)

    def whitened_steps(self, steps: FloatArray, noise: ErrorModel) -> FloatArray:
        """Steps (T-1, 3), or their derivatives (T-1, 3, k), vectors in the first sample's frame, whitened under ``noise``
        as :meth:`residuals` and :meth:`jacobian` whiten the channel's own: (3T-6,) or (3T-6, k)."""
        steps = np.asarray(steps, dtype=float)
        if steps.ndim == 2:
            return self._whiten(self._in_axes(steps), noise).ravel()
        return self._whiten(self._jacobian_in_axes(steps), noise).reshape(-1, steps.shape[2])

    def moved_chi2(self, other: AttitudeChannel, theta: FloatArray, noise: ErrorModel) -> float:
        """How much ``other`` (this log's channel at another reference) moves the residual at ``theta`` (k,): the
        squared norm of the change of :meth:`residuals`, whitened as here under ``noise``. Its square root bounds the
        shift the change can cause in a fit of both channels at ``theta``, in that fit's standard deviations: to first
        order, with the error model held, the shift's norm in the joint information is at most the change's projection
        on the attitude's Jacobian, since the joint information is at least the attitude's. It bounds the unknowns'
        shift, not a likelihood ratio's (that moves by up to about twice the change's norm times the residuals')."""
        change = other.differences(theta) - self.differences(theta)
        whitened = self._whiten(self._in_axes(change), noise)
        return float(np.sum(whitened * whitened))

    def difference_jacobian(self, theta: FloatArray) -> FloatArray:
        """``d differences / d theta`` (T-1, 3, k) at ``theta`` (k,)."""
        n_t = len(self.measured)
        rates = self.problem.base_rate_jacobian(np.asarray(theta, dtype=float)).reshape(n_t, 3, -1)[1:]
        rate_steps = np.einsum("tij,tjk->tik", self._step_map, rates)
        steps = rate_steps.copy()
        if self._error_jacobian is not None:
            steps[:, :, : self._error_jacobian.shape[2]] += self._error_jacobian
        if self.coupling is None:
            return steps
        response = self.coupling.response(np.moveaxis(rate_steps, 2, 0))  # (k, T-1, 3): the gyro steps' derivative
        return steps - np.moveaxis(response, 0, 2)

    def jacobian(self, theta: FloatArray, noise: ErrorModel) -> FloatArray:
        """``d residuals / d theta`` (3T-6, k) at ``theta`` (k,)."""
        return self.whitened_steps(self.difference_jacobian(theta), noise)

    def chi2(self, theta: FloatArray, noise: ErrorModel) -> float:
        """The channel's chi-square at ``theta`` (k,) under ``noise`` (``n_values`` degrees of freedom at the truth)."""
        r = self.residuals(theta, noise)
        return float(r @ r)

    def chi2s(self, thetas: FloatArray, noise: ErrorModel) -> FloatArray:
        """:meth:`chi2` of each row of ``thetas`` (P, k), the model evaluated once for all: (P,)."""
        rows = self.residual_rows(thetas, noise)
        return np.sum(rows * rows, axis=1)

    def residual_rows(self, thetas: FloatArray, noise: ErrorModel) -> FloatArray:
        """:meth:`residuals` of each row of ``thetas`` (P, k), the model evaluated once for all: (P, 3T-6)."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        differences = self._in_axes(self._differences(thetas, self.problem.base_rate(thetas)))
        if isinstance(noise, PropagatedNoise):  # the rows whitened at once, as columns
            columns = self._whiten(np.moveaxis(differences, 0, 2), noise)
            return np.moveaxis(columns, 2, 0).reshape(len(thetas), -1)
        return np.array([self._whiten(d, noise).ravel() for d in differences])

    def fisher(self, theta: FloatArray, noise: ErrorModel) -> FloatArray:
        """Fisher information (k, k) of the attitude source about ``theta`` (k,) under ``noise``."""
        jac = self.jacobian(theta, noise)
        return jac.T @ jac

    def estimate_propagated_noise(self, theta: FloatArray) -> PropagatedNoise:
        """The propagated error model fitted to the residual at ``theta`` (k,) from its default starts, whatever error
        model the channel was weighed with (:func:`~estimators.attitude_propagation.fit_propagated_noise`).

        Raises:
            SpaceIdInputError: a channel without the encoders' propagation (coupled to the gyro)."""
        return fit_propagated_noise(self._in_axes(self.differences(theta)), self._require_propagation())

    def estimate_noise(self, theta: FloatArray, start: ErrorModel | None = None, only_from_start: bool = False) -> ErrorModel:
        """The error model fitted to the residual at ``theta`` (k,) by maximum likelihood. With a ``start`` (a nearby
        fit's error model), of ``start``'s kind: a stationary one tried as one more start (the only one with
        ``only_from_start``); a propagated one searched from the start alone in a narrow simplex, which keeps the start
        unless the likelihood falls across it (:func:`~estimators.attitude_propagation.fit_propagated_noise`: in
        practice the candidates' refits keep the baseline's propagated error model, and their profile ratio is the
        held one).
        Without, both kinds where the channel has the encoders' propagation (no gyro coupling): the stationary one
        (:func:`~estimators.attitude_noise.fit_attitude_noise`, :data:`STATIONARY_PARAMETERS` numbers) and the
        propagated one (:func:`~estimators.attitude_propagation.fit_propagated_noise`, :data:`PROPAGATED_PARAMETERS`),
        the one of lower BIC (``-2 log L`` plus the numbers times ``log`` of the values). On a noise-free attitude the
        propagated one describes the residual better by ~15,000 units of ``-2 log L`` on a 60 s, 100 Hz log
        (``benchmarks/attitude_error_model.py``): the encoders' noise changes direction with the arm's configuration,
        which no stationary model follows; with a star tracker the two are within a few units."""
        differences = self._in_axes(self.differences(theta))
        if isinstance(start, PropagatedNoise):
            return fit_propagated_noise(differences, self._require_propagation(), start, only_from_start)
        stationary = fit_attitude_noise(differences, start, only_from_start)
        if start is not None or self._propagation_axes is None:
            return stationary
        propagated = fit_propagated_noise(differences, self._propagation_axes)
        n_values = 3 * (len(differences) - 1)
        whitened = self._whiten(differences, stationary)
        stationary_bic = (
            float(np.sum(whitened * whitened)) + self._log_det(stationary) + STATIONARY_PARAMETERS * math.log(n_values)
        )
        propagated_bic = propagated_log_likelihood(differences, self._propagation_axes, propagated) + (
            PROPAGATED_PARAMETERS * math.log(n_values)
        )
        return propagated if propagated_bic < stationary_bic else stationary

    def profile_chi2(self, theta: FloatArray, noise: ErrorModel, reference: ErrorModel) -> float:
        """``-2 log L`` of the residual at ``theta`` (k,) under ``noise``, less that of a white residual under
        ``reference``'s covariance: ``chi2(theta, noise) + log det(noise) - log det(reference)``. With ``noise`` fitted
        at ``theta`` (:meth:`estimate_noise`), differences of it between models are profile likelihood ratios: the
        error model is a nuisance refitted under each model, so a model that explains structure the error model had
        absorbed as the model's own wander gains its log-determinant, and one that explains nothing gains nothing."""
        return self.chi2(theta, noise) + self._log_det(noise) - self._log_det(reference)

    def _whiten(self, differences: FloatArray, noise: ErrorModel) -> FloatArray:
        """Differences in the noise axes (T-1, 3[, k]) whitened under ``noise``: (T-2, 3[, k])."""
        if isinstance(noise, PropagatedNoise):
            return solve_with_factor(self._factor(noise)[0], filtered(differences, noise.walk_correlation))
        return noise.whiten(differences, self._factors(noise))

    def _log_det(self, noise: ErrorModel) -> float:
        """``log det`` of ``noise``'s covariance of the values :meth:`_whiten` gives (T-2 per axis)."""
        if isinstance(noise, PropagatedNoise):
            return self._factor(noise)[1]
        return noise.log_det(len(self._measured_steps))

    def _require_propagation(self) -> EncoderPropagation:
        """The encoders' propagation in the noise axes, which a :class:`PropagatedNoise` needs."""
        if self._propagation_axes is None:
            raise SpaceIdInputError(
                "attitude channel: a propagated error model needs the encoders' propagation, which a channel coupled to "
                "the gyro (a fused attitude) does not have"
            )
        return self._propagation_axes

    def _factor(self, noise: PropagatedNoise) -> tuple[FloatArray, float]:
        """The banded Cholesky factor of ``noise``'s covariance and its log-determinant
        (:func:`~estimators.attitude_propagation.band_factor`), cached for the last noise model asked."""
        if self._cached_factor is None or self._cached_factor[0] != noise:
            self._cached_factor = (noise, *band_factor(self._require_propagation().covariance(noise)))
        return self._cached_factor[1], self._cached_factor[2]

    def _factors(self, noise: AttitudeNoise) -> list[FloatArray]:
        """The whitening factors of ``noise``, cached for the last noise model asked."""
        if self._cached is None or self._cached[0] != noise:
            self._cached = (noise, noise.factors(len(self._measured_steps)))
        return self._cached[1]

    @property
    def axes(self) -> FloatArray:
        """The noise axes (3, 3), columns in the first sample's frame, in which the error model whitens (identity before
        :meth:`set_reference`)."""
        return np.eye(3) if self._axes is None else self._axes.copy()

    def _in_axes(self, steps: FloatArray) -> FloatArray:
        """``steps`` (..., 3), vectors in the first sample's frame, in the noise axes."""
        return steps if self._axes is None else steps @ self._axes

    def _jacobian_in_axes(self, jac: FloatArray) -> FloatArray:
        """``jac`` (T-1, 3, k), derivatives of steps in the first sample's frame, in the noise axes."""
        return jac if self._axes is None else np.einsum("tik,ij->tjk", jac, self._axes)
