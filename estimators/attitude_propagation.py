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
noise-free attitude this is the whole residual but for the model's own small wander (the midpoint rule's error is
taken out to first order, and a simulator's integrator has its own, ~1e-8 rad over a minute): at this precision that
wander shows, and a model without it named a momentum on clean logs.

:class:`PropagatedNoise` adds to it the attitude source's white error and that wander, as the stationary model
(:class:`~estimators.attitude_noise.AttitudeNoise`) has them but the same on every axis: the steps are filtered,
``u_k = d_k - phi d_{k-1}``, and their covariance is then banded, two blocks of three below the diagonal
(:meth:`EncoderPropagation.covariance`); :func:`whiten_propagated` whitens with its banded Cholesky factor and gives
its log-determinant, :func:`fit_propagated_noise` fits the four numbers by maximum likelihood.

The derivatives are taken where the base rate is computed, on the channel's midpoint samples: ``W`` by a forward
difference of each joint's angle over every sample at once (the base rate of a sample depends on that sample's joint
state alone in a model without state-carrying effects, which is checked), ``V`` likewise, where the base rate is
linear.
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from scipy.optimize import minimize

from estimators.attitude_integration import midpoint_step_map, relative_attitudes, shared_midpoint_log
from estimators.problem import IdentificationModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog

#: the forward-difference step of the joint angles (rad) and rates (rad/s) for the base rate's derivatives: the
#: base rate is smooth in the angles (a 1e-6 rad step leaves a relative error of order 1e-6) and linear in the rates
ANGLE_STEP_RAD, RATE_STEP_RAD_S = 1e-6, 1e-3


@dataclass(frozen=True)
class PropagatedNoise:
    """The attitude residual's error model built from the encoders' noise propagated step by step
    (:class:`EncoderPropagation`), the attitude source's white error and the model's own wander, the last two as in
    :class:`~estimators.attitude_noise.AttitudeNoise` but the same on every axis.

    Attributes:
        encoder_std_rad: the encoders' white noise per joint, rad.
        white_std_rad: the attitude source's white error per axis, rad (a star tracker's; 0 for an exact attitude).
        walk_std_rad: the std of the innovation of the wander's steps per axis, rad: what the model's prediction loses
            beyond the encoders (the channel's integration error left, another simulator's integrator).
        walk_correlation: ``phi`` in ``[0, 1)``, the correlation of the wander's successive steps (0: a random walk;
            near 1: a smooth wander).
    """

    encoder_std_rad: float
    white_std_rad: float = 0.0
    walk_std_rad: float = 0.0
    walk_correlation: float = 0.0

    def __post_init__(self) -> None:
        for label in ("encoder_std_rad", "white_std_rad", "walk_std_rad", "walk_correlation"):
            value = getattr(self, label)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0.0):
                raise SpaceIdInputError(f"propagated attitude noise: {label} expected a finite number >= 0, got {value!r}")
        if self.walk_correlation >= 1.0:
            raise SpaceIdInputError(
                f"propagated attitude noise: walk_correlation expected in [0, 1), got {self.walk_correlation!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-able, with ``attitude_error_model``: ``"propagated"``."""
        return {"attitude_error_model": "propagated"} | {
            label: getattr(self, label) for label in ("encoder_std_rad", "white_std_rad", "walk_std_rad", "walk_correlation")
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PropagatedNoise:
        """The inverse of :meth:`to_dict`."""
        return cls(*(float(data[k]) for k in ("encoder_std_rad", "white_std_rad", "walk_std_rad", "walk_correlation")))


class EncoderPropagation:
    """How each encoder sample's error moves the attitude residual's steps (see the module docstring).

    Args:
        previous: ``P`` (m, 3, n): step ``k``'s rotation (rad) per rad of the encoders at sample ``k - 1``.
        current: ``C`` (m, 3, n): the same per rad of the encoders at sample ``k``.

    Rows are the log's steps in order; axes those of the channel's first sample unless :meth:`in_axes` turned them.
    """

    def __init__(self, previous: FloatArray, current: FloatArray) -> None:
        self.previous = np.asarray(previous, dtype=float)
        self.current = np.asarray(current, dtype=float)
        if self.previous.shape != self.current.shape or self.previous.ndim != 3 or self.previous.shape[1] != 3:
            raise SpaceIdInputError(
                f"encoder propagation: expected two (m, 3, n) arrays, got {self.previous.shape} and {self.current.shape}"
            )
        p, c = self.previous, self.current
        #: the blocks of the covariance per unit encoder variance: ``P_k P_k^T + C_k C_k^T`` and ``P_k C_{k-1}^T``
        self.unit_diagonal = np.einsum("kin,kjn->kij", p, p) + np.einsum("kin,kjn->kij", c, c)
        self.unit_below = np.einsum("kin,kjn->kij", p[1:], c[:-1])

    def __len__(self) -> int:
        return len(self.previous)

    def in_axes(self, axes: FloatArray) -> EncoderPropagation:
        """The same in the axes ``axes`` (3, 3), columns in the current axes."""
        return EncoderPropagation(np.einsum("ia,kin->kan", axes, self.previous), np.einsum("ia,kin->kan", axes, self.current))

    def covariance(self, noise: PropagatedNoise) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The covariance (rad^2) under ``noise`` of the filtered steps ``u_k = d_k - phi d_{k-1}`` (``k >= 1``;
        :func:`whiten_propagated`): its blocks at lags 0, 1 and 2, (m-1, 3, 3), (m-2, 3, 3) and (m-3, 3, 3), ``u_1``
        first. With ``D_k = P_k P_k^T + C_k C_k^T`` and ``X_k = P_k C_{k-1}^T`` (per unit encoder variance), the encoders
        give ``D_k + phi^2 D_{k-1} - phi (X_k + X_k^T)``, ``X_k - phi D_{k-1} + phi^2 X_{k-1}`` and ``-phi X_{k-1}``; the
        white error and the wander add what they add in :class:`~estimators.attitude_noise.AttitudeNoise`."""
        if len(self) < 4:
            raise SpaceIdInputError(f"encoder propagation: expected at least 4 steps, got {len(self)}")
        e2, s2, w2, phi = noise.encoder_std_rad**2, noise.white_std_rad**2, noise.walk_std_rad**2, noise.walk_correlation
        d, x = self.unit_diagonal, self.unit_below  # x[k - 1] = X_k
        eye = np.eye(3)
        lag0 = e2 * (d[1:] + phi * phi * d[:-1] - phi * (x + np.swapaxes(x, 1, 2)))
        lag0 += (s2 * (1.0 + (1.0 + phi) ** 2 + phi * phi) + w2) * eye
        lag1 = e2 * (x[1:] - phi * d[1:-1] + phi * phi * x[:-1]) - s2 * (1.0 + phi) ** 2 * eye
        lag2 = -e2 * phi * x[1:-1] + s2 * phi * eye
        return lag0, lag1, lag2


def encoder_propagation(model: IdentificationModel, log: MeasurementLog, theta: FloatArray) -> EncoderPropagation:
    """:class:`EncoderPropagation` of ``model`` at unknowns ``theta`` (k,) on ``log`` (with attitude quaternions).

    Raises:
        SpaceIdInputError: the log has no attitude, fewer than 3 samples, or ``model``'s base rate at a sample depends
            on other samples' joint state (an effect with a state carried in time), where this propagation does not
            hold."""
    if log.n_samples < 3:
        raise SpaceIdInputError(f"encoder propagation: expected a log of at least 3 samples, got {log.n_samples}")
    step_map = midpoint_step_map(relative_attitudes(log), log.t_s)
    mid, moved_logs = _moved_logs(log)
    theta = np.asarray(theta, dtype=float)[None]
    base = model.problem(mid).base_rate(theta, count=False)[0, 1:]
    n_joints = mid.q_rad.shape[1]
    angle, rate = np.empty((len(base), 3, n_joints)), np.empty((len(base), 3, n_joints))
    for (array, joint), moved in moved_logs.items():
        step, out = (ANGLE_STEP_RAD, angle) if array == "q_rad" else (RATE_STEP_RAD_S, rate)
        shifted = model.problem(moved).base_rate(theta, count=False)[0, 1:]
        out[:, :, joint] = (shifted - base) / step
    _check_pointwise(model, mid, theta, base)
    dt = np.diff(np.asarray(log.t_s, dtype=float))[:, None, None]
    previous = np.einsum("kij,kjn->kin", step_map, 0.5 * angle - rate / dt)
    current = np.einsum("kij,kjn->kin", step_map, 0.5 * angle + rate / dt)
    return EncoderPropagation(previous, current)


def _moved_logs(log: MeasurementLog) -> tuple[MeasurementLog, dict[tuple[str, int], MeasurementLog]]:
    """The midpoint log of ``log`` (:func:`~estimators.attitude_integration.shared_midpoint_log`, the attitude channel's
    own) and its copies with one joint's angles (``"q_rad"``) or rates (``"dq_rad_s"``) moved by
    :data:`ANGLE_STEP_RAD` or :data:`RATE_STEP_RAD_S` from the second sample on, by (array, joint); made once per log
    (logs are read-only), so that the momentum models built on them are shared too: a diagnosis propagates the
    encoders' noise at two references at least, and each angle-moved log's model costs a pass of the arm's dynamics."""
    made = _MOVED_LOGS.get(log)
    if made is None:
        mid = shared_midpoint_log(log)
        moved_logs = {}
        for joint in range(mid.q_rad.shape[1]):
            for array, step in (("q_rad", ANGLE_STEP_RAD), ("dq_rad_s", RATE_STEP_RAD_S)):
                moved = np.array(getattr(mid, array), dtype=float)
                moved[1:, joint] += step
                moved_logs[array, joint] = dataclasses.replace(mid, **{array: moved})
        made = _MOVED_LOGS[log] = (mid, moved_logs)
    return made


#: :func:`_moved_logs` per log
_MOVED_LOGS: weakref.WeakKeyDictionary[MeasurementLog, tuple[MeasurementLog, dict[tuple[str, int], MeasurementLog]]] = (
    weakref.WeakKeyDictionary()
)


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


#: the lower bandwidth of the filtered steps' covariance, scalars in time then axis order (two blocks of three, less one)
BANDWIDTH = 8


def whiten_block_banded(values: FloatArray, blocks: tuple[FloatArray, FloatArray, FloatArray]) -> tuple[FloatArray, float]:
    """``values`` (m, 3) or (m, 3, k) whitened under the covariance of ``blocks`` (its blocks at lags 0, 1 and 2:
    (m, 3, 3), (m-1, 3, 3), (m-2, 3, 3), :meth:`EncoderPropagation.covariance`): ``L^-1 values`` with ``L`` its lower
    Cholesky factor (rows in time, then axis order), and ``log det`` of the covariance.

    Raises:
        SpaceIdInputError: shapes that do not match, or a covariance that is not positive definite."""
    factor, log_det = band_factor(blocks)
    return solve_with_factor(factor, values), log_det


def band_factor(blocks: tuple[FloatArray, FloatArray, FloatArray]) -> tuple[FloatArray, float]:
    """The lower Cholesky factor ``L`` of the covariance of ``blocks`` (:func:`whiten_block_banded`) as rows (3m,
    BANDWIDTH + 1), ``factor[i, r] = L[i, i - r]``, and the covariance's ``log det``.

    Raises:
        SpaceIdInputError: shapes that do not match, or a covariance that is not positive definite."""
    lag0, lag1, lag2 = (np.ascontiguousarray(b, dtype=float) for b in blocks)
    m = lag0.shape[0]
    if lag0.shape != (m, 3, 3) or lag1.shape != (max(m - 1, 0), 3, 3) or lag2.shape != (max(m - 2, 0), 3, 3):
        raise SpaceIdInputError(
            f"whiten: expected blocks (m, 3, 3), (m-1, 3, 3), (m-2, 3, 3); got {lag0.shape}, {lag1.shape}, {lag2.shape}"
        )
    band = np.zeros((3 * m, BANDWIDTH + 1))  # band[i, r] = Cov[i, i - r]
    rows = 3 * np.arange(m)
    for a in range(3):
        for b in range(3):
            if a >= b:
                band[rows + a, a - b] = lag0[:, a, b]
            band[rows[1:] + a, 3 + a - b] = lag1[:, a, b]
            band[rows[2:] + a, 6 + a - b] = lag2[:, a, b]
    factor, log_det = _band_cholesky(band)
    if not math.isfinite(log_det):
        raise SpaceIdInputError("whiten: the covariance is not positive definite")
    return factor, log_det


def solve_with_factor(factor: FloatArray, values: FloatArray) -> FloatArray:
    """``L^-1 values`` for ``values`` (m, 3[, k]) and ``L`` a :func:`band_factor` of 3m rows.

    Raises:
        SpaceIdInputError: ``values`` of another length."""
    if values.shape[0] * 3 != factor.shape[0] or values.shape[1] != 3:
        raise SpaceIdInputError(f"whiten: expected values ({factor.shape[0] // 3}, 3[, k]), got {values.shape}")
    flat = np.ascontiguousarray(np.asarray(values, dtype=float).reshape(factor.shape[0], -1))
    return _band_solve(factor, flat).reshape(values.shape)


@njit(cache=True)
def _band_cholesky(band: FloatArray) -> tuple[FloatArray, float]:
    """The banded Cholesky factor (n, p + 1) of the covariance ``band`` (n, p + 1), ``band[i, r] = Cov[i, i - r]``, row
    by row (``factor[i, r] = L[i, i - r]``), and ``log det``; ``-inf`` where the covariance is not positive definite."""
    n, width = band.shape
    p = width - 1
    factor = np.zeros((n, width))
    log_det = 0.0
    for i in range(n):
        first = max(0, i - p)
        for j in range(first, i + 1):
            value = band[i, i - j]
            for t in range(first, j):
                value -= factor[i, i - t] * factor[j, j - t]
            if j < i:
                factor[i, i - j] = value / factor[j, 0]
            else:
                if not value > 0.0:
                    return factor, -math.inf
                factor[i, 0] = math.sqrt(value)
                log_det += 2.0 * math.log(factor[i, 0])
    return factor, log_det


@njit(cache=True)
def _band_solve(factor: FloatArray, values: FloatArray) -> FloatArray:
    """``L^-1 values`` (n, c) by forward substitution with the banded factor of :func:`_band_cholesky`."""
    n, c = values.shape
    p = factor.shape[1] - 1
    out = np.empty((n, c))
    for i in range(n):
        first = max(0, i - p)
        for col in range(c):
            value = values[i, col]
            for t in range(first, i):
                value -= factor[i, i - t] * out[t, col]
            out[i, col] = value / factor[i, 0]
    return out


def filtered(differences: FloatArray, phi: float) -> FloatArray:
    """``u_k = d_k - phi d_{k-1}`` (m-1, 3[, k]) of steps ``differences`` (m, 3[, k])."""
    return differences[1:] - phi * differences[:-1]


def whiten_propagated(
    differences: FloatArray, propagation: EncoderPropagation, noise: PropagatedNoise
) -> tuple[FloatArray, float]:
    """Steps ``differences`` (m, 3[, k]), the axes of ``propagation``, whitened under ``noise``: (m-1, 3[, k]), unit
    variance and independent under it, and the ``log det`` of their covariance."""
    return whiten_block_banded(filtered(differences, noise.walk_correlation), propagation.covariance(noise))


def propagated_log_likelihood(differences: FloatArray, propagation: EncoderPropagation, noise: PropagatedNoise) -> float:
    """``-2 log L`` (without the constant ``n log 2 pi``) of steps ``differences`` (m, 3) under ``noise``."""
    whitened, log_det = whiten_propagated(differences, propagation, noise)
    return float(np.sum(whitened * whitened)) + log_det


#: the range of the base-10 logarithms of the white error's and the wander's variances relative to the encoders' that
#: :func:`fit_propagated_noise` explores, and the largest wander correlation
LOG_RATIO_RANGE, MAX_CORRELATION = (-12.0, 8.0), 0.999


def fit_propagated_noise(
    differences: FloatArray, propagation: EncoderPropagation, start: PropagatedNoise | None = None, only_from_start: bool = False
) -> PropagatedNoise:
    """Maximum-likelihood :class:`PropagatedNoise` of steps ``differences`` (m, 3), rad, as ``propagation`` carries the
    encoders' noise into them: the overall scale in closed form; the white error's and the wander's variances relative
    to the encoders' (their logarithms, within :data:`LOG_RATIO_RANGE`) and the wander's correlation (its logit) by
    Nelder-Mead: without ``start``, from a small white error and wander at correlations 0.05 and 0.9; with it, from
    ``start`` alone (``only_from_start`` is then the same) in a first simplex a tenth of a unit wide, narrower than the
    stopping span, so the search stops at once where the likelihood changes by less than a thousandth across it: a
    refit keeps a nearby fit's error model unless the data move it. A wander left at its range's end (an exact
    attitude's phi near 0) cannot be left from there: the refit does not look for another basin (a smooth wander the
    candidate's fit would reveal), and the candidates' profile likelihood is then the held one.

    Raises:
        SpaceIdInputError: ``differences`` not (len(propagation), 3), or ``only_from_start`` without a ``start``."""
    d = np.asarray(differences, dtype=float)
    if d.shape != (len(propagation), 3):
        raise SpaceIdInputError(f"propagated attitude noise: expected differences ({len(propagation)}, 3), got {d.shape}")
    if only_from_start and start is None:
        raise SpaceIdInputError("propagated attitude noise: only_from_start needs a start")
    n = 3 * (len(d) - 1)
    low, high = LOG_RATIO_RANGE

    def profile(x: FloatArray) -> tuple[float, PropagatedNoise]:
        white, walk = (10.0 ** min(max(float(v), low), high) for v in x[:2])
        phi = MAX_CORRELATION / (1.0 + math.exp(-min(max(float(x[2]), -50.0), 50.0)))
        unit = PropagatedNoise(1.0, math.sqrt(white), math.sqrt(walk), phi)
        whitened, log_det = whiten_propagated(d, propagation, unit)
        scale = max(float(np.sum(whitened * whitened)) / n, 1e-300)
        noise = PropagatedNoise(math.sqrt(scale), math.sqrt(scale * white), math.sqrt(scale * walk), phi)
        return n * math.log(scale) + log_det + n, noise

    def logit(phi: float) -> float:
        phi = min(max(phi, 1e-6), MAX_CORRELATION * (1.0 - 1e-9))
        return math.log(phi / (MAX_CORRELATION - phi))

    # from a nearby fit's error model alone: the defaults cost a search each (~150 likelihoods)
    starts = [] if only_from_start or start is not None else [np.array([-6.0, -6.0, logit(phi)]) for phi in (0.05, 0.9)]
    if start is not None:
        if start.encoder_std_rad <= 0.0:
            raise SpaceIdInputError("propagated attitude noise: the start has no encoder noise")
        e2 = start.encoder_std_rad**2
        ratios = np.log10(np.maximum([start.white_std_rad**2 / e2, start.walk_std_rad**2 / e2], 10.0**low))
        starts.append(np.append(ratios, logit(start.walk_correlation)))
    best: tuple[float, PropagatedNoise] | None = None
    for x0 in starts:
        # a first simplex half a decade wide, a tenth from a nearby fit's error model (scipy's default is 5 % of each
        # coordinate: 0.3 decades in the ratios but 1e-4 in a logit near 0); stops when the vertices' -2 log L lie
        # within a thousandth of a unit and span at most 0.3 decades or logit units: the likelihood is flat along a
        # ratio held at its range's end (an exact attitude's white error), where a tighter span costs a search again
        simplex = np.vstack([x0, x0 + np.diag([0.5, 0.5, 0.5] if start is None else [0.1, 0.1, 0.1])])
        options = {"xatol": 0.3, "fatol": 1e-3, "initial_simplex": simplex}
        found = minimize(lambda x: profile(x)[0], x0, method="Nelder-Mead", options=options)
        candidate = profile(found.x)
        if best is None or candidate[0] < best[0]:
            best = candidate
    assert best is not None
    return best[1]
