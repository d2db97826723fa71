"""Unscented Kalman filter on the identification model's unknowns (registry name ``ukf``), sample by sample.

State: the unknowns ``theta`` (k,) of the model's parameterisation (``fuel``: fuel consumed ``mdf`` kg and tank
position ``bf`` m, base frame; with effects, their unknowns after them), modelled as a random walk. Measurement:
the gyro's base rate (3,), rad/s, base body frame, one sample at a time, predicted through the same
:meth:`~estimators.problem.IdentificationProblem.predict` the batch estimators minimise: all ``2k + 1`` sigma
points of one sample go through one batched call, so there is no second copy of the physics. The filter itself
is filterpy's :class:`~filterpy.kalman.UnscentedKalmanFilter` with :class:`~filterpy.kalman.MerweScaledSigmaPoints`.

Model, in the units of the parameters:

* initial state (``start``, :meth:`UnscentedKalman.fit`): ``global`` (default) starts the filter at the estimate of
  a global search (``global_search``, by default the improved PSO, the ``hybrid``'s first stage, ~0.1 s on a 60 s
  window) with the prior covariance ``P0 = prior_inflation^2 (F + B^-1)^-1``: ``F`` the window's Fisher information
  at that start with the filter's noise (the batch fit's own Cramér-Rao covariance there), ``B`` the box prior below,
  ``prior_inflation`` 3 by default (the prior std three times the bound: the data, not the prior, set the estimate
  and its covariance; the prior adds 1/9 of the window's information). ``interior`` starts at the nominal moved
  :data:`~estimators.least_squares.INTERIOR_FRACTION` of the width inside the box, as ``lm`` starts (the fuel
  nominal ``mdf = 0`` sits on its bound, where the tank position has no effect on the rates), with the box prior
  ``B = diag((initial_std_fraction x scale)^2)``, ``scale`` the parameters' typical sizes
  (:attr:`~estimators.parameters.Parameterisation.scale`: the search widths for ``fuel``), i.e. by default a
  quarter of the box. The streaming :meth:`UnscentedKalman.tracker` starts as ``interior`` unless given a state;
* process noise: a parameter random walk, ``Q = diag((random_walk x scale)^2) x dt`` for a step of ``dt`` s
  (``random_walk`` in fractions of the scale per square-root second). The default ``1e-5`` is small enough that
  one window behaves like a batch fit (over 60 s the walk adds 8e-5 of the width, 2e-4 over the fit's 6 passes,
  far below the Cramér-Rao std); a larger value, or :meth:`UKFTracker.advance` over the gap between windows,
  lets the filter follow fuel consumed over a mission;
* measurement noise: ``R = sigma^2 I_3`` with ``sigma`` the gyro noise std per sample and axis (rad/s): the
  estimator's ``noise_std_rad_s`` if given, else the model's (``IdentificationModel(noise_std_rad_s=...)``, as
  the batch estimators' bound uses it), else estimated from the log's gyro by third differences
  (:func:`difference_noise_std`), since the filter needs it before any fit exists.

Constraint: after every update the mean is projected into the search box (clipped; the covariance is kept).
Outside the box lie non-physical basins of the fit (e.g. negative fuel consumed with a mirrored tank) which a
filter started with a wide prior can otherwise run into.

One window, several passes (``passes``, :meth:`UnscentedKalman.fit`): a single pass of the filter over a window
with a wide prior linearises the early samples far from the truth, where the fuel's coupling with the tank
position makes the rates strongly nonlinear in ``theta``; their information is then over-counted and the final
covariance is too small (on simulated 60 s windows the fuel's std came out at about 0.6 of the Cramér-Rao std
with a single pass). The fit therefore runs ``passes`` tempered passes over the window, each with the gyro noise
variance multiplied by ``passes`` (each pass takes ``1 / passes`` of the likelihood, so the passes together take
it once), carrying state and covariance from pass to pass: later passes linearise near the estimate, as a batch
fit does. The streaming interface (:class:`UKFTracker`) is the plain filter (``weight`` 1 per sample); it is
over-confident in the same way while its state is far from the truth (a mission tracker can start it from a
tempered fit of the first window, as ``spaceid track`` does: :mod:`spaceid_gym.tracking`).

Why the global start (measured, ``benchmarks/ukf_settings.py``; 29 to 30 settings drawn as the evaluation harness
draws them, paper6, 60 s windows): the filter is a local method. Started ``interior`` it ended more than 3
Cramér-Rao std from the truth in the fuel on 14 of 29 windows (NEES median 108), mostly at ``mdf = 0`` (the lower
bound, where the tank position has no effect) or in a mirrored basin; started at the middle of the fuel range, 10 of
29. Making the state the fuel's first moment ``h = mdf bf`` instead of ``bf`` (the inertia is then
``h h^T / mdf`` away from linear, mass and first moment linear) did not help: 13 of 29 from the same middle start
and 9 of 29 from the global start (the division by ``mdf`` near the lower bound makes it worse there). From the
global search's estimate with the wide box prior 2 of 29 windows still left the truth (the first samples' sigma
points span half the box and carry the mean out of the basin); with the Fisher-scaled prior above the filter
stays in the basin: 29 of 30 windows within 3 std in every unknown, as ``hybrid`` (the 30th is a failure of the
shared global search: a basin whose cost is 1.119 noise variances against 1.069 at the truth, where ``hybrid``
fails too), the RMS fuel error 1.05 times ``hybrid``'s, the filter's std 0.95 of the bound (median), NEES below
chi-square(4)'s 95 % point on 26 of 30 (a window with little fuel consumed, 33 kg, is over-confident: its std 0.55
of the bound in the fuel).

Numerical safety: the covariance is symmetrised after every step; a covariance that is not positive definite
(the sigma points' Cholesky factor fails) or a non-finite prediction raises a :class:`FilterDivergedError`
naming the sample, never a bare ``LinAlgError`` and never a silent reset.

Two interfaces: :class:`UnscentedKalman` follows the estimator protocol (``fit(model, log)`` runs the filter
over the whole window; the :class:`~estimators.estimate.Estimate` carries the final state as ``theta``, the
filter's final covariance as ``extra["covariance"]`` (k, k) and ``extra["filter_std"]`` (k,), next to the
Cramér-Rao ``theta_std`` every estimate has); :class:`UKFTracker` is the streaming interface
(``update(sample_index)``, ``estimate()``, ``advance(gap_s)``, ``bind(next_problem)``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from numpy.typing import ArrayLike

from estimators.base import Estimator, SearchResult
from estimators.least_squares import interior_start
from estimators.options import check_bool, check_float, finite_vector, positive_option
from estimators.problem import IdentificationProblem
from estimators.registry import make_estimator
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: third differences of white noise of std sigma have std ``sqrt(20) sigma`` (binomial coefficients 1, 3, 3, 1)
THIRD_DIFFERENCE_GAIN = float(np.sqrt(20.0))

#: where :meth:`UnscentedKalman.fit` starts the filter (see the module docstring)
STARTS = ("global", "interior")

#: the median of ``|x|`` for a standard normal ``x``
HALF_NORMAL_MEDIAN = 0.6744897501960817


class FilterDivergedError(SpaceIdInputError):
    """The filter's covariance lost positive definiteness, or its prediction is not finite, at a named sample."""


def difference_noise_std(measured: FloatArray) -> float:
    """Gyro noise std per sample and axis (rad/s) from the measured rates (T, 3): the median absolute third
    difference over samples and axes divided by ``0.6745 sqrt(20)``. The joint motion's rates are smooth at the
    log's rate, so the third differences are the noise's; the median ignores the few samples of fast transients."""
    if len(measured) < 4:
        raise SpaceIdInputError(f"log: {len(measured)} samples are too few to estimate the gyro noise (4 needed)")
    third = np.diff(np.asarray(measured, dtype=float), n=3, axis=0)
    return float(np.median(np.abs(third)) / (HALF_NORMAL_MEDIAN * THIRD_DIFFERENCE_GAIN))


def _same(x: FloatArray, dt: float) -> FloatArray:
    """The random walk's state transition: the state is unchanged, only its covariance grows by ``Q``."""
    return x


class RandomWalkUKF(UnscentedKalmanFilter):
    """filterpy's unscented filter for a state that only walks (``fx`` the identity), with two steps in closed form.

    :meth:`predict`: the unscented transform of sigma points through the identity returns their mean and covariance,
    ``x`` and ``P`` (to rounding), so the prediction is ``x``, ``P + Q`` and the sigma points of that, as filterpy's
    own predict computes them, without its first set of sigma points and its transform. :meth:`cross_variance`:
    ``sum_i Wc_i dx_i dz_i^T`` as one product instead of a loop of outer products. Together a third of a 60 s
    window's fit on ``paper6`` (``benchmarks/ukf_speed.py``). The same for any Merwe parameters (the transform of a
    linear map is exact); one difference: filterpy factorises ``P`` before adding ``Q``, this only ``P + Q``, so a ``P``
    that is not positive definite but is mended by ``Q`` does not raise here."""

    def predict(self, dt: float | None = None, UT: Any = None, fx: Any = None, **fx_args: Any) -> None:
        if UT is not None or fx is not None or fx_args or self.x_mean is not None or self.residual_x is not np.subtract:
            raise ValueError(
                "RandomWalkUKF.predict: the walk's transition is the identity in a vector space; no UT, fx, fx_args, "
                "x_mean_fn or residual_x"
            )
        self.P = self.P + self.Q
        self.sigmas_f = self.points_fn.sigma_points(self.x, self.P)
        self.x_prior = np.copy(self.x)
        self.P_prior = np.copy(self.P)

    def cross_variance(self, x: FloatArray, z: FloatArray, sigmas_f: FloatArray, sigmas_h: FloatArray) -> FloatArray:
        return (self.Wc[:, None] * (sigmas_f - x)).T @ (sigmas_h - z)


def _next_row(x: FloatArray, rows: Any) -> FloatArray:
    """filterpy's measurement function, sigma point by sigma point: the next row of the batched prediction."""
    return next(rows)


def _covariance(name: str, value: FloatArray, k: int) -> FloatArray:
    """``value`` as a symmetrised finite (k, k) positive definite covariance; raises naming ``name`` otherwise."""
    cov = np.asarray(value, dtype=float)
    if cov.shape != (k, k) or not np.all(np.isfinite(cov)):
        raise SpaceIdInputError(f"{name}: expected a finite ({k}, {k}) covariance, got shape {cov.shape}")
    cov = 0.5 * (cov + cov.T)
    if np.linalg.eigvalsh(cov)[0] <= 0.0:
        raise SpaceIdInputError(f"{name}: the covariance is not positive definite")
    return cov


class UKFTracker:
    """The streaming unscented Kalman filter on one problem at a time (see the module docstring).

    Args:
        problem: the window's identification problem (its ``predict`` is the measurement model).
        noise_std_rad_s: gyro noise std per sample and axis, rad/s (``R = sigma^2 I_3``).
        random_walk: process noise, fractions of each parameter's scale per square-root second, scalar or (k,).
        alpha, beta, kappa: Merwe's sigma-point parameters (spread, prior knowledge of the distribution, scaling).
        x0: initial state (k,); ``P0``: initial covariance (k, k), symmetric positive definite.
        clip: project the mean into the parameterisation's box after each update (see the module docstring).

    Attributes:
        nis: normalised innovation squared ``y^T S^-1 y`` of each update (3 degrees of freedom each).
        innovations: the innovations ``measured - predicted`` (3,) rad/s, base body frame, of each update.
        samples: the sample index of each update, in the problem it was made on.
    """

    def __init__(
        self,
        problem: IdentificationProblem,
        *,
        noise_std_rad_s: float,
        random_walk: float | FloatArray,
        alpha: float,
        beta: float,
        kappa: float,
        x0: FloatArray,
        P0: FloatArray,
        clip: bool = True,
    ) -> None:
        k = problem.n_params
        self.scale = np.asarray(problem.parameters.scale, dtype=float)
        self.random_walk = np.broadcast_to(np.asarray(random_walk, dtype=float), (k,)).copy()
        if not np.all(np.isfinite(self.random_walk) & (self.random_walk >= 0.0)):
            raise SpaceIdInputError(f"random_walk: expected finite numbers >= 0, got {random_walk!r}")
        self.noise_std_rad_s = positive_option("noise_std_rad_s", noise_std_rad_s)
        cov = _covariance("P0", P0, k)
        points = MerweScaledSigmaPoints(k, alpha=alpha, beta=beta, kappa=kappa)
        self.filter = RandomWalkUKF(dim_x=k, dim_z=3, dt=0.0, hx=_next_row, fx=_same, points=points)
        self.filter.x = finite_vector("x0", x0, problem.parameters.names).copy()
        self.x0 = self.filter.x.copy()
        self.filter.P = cov
        self.filter.R = np.eye(3) * self.noise_std_rad_s**2
        self.nis: list[float] = []
        self.innovations: list[FloatArray] = []
        self.samples: list[int] = []
        self.problem = problem
        self.clip = clip
        self._last_t_s: float | None = None

    @property
    def n_params(self) -> int:
        """k."""
        return len(self.scale)

    def process_noise(self, dt_s: float) -> FloatArray:
        """The random walk's covariance growth (k, k) over ``dt_s`` seconds."""
        return np.diag((self.random_walk * self.scale) ** 2 * dt_s)

    def set_noise(self, noise_std_rad_s: float) -> None:
        """Use the gyro noise std ``noise_std_rad_s`` (rad/s per sample and axis) from the next update on."""
        self.noise_std_rad_s = positive_option("noise_std_rad_s", noise_std_rad_s)
        self.filter.R = np.eye(3) * self.noise_std_rad_s**2

    def set_state(self, x: FloatArray, P: FloatArray) -> None:
        """Continue from the state ``x`` (k,) with covariance ``P`` (k, k), symmetric positive definite (e.g. a posterior
        computed outside the filter)."""
        cov = _covariance("P", P, self.n_params)
        self.filter.x = finite_vector("x", x, self.problem.parameters.names).copy()
        self.filter.P = cov

    def bind(self, problem: IdentificationProblem) -> None:
        """Continue on ``problem`` (the next window of the same model): the state and covariance are kept; call
        :meth:`advance` for the time between the windows."""
        if problem.parameters.names != self.problem.parameters.names:
            raise SpaceIdInputError(
                f"problem: its unknowns {problem.parameters.names} differ from the tracker's {self.problem.parameters.names}"
            )
        self.problem = problem
        self._last_t_s = None

    def advance(self, gap_s: float) -> None:
        """Let the random walk run ``gap_s`` seconds without measurements (e.g. between two windows)."""
        gap_s = check_float("gap_s", gap_s, 0.0, np.inf)
        self.filter.P = self.filter.P + self.process_noise(gap_s)

    def rewind(self) -> None:
        """Start again at the bound window's first sample (a further pass over the same data): the random walk does
        not run between the last sample and the first."""
        self._last_t_s = None

    def update(self, sample_index: int, weight: float = 1.0) -> FloatArray:
        """Assimilate the gyro sample ``sample_index`` of the bound problem; returns the innovation (3,), rad/s.

        Samples go forward in time; the random walk runs over the time since the previous sample of this
        window (none before the first). ``weight`` in (0, 1]: the fraction of the sample's likelihood taken
        (the noise variance divided by it), 1 for the plain filter, ``1 / passes`` in a tempered pass.
        """
        problem = self.problem
        if isinstance(sample_index, bool) or not isinstance(sample_index, (int, np.integer)):
            raise SpaceIdInputError(f"sample_index: expected an integer, got {sample_index!r}")
        if not 0 <= sample_index < problem.n_samples:
            raise SpaceIdInputError(f"sample_index: expected 0..{problem.n_samples - 1}, got {sample_index}")
        t_s = float(problem.log.t_s[sample_index])
        if self._last_t_s is not None and t_s <= self._last_t_s:
            raise SpaceIdInputError(
                f"sample_index {sample_index}: t = {t_s:g} s is not after the previous update's t = {self._last_t_s:g} s"
            )
        dt_s = 0.0 if self._last_t_s is None else t_s - self._last_t_s
        ukf = self.filter
        ukf.Q = self.process_noise(dt_s)
        where = f"sample {sample_index} (t = {t_s:g} s)"
        try:
            ukf.predict(dt=dt_s)
            predicted = problem.predict(ukf.sigmas_f, slice(sample_index, sample_index + 1))[:, 0, :]
            if not np.all(np.isfinite(predicted)):
                raise FilterDivergedError(f"ukf: the model's prediction is not finite at {where}, state {ukf.x.tolist()}")
            ukf.update(problem.measured[sample_index], R=self.filter.R / weight, rows=iter(predicted))
        except np.linalg.LinAlgError as exc:
            raise FilterDivergedError(
                f"ukf: the state covariance is not positive definite at {where} ({exc}); "
                "try a smaller initial_std_fraction or a larger alpha"
            ) from None
        ukf.P = 0.5 * (ukf.P + ukf.P.T)
        if self.clip:
            params = problem.parameters
            ukf.x = np.clip(ukf.x, params.lower, params.upper)
        innovation = np.array(ukf.y, dtype=float)
        self.nis.append(float(innovation @ ukf.SI @ innovation))
        self.innovations.append(innovation)
        self.samples.append(int(sample_index))
        self._last_t_s = t_s
        return innovation

    def run(self, samples: ArrayLike | None = None, weight: float = 1.0) -> None:
        """:meth:`update` on each of ``samples`` (default: every sample of the bound problem, in order) with ``weight``."""
        weight = check_float("weight", weight, 0.0, 1.0, low_open=True)
        indices = range(self.problem.n_samples) if samples is None else np.asarray(samples, dtype=int).ravel().tolist()
        for index in indices:
            self.update(index, weight)

    def estimate(self) -> tuple[FloatArray, FloatArray]:
        """The current state (k,) and its covariance (k, k) (copies)."""
        return self.filter.x.copy(), self.filter.P.copy()


class UnscentedKalman(Estimator):
    """The unscented Kalman filter as an estimator (registry name ``ukf``); see the module docstring.

    Args:
        random_walk: process noise in fractions of each parameter's scale per square-root second, >= 0
            (scalar or one per unknown); default ``1e-5``.
        initial_std_fraction: initial std of each unknown as a fraction of its scale (> 0); default ``0.25``.
        passes: tempered passes over the window in :meth:`fit` (>= 1, see the module docstring); default 6.
        clip: project the mean into the search box after each update; default ``True``.
        alpha: Merwe's spread of the sigma points around the mean, in (0, 1]; default 1 (with ``kappa`` 0 the sigma
            points lie ``sqrt(k)`` std from the mean: a wide spread averages the model's curvature over the prior).
        beta: Merwe's prior-distribution parameter (2 is optimal for a Gaussian), >= 0.
        kappa: Merwe's secondary scaling, >= 0.
        noise_std_rad_s: gyro noise std per sample and axis (rad/s); ``None``: the model's, else the log's
            (:func:`difference_noise_std`).
        start: ``global`` (default) or ``interior``, where :meth:`fit` starts the filter (see the module docstring).
        global_search: registry name of the global search of the ``global`` start (default ``improved-pso``).
        prior_inflation: the ``global`` start's prior std over the window's Cramér-Rao std there (> 0, default 3).
        seed: seed of the global search's generator (the filter itself is deterministic).

    ``extra`` of the estimate: ``covariance`` (k, k) and ``filter_std`` (k,), the filter's final covariance and
    standard deviations; ``nis_mean_last_pass`` (the last pass's mean NIS, with the tempered noise: ``3 / passes``
    for a consistent filter); ``filter_noise_std_rad_s`` and
    ``filter_noise_source`` (``given``, ``model`` or ``differences``); ``start_theta`` (k,), where the filter started.
    """

    name: ClassVar[str] = "ukf"

    def __init__(
        self,
        *,
        random_walk: float | list[float] = 1e-5,
        initial_std_fraction: float = 0.25,
        passes: int = 6,
        clip: bool = True,
        alpha: float = 1.0,
        beta: float = 2.0,
        kappa: float = 0.0,
        noise_std_rad_s: float | None = None,
        start: str = "global",
        global_search: str = "improved-pso",
        prior_inflation: float = 3.0,
        seed: int | None = 0,
    ) -> None:
        super().__init__(seed=seed)
        walk = np.asarray(random_walk, dtype=float) if isinstance(random_walk, (int, float, list, np.ndarray)) else None
        if walk is None or isinstance(random_walk, bool) or walk.ndim > 1 or not np.all(np.isfinite(walk) & (walk >= 0.0)):
            raise SpaceIdInputError(f"random_walk: expected a number >= 0 or a list of them, got {random_walk!r}")
        self.random_walk = random_walk
        self.initial_std_fraction = positive_option("initial_std_fraction", initial_std_fraction)
        self.passes = positive_option("passes", passes, integer=True)
        self.clip = check_bool("clip", clip)
        self.alpha = check_float("alpha", alpha, 0.0, 1.0, low_open=True)
        self.beta = check_float("beta", beta, 0.0, np.inf)
        self.kappa = check_float("kappa", kappa, 0.0, np.inf)
        self.noise_std_rad_s = None if noise_std_rad_s is None else positive_option("noise_std_rad_s", noise_std_rad_s)
        if start not in STARTS:
            raise SpaceIdInputError(f"start: expected one of {', '.join(STARTS)}, got {start!r}")
        self.start = start
        self.global_search = global_search
        self.global_estimator = make_estimator(global_search)
        self.prior_inflation = positive_option("prior_inflation", prior_inflation)

    def filter_noise(self, problem: IdentificationProblem) -> tuple[float, str]:
        """The gyro noise std (rad/s) the filter uses on ``problem`` and where it comes from (see ``noise_std_rad_s``)."""
        if self.noise_std_rad_s is not None:
            return self.noise_std_rad_s, "given"
        if problem.model.noise_std_rad_s is not None:
            return float(problem.model.noise_std_rad_s), "model"
        return difference_noise_std(problem.measured), "differences"

    def min_samples(self, problem: IdentificationProblem) -> int:
        """The base's count, and 4 for the difference noise estimate."""
        return max(super().min_samples(problem), 4)

    def box_prior(self, problem: IdentificationProblem) -> FloatArray:
        """The prior covariance of the ``interior`` start (k, k): ``diag((initial_std_fraction x scale)^2)``."""
        std = self.initial_std_fraction * np.asarray(problem.parameters.scale, dtype=float)
        return np.diag(std * std)

    def global_start(self, problem: IdentificationProblem, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
        """The ``global`` start (see the module docstring): the global search's estimate ``x0`` (k,) and
        ``P0 = prior_inflation^2 (F + B^-1)^-1`` (k, k), ``F`` the window's Fisher information at ``x0`` with the filter's
        noise, ``B`` the :meth:`box_prior`."""
        x0 = np.asarray(self.global_estimator.search(problem, rng).theta, dtype=float)
        fisher = problem.fisher(x0, self.filter_noise(problem)[0])
        information = fisher + np.linalg.inv(self.box_prior(problem))
        cov = self.prior_inflation**2 * np.linalg.inv(information)
        return x0, 0.5 * (cov + cov.T)

    def tracker(self, problem: IdentificationProblem, x0: FloatArray | None = None, P0: FloatArray | None = None) -> UKFTracker:
        """A :class:`UKFTracker` on ``problem`` with this estimator's options, at ``x0`` (k,) with covariance ``P0``
        (k, k); by default the ``interior`` start and the :meth:`box_prior`."""
        params = problem.parameters
        walk = np.asarray(self.random_walk, dtype=float)
        if walk.ndim == 1 and walk.shape != (params.n_params,):
            raise SpaceIdInputError(f"random_walk: expected 1 or {params.n_params} numbers ({', '.join(params.names)})")
        return UKFTracker(
            problem,
            noise_std_rad_s=self.filter_noise(problem)[0],
            random_walk=walk,
            alpha=self.alpha,
            beta=self.beta,
            kappa=self.kappa,
            x0=interior_start(params) if x0 is None else x0,
            P0=self.box_prior(problem) if P0 is None else P0,
            clip=self.clip,
        )

    def fitted_tracker(self, problem: IdentificationProblem, rng: np.random.Generator) -> UKFTracker:
        """The tracker after :meth:`fit`'s work on ``problem``: started as ``start`` says, then ``passes`` tempered
        passes over the window (a mission tracker continues from it on the next window)."""
        started = self.global_start(problem, rng) if self.start == "global" else (None, None)
        tracker = self.tracker(problem, *started)
        for _ in range(self.passes):
            tracker.rewind()
            tracker.run(weight=1.0 / self.passes)
        return tracker

    def _search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        tracker = self.fitted_tracker(problem, rng)
        theta, cov = tracker.estimate()
        sigma, source = self.filter_noise(problem)
        return SearchResult(
            theta=theta,
            cost_history=[float(problem.cost(theta, count=False)[0])],
            extra={
                "covariance": cov.tolist(),
                "filter_std": np.sqrt(np.diag(cov)).tolist(),
                "nis_mean_last_pass": float(np.mean(tracker.nis[-problem.n_samples :])),
                "filter_noise_std_rad_s": sigma,
                "filter_noise_source": source,
                "start_theta": tracker.x0.tolist(),
            },
        )
