"""The attitude residual's error model: the attitude source's white error and the model's own wander.

Per noise axis (the principal axes of the residual's white part in the first sample's base frame), the attitude
channel's residual (:mod:`estimators.attitude_channel`) is
modelled as

* the attitude source's white error ``w_k`` (std ``white_std_rad``): a star tracker's noise;
* the model's own accumulated error ``s_k``, whose steps ``a_k = s_k - s_{k-1}`` are a first-order
  autoregression, ``a_k = phi a_{k-1} + nu_k`` (``walk_std_rad``: std of ``nu``; ``walk_correlation``: ``phi``
  in ``[0, 1)``). ``phi = 0`` is a random walk (encoder and rate noise through the nonlinear momentum map, a
  filtered attitude's drift with its gyro); ``phi`` near 1 a smooth wander (another simulator's integrator, what is
  left of the channel's own integration error, :mod:`estimators.attitude_integration`).

Then ``u_k = d_k - phi d_{k-1} = w_k - (1 + phi) w_{k-1} + phi w_{k-2} + nu_k`` (``k >= 2``) of the residual's
differences ``d`` is a moving average of order 2: its covariance is banded, and :meth:`AttitudeNoise.whiten` whitens
``u`` with that covariance's banded Cholesky factor, a chi-square exact for this model. The three numbers per axis
are fitted by maximum likelihood (:func:`fit_attitude_noise`), the overall scale in closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from scipy.linalg import cholesky_banded

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: the smallest std (rad) either part of :class:`AttitudeNoise` may have: keeps the whitening finite on a
#: noise-free log (the midpoint rule's own error there is ~1e-9 rad per step)
MIN_STD_RAD = 1e-10

#: the range of the logit of the white error's share of the variance, ``sw^2 / (sw^2 + snu^2)``, that the error
#: model's fit explores (:func:`fit_attitude_noise`): either part down to 1e-20 of the other
LOGIT_SHARE_LIMIT = math.log(1e20)

#: the largest step correlation ``phi`` fitted (:func:`fit_attitude_noise`)
MAX_CORRELATION = 0.999


@dataclass(frozen=True)
class AttitudeNoise:
    """The attitude residual's error model, per noise axis of the channel (see the module docstring).

    Attributes:
        white_std_rad: std of the attitude source's white error (3,), rad.
        walk_std_rad: std of the innovation ``nu`` of the model's wander steps (3,), rad.
        walk_correlation: ``phi`` (3,), in ``[0, 1)``: the correlation of successive wander steps (0: a random walk).
    """

    white_std_rad: tuple[float, float, float]
    walk_std_rad: tuple[float, float, float]
    walk_correlation: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for label in ("white_std_rad", "walk_std_rad", "walk_correlation"):
            value = np.asarray(getattr(self, label), dtype=float)
            if value.shape != (3,) or not np.all(np.isfinite(value)) or np.any(value < 0.0):
                raise SpaceIdInputError(f"attitude noise: {label} expected 3 finite numbers >= 0, got {value!r}")
        if np.any(np.asarray(self.walk_correlation) >= 1.0):
            raise SpaceIdInputError(f"attitude noise: walk_correlation expected values in [0, 1), got {self.walk_correlation!r}")

    @classmethod
    def white(cls, std_rad: float) -> AttitudeNoise:
        """A white attitude error of ``std_rad`` per axis and no wander (a star tracker and an exact model)."""
        return cls((std_rad,) * 3, (0.0,) * 3)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> AttitudeNoise:
        """The inverse of :meth:`to_dict`."""
        return cls(*(tuple(float(v) for v in data[k]) for k in ("white_std_rad", "walk_std_rad", "walk_correlation")))  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, list[float]]:
        """JSON-able: ``white_std_rad``, ``walk_std_rad`` and ``walk_correlation``, three each."""
        return {k: [float(v) for v in getattr(self, k)] for k in ("white_std_rad", "walk_std_rad", "walk_correlation")}

    @property
    def step_std_rad(self) -> FloatArray:
        """The std of the wander's steps ``a`` (3,), rad: ``walk_std_rad / sqrt(1 - phi^2)``."""
        return np.asarray(self.walk_std_rad) / np.sqrt(1.0 - np.asarray(self.walk_correlation) ** 2)

    def factors(self, n_steps: int) -> list[FloatArray]:
        """Per axis, the lower banded Cholesky factor (3, n_steps - 1) of the covariance of the filtered differences
        ``u`` of ``n_steps`` differences (a log of ``n_steps + 1`` samples: ``n_steps - 1`` values of ``u``)."""
        return [
            _filtered_factor(white, walk, phi, n_steps - 1)
            for white, walk, phi in zip(self.white_std_rad, self.walk_std_rad, self.walk_correlation, strict=True)
        ]

    def log_det(self, n_steps: int) -> float:
        """``log det`` of the covariance of the filtered differences of ``n_steps`` differences (all three axes; the
        values :meth:`whiten` gives for them): the term that, added to the chi-square, makes ``-2 log L`` comparable
        across error models."""
        return float(sum(2.0 * np.sum(np.log(factor[0])) for factor in self.factors(n_steps)))

    def whiten(self, differences: FloatArray, factors: list[FloatArray] | None = None) -> FloatArray:
        """Differenced residuals (T-1, 3) or their Jacobian (T-1, 3, k) -> whitened (T-2, 3[, k]): ``u = d_k - phi
        d_{k-1}``, then ``L^-1 u`` per axis, unit variance and independent under the model."""
        factors = self.factors(differences.shape[0]) if factors is None else factors
        out = np.empty((differences.shape[0] - 1, *differences.shape[1:]))
        for axis, (phi, factor) in enumerate(zip(self.walk_correlation, factors, strict=True)):
            d = differences[:, axis]
            u = d[1:] - phi * d[:-1]
            out[:, axis] = _lower_banded_solve(factor, np.ascontiguousarray(u.reshape(len(u), -1))).reshape(u.shape)
        return out


@njit(cache=True)
def _lower_banded_solve(factor: FloatArray, rhs: FloatArray) -> FloatArray:
    """``L^-1 rhs`` (n, m) by forward substitution, for ``L`` a lower factor of bandwidth 2 in LAPACK's band storage
    (3, n) (row ``r`` holds ``L[j + r, j]``, as :func:`_filtered_factor` gives it) and ``rhs`` (n, m)."""
    n, m = rhs.shape
    out = np.empty((n, m))
    for j in range(n):
        for c in range(m):
            value = rhs[j, c]
            if j >= 2:
                value -= factor[2, j - 2] * out[j - 2, c]
            if j >= 1:
                value -= factor[1, j - 1] * out[j - 1, c]
            out[j, c] = value / factor[0, j]
    return out


def _filtered_factor(white_std: float, walk_std: float, phi: float, n: int) -> FloatArray:
    """Lower banded Cholesky factor (3, n) of the MA(2) covariance of ``u`` (see the module docstring)."""
    sw2, snu2 = max(white_std, MIN_STD_RAD) ** 2, max(walk_std, MIN_STD_RAD) ** 2
    bands = np.zeros((3, n))
    bands[0] = sw2 * (1.0 + (1.0 + phi) ** 2 + phi * phi) + snu2
    bands[1, :-1] = -sw2 * (1.0 + phi) ** 2
    bands[2, :-2] = sw2 * phi
    return cholesky_banded(bands, lower=True, check_finite=False)


@njit(cache=True)
def _shares(x: FloatArray) -> tuple[float, float, float]:
    """``(sw^2, snu^2, phi)`` with ``sw^2 + snu^2 = 1`` of a point ``x = [logit share, logit phi]`` of the profile
    likelihood's plane, clamped to the explored range (beyond it the likelihood is flat, and exp would overflow where
    the simplex wanders)."""
    share = 1.0 / (1.0 + math.exp(-min(max(x[0], -LOGIT_SHARE_LIMIT), LOGIT_SHARE_LIMIT)))
    phi = MAX_CORRELATION / (1.0 + math.exp(-min(max(x[1], -50.0), 50.0)))
    return share, 1.0 - share, phi


@njit(cache=True)
def _profile_scale(chi2_unit: float, n: int) -> float:
    """The maximum-likelihood variance scale ``sigma^2`` of a covariance ``sigma^2 C`` whose whitened residual has
    chi-square ``chi2_unit`` under ``C`` (``n`` values), floored at :data:`MIN_STD_RAD` squared (a residual of zeros)."""
    return max(chi2_unit / n, MIN_STD_RAD**2)


@njit(cache=True)
def _negative_log_likelihood(x: FloatArray, differences: FloatArray) -> float:
    """``-log L`` (up to a constant) of one axis's differences (n,) at ``x = [logit share, logit phi]``, maximised
    over the variance scale (the profile likelihood): the covariance is ``sigma^2 C(share, phi)``, and ``sigma^2 =
    chi2_C / n`` in closed form."""
    sw2, snu2, phi = _shares(x)
    half_log_det, chi2_unit = _whitened_terms(sw2, snu2, phi, differences)
    n = len(differences) - 1
    scale = _profile_scale(chi2_unit, n)
    return 0.5 * n * math.log(scale) + half_log_det + 0.5 * chi2_unit / scale


#: relative change of a Cholesky row below which the factor counts as stationary (:func:`_whitened_terms`)
STATIONARY_RTOL = 1e-15


@njit(cache=True)
def _whitened_terms(sw2: float, snu2: float, phi: float, d: FloatArray) -> tuple[float, float]:
    """``(sum log L_jj, |L^-1 u|^2)`` for ``u = d_k - phi d_{k-1}`` and ``L`` the Cholesky factor of the covariance of
    :func:`_filtered_factor`, in one pass: each row of ``L`` (three numbers, the covariance is banded Toeplitz) and
    the forward substitution as they come, without storing either."""
    c0 = sw2 * (1.0 + (1.0 + phi) ** 2 + phi * phi) + snu2
    c1 = -sw2 * (1.0 + phi) ** 2
    c2 = sw2 * phi
    n = len(d) - 1
    log_det, chi2 = 0.0, 0.0
    diag1, diag2, sub1 = 1.0, 1.0, 0.0  # L[j-1, j-1], L[j-2, j-2], L[j-1, j-2]
    w1, w2 = 0.0, 0.0  # the whitened values of rows j-1 and j-2
    j = 0
    while j < n:
        far = c2 / diag2 if j >= 2 else 0.0  # L[j, j-2]
        near = (c1 - far * sub1) / diag1 if j >= 1 else 0.0  # L[j, j-1]
        diag = math.sqrt(c0 - far * far - near * near)
        w = (d[j + 1] - phi * d[j] - far * w2 - near * w1) / diag
        log_det += math.log(diag)
        chi2 += w * w
        # the rows converge to the stationary factor (the spectral factor of the MA(2)); once a row equals the one
        # before to STATIONARY_RTOL, the rest are that row and the substitution is a fixed recursion
        settled = j >= 3 and abs(diag - diag1) <= STATIONARY_RTOL * diag and abs(near - sub1) <= STATIONARY_RTOL * diag
        diag2, diag1, sub1, w2, w1 = diag1, diag, near, w1, w
        j += 1
        if settled:
            break
    if j < n:
        inverse = 1.0 / diag1
        far = c2 / diag1
        log_det += (n - j) * math.log(diag1)
        for i in range(j, n):
            w = (d[i + 1] - phi * d[i] - far * w2 - sub1 * w1) * inverse
            chi2 += w * w
            w2, w1 = w1, w
    return log_det, chi2


#: the error model's Nelder-Mead stops when the simplex spans less than ``SIMPLEX_X_TOLERANCE`` in the logits of the
#: white share and of ``phi`` and less than ``SIMPLEX_F_TOLERANCE`` in ``-log L`` (a thousandth of a unit of a
#: likelihood ratio), or after ``SIMPLEX_MAX_EVALUATIONS`` evaluations (200 per dimension)
SIMPLEX_X_TOLERANCE, SIMPLEX_F_TOLERANCE, SIMPLEX_MAX_EVALUATIONS = 1e-3, 1e-3, 400


@njit(cache=True)
def _simplex_minimum(
    x0: FloatArray, d: FloatArray, x_tolerance: float, f_tolerance: float, max_evaluations: int
) -> tuple[FloatArray, float]:
    """The minimum ``(x, -log L)`` of :func:`_negative_log_likelihood` on one axis's differences ``d`` from ``x0`` (2,):
    the Nelder-Mead simplex (Lagarias, Reeds, Wright and Wright 1998: reflection 1, expansion 2, contraction and
    shrink 1/2), compiled with its objective (the likelihood costs ~9 us, a Python-level simplex ~30 us more per
    point). The first simplex steps each coordinate of ``x0`` by 5 % (0.00025 where it is 0). Stops when the simplex
    spans at most ``x_tolerance`` in every coordinate and ``f_tolerance`` in value, or after ``max_evaluations``."""
    n = x0.shape[0]
    sim = np.empty((n + 1, n))
    values = np.empty(n + 1)
    sim[0] = x0
    for k in range(n):
        sim[k + 1] = x0
        sim[k + 1, k] = 1.05 * x0[k] if x0[k] != 0.0 else 0.00025
    for j in range(n + 1):
        values[j] = _negative_log_likelihood(sim[j], d)
    evaluations = n + 1
    order = np.argsort(values, kind="mergesort")
    sim, values = sim[order], values[order]
    while evaluations < max_evaluations:
        if np.max(np.abs(sim[1:] - sim[0])) <= x_tolerance and np.max(np.abs(values[1:] - values[0])) <= f_tolerance:
            break
        centre = np.zeros(n)
        for j in range(n):
            centre += sim[j]
        centre /= n
        worst = sim[n].copy()
        reflected = 2.0 * centre - worst
        f_reflected = _negative_log_likelihood(reflected, d)
        evaluations += 1
        shrink = False
        if f_reflected < values[0]:
            expanded = 3.0 * centre - 2.0 * worst
            f_expanded = _negative_log_likelihood(expanded, d)
            evaluations += 1
            if f_expanded < f_reflected:
                sim[n], values[n] = expanded, f_expanded
            else:
                sim[n], values[n] = reflected, f_reflected
        elif f_reflected < values[n - 1]:
            sim[n], values[n] = reflected, f_reflected
        elif f_reflected < values[n]:  # outside contraction
            contracted = 1.5 * centre - 0.5 * worst
            f_contracted = _negative_log_likelihood(contracted, d)
            evaluations += 1
            if f_contracted <= f_reflected:
                sim[n], values[n] = contracted, f_contracted
            else:
                shrink = True
        else:  # inside contraction
            contracted = 0.5 * centre + 0.5 * worst
            f_contracted = _negative_log_likelihood(contracted, d)
            evaluations += 1
            if f_contracted < values[n]:
                sim[n], values[n] = contracted, f_contracted
            else:
                shrink = True
        if shrink:
            for j in range(1, n + 1):
                sim[j] = sim[0] + 0.5 * (sim[j] - sim[0])
                values[j] = _negative_log_likelihood(sim[j], d)
            evaluations += n
        order = np.argsort(values, kind="mergesort")
        sim, values = sim[order], values[order]
    return sim[0].copy(), values[0]


def fit_attitude_noise(
    differences: FloatArray, start: AttitudeNoise | None = None, only_from_start: bool = False
) -> AttitudeNoise:
    """Maximum-likelihood :class:`AttitudeNoise` of differenced attitude residuals (T-1, 3), rad, axis by axis.

    The variance's scale is profiled out in closed form (:func:`_negative_log_likelihood`), so Nelder-Mead searches
    the plane of the white error's share of the variance and ``phi`` (two dimensions instead of three; the same
    maximum, to 1e-4 in ``log L`` on six logs of every attitude source, with up to half the evaluations). Starts from the moments of a white error plus a random walk (lag-1
    autocovariance ``-sw^2``, variance ``2 sw^2 + snu^2``) with ``phi`` = 0.5, and from ``phi`` = 0.05 and 0.95; the
    best of the three. ``start``: an error model fitted to a nearby residual (another model's on the same log),
    tried as a fourth start; with ``only_from_start``, the only one (a polish of an optimum found at nearby unknowns).

    Raises:
        SpaceIdInputError: ``only_from_start`` without a ``start``."""
    if only_from_start and start is None:
        raise SpaceIdInputError("attitude noise: only_from_start needs a start")
    white, walk, correlation = [], [], []
    for axis, d in enumerate(np.ascontiguousarray(np.asarray(differences, dtype=float).T)):
        variance = float(d @ d) / len(d)
        lag1 = float(d[1:] @ d[:-1]) / len(d)
        sw2 = min(max(-lag1, 0.01 * variance), 0.49 * variance)
        snu2 = max(variance - 2.0 * sw2, 0.01 * variance)
        share = _logit_share(sw2, snu2)
        starts = [] if only_from_start else [np.array([share, _logit(phi)]) for phi in (0.05, 0.5, 0.95)]
        if start is not None:
            near_w2, near_r2 = start.white_std_rad[axis] ** 2, start.walk_std_rad[axis] ** 2
            starts.append(np.array([_logit_share(near_w2, near_r2), _logit(start.walk_correlation[axis])]))
        best = None
        for x0 in starts:
            x, value = _simplex_minimum(x0, d, SIMPLEX_X_TOLERANCE, SIMPLEX_F_TOLERANCE, SIMPLEX_MAX_EVALUATIONS)
            if best is None or value < best[1]:
                best = (x, value)
        assert best is not None
        # the point as the likelihood saw it (clamped to the explored range, where the simplex may have wandered)
        w2, r2, phi = _shares(best[0])
        scale = _profile_scale(_whitened_terms(w2, r2, phi, d)[1], len(d) - 1)
        w, r = math.sqrt(w2 * scale), math.sqrt(r2 * scale)
        white.append(w if w > MIN_STD_RAD else 0.0)
        walk.append(r if r > MIN_STD_RAD else 0.0)
        correlation.append(phi)
    return AttitudeNoise(tuple(white), tuple(walk), tuple(correlation))  # type: ignore[arg-type]


def _logit_share(white_var: float, walk_var: float) -> float:
    """The Nelder-Mead coordinate of the white share ``white_var / (white_var + walk_var)``, within the explored range."""
    white_var, walk_var = max(white_var, MIN_STD_RAD**2), max(walk_var, MIN_STD_RAD**2)
    return min(max(math.log(white_var / walk_var), -LOGIT_SHARE_LIMIT), LOGIT_SHARE_LIMIT)


def _logit(phi: float) -> float:
    """The Nelder-Mead coordinate of a step correlation ``phi`` in ``(0, MAX_CORRELATION)``."""
    phi = min(max(phi, 1e-6), MAX_CORRELATION * (1.0 - 1e-9))
    return math.log(phi / (MAX_CORRELATION - phi))
